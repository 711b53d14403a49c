"""The device side of the fused rasterizer (:mod:`course.kernels.triton_raster`, which
states the design and the contract, and launches them): the edge functions and fill rule,
the small-triangle and large-triangle raster kernels; and, re-exported from
:mod:`course.kernels.triton_raster_vertex`, the vertex kernel (clip, near-plane split,
screen positions) and the id map.

Given code, not an exercise.
"""

from __future__ import annotations

from course.kernels.triton_intersect import _jit, tl
from course.kernels.triton_raster_vertex import _ids_kernel as _ids_kernel
from course.kernels.triton_raster_vertex import _vertex_kernel as _vertex_kernel


@_jit
def _edge(ax, ay, bx, by, px, py):
    """E_ab(p), evaluated from the lexicographically smaller endpoint (consistent)."""
    swap = (bx < ax) | ((bx == ax) & (by < ay))
    rx = tl.where(swap, bx, ax)
    ry = tl.where(swap, by, ay)
    sx = tl.where(swap, ax, bx)
    sy = tl.where(swap, ay, by)
    value = (px - rx) * (sy - ry) - (py - ry) * (sx - rx)
    return tl.where(swap, -value, value)


@_jit
def _top_left(ax, ay, bx, by, positive):
    forward = (by > ay) | ((by == ay) & (bx < ax))
    backward = (ay > by) | ((ay == by) & (ax < bx))
    return tl.where(positive, forward, backward)


@_jit
def _load_triangle(screen_ptr, tri, live):
    base = screen_ptr + tri * 12
    x0 = tl.load(base + 0, mask=live, other=0.0)
    y0 = tl.load(base + 1, mask=live, other=0.0)
    z0 = tl.load(base + 2, mask=live, other=0.0)
    w0 = tl.load(base + 3, mask=live, other=0.0)
    x1 = tl.load(base + 4, mask=live, other=0.0)
    y1 = tl.load(base + 5, mask=live, other=0.0)
    z1 = tl.load(base + 6, mask=live, other=0.0)
    w1 = tl.load(base + 7, mask=live, other=0.0)
    x2 = tl.load(base + 8, mask=live, other=0.0)
    y2 = tl.load(base + 9, mask=live, other=0.0)
    z2 = tl.load(base + 10, mask=live, other=0.0)
    w2 = tl.load(base + 11, mask=live, other=0.0)
    return x0, y0, z0, w0, x1, y1, z1, w1, x2, y2, z2, w2


@_jit
def _load_rows(screen_ptr, tri, live, BLOCK: tl.constexpr):
    """``_load_triangle`` for one triangle per lane, as whole rows (coalesced; the inverse
    of ``_store_rows``' joins)."""
    cols = tl.arange(0, 16)
    ptrs = screen_ptr + tri.to(tl.int64)[:, None] * 12 + cols[None, :]
    rows = tl.load(ptrs, mask=live[:, None] & (cols[None, :] < 12), other=0.0)
    r0, r1 = tl.split(tl.reshape(rows, (BLOCK, 2, 2, 2, 2)))
    q0, q2 = tl.split(r0)
    q1, q3 = tl.split(r1)
    p0, p4 = tl.split(q0)
    p1, p5 = tl.split(q1)
    p2, p6 = tl.split(q2)
    p3, p7 = tl.split(q3)
    v0, v8 = tl.split(p0)
    v1, v9 = tl.split(p1)
    v2, v10 = tl.split(p2)
    v3, v11 = tl.split(p3)
    v4, _ = tl.split(p4)
    v5, _ = tl.split(p5)
    v6, _ = tl.split(p6)
    v7, _ = tl.split(p7)
    return v0, v1, v2, v3, v4, v5, v6, v7, v8, v9, v10, v11


@_jit
def _fragment(
    out_ptr,
    tri,
    col,
    row,
    ok,
    width,
    x0,
    y0,
    z0,
    w0,
    x1,
    y1,
    z1,
    w1,
    x2,
    y2,
    z2,
    w2,
    positive,
    tl0,
    tl1,
    tl2,
    DEPTH_BITS: tl.constexpr,
):
    """Inside test, depth and atomic minimum of the fragments (tri, row, col) where ok."""
    px = col.to(tl.float32) + 0.5
    py = row.to(tl.float32) + 0.5
    e0 = _edge(x1, y1, x2, y2, px, py)
    e1 = _edge(x2, y2, x0, y0, px, py)
    e2 = _edge(x0, y0, x1, y1, px, py)
    e0 = tl.where(positive, e0, -e0)
    e1 = tl.where(positive, e1, -e1)
    e2 = tl.where(positive, e2, -e2)
    inside = (
        ((e0 > 0) | ((e0 == 0) & tl0))
        & ((e1 > 0) | ((e1 == 0) & tl1))
        & ((e2 > 0) | ((e2 == 0) & tl2))
    )
    total = e0 + e1 + e2
    # Correctly rounded divisions (``/`` would compile to the 2-ulp approximation) and no
    # FMA contraction (FP_FUSION): the torch version's values, bit for bit.
    b1 = tl.div_rn(e1, total)
    b2 = tl.div_rn(e2, total)
    z_ndc = z0 + b1 * (z1 - z0) + b2 * (z2 - z0)
    if DEPTH_BITS == 32:
        depth = tl.div_rn(tl.full(b1.shape, 1.0, tl.float32), w0 + b1 * (w1 - w0) + b2 * (w2 - w0))
        depth = tl.where(depth != depth, float("inf"), depth)  # noqa: PLR0124 (NaN test)
        depth = tl.where(depth > 0, depth, 0.0)  # -0.0 and below -> +0.0
        quantised = depth.to(tl.int32, bitcast=True).to(tl.int64)
    else:
        window = (z_ndc * 0.5 + 0.5).to(tl.float64)
        window = tl.where(window != window, 1.0, window)  # noqa: PLR0124 (NaN test)
        window = tl.minimum(tl.maximum(window, 0.0), 1.0)
        # round half to even, like torch.round: values here are below 2^24, exact in fp64
        scaled = window * 16777215.0
        down = tl.floor(scaled)
        frac = scaled - down
        odd = (down.to(tl.int64) & 1) == 1
        quantised = (down + tl.where((frac > 0.5) | ((frac == 0.5) & odd), 1.0, 0.0)).to(tl.int64)
    key = (quantised << 32) | tri.to(tl.int64)
    hit = ok & inside & (z_ndc <= 1.0)
    tl.atomic_min(out_ptr + row.to(tl.int64) * width + col, key, mask=hit)


@_jit
def _setup(x0, y0, x1, y1, x2, y2, live, width, height, CULL: tl.constexpr):
    """Per triangle: drawn?, positive area?, top-left flags, clamped box of pixel centres."""
    area = _edge(x1, y1, x2, y2, x0, y0)
    inf = float("inf")
    finite = (
        (tl.abs(x0) < inf)
        & (tl.abs(y0) < inf)
        & (tl.abs(x1) < inf)
        & (tl.abs(y1) < inf)
        & (tl.abs(x2) < inf)
        & (tl.abs(y2) < inf)
    )
    drawn = live & finite & (tl.abs(area) < inf) & (area != 0)
    if CULL:
        drawn = drawn & (area > 0)
    positive = area > 0
    tl0 = _top_left(x1, y1, x2, y2, positive)
    tl1 = _top_left(x2, y2, x0, y0, positive)
    tl2 = _top_left(x0, y0, x1, y1, positive)
    fw = width.to(tl.float32)
    fh = height.to(tl.float32)
    lo_x = tl.minimum(tl.maximum(tl.minimum(tl.minimum(x0, x1), x2), -1.0), fw + 1)
    hi_x = tl.minimum(tl.maximum(tl.maximum(tl.maximum(x0, x1), x2), -1.0), fw + 1)
    lo_y = tl.minimum(tl.maximum(tl.minimum(tl.minimum(y0, y1), y2), -1.0), fh + 1)
    hi_y = tl.minimum(tl.maximum(tl.maximum(tl.maximum(y0, y1), y2), -1.0), fh + 1)
    bx = tl.minimum(tl.maximum(tl.ceil(lo_x - 0.5).to(tl.int32), 0), width)
    by = tl.minimum(tl.maximum(tl.ceil(lo_y - 0.5).to(tl.int32), 0), height)
    ex = tl.maximum(tl.minimum((tl.floor(hi_x - 0.5) + 1).to(tl.int32), width), bx)
    ey = tl.maximum(tl.minimum((tl.floor(hi_y - 0.5) + 1).to(tl.int32), height), by)
    box_w = tl.where(drawn, ex - bx, 0)
    box_h = tl.where(drawn, ey - by, 0)
    return positive, tl0, tl1, tl2, bx, by, box_w, box_h


@_jit
def _small_kernel(
    screen_ptr,
    out_ptr,
    list_ptr,
    counter_ptr,
    count,
    width,
    height,
    small_box,
    huge_box,
    DEPTH_BITS: tl.constexpr,
    CULL: tl.constexpr,
    BLOCK: tl.constexpr,
):
    """One lane per triangle: rasterizes the small ones, queues the others for
    ``_large_kernel`` (``list[:count]``: one program each; ``list[count:]``: huge, shared by
    all programs), rejects the rest (empty slots, NaN, zero area, off screen, culled)."""
    lanes = tl.arange(0, BLOCK)
    tri = tl.program_id(0) * BLOCK + lanes
    live = tri < count
    x0, y0, z0, w0, x1, y1, z1, w1, x2, y2, z2, w2 = _load_rows(screen_ptr, tri, live, BLOCK)
    positive, tl0, tl1, tl2, bx, by, box_w, box_h = _setup(
        x0, y0, x1, y1, x2, y2, live, width, height, CULL
    )
    pixels = box_w * box_h
    # Queue the large boxes: one atomic per large triangle (they are few).
    large = pixels > small_box
    huge = pixels > huge_box
    zero = tl.zeros([BLOCK], tl.int32)
    slot = tl.atomic_add(counter_ptr + zero, 1, mask=large & ~huge)
    tl.store(list_ptr + slot, tri, mask=large & ~huge)
    slot = tl.atomic_add(counter_ptr + 1 + zero, 1, mask=huge)
    tl.store(list_ptr + count + slot, tri, mask=huge)
    pixels = tl.where(large, 0, pixels)
    # The block loops as long as its largest small box (lanes with smaller boxes idle).
    # Pixels in row-major order, stepped rather than divided out of k (an integer division
    # by a variable costs more than the rest of the index arithmetic).
    most = tl.max(pixels, axis=0)
    col = bx
    row = by
    end = bx + box_w
    for k in range(most):
        _fragment(
            out_ptr,
            tri,
            col,
            row,
            k < pixels,
            width,
            x0,
            y0,
            z0,
            w0,
            x1,
            y1,
            z1,
            w1,
            x2,
            y2,
            z2,
            w2,
            positive,
            tl0,
            tl1,
            tl2,
            DEPTH_BITS,
        )
        col += 1
        wrap = col >= end
        col = tl.where(wrap, bx, col)
        row = tl.where(wrap, row + 1, row)


@_jit
def _large_fragments(
    screen_ptr,
    out_ptr,
    tri,
    lanes,
    first,
    step,
    width,
    height,
    DEPTH_BITS: tl.constexpr,
    CULL: tl.constexpr,
    BLOCK: tl.constexpr,
):
    """Pixels ``first, first + step, ...`` (BLOCK at a time) of triangle ``tri``'s box."""
    tri_v = tl.zeros([BLOCK], tl.int64) + tri  # the same triangle in every lane
    live = lanes >= 0
    x0, y0, z0, w0, x1, y1, z1, w1, x2, y2, z2, w2 = _load_triangle(screen_ptr, tri_v, live)
    positive, tl0, tl1, tl2, bx, by, box_w, box_h = _setup(
        x0, y0, x1, y1, x2, y2, live, width, height, CULL
    )
    pixels = tl.max(box_w * box_h, axis=0)
    safe_w = tl.maximum(box_w, 1)
    for start in range(first, pixels, step):
        k = start + lanes
        _fragment(
            out_ptr,
            tri_v,
            bx + k % safe_w,
            by + k // safe_w,
            k < pixels,
            width,
            x0,
            y0,
            z0,
            w0,
            x1,
            y1,
            z1,
            w1,
            x2,
            y2,
            z2,
            w2,
            positive,
            tl0,
            tl1,
            tl2,
            DEPTH_BITS,
        )


@_jit
def _large_kernel(
    screen_ptr,
    out_ptr,
    list_ptr,
    counter_ptr,
    count,
    width,
    height,
    DEPTH_BITS: tl.constexpr,
    CULL: tl.constexpr,
    BLOCK: tl.constexpr,
):
    """A fixed grid over ``_small_kernel``'s queues: the large triangles round robin, one
    program each (lanes over its box); then every huge triangle split over all programs."""
    pid = tl.program_id(0)
    programs = tl.num_programs(0)
    lanes = tl.arange(0, BLOCK)
    queued = tl.load(counter_ptr)
    for k in range(pid, queued, programs):
        tri = tl.load(list_ptr + k).to(tl.int64)
        _large_fragments(
            screen_ptr, out_ptr, tri, lanes, 0, BLOCK, width, height, DEPTH_BITS, CULL, BLOCK
        )
    huge = tl.load(counter_ptr + 1)
    for k in range(huge):
        tri = tl.load(list_ptr + count + k).to(tl.int64)
        _large_fragments(
            screen_ptr,
            out_ptr,
            tri,
            lanes,
            pid * BLOCK,
            programs * BLOCK,
            width,
            height,
            DEPTH_BITS,
            CULL,
            BLOCK,
        )
