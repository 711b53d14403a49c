"""Task 1: the uniform grid: ``grid_resolution``, ``build_grid``, ``grid_closest_hit``
(3D DDA, mailboxing, the cell-interval test).
"""

from __future__ import annotations

import math

import torch

from course.core.types import Mesh, Rays
from course.given.lab2 import (
    COUNTERS,
    add_count,
    as_hits,
    check_grid_inputs,
    check_mesh,
    check_resolution,
    check_structure,
    check_trace_inputs,
    expand_ranges,
    intersect_pairs,
    new_closest,
    new_counters,
    pair_chunks,
    slab_test,
    triangle_bounds,
)
from course.given.lab2_robust import reach


def grid_resolution(
    extent, num_triangles: int, density: float = 2.0, max_cells: int = 2**22
) -> tuple[int, int, int]:
    """Cells per axis for a grid over a box of size ``extent``: the classic heuristic.

    extent: 3 non-negative numbers (a sequence or a (3,) tensor), the box's size;
    num_triangles: N >= 1; density: lambda > 0, cells per triangle; max_cells: a cap.
    Returns ``(rx, ry, rz)``, Python ints >= 1.

    Aim for about ``min(lambda N, max_cells)`` cells (the rounding may go a little past
    either) that are as close to cubes as possible: with ``k`` cells per unit length,
    ``r_i = round(k * extent_i)`` and ``k = (min(lambda N, max_cells) / prod extent_i) **
    (1/3)``. A thin axis (``k * extent_i < 1``, e.g.
    a flat scene) gets one cell and drops out: solve for ``k`` again over the other axes
    (``k = (lambda N / prod of their extents) ** (1/d)`` for ``d`` remaining axes).

    Errors (the provided check): ValueError naming ``extent`` unless it is 3 finite
    non-negative numbers, ``num_triangles`` unless it is an int >= 1, or ``density`` unless
    it is a positive number.

    Hints: Plain Python: ``math.prod`` and a loop that drops thin axes (at most three
    rounds).
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    extent = check_grid_inputs(extent, num_triangles, density)  # as 3 Python floats
    raise NotImplementedError("not implemented yet: grid_resolution (task 1)")


def build_grid(mesh: Mesh, resolution=None, density: float = 2.0) -> dict:
    """A uniform grid over the mesh, with one triangle list per cell (CSR layout).

    mesh: F triangles; resolution: ``(rx, ry, rz)`` cells, or None for
    ``grid_resolution(hi - lo, F, density)``. Returns a dict on the mesh's device:

    ==============  ===================  ===============================================
    ``kind``        ``"grid"``
    ``lo, hi``      (3,) float           the grid's box: the scene bounds, padded
    ``resolution``  (3,) int64           ``(rx, ry, rz)``; cell ``(x, y, z)`` has the
                                         linear index ``x + rx * (y + ry * z)``
    ``cell_start``  (C,) int64           cell ``c``'s triangles are ``triangles[
    ``cell_count``  (C,) int64           cell_start[c] : cell_start[c] + cell_count[c]]``
    ``triangles``   (K,) int64           triangle indices, grouped by cell, ascending
                                         within a cell
    ``tri_cell_lo``  (F, 3) int64        the box of cells triangle ``f`` is listed in:
    ``tri_cell_hi``  (F, 3) int64        ``tri_cell_lo[f] <= (x, y, z) <= tri_cell_hi[f]``
    ==============  ===================  ===============================================

    A triangle goes into every cell its bounds overlap: with cell size ``w = (hi - lo) /
    r``, the cells ``floor((tri_lo - pad - lo) / w)`` to ``floor((tri_hi + pad - lo) / w)``
    (clamped to the grid). The small ``pad`` (and the padded box) keeps rounding from
    dropping a triangle that touches a cell boundary, and gives a flat scene a thickness.

    Build without a loop over triangles or cells: the count of cells per triangle, then
    one ``repeat_interleave`` into (triangle, cell) pairs, one stable sort by cell, and a
    ``bincount`` for ``cell_count`` (``cell_start`` is its exclusive prefix sum).

    Errors (the provided checks): TypeError or ValueError naming ``mesh`` (not a ``Mesh``,
    or a vertex with a NaN or inf coordinate); ValueError naming ``resolution`` unless it is
    None or 3 ints >= 1.

    Hints: ``triangle_bounds(mesh)`` gives the bounds; ``expand_ranges(torch.zeros_like(n), n)``
    enumerates ``n[f]`` cells per triangle ``f``; split each local index into x, y, z with ``%``
    and ``//``; ``torch.sort(cell_id, stable=True)`` and ``torch.bincount(cell_id,
    minlength=C)`` make the CSR arrays.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    check_mesh(mesh, finite=True)
    check_resolution(resolution)
    raise NotImplementedError("not implemented yet: build_grid (task 1)")


def grid_closest_hit(rays: Rays, mesh: Mesh, grid: dict, intersect, mailbox: bool = True):
    """Closest hits through a uniform grid: 3D DDA (Amanatides & Woo 1987) per ray.

    rays: N rays; mesh: the grid's mesh; grid: from :func:`build_grid`; intersect: the
    triangle kernel; mailbox: skip a triangle this ray has already tested.
    Returns ``(Hits, counters)`` with counters ``"steps"`` (cells visited), ``"tests"``
    and ``"skipped"`` (tests the mailbox avoided), each (N,) int64.

    1. Clip each ray to the grid's box (``slab_test``): ``[t_enter, t_exit]``; rays that
       miss it are done (the test is conservative: its far distance is widened by
       ``1 + 2 gamma(3)``, so rounding never turns a box hit into a miss). The first cell
       is the one holding ``o + t_enter d``, computed with ``floor`` and clamped into the
       grid (rounding may put the point just outside).
    2. Per axis: ``step = sign(d)`` (0 for ``+0.0`` and ``-0.0``) and ``t_next``, the ``t``
       where the ray crosses the cell's next boundary on that axis: the plane
       ``lo + (cell + 1) w`` when stepping up, ``lo + cell w`` when stepping down, ``inf``
       on an axis with ``step == 0`` (never ``0 * inf = NaN``). Computing ``t_next`` from
       the cell index every step (instead of adding ``t_delta``) keeps long walks from
       drifting off the cell boundaries.
    3. Each iteration, every active ray visits its cell ``[t_in, t_out]``,
       ``t_out = min(t_next, t_exit)``: it tests the cell's triangles and keeps the
       closest hit. A hit only ends the walk inside the cell: a triangle that spans
       several cells can be hit *beyond* this cell, and a nearer triangle may sit in the
       next cell (the classic grid bug is to stop at the first hit). Keep such a hit as
       the best so far, but walk on. Compare through ``reach``: end only if
       ``reach(best_t) < t_out``. A ray through a vertex on a cell boundary (or a cell
       corner) hits triangles of both cells at the same ``t`` give or take rounding, and
       brute force may pick the one in the next cell (ties go to the lowest index).
    4. Then step along the axis of the smallest ``t_next``: ``cell[axis] += step[axis]``.
       A ray that leaves the grid or passes ``t_exit`` is done.

    Mailboxing: a big triangle is listed in many cells, and without a mailbox a ray tests
    it again in each ("7 times the same triangle in 15 voxels"). Exact and O(1) per ray:
    a triangle's cells form a box (``tri_cell_lo..tri_cell_hi``), and a DDA walk, being
    monotone on every axis, never re-enters a box it left; so the triangle was already
    tested iff the ray's *previous* cell lies inside the triangle's box of cells.

    Contract: the same hits as brute force with ``intersect`` (same triangle, same
    ``t``), whatever the resolution. At most ``rx + ry + rz`` steps per ray.

    Errors (the provided checks): TypeError or ValueError naming ``rays`` (not ``Rays``),
    ``mesh`` (not a ``Mesh``, or another dtype or device than the rays), ``intersect`` (not
    callable) or ``grid`` (not a :func:`build_grid` dict of this mesh's device and
    triangles).

    Hints: Keep, per active ray, its index, origin, direction, ``1 / d``, ``t_exit``, cell
    ``(a, 3)`` int64, step ``(a, 3)`` and previous cell ``(a, 3)`` (-1: none), and compact them
    all with ``[keep]`` at the end of each iteration. ``expand_ranges(cell_start[c],
    cell_count[c])`` lists the (ray, triangle) pairs of the cells; ``intersect_pairs`` tests them
    and keeps the closest hits. Loop at most ``rx + ry + rz + 1`` times.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    check_trace_inputs(rays, mesh, intersect)
    check_structure(grid, "grid", "grid", mesh)
    raise NotImplementedError("not implemented yet: grid_closest_hit (task 1)")
