"""Lab 2's building blocks of every structure's build and walk: triangle bounds, the slab
test, range expansion, grid resolutions, (ray, triangle) pair batches, hit and work
counters, and Lab 1's Möller–Trumbore on rows.

Given code, not exercises (imported through :mod:`course.given.lab2`).
"""

from __future__ import annotations

import math

import torch

from course.core.raymath import columns, cross, dot, gamma
from course.core.types import Hits, Mesh, Rays
from course.given.lab2_checks import COUNTERS, MAX_PAIRS


def triangle_bounds(mesh: Mesh) -> tuple[torch.Tensor, torch.Tensor]:
    """Provided: ``(lo, hi)``, each (F, 3): the axis-aligned bounds of every triangle."""
    corners = mesh.triangles()
    return corners.amin(dim=1), corners.amax(dim=1)


def surface_area(lo: torch.Tensor, hi: torch.Tensor) -> torch.Tensor:
    """Provided: ``2 (dx dy + dy dz + dz dx)`` of boxes ``(..., 3)``; 0 for empty boxes
    (``lo > hi``, e.g. the ``+inf``/``-inf`` bounds of an empty bin)."""
    ext = (hi - lo).clamp(min=0).nan_to_num(0.0, posinf=0.0)
    return 2 * (ext[..., 0] * ext[..., 1] + ext[..., 1] * ext[..., 2] + ext[..., 2] * ext[..., 0])


def slab_test(origins, inv_directions, lo, hi, t_lo, t_hi):
    """Provided: rays against axis-aligned boxes (Lab 1's conservative slab test).

    origins, inv_directions: (n, 3) with ``inv_directions = 1 / directions`` (``1/+-0 =
    +-inf``); lo, hi: (n, 3) or (3,) boxes; t_lo, t_hi: (n,). Returns ``(t_near, t_far,
    hit)``, each (n,): the ray's interval inside the box clipped to ``[t_lo, t_hi]``.

    NaN from ``0 * inf`` (a ray in a slab plane with a zero direction component) is
    dropped by ``fmax``/``fmin``; ``t_far`` is scaled by ``1 + 2 gamma(3)`` (Ize 2013) so
    rounding never turns a hit into a miss; NaN/inf rays and empty boxes never hit.
    """
    t0 = (lo - origins) * inv_directions
    t1 = (hi - origins) * inv_directions
    near = torch.minimum(t0, t1)
    far = torch.maximum(t0, t1) * (1 + 2 * gamma(3, t0.dtype))
    t_near = torch.fmax(t_lo, torch.fmax(torch.fmax(near[..., 0], near[..., 1]), near[..., 2]))
    t_far = torch.fmin(t_hi, torch.fmin(torch.fmin(far[..., 0], far[..., 1]), far[..., 2]))
    valid = (
        torch.isfinite(origins).all(-1) & (inv_directions.abs() > 0).all(-1) & (lo <= hi).all(-1)
    )
    return t_near, t_far, (t_near <= t_far) & (t_near < math.inf) & valid


def expand_ranges(first: torch.Tensor, count: torch.Tensor):
    """Provided: every element of the ranges ``[first[i], first[i] + count[i])``.

    first, count: (k,) int64. Returns ``(owner, index)``, each (sum(count),) int64: range
    ``owner[j]`` contains element ``index[j]``; owners ascending, indices ascending within
    each range. The batched form of ``for i: for j in range(first[i], first[i] + count[i])``
    (a cell's triangle list, a leaf's triangles, a node's primitives).
    """
    owner = torch.repeat_interleave(torch.arange(len(count), device=count.device), count)
    offset = torch.cumsum(count, 0) - count
    index = first[owner] + torch.arange(len(owner), device=count.device) - offset[owner]
    return owner, index


def grid_resolutions(
    extent: torch.Tensor, num_triangles: torch.Tensor, density: float = 2.0, max_cells: int = 2**22
) -> torch.Tensor:
    """Provided: Lab 2's ``grid_resolution`` heuristic for many boxes at once (sub-grids).

    extent: (S, 3) float, non-negative box sizes; num_triangles: (S,) int64 >= 1.
    Returns (S, 3) int64 resolutions >= 1: about ``density * n`` cells per box (at most
    ``max_cells``), as close to cubes as possible, one cell on a thin axis.

    The thin-axis rule of ``grid_resolution`` without a loop over boxes: solve for
    ``k`` over the free axes in logs, drop the axes with ``k * extent < 1``, and repeat;
    three rounds suffice (each round drops an axis or changes nothing).
    """
    target = (density * num_triangles.double()).clamp(max=max_cells)
    ext = extent.double()
    free = ext > 0
    k = torch.zeros_like(target)
    for _ in range(3):
        n_free = free.sum(dim=1)
        log_volume = torch.where(free, ext.clamp(min=1e-300).log(), 0.0).sum(dim=1)
        k = torch.where(n_free > 0, ((target.log() - log_volume) / n_free.clamp(min=1)).exp(), 0.0)
        free = free & (ext * k[:, None] >= 1)
    return torch.where(free, torch.round(ext * k[:, None]), 1.0).long().clamp(min=1)


def pair_chunks(first: torch.Tensor, count: torch.Tensor, max_pairs: int = MAX_PAIRS):
    """Provided: :func:`expand_ranges` in chunks of at most ``max_pairs`` elements.

    Yields ``(owner, index)`` like ``expand_ranges(first, count)``, a chunk at a time (a range
    may be split between two chunks), so only one chunk is ever in memory.
    """
    end = torch.cumsum(count, 0)
    total = int(end[-1]) if len(end) else 0
    for p0 in range(0, total, max_pairs):
        j = torch.arange(p0, min(total, p0 + max_pairs), device=count.device)
        owner = torch.searchsorted(end, j, right=True)  # the first range ending after j
        yield owner, first[owner] + j - (end - count)[owner]


def test_ranges(
    intersect,
    rays: Rays,
    corners: torch.Tensor,
    ray: torch.Tensor,
    first: torch.Tensor,
    count: torch.Tensor,
    triangles: torch.Tensor,
    closest: dict,
    counters: dict,
) -> None:
    """Provided: test ray ``ray[i]`` against ``triangles[first[i] : first[i] + count[i]]``
    for every ``i`` (its leaf's list), in chunks, with :func:`intersect_pairs`."""
    for owner, k in pair_chunks(first, count):
        intersect_pairs(intersect, rays, corners, ray[owner], triangles[k], closest, counters)


def new_closest(n: int, like: torch.Tensor) -> dict:
    """Provided: the closest-hit state of ``n`` rays, all missed (dtype/device of ``like``)."""
    miss = Hits.miss(n, dtype=like.dtype, device=like.device)
    return {"t": miss.t, "triangle": miss.triangle, "u": miss.u, "v": miss.v}


def intersect_pairs(
    intersect,
    rays: Rays,
    corners: torch.Tensor,
    ray: torch.Tensor,
    tri: torch.Tensor,
    closest: dict,
    counters: dict,
) -> None:
    """Provided: run ``intersect`` on the (ray, triangle) pairs and keep each ray's closest.

    ray, tri: (P,) int64 indices into ``rays`` and ``corners`` (F, 3, 3). Updates
    ``closest`` (from :func:`new_closest`) in place: a pair replaces a ray's hit when its
    ``t`` is smaller, or equal with a lower triangle index (the brute-force order), and
    adds each ray's number of pairs to ``counters["tests"]``.
    """
    if len(ray) == 0:
        return
    tri_corners = corners[tri]
    t, u, v = intersect(
        rays.origins[ray],
        rays.directions[ray],
        tri_corners[:, 0],
        tri_corners[:, 1],
        tri_corners[:, 2],
        rays.t_min[ray],
        rays.t_max[ray],
    )
    counters["tests"].index_add_(0, ray, torch.ones_like(ray))
    best_t, best_tri = closest["t"], closest["triangle"]
    hit = t < math.inf
    # The nearest t per ray over the old hit and all pairs ...
    nearest = best_t.scatter_reduce(0, ray, t, "amin")
    # ... and among those at that t, the lowest triangle index.
    candidate = hit & (t == nearest[ray])
    big = torch.iinfo(torch.int64).max
    lowest = torch.where((best_t == nearest) & (best_tri >= 0), best_tri, big)
    lowest = lowest.scatter_reduce(0, ray[candidate], tri[candidate], "amin")
    win = candidate & (tri == lowest[ray])
    winners = ray[win]
    closest["t"][winners] = t[win]
    closest["triangle"][winners] = tri[win]
    closest["u"][winners] = u[win]
    closest["v"][winners] = v[win]


def new_counters(n: int, device, names=COUNTERS) -> dict:
    """Provided: zeroed per-ray counters ``{name: (n,) int64}``."""
    return {name: torch.zeros(n, dtype=torch.int64, device=device) for name in names}


def as_hits(closest: dict) -> Hits:
    """Provided: the closest-hit state as ``course.core.types.Hits``."""
    return Hits(t=closest["t"], triangle=closest["triangle"], u=closest["u"], v=closest["v"])


def add_count(counter: torch.Tensor, ray: torch.Tensor) -> None:
    """Provided: ``counter[r] += 1`` for every entry ``r`` of ``ray`` (repeats count)."""
    counter.index_add_(0, ray, torch.ones_like(ray))


def moller_trumbore_rows(o, d, v0, e1, e2, t_min, t_max):
    """Provided: Lab 1's Möller–Trumbore on precomputed edges, one ray per row.

    o, d, v0, e1, e2: (n, 3) float (``e1 = v1 - v0``, ``e2 = v2 - v0``), or each a tuple of
    its three (n,) columns; t_min, t_max: (n,).
    Returns ``(t, u, v, hit)``, each (n,): unmasked ``t, u, v`` and whether they are a hit
    (inside, not parallel, ``t`` in ``[t_min, t_max]``). The parallel test is relative:
    ``|det| <= eps |d| |e1| |e2|`` (max-norms). Every product is written out on (n,)
    columns: elementwise ops that ``torch.compile`` fuses into the kernel of its caller.
    """
    o, d, v0, e1, e2 = (columns(x) for x in (o, d, v0, e1, e2))
    p = cross(d, e2)
    det = dot(e1, p)
    scale = _max_abs(d) * _max_abs(e1) * _max_abs(e2)
    not_parallel = det.abs() > torch.finfo(det.dtype).eps * scale
    inv_det = 1 / det
    s = tuple(a - b for a, b in zip(o, v0))
    u = dot(s, p) * inv_det
    q = cross(s, e1)
    v = dot(d, q) * inv_det
    t = dot(e2, q) * inv_det
    hit = not_parallel & (u >= 0) & (v >= 0) & (u + v <= 1) & (t >= t_min) & (t <= t_max)
    return t, u, v, hit


def _max_abs(a):
    return torch.maximum(torch.maximum(a[0].abs(), a[1].abs()), a[2].abs())
