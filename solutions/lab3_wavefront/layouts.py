"""Task 5: where the triangles live: ``layout_indexed``, ``layout_float4``, ``layout_woop`` and
``intersect_layout`` (brute force over a layout, in tiles).
"""

from __future__ import annotations

import math

import torch

from course.core.types import Hits, Mesh
from course.given.lab3 import (
    LAYOUTS,
    check_layout_inputs,
    check_mesh,
    check_order,
    dot,
    float_as_index,
    index_as_float,
    normalize,
    pair_tiles,
)


# BEGIN SOLUTION
def _bytes(*tensors) -> int:
    return sum(x.numel() * x.element_size() for x in tensors)


# END SOLUTION


def layout_indexed(mesh: Mesh) -> dict:
    """Indexed geometry: shared vertices and an index triple per triangle.

    mesh: F triangles. Returns ``{"kind": "indexed", "vertices": (V, 3) the mesh's,
    "faces": (F, 3) int32, "bytes_per_triangle": float}`` (vertex bytes + index bytes, per
    triangle). Compact (a vertex is stored once, shared by ~6 triangles of a closed mesh),
    but a triangle test first gathers three vertices through the indices: dependent loads.

    Errors: ValueError or TypeError naming ``mesh`` unless it is a ``Mesh``.

    Hints: ``x.numel() * x.element_size()`` is a tensor's size in bytes.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    check_mesh(mesh)
    # BEGIN SOLUTION (task 5)
    faces = mesh.faces.to(torch.int32)
    return {
        "kind": "indexed",
        "vertices": mesh.vertices,
        "faces": faces,
        "bytes_per_triangle": _bytes(mesh.vertices, faces) / mesh.num_faces,
    }
    # END SOLUTION


def layout_float4(mesh: Mesh, order: torch.Tensor | None = None) -> dict:
    """Three float4 per triangle, the triangle's index in the w components.

    mesh: F triangles; order: (F,) int64 permutation: slot ``k`` holds triangle
    ``order[k]`` (a BVH stores its leaves' triangles contiguously in leaf order); None for
    ``arange(F)``. Returns ``{"kind": "float4", "triangles": (F, 3, 4) the mesh's dtype,
    "bytes_per_triangle": float}``: ``triangles[k, j, :3]`` is corner ``j`` of triangle
    ``order[k]``, and every ``triangles[k, j, 3]`` holds ``order[k]`` bit for bit
    (``index_as_float``). One aligned 16-byte load per corner and no indirection; the index
    in w tells a hit's original triangle after reordering.

    Errors: ValueError or TypeError naming ``mesh`` unless it is a ``Mesh``, and naming
    ``order`` unless it is None or a permutation of ``range(F)``.

    Hints: ``mesh.triangles()`` gives (F, 3, 3) corners; ``torch.cat`` the w column.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    check_mesh(mesh)
    index = check_order(order, mesh)  # noqa: F841 (the permutation; arange(F) for None)
    # BEGIN SOLUTION (task 5)
    corners = mesh.triangles()[index]  # (F, 3, 3)
    w = index_as_float(index, mesh.dtype)[:, None, None].expand(-1, 3, 1)
    triangles = torch.cat((corners, w), dim=2).contiguous()
    return {
        "kind": "float4",
        "triangles": triangles,
        "bytes_per_triangle": _bytes(triangles) / mesh.num_faces,
    }
    # END SOLUTION


def layout_woop(mesh: Mesh) -> dict:
    """Woop's unit-triangle test: a precomputed affine map per triangle (3 float4 rows).

    mesh: F triangles. Returns ``{"kind": "woop", "transforms": (F, 3, 4) the mesh's dtype,
    "bytes_per_triangle": float}``. ``M = transforms[f]`` maps world space to the triangle's
    space: ``M [v0, 1] = (0, 0, 0)``, ``M [v1, 1] = (1, 0, 0)``, ``M [v2, 1] = (0, 1, 0)``.
    It is the inverse of the affine frame with columns ``e1 = v1 - v0``, ``e2 = v2 - v0``,
    the **unit** normal ``normalize(e1 x e2)`` and the origin ``v0``: ``M[:, :3] = F^-1``,
    ``M[:, 3] = -F^-1 v0``. Compute it in float64, then cast. A degenerate triangle (zero
    area) has no such map: fill its rows with NaN, which no ray hits.

    The test then costs two transformed coordinates and a division (the lecture: mul 20,
    add 20, div 1) and needs no vertices at all: 48 bytes in float32, like float4.

    Errors: ValueError or TypeError naming ``mesh`` unless it is a ``Mesh``.

    Hints: ``torch.linalg.inv_ex`` returns ``info != 0`` for singular frames.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    check_mesh(mesh)
    # BEGIN SOLUTION (task 5)
    c = mesh.triangles().to(torch.float64)
    e1, e2 = c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]
    # Columns e1, e2 and the unit normal: z' is then the signed distance from the plane in
    # world units, which keeps the third row as well conditioned as the ray's coordinates.
    frame = torch.stack((e1, e2, normalize(torch.linalg.cross(e1, e2, dim=-1))), dim=2)
    inverse, info = torch.linalg.inv_ex(frame)
    # A degenerate triangle has no unit-triangle map: NaN rows, which no ray hits.
    inverse = torch.where((info == 0)[:, None, None], inverse, math.nan)
    translation = -(inverse @ c[:, 0, :, None])
    transforms = torch.cat((inverse, translation), dim=2).to(mesh.dtype).contiguous()
    return {
        "kind": "woop",
        "transforms": transforms,
        "bytes_per_triangle": _bytes(transforms) / mesh.num_faces,
    }
    # END SOLUTION


# BEGIN SOLUTION
def _moller_trumbore(o, d, v0, v1, v2):
    e1, e2 = v1 - v0, v2 - v0
    p = torch.linalg.cross(d, e2, dim=-1)
    det = dot(e1, p)
    s = o - v0
    q = torch.linalg.cross(s, e1, dim=-1)
    u, v, t = dot(s, p) / det, dot(d, q) / det, dot(e2, q) / det
    return t, u, v, det != 0


def _woop(o, d, m):
    ox = dot(m[..., 0, :3], o) + m[..., 0, 3]
    oy = dot(m[..., 1, :3], o) + m[..., 1, 3]
    oz = dot(m[..., 2, :3], o) + m[..., 2, 3]
    dx, dy, dz = dot(m[..., 0, :3], d), dot(m[..., 1, :3], d), dot(m[..., 2, :3], d)
    t = -oz / dz
    return t, ox + t * dx, oy + t * dy, dz != 0


# END SOLUTION


def intersect_layout(
    layout: dict,
    origins: torch.Tensor,
    directions: torch.Tensor,
    t_min: torch.Tensor,
    t_max: torch.Tensor,
) -> Hits:
    """Closest hits of N rays against every triangle of a layout (brute force, in tiles).

    layout: from ``layout_indexed``/``layout_float4``/``layout_woop``; origins, directions:
    (N, 3); t_min, t_max: (N,), of the layout's dtype. Returns ``Hits``: the nearest hit in
    ``[t_min, t_max]`` per ray, ``triangle`` the **original** triangle index (for float4:
    read from w with ``float_as_index``), among equal ``t`` the lowest index; ``t = inf``,
    ``triangle = -1``, ``u = v = 0`` for misses; NaN/inf rays miss.

    * indexed: gather the corners ``vertices[faces]``, then Möller–Trumbore;
    * float4: Möller–Trumbore on ``triangles[..., :3]``;
    * woop: ``o' = M [o, 1]``, ``d' = M [d, 0]``, ``t = -o'_z / d'_z``, ``(u, v) = (o'_x + t
      d'_x, o'_y + t d'_y)``; a hit iff ``u, v >= 0`` and ``u + v <= 1`` (``d'_z = 0``:
      parallel, no hit).

    Tiles of at most ``MEMORY_BUDGET_BYTES / BYTES_PER_PAIR`` (ray, triangle) pairs:
    ``pair_tiles(N, F)`` yields them.

    Errors (the provided check): ValueError or TypeError naming ``layout`` (not a layout of
    a kind in ``LAYOUTS``), ``origins``, ``directions``, ``t_min`` or ``t_max``.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    kind, f = check_layout_inputs(  # noqa: RUF059 (the layout's kind and F, for your code)
        layout, origins, directions, t_min, t_max
    )
    # BEGIN SOLUTION (task 5)
    like = layout[LAYOUTS[kind]]
    n = origins.shape[0]
    best = Hits.miss(n, dtype=like.dtype, device=like.device)
    valid = torch.isfinite(origins).all(1) & torch.isfinite(directions).all(1)
    pairs = ((rows, cols) for rows, tiles in pair_tiles(n, f) for cols in tiles)
    for rows, cols in pairs:
        o, d = origins[rows, None], directions[rows, None]
        if kind == "woop":
            t, u, v, ok = _woop(o, d, layout["transforms"][None, cols])
            index = torch.arange(f, device=like.device)[cols]
        elif kind == "float4":
            tri = layout["triangles"][None, cols]
            t, u, v, ok = _moller_trumbore(o, d, tri[..., 0, :3], tri[..., 1, :3], tri[..., 2, :3])
            index = float_as_index(layout["triangles"][cols, 0, 3])  # the w word
        else:
            c = layout["vertices"][layout["faces"][cols].long()][None]
            t, u, v, ok = _moller_trumbore(o, d, c[..., 0, :], c[..., 1, :], c[..., 2, :])
            index = torch.arange(f, device=like.device)[cols]
        hit = (
            ok
            & valid[rows, None]
            & (u >= 0)
            & (v >= 0)
            & (u + v <= 1)
            & (t >= t_min[rows, None])
            & (t <= t_max[rows, None])
        )
        t = torch.where(hit, t, math.inf)
        # Nearest per ray; among equal t the lowest triangle index (as brute force).
        key = torch.where(hit, index[None].expand_as(t), torch.iinfo(torch.int64).max)
        nearest = t.amin(dim=1, keepdim=True)
        j = torch.where(t == nearest, key, torch.iinfo(torch.int64).max).argmin(dim=1, keepdim=True)
        tb, ib = t.gather(1, j)[:, 0], index[j[:, 0]]
        better = (tb < best.t[rows]) | (
            (tb == best.t[rows]) & (tb < math.inf) & (ib < best.triangle[rows])
        )
        best.t[rows] = torch.where(better, tb, best.t[rows])
        best.triangle[rows] = torch.where(better, ib, best.triangle[rows])
        best.u[rows] = torch.where(better, u.gather(1, j)[:, 0], best.u[rows])
        best.v[rows] = torch.where(better, v.gather(1, j)[:, 0], best.v[rows])
    return best
    # END SOLUTION
