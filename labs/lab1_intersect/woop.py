"""Task 3: Woop's unit-triangle test: ``woop_precompute`` (the affine map of each triangle to
the unit triangle, once per triangle) and ``woop_unit`` (rays against it, row by row).
"""

from __future__ import annotations

import math

import torch

from course.core.raymath import check_inputs, cross, dot, masked_result
from course.given.lab1 import affine_row


def woop_precompute(v0, v1, v2):
    """The affine map that takes each triangle to the unit triangle (Woop 2004).

    v0, v1, v2: (..., 3) float. Returns ``(..., 3, 4)`` of the same dtype: rows
    ``[r_i | c_i]`` with ``x' = r_i . x + c_i`` such that ``v0 -> (0, 0, 0)``,
    ``v1 -> (1, 0, 0)``, ``v2 -> (0, 1, 0)`` and ``v0 + n -> (0, 0, 1)`` for the unit normal
    ``n = e1 x e2 / |e1 x e2|`` (so z' is the signed distance to the plane). It is the
    inverse of the matrix with columns ``[e1 e2 n]``, whose rows are
    ``(e2 x n) / |e1 x e2|``, ``(n x e1) / |e1 x e2|`` and ``n``; then ``c_i = -r_i . v0``.

    Computed in float64 and rounded once (it runs once per triangle, offline). A
    degenerate triangle (``e1 x e2 == 0``) gets the zero transform, which every ray misses
    (``t = -0 / 0`` is NaN).

    Hints: do the arithmetic on ``v0.double()`` etc. and ``.to(v0.dtype)`` at the end;
    ``rows @ v0[..., None]`` applies three rows at once; ``torch.where`` picks the zero
    transform for degenerate triangles.

    Errors: ValueError or TypeError naming ``v0``, ``v1`` or ``v2`` (wrong shape or dtype).
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    check_inputs({"v0": (v0, (3,)), "v1": (v1, (3,)), "v2": (v2, (3,))})
    raise NotImplementedError("not implemented yet: woop_precompute (task 3)")


def woop_unit(origins, directions, transform, t_min=0.0, t_max=math.inf):
    """Intersect rays with unit triangles given by :func:`woop_precompute` transforms.

    origins, directions: (..., 3) float; transform: (..., 3, 4) float; returns ``(t, u, v)``.

    One row at a time, each with an early exit (on a GPU, a warp skips the rest once
    all its lanes fail; batched, the rejections accumulate in a mask):
    z: ``t = -o'z / d'z``, reject outside ``[t_min, t_max]``;
    x: ``u = o'x + t d'x``, reject outside ``[0, 1]``;
    y: ``v = o'y + t d'y``, reject ``v < 0`` or ``u + v > 1``.

    Accuracy: the transform's offsets are about ``|v0| / |edge|``; far from the origin
    ``r . o + c`` cancels those digits, so the test degrades like ``eps |x| / |edge|``.

    Errors: ValueError or TypeError naming ``origins``, ``directions``, ``transform``,
    ``t_min`` or ``t_max`` (the provided check, as in :func:`intersect_simple`).

    Hints: ``transform[..., 2, :]`` is the z row; the given ``affine_row`` gives
    ``(r . o + c, r . d)`` for one row.
    """
    # Provided: validates the arguments; s: {name: tensor}, the scalars in the kernel's dtype.
    _, s = check_inputs(
        {
            "origins": (origins, (3,)),
            "directions": (directions, (3,)),
            "transform": (transform, (3, 4)),
        },
        {"t_min": t_min, "t_max": t_max},
    )
    raise NotImplementedError("not implemented yet: woop_unit (task 3)")
