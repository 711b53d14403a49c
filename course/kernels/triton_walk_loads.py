"""The BVH walk's constants and its loads and stores: rays in, hits out, a node pair's row
(``_row``, ``_load4``), the conservative box test (``_slab``) and where a child goes
(``_dispatch``). Part of :mod:`course.kernels.triton_walk`, whose docstring tells the walk.
"""

from __future__ import annotations

from course.kernels.flat_bvh import HIT_SLACK, STACK_DEPTH
from course.kernels.triton_intersect import _jit, _store_hits, tl

LOCAL_STACK = tl.constexpr(-1) if tl is not None else -1
"""``REGS`` of a stack in each lane's local memory (compiled only; ``stack="local"``)."""
if STACK_DEPTH != 64:  # _local_stack declares 64 entries in its PTX
    raise ImportError(
        f"triton_walk: the local stack holds 64 entries, STACK_DEPTH is {STACK_DEPTH}"
    )
NONE = tl.constexpr(-2147483648) if tl is not None else -2147483648
"""The walk's "no node" (int32 min: every other negative value is a leaf's ``~first``)."""
HIT_UP = tl.constexpr(1.0 + HIT_SLACK) if tl is not None else 1.0 + HIT_SLACK
HIT_DOWN = tl.constexpr(1.0 - HIT_SLACK) if tl is not None else 1.0 - HIT_SLACK
"""The box test's interval end widened away from zero by ``flat_bvh.HIT_SLACK``."""


# --------------------------------------------------------------------------------------
# Device functions
# --------------------------------------------------------------------------------------


@_jit
def _nan_to(x, value):
    """``x`` with NaN replaced by ``value`` (NaN is the only float not ``>= -inf``)."""
    return tl.where(x >= -float("inf"), x, value)


@_jit
def _or(a, b):
    return a | b


@_jit
def _row(ptr, row, width: tl.constexpr):
    """The address of row ``row`` of a table of ``width``-word rows (32-bit words), of row
    0 (which every table has) where ``row`` is negative (a lane with no row to read): one
    address per row, whose words ``_load4`` then reads at constant offsets, as CUDA C's
    ``p[0], p[1]`` do (an address per load costs ~6 instructions of 64-bit arithmetic; a
    row known to be >= 0 needs no sign extension)."""
    return ptr + tl.maximum(row, 0).to(tl.int64) * width


@_jit
def _load4(row, WORD: tl.constexpr, VEC: tl.constexpr):
    """Words ``WORD .. WORD + 3`` (WORD: 0, 4, 8 or 12) of the row at ``row`` (``_row``):
    compiled, one 16-byte load (``ld.global.nc.v4``, the offset in the instruction);
    interpreted, four loads. Returns four int32 (bit patterns)."""
    if VEC:
        if WORD == 0:
            return tl.inline_asm_elementwise(
                "ld.global.nc.v4.b32 {$0, $1, $2, $3}, [$4];",
                "=r,=r,=r,=r,l",
                [row],
                dtype=(tl.int32, tl.int32, tl.int32, tl.int32),
                is_pure=True,
                pack=1,
            )
        elif WORD == 4:
            return tl.inline_asm_elementwise(
                "ld.global.nc.v4.b32 {$0, $1, $2, $3}, [$4+16];",
                "=r,=r,=r,=r,l",
                [row],
                dtype=(tl.int32, tl.int32, tl.int32, tl.int32),
                is_pure=True,
                pack=1,
            )
        elif WORD == 8:
            return tl.inline_asm_elementwise(
                "ld.global.nc.v4.b32 {$0, $1, $2, $3}, [$4+32];",
                "=r,=r,=r,=r,l",
                [row],
                dtype=(tl.int32, tl.int32, tl.int32, tl.int32),
                is_pure=True,
                pack=1,
            )
        else:
            tl.static_assert(WORD == 12, "_load4: WORD must be 0, 4, 8 or 12")
            return tl.inline_asm_elementwise(
                "ld.global.nc.v4.b32 {$0, $1, $2, $3}, [$4+48];",
                "=r,=r,=r,=r,l",
                [row],
                dtype=(tl.int32, tl.int32, tl.int32, tl.int32),
                is_pure=True,
                pack=1,
            )
    else:
        return (
            tl.load(row + WORD),
            tl.load(row + WORD + 1),
            tl.load(row + WORD + 2),
            tl.load(row + WORD + 3),
        )


@_jit
def _f(x):
    return x.to(tl.float32, bitcast=True)


@_jit
def _rcp(x, VEC: tl.constexpr):
    """``1 / x`` correctly rounded. Compiled: ``rcp.rn.f32`` (what the CUDA C kernel's
    ``__frcp_rn`` is), a few instructions where the IEEE division ``div.rn.f32`` is a
    subroutine; both round the exact quotient, so the bits are the same."""
    if VEC:
        return tl.inline_asm_elementwise(
            "rcp.rn.f32 $0, $1;", "=f,f", [x], dtype=tl.float32, is_pure=True, pack=1
        )
    else:
        return tl.math.div_rn(tl.full(x.shape, 1.0, tl.float32), x)


@_jit
def _slab(
    ox,
    oy,
    oz,
    ix,
    iy,
    iz,
    neg_x,
    neg_y,
    neg_z,
    lx,
    hx,
    ly,
    hy,
    lz,
    hz,
    t_lo,
    t_hi,
    EXIT: tl.constexpr,
    SANITIZE: tl.constexpr,
):
    """Rays against one box each: (entry distance, hit?). Each axis's near plane is lo
    (hi) for a positive (negative) direction, so ``(plane - o) / d`` comes out in order. A
    NaN from ``0 * inf`` (a ray in a slab plane, parallel to it) means "inside this slab":
    compiled, ``max.f32``/``min.f32`` return the other operand; interpreted (numpy), the
    NaN is replaced first (SANITIZE). Conservative, as ``flat_bvh._slab``: the exit is
    widened away from zero by ``EXIT`` (its own rounding), then the end of the interval,
    ``min(t_hi, exit)``, by ``HIT_SLACK`` (the triangle test's rounding), by multiplications
    as in torch."""
    nx = (tl.where(neg_x, hx, lx) - ox) * ix
    fx = (tl.where(neg_x, lx, hx) - ox) * ix
    ny = (tl.where(neg_y, hy, ly) - oy) * iy
    fy = (tl.where(neg_y, ly, hy) - oy) * iy
    nz = (tl.where(neg_z, hz, lz) - oz) * iz
    fz = (tl.where(neg_z, lz, hz) - oz) * iz
    if SANITIZE:
        nx = _nan_to(nx, -float("inf"))
        ny = _nan_to(ny, -float("inf"))
        nz = _nan_to(nz, -float("inf"))
        fx = _nan_to(fx, float("inf"))
        fy = _nan_to(fy, float("inf"))
        fz = _nan_to(fz, float("inf"))
    enter = tl.maximum(tl.maximum(t_lo, nx), tl.maximum(ny, nz))
    far = tl.minimum(fx, tl.minimum(fy, fz))
    leave = tl.minimum(t_hi, far * tl.where(far >= 0, EXIT, 2.0 - EXIT))
    leave = leave * tl.where(leave >= 0, HIT_UP, HIT_DOWN)
    return enter, enter <= leave


@_jit
def _dispatch(mask, ref, node, cur):
    """Go to child/stack entry ``ref`` in the lanes of ``mask``: an interior node (ref >= 0)
    becomes the next ``node``; a leaf (``~first``) becomes pending rows from ``cur = first``,
    or, in a lane still busy with another leaf (speculative traversal), waits in ``node``
    (a negative ref other than NONE) until that one is done."""
    take = mask & (ref < 0) & (cur < 0)
    node = tl.where(mask, tl.where(take, NONE, ref), node)
    cur = tl.where(take, -1 - ref, cur)
    return node, cur


@_jit
def _valid(ox, oy, oz, dx, dy, dz):
    """Rays that can hit: finite components and a nonzero direction."""
    inf = float("inf")
    return (
        (tl.abs(ox) < inf)
        & (tl.abs(oy) < inf)
        & (tl.abs(oz) < inf)
        & (tl.abs(dx) < inf)
        & (tl.abs(dy) < inf)
        & (tl.abs(dz) < inf)
        & ((dx != 0.0) | (dy != 0.0) | (dz != 0.0))
    )


@_jit
def _load_rays(
    o_ptr,
    d_ptr,
    tlo_ptr,
    tlo_value,
    thi_ptr,
    thi_value,
    ray,
    live,
    TLO_ARRAY: tl.constexpr,
    THI_ARRAY: tl.constexpr,
):
    """Rays ``ray`` in the lanes of ``live``: ``(ox, oy, oz, dx, dy, dz, t_lo, t_hi,
    alive)``; alive: the ray can hit (rays with NaN/inf, a zero direction, t_max < t_min
    or NaN never walk)."""
    ox = tl.load(o_ptr + ray * 3 + 0, mask=live, other=0.0)
    oy = tl.load(o_ptr + ray * 3 + 1, mask=live, other=0.0)
    oz = tl.load(o_ptr + ray * 3 + 2, mask=live, other=0.0)
    dx = tl.load(d_ptr + ray * 3 + 0, mask=live, other=1.0)
    dy = tl.load(d_ptr + ray * 3 + 1, mask=live, other=1.0)
    dz = tl.load(d_ptr + ray * 3 + 2, mask=live, other=1.0)
    zero = tl.zeros(ox.shape, tl.float32)
    if TLO_ARRAY:
        t_lo = tl.load(tlo_ptr + ray, mask=live, other=0.0)
    else:
        t_lo = zero + tlo_value
    if THI_ARRAY:
        t_hi = tl.load(thi_ptr + ray, mask=live, other=0.0)
    else:
        t_hi = zero + thi_value
    alive = live & _valid(ox, oy, oz, dx, dy, dz) & (t_lo <= t_hi)
    return ox, oy, oz, dx, dy, dz, t_lo, t_hi, alive


@_jit
def _store_row_hits(tris, t_ptr, id_ptr, u_ptr, v_ptr, ray, mask, t, row, u, v):
    """The Hits of rays ``ray`` in the lanes of ``mask`` (row: the hit's row of the
    triangle layout, -1 on a miss; the original index is the row's ``v0.w``)."""
    tri = tl.load(tris + row * 12 + 3, mask=mask & (row >= 0), other=-1)
    _store_hits(t_ptr, id_ptr, u_ptr, v_ptr, ray, mask, t, tri, u, v)
