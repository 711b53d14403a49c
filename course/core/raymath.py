"""Small vector helpers and input checks shared by the ray-primitive kernels.

Given code, not exercises: the labs import these so that every kernel validates its
inputs the same way and reports bad ones with the argument's name.
"""

from __future__ import annotations

import math

import torch


def cross(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Cross product over the last axis, written out (6 mul, 3 sub per vector)."""
    ax, ay, az = a.unbind(-1)
    bx, by, bz = b.unbind(-1)
    return torch.stack((ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx), dim=-1)


def dot(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Dot product over the last axis, written out (3 mul, 2 add): ``(..., 3) -> (...)``."""
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]


def gamma(n: int, dtype: torch.dtype) -> float:
    """``n u / (1 - n u)`` with ``u`` the unit roundoff of ``dtype``: the relative error
    bound of ``n`` successive roundings (pbrt's gamma)."""
    u = torch.finfo(dtype).eps / 2
    return n * u / (1 - n * u)


def check_inputs(vectors: dict, scalars: dict | None = None):
    """Validate a kernel's arguments; return ``(shape, scalars)``.

    vectors: ``{name: (tensor, trailing)}``: each must be a floating-point tensor whose
        last dimensions equal ``trailing`` (e.g. ``(3,)`` for points, ``(3, 4)`` for a
        transform), all of one dtype and device, with leading dimensions that broadcast.
    scalars: ``{name: value}`` such as ``t_min``: Python numbers or float tensors on the
        same device, broadcast with the rest and converted to the kernels' dtype.
    shape: the broadcast shape of the results.
    Raises TypeError (not a tensor, not floating point, mixed dtypes) or ValueError
    (wrong trailing shape, other device, shapes that do not broadcast) naming the argument.
    """
    first = None
    shape = torch.Size()
    for name, (x, trailing) in vectors.items():
        want = "(..., " + ", ".join(map(str, trailing)) + ")"
        if not isinstance(x, torch.Tensor):
            raise TypeError(f"{name}: expected a torch.Tensor of shape {want}, "
                            f"got {type(x).__name__}")
        if not x.is_floating_point():
            raise TypeError(f"{name}: expected a floating-point tensor (float16, bfloat16, "
                            f"float32 or float64), got {x.dtype}")
        if x.ndim < len(trailing) or tuple(x.shape[x.ndim - len(trailing):]) != trailing:
            raise ValueError(f"{name}: expected shape {want}, got {tuple(x.shape)}")
        if first is None:
            first = (name, x)
        elif x.dtype != first[1].dtype:
            raise TypeError(f"{name}: expected dtype {first[1].dtype} like {first[0]}, "
                            f"got {x.dtype}")
        elif x.device != first[1].device:
            raise ValueError(f"{name}: expected a tensor on {first[1].device} like {first[0]}, "
                             f"got one on {x.device}")
        shape = _broadcast(shape, x.shape[:x.ndim - len(trailing)], name, vectors)
    converted = {}
    for name, value in (scalars or {}).items():
        if isinstance(value, torch.Tensor):
            if not value.is_floating_point():
                raise TypeError(f"{name}: expected a number or a floating-point tensor, "
                                f"got {value.dtype}")
            if value.device != first[1].device:
                raise ValueError(f"{name}: expected a tensor on {first[1].device} like "
                                 f"{first[0]}, got one on {value.device}")
        elif not isinstance(value, (int, float)) or isinstance(value, bool):
            raise TypeError(f"{name}: expected a number or a float tensor, "
                            f"got {type(value).__name__}")
        value = torch.as_tensor(value, dtype=first[1].dtype, device=first[1].device)
        shape = _broadcast(shape, value.shape, name, vectors)
        converted[name] = value
    return shape, converted


def _broadcast(shape, other, name, vectors):
    try:
        return torch.broadcast_shapes(shape, other)
    except RuntimeError:
        before = list(vectors)[:list(vectors).index(name)] if name in vectors else list(vectors)
        raise ValueError(f"{name}: leading shape {tuple(other)} does not broadcast with "
                         f"{tuple(shape)}, the broadcast of {', '.join(before)}; rays "
                         f"(N, 1, 3) against triangles (1, M, 3) give (N, M) results") from None


def check_triangle_inputs(origins, directions, v0, v1, v2, t_min, t_max):
    """``check_inputs`` for a triangle kernel's arguments; returns ``t_min, t_max`` as
    tensors of the kernel's dtype and device."""
    p3 = (3,)
    _, s = check_inputs({"origins": (origins, p3), "directions": (directions, p3),
                         "v0": (v0, p3), "v1": (v1, p3), "v2": (v2, p3)},
                        {"t_min": t_min, "t_max": t_max})
    return s["t_min"], s["t_max"]


def masked_result(hit, t, u, v):
    """A triangle kernel's outputs: ``(t, u, v)`` where ``hit``, ``(inf, 0, 0)`` elsewhere
    (so no NaN computed for a miss ever leaves the kernel)."""
    inf = torch.full((), math.inf, dtype=t.dtype, device=t.device)
    zero = torch.zeros((), dtype=t.dtype, device=t.device)
    return torch.where(hit, t, inf), torch.where(hit, u, zero), torch.where(hit, v, zero)
