"""Lab 2's robust traversal: how far a walk must look past the closest hit so far.

Given code, not exercises. Every walk of Lab 2 promises the hit brute force finds with the
same ``intersect``: the same triangle, and among equal ``t`` the lowest index. Rays aimed at
a vertex or an edge hit several triangles at the same true ``t``; their computed ``t``
differ by rounding, and a box, split plane or cell boundary through that point is crossed
at a computed ``t`` that rounds on its own. A walk that culls a node whose entry is beyond
the closest hit, or stops at a cell or leaf whose exit lies past it, compares two rounded
numbers: it may drop the triangle brute force picks (a smaller computed ``t``, or the same
``t`` and a lower index). Ize 2013 ("Robust BVH Ray Traversal") and pbrt-v4 make the box
test itself conservative (:func:`course.given.lab2_blocks.slab_test` scales its far
distance by ``1 + 2 gamma(3)``); :func:`reach` does the same for the other side of those
comparisons, the closest hit's ``t``.
"""

from __future__ import annotations

import torch

from course.core.raymath import gamma

HIT_ULPS = 16
"""The error a walk allows the ``intersect`` kernel's ``t``, in units of ``eps``.

Lab 1's kernels (Möller–Trumbore, watertight) round a well-conditioned hit's ``t`` by a few
``eps`` (relative); the float64 kernel the grader passes, rounded once, by half an ``eps``.
A larger allowance only makes a walk visit the nodes or cells whose entry lies within that
relative distance of the hit: ``bench/results/cpu-2cores/lab2_robust/`` measures the cost."""


def hit_slack(dtype: torch.dtype) -> float:
    """The relative slack of :func:`reach` for ``dtype``: the slab test's ``2 gamma(3)``
    (a box or plane crossing rounded) plus ``HIT_ULPS eps`` (the hit's ``t`` rounded)."""
    return 2 * gamma(3, dtype) + HIT_ULPS * torch.finfo(dtype).eps


def reach(t: torch.Tensor) -> torch.Tensor:
    """Provided: the farthest computed entry ``t`` of a box, cell or leaf that may still hold
    a hit brute force prefers to a hit at ``t`` (the closest so far).

    t: any shape, float (``inf`` where nothing was hit yet). Returns ``t + |t| s`` with
    ``s = hit_slack(t.dtype)``; ``inf`` stays ``inf``. A walk keeps a node whose entry is
    ``<= reach(best_t)`` (``slab_test(..., t_hi=torch.minimum(t_max, reach(best_t)))``), and
    ends at a cell or leaf only if ``reach(best_t) < t_exit``: a node entered or a cell
    left at the hit's own ``t``, give or take rounding, is still visited, so a tie at a
    vertex or an edge goes to the lowest triangle index, as in brute force.
    """
    return t + t.abs() * hit_slack(t.dtype)
