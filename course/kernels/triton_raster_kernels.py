"""The device side of the fused rasterizer (:mod:`course.kernels.triton_raster`, which
states the design and the contract, and launches them): the edge functions and fill rule,
the small-triangle and large-triangle raster kernels, the vertex kernel (clip, near-plane
split, screen positions) and the id map.

Given code, not an exercise.
"""

from __future__ import annotations

from course.kernels.triton_intersect import _jit, tl


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


@_jit
def _clip_corner(
    vert_ptr,
    index,
    live,
    m00,
    m01,
    m02,
    m03,
    m10,
    m11,
    m12,
    m13,
    m20,
    m21,
    m22,
    m23,
    m30,
    m31,
    m32,
    m33,
):
    """``to_clip_space`` of one corner: ``mvp @ [x, y, z, 1]`` in float64, rounded once."""
    base = vert_ptr + index * 3
    x = tl.load(base + 0, mask=live, other=0.0).to(tl.float64)
    y = tl.load(base + 1, mask=live, other=0.0).to(tl.float64)
    z = tl.load(base + 2, mask=live, other=0.0).to(tl.float64)
    cx = (m00 * x + m01 * y + m02 * z + m03).to(tl.float32)
    cy = (m10 * x + m11 * y + m12 * z + m13).to(tl.float32)
    cz = (m20 * x + m21 * y + m22 * z + m23).to(tl.float32)
    cw = (m30 * x + m31 * y + m32 * z + m33).to(tl.float32)
    return cx, cy, cz, cw


@_jit
def _pick(first, a, b, c):
    return tl.where(first == 0, a, tl.where(first == 1, b, c))


@_jit
def _cross(p, q, t):
    """``crossing``'s point: ``p + t (q - p)``, from the inside corner p."""
    return p + t * (q - p)


@_jit
def _screen_corner(valid, x, y, z, w, half_w, half_h):
    """``to_screen`` of one corner, NaN where the slot holds no triangle."""
    one = tl.full(x.shape, 1.0, tl.float32)
    nan = float("nan")
    sx = (tl.div_rn(x, w) + 1.0) * half_w
    sy = (1.0 - tl.div_rn(y, w)) * half_h
    return (
        tl.where(valid, sx, nan),
        tl.where(valid, sy, nan),
        tl.where(valid, tl.div_rn(z, w), nan),
        tl.where(valid, tl.div_rn(one, w), nan),
    )


@_jit
def _store_rows(
    screen_ptr, slot, live, v0, v1, v2, v3, v4, v5, v6, v7, v8, v9, v10, v11, BLOCK: tl.constexpr
):
    """Store 12 floats per lane as one contiguous row of ``screen`` (12 floats per slot):
    the lanes' rows are adjacent, so a warp writes whole sectors (12 scalar stores with a
    48-byte stride would each touch 32 sectors). The row is assembled in registers by
    joins: column ``8a + 4b + 2c + d`` of the (BLOCK, 2, 2, 2, 2) result is value number
    ``8a + 4b + 2c + d``; columns 12..15 are padding, never stored."""
    pad = tl.zeros([BLOCK], tl.float32)
    q0 = tl.join(tl.join(v0, v8), tl.join(v4, pad))
    q1 = tl.join(tl.join(v1, v9), tl.join(v5, pad))
    q2 = tl.join(tl.join(v2, v10), tl.join(v6, pad))
    q3 = tl.join(tl.join(v3, v11), tl.join(v7, pad))
    rows = tl.reshape(tl.join(tl.join(q0, q2), tl.join(q1, q3)), (BLOCK, 16))
    cols = tl.arange(0, 16)
    ptrs = screen_ptr + slot[:, None] * 12 + cols[None, :]
    tl.store(ptrs, rows, mask=live[:, None] & (cols[None, :] < 12))


@_jit
def _vertex_kernel(
    vert_ptr,
    face_ptr,
    mvp_ptr,
    screen_ptr,
    keys_ptr,
    counter_ptr,
    count,
    n_keys,
    half_w,
    half_h,
    BLOCK: tl.constexpr,
    FILL: tl.constexpr,
    PREPARE: tl.constexpr,
):
    """Lab 6's ``to_clip_space``, ``clip_triangles`` and ``to_screen``, one lane per face:
    slot ``i`` of ``screen`` (2F, 3, 4) gets face i's triangle (the first piece when the
    near plane cuts it), slot ``F + i`` the second piece of a face cut into a quad, NaN
    where there is none. With PREPARE it also clears ``FILL`` keys of the visibility buffer
    per program and (program 0) the queue counters of ``_small_kernel``."""
    pid = tl.program_id(0)
    if PREPARE:
        spots = pid.to(tl.int64) * FILL + tl.arange(0, FILL)
        tl.store(
            keys_ptr + spots, tl.full([FILL], 9223372036854775807, tl.int64), mask=spots < n_keys
        )
        pair = tl.arange(0, 2)
        tl.store(counter_ptr + pair, tl.zeros([2], tl.int32), mask=(pair * 0 + pid) == 0)
    tri = pid.to(tl.int64) * BLOCK + tl.arange(0, BLOCK)
    live = tri < count
    i0 = tl.load(face_ptr + tri * 3 + 0, mask=live, other=0).to(tl.int64)
    i1 = tl.load(face_ptr + tri * 3 + 1, mask=live, other=0).to(tl.int64)
    i2 = tl.load(face_ptr + tri * 3 + 2, mask=live, other=0).to(tl.int64)
    m00 = tl.load(mvp_ptr + 0)
    m01 = tl.load(mvp_ptr + 1)
    m02 = tl.load(mvp_ptr + 2)
    m03 = tl.load(mvp_ptr + 3)
    m10 = tl.load(mvp_ptr + 4)
    m11 = tl.load(mvp_ptr + 5)
    m12 = tl.load(mvp_ptr + 6)
    m13 = tl.load(mvp_ptr + 7)
    m20 = tl.load(mvp_ptr + 8)
    m21 = tl.load(mvp_ptr + 9)
    m22 = tl.load(mvp_ptr + 10)
    m23 = tl.load(mvp_ptr + 11)
    m30 = tl.load(mvp_ptr + 12)
    m31 = tl.load(mvp_ptr + 13)
    m32 = tl.load(mvp_ptr + 14)
    m33 = tl.load(mvp_ptr + 15)
    x0, y0, z0, w0 = _clip_corner(
        vert_ptr,
        i0,
        live,
        m00,
        m01,
        m02,
        m03,
        m10,
        m11,
        m12,
        m13,
        m20,
        m21,
        m22,
        m23,
        m30,
        m31,
        m32,
        m33,
    )
    x1, y1, z1, w1 = _clip_corner(
        vert_ptr,
        i1,
        live,
        m00,
        m01,
        m02,
        m03,
        m10,
        m11,
        m12,
        m13,
        m20,
        m21,
        m22,
        m23,
        m30,
        m31,
        m32,
        m33,
    )
    x2, y2, z2, w2 = _clip_corner(
        vert_ptr,
        i2,
        live,
        m00,
        m01,
        m02,
        m03,
        m10,
        m11,
        m12,
        m13,
        m20,
        m21,
        m22,
        m23,
        m30,
        m31,
        m32,
        m33,
    )
    # clip_triangles, step 1: trivial reject (non-finite, or all corners outside one plane).
    inf = float("inf")
    finite = (
        (tl.abs(x0) < inf)
        & (tl.abs(y0) < inf)
        & (tl.abs(z0) < inf)
        & (tl.abs(w0) < inf)
        & (tl.abs(x1) < inf)
        & (tl.abs(y1) < inf)
        & (tl.abs(z1) < inf)
        & (tl.abs(w1) < inf)
        & (tl.abs(x2) < inf)
        & (tl.abs(y2) < inf)
        & (tl.abs(z2) < inf)
        & (tl.abs(w2) < inf)
    )
    outside = (
        ((x0 < -w0) & (x1 < -w1) & (x2 < -w2))
        | ((x0 > w0) & (x1 > w1) & (x2 > w2))
        | ((y0 < -w0) & (y1 < -w1) & (y2 < -w2))
        | ((y0 > w0) & (y1 > w1) & (y2 > w2))
        | ((z0 < -w0) & (z1 < -w1) & (z2 < -w2))
        | ((z0 > w0) & (z1 > w1) & (z2 > w2))
    )
    keep = live & finite & ~outside
    # Step 2: the near plane d = z + w >= 0; the corner alone on its side first.
    d0 = z0 + w0
    d1 = z1 + w1
    d2 = z2 + w2
    in0 = d0 >= 0
    in1 = d1 >= 0
    in2 = d2 >= 0
    n_in = in0.to(tl.int32) + in1.to(tl.int32) + in2.to(tl.int32)
    one_in = n_in == 1
    odd0 = tl.where(one_in, in0, ~in0)
    odd1 = tl.where(one_in, in1, ~in1)
    odd2 = tl.where(one_in, in2, ~in2)
    first = tl.where(odd0, 0, tl.where(odd1, 1, tl.where(odd2, 2, 0)))
    ax = _pick(first, x0, x1, x2)
    ay = _pick(first, y0, y1, y2)
    az = _pick(first, z0, z1, z2)
    aw = _pick(first, w0, w1, w2)
    da = _pick(first, d0, d1, d2)
    bx = _pick(first, x1, x2, x0)
    by = _pick(first, y1, y2, y0)
    bz = _pick(first, z1, z2, z0)
    bw = _pick(first, w1, w2, w0)
    db = _pick(first, d1, d2, d0)
    cx = _pick(first, x2, x0, x1)
    cy = _pick(first, y2, y0, y1)
    cz = _pick(first, z2, z0, z1)
    cw = _pick(first, w2, w0, w1)
    dc = _pick(first, d2, d0, d1)
    t_ab = tl.div_rn(da, da - db)
    t_ac = tl.div_rn(da, da - dc)
    t_ba = tl.div_rn(db, db - da)
    t_ca = tl.div_rn(dc, dc - da)
    two_in = n_in == 2
    # First piece: (A, AB, AC) with one corner in, (BA, B, C) with two, (A, B, C) with three.
    p0x = tl.where(one_in, ax, tl.where(two_in, _cross(bx, ax, t_ba), ax))
    p0y = tl.where(one_in, ay, tl.where(two_in, _cross(by, ay, t_ba), ay))
    p0z = tl.where(one_in, az, tl.where(two_in, _cross(bz, az, t_ba), az))
    p0w = tl.where(one_in, aw, tl.where(two_in, _cross(bw, aw, t_ba), aw))
    p1x = tl.where(one_in, _cross(ax, bx, t_ab), bx)
    p1y = tl.where(one_in, _cross(ay, by, t_ab), by)
    p1z = tl.where(one_in, _cross(az, bz, t_ab), bz)
    p1w = tl.where(one_in, _cross(aw, bw, t_ab), bw)
    p2x = tl.where(one_in, _cross(ax, cx, t_ac), cx)
    p2y = tl.where(one_in, _cross(ay, cy, t_ac), cy)
    p2z = tl.where(one_in, _cross(az, cz, t_ac), cz)
    p2w = tl.where(one_in, _cross(aw, cw, t_ac), cw)
    a0, a1, a2, a3 = _screen_corner(keep, p0x, p0y, p0z, p0w, half_w, half_h)
    a4, a5, a6, a7 = _screen_corner(keep, p1x, p1y, p1z, p1w, half_w, half_h)
    a8, a9, a10, a11 = _screen_corner(keep, p2x, p2y, p2z, p2w, half_w, half_h)
    _store_rows(screen_ptr, tri, live, a0, a1, a2, a3, a4, a5, a6, a7, a8, a9, a10, a11, BLOCK)
    # Second piece of a quad: (BA, C, CA).
    second = keep & two_in
    a0, a1, a2, a3 = _screen_corner(
        second,
        _cross(bx, ax, t_ba),
        _cross(by, ay, t_ba),
        _cross(bz, az, t_ba),
        _cross(bw, aw, t_ba),
        half_w,
        half_h,
    )
    a4, a5, a6, a7 = _screen_corner(second, cx, cy, cz, cw, half_w, half_h)
    a8, a9, a10, a11 = _screen_corner(
        second,
        _cross(cx, ax, t_ca),
        _cross(cy, ay, t_ca),
        _cross(cz, az, t_ca),
        _cross(cw, aw, t_ca),
        half_w,
        half_h,
    )
    _store_rows(
        screen_ptr, tri + count, live, a0, a1, a2, a3, a4, a5, a6, a7, a8, a9, a10, a11, BLOCK
    )


@_jit
def _ids_kernel(keys_ptr, n_keys, count, BLOCK: tl.constexpr):
    """In place: key -> source face (slot mod count), -1 where EMPTY."""
    spots = tl.program_id(0).to(tl.int64) * BLOCK + tl.arange(0, BLOCK)
    live = spots < n_keys
    key = tl.load(keys_ptr + spots, mask=live, other=0)
    slot = key & tl.full([BLOCK], 4294967295, tl.int64)
    face = tl.where(slot >= count, slot - count, slot)
    empty = key == tl.full([BLOCK], 9223372036854775807, tl.int64)
    tl.store(keys_ptr + spots, tl.where(empty, -1, face), mask=live)
