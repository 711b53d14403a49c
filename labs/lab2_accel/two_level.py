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
    raise NotImplementedError("not implemented yet: build_two_level_grid (task 6)")


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
    raise NotImplementedError("not implemented yet: two_level_closest_hit (task 6)")
