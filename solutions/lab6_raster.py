"""Lab 6: a compute rasterizer.

The lecture's last part: instead of shooting a ray per pixel, project every triangle to the
screen, loop over the pixels of its bounding box, test them with edge functions and resolve
visibility with an atomic minimum on a 64-bit key that packs depth and triangle id. This is
how compute-shader rasterizers (and the visibility buffers of modern engines) work; in
PyTorch the "threads" are the elements of a batch of fragments, and the atomic minimum is
``Tensor.scatter_reduce_(..., reduce="amin")``.

The pipeline, one task per stage::

    vertices --(1) MVP--> clip space --(1) clip--> screen triangles --(2) coverage--> fragments
    fragments --(3) pack (depth | id), atomic min--> visibility buffer (H*W,) int64
    visibility buffer --(4) barycentrics, 1/w--> perspective-correct attributes, shading
    (5) compare with ray-traced primary visibility; trace shadow rays from raster positions

Run the grader for this lab with ``pytest tests/test_lab6_raster.py`` (``-k coverage`` for
one function's tests, ``-s`` to see the measured disagreement with ray tracing). The tests
call your functions on the CPU and, where present, on CUDA: write device- and dtype-agnostic
tensor code, with no Python loop over triangles or pixels (a loop over chunks of triangles
sized by a memory budget is fine).

What the grader asserts
-----------------------
* Edges through pixel centres (grids, fans) and a jittered mesh covering the screen: every
  pixel covered exactly once; each triangle's pixels equal an exact integer top-left rule.
* Suzanne (968 triangles) rasterized vs float64 ray tracing through the same pixel centres:
  at least 99.5% of the ids equal, every other pixel within rounding of an edge.
* Perspective-correct barycentrics within 2e-4 (float32) of the exact ray/plane point.
* The same visibility buffer bit for bit whatever the triangle order and the chunking, and
  on the CPU and CUDA.

Disagreement with ray tracing, z-fighting of 24-bit window depth against 32-bit view depth
and throughput, measured by ``bench/lab6_raster.py``: ``bench/results/cpu-2cores/lab6/``
(GPUs: ``bench/results/<gpu>/lab6/``).

Conventions (those of ``course.core.camera``)
---------------------------------------------
* Clip space is OpenGL's: a point is visible when ``-w <= x, y, z <= w``; the near plane is
  ``z = -w``, which for ``course.core.camera.perspective`` is the plane ``w = near`` (eye-space
  ``z = -near``); ``w`` is the distance in front of the eye along the view axis.
* Screen space: pixel ``(row, col)`` has its centre at ``(x, y) = (col + 0.5, row + 0.5)``;
  row 0 is the top, so ``x = (x_ndc + 1) / 2 * width`` and ``y = (1 - y_ndc) / 2 * height``.
  Pixels are numbered row-major, ``pixel = row * width + col``, like ``primary_rays``.
* Winding: a triangle counter-clockwise seen from the front (``course.core.types.Mesh``) has a
  *positive* signed area ``E_12(v0)`` in screen space (the y flip turns the mathematical sign
  around; see ``edge_functions``).
* Degenerate input is a case, not an error: NaN/inf vertices, zero-area triangles and
  triangles outside the view cover nothing. Malformed input (wrong shape, dtype, device)
  raises ``ValueError``/``TypeError`` naming the argument.
* Positions are float32 or float64; every kernel computes in the dtype of its inputs (the
  per-vertex MVP transform excepted: float64, see ``to_clip_space``). Only element-wise
  operations touch the values that decide coverage and depth, so the CPU and CUDA give
  bit-identical visibility buffers.

Tasks (points)
--------------
1. ``to_clip_space``, ``clip_triangles``, ``to_screen``: MVP, trivial reject, near-plane
   clipping, perspective divide and viewport                                        (4)
2. ``edge_functions``, ``bounding_boxes``, ``coverage``: edge functions, the top-left fill
   rule, back-face culling                                                           (3)
3. ``pack_depth_id``, ``triangle_ids``, ``depth_test``, ``rasterize``: 64-bit
   (depth | id) keys and the atomic-min visibility buffer                            (3)
4. ``perspective_correct``, ``resolve_pixels``, ``rasterize_mesh``, ``interpolate``,
   ``shade``: perspective-correct barycentrics, attributes, flat/smooth shading      (3)
5. ``traced_visibility``, ``world_positions``, ``shadow_epsilon``, ``hybrid_shadows``,
   ``traced_shadows``: raster vs ray-traced visibility, hybrid shadows               (2)
6. End to end: your ``rasterize_mesh`` (tasks 1-4 together) against ray tracing
   (the other tasks are graded on the reference's results of the tasks before them)  (2)

The ray tracer of task 5 is a callable ``trace(origins, directions, t_min, t_max)`` taking
``(N, 3)``, ``(N, 3)``, ``(N,)``, ``(N,)`` tensors and returning an object with ``t (N,)``
(inf where missed) and ``triangle (N,)`` int64 (-1 where missed), e.g. ``course.core.types.Hits``:
any closest-hit tracer (Lab 1's ``closest_hit``, a BVH of Lab 2) fits.
"""

from __future__ import annotations

import math  # noqa: F401  (math.inf, math.isfinite, ...)

import torch

from course.core.camera import Camera, primary_rays  # noqa: F401  (task 5)
from course.core.types import Mesh
from course.given.lab6 import (  # noqa: F401  (given code, for the tasks to use)
    BYTES_PER_FRAGMENT,
    EMPTY,
    ID_BITS,
    ID_MASK,
    any_shape,
    check_screen,
    check_size,
    check_tensor,
    crossing,
    face_normals,
    fragment_depth,
    normalized,
    sun_direction,
    traced_hits,
)

# ---------------------------------------------------------------------------------------
# Task 1: MVP transform, clipping, viewport


def to_clip_space(vertices, mvp):
    """Homogeneous clip coordinates ``mvp @ [x, y, z, 1]`` of every vertex.

    vertices: (V, 3) float32/float64; mvp: (4, 4) float on the same device (e.g.
    ``camera.view_projection()``). Returns (V, 4) ``(x, y, z, w)`` in the vertices' dtype.

    Computed in float64, then rounded once: a mesh 1e5 from the origin with the camera next
    to it cancels about five digits in ``m . [x, y, z, 1]``, which float32 does not have
    (one transform per vertex, so the cost is negligible). Written out element-wise
    (``m[r, 0] * x + m[r, 1] * y + m[r, 2] * z + m[r, 3]``) rather than as a matmul, whose
    summation order differs between BLAS libraries: the CPU and CUDA agree bit for bit.

    Hints: ``m[r, 0] * x`` with a 0-d tensor ``m[r, 0]`` broadcasts over all vertices;
    ``torch.stack(rows, dim=-1)`` assembles the four coordinates.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    check_tensor(vertices, "vertices", (None, 3))
    check_tensor(mvp, "mvp", (4, 4), like=vertices)
    # BEGIN SOLUTION (task 1)
    v = vertices.to(torch.float64)
    m = mvp.to(torch.float64)
    x, y, z = v.unbind(-1)
    rows = [m[r, 0] * x + m[r, 1] * y + m[r, 2] * z + m[r, 3] for r in range(4)]
    return torch.stack(rows, dim=-1).to(vertices.dtype)
    # END SOLUTION


def clip_triangles(clip):
    """Trivially reject triangles outside the view, clip the rest against the near plane.

    clip: (F, 3, 4) float, the clip coordinates of each triangle's corners
    (``to_clip_space(vertices)[faces]``). Returns ``(clipped, source, weights)``:
    clipped (K, 3, 4) the triangles to rasterize, same dtype; source (K,) int64 the input
    triangle each came from, in increasing order; weights (K, 3, 3): ``clipped[k, j] =
    sum_i weights[k, j, i] * clip[source[k], i]`` (the object-space barycentrics of each
    output corner in its source triangle: attributes follow with the same weights).

    1. Reject a triangle with a NaN/inf coordinate, or whose three corners all lie outside
       one of the seven half-spaces ``x < -w``, ``x > w``, ``y < -w``, ``y > w``,
       ``z < -w``, ``z > w`` and ``w <= 0`` (it cannot be visible: the half-spaces are
       those of homogeneous space, so this is exact even for corners behind the eye; the
       view volume has ``w >= |x|, |y|, |z|``, so none of it lies at ``w <= 0`` but its
       apex, the origin).
    2. With ``d = z + w`` (>= 0 on the visible side of the near plane), count the inside
       corners: 3 -> keep the triangle; 1 -> one smaller triangle; 2 -> a quad, two
       triangles. Rotate the corners (a rotation keeps the winding) so that the corner
       alone on its side comes first, call them A, B, C:
       one inside (A): ``(A, AB, AC)``; two inside (B, C): ``(BA, B, C)`` and
       ``(BA, C, CA)``, where ``XY = X + t (Y - X)``, ``t = d_X / (d_X - d_Y)``, is
       computed from the inside corner X (see ``crossing``).
    3. Drop a triangle whose clipped part has a corner at ``w <= 0`` (all its outputs). On
       the visible side of the near plane such a corner has ``z >= |w|``: it lies at or
       beyond the far plane, so no perspective camera makes one (there ``z + w >= 0``
       means ``w >= near > 0``), but degenerate clip coordinates can (a zero matrix,
       every ``w = 0``); dividing by its ``w`` would put inf/NaN or a flipped corner on
       screen. Every output corner has ``w > 0``.
    The near plane must be clipped: a corner behind the eye has ``w < 0`` and its
    perspective divide flips it to the other side of the screen. The other five planes
    need no clipping: the bounding box is clamped to the screen (a "guard band").

    Hints: work on all F triangles at once and select at the end. ``d.gather(1, order)``
    and ``clip.gather(1, order[..., None].expand(F, 3, 4))`` rotate the corners;
    ``torch.nn.functional.one_hot(order, 3)`` gives each rotated corner's weight row; the
    provided ``crossing`` makes the cut points. Build two candidate triangles per input,
    ``(F, 2, 3, 4)``, and a validity mask ``(F, 2)`` (the first is valid when kept, the second
    only for the quad case; neither when one of them has a corner at ``w <= 0``); indexing
    with the mask keeps the input order. ``torch.where`` picks per case; NaNs computed for
    the cases that do not use them are harmless.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    check_tensor(clip, "clip", (None, 3, 4))
    # BEGIN SOLUTION (task 1)
    F = clip.shape[0]
    x, y, z, w = clip.unbind(-1)  # (F, 3) each
    finite = torch.isfinite(clip).all(-1).all(-1)
    outside = ((x < -w).all(-1) | (x > w).all(-1) | (y < -w).all(-1) | (y > w).all(-1)
               | (z < -w).all(-1) | (z > w).all(-1) | (w <= 0).all(-1))
    keep = finite & ~outside
    d = z + w
    inside = d >= 0
    n_in = inside.sum(-1)
    # The corner alone on its side: the inside one of 1, the outside one of 2 (0 when 3 in).
    odd = torch.where((n_in == 1)[:, None], inside, ~inside)
    first = odd.to(torch.int64).argmax(-1)
    order = (first[:, None] + torch.arange(3, device=clip.device)) % 3  # (F, 3)
    rot = clip.gather(1, order[..., None].expand(F, 3, 4))
    dr = d.gather(1, order)
    slots = torch.nn.functional.one_hot(order, 3).to(clip.dtype)  # row j: slot of corner j
    A, B, C = rot.unbind(1)
    dA, dB, dC = dr.unbind(1)
    wA, wB, wC = slots.unbind(1)
    AB, w_AB = crossing(A, dA, wA, B, dB, wB)
    AC, w_AC = crossing(A, dA, wA, C, dC, wC)
    BA, w_BA = crossing(B, dB, wB, A, dA, wA)
    CA, w_CA = crossing(C, dC, wC, A, dA, wA)
    one, two = (n_in == 1)[:, None, None], (n_in == 2)[:, None, None]
    first_tri = torch.where(one, torch.stack([A, AB, AC], 1),
                            torch.where(two, torch.stack([BA, B, C], 1), rot))
    first_w = torch.where(one, torch.stack([wA, w_AB, w_AC], 1),
                          torch.where(two, torch.stack([w_BA, wB, wC], 1), slots))
    tris = torch.stack([first_tri, torch.stack([BA, C, CA], 1)], 1)  # (F, 2, 3, 4)
    weights = torch.stack([first_w, torch.stack([w_BA, wC, w_CA], 1)], 1)
    valid = torch.stack([keep, keep & (n_in == 2)], 1)  # (F, 2): row-major keeps F's order
    behind = valid & ~(tris[..., 3] > 0).all(-1)  # step 3: a corner at w <= 0 (or NaN)
    valid &= ~behind.any(1, keepdim=True)
    source = torch.arange(F, device=clip.device)[:, None].expand(F, 2)
    return tris[valid], source[valid], weights[valid]
    # END SOLUTION


def to_screen(clipped, width: int, height: int):
    """Perspective divide and viewport transform.

    clipped: (K, 3, 4) clip coordinates with ``w > 0`` (the output of ``clip_triangles``);
    width, height: the viewport in pixels. Returns (K, 3, 4) ``(x, y, z_ndc, 1/w)``, same
    dtype: ``x = (x_c / w + 1) * width / 2``, ``y = (1 - y_c / w) * height / 2`` (row 0 at
    the top, pixel centres at ``+0.5``), ``z_ndc = z_c / w`` in [-1, 1] from the near to the
    far plane, and ``1/w``, which varies linearly across the screen (task 4 needs it).

    Hints: ``clipped.unbind(-1)`` gives x, y, z, w of shape (K, 3).
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    check_tensor(clipped, "clipped", (None, 3, 4))
    check_size(width, height)
    # BEGIN SOLUTION (task 1)
    x, y, z, w = clipped.unbind(-1)
    sx = (x / w + 1) * (width / 2)
    sy = (1 - y / w) * (height / 2)
    return torch.stack([sx, sy, z / w, 1 / w], dim=-1)
    # END SOLUTION


# ---------------------------------------------------------------------------------------
# Task 2: edge functions, bounding boxes, coverage with the top-left rule


def edge_functions(tri, px, py):
    """The three edge functions of triangles at points.

    tri: (..., 3, C) float screen positions (x, y first; C >= 2); px, py: (...) float
    points (broadcast with ``tri``'s leading dimensions). Returns (..., 3): ``e0 = E_12(p)``,
    ``e1 = E_20(p)``, ``e2 = E_01(p)`` with the edge function of the edge a -> b

        E_ab(p) = (p_x - a_x) (b_y - a_y) - (p_y - a_y) (b_x - a_x),

    twice the signed area of (a, b, p). Positive on the inside of a triangle with positive
    area ``E_12(v0)`` (a front face, see the module's conventions); ``e_i / (e0 + e1 + e2)``
    are the screen-space barycentrics of p.

    Accuracy contract: **consistent**. ``E_ab`` is evaluated from the lexicographically
    smaller endpoint (by x, then y) and negated when that is b, so the two triangles sharing
    an edge compute exactly opposite values (``E_ba = -E_ab`` bit for bit): a pixel centre
    can never be inside both or neither because of rounding, only by the fill rule.

    Hints: ``tri[..., [1, 2, 0], :2]`` and ``tri[..., [2, 0, 1], :2]`` are the start and end
    corners of the three edges; ``px[..., None]`` broadcasts a point against them;
    ``torch.where`` picks the reference endpoint and the sign.
    """
    # BEGIN SOLUTION (task 2)
    a = tri[..., [1, 2, 0], :2]
    b = tri[..., [2, 0, 1], :2]
    ax, ay, bx, by = a[..., 0], a[..., 1], b[..., 0], b[..., 1]
    px, py = px[..., None], py[..., None]
    swap = (bx < ax) | ((bx == ax) & (by < ay))
    rx, ry = torch.where(swap, bx, ax), torch.where(swap, by, ay)
    sx, sy = torch.where(swap, ax, bx), torch.where(swap, ay, by)
    value = (px - rx) * (sy - ry) - (py - ry) * (sx - rx)
    return torch.where(swap, -value, value)
    # END SOLUTION


def bounding_boxes(screen, width: int, height: int):
    """The pixels whose centres a triangle could cover, clamped to the screen.

    screen: (K, 3, C) float (x, y first); width, height: the viewport. Returns (K, 4) int64
    ``[col_begin, row_begin, col_end, row_end]``, half-open: columns ``col_begin <= col <
    col_end``. Pixel ``col`` qualifies when its centre ``col + 0.5`` lies in ``[x_min, x_max]``:
    ``col_begin = ceil(x_min - 0.5)``, ``col_end = floor(x_max - 0.5) + 1``, both clamped
    to ``[0, width]`` (rows likewise). A triangle off screen, or with a NaN/inf coordinate,
    gets an empty box (``begin == end``).

    Clamping is what makes huge triangles cheap: a triangle 1e6 pixels across costs at
    most ``width * height`` fragments. (Clamp the floats before converting: ``1e30`` or
    NaN do not fit an int64.)

    Hints: ``xy.amin(1)``, ``xy.amax(1)``; clamp the floats to ``[-1, size + 1]``, then
    ``torch.ceil``/``torch.floor`` and ``.to(torch.int64)``; ``torch.minimum``/``maximum``
    with a ``tensor([width, height])`` clamp both axes at once.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    check_screen(screen)
    check_size(width, height)
    # BEGIN SOLUTION (task 2)
    xy = screen[..., :2]
    finite = torch.isfinite(xy).all(-1).all(-1)
    xy = torch.where(finite[:, None, None], xy, torch.zeros_like(xy))
    size = torch.tensor([width, height], device=xy.device)
    bound = size.to(xy.dtype) + 1
    lo = torch.minimum(xy.amin(1).clamp(min=-1.0), bound)
    hi = torch.minimum(xy.amax(1).clamp(min=-1.0), bound)
    begin = torch.ceil(lo - 0.5).to(torch.int64)
    end = (torch.floor(hi - 0.5) + 1).to(torch.int64)
    begin = torch.minimum(begin.clamp(min=0), size)
    end = torch.maximum(torch.minimum(end, size), begin)
    boxes = torch.cat([begin, end], dim=1)
    return torch.where(finite[:, None], boxes, torch.zeros_like(boxes))
    # END SOLUTION


def _top_left(xy, positive):
    """(K, 3) bool: whether edge i (opposite corner i, a -> b as in ``edge_functions``) is a
    top or left edge of its triangle. For positive area (counter-clockwise on screen, y
    down): left edges run downwards (``b_y > a_y``), top edges are horizontal and run to
    the left (``b_x < a_x``). For negative area the edges run the other way round.

    Write this helper for ``coverage``.
    """
    # BEGIN SOLUTION (task 2)
    a = xy[:, [1, 2, 0]]
    b = xy[:, [2, 0, 1]]
    ax, ay, bx, by = a[..., 0], a[..., 1], b[..., 0], b[..., 1]
    forward = (by > ay) | ((by == ay) & (bx < ax))
    backward = (ay > by) | ((ay == by) & (ax < bx))
    return torch.where(positive[:, None], forward, backward)
    # END SOLUTION


def coverage(screen, width: int, height: int, cull_backfaces: bool = False):
    """Every (triangle, pixel) pair whose pixel centre lies inside the triangle.

    screen: (K, 3, C) float screen positions (x, y first; e.g. ``to_screen``'s output);
    width, height: the viewport; cull_backfaces: drop triangles of negative area (seen from
    behind). Returns ``(triangle, pixel, bary)``: triangle (N,) int64 indices into
    ``screen``, pixel (N,) int64 ``row * width + col``, bary (N, 3) the screen-space
    barycentrics ``e_i / (e0 + e1 + e2)`` at the pixel centre (same dtype as ``screen``).
    Fragments come grouped by triangle, in increasing triangle order.

    1. Per triangle: its area ``E_12(v0)``; zero-area and non-finite triangles cover
       nothing, nor do back faces (area < 0) when culling.
    2. Enumerate each triangle's ``bounding_boxes`` as fragments, without a Python loop:
       ``counts = box width * height``, ``triangle = repeat_interleave(arange(K), counts)``,
       the fragment's rank inside its box gives its column and row.
    3. Inside test with the **top-left rule**: flip the edge functions of a negative-area
       triangle, then a pixel centre is inside when every edge has ``e > 0``, or ``e == 0``
       on a top or left edge (see ``_top_left``). A centre exactly on an edge shared by two
       triangles is thus covered by exactly one of them (with ``e >= 0`` by both: double
       blending and double counting; with ``e > 0`` by neither: cracks).

    Hints: ``edge_functions(xy, v0[:, 0], v0[:, 1])[:, 0]`` is the area of every triangle;
    ``torch.repeat_interleave(torch.arange(K), counts)`` and ``torch.cumsum`` enumerate the
    boxes; ``rank % box_width`` and ``rank // box_width`` give column and row.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    check_screen(screen)
    check_size(width, height)
    # BEGIN SOLUTION (task 2)
    xy = screen[..., :2]
    K = xy.shape[0]
    v0 = xy[:, 0]
    area = edge_functions(xy, v0[:, 0], v0[:, 1])[:, 0]
    drawn = torch.isfinite(xy).all(-1).all(-1) & torch.isfinite(area) & (area != 0)
    if cull_backfaces:
        drawn &= area > 0
    boxes = bounding_boxes(screen, width, height)
    box_w = boxes[:, 2] - boxes[:, 0]
    box_h = boxes[:, 3] - boxes[:, 1]
    counts = torch.where(drawn, box_w * box_h, 0)
    triangle = torch.repeat_interleave(torch.arange(K, device=xy.device), counts)
    starts = torch.cumsum(counts, 0) - counts
    rank = torch.arange(triangle.shape[0], device=xy.device) - starts[triangle]
    cols = boxes[triangle, 0] + rank % box_w[triangle]
    rows = boxes[triangle, 1] + rank // box_w[triangle]
    px = cols.to(xy.dtype) + 0.5
    py = rows.to(xy.dtype) + 0.5
    e = edge_functions(xy[triangle], px, py)
    positive = area > 0
    e = torch.where(positive[triangle, None], e, -e)
    top_left = _top_left(xy, positive)[triangle]
    inside = ((e > 0) | ((e == 0) & top_left)).all(-1)
    bary = e / (e[:, 0] + e[:, 1] + e[:, 2])[:, None]
    return triangle[inside], (rows * width + cols)[inside], bary[inside]
    # END SOLUTION


# ---------------------------------------------------------------------------------------
# Task 3: packed (depth | id) keys and the atomic-min visibility buffer


def pack_depth_id(depth, triangle, depth_bits: int = 32):
    """64-bit keys that order fragments by depth, then by triangle id.

    depth: (N,) float, non-negative (nearer is smaller); triangle: (N,) int64 ids in
    ``[0, 2**32)``; depth_bits: 32 or 24. Returns (N,) int64
    ``key = (quantised_depth << 32) | triangle``: comparing keys as integers compares
    depths first and breaks exact ties by the lower id, so one ``atomicMin`` per fragment
    resolves visibility and keeps the winner's id.

    * 32 bits: the float32 bit pattern of the depth. For non-negative IEEE floats the bit
      pattern, read as an integer, increases with the value (exponent above mantissa, both
      unsigned; the sign bit is 0), so no conversion is needed and the full float precision
      is kept. ``-0.0`` has the sign bit set and must become ``+0.0`` first; NaN sorts as
      ``+inf`` (farthest).
    * 24 bits: a unorm24 depth buffer: ``round(clamp(depth, 0, 1) * (2**24 - 1))`` (computed
      in float64), for depths in [0, 1] (window z). Fewer bits: nearby surfaces quantise to
      equal keys and the id, not the depth, decides (z-fighting).

    Hints: ``x.view(torch.int32)`` reinterprets float32 bits; ``torch.where(depth > 0, depth,
    0)`` turns -0.0 (and NaN) into +0.0, so deal with NaN first (``torch.isnan``).
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    check_tensor(depth, "depth", (None,))
    check_tensor(triangle, "triangle", (depth.shape[0],), kind="int64", like=depth)
    if depth_bits not in (24, 32):
        raise ValueError(f"depth_bits: expected 24 or 32, got {depth_bits!r}")
    # BEGIN SOLUTION (task 3)
    if triangle.numel() and (int(triangle.min()) < 0 or int(triangle.max()) > ID_MASK):
        raise ValueError(f"triangle: expected ids in [0, 2**{ID_BITS}), got values in "
                         f"[{int(triangle.min())}, {int(triangle.max())}]")
    depth = torch.where(torch.isnan(depth), math.inf, depth)
    depth = torch.where(depth > 0, depth, torch.zeros_like(depth))  # -0.0 and below -> +0.0
    if depth_bits == 32:
        quantised = depth.to(torch.float32).view(torch.int32).to(torch.int64)
    else:
        # In float64: float32 would round depth * (2**24 - 1) before the rounding to an integer.
        quantised = torch.round(depth.to(torch.float64).clamp(max=1.0) * (2**24 - 1)).to(
            torch.int64)
    return (quantised << ID_BITS) | triangle
    # END SOLUTION


def triangle_ids(keys):
    """The triangle id in each key: (...) int64 -> (...) int64, -1 where ``EMPTY``.

    Hints: ``keys & ID_MASK``; ``torch.where``.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    check_tensor(keys, "keys", any_shape(keys), kind="int64")
    # BEGIN SOLUTION (task 3)
    return torch.where(keys == EMPTY, -1, keys & ID_MASK)
    # END SOLUTION


def depth_test(pixel, key, out):
    """Resolve fragments into a visibility buffer: ``out[p] = min(out[p], keys of p)``.

    pixel: (N,) int64 indices into ``out``; key: (N,) int64 packed keys; out: (P,) int64,
    updated in place and returned (start from ``EMPTY`` everywhere for a new frame).

    One ``scatter_reduce_(0, pixel, key, reduce="amin")``: for every pixel, the minimum over
    all its fragments, however many there are and in whatever order they come. It is the
    batched form of one ``atomicMin(&buffer[pixel], key)`` per GPU thread; a plain
    read-compare-write (``out[pixel] = minimum(out[pixel], key)``) is a race: among
    fragments of one pixel the last writer wins, not the nearest.

    Hints: ``Tensor.scatter_reduce_`` with ``reduce="amin"`` (``include_self=True``, the default,
    keeps what ``out`` already holds).
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    check_tensor(out, "out", (None,), kind="int64")
    check_tensor(pixel, "pixel", (None,), kind="int64", like=out)
    check_tensor(key, "key", (pixel.shape[0],), kind="int64", like=out)
    # BEGIN SOLUTION (task 3)
    if pixel.numel() and (int(pixel.min()) < 0 or int(pixel.max()) >= out.shape[0]):
        raise ValueError(f"pixel: expected indices in [0, {out.shape[0]}), got values in "
                         f"[{int(pixel.min())}, {int(pixel.max())}]")
    out.scatter_reduce_(0, pixel, key, reduce="amin")
    return out
    # END SOLUTION


def rasterize(screen, width: int, height: int, *, depth_bits: int = 32,
              cull_backfaces: bool = False, memory_budget_bytes: int = 2**28, out=None):
    """The visibility buffer of screen-space triangles.

    screen: (K, 3, 4) float ``(x, y, z_ndc, 1/w)`` (``to_screen``'s output); width, height:
    the viewport; depth_bits: 32 or 24 (see ``pack_depth_id``); cull_backfaces: as in
    ``coverage``; memory_budget_bytes: bounds the fragments alive at once; out: optional
    (width * height,) int64 buffer to write (every element is written). Returns the
    (width * height,) int64 keys: ``EMPTY`` where no triangle covers the pixel centre, else
    ``pack_depth_id(depth, k)`` of the nearest triangle ``k`` (an index into ``screen``);
    exact depth ties go to the lowest ``k``.

    Clear ``out`` to ``EMPTY``; walk the triangles in chunks whose bounding boxes hold at
    most ``memory_budget_bytes // BYTES_PER_FRAGMENT`` pixels (at least one triangle per
    chunk); per chunk: ``coverage``, the fragment depth (see ``fragment_depth``; fragments
    beyond the far plane, ``z_ndc > 1``, are dropped), ``pack_depth_id`` with the chunk's
    offset added to the ids, ``depth_test``. The atomic minimum makes the result independent
    of the chunking and of the triangle order: bit for bit the same keys.

    Hints: plan the chunks on the host: ``ends = torch.cumsum(sizes, 0).cpu()`` and
    ``torch.searchsorted(ends, before + per_chunk, right=True)`` find where a chunk ends; a
    Python loop over chunks (not triangles) is fine. ``fragment_depth`` is provided.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    check_screen(screen)
    if screen.shape[2] != 4:
        raise ValueError(f"screen: expected shape (K, 3, 4) (x, y, z_ndc, 1/w), "
                         f"got {tuple(screen.shape)}")
    check_size(width, height)
    if depth_bits not in (24, 32):
        raise ValueError(f"depth_bits: expected 24 or 32, got {depth_bits!r}")
    if isinstance(memory_budget_bytes, bool) or not isinstance(memory_budget_bytes, int) \
            or memory_budget_bytes <= 0:
        raise ValueError(f"memory_budget_bytes: expected a positive int, "
                         f"got {memory_budget_bytes!r}")
    # BEGIN SOLUTION (task 3)
    if out is None:
        out = torch.empty(width * height, dtype=torch.int64, device=screen.device)
    check_tensor(out, "out", (width * height,), kind="int64", like=screen)
    out.fill_(EMPTY)
    boxes = bounding_boxes(screen, width, height)
    sizes = (boxes[:, 2] - boxes[:, 0]) * (boxes[:, 3] - boxes[:, 1])
    ends = torch.cumsum(sizes, 0).cpu()  # chunk planning on the host: one small copy
    per_chunk = max(1, memory_budget_bytes // BYTES_PER_FRAGMENT)
    K, first = screen.shape[0], 0
    while first < K:
        before = int(ends[first - 1]) if first else 0
        last = max(first + 1, int(torch.searchsorted(ends, before + per_chunk, right=True)))
        chunk = screen[first:last]
        triangle, pixel, bary = coverage(chunk, width, height, cull_backfaces)
        depth, in_range = fragment_depth(chunk, triangle, bary, depth_bits)
        keys = pack_depth_id(depth[in_range], triangle[in_range] + first, depth_bits)
        depth_test(pixel[in_range], keys, out)
        first = last
    return out
    # END SOLUTION


# ---------------------------------------------------------------------------------------
# Task 4: perspective-correct interpolation and shading


def perspective_correct(bary, inv_w):
    """Screen-space barycentrics -> barycentrics on the triangle in 3D.

    bary: (..., 3) float screen-space barycentrics of a point; inv_w: (..., 3) float the
    corners' ``1/w``. Returns (..., 3): ``(b_i / w_i) / sum_j (b_j / w_j)``.

    Why: the projection divides by w, so equal steps on screen are not equal steps on the
    triangle. Attributes divided by w (and 1/w itself) are linear in screen space; dividing
    the interpolated ``a/w`` by the interpolated ``1/w`` recovers the attribute. Plain
    screen-space weights bend textures and normals on surfaces that recede from the eye.

    Hints: three multiplies, a sum over the last axis, one division.
    """
    # BEGIN SOLUTION (task 4)
    q = bary * inv_w
    return q / (q[..., 0] + q[..., 1] + q[..., 2])[..., None]
    # END SOLUTION


def resolve_pixels(keys, screen, source, weights, width: int, height: int):
    """Deferred per-pixel barycentrics from a visibility buffer.

    keys: (H*W,) int64 from ``rasterize``; screen, source, weights: the (K, 3, 4), (K,),
    (K, 3, 3) triangles that were rasterized, their source faces and clip weights
    (``clip_triangles``); width, height: the viewport. Returns ``(face, bary)``: face (H, W)
    int64 the visible source face (-1 where empty), bary (H, W, 3) the perspective-correct
    barycentrics of the pixel centre **in the source face** (0 where empty).

    Per pixel (no fragments are kept: the visibility buffer's id is enough): the triangle
    ``k``, its ``edge_functions`` at the pixel centre normalised by their sum (screen-space
    barycentrics), ``perspective_correct`` with its corners' 1/w, then the clip weights:
    ``bary_source = sum_j mu_j weights[k, j]``.

    Hints: do it for all ``H*W`` pixels at once: gather triangle ``k`` (0 for empty pixels)
    and mask the results with ``torch.where`` at the end; ``pixel % width`` and
    ``pixel // width`` give the column and row.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    check_size(width, height)
    check_tensor(keys, "keys", (width * height,), kind="int64")
    check_tensor(screen, "screen", (None, 3, 4), like=keys)
    check_tensor(source, "source", (screen.shape[0],), kind="int64", like=keys)
    check_tensor(weights, "weights", (screen.shape[0], 3, 3), like=keys)
    # BEGIN SOLUTION (task 4)
    covered = keys != EMPTY
    k = torch.where(covered, keys & ID_MASK, 0)
    if screen.shape[0] == 0:  # nothing was rasterized: no triangle to gather from
        empty = torch.full((height, width), -1, dtype=torch.int64, device=keys.device)
        return empty, torch.zeros(height, width, 3, dtype=screen.dtype, device=keys.device)
    pixel = torch.arange(width * height, device=keys.device)
    px = (pixel % width).to(screen.dtype) + 0.5
    py = (pixel // width).to(screen.dtype) + 0.5
    tri = screen[k]
    e = edge_functions(tri, px, py)
    b = e / (e[:, 0] + e[:, 1] + e[:, 2])[:, None]
    mu = perspective_correct(b, tri[..., 3])
    w = weights[k]
    bary = mu[:, 0, None] * w[:, 0] + mu[:, 1, None] * w[:, 1] + mu[:, 2, None] * w[:, 2]
    bary = torch.where(covered[:, None], bary, torch.zeros_like(bary))
    face = torch.where(covered, source[k], -1)
    return face.reshape(height, width), bary.reshape(height, width, 3)
    # END SOLUTION


def rasterize_mesh(mesh: Mesh, camera: Camera, *, depth_bits: int = 32,
                   cull_backfaces: bool = False, memory_budget_bytes: int = 2**28):
    """The whole pipeline: ``(face (H, W) int64, bary (H, W, 3))`` of ``mesh`` seen by
    ``camera`` (``camera.width`` x ``camera.height`` pixels), on the mesh's device and dtype.

    ``to_clip_space`` with ``camera.view_projection()``, ``clip_triangles``, ``to_screen``,
    ``rasterize``, ``resolve_pixels``. face is -1 where nothing is visible; bary are the
    perspective-correct barycentrics of the pixel centre in that face.

    Hints: ``camera.view_projection(torch.float64).to(mesh.device)``; ``clip[mesh.faces]``
    gathers the corners of every face.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    if not isinstance(mesh, Mesh):
        raise TypeError(f"mesh: expected course.core.types.Mesh, got {type(mesh).__name__}")
    if not isinstance(camera, Camera):
        raise TypeError(f"camera: expected course.core.camera.Camera, got {type(camera).__name__}")
    mesh.validate()
    # BEGIN SOLUTION (task 4)
    mvp = camera.view_projection(torch.float64).to(mesh.device)
    clip = to_clip_space(mesh.vertices, mvp)
    clipped, source, weights = clip_triangles(clip[mesh.faces])
    screen = to_screen(clipped, camera.width, camera.height)
    keys = rasterize(screen, camera.width, camera.height, depth_bits=depth_bits,
                     cull_backfaces=cull_backfaces, memory_budget_bytes=memory_budget_bytes)
    return resolve_pixels(keys, screen, source, weights, camera.width, camera.height)
    # END SOLUTION


def interpolate(values, faces, face, bary):
    """Per-vertex attributes at pixels: ``sum_i bary_i * values[faces[face, i]]``.

    values: (V, C) float (normals, UVs, colours), faces: (F, 3) int64, face: (...) int64
    face per pixel (-1: empty), bary: (..., 3) float. Returns (..., C) in ``values``' dtype,
    0 where ``face == -1``.

    Hints: ``values[faces[face]]`` is (..., 3, C) (use face 0 for empty pixels, then mask).
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    check_tensor(values, "values", (None, None))
    check_tensor(faces, "faces", (None, 3), kind="int64", like=values)
    check_tensor(face, "face", any_shape(face), kind="int64", like=values)
    check_tensor(bary, "bary", (*face.shape, 3), like=values)
    # BEGIN SOLUTION (task 4)
    hit = face >= 0
    corners = values[faces[torch.where(hit, face, 0)]]  # (..., 3, C)
    b = bary.to(values.dtype)
    result = (b[..., 0, None] * corners[..., 0, :] + b[..., 1, None] * corners[..., 1, :]
              + b[..., 2, None] * corners[..., 2, :])
    return torch.where(hit[..., None], result, torch.zeros_like(result))
    # END SOLUTION


def shade(mesh: Mesh, face, bary, light_direction, smooth: bool = True):
    """Lambert shading with a directional light: ``max(0, n . l)`` per pixel.

    mesh: the rasterized mesh; face (H, W) int64 and bary (H, W, 3) from ``rasterize_mesh``;
    light_direction: (3,) float toward the light (normalised here); smooth: per-vertex
    normals interpolated with ``bary`` (Gouraud/Phong normals), else the face normal (flat).
    Returns (H, W) in the mesh's dtype, 0 where ``face == -1``. One-sided: the normal of a
    face is ``(v1 - v0) x (v2 - v0)`` as wound, a vertex normal the normalised sum of the
    (area-weighted, i.e. unnormalised) normals of its faces.

    The interpolated normal must be normalised again: a blend of unit vectors is shorter
    than 1 (by up to a few percent on a coarse mesh), which darkens the middle of each face.

    Hints: the provided ``face_normals`` and ``normalized``; ``index_add_`` over
    ``mesh.faces.reshape(-1)`` sums face normals into their vertices; ``interpolate``.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    if not isinstance(mesh, Mesh):
        raise TypeError(f"mesh: expected course.core.types.Mesh, got {type(mesh).__name__}")
    check_tensor(face, "face", (None, None), kind="int64", like=mesh.vertices)
    check_tensor(bary, "bary", (*face.shape, 3), like=mesh.vertices)
    check_tensor(light_direction, "light_direction", (3,), like=mesh.vertices)
    # BEGIN SOLUTION (task 4)
    light = normalized(light_direction.to(mesh.dtype))
    normals = face_normals(mesh)
    if smooth:
        vertex_normals = torch.zeros_like(mesh.vertices).index_add_(
            0, mesh.faces.reshape(-1), normals.repeat_interleave(3, dim=0))
        n = normalized(interpolate(normalized(vertex_normals), mesh.faces, face, bary))
    else:
        n = normalized(normals)[torch.where(face >= 0, face, 0)]
    cosine = (n * light).sum(-1).clamp(min=0)
    return torch.where(face >= 0, cosine, torch.zeros_like(cosine))
    # END SOLUTION


# ---------------------------------------------------------------------------------------
# Task 5: raster vs ray-traced visibility, hybrid shadows


def traced_visibility(trace, camera: Camera, device=None, dtype=torch.float32):
    """Ray-traced primary visibility: (H, W) int64, the triangle each pixel's primary ray
    hits first (-1 where it misses), for the same pixel centres as the rasterizer.

    trace: ``trace(origins, directions, t_min, t_max) -> hits`` (see the module docstring);
    camera: the view; device, dtype: of the rays (``course.core.camera.primary_rays``).

    Hints: ``course.core.camera.primary_rays(camera, device, dtype)``; the provided ``traced_hits``
    calls the tracer and checks its answer.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    if not callable(trace):
        raise TypeError(f"trace: expected a callable, got {type(trace).__name__}")
    if not isinstance(camera, Camera):
        raise TypeError(f"camera: expected course.core.camera.Camera, got {type(camera).__name__}")
    # BEGIN SOLUTION (task 5)
    rays = primary_rays(camera, device=device, dtype=dtype)
    _, triangle = traced_hits(trace, rays.origins, rays.directions, rays.t_min, rays.t_max)
    return triangle.reshape(camera.height, camera.width)
    # END SOLUTION


def world_positions(mesh: Mesh, face, bary):
    """(H, W, 3) world-space points ``sum_i bary_i * v_i`` of the visible faces (0 where
    ``face == -1``): the G-buffer's positions, reconstructed from the visibility buffer.

    Hints: ``interpolate``.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    if not isinstance(mesh, Mesh):
        raise TypeError(f"mesh: expected course.core.types.Mesh, got {type(mesh).__name__}")
    # BEGIN SOLUTION (task 5)
    return interpolate(mesh.vertices, mesh.faces, face, bary)
    # END SOLUTION


def shadow_epsilon(mesh: Mesh) -> float:
    """The ``t_min`` of shadow rays (with unit directions), relative to the scene.

    ``1e-4 * extent + 8 * eps * max|x|``: extent is the diagonal of the mesh's bounding box
    (the scene's scale), ``max|x|`` its largest absolute coordinate and eps the machine
    epsilon of its dtype. A reconstructed point is off the true surface by a few ulps of its
    coordinates; a shadow ray starting there must not hit its own triangle (shadow acne),
    and far from the origin the ulps grow with the coordinates. Too large an offset lets
    light leak through thin occluders in contact: scale, not a constant.

    Hints: compute in float64; ``torch.finfo(mesh.dtype).eps``; ignore non-finite vertices.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    if not isinstance(mesh, Mesh):
        raise TypeError(f"mesh: expected course.core.types.Mesh, got {type(mesh).__name__}")
    # BEGIN SOLUTION (task 5)
    v = mesh.vertices.to(torch.float64)
    v = v[torch.isfinite(v).all(-1)]
    if v.numel() == 0:
        return 0.0
    extent = float((v.amax(0) - v.amin(0)).norm())
    return 1e-4 * extent + 8 * torch.finfo(mesh.dtype).eps * float(v.abs().max())
    # END SOLUTION


def _shadow_rays(trace, mesh: Mesh, points, hit, light):
    """(N,) bool: which of the points (N, 3) marked ``hit`` see something toward ``light``.

    Write this helper for ``hybrid_shadows`` and ``traced_shadows``: shadow rays from the
    points with ``hit``, ``t_min = shadow_epsilon(mesh)``, ``t_max = inf``, through
    ``traced_hits``.
    """
    # BEGIN SOLUTION (task 5)
    origins = points[hit]
    directions = light.expand_as(origins).contiguous()
    n = origins.shape[0]
    t_min = torch.full((n,), shadow_epsilon(mesh), dtype=origins.dtype, device=origins.device)
    t_max = torch.full((n,), math.inf, dtype=origins.dtype, device=origins.device)
    _, blocker = traced_hits(trace, origins, directions, t_min, t_max)
    shadowed = torch.zeros(hit.shape, dtype=torch.bool, device=points.device)
    shadowed[hit] = blocker >= 0
    return shadowed
    # END SOLUTION


def hybrid_shadows(trace, mesh: Mesh, face, bary, light_direction):
    """Shadows of a rasterized frame by ray tracing: (H, W) bool, True where the visible
    point's shadow ray toward the directional light hits any triangle (False where
    ``face == -1``).

    trace: the tracer (module docstring); mesh: the scene; face, bary: ``rasterize_mesh``'s
    output; light_direction: (3,) toward the light. Primary visibility costs one raster pass
    instead of one ray per pixel; positions come from ``world_positions``; shadow rays start
    at ``t_min = shadow_epsilon(mesh)`` (unit directions) with ``t_max = inf``.

    Hints: ``world_positions``, then ``_shadow_rays`` on the flattened pixels.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    if not callable(trace):
        raise TypeError(f"trace: expected a callable, got {type(trace).__name__}")
    light = sun_direction(light_direction, mesh.vertices)  # unit, toward the light
    # BEGIN SOLUTION (task 5)
    points = world_positions(mesh, face, bary)
    return _shadow_rays(trace, mesh, points.reshape(-1, 3), face.reshape(-1) >= 0,
                        light).reshape(face.shape)
    # END SOLUTION


def traced_shadows(trace, mesh: Mesh, camera: Camera, light_direction):
    """The fully ray-traced counterpart of ``hybrid_shadows``: ``(face (H, W) int64,
    shadowed (H, W) bool)``, the primary rays of ``camera`` traced too (hit points
    ``o + t d``), shadow rays as in ``hybrid_shadows``. Rays in the mesh's dtype and device.

    Hints: ``primary_rays``, ``traced_hits``, hit points ``o + t d`` (use t = 0 for misses to
    avoid ``inf * 0``), then ``_shadow_rays``.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    if not callable(trace):
        raise TypeError(f"trace: expected a callable, got {type(trace).__name__}")
    if not isinstance(mesh, Mesh):
        raise TypeError(f"mesh: expected course.core.types.Mesh, got {type(mesh).__name__}")
    light = sun_direction(light_direction, mesh.vertices)  # unit, toward the light
    # BEGIN SOLUTION (task 5)
    rays = primary_rays(camera, device=mesh.device, dtype=mesh.dtype)
    t, triangle = traced_hits(trace, rays.origins, rays.directions, rays.t_min, rays.t_max)
    hit = triangle >= 0
    points = rays.origins + torch.where(hit, t, 0)[:, None] * rays.directions
    shadowed = _shadow_rays(trace, mesh, points, hit, light)
    shape = (camera.height, camera.width)
    return triangle.reshape(shape), shadowed.reshape(shape)
    # END SOLUTION
