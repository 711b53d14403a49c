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
    raise NotImplementedError("not implemented yet: layout_indexed (task 5)")


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
    raise NotImplementedError("not implemented yet: layout_float4 (task 5)")


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
    raise NotImplementedError("not implemented yet: layout_woop (task 5)")


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
    raise NotImplementedError("not implemented yet: intersect_layout (task 5)")
