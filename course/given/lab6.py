"""Given code of Lab 6 (the compute rasterizer), shared by the skeleton and the reference.

The key layout of the visibility buffer, argument checks that name what was expected,
where an edge crosses the near plane, the fragment depth of each depth mode, and small
helpers of the shading and ray-tracing tasks. They are not exercises: the lab imports
them, and the grader never asks for them.
"""

from __future__ import annotations

import torch

from course.core.raymath import normalize as normalized  # Provided: unit vectors, 0 stays 0
from course.core.types import Mesh

EMPTY = torch.iinfo(torch.int64).max
"""The key of a pixel no fragment reached: larger than every packed key (the "far" value
a depth buffer is cleared to)."""


ID_BITS = 32


ID_MASK = (1 << ID_BITS) - 1
"""Triangle ids live in the low 32 bits of a key, depth in the bits above."""


BYTES_PER_FRAGMENT = 256
"""Bytes ``rasterize`` keeps alive per fragment, at most: the fragments of one chunk of
triangles number at most ``memory_budget_bytes // BYTES_PER_FRAGMENT`` (or one triangle's
clamped bounding box, at most ``width * height``, when a single triangle needs more)."""


def check_tensor(x, name: str, shape: tuple, kind: str = "float", like=None) -> torch.Tensor:
    """Provided: ``x`` must be a tensor of ``shape`` (``None`` = any size); ``kind`` is
    ``"float"`` (float32/float64), ``"int64"`` or ``"any"``; ``like``: a tensor whose device
    ``x`` must share. Raises TypeError/ValueError naming ``name`` and what was expected."""
    want = (
        "("
        + ", ".join("N" if s is None else str(s) for s in shape)
        + ("," if len(shape) == 1 else "")
        + ")"
    )
    if not isinstance(x, torch.Tensor):
        raise TypeError(f"{name}: expected a torch.Tensor of shape {want}, got {type(x).__name__}")
    if x.ndim != len(shape) or any(s is not None and s != d for s, d in zip(shape, x.shape)):
        raise ValueError(f"{name}: expected shape {want}, got {tuple(x.shape)}")
    if kind == "float" and x.dtype not in (torch.float32, torch.float64):
        raise TypeError(f"{name}: expected float32 or float64, got {x.dtype}")
    if kind == "int64" and x.dtype != torch.int64:
        raise TypeError(f"{name}: expected dtype torch.int64, got {x.dtype}")
    if like is not None and x.device != like.device:
        raise ValueError(f"{name}: expected a tensor on {like.device}, got one on {x.device}")
    return x


def check_size(width, height) -> None:
    """Provided: the viewport must be positive integers (at most 2**15 each, which keeps
    pixel centres and ``row * width + col`` exact)."""
    for name, size in (("width", width), ("height", height)):
        if isinstance(size, bool) or not isinstance(size, int) or not 0 < size <= 2**15:
            raise ValueError(
                f"{name}: expected a positive integer pixel count <= 32768, got {size!r}"
            )


def any_shape(x) -> tuple:
    return (None,) * x.ndim if isinstance(x, torch.Tensor) else (None,)


def check_screen(screen, name="screen") -> torch.Tensor:
    check_tensor(screen, name, (None, 3, None))
    if screen.shape[2] < 2:
        raise ValueError(
            f"{name}: expected shape (K, 3, C) with C >= 2 (x, y first), got {tuple(screen.shape)}"
        )
    return screen


def crossing(p_in, d_in, w_in, p_out, d_out, w_out):
    """Provided: where the edge from an inside to an outside vertex meets the plane ``d = 0``,
    and that point's weights. Always interpolated from the inside vertex: the two triangles
    sharing the edge then compute the same point bit for bit (no cracks along the cut)."""
    t = d_in / (d_in - d_out)
    return p_in + t[:, None] * (p_out - p_in), w_in + t[:, None] * (w_out - w_in)


def fragment_depth(screen, triangle, bary, depth_bits: int):
    """Provided: per fragment, (depth to pack, in front of the far plane).

    Interpolated as offsets from corner 0 (``a0 + b1 (a1 - a0) + b2 (a2 - a0)``): a triangle
    at constant depth gets exactly that depth at every pixel, so coplanar triangles facing
    the camera tie exactly and the id decides. z_ndc and 1/w are both linear in screen space.
    32 bits: the view depth ``w = 1 / (1/w)``, which a float holds with the same relative
    precision at every distance. 24 bits: the window depth ``(z_ndc + 1) / 2`` in [0, 1] of a
    classic depth buffer, whose resolution is crowded near the near plane.
    """
    v = screen[triangle]
    b1, b2 = bary[:, 1], bary[:, 2]

    def lerp(a):
        return a[:, 0] + b1 * (a[:, 1] - a[:, 0]) + b2 * (a[:, 2] - a[:, 0])

    z_ndc = lerp(v[..., 2])
    depth = 1 / lerp(v[..., 3]) if depth_bits == 32 else z_ndc * 0.5 + 0.5
    return depth, z_ndc <= 1


def face_normals(mesh: Mesh):
    """Provided: (F, 3) unnormalised face normals ``(v1 - v0) x (v2 - v0)`` (length: twice
    the area)."""
    tri = mesh.triangles()
    return torch.linalg.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])


def traced_hits(trace, origins, directions, t_min, t_max):
    """Provided: call a tracer, check what comes back: ``(t, triangle)`` on the rays' device."""
    hits = trace(origins, directions, t_min, t_max)
    t, triangle = getattr(hits, "t", None), getattr(hits, "triangle", None)
    n = origins.shape[0]
    if (
        not isinstance(t, torch.Tensor)
        or not isinstance(triangle, torch.Tensor)
        or t.shape != (n,)
        or triangle.shape != (n,)
    ):
        raise TypeError(
            f"trace: expected a result with t ({n},) and triangle ({n},) "
            f"tensors, got {type(hits).__name__}"
        )
    return t.to(origins.device), triangle.to(origins.device, torch.int64)


def sun_direction(light_direction, like):
    """Provided: the (3,) light direction, checked and normalised, in ``like``'s dtype."""
    check_tensor(light_direction, "light_direction", (3,), like=like)
    return normalized(light_direction.to(like.dtype))
