"""Lab 6's ``rasterize`` as fused Triton kernels: the compute rasterizer of the lecture.

Lab 6 writes the rasterizer as batched torch code: every triangle's bounding box is
enumerated into a tensor of fragments (triangle, pixel), each fragment's edge functions,
depth and key are computed by a dozen tensor operations, and one ``scatter_reduce`` does
the atomic minimum. That is the right way to *learn* it, but every intermediate makes a
trip through DRAM. A compute-shader rasterizer keeps a fragment in registers from the
inside test to the ``atomicMin``. These kernels are that design, given (not an exercise),
so the lab can measure raster against ray-traced visibility with both sides fused
(``course.kernels.triton_tracer`` is the other side).

Two raster kernels, because triangle sizes on screen differ by orders of magnitude:

* ``_small_kernel`` runs over every triangle, one lane each. A small one (bounding box up to
  ``SMALL_BOX`` pixels, nearly all of a dense mesh) loops over its own box; the block loops
  as long as its largest small box, so they are kept small. A larger one is appended to a
  queue on the device (an atomic counter); empty, non-finite, zero-area, off-screen and
  culled triangles get an empty box and cost nothing more.
* ``_large_kernel`` runs a fixed grid (a few programs per SM) over the queue: each queued
  triangle gets one program whose lanes spread over its box, and a huge one (over
  ``HUGE_BOX`` pixels, e.g. a floor filling the screen) is split over all programs.
  With one program per triangle instead (nearly all of them leaving at once), the two
  kernels took 0.23 ms for bunny_x4 (278K triangles) at 1080p on an H200; queued, 0.06 ms
  on an H100.

Nothing goes back to the host: no sort, compaction or count is read, so a frame has no
synchronisation.

``screen_triangles_triton`` is the lab's setup (``to_clip_space``, ``clip_triangles``,
``to_screen``) as one kernel, one lane per face, writing slot ``i`` (face i or its first
piece) and slot ``F + i`` (the second piece of a face the near plane cuts into a quad) of a
(2F, 3, 4) buffer, NaN where there is no triangle. ``visibility_fused`` chains it with the
raster kernels and an id map: camera matrix to (H, W) face ids in four kernels (the vertex
kernel also clears the visibility buffer). ``FusedVisibility`` records those four in a CUDA
graph: at 1080p the Python launches take longer than the kernels.

The arithmetic is Lab 6's contract (``solutions``' docstrings state it in full): clip
coordinates in float64 rounded once, trivial rejection, near-plane crossings interpolated
from the inside corner; screen positions ``(x, y, z_ndc, 1/w)``; bounding boxes of pixel
centres clamped to the screen; consistent edge functions (evaluated from the
lexicographically smaller endpoint, so a shared edge gives exactly opposite values); the
top-left fill rule; depth interpolated from corner 0; 32-bit keys from the float bits of
the view depth ``1 / lerp(1/w)`` or 24-bit unorm window depth; fragments beyond the far
plane dropped; ``key = depth << 32 | id``, resolved by ``atomic_min``. The kernels are
compiled without FMA contraction (``enable_fp_fusion=False``; ``FP_FUSION`` for the raster
kernels, whose speed on an H100 did not change) and divide with correctly rounded
``div_rn``, so every value is the torch version's, bit for bit, and so are the keys. What
remains is the order of the triangles: keys hold slot numbers, so an exact depth tie (two
coplanar overlapping triangles) between the second piece of a clipped face and another
face resolves by slot, not by face number as in the lab (``tests/meta/test_triton_raster.py``
bounds how often; none occurred in its scenes or in the benchmark's).
"""

from __future__ import annotations

import torch

from course.kernels.triton_intersect import (
    _ieee_quiet,
    _jit,
    _require_triton,
    interpreting,
    tl,
    triton,
)

__all__ = ["EMPTY", "SMALL_BOX", "FusedVisibility", "rasterize_triton",
           "screen_triangles_fast", "screen_triangles_triton", "visibility_fused"]

EMPTY = torch.iinfo(torch.int64).max  # the key of a pixel no fragment reached
# Launch settings (module attributes, read at every launch; bench/lab6_raster.py's sweep).
SMALL_BOX = 64  # pixels: boxes up to this size go to the lane-per-triangle kernel
HUGE_BOX = 16384  # pixels: boxes above this size are split over all large-kernel programs
BLOCK_TRIANGLES = 64  # lanes (triangles) per program of the small kernel
SMALL_WARPS = 2
BLOCK_PIXELS = 256  # lanes (pixels) per program of the large kernel
LARGE_WARPS = 4
LARGE_PROGRAMS_PER_SM = 4
BLOCK_FACES = 128  # faces per program of the vertex kernel
FILL_KEYS = 4096  # keys cleared per program of the vertex kernel
BLOCK_IDS = 1024
FP_FUSION = False  # no FMA contraction in the raster kernels: the lab's keys bit for bit


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
def _fragment(out_ptr, tri, col, row, ok, width,
              x0, y0, z0, w0, x1, y1, z1, w1, x2, y2, z2, w2, positive,
              tl0, tl1, tl2, DEPTH_BITS: tl.constexpr):
    """Inside test, depth and atomic minimum of the fragments (tri, row, col) where ok."""
    px = col.to(tl.float32) + 0.5
    py = row.to(tl.float32) + 0.5
    e0 = _edge(x1, y1, x2, y2, px, py)
    e1 = _edge(x2, y2, x0, y0, px, py)
    e2 = _edge(x0, y0, x1, y1, px, py)
    e0 = tl.where(positive, e0, -e0)
    e1 = tl.where(positive, e1, -e1)
    e2 = tl.where(positive, e2, -e2)
    inside = (((e0 > 0) | ((e0 == 0) & tl0)) & ((e1 > 0) | ((e1 == 0) & tl1))
              & ((e2 > 0) | ((e2 == 0) & tl2)))
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
        quantised = (down + tl.where((frac > 0.5) | ((frac == 0.5) & odd), 1.0, 0.0)
                     ).to(tl.int64)
    key = (quantised << 32) | tri.to(tl.int64)
    hit = ok & inside & (z_ndc <= 1.0)
    tl.atomic_min(out_ptr + row.to(tl.int64) * width + col, key, mask=hit)


@_jit
def _setup(x0, y0, x1, y1, x2, y2, live, width, height, CULL: tl.constexpr):
    """Per triangle: drawn?, positive area?, top-left flags, clamped box of pixel centres."""
    area = _edge(x1, y1, x2, y2, x0, y0)
    inf = float("inf")
    finite = ((tl.abs(x0) < inf) & (tl.abs(y0) < inf) & (tl.abs(x1) < inf)
              & (tl.abs(y1) < inf) & (tl.abs(x2) < inf) & (tl.abs(y2) < inf))
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
def _small_kernel(screen_ptr, out_ptr, list_ptr, counter_ptr, count, width, height, small_box,
                  huge_box, DEPTH_BITS: tl.constexpr, CULL: tl.constexpr, BLOCK: tl.constexpr):
    """One lane per triangle: rasterizes the small ones, queues the others for
    ``_large_kernel`` (``list[:count]``: one program each; ``list[count:]``: huge, shared by
    all programs), rejects the rest (empty slots, NaN, zero area, off screen, culled)."""
    lanes = tl.arange(0, BLOCK)
    tri = tl.program_id(0) * BLOCK + lanes
    live = tri < count
    x0, y0, z0, w0, x1, y1, z1, w1, x2, y2, z2, w2 = _load_rows(screen_ptr, tri, live, BLOCK)
    positive, tl0, tl1, tl2, bx, by, box_w, box_h = _setup(x0, y0, x1, y1, x2, y2, live,
                                                           width, height, CULL)
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
        _fragment(out_ptr, tri, col, row, k < pixels, width, x0, y0, z0, w0, x1, y1, z1,
                  w1, x2, y2, z2, w2, positive, tl0, tl1, tl2, DEPTH_BITS)
        col += 1
        wrap = col >= end
        col = tl.where(wrap, bx, col)
        row = tl.where(wrap, row + 1, row)


@_jit
def _large_fragments(screen_ptr, out_ptr, tri, lanes, first, step, width, height,
                     DEPTH_BITS: tl.constexpr, CULL: tl.constexpr, BLOCK: tl.constexpr):
    """Pixels ``first, first + step, ...`` (BLOCK at a time) of triangle ``tri``'s box."""
    tri_v = tl.zeros([BLOCK], tl.int64) + tri  # the same triangle in every lane
    live = lanes >= 0
    x0, y0, z0, w0, x1, y1, z1, w1, x2, y2, z2, w2 = _load_triangle(screen_ptr, tri_v, live)
    positive, tl0, tl1, tl2, bx, by, box_w, box_h = _setup(x0, y0, x1, y1, x2, y2, live,
                                                           width, height, CULL)
    pixels = tl.max(box_w * box_h, axis=0)
    safe_w = tl.maximum(box_w, 1)
    for start in range(first, pixels, step):
        k = start + lanes
        _fragment(out_ptr, tri_v, bx + k % safe_w, by + k // safe_w, k < pixels, width,
                  x0, y0, z0, w0, x1, y1, z1, w1, x2, y2, z2, w2, positive, tl0, tl1, tl2,
                  DEPTH_BITS)


@_jit
def _large_kernel(screen_ptr, out_ptr, list_ptr, counter_ptr, count, width, height,
                  DEPTH_BITS: tl.constexpr, CULL: tl.constexpr, BLOCK: tl.constexpr):
    """A fixed grid over ``_small_kernel``'s queues: the large triangles round robin, one
    program each (lanes over its box); then every huge triangle split over all programs."""
    pid = tl.program_id(0)
    programs = tl.num_programs(0)
    lanes = tl.arange(0, BLOCK)
    queued = tl.load(counter_ptr)
    for k in range(pid, queued, programs):
        tri = tl.load(list_ptr + k).to(tl.int64)
        _large_fragments(screen_ptr, out_ptr, tri, lanes, 0, BLOCK, width, height, DEPTH_BITS,
                         CULL, BLOCK)
    huge = tl.load(counter_ptr + 1)
    for k in range(huge):
        tri = tl.load(list_ptr + count + k).to(tl.int64)
        _large_fragments(screen_ptr, out_ptr, tri, lanes, pid * BLOCK, programs * BLOCK,
                         width, height, DEPTH_BITS, CULL, BLOCK)


@_jit
def _clip_corner(vert_ptr, index, live, m00, m01, m02, m03, m10, m11, m12, m13,
                 m20, m21, m22, m23, m30, m31, m32, m33):
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
    return (tl.where(valid, sx, nan), tl.where(valid, sy, nan),
            tl.where(valid, tl.div_rn(z, w), nan), tl.where(valid, tl.div_rn(one, w), nan))


@_jit
def _store_rows(screen_ptr, slot, live, v0, v1, v2, v3, v4, v5, v6, v7, v8, v9, v10, v11,
                BLOCK: tl.constexpr):
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
def _vertex_kernel(vert_ptr, face_ptr, mvp_ptr, screen_ptr, keys_ptr, counter_ptr, count,
                   n_keys, half_w, half_h, BLOCK: tl.constexpr, FILL: tl.constexpr,
                   PREPARE: tl.constexpr):
    """Lab 6's ``to_clip_space``, ``clip_triangles`` and ``to_screen``, one lane per face:
    slot ``i`` of ``screen`` (2F, 3, 4) gets face i's triangle (the first piece when the
    near plane cuts it), slot ``F + i`` the second piece of a face cut into a quad, NaN
    where there is none. With PREPARE it also clears ``FILL`` keys of the visibility buffer
    per program and (program 0) the queue counters of ``_small_kernel``."""
    pid = tl.program_id(0)
    if PREPARE:
        spots = pid.to(tl.int64) * FILL + tl.arange(0, FILL)
        tl.store(keys_ptr + spots, tl.full([FILL], 9223372036854775807, tl.int64),
                 mask=spots < n_keys)
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
    x0, y0, z0, w0 = _clip_corner(vert_ptr, i0, live, m00, m01, m02, m03, m10, m11, m12, m13,
                                  m20, m21, m22, m23, m30, m31, m32, m33)
    x1, y1, z1, w1 = _clip_corner(vert_ptr, i1, live, m00, m01, m02, m03, m10, m11, m12, m13,
                                  m20, m21, m22, m23, m30, m31, m32, m33)
    x2, y2, z2, w2 = _clip_corner(vert_ptr, i2, live, m00, m01, m02, m03, m10, m11, m12, m13,
                                  m20, m21, m22, m23, m30, m31, m32, m33)
    # clip_triangles, step 1: trivial reject (non-finite, or all corners outside one plane).
    inf = float("inf")
    finite = ((tl.abs(x0) < inf) & (tl.abs(y0) < inf) & (tl.abs(z0) < inf) & (tl.abs(w0) < inf)
              & (tl.abs(x1) < inf) & (tl.abs(y1) < inf) & (tl.abs(z1) < inf)
              & (tl.abs(w1) < inf) & (tl.abs(x2) < inf) & (tl.abs(y2) < inf)
              & (tl.abs(z2) < inf) & (tl.abs(w2) < inf))
    outside = (((x0 < -w0) & (x1 < -w1) & (x2 < -w2)) | ((x0 > w0) & (x1 > w1) & (x2 > w2))
               | ((y0 < -w0) & (y1 < -w1) & (y2 < -w2)) | ((y0 > w0) & (y1 > w1) & (y2 > w2))
               | ((z0 < -w0) & (z1 < -w1) & (z2 < -w2)) | ((z0 > w0) & (z1 > w1) & (z2 > w2)))
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
    a0, a1, a2, a3 = _screen_corner(second, _cross(bx, ax, t_ba), _cross(by, ay, t_ba),
                                    _cross(bz, az, t_ba), _cross(bw, aw, t_ba), half_w, half_h)
    a4, a5, a6, a7 = _screen_corner(second, cx, cy, cz, cw, half_w, half_h)
    a8, a9, a10, a11 = _screen_corner(second, _cross(cx, ax, t_ca), _cross(cy, ay, t_ca),
                                      _cross(cz, az, t_ca), _cross(cw, aw, t_ca), half_w, half_h)
    _store_rows(screen_ptr, tri + count, live, a0, a1, a2, a3, a4, a5, a6, a7, a8, a9, a10,
                a11, BLOCK)


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


# ---------------------------------------------------------------------------------------
# Launchers


def _programs(device: torch.device) -> int:
    """The fixed grid of ``_large_kernel``: a few programs per SM (2 when interpreting)."""
    if interpreting():
        return 2
    index = device.index if device.index is not None else torch.cuda.current_device()
    if index not in _SM_COUNT:
        _SM_COUNT[index] = torch.cuda.get_device_properties(index).multi_processor_count
    return LARGE_PROGRAMS_PER_SM * _SM_COUNT[index]


_SM_COUNT: dict[int, int] = {}


def _raster_launch(screen, out, queue, counter, count: int, width: int, height: int,
                   depth_bits: int, cull: bool, small_box: int, huge_box: int) -> None:
    """The two raster kernels on ``screen`` (count, 3, 4) float32; ``out`` cleared to
    EMPTY, ``counter`` (2,) int32 zeroed, ``queue`` (2 * count,) int32 scratch."""
    _small_kernel[(triton.cdiv(count, BLOCK_TRIANGLES),)](
        screen, out, queue, counter, count, width, height, small_box, huge_box,
        DEPTH_BITS=depth_bits, CULL=cull, BLOCK=BLOCK_TRIANGLES, num_warps=SMALL_WARPS, enable_fp_fusion=FP_FUSION)
    _large_kernel[(_programs(screen.device),)](
        screen, out, queue, counter, count, width, height, DEPTH_BITS=depth_bits,
        CULL=cull, BLOCK=BLOCK_PIXELS, num_warps=LARGE_WARPS, enable_fp_fusion=FP_FUSION)


def _check_viewport(width, height) -> None:
    for name, value in (("width", width), ("height", height)):
        if isinstance(value, bool) or not isinstance(value, int) or not 0 < value < 2**15:
            raise ValueError(f"{name}: expected an int in [1, 32767], got {value!r}")


def _check_knobs(depth_bits, small_box, huge_box=HUGE_BOX) -> None:
    if depth_bits not in (24, 32):
        raise ValueError(f"depth_bits: expected 24 or 32, got {depth_bits!r}")
    # The small kernel compares every lane's box size (0 for lanes past the last triangle)
    # with these: below 0, every lane of a block is queued, past the end of the queue (the
    # interpreter corrupted its heap on small_box=-1); None or a string fails inside Triton.
    for name, value in (("small_box", small_box), ("huge_box", huge_box)):
        if isinstance(value, bool) or not isinstance(value, int) or value < 0:
            raise ValueError(f"{name}: expected an int >= 0 (pixels), got {value!r}")


def _check_device(device: torch.device, name: str) -> None:
    if not interpreting() and device.type != "cuda":
        raise ValueError(f"{name}: the compiled Triton kernels need a CUDA tensor, got {device} "
                         "(for the CPU, set TRITON_INTERPRET=1 before importing triton)")


def rasterize_triton(screen: torch.Tensor, width: int, height: int, *, depth_bits: int = 32,
                     cull_backfaces: bool = False, out: torch.Tensor | None = None,
                     small_box: int = SMALL_BOX, huge_box: int | None = None) -> torch.Tensor:
    """Lab 6's ``rasterize`` (same arguments and keys), fused: (width * height,) int64.

    screen: (K, 3, 4) float ``(x, y, z_ndc, 1/w)`` (computed in float32); width, height:
    the viewport; depth_bits: 32 or 24; cull_backfaces: drop negative-area triangles;
    out: optional (width * height,) int64 buffer (every element written); small_box: the
    box size, in pixels, up to which a triangle gets one lane rather than a program;
    huge_box: above it, a triangle is split over all programs (default ``HUGE_BOX``).
    """
    _require_triton()
    if not isinstance(screen, torch.Tensor) or screen.ndim != 3 or screen.shape[1:] != (3, 4) \
            or not screen.is_floating_point():
        got = tuple(screen.shape) if isinstance(screen, torch.Tensor) else type(screen).__name__
        raise ValueError(f"screen: expected a (K, 3, 4) float tensor (x, y, z_ndc, 1/w), "
                         f"got {got}")
    _check_viewport(width, height)
    _check_knobs(depth_bits, small_box, HUGE_BOX if huge_box is None else huge_box)
    device = screen.device
    _check_device(device, "screen")
    if out is None:
        out = torch.empty(width * height, dtype=torch.int64, device=device)
    if out.shape != (width * height,) or out.dtype != torch.int64 or out.device != device:
        raise ValueError(f"out: expected a ({width * height},) int64 tensor on {device}, got "
                         f"{tuple(out.shape)} {out.dtype} on {out.device}")
    out.fill_(EMPTY)
    data = screen.to(torch.float32).contiguous()
    count = data.shape[0]
    if count:  # no host synchronisation: the queues of large triangles stay on the device
        counter = torch.zeros(2, dtype=torch.int32, device=device)
        queue = torch.empty(2 * count, dtype=torch.int32, device=device)
        with _ieee_quiet():
            _raster_launch(data, out, queue, counter, count, width, height, depth_bits,
                           cull_backfaces, small_box, HUGE_BOX if huge_box is None else huge_box)
    return out


def _mesh_arguments(vertices, faces, mvp, width, height, depth_bits=32, small_box=SMALL_BOX):
    """Checked arguments of the mesh entry points. The device comes last: on a machine
    without CUDA every other bad argument is still named, not reported as a CPU tensor."""
    _require_triton()
    if not isinstance(vertices, torch.Tensor) or vertices.ndim != 2 \
            or vertices.shape[1] != 3 or vertices.dtype not in (torch.float32, torch.float64):
        got = (f"{tuple(vertices.shape)} {vertices.dtype}" if isinstance(vertices, torch.Tensor)
               else type(vertices).__name__)
        raise ValueError(f"vertices: expected a (V, 3) float32/float64 tensor, got {got}")
    if not isinstance(faces, torch.Tensor) or faces.ndim != 2 or faces.shape[1] != 3 \
            or faces.dtype not in (torch.int32, torch.int64):
        got = (f"{tuple(faces.shape)} {faces.dtype}" if isinstance(faces, torch.Tensor)
               else type(faces).__name__)
        raise ValueError(f"faces: expected an (F, 3) int32/int64 tensor, got {got}")
    if not isinstance(mvp, torch.Tensor) or mvp.shape != (4, 4) or not mvp.is_floating_point():
        got = tuple(mvp.shape) if isinstance(mvp, torch.Tensor) else type(mvp).__name__
        raise ValueError(f"mvp: expected a (4, 4) float tensor, got {got}")
    device = vertices.device
    if faces.device != device:
        raise ValueError(f"faces: expected a tensor on {device} like vertices, got {faces.device}")
    _check_viewport(width, height)
    _check_knobs(depth_bits, small_box)
    _check_device(device, "vertices")
    # A CPU matrix is copied without a synchronisation (the copy is queued like a kernel).
    m = mvp.to(device=device, dtype=torch.float64, non_blocking=True).contiguous()
    return vertices.contiguous(), faces.contiguous(), m


def _vertex_launch(vertices, faces, mvp, screen, keys, counter, width, height) -> None:
    count = faces.shape[0]
    n_keys = 0 if keys is None else keys.shape[0]
    grid = max(triton.cdiv(count, BLOCK_FACES), triton.cdiv(n_keys, FILL_KEYS))
    _vertex_kernel[(grid,)](
        vertices, faces, mvp, screen, screen if keys is None else keys,
        screen if counter is None else counter, count, n_keys, width / 2, height / 2,
        BLOCK=BLOCK_FACES, FILL=FILL_KEYS, PREPARE=keys is not None, num_warps=4,
        enable_fp_fusion=False)


def screen_triangles_triton(vertices: torch.Tensor, faces: torch.Tensor, mvp: torch.Tensor,
                            width: int, height: int) -> torch.Tensor:
    """Lab 6's ``to_clip_space``, ``clip_triangles`` and ``to_screen`` in one kernel.

    vertices: (V, 3) float32 (float64 is rounded to float32 clip coordinates); faces: (F, 3)
    int64/int32 indices into vertices (not range-checked: that would cost a
    synchronisation); mvp: (4, 4) float, used in float64 (``to_clip_space``'s contract);
    width, height: the viewport. Returns (2F, 3, 4) float32 ``(x, y, z_ndc, 1/w)``: slot
    ``i`` is face i (its first piece when the near plane cuts it), slot ``F + i`` the second
    piece of a face cut into a quad, and every coordinate of a slot holding nothing (a
    rejected face, no second piece) is NaN, which every rasterizer draws as nothing. The
    pieces are those of the lab, bit for bit (same operations, no FMA contraction, correctly
    rounded divisions); their order differs: source face = slot mod F.
    """
    vertices, faces, m = _mesh_arguments(vertices, faces, mvp, width, height)
    screen = torch.empty(2 * faces.shape[0], 3, 4, dtype=torch.float32, device=vertices.device)
    if faces.shape[0]:
        with _ieee_quiet():
            _vertex_launch(vertices, faces, m, screen, None, None, width, height)
    return screen


def visibility_fused(vertices: torch.Tensor, faces: torch.Tensor, mvp: torch.Tensor,
                     width: int, height: int, *, depth_bits: int = 32,
                     cull_backfaces: bool = False, small_box: int = SMALL_BOX) -> torch.Tensor:
    """Primary visibility of a mesh: (height, width) int64 source-face ids, -1 where empty.

    Lab 6's pipeline (``to_clip_space`` .. ``rasterize``, ids through ``source``) in four
    kernels and no host synchronisation: ``_vertex_kernel`` (MVP, clipping, viewport; it
    also clears the visibility buffer), ``_small_kernel``, ``_large_kernel`` and the id map,
    written in place over the keys. Arguments as ``screen_triangles_triton``; depth_bits,
    cull_backfaces, small_box as ``rasterize_triton``. The keys are the lab's for the
    triangles of ``screen_triangles_triton``: the same pixels see the same faces, except
    that an exact depth tie between a face's second piece and another face goes to the
    other face here (slot order), to the lower face in the lab.
    """
    vertices, faces, m = _mesh_arguments(vertices, faces, mvp, width, height, depth_bits,
                                         small_box)
    device, count = vertices.device, faces.shape[0]
    if count == 0:
        return torch.full((height, width), -1, dtype=torch.int64, device=device)
    keys = torch.empty(width * height, dtype=torch.int64, device=device)
    screen = torch.empty(2 * count, 3, 4, dtype=torch.float32, device=device)
    counter = torch.empty(2, dtype=torch.int32, device=device)  # zeroed by the vertex kernel
    queue = torch.empty(4 * count, dtype=torch.int32, device=device)
    with _ieee_quiet():
        _vertex_launch(vertices, faces, m, screen, keys, counter, width, height)
        _raster_launch(screen, keys, queue, counter, 2 * count, width, height, depth_bits,
                       cull_backfaces, small_box, HUGE_BOX)
        _ids_kernel[(triton.cdiv(keys.shape[0], BLOCK_IDS),)](keys, keys.shape[0], count,
                                                              BLOCK=BLOCK_IDS, num_warps=4)
    return keys.view(height, width)


class FusedVisibility:
    """``visibility_fused`` for one mesh and viewport, recorded once as a CUDA graph.

    ``FusedVisibility(vertices, faces, width, height, ...)(mvp)`` returns what
    ``visibility_fused(vertices, faces, mvp, width, height, ...)`` returns (a new tensor
    each call). The first call on CUDA runs the pipeline once (compiling the kernels) and
    records its four kernels in a graph; every later call copies the 4x4 matrix into the
    graph's input, replays the graph and copies the ids out: one launch instead of four
    kernel launches with their Python argument handling, which at 1080p take longer on the
    host than the kernels on the GPU. The graph reads ``vertices`` and ``faces`` where they
    are: their contents may change between calls, not their storage (shape, dtype, place);
    this object keeps them alive. Without CUDA (Triton's interpreter) every call runs
    ``visibility_fused``.
    """

    def __init__(self, vertices: torch.Tensor, faces: torch.Tensor, width: int, height: int,
                 *, depth_bits: int = 32, cull_backfaces: bool = False,
                 small_box: int = SMALL_BOX) -> None:
        # A stand-in matrix on the CPU: vertices, not yet checked, may have no device.
        eye = torch.eye(4, dtype=torch.float64)
        vertices, faces, _ = _mesh_arguments(vertices, faces, eye, width, height, depth_bits,
                                             small_box)
        self.vertices, self.faces, self.width, self.height = vertices, faces, width, height
        self.knobs = {"depth_bits": depth_bits, "cull_backfaces": cull_backfaces,
                      "small_box": small_box}
        self._graph = None
        self._mvp = None
        self._ids = None

    def _eager(self, mvp: torch.Tensor) -> torch.Tensor:
        return visibility_fused(self.vertices, self.faces, mvp, self.width, self.height,
                                **self.knobs)

    def __call__(self, mvp: torch.Tensor) -> torch.Tensor:
        device = self.vertices.device
        if device.type != "cuda" or interpreting():
            return self._eager(mvp)
        if not isinstance(mvp, torch.Tensor) or mvp.shape != (4, 4) \
                or not mvp.is_floating_point():
            got = tuple(mvp.shape) if isinstance(mvp, torch.Tensor) else type(mvp).__name__
            raise ValueError(f"mvp: expected a (4, 4) float tensor, got {got}")
        if self._graph is None:
            self._mvp = torch.empty(4, 4, dtype=torch.float64, device=device)
            self._mvp.copy_(mvp)
            side = torch.cuda.Stream(device)
            side.wait_stream(torch.cuda.current_stream(device))
            with torch.cuda.stream(side):
                self._eager(self._mvp)  # compiles and loads the kernels outside the capture
            torch.cuda.current_stream(device).wait_stream(side)
            graph = torch.cuda.CUDAGraph()
            with torch.cuda.graph(graph):
                self._ids = self._eager(self._mvp)
            self._graph = graph
        # A small copy from pageable memory is queued without waiting for the GPU.
        self._mvp.copy_(mvp, non_blocking=True)
        self._graph.replay()
        return self._ids.clone()


def screen_triangles_fast(clip_vertices: torch.Tensor, faces: torch.Tensor, width: int,
                          height: int, clip_triangles, to_screen):
    """Lab 6's setup stages (``clip_triangles`` then ``to_screen``), cheap for most triangles.

    clip_vertices: (V, 4) clip coordinates (``to_clip_space``); faces: (F, 3) int64;
    clip_triangles, to_screen: the lab's functions, used for the triangles that need them.
    Returns ``(screen (K, 3, 4), source (K,) int64)`` like ``to_screen(clip_triangles(...))``
    but in another order: first the triangles entirely on the visible side of the near
    plane (no clipping: only the viewport, a handful of element-wise kernels), then what
    ``clip_triangles`` makes of the others (near-plane crossings, NaN/inf corners). Trivially
    rejected triangles are not removed from the first group: their clamped boxes are empty,
    or they cover nothing, which costs less than a compaction. Ids index the returned
    ``screen``; exact depth ties may therefore go to another triangle than in the lab's
    order (visible only as coplanar z-fighting).
    """
    clip = clip_vertices[faces]  # (F, 3, 4)
    d = clip[..., 2] + clip[..., 3]
    simple = (d >= 0).all(-1) & (clip[..., 3] > 0).all(-1) & torch.isfinite(clip).all(-1).all(-1)
    first = simple.nonzero()[:, 0]
    rest = (~simple).nonzero()[:, 0]
    parts, sources = [], []
    if len(first):
        parts.append(to_screen(clip[first], width, height))
        sources.append(first)
    if len(rest):
        clipped, source, _ = clip_triangles(clip[rest])
        if len(source):
            parts.append(to_screen(clipped, width, height))
            sources.append(rest[source])
    if not parts:
        return clip.new_zeros(0, 3, 4), faces.new_zeros(0)
    return torch.cat(parts), torch.cat(sources)
