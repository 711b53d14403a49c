"""The fused rasterizer's vertex side (:mod:`course.kernels.triton_raster` launches it): the
vertex kernel (clip, near-plane split, screen positions, one row per screen triangle) and
the id map from depth keys to faces.

Given code, not an exercise.
"""

from __future__ import annotations

from course.kernels.triton_intersect import _jit, tl


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
