"""Small vector functions and input checks shared by the ray-primitive kernels.

Given code, not exercises: the labs import these so that every kernel validates its
inputs the same way and reports bad ones with the argument's name.
"""

from __future__ import annotations

import math

import torch

from course.core.types import Mesh


def columns(v) -> tuple:
    """``(..., 3)`` tensor -> its three ``(...)`` columns ``(x, y, z)`` (views); a tuple of
    three columns is returned as it is."""
    return tuple(v.unbind(-1)) if isinstance(v, torch.Tensor) else tuple(v)


def cross(a, b):
    """Cross product, written out (6 mul, 3 sub per vector): ``(..., 3), (..., 3) ->
    (..., 3)``; on tuples of three columns (see :func:`columns`), a tuple of three columns
    (elementwise ops that ``torch.compile`` fuses into the caller's kernel)."""
    (ax, ay, az), (bx, by, bz) = columns(a), columns(b)
    out = (ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx)
    return torch.stack(out, dim=-1) if isinstance(a, torch.Tensor) else out


def dot(a, b) -> torch.Tensor:
    """Dot product, written out (3 mul, 2 add): ``(..., 3), (..., 3) -> (...)``, or on
    tuples of three columns (see :func:`columns`)."""
    if isinstance(a, torch.Tensor):
        return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def normalize(v: torch.Tensor) -> torch.Tensor:
    """``v / |v|`` over the last axis: ``(..., 3) -> (..., 3)``; a zero vector stays zero
    (never NaN)."""
    length = v.norm(dim=-1, keepdim=True)
    return v / torch.where(length > 0, length, torch.ones_like(length))


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
            raise TypeError(
                f"{name}: expected a torch.Tensor of shape {want}, got {type(x).__name__}"
            )
        if not x.is_floating_point():
            raise TypeError(
                f"{name}: expected a floating-point tensor (float16, bfloat16, "
                f"float32 or float64), got {x.dtype}"
            )
        if x.ndim < len(trailing) or tuple(x.shape[x.ndim - len(trailing) :]) != trailing:
            raise ValueError(f"{name}: expected shape {want}, got {tuple(x.shape)}")
        if first is None:
            first = (name, x)
        elif x.dtype != first[1].dtype:
            raise TypeError(
                f"{name}: expected dtype {first[1].dtype} like {first[0]}, got {x.dtype}"
            )
        elif x.device != first[1].device:
            raise ValueError(
                f"{name}: expected a tensor on {first[1].device} like {first[0]}, "
                f"got one on {x.device}"
            )
        shape = _broadcast(shape, x.shape[: x.ndim - len(trailing)], name, vectors)
    converted = {}
    for name, value in (scalars or {}).items():
        if isinstance(value, torch.Tensor):
            if not value.is_floating_point():
                raise TypeError(
                    f"{name}: expected a number or a floating-point tensor, got {value.dtype}"
                )
            if value.device != first[1].device:
                raise ValueError(
                    f"{name}: expected a tensor on {first[1].device} like "
                    f"{first[0]}, got one on {value.device}"
                )
        elif not isinstance(value, (int, float)) or isinstance(value, bool):
            raise TypeError(
                f"{name}: expected a number or a float tensor, got {type(value).__name__}"
            )
        value = torch.as_tensor(value, dtype=first[1].dtype, device=first[1].device)
        shape = _broadcast(shape, value.shape, name, vectors)
        converted[name] = value
    return shape, converted


def _broadcast(shape, other, name, vectors):
    try:
        return torch.broadcast_shapes(shape, other)
    except RuntimeError:
        before = list(vectors)[: list(vectors).index(name)] if name in vectors else list(vectors)
        raise ValueError(
            f"{name}: leading shape {tuple(other)} does not broadcast with "
            f"{tuple(shape)}, the broadcast of {', '.join(before)}; rays "
            f"(N, 1, 3) against triangles (1, M, 3) give (N, M) results"
        ) from None


def check_triangle_inputs(origins, directions, v0, v1, v2, t_min, t_max):
    """``check_inputs`` for a triangle kernel's arguments; returns ``t_min, t_max`` as
    tensors of the kernel's dtype and device."""
    p3 = (3,)
    _, s = check_inputs(
        {
            "origins": (origins, p3),
            "directions": (directions, p3),
            "v0": (v0, p3),
            "v1": (v1, p3),
            "v2": (v2, p3),
        },
        {"t_min": t_min, "t_max": t_max},
    )
    return s["t_min"], s["t_max"]


def masked_result(hit, t, u, v):
    """A triangle kernel's outputs: ``(t, u, v)`` where ``hit``, ``(inf, 0, 0)`` elsewhere
    (so no NaN computed for a miss ever leaves the kernel)."""
    inf = torch.full((), math.inf, dtype=t.dtype, device=t.device)
    zero = torch.zeros((), dtype=t.dtype, device=t.device)
    return torch.where(hit, t, inf), torch.where(hit, u, zero), torch.where(hit, v, zero)


def check_mesh(mesh, finite: bool = False, dtypes=None, name: str = "mesh") -> None:
    """``mesh`` must be a valid ``course.core.types.Mesh`` (TypeError/ValueError naming
    ``name``, or the field ``Mesh.validate`` names).

    finite: also require finite vertices (every structure builder does: a NaN or inf corner
    has no bounds to sort by); the ValueError gives the count and the first such vertex.
    dtypes: the vertex dtypes accepted (None: any floating-point dtype).
    """
    if not isinstance(mesh, Mesh):
        raise TypeError(f"{name}: expected course.core.types.Mesh, got {type(mesh).__name__}")
    mesh.validate()
    if dtypes is not None and mesh.dtype not in dtypes:
        allowed = " or ".join(str(d).removeprefix("torch.") for d in dtypes)
        raise TypeError(f"{name}: expected {allowed} vertices, got {mesh.dtype}")
    if finite:
        bad = ~torch.isfinite(mesh.vertices).all(-1)
        if bool(bad.any()):
            first = int(bad.nonzero()[0, 0])
            raise ValueError(
                f"{name}: expected finite vertices to build a structure over, got "
                f"{int(bad.sum())} of {len(bad)} with NaN or inf coordinates (first: vertex "
                f"{first} = {mesh.vertices[first].tolist()}); repair or drop those triangles"
            )
