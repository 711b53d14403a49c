"""Task 2: ``edge_functions``, ``bounding_boxes`` and ``coverage``: which pixel centres a
triangle covers, with the top-left fill rule and back-face culling.
"""

from __future__ import annotations

import torch

from course.given.lab6 import check_screen, check_size


def edge_functions(tri, px, py):
    """The three edge functions of triangles at points.

    tri: (..., 3, C) float screen positions (x, y first; C >= 2); px, py: (...) float
    points (broadcast with ``tri``'s leading dimensions). Returns (..., 3): ``e0 = E_12(p)``,
    ``e1 = E_20(p)``, ``e2 = E_01(p)`` with the edge function of the edge a -> b

        E_ab(p) = (p_x - a_x) (b_y - a_y) - (p_y - a_y) (b_x - a_x),

    twice the signed area of (a, b, p). Positive on the inside of a triangle with positive
    area ``E_12(v0)`` (a front face, see the lab's conventions); ``e_i / (e0 + e1 + e2)``
    are the screen-space barycentrics of p.

    Accuracy contract: **consistent**. ``E_ab`` is evaluated from the lexicographically
    smaller endpoint (by x, then y) and negated when that is b, so the two triangles sharing
    an edge compute exactly opposite values (``E_ba = -E_ab`` bit for bit): a pixel centre
    can never be inside both or neither because of rounding, only by the fill rule.

    Hints: ``tri[..., [1, 2, 0], :2]`` and ``tri[..., [2, 0, 1], :2]`` are the start and end
    corners of the three edges; ``px[..., None]`` broadcasts a point against them;
    ``torch.where`` picks the reference endpoint and the sign.
    """
    raise NotImplementedError("not implemented yet: edge_functions (task 2)")


def bounding_boxes(screen, width: int, height: int):
    """The pixels whose centres a triangle could cover, clamped to the screen.

    screen: (K, 3, C) float (x, y first); width, height: the viewport. Returns (K, 4) int64
    ``[col_begin, row_begin, col_end, row_end]``, half-open: columns ``col_begin <= col <
    col_end``. Pixel ``col`` qualifies when its centre ``col + 0.5`` lies in ``[x_min, x_max]``:
    ``col_begin = ceil(x_min - 0.5)``, ``col_end = floor(x_max - 0.5) + 1``, both clamped
    to ``[0, width]`` (rows likewise). A triangle off screen, or with a NaN/inf x or y,
    gets an empty box (``begin == end``). Only x and y are read: further columns (``z_ndc``,
    ``1/w``) play no part, even NaN.

    Clamping is what makes huge triangles cheap: a triangle 1e6 pixels across costs at
    most ``width * height`` fragments. (Clamp the floats before converting: ``1e30`` or
    NaN do not fit an int64.)

    Errors: ValueError or TypeError naming ``screen`` (not a (K, 3, C) float tensor with C
    >= 2); ValueError naming ``width`` / ``height`` unless they are positive ints <= 32768.

    Hints: ``xy.amin(1)``, ``xy.amax(1)``; clamp the floats to ``[-1, size + 1]``, then
    ``torch.ceil``/``torch.floor`` and ``.to(torch.int64)``; ``torch.minimum``/``maximum``
    with a ``tensor([width, height])`` clamp both axes at once.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    check_screen(screen)
    check_size(width, height)
    raise NotImplementedError("not implemented yet: bounding_boxes (task 2)")


def _top_left(xy, positive):
    """(K, 3) bool: whether edge i (opposite corner i, a -> b as in ``edge_functions``) is a
    top or left edge of its triangle. For positive area (counter-clockwise on screen, y
    down): left edges run downwards (``b_y > a_y``), top edges are horizontal and run to
    the left (``b_x < a_x``). For negative area the edges run the other way round.

    Write this function for ``coverage``.
    """
    raise NotImplementedError("not implemented yet: _top_left (task 2)")


def coverage(screen, width: int, height: int, cull_backfaces: bool = False):
    """Every (triangle, pixel) pair whose pixel centre lies inside the triangle.

    screen: (K, 3, C) float screen positions (x, y first; e.g. ``to_screen``'s output);
    width, height: the viewport; cull_backfaces: drop triangles of negative area (seen from
    behind). Returns ``(triangle, pixel, bary)``: triangle (N,) int64 indices into
    ``screen``, pixel (N,) int64 ``row * width + col``, bary (N, 3) the screen-space
    barycentrics ``e_i / (e0 + e1 + e2)`` at the pixel centre (same dtype as ``screen``).
    Fragments come grouped by triangle, in increasing triangle order. Only x and y are
    read: further columns (``z_ndc``, ``1/w``) play no part, even NaN.

    1. Per triangle: its area ``E_12(v0)``; zero-area and non-finite triangles (a NaN or
       inf corner) cover nothing, nor do back faces (area < 0) when culling. A finite
       triangle whose area overflows the dtype (corners beyond about 1e19 in float32) may
       be drawn or not: no grader asks.
    2. Enumerate each triangle's ``bounding_boxes`` as fragments, without a Python loop:
       ``counts = box width * height``, ``triangle = repeat_interleave(arange(K), counts)``,
       the fragment's rank inside its box gives its column and row.
    3. Inside test with the **top-left rule**: flip the edge functions of a negative-area
       triangle, then a pixel centre is inside when every edge has ``e > 0``, or ``e == 0``
       on a top or left edge (see ``_top_left``). A centre exactly on an edge shared by two
       triangles is thus covered by exactly one of them (with ``e >= 0`` by both: double
       blending and double counting; with ``e > 0`` by neither: cracks).

    Errors: ValueError or TypeError naming ``screen`` (not a (K, 3, C) float tensor with C
    >= 2); ValueError naming ``width`` / ``height`` unless they are positive ints <= 32768.

    Hints: ``edge_functions(xy, v0[:, 0], v0[:, 1])[:, 0]`` is the area of every triangle;
    ``torch.repeat_interleave(torch.arange(K), counts)`` and ``torch.cumsum`` enumerate the
    boxes; ``rank % box_width`` and ``rank // box_width`` give column and row.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    check_screen(screen)
    check_size(width, height)
    raise NotImplementedError("not implemented yet: coverage (task 2)")
