"""Task 6: the two-level grid: ``build_two_level_grid``, ``two_level_closest_hit`` (nested
DDA, mailboxing across both levels): the teapot in a stadium.
"""

from __future__ import annotations

import math

import torch

from course.core.types import Mesh, Rays
from course.given.lab2 import (
    COUNTERS,
    add_count,
    as_hits,
    check_mesh,
    check_structure,
    check_trace_inputs,
    check_two_level_knobs,
    expand_ranges,
    grid_resolutions,
    intersect_pairs,
    new_closest,
    new_counters,
    pair_chunks,
    slab_test,
    triangle_bounds,
)
from course.given.lab2_robust import reach

from .grid import build_grid


def build_two_level_grid(
    mesh: Mesh, top_density: float = 1 / 16, density: float = 2.0, min_triangles: int = 16
) -> dict:
    """A two-level (hierarchical) grid: a coarse top grid, and a fine grid in each crowded
    top cell, sized for the triangles it holds (Jevans & Wyvill 1989; Kalojanov et al.
    2011 on GPUs). The answer to the teapot in a stadium.

    mesh: F triangles; top_density: cells per triangle of the top grid (coarse: 1/16);
    density: cells per triangle inside each sub-grid; min_triangles: a top cell with more
    *small* triangles than this gets a sub-grid. Returns a dict on the mesh's device:

    ===================  ===============  =================================================
    ``kind``             ``"grid2"``
    ``lo, hi``           (3,) float       the top grid, exactly as :func:`build_grid` with
    ``resolution``       (3,) int64       ``density=top_density`` builds it (same box,
    ``tri_cell_lo/hi``   (F, 3) int64     resolution and per-triangle boxes of top cells)
    ``cell_start``       (C,) int64       per top cell, the **direct** list (CSR, ascending):
    ``cell_count``       (C,) int64       tested when a ray enters the cell: all its
    ``triangles``        (K,) int64       triangles in a plain cell, only its *big* ones in
                                          a cell with a sub-grid
    ``big``              (F,) bool        a triangle whose bounds are at least one top cell
                                          wide on some axis: never in a sub-grid
    ``sub_of``           (C,) int64       the sub-grid of each top cell, -1 for plain cells
    ``sub_lo, sub_hi``   (S, 3) float     sub-grid boxes: its small triangles' bounds,
                                          clipped to the top cell, padded
    ``sub_resolution``   (S, 3) int64     :func:`grid_resolutions` of the box for its
                                          small triangles at ``density``
    ``sub_cell_base``    (S,) int64       sub-grid ``s``'s cell ``(x, y, z)`` is the global
                                          sub cell ``base[s] + x + rx * (y + ry * z)``
    ``sub_cell_start``   (SC,) int64      per sub cell, its triangles (CSR, ascending)
    ``sub_cell_count``   (SC,) int64
    ``sub_triangles``    (K2,) int64
    ``sub_tri_cell_lo``  (K2, 3) int64    per entry of ``sub_triangles``: the box of cells
    ``sub_tri_cell_hi``  (K2, 3) int64    of its sub-grid that triangle is listed in
    ===================  ===============  =================================================

    1. The top grid: :func:`build_grid` at ``top_density``.
    2. Big triangles (as wide as a top cell) stay in the direct lists: they would fill a
       sub-grid's box (the stadium's floor under the teapot) and defeat it.
    3. A top cell with more than ``min_triangles`` small triangles gets a sub-grid over
       their bounds clipped to the cell, padded like the top grid (relative to the
       sub-grid's own size, plus a few ulps of its coordinates), with the density
       heuristic on its own triangle count: a crowded cell gets many cells, where they
       are needed.
    4. The sub cells' lists: as in :func:`build_grid`, one (entry, sub cell) pair per
       overlap, one stable sort by global sub cell: no loop over cells or triangles.

    Errors (the provided checks): TypeError or ValueError naming ``mesh`` (not a ``Mesh``,
    or a vertex with a NaN or inf coordinate); ValueError naming ``top_density`` or
    ``density`` unless it is a positive number, or ``min_triangles`` unless it is a
    non-negative int.

    Hints: start from your ``build_grid`` at ``top_density``; ``expand_ranges`` and a
    ``bincount`` per top cell give the small triangles of each cell; ``scatter_reduce``
    (amin/amax) their bounds per sub-grid; ``grid_resolutions`` (provided) sizes all
    sub-grids at once; then the (pair, cell) expansion and stable sort of ``build_grid``.
    """
    # Provided: validates the arguments (ValueError naming the argument).
    check_mesh(mesh, finite=True)
    check_two_level_knobs(top_density, density, min_triangles)
    # BEGIN SOLUTION (task 6)
    top = build_grid(mesh, density=top_density)
    device = mesh.device
    lo, hi, res = top["lo"], top["hi"], top["resolution"]
    width = (hi - lo) / res
    tri_lo, tri_hi = triangle_bounds(mesh)
    big = (tri_hi - tri_lo).amax(dim=1) >= width.amin()
    # Each top cell's small triangles, counted per cell.
    entry_cell = torch.repeat_interleave(
        torch.arange(len(top["cell_count"]), device=device), top["cell_count"]
    )
    entry_tri = top["triangles"]
    small = ~big[entry_tri]
    n_small = torch.bincount(entry_cell[small], minlength=len(top["cell_count"]))
    dense = n_small > min_triangles
    sub_of = torch.full_like(n_small, -1)
    dense_cells = dense.nonzero()[:, 0]
    sub_of[dense_cells] = torch.arange(len(dense_cells), device=device)
    # Direct lists: everything in plain cells, the big triangles in dense ones.
    direct = ~dense[entry_cell] | ~small
    cell_count = torch.bincount(entry_cell[direct], minlength=len(top["cell_count"]))
    out = dict(
        top,
        cell_start=torch.cumsum(cell_count, 0) - cell_count,
        cell_count=cell_count,
        triangles=entry_tri[direct],
        kind="grid2",
        big=big,
        sub_of=sub_of,
    )
    # Sub-grid boxes: the bounds of the cell's small triangles, clipped to the cell.
    into_sub = dense[entry_cell] & small
    s, tri = sub_of[entry_cell[into_sub]], entry_tri[into_sub]  # (pairs,), ascending tri per s
    num_sub = len(dense_cells)
    rx, ry = res[0], res[1]
    c = torch.stack((dense_cells % rx, (dense_cells // rx) % ry, dense_cells // (rx * ry)), 1)
    cell_lo, cell_hi = lo + c * width, lo + (c + 1) * width
    inf = torch.full((num_sub, 3), math.inf, dtype=lo.dtype, device=device)
    index = s[:, None].expand(-1, 3)
    box_lo = torch.maximum(inf.scatter_reduce(0, index, tri_lo[tri], "amin"), cell_lo)
    box_hi = torch.minimum((-inf).scatter_reduce(0, index, tri_hi[tri], "amax"), cell_hi)
    eps = torch.finfo(lo.dtype).eps
    pad = 1e-4 * (box_hi - box_lo).amax(dim=1) + 16 * eps * torch.maximum(
        box_lo.abs(), box_hi.abs()
    ).amax(dim=1)
    pad = torch.where(pad > 0, pad, 1e-4 * width.amin())[:, None]
    sub_lo, sub_hi = box_lo - pad, box_hi + pad
    n_sub = torch.bincount(s, minlength=num_sub)
    sub_res = grid_resolutions(sub_hi - sub_lo, n_sub.clamp(min=1), density)
    cells_per_sub = sub_res.prod(dim=1)
    base = torch.cumsum(cells_per_sub, 0) - cells_per_sub
    total = int(cells_per_sub.sum()) if num_sub else 0
    # (entry, sub cell) pairs, as in build_grid, inside each pair's own sub-grid.
    sub_w = (sub_hi - sub_lo) / sub_res
    top_cell = sub_res - 1
    p = pad[s]
    c_lo = torch.minimum(
        torch.floor((tri_lo[tri] - p - sub_lo[s]) / sub_w[s]).long().clamp(min=0), top_cell[s]
    )
    c_hi = torch.minimum(
        torch.floor((tri_hi[tri] + p - sub_lo[s]) / sub_w[s]).long().clamp(min=0), top_cell[s]
    )
    span = c_hi - c_lo + 1
    pair, local = expand_ranges(torch.zeros_like(s), span.prod(dim=1))
    sx, sy = span[pair, 0], span[pair, 1]
    x = c_lo[pair, 0] + local % sx
    y = c_lo[pair, 1] + (local // sx) % sy
    z = c_lo[pair, 2] + local // (sx * sy)
    sp = s[pair]
    cell_id = base[sp] + x + sub_res[sp, 0] * (y + sub_res[sp, 1] * z)
    order = torch.sort(cell_id, stable=True).indices
    sub_count = torch.bincount(cell_id, minlength=total)
    out.update(
        sub_lo=sub_lo,
        sub_hi=sub_hi,
        sub_resolution=sub_res,
        sub_cell_base=base,
        sub_cell_start=torch.cumsum(sub_count, 0) - sub_count,
        sub_cell_count=sub_count,
        sub_triangles=tri[pair[order]],
        sub_tri_cell_lo=c_lo[pair[order]],
        sub_tri_cell_hi=c_hi[pair[order]],
    )
    return out
    # END SOLUTION


def two_level_closest_hit(rays: Rays, mesh: Mesh, grid2: dict, intersect, mailbox: bool = True):
    """Closest hits through a two-level grid: a DDA over the top grid, and in each top cell
    with a sub-grid a nested DDA over it.

    rays: N rays; mesh: the grid's mesh; grid2: from :func:`build_two_level_grid`;
    intersect: the triangle kernel; mailbox: skip triangles known to be tested already.
    Returns ``(Hits, counters)``: ``"steps"`` (top cells plus sub cells visited),
    ``"tests"``, ``"skipped"`` (tests the mailbox avoided), each (N,) int64.

    Per top step, every active ray, in its top cell ``[t_in, t_out]`` (the uniform grid's
    DDA: ``t_in`` is the previous ``t_out``):

    1. tests the cell's direct list;
    2. if the cell has a sub-grid: clips ``[t_in, t_out]`` to the sub-grid's box
       (``slab_test``) and walks it with the same DDA, one sub cell per inner step, until
       a hit lies inside the sub cell's interval, the interval ends, or the walk leaves
       the sub-grid;
    3. ends if the closest hit lies inside ``[.., t_out]`` (``reach(best_t) < t_out``, as
       in the uniform grid), else steps to the next top cell. The sub-grid's clip in 2. runs
       to ``reach(t_out)``: a ray that grazes a crowded cell's corner still walks its sub-grid.

    The mailbox is O(1) per ray, and only skips a test that certainly ran before. A DDA
    is monotone, so a triangle was tested in the previous cell of the *same* walk iff
    that cell lies in its box of cells. At the top level that holds when the previous top
    cell was plain (it tested all its triangles) or the triangle is big (tested from the
    direct list of every top cell); in a sub-grid, also for the previous sub cell of this
    sub-grid's walk (``sub_tri_cell_lo/hi``). A small triangle that straddles two
    crowded top cells may be tested once in each: a repeat, never a miss.

    Contract: the same hits as brute force with ``intersect``, whatever the resolutions.

    Hints: your ``grid_closest_hit`` is the top-level walk; the nested walk is the same
    loop over the rays of crowded cells, with per-ray boxes and resolutions (``sub_lo[s]``,
    ``sub_resolution[s]``); keep a "previous cell was plain" flag per ray for the mailbox.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    check_trace_inputs(rays, mesh, intersect)
    check_structure(grid2, "grid2", "grid2", mesh)
    # BEGIN SOLUTION (task 6)
    n, device = len(rays), rays.device
    closest = new_closest(n, rays.t_min)
    counters = new_counters(n, device, COUNTERS + ("skipped",))
    lo, hi, res = grid2["lo"], grid2["hi"], grid2["resolution"]
    width = (hi - lo) / res
    inv = 1 / rays.directions
    t_enter, t_exit, inside = slab_test(rays.origins, inv, lo, hi, rays.t_min, rays.t_max)
    ray = inside.nonzero()[:, 0]
    o, inv_r, t_end, t_in = rays.origins[ray], inv[ray], t_exit[ray], t_enter[ray]
    start = o + t_in[:, None] * rays.directions[ray]
    cell = torch.minimum(torch.floor((start - lo) / width).long().clamp(min=0), res - 1)
    step = torch.sign(rays.directions[ray]).long()
    prev = torch.full_like(cell, -1)  # the previous top cell (-1: none)
    prev_plain = torch.ones(len(ray), dtype=torch.bool, device=device)  # ... had no sub-grid
    corners = mesh.triangles()
    big = grid2["big"]
    for _ in range(int(res.sum()) + 1):
        if len(ray) == 0:
            break
        boundary = lo + (cell + (step > 0).long()) * width
        t_next = torch.where(step == 0, math.inf, (boundary - o) * inv_r)
        t_out = torch.minimum(t_next.amin(dim=1), t_end)
        cell_id = cell[:, 0] + res[0] * (cell[:, 1] + res[1] * cell[:, 2])
        for owner, k in pair_chunks(grid2["cell_start"][cell_id], grid2["cell_count"][cell_id]):
            tri = grid2["triangles"][k]
            if mailbox:
                seen = (
                    (prev[owner] >= grid2["tri_cell_lo"][tri])
                    & (prev[owner] <= grid2["tri_cell_hi"][tri])
                ).all(dim=1)
                seen &= prev_plain[owner] | big[tri]
                add_count(counters["skipped"], ray[owner[seen]])
                owner, tri = owner[~seen], tri[~seen]
            intersect_pairs(intersect, rays, corners, ray[owner], tri, closest, counters)
        add_count(counters["steps"], ray)
        sub = grid2["sub_of"][cell_id]
        crowded = (sub >= 0).nonzero()[:, 0]
        if len(crowded):
            _walk_sub_grids(
                rays,
                grid2,
                intersect,
                corners,
                closest,
                counters,
                ray[crowded],
                sub[crowded],
                t_in[crowded],
                reach(t_out[crowded]),
                torch.where(prev_plain[crowded, None], prev[crowded], -1),
                mailbox,
            )
        done = (reach(closest["t"][ray]) < t_out) | (t_out >= t_end)
        axis = t_next.argmin(dim=1, keepdim=True)
        prev, prev_plain = cell, sub < 0
        cell = cell.scatter_add(1, axis, step.gather(1, axis))
        t_in = t_out
        done |= ((cell < 0) | (cell >= res)).any(dim=1)
        keep = ~done
        ray, o, inv_r, t_end, t_in = ray[keep], o[keep], inv_r[keep], t_end[keep], t_in[keep]
        cell, prev, prev_plain, step = cell[keep], prev[keep], prev_plain[keep], step[keep]
    return as_hits(closest), counters
    # END SOLUTION


# BEGIN SOLUTION
def _walk_sub_grids(
    rays, grid2, intersect, corners, closest, counters, ray, sub, t_lo, t_hi, prev_top, mailbox
):
    """The nested DDA of :func:`two_level_closest_hit`: rays ``ray`` (k,) walk sub-grids
    ``sub`` (k,) over ``[t_lo, t_hi]`` (their top cell's interval); ``prev_top`` (k, 3):
    the previous top cell if it was plain, else -1."""
    inv_all = 1 / rays.directions
    sub_lo, sub_hi = grid2["sub_lo"][sub], grid2["sub_hi"][sub]
    s_in, s_out, hit = slab_test(rays.origins[ray], inv_all[ray], sub_lo, sub_hi, t_lo, t_hi)
    keep = hit.nonzero()[:, 0]
    ray, sub, s_in, s_out, prev_top = ray[keep], sub[keep], s_in[keep], s_out[keep], prev_top[keep]
    lo, hi = sub_lo[keep], sub_hi[keep]
    res = grid2["sub_resolution"][sub]
    base = grid2["sub_cell_base"][sub]
    width = (hi - lo) / res
    o, inv = rays.origins[ray], inv_all[ray]
    start = o + s_in[:, None] * rays.directions[ray]
    cell = torch.minimum(torch.floor((start - lo) / width).long().clamp(min=0), res - 1)
    step = torch.sign(rays.directions[ray]).long()
    prev = torch.full_like(cell, -1)
    bound = int(res.sum(dim=1).max()) + 1 if len(ray) else 0
    for _ in range(bound):
        if len(ray) == 0:
            break
        boundary = lo + (cell + (step > 0).long()) * width
        t_next = torch.where(step == 0, math.inf, (boundary - o) * inv)
        t_out = torch.minimum(t_next.amin(dim=1), s_out)
        cell_id = base + cell[:, 0] + res[:, 0] * (cell[:, 1] + res[:, 1] * cell[:, 2])
        for owner, k in pair_chunks(
            grid2["sub_cell_start"][cell_id], grid2["sub_cell_count"][cell_id]
        ):
            tri = grid2["sub_triangles"][k]
            if mailbox:
                here = (
                    (prev[owner] >= grid2["sub_tri_cell_lo"][k])
                    & (prev[owner] <= grid2["sub_tri_cell_hi"][k])
                ).all(dim=1)
                before = (
                    (prev_top[owner] >= grid2["tri_cell_lo"][tri])
                    & (prev_top[owner] <= grid2["tri_cell_hi"][tri])
                ).all(dim=1)
                seen = here | before
                add_count(counters["skipped"], ray[owner[seen]])
                owner, tri = owner[~seen], tri[~seen]
            intersect_pairs(intersect, rays, corners, ray[owner], tri, closest, counters)
        add_count(counters["steps"], ray)
        done = (reach(closest["t"][ray]) < t_out) | (t_out >= s_out)
        axis = t_next.argmin(dim=1, keepdim=True)
        prev = cell
        cell = cell.scatter_add(1, axis, step.gather(1, axis))
        done |= ((cell < 0) | (cell >= res)).any(dim=1)
        keep = ~done
        ray, o, inv, s_out, prev_top = ray[keep], o[keep], inv[keep], s_out[keep], prev_top[keep]
        lo, res, base, width = lo[keep], res[keep], base[keep], width[keep]
        cell, prev, step = cell[keep], prev[keep], step[keep]


# END SOLUTION
