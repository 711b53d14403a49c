"""Lab 6's ``rasterize`` as fused Triton kernels: the compute rasterizer of the lecture.

Lab 6 writes the rasterizer as batched torch code: every triangle's bounding box is
enumerated into a tensor of fragments (triangle, pixel), each fragment's edge functions,
depth and key are computed by a dozen tensor operations, and one ``scatter_reduce`` does
the atomic minimum. That is the right way to *learn* it, but every intermediate makes a
trip through DRAM. A compute-shader rasterizer keeps a fragment in registers from the
inside test to the ``atomicMin``. These kernels are that design, given (not an exercise),
so the lab can measure raster against ray-traced visibility with both sides fused
(``course.triton_tracer`` is the other side).

Two kernels, because triangle sizes on screen differ by orders of magnitude:

* small triangles (bounding box up to ``SMALL_BOX`` pixels, nearly all of a dense mesh): one
  lane per triangle, which loops over its own box; the block loops as long as its largest
  box, so boxes are kept small;
* large triangles: one program per triangle, its lanes spread over the box's pixels (a
  screen-filling triangle costs ``box / BLOCK`` iterations, not ``box``).

Both kernels run over all triangles and each keeps its own: no sort or compaction on the
host, so a frame has no synchronisation and no launches beyond these two.

The arithmetic is Lab 6's contract (``solutions``' docstrings state it in full): screen
positions ``(x, y, z_ndc, 1/w)``; bounding boxes of pixel centres clamped to the screen;
consistent edge functions (evaluated from the lexicographically smaller endpoint, so a
shared edge gives exactly opposite values); the top-left fill rule; depth interpolated from
corner 0; 32-bit keys from the float bits of the view depth ``1 / lerp(1/w)`` or 24-bit
unorm window depth; fragments beyond the far plane dropped; ``key = depth << 32 | id``,
resolved by ``atomic_min``. Where the compiler contracts a multiply and an add into one
FMA, a value may differ from the torch version in its last bit: a pixel centre exactly on
an edge or a depth tie can then resolve the other way (``tests/meta/test_triton_raster.py``
bounds how often). Watertightness holds regardless: both sides of a shared edge evaluate
the same expression.
"""

from __future__ import annotations

import torch

from course.triton_intersect import (
    _ieee_quiet,
    _jit,
    _require_triton,
    interpreting,
    tl,
    triton,
)

__all__ = ["EMPTY", "SMALL_BOX", "rasterize_triton", "screen_triangles_fast"]

EMPTY = torch.iinfo(torch.int64).max  # the key of a pixel no fragment reached
SMALL_BOX = 64  # pixels: boxes up to this size go to the lane-per-triangle kernel
BLOCK_TRIANGLES = 128
BLOCK_PIXELS = 256


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
    # Correctly rounded divisions (``/`` would compile to the 2-ulp approximation): the
    # keys then differ from the torch version only where an FMA contraction does.
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
def _small_kernel(screen_ptr, out_ptr, count, width, height, small_box,
                  DEPTH_BITS: tl.constexpr, CULL: tl.constexpr, BLOCK: tl.constexpr):
    tri = tl.program_id(0) * BLOCK + tl.arange(0, BLOCK)
    live = tri < count
    x0, y0, z0, w0, x1, y1, z1, w1, x2, y2, z2, w2 = _load_triangle(screen_ptr, tri, live)
    positive, tl0, tl1, tl2, bx, by, box_w, box_h = _setup(x0, y0, x1, y1, x2, y2, live,
                                                           width, height, CULL)
    pixels = box_w * box_h
    pixels = tl.where(pixels <= small_box, pixels, 0)  # large boxes: the other kernel's
    most = tl.max(pixels, axis=0)
    safe_w = tl.maximum(box_w, 1)
    for k in range(most):
        col = bx + k % safe_w
        row = by + k // safe_w
        _fragment(out_ptr, tri, col, row, k < pixels, width, x0, y0, z0, w0, x1, y1, z1, w1,
                  x2, y2, z2, w2, positive, tl0, tl1, tl2, DEPTH_BITS)


@_jit
def _large_kernel(screen_ptr, out_ptr, width, height, small_box,
                  DEPTH_BITS: tl.constexpr, CULL: tl.constexpr, BLOCK: tl.constexpr):
    # One program per triangle; the small ones (nearly all) leave at once, which costs
    # less than sorting the triangles by size on the host (a synchronisation).
    lanes = tl.arange(0, BLOCK)
    # The triangle's data, the same for every lane (uniform loads).
    tri_v = tl.zeros([BLOCK], tl.int64) + tl.program_id(0)
    live = lanes >= 0
    x0, y0, z0, w0, x1, y1, z1, w1, x2, y2, z2, w2 = _load_triangle(screen_ptr, tri_v, live)
    positive, tl0, tl1, tl2, bx, by, box_w, box_h = _setup(x0, y0, x1, y1, x2, y2, live,
                                                           width, height, CULL)
    pixels = tl.max(box_w * box_h, axis=0)
    pixels = tl.where(pixels > small_box, pixels, 0)
    safe_w = tl.maximum(box_w, 1)
    for start in range(0, pixels, BLOCK):
        k = start + lanes
        col = bx + k % safe_w
        row = by + k // safe_w
        _fragment(out_ptr, tri_v, col, row, k < pixels, width, x0, y0, z0, w0, x1, y1, z1,
                  w1, x2, y2, z2, w2, positive, tl0, tl1, tl2, DEPTH_BITS)


def rasterize_triton(screen: torch.Tensor, width: int, height: int, *, depth_bits: int = 32,
                     cull_backfaces: bool = False, out: torch.Tensor | None = None,
                     small_box: int = SMALL_BOX) -> torch.Tensor:
    """Lab 6's ``rasterize`` (same arguments and keys), fused: (width * height,) int64.

    screen: (K, 3, 4) float ``(x, y, z_ndc, 1/w)`` (computed in float32); width, height:
    the viewport; depth_bits: 32 or 24; cull_backfaces: drop negative-area triangles;
    out: optional (width * height,) int64 buffer (every element written); small_box: the
    box size, in pixels, up to which a triangle gets one lane rather than a program.
    """
    _require_triton()
    if not isinstance(screen, torch.Tensor) or screen.ndim != 3 or screen.shape[1:] != (3, 4) \
            or not screen.is_floating_point():
        got = tuple(screen.shape) if isinstance(screen, torch.Tensor) else type(screen).__name__
        raise ValueError(f"screen: expected a (K, 3, 4) float tensor (x, y, z_ndc, 1/w), "
                         f"got {got}")
    for name, value in (("width", width), ("height", height)):
        if isinstance(value, bool) or not isinstance(value, int) or not 0 < value < 2**15:
            raise ValueError(f"{name}: expected an int in [1, 32767], got {value!r}")
    if depth_bits not in (24, 32):
        raise ValueError(f"depth_bits: expected 24 or 32, got {depth_bits!r}")
    device = screen.device
    if not interpreting() and device.type != "cuda":
        raise ValueError(f"screen: the compiled Triton kernels need a CUDA tensor, got {device} "
                         "(for the CPU, set TRITON_INTERPRET=1 before importing triton)")
    if out is None:
        out = torch.empty(width * height, dtype=torch.int64, device=device)
    if out.shape != (width * height,) or out.dtype != torch.int64 or out.device != device:
        raise ValueError(f"out: expected a ({width * height},) int64 tensor on {device}, got "
                         f"{tuple(out.shape)} {out.dtype} on {out.device}")
    out.fill_(EMPTY)
    data = screen.to(torch.float32).contiguous()
    count = data.shape[0]
    if count:  # no host synchronisation: both kernels see every triangle, keep their own
        with _ieee_quiet():
            _small_kernel[(triton.cdiv(count, BLOCK_TRIANGLES),)](
                data, out, count, width, height, small_box, DEPTH_BITS=depth_bits,
                CULL=cull_backfaces, BLOCK=BLOCK_TRIANGLES, num_warps=4)
            _large_kernel[(count,)](
                data, out, width, height, small_box, DEPTH_BITS=depth_bits,
                CULL=cull_backfaces, BLOCK=BLOCK_PIXELS, num_warps=4)
    return out


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
