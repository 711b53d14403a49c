"""BVH traversal and a whole Whitted frame as Triton kernels (given, not an exercise).

Lab 3 compares ways of organising a tracer. These kernels are the GPU end of that
comparison: ``trace_flat_triton`` is a closest-hit / any-hit BVH walk (what the separate
kernels of a wavefront tracer launch once per bounce), ``render_whitted_triton`` the
lecture's **uber kernel**: each lane runs its pixel's whole Whitted recursion, the
TRAVERSE -> INTERSECT -> SHADE state machine, in one launch, with no rays written to memory
between the stages.

How "one ray per thread" maps onto Triton. A Triton program works on a block of lanes in
lock step; control flow is per program, not per lane. So each kernel is a loop that runs
while *any* lane of the program still has work (``tl.max`` of the lanes' alive flags), and
every step is written with per-lane masks: a lane that is done, or has nothing of that
kind to do this step, just has its loads and stores masked off. This is what a CUDA warp
does with divergent branches anyway; the default launch (32 lanes, one warp per program)
makes a program exactly one warp, so the loop condition is a warp vote and the lanes of
different warps never wait for each other.

Each step of the walk does, per lane (see course.kernels.flat_bvh for the layouts and the contract):

1. TRAVERSE: a lane at an interior node reads its row of ``pairs`` (both children's boxes
   and links: four 16-byte loads, the layout the CUDA C kernel reads), tests both boxes,
   goes to the nearer hit child and pushes the farther; a leaf child becomes pending work;
2. INTERSECT: a lane with pending leaf work tests one triangle (Möller–Trumbore, three
   16-byte loads), or two with ``tris_per_step=2``;
3. POP: a lane with no node pops its stack (or finishes when it is empty and its leaf is
   done). With ``speculate`` (the default) it does so even while its leaf is being tested,
   parking at most one more leaf: it then takes part in both stages of a step instead of
   idling through one (Aila & Laine's speculative traversal).

Stages no lane needs are skipped (``uniform_branches``, on by default): before TRAVERSE and
INTERSECT the program votes over its lanes (``redux.sync``) and branches around the stage
when none needs it, as a warp does when none of its threads takes a branch. The kernel
itself leaves out rays that cannot hit and takes numbers for ``t_min``/``t_max`` as
numbers, so a call is one launch (and, with ``refill``, a fill of its ray counter).

What the knobs measured on an H200 (bench/results/nvidia-h200/lab3_packed/: 1M rays on the
bunny, one warp per program): skipping stages 5.7 -> 4.9 G primary rays/s without it;
speculation +20% primary (5.7 -> 6.9 G), +8% diffuse (1.95 -> 2.10 G); the stack's top four
entries in registers (``stack_regs=4``) cost 12% (6.5 -> 5.7 G) against the stack in
memory; two triangle tests per step +10% primary and -4% diffuse; 64 lanes per warp (two
rays per thread) or two warps per program were slower. The CUDA C kernel on the same rays:
11.8 G primary, 3.2 G diffuse. Then (bench/results/nvidia-h200/lab3_loops/): the CUDA C
kernel's loop shape (``loop="while"``, Aila & Laine's while-while) and its stack's place
(``stack="local"``, each lane's entries in local memory) together with speculation: 8.0 G
primary, 2.2 G diffuse, 69% and 70% of CUDA C's 11.6 G and 3.2 G in that run. Rows of
one run varied by up to 2x for the same code, so single knobs are not ranked from it;
``bench/lab3_gpu.py`` now also times the best launch of each tracer in alternating rounds.
A one-warp program can hold at most half of an SM's warps (32 programs per SM); the CUDA C
kernel runs at 62.5%. Measured again with the best launch of each tracer timed in 7
alternating rounds (bench/results/nvidia-h200/lab3_head_to_head/): 71% primary (8.2 G
against 11.5 G rays/s), 72% diffuse (2.3 G against 3.2 G), the same launch best for both
(while-while, speculative, local stack: now the defaults).

Then the instructions (bench/results/nvidia-h200/lab3_rows/, the SASS of both kernels
side by side, ``bench/sass_loops.py``): a TRAVERSE iteration of this walk was 118
instructions where the CUDA C kernel's is 83 (both arms of its branches counted), an
INTERSECT one 110 against 64. Two things made the difference. Each
16-byte load computed its own 64-bit address from a masked offset (~6 instructions
each), where CUDA C computes one per row and reads its words at constant offsets: here
too now (``_row``, ``_load4``). And the triangle's ``u >= 0 & v >= 0 & u + v <= 1 & det
!= 0`` was compiled into flags packed into bits and unpacked (~10 instructions): one
NaN-propagating min tests the same now. 97 and 85 instructions per iteration: with the
defaults 9.8 G primary rays/s, 84% of CUDA C's 11.7 G in alternating rounds (target 80%
met), and 2.8 G diffuse, 88% of 3.2 G (the kernels timed alone; per call, a 1M-ray call's
Python, ~100-200 us, outlasts its 107 us kernel).

Refilling free lanes (``refill``, off by default). A program whose
lanes finish at different times runs on with most of them idle: on diffuse rays, a warp
waits for its slowest ray. With ``refill=k`` the kernel launches persistent programs (32
per SM) that take new rays from a global counter whenever ``k`` of their lanes are free
(Aila & Laine's dynamic ray fetch: a prefix sum over the free lanes gives each its ray, one
atomic add per program). Measured on an H200 (bench/results/nvidia-h200/lab3_refill/):
diffuse rays 2.3 -> 3.0 G rays/s, 94% of the CUDA C kernel's 3.2 G in alternating rounds;
primary rays, whose lanes finish together anyway, lose ~5% (coherence traded for
occupancy of the lanes): ~67% of CUDA C there. ``k`` from 1 to 8 measured the same on
diffuse rays; 8 the best of them on primary rays. With the leaner loops
(bench/results/nvidia-h200/lab3_rows/): ``refill=8`` 3.26 G diffuse (101% of CUDA C)
but 8.9 G primary (75%), against 2.8 G and 9.8 G without: so refill is off by default,
and ``refill=8`` is the launch for incoherent rays (bounces, shadow rays of a path
tracer).

The stack. Triton has no per-lane arrays with dynamic indices, so by default
(``stack="global"``) each lane's stack is a column of a scratch buffer in global memory,
``stack[level, lane]``: entries of one level of neighbouring lanes are neighbours, so
pushes and pops of a warp at similar depths touch few cache lines (the interleaving CUDA
gives local memory). It is what the CUDA kernel's local-memory stack is, too: both live in
L1/L2-cached device memory. A lane owns its column for the program's lifetime, so nothing
needs synchronising. With ``stack_regs=4`` the top four entries stay in registers (shifted
on every push and pop) and only deeper ones go to the buffer. ``stack="local"`` declares a 64-entry array in each
lane's local memory in inline PTX instead (``_local_stack``), as ``int stack[64]`` is in
CUDA C: no buffer is allocated, and the hardware interleaves the lanes' entries itself.

Accuracy contract: that of course.kernels.flat_bvh (float32 slab test with NaN-safe zero
directions and Ize's widened exit, float32 Möller–Trumbore with IEEE division, closed
``[t_min, t_max]``, ties to the lower triangle index, NaN/inf/zero rays miss, not
watertight). The uber kernel shades by the contract of course.given.lab3, in float32.

Runs compiled on CUDA, or in Triton's CPU interpreter under ``TRITON_INTERPRET=1`` (set
before ``triton`` is imported; slow, for tiny tests). Importing this module without
Triton works; calling a kernel then raises ImportError.
"""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass

import torch

from course.core.types import Hits
from course.kernels.flat_bvh import (
    EXIT_SCALE,
    STACK_DEPTH,
    FlatBVH,
    check_ray_bounds,
    check_rays,
    flat_bvh_for,
)
from course.kernels.triton_intersect import (
    _ieee_quiet,
    _jit,
    _require_triton,
    _store_hits,
    tl,
    triton,
)

__all__ = [
    "TracerKernelInfo",
    "interpreting",
    "render_whitted_triton",
    "trace_flat_triton",
    "triton_available",
]

DEFAULT_BLOCK = 32
DEFAULT_NUM_WARPS = 1
DEFAULT_UNIFORM = True
# The defaults are the launch measured fastest on primary and on diffuse rays
# (bench/results/nvidia-h200/lab3_head_to_head/): while-while, speculative, local stack.
# Refilling free lanes is off: +15% diffuse but -10% primary
# (bench/results/nvidia-h200/lab3_rows/); pass refill=8 for incoherent rays.
DEFAULT_STACK_REGS = 0
DEFAULT_TRIS_PER_STEP = 1
DEFAULT_SPECULATE = True
DEFAULT_LOOP = "while"
DEFAULT_STACK = None  # "local", or "global" when stack_regs keeps entries in registers
DEFAULT_REFILL = 0  # free lanes at which a persistent program takes new rays (0: off)
LOOPS = ("if", "while")
STACKS = ("global", "local")
# The uber kernel's walk, as measured for its frames (bench/results/nvidia-h200/lab3_packed/).
UBER_STACK_REGS, UBER_TRIS_PER_STEP, UBER_SPECULATE = 4, 1, False
LOCAL_STACK = tl.constexpr(-1) if tl is not None else -1
"""``REGS`` of a stack in each lane's local memory (compiled only; ``stack="local"``)."""
if STACK_DEPTH != 64:  # _local_stack declares 64 entries in its PTX
    raise ImportError(f"triton_tracer: the local stack holds 64 entries, STACK_DEPTH is "
                      f"{STACK_DEPTH}")
NONE = tl.constexpr(-2147483648) if tl is not None else -2147483648
"""The walk's "no node" (int32 min: every other negative value is a leaf's ``~first``)."""


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
                "ld.global.nc.v4.b32 {$0, $1, $2, $3}, [$4];", "=r,=r,=r,=r,l", [row],
                dtype=(tl.int32, tl.int32, tl.int32, tl.int32), is_pure=True, pack=1)
        elif WORD == 4:
            return tl.inline_asm_elementwise(
                "ld.global.nc.v4.b32 {$0, $1, $2, $3}, [$4+16];", "=r,=r,=r,=r,l", [row],
                dtype=(tl.int32, tl.int32, tl.int32, tl.int32), is_pure=True, pack=1)
        elif WORD == 8:
            return tl.inline_asm_elementwise(
                "ld.global.nc.v4.b32 {$0, $1, $2, $3}, [$4+32];", "=r,=r,=r,=r,l", [row],
                dtype=(tl.int32, tl.int32, tl.int32, tl.int32), is_pure=True, pack=1)
        else:
            tl.static_assert(WORD == 12, "_load4: WORD must be 0, 4, 8 or 12")
            return tl.inline_asm_elementwise(
                "ld.global.nc.v4.b32 {$0, $1, $2, $3}, [$4+48];", "=r,=r,=r,=r,l", [row],
                dtype=(tl.int32, tl.int32, tl.int32, tl.int32), is_pure=True, pack=1)
    else:
        return (tl.load(row + WORD), tl.load(row + WORD + 1), tl.load(row + WORD + 2),
                tl.load(row + WORD + 3))


@_jit
def _f(x):
    return x.to(tl.float32, bitcast=True)


@_jit
def _rcp(x, VEC: tl.constexpr):
    """``1 / x`` correctly rounded. Compiled: ``rcp.rn.f32`` (what the CUDA C kernel's
    ``__frcp_rn`` is), a few instructions where the IEEE division ``div.rn.f32`` is a
    subroutine; both round the exact quotient, so the bits are the same."""
    if VEC:
        return tl.inline_asm_elementwise("rcp.rn.f32 $0, $1;", "=f,f", [x], dtype=tl.float32,
                                         is_pure=True, pack=1)
    else:
        return tl.math.div_rn(tl.full(x.shape, 1.0, tl.float32), x)


@_jit
def _slab(ox, oy, oz, ix, iy, iz, neg_x, neg_y, neg_z, lx, hx, ly, hy, lz, hz, t_lo, t_hi,
          EXIT: tl.constexpr, SANITIZE: tl.constexpr):
    """Rays against one box each: (entry distance, hit?). Each axis's near plane is lo
    (hi) for a positive (negative) direction, so ``(plane - o) / d`` comes out in order. A
    NaN from ``0 * inf`` (a ray in a slab plane, parallel to it) means "inside this slab":
    compiled, ``max.f32``/``min.f32`` return the other operand; interpreted (numpy), the
    NaN is replaced first (SANITIZE)."""
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
    leave = tl.minimum(t_hi, tl.minimum(fx, tl.minimum(fy, fz)) * EXIT)
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
def _local_stack(like):
    """A 64-entry int32 array in each lane's local memory (what ``int stack[64]`` is in
    CUDA C: interleaved across the warp, cached write-back in L1) and its address: a
    ``.local`` declaration in inline PTX, kept by ptxas because its address is used. 64 is
    flat_bvh's STACK_DEPTH: every FlatBVH is checked at build to need no more."""
    return tl.inline_asm_elementwise(
        "{ .local .align 16 .b32 stk[64]; mov.u64 $0, stk; }", "=l,r", [like],
        dtype=tl.int64, is_pure=False, pack=1)


@_jit
def _push(stack_ptr, slot, stride, sp, value, mask, s0, s1, s2, s3, REGS: tl.constexpr):
    """Push ``value`` in the lanes of ``mask``. REGS = 4: the top four entries live in
    registers (s0 the top); the one they push out goes to the memory stack, whose entries
    are ``0 .. sp - 5``. REGS = 0: every entry in memory. REGS = LOCAL_STACK: every entry in
    the lane's local memory (see _local_stack; ``slot`` is its address). Returns (sp, s0,
    s1, s2, s3)."""
    if REGS == LOCAL_STACK:
        tl.inline_asm_elementwise(
            "{ .reg .pred p; setp.ne.s32 p, $3, 0; @p st.local.b32 [$1], $2; mov.b32 $0, 0; }",
            "=r,l,r,r", [slot + sp.to(tl.int64) * 4, value, mask.to(tl.int32)],
            dtype=tl.int32, is_pure=False, pack=1)
    elif REGS == 0:
        tl.store(stack_ptr + sp * stride + slot, value, mask=mask)
    else:
        tl.store(stack_ptr + (sp - 4) * stride + slot, s3, mask=mask & (sp >= 4))
        s3 = tl.where(mask, s2, s3)
        s2 = tl.where(mask, s1, s2)
        s1 = tl.where(mask, s0, s1)
        s0 = tl.where(mask, value, s0)
    return sp + mask.to(tl.int32), s0, s1, s2, s3


@_jit
def _pop(stack_ptr, slot, stride, sp, mask, s0, s1, s2, s3, REGS: tl.constexpr):
    """Pop the top entry in the lanes of ``mask`` (see _push). Returns (value, sp, s0..s3)."""
    sp = sp - mask.to(tl.int32)
    if REGS == LOCAL_STACK:
        value = tl.inline_asm_elementwise(
            "{ .reg .pred p; setp.ne.s32 p, $2, 0; mov.b32 $0, 0; @p ld.local.b32 $0, [$1]; }",
            "=r,l,r", [slot + sp.to(tl.int64) * 4, mask.to(tl.int32)], dtype=tl.int32,
            is_pure=False, pack=1)
    elif REGS == 0:
        value = tl.load(stack_ptr + sp * stride + slot, mask=mask, other=0)
    else:
        value = s0
        s0 = tl.where(mask, s1, s0)
        s1 = tl.where(mask, s2, s1)
        s2 = tl.where(mask, s3, s2)
        s3 = tl.where(mask, tl.load(stack_ptr + (sp - 4) * stride + slot,
                                    mask=mask & (sp >= 4), other=0), s3)
    return value, sp, s0, s1, s2, s3


@_jit
def _visit(pairs, stack_ptr, slot, stride, ox, oy, oz, ix, iy, iz, neg_x, neg_y, neg_z,
           t_lo, best_t, visit, node, sp, cur, s0, s1, s2, s3, EXIT: tl.constexpr,
           VEC: tl.constexpr, SANITIZE: tl.constexpr, REGS: tl.constexpr):
    """TRAVERSE for the lanes in ``visit``: one row of ``pairs`` (both children's boxes and
    links, four 16-byte loads); go to the nearer hit child, push the farther. Returns the
    lanes' new ``(node, sp, cur, s0, s1, s2, s3)``; node = cur = -1: pop next."""
    row = _row(pairs, node, 16)  # lanes not in `visit` mask their results
    ax0, ax1, bx0, bx1 = _load4(row, 0, VEC)
    ay0, ay1, by0, by1 = _load4(row, 4, VEC)
    az0, az1, bz0, bz1 = _load4(row, 8, VEC)
    ref_a, ref_b, _ca, _cb = _load4(row, 12, VEC)
    ta, ha = _slab(ox, oy, oz, ix, iy, iz, neg_x, neg_y, neg_z, _f(ax0), _f(ax1), _f(ay0),
                   _f(ay1), _f(az0), _f(az1), t_lo, best_t, EXIT, SANITIZE)
    tb, hb = _slab(ox, oy, oz, ix, iy, iz, neg_x, neg_y, neg_z, _f(bx0), _f(bx1), _f(by0),
                   _f(by1), _f(bz0), _f(bz1), t_lo, best_t, EXIT, SANITIZE)
    ha = ha & visit
    hb = hb & visit
    b_first = hb & (~ha | (tb < ta))
    both = ha & hb
    sp, s0, s1, s2, s3 = _push(stack_ptr, slot, stride, sp, tl.where(b_first, ref_a, ref_b),
                               both, s0, s1, s2, s3, REGS)
    node = tl.where(visit, NONE, node)
    node, cur = _dispatch(ha | hb, tl.where(b_first, ref_b, ref_a), node, cur)
    return node, sp, cur, s0, s1, s2, s3


@_jit
def _intersect(tris, ox, oy, oz, dx, dy, dz, t_lo, test, cur,
               best_t, best_row, best_tri, best_u, best_v, VEC: tl.constexpr):
    """INTERSECT for the lanes in ``test``: Möller–Trumbore against row ``cur`` (three
    16-byte loads); keeps the nearest hit (ties: lower original index). Returns the updated
    best, the hit mask and the next row (-1 after the row flagged last in its leaf)."""
    row = _row(tris, cur, 12)  # lanes not in `test` mask their results
    v0x, v0y, v0z, tri = _load4(row, 0, VEC)
    e1x, e1y, e1z, _w = _load4(row, 4, VEC)
    e2x, e2y, e2z, last = _load4(row, 8, VEC)
    v0x, v0y, v0z = _f(v0x), _f(v0y), _f(v0z)
    e1x, e1y, e1z = _f(e1x), _f(e1y), _f(e1z)
    e2x, e2y, e2z = _f(e2x), _f(e2y), _f(e2z)
    px = dy * e2z - dz * e2y
    py = dz * e2x - dx * e2z
    pz = dx * e2y - dy * e2x
    det = e1x * px + e1y * py + e1z * pz
    inv = _rcp(det, VEC)
    sx = ox - v0x
    sy = oy - v0y
    sz = oz - v0z
    u = (sx * px + sy * py + sz * pz) * inv
    qx = sy * e1z - sz * e1y
    qy = sz * e1x - sx * e1z
    qz = sx * e1y - sy * e1x
    v = (dx * qx + dy * qy + dz * qz) * inv
    t = (e2x * qx + e2y * qy + e2z * qz) * inv
    # u >= 0, v >= 0, u + v <= 1 as one test, exactly: 1 - s rounds to a value of the
    # sign of the exact 1 - s (s = 1 + 2^-23 is the float after 1), and the NaN-propagating
    # min fails the test for a NaN u or v as the comparisons do. It also stands for det != 0:
    # det = +-0 makes 1/det infinite, so u and v are +-inf or NaN and fail it. Written as
    # the separate comparisons, the compiler packs the flags into bits and unpacks them
    # (~10 more instructions per test; bench/results/nvidia-h200/lab3_rows/).
    inside = tl.minimum(tl.minimum(u, v, propagate_nan=tl.PropagateNan.ALL), 1.0 - (u + v),
                        propagate_nan=tl.PropagateNan.ALL) >= 0.0
    hit = test & inside & (t >= t_lo) & (t <= best_t) & ((t < best_t) | (tri < best_tri))
    nxt = tl.where(test, tl.where(last != 0, -1, cur + 1), cur)
    return (tl.where(hit, t, best_t), tl.where(hit, cur, best_row), tl.where(hit, tri, best_tri),
            tl.where(hit, u, best_u), tl.where(hit, v, best_v), hit, nxt)


@_jit
def _test_leaves(tris, ox, oy, oz, dx, dy, dz, t_lo, alive, cur, best_t, best_row, best_tri,
                 best_u, best_v, ANY_HIT: tl.constexpr, VEC: tl.constexpr,
                 TRIS: tl.constexpr, UNIFORM: tl.constexpr):
    """INTERSECT: up to TRIS rows of each lane's pending leaf (``_intersect``); with
    UNIFORM, a test no lane needs is skipped (a vote). Any hit ends a lane's walk. Returns
    ``(alive, cur, best_t, best_row, best_tri, best_u, best_v)``."""
    for _k in tl.static_range(TRIS):
        test = alive & (cur >= 0)
        hit = test & (cur < -1)  # cur >= -1 always: no hit where the test is skipped
        if UNIFORM:
            if tl.max(test.to(tl.int32), axis=0) > 0:
                best_t, best_row, best_tri, best_u, best_v, hit, cur = _intersect(
                    tris, ox, oy, oz, dx, dy, dz, t_lo, test, cur,
                    best_t, best_row, best_tri, best_u, best_v, VEC)
        else:
            best_t, best_row, best_tri, best_u, best_v, hit, cur = _intersect(
                tris, ox, oy, oz, dx, dy, dz, t_lo, test, cur,
                best_t, best_row, best_tri, best_u, best_v, VEC)
        if ANY_HIT:
            alive = alive & ~hit
    return alive, cur, best_t, best_row, best_tri, best_u, best_v


@_jit
def _start_waiting(alive, node, cur, SPECULATE: tl.constexpr):
    """Speculative traversal: a leaf waiting in ``node`` becomes the pending leaf once the
    current one is done."""
    if SPECULATE:
        waiting = alive & (cur < 0) & (node < 0) & (node != NONE)
        cur = tl.where(waiting, -1 - node, cur)
        node = tl.where(waiting, NONE, node)
    return node, cur


@_jit
def _pop_or_finish(stack_ptr, slot, stride, alive, node, cur, sp, s0, s1, s2, s3,
                   REGS: tl.constexpr, SPECULATE: tl.constexpr):
    """A lane with no node pops its stack; with an empty stack and no leaf work it is done.
    Without SPECULATE a lane with leaf work waits for it before popping."""
    no_node = alive & (node == NONE)
    alive = alive & ~(no_node & (cur < 0) & (sp == 0))
    if SPECULATE:  # traverse on while the leaf's triangles are tested
        pop = no_node & (sp > 0)
    else:
        pop = no_node & (cur < 0) & (sp > 0)
    ref, sp, s0, s1, s2, s3 = _pop(stack_ptr, slot, stride, sp, pop, s0, s1, s2, s3, REGS)
    node, cur = _dispatch(pop, ref, node, cur)
    return alive, node, cur, sp, s0, s1, s2, s3


@_jit
def _start(root, root_ref, ox, oy, oz, dx, dy, dz, t_lo, t_hi, alive, EXIT: tl.constexpr,
           VEC: tl.constexpr, SANITIZE: tl.constexpr):
    """A walk's start per lane: the inverse direction and its signs, and, for the lanes of
    ``alive`` whose ray enters the root's box (row 0 of the float ``nodes``), the root as
    the next node (or pending leaf). Returns ``(ix, iy, iz, neg_x, neg_y, neg_z, alive,
    node, cur)``."""
    ix = _rcp(dx, VEC)  # IEEE: 1/+-0 = +-inf, which the slab test expects
    iy = _rcp(dy, VEC)
    iz = _rcp(dz, VEC)
    neg_x = ix.to(tl.int32, bitcast=True) < 0  # the sign bit: -0 counts as negative
    neg_y = iy.to(tl.int32, bitcast=True) < 0
    neg_z = iz.to(tl.int32, bitcast=True) < 0
    zero_i = tl.zeros(ox.shape, tl.int32)
    lx = tl.load(root + zero_i + 0)
    ly = tl.load(root + zero_i + 1)
    lz = tl.load(root + zero_i + 2)
    hx = tl.load(root + zero_i + 3)
    hy = tl.load(root + zero_i + 4)
    hz = tl.load(root + zero_i + 5)
    _, in_root = _slab(ox, oy, oz, ix, iy, iz, neg_x, neg_y, neg_z, lx, hx, ly, hy, lz, hz,
                       t_lo, t_hi, EXIT, SANITIZE)
    alive = alive & in_root
    node = zero_i + NONE  # the pair row to visit next (or a leaf waiting); NONE: none
    cur = zero_i - 1  # the leaf row to test next; -1: none
    node, cur = _dispatch(alive, zero_i + root_ref, node, cur)
    return ix, iy, iz, neg_x, neg_y, neg_z, alive, node, cur


@_jit
def _while_round(pairs, tris, stack_ptr, slot, stride, ox, oy, oz, dx, dy, dz, ix, iy, iz,
                 neg_x, neg_y, neg_z, t_lo, alive, node, cur, sp, s0, s1, s2, s3, best_t,
                 best_row, best_tri, best_u, best_v, ANY_HIT: tl.constexpr,
                 EXIT: tl.constexpr, VEC: tl.constexpr, SANITIZE: tl.constexpr,
                 REGS: tl.constexpr, TRIS: tl.constexpr, SPECULATE: tl.constexpr):
    """One round of Aila & Laine's *while-while* loop, the shape of the CUDA C kernel: the
    program traverses while some lane still looks for a leaf (a lane that found one waits
    or, with SPECULATE, traverses on and parks one more), then tests triangles while some
    lane has leaf work, then pops. A warp running that C code diverges the same way; here
    each inner loop is a vote over the lanes. Returns the lanes' new state ``(alive, node,
    cur, sp, s0..s3, best_t, best_row, best_tri, best_u, best_v)``."""
    # TRAVERSE (and pop) until every lane has a leaf or is done.
    searching = tl.reduce((alive & (node >= 0) & (cur < 0)).to(tl.int32), 0, _or)
    while searching != 0:
        node, sp, cur, s0, s1, s2, s3 = _visit(
            pairs, stack_ptr, slot, stride, ox, oy, oz, ix, iy, iz, neg_x, neg_y, neg_z,
            t_lo, best_t, alive & (node >= 0), node, sp, cur, s0, s1, s2, s3, EXIT, VEC,
            SANITIZE, REGS)
        alive, node, cur, sp, s0, s1, s2, s3 = _pop_or_finish(
            stack_ptr, slot, stride, alive, node, cur, sp, s0, s1, s2, s3, REGS, SPECULATE)
        searching = tl.reduce((alive & (node >= 0) & (cur < 0)).to(tl.int32), 0, _or)
    # INTERSECT while some lane has leaf work (a parked leaf follows its predecessor).
    testing = tl.reduce((alive & (cur >= 0)).to(tl.int32), 0, _or)
    while testing != 0:
        alive, cur, best_t, best_row, best_tri, best_u, best_v = _test_leaves(
            tris, ox, oy, oz, dx, dy, dz, t_lo, alive, cur, best_t, best_row, best_tri,
            best_u, best_v, ANY_HIT, VEC, TRIS, False)
        node, cur = _start_waiting(alive, node, cur, SPECULATE)
        testing = tl.reduce((alive & (cur >= 0)).to(tl.int32), 0, _or)
    # POP: lanes left with no node go on from their stack (or finish).
    alive, node, cur, sp, s0, s1, s2, s3 = _pop_or_finish(
        stack_ptr, slot, stride, alive, node, cur, sp, s0, s1, s2, s3, REGS, SPECULATE)
    return alive, node, cur, sp, s0, s1, s2, s3, best_t, best_row, best_tri, best_u, best_v


@_jit
def _while_while(pairs, tris, stack_ptr, slot, stride, ox, oy, oz, dx, dy, dz, ix, iy, iz,
                 neg_x, neg_y, neg_z, t_lo, alive, node, cur, sp, s0, s1, s2, s3, best_t,
                 best_row, best_tri, best_u, best_v, ANY_HIT: tl.constexpr,
                 EXIT: tl.constexpr, VEC: tl.constexpr, SANITIZE: tl.constexpr,
                 REGS: tl.constexpr, TRIS: tl.constexpr, SPECULATE: tl.constexpr):
    """The walk as rounds of ``_while_round`` while some lane is alive: same state and
    results as the *if-if* loop of ``_trace``."""
    votes = tl.reduce(alive.to(tl.int32), 0, _or)
    while votes != 0:
        (alive, node, cur, sp, s0, s1, s2, s3, best_t, best_row, best_tri, best_u,
         best_v) = _while_round(
            pairs, tris, stack_ptr, slot, stride, ox, oy, oz, dx, dy, dz, ix, iy, iz, neg_x,
            neg_y, neg_z, t_lo, alive, node, cur, sp, s0, s1, s2, s3, best_t, best_row,
            best_tri, best_u, best_v, ANY_HIT, EXIT, VEC, SANITIZE, REGS, TRIS, SPECULATE)
        votes = tl.reduce(alive.to(tl.int32), 0, _or)
    return best_t, best_row, best_u, best_v


@_jit
def _trace(pairs, root, tris, root_ref, stack_ptr, slot, stride,
           ox, oy, oz, dx, dy, dz, t_lo, t_hi, alive, ANY_HIT: tl.constexpr,
           EXIT: tl.constexpr, UNIFORM: tl.constexpr, VEC: tl.constexpr,
           SANITIZE: tl.constexpr, REGS: tl.constexpr, TRIS: tl.constexpr,
           SPECULATE: tl.constexpr, WHILE: tl.constexpr):
    """Walk the BVH for every lane with ``alive`` set: the TRAVERSE/INTERSECT/POP loop.

    pairs, tris: the int32 views of the ``pairs`` and ``triangles`` layouts; root: the
    float ``nodes`` (only row 0, the root's box, is read); root_ref: where the walk starts.
    UNIFORM: skip a stage in a step where no lane of the program needs it (a branch on a
    vote over the lanes, what a warp does when none of its threads takes a branch), instead
    of running it with every lane masked off. VEC: 16-byte loads (compiled kernels);
    SANITIZE: replace the slab test's NaN before min/max (the interpreter's keep NaN).
    REGS: stack entries kept in registers (0 or 4, see _push); TRIS: triangle tests per
    step (1 or 2: a lane with leaf work tests up to TRIS rows of its leaf per step);
    SPECULATE: a lane with leaf work keeps traversing (pops and visits nodes) meanwhile,
    parking at most one more leaf (Aila & Laine's speculative traversal), so it takes part
    in both stages of a step instead of idling through one.
    Returns ``(t, row, u, v)``: row (int32) of the hit in the triangle layout, -1 on a miss.
    """
    zero_i = tl.zeros(ox.shape, tl.int32)
    best_t = t_hi
    best_row = zero_i - 1
    best_tri = zero_i + 2147483647  # original index, for the tie rule
    best_u = tl.zeros(ox.shape, tl.float32)
    best_v = tl.zeros(ox.shape, tl.float32)
    ix, iy, iz, neg_x, neg_y, neg_z, alive, node, cur = _start(
        root, root_ref, ox, oy, oz, dx, dy, dz, t_lo, t_hi, alive, EXIT, VEC, SANITIZE)
    if REGS == LOCAL_STACK:
        slot = _local_stack(zero_i)
    sp = zero_i
    s0 = zero_i
    s1 = zero_i
    s2 = zero_i
    s3 = zero_i
    if WHILE:
        best_t, best_row, best_u, best_v = _while_while(
            pairs, tris, stack_ptr, slot, stride, ox, oy, oz, dx, dy, dz, ix, iy, iz,
            neg_x, neg_y, neg_z, t_lo, alive, node, cur, sp, s0, s1, s2, s3, best_t,
            best_row, best_tri, best_u, best_v, ANY_HIT, EXIT, VEC, SANITIZE, REGS, TRIS,
            SPECULATE)
        return best_t, best_row, best_u, best_v
    # One vote per step for the loop and the TRAVERSE skip: bit 0 some lane alive, bit 1
    # some lane at an interior node.
    votes = tl.reduce(alive.to(tl.int32) | ((node >= 0).to(tl.int32) << 1), 0, _or)
    while (votes & 1) != 0:
        # 1. TRAVERSE
        visit = alive & (node >= 0)
        if UNIFORM:
            if (votes & 2) != 0:
                node, sp, cur, s0, s1, s2, s3 = _visit(
                    pairs, stack_ptr, slot, stride, ox, oy, oz, ix, iy, iz, neg_x, neg_y,
                    neg_z, t_lo, best_t, visit, node, sp, cur, s0, s1, s2, s3, EXIT, VEC,
                    SANITIZE, REGS)
        else:
            node, sp, cur, s0, s1, s2, s3 = _visit(
                pairs, stack_ptr, slot, stride, ox, oy, oz, ix, iy, iz, neg_x, neg_y, neg_z,
                t_lo, best_t, visit, node, sp, cur, s0, s1, s2, s3, EXIT, VEC, SANITIZE, REGS)
        # 2. INTERSECT up to TRIS triangles of the pending leaf
        alive, cur, best_t, best_row, best_tri, best_u, best_v = _test_leaves(
            tris, ox, oy, oz, dx, dy, dz, t_lo, alive, cur, best_t, best_row, best_tri,
            best_u, best_v, ANY_HIT, VEC, TRIS, UNIFORM)
        # 3. POP: a lane with no node and no leaf work pops its stack (or finishes)
        node, cur = _start_waiting(alive, node, cur, SPECULATE)
        alive, node, cur, sp, s0, s1, s2, s3 = _pop_or_finish(
            stack_ptr, slot, stride, alive, node, cur, sp, s0, s1, s2, s3, REGS, SPECULATE)
        votes = tl.reduce(alive.to(tl.int32) | ((alive & (node >= 0)).to(tl.int32) << 1), 0,
                          _or)
    return best_t, best_row, best_u, best_v


@_jit
def _valid(ox, oy, oz, dx, dy, dz):
    """Rays that can hit: finite components and a nonzero direction."""
    inf = float("inf")
    return ((tl.abs(ox) < inf) & (tl.abs(oy) < inf) & (tl.abs(oz) < inf)
            & (tl.abs(dx) < inf) & (tl.abs(dy) < inf) & (tl.abs(dz) < inf)
            & ((dx != 0.0) | (dy != 0.0) | (dz != 0.0)))


@_jit
def _load_rays(o_ptr, d_ptr, tlo_ptr, tlo_value, thi_ptr, thi_value, ray, live,
               TLO_ARRAY: tl.constexpr, THI_ARRAY: tl.constexpr):
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


@_jit
def _trace_kernel(o_ptr, d_ptr, tlo_ptr, tlo_value, thi_ptr, thi_value, pairs, root, tris,
                  root_ref, stack_ptr, t_ptr, id_ptr, u_ptr, v_ptr, n_rays, stride,
                  BLOCK: tl.constexpr, ANY_HIT: tl.constexpr, EXIT: tl.constexpr,
                  UNIFORM: tl.constexpr, VEC: tl.constexpr, SANITIZE: tl.constexpr,
                  REGS: tl.constexpr, TRIS: tl.constexpr, SPECULATE: tl.constexpr,
                  WHILE: tl.constexpr, TLO_ARRAY: tl.constexpr, THI_ARRAY: tl.constexpr):
    slot = tl.program_id(0) * BLOCK + tl.arange(0, BLOCK)
    live = slot < n_rays
    ox, oy, oz, dx, dy, dz, t_lo, t_hi, alive = _load_rays(
        o_ptr, d_ptr, tlo_ptr, tlo_value, thi_ptr, thi_value, slot, live, TLO_ARRAY, THI_ARRAY)
    t, row, u, v = _trace(pairs, root, tris, root_ref, stack_ptr, slot, stride,
                          ox, oy, oz, dx, dy, dz, t_lo, t_hi, alive, ANY_HIT, EXIT, UNIFORM,
                          VEC, SANITIZE, REGS, TRIS, SPECULATE, WHILE)
    _store_row_hits(tris, t_ptr, id_ptr, u_ptr, v_ptr, slot, live, t, row, u, v)


@_jit
def _refill_kernel(o_ptr, d_ptr, tlo_ptr, tlo_value, thi_ptr, thi_value, pairs, root, tris,
                   root_ref, stack_ptr, counter, t_ptr, id_ptr, u_ptr, v_ptr, n_rays, stride,
                   BLOCK: tl.constexpr, ANY_HIT: tl.constexpr, EXIT: tl.constexpr,
                   VEC: tl.constexpr, SANITIZE: tl.constexpr, REGS: tl.constexpr,
                   TRIS: tl.constexpr, SPECULATE: tl.constexpr, REFILL: tl.constexpr,
                   TLO_ARRAY: tl.constexpr, THI_ARRAY: tl.constexpr):
    """The while-while walk in persistent programs that replace finished rays (Aila &
    Laine's dynamic ray fetch): a program runs rounds of ``_while_round``; after each, the
    lanes whose ray is done write its hit, and once at least REFILL lanes are free they
    take the next rays from a global counter (one atomic per program: the free lanes'
    ranks from a prefix sum). A lane's stack is its own for the program's lifetime, as in
    ``_trace_kernel``; ``ray`` = -1: the lane holds no ray."""
    slot = tl.program_id(0) * BLOCK + tl.arange(0, BLOCK)
    zero_i = tl.zeros([BLOCK], tl.int32)
    zero_f = tl.zeros([BLOCK], tl.float32)
    if REGS == LOCAL_STACK:
        slot = _local_stack(zero_i)
    ray = zero_i - 1
    ox, oy, oz, dx, dy, dz = zero_f, zero_f, zero_f, zero_f, zero_f, zero_f
    ix, iy, iz, t_lo = zero_f, zero_f, zero_f, zero_f
    neg_x, neg_y, neg_z, alive = ray >= 0, ray >= 0, ray >= 0, ray >= 0
    node, cur, sp, s0, s1, s2, s3 = zero_i + NONE, zero_i - 1, zero_i, zero_i, zero_i, zero_i, zero_i
    best_t, best_row, best_tri, best_u, best_v = zero_f, zero_i - 1, zero_i, zero_f, zero_f
    more = n_rays > 0  # rays left to take
    busy = more.to(tl.int32)
    while busy != 0:
        free = ray < 0
        n_free = tl.sum(free.to(tl.int32), 0)
        if more & (n_free >= REFILL):
            first = tl.atomic_add(counter, n_free)
            fresh = first + tl.cumsum(free.to(tl.int32), 0) - 1
            take = free & (fresh < n_rays)
            more = first + n_free < n_rays
            ray = tl.where(take, fresh, ray)
            (nox, noy, noz, ndx, ndy, ndz, nlo, nhi, nalive) = _load_rays(
                o_ptr, d_ptr, tlo_ptr, tlo_value, thi_ptr, thi_value, fresh, take, TLO_ARRAY,
                THI_ARRAY)
            nix, niy, niz, nnx, nny, nnz, nalive, nnode, ncur = _start(
                root, root_ref, nox, noy, noz, ndx, ndy, ndz, nlo, nhi, nalive, EXIT, VEC,
                SANITIZE)
            ox, oy, oz = tl.where(take, nox, ox), tl.where(take, noy, oy), tl.where(take, noz, oz)
            dx, dy, dz = tl.where(take, ndx, dx), tl.where(take, ndy, dy), tl.where(take, ndz, dz)
            ix, iy, iz = tl.where(take, nix, ix), tl.where(take, niy, iy), tl.where(take, niz, iz)
            neg_x = tl.where(take, nnx, neg_x)
            neg_y = tl.where(take, nny, neg_y)
            neg_z = tl.where(take, nnz, neg_z)
            t_lo = tl.where(take, nlo, t_lo)
            alive = tl.where(take, nalive, alive)
            node = tl.where(take, nnode, node)
            cur = tl.where(take, ncur, cur)
            sp = tl.where(take, 0, sp)
            best_t = tl.where(take, nhi, best_t)
            best_row = tl.where(take, -1, best_row)
            best_tri = tl.where(take, 2147483647, best_tri)
            best_u = tl.where(take, 0.0, best_u)
            best_v = tl.where(take, 0.0, best_v)
        (alive, node, cur, sp, s0, s1, s2, s3, best_t, best_row, best_tri, best_u,
         best_v) = _while_round(
            pairs, tris, stack_ptr, slot, stride, ox, oy, oz, dx, dy, dz, ix, iy, iz, neg_x,
            neg_y, neg_z, t_lo, alive, node, cur, sp, s0, s1, s2, s3, best_t, best_row,
            best_tri, best_u, best_v, ANY_HIT, EXIT, VEC, SANITIZE, REGS, TRIS, SPECULATE)
        done = (ray >= 0) & ~alive
        _store_row_hits(tris, t_ptr, id_ptr, u_ptr, v_ptr, ray, done, best_t, best_row, best_u,
                    best_v)
        ray = tl.where(done, -1, ray)
        busy = tl.reduce((ray >= 0).to(tl.int32), 0, _or) | more.to(tl.int32)


@_jit
def _pow(x, s):
    """``x ** s`` for x >= 0 as torch computes it (``0 ** 0 = 1``, ``0 ** s = 0``)."""
    safe = tl.where(x > 0.0, x, 1.0)
    return tl.where(x > 0.0, tl.exp2(s * tl.log2(safe)), tl.where(s == 0.0, 1.0, 0.0))


@_jit
def _whitted_kernel(o_ptr, d_ptr, out_ptr, n_rays, pairs, root, tris_f, tris_i, root_ref,
                    stack_ptr, stride, mat_id_ptr, mat_ptr, light_ptr,
                    amb_r, amb_g, amb_b, bg_r, bg_g, bg_b, offset,
                    N_LIGHTS: tl.constexpr, MAX_DEPTH: tl.constexpr,
                    BLOCK: tl.constexpr, EXIT: tl.constexpr, UNIFORM: tl.constexpr,
                    VEC: tl.constexpr, SANITIZE: tl.constexpr, REGS: tl.constexpr,
                    TRIS: tl.constexpr, SPECULATE: tl.constexpr):
    """The uber kernel: per lane, primary ray -> (closest hit -> shade with shadow rays ->
    mirror bounce) up to ``max_depth`` bounces; the radiance recursion unrolled into a
    loop with a throughput weight (``L += kr * radiance(...)`` becomes ``weight *= kr``).

    The light count and the depth are compile-time constants: the loops stay loops (not
    unrolled), but their trip counts are known, which also keeps the interpreter of older
    Tritons (whose scalar arguments are 1-element arrays) able to run them."""
    slot = tl.program_id(0) * BLOCK + tl.arange(0, BLOCK)
    live = slot < n_rays
    ox = tl.load(o_ptr + slot * 3 + 0, mask=live, other=0.0)
    oy = tl.load(o_ptr + slot * 3 + 1, mask=live, other=0.0)
    oz = tl.load(o_ptr + slot * 3 + 2, mask=live, other=0.0)
    dx = tl.load(d_ptr + slot * 3 + 0, mask=live, other=1.0)
    dy = tl.load(d_ptr + slot * 3 + 1, mask=live, other=1.0)
    dz = tl.load(d_ptr + slot * 3 + 2, mask=live, other=1.0)
    zero = tl.zeros([BLOCK], tl.float32)
    inf = zero + float("inf")
    # A primary ray with a NaN/inf component or a zero direction misses: background.
    finite = ((tl.abs(ox) < inf) & (tl.abs(oy) < inf) & (tl.abs(oz) < inf)
              & (tl.abs(dx) < inf) & (tl.abs(dy) < inf) & (tl.abs(dz) < inf)
              & ((dx != 0.0) | (dy != 0.0) | (dz != 0.0)))
    w_r = zero + 1.0
    w_g = zero + 1.0
    w_b = zero + 1.0
    c_r = tl.where(finite, zero, bg_r)
    c_g = tl.where(finite, zero, bg_g)
    c_b = tl.where(finite, zero, bg_b)
    active = live & finite
    inv_pi = 0.3183098861837907
    for depth in range(MAX_DEPTH + 1):
        t, row, _u, _v = _trace(pairs, root, tris_i, root_ref, stack_ptr, slot, stride,
                                ox, oy, oz, dx, dy, dz, zero, inf, active, False, EXIT,
                                UNIFORM, VEC, SANITIZE, REGS, TRIS, SPECULATE, False)
        hit = active & (row >= 0)
        miss = active & (row < 0)
        c_r += tl.where(miss, w_r * bg_r, 0.0)
        c_g += tl.where(miss, w_g * bg_g, 0.0)
        c_b += tl.where(miss, w_b * bg_b, 0.0)
        active = hit
        # SHADE: geometric normal from the stored edges, facing the ray.
        base = tris_f + row * 12
        e1x = tl.load(base + 4, mask=hit, other=0.0)
        e1y = tl.load(base + 5, mask=hit, other=0.0)
        e1z = tl.load(base + 6, mask=hit, other=1.0)
        e2x = tl.load(base + 8, mask=hit, other=0.0)
        e2y = tl.load(base + 9, mask=hit, other=1.0)
        e2z = tl.load(base + 10, mask=hit, other=0.0)
        tri = tl.load(tris_i + row * 12 + 3, mask=hit, other=0)
        nx = e1y * e2z - e1z * e2y
        ny = e1z * e2x - e1x * e2z
        nz = e1x * e2y - e1y * e2x
        n_len = tl.sqrt(nx * nx + ny * ny + nz * nz)
        flip = tl.where(nx * dx + ny * dy + nz * dz > 0.0, -1.0, 1.0) / n_len
        nx = nx * flip
        ny = ny * flip
        nz = nz * flip
        px = ox + t * dx
        py = oy + t * dy
        pz = oz + t * dz
        scale = offset * tl.maximum(tl.maximum(tl.abs(px), tl.abs(py)),
                                    tl.maximum(tl.abs(pz), 1.0))
        px = px + nx * scale
        py = py + ny * scale
        pz = pz + nz * scale
        m = tl.load(mat_id_ptr + tri, mask=hit, other=0)
        mb = mat_ptr + m * 12
        kd_r = tl.load(mb + 0, mask=hit, other=0.0)
        kd_g = tl.load(mb + 1, mask=hit, other=0.0)
        kd_b = tl.load(mb + 2, mask=hit, other=0.0)
        ks_r = tl.load(mb + 3, mask=hit, other=0.0)
        ks_g = tl.load(mb + 4, mask=hit, other=0.0)
        ks_b = tl.load(mb + 5, mask=hit, other=0.0)
        kr_r = tl.load(mb + 6, mask=hit, other=0.0)
        kr_g = tl.load(mb + 7, mask=hit, other=0.0)
        kr_b = tl.load(mb + 8, mask=hit, other=0.0)
        shin = tl.load(mb + 9, mask=hit, other=0.0)
        spec_norm = (shin + 8.0) * (0.125 * inv_pi)
        c_r += tl.where(hit, w_r * amb_r * kd_r, 0.0)
        c_g += tl.where(hit, w_g * amb_g * kd_g, 0.0)
        c_b += tl.where(hit, w_b * amb_b * kd_b, 0.0)
        for li in range(N_LIGHTS):
            lb = light_ptr + li * 8
            lpx = tl.load(lb + 0)
            lpy = tl.load(lb + 1)
            lpz = tl.load(lb + 2)
            is_point = tl.load(lb + 3) > 0.5
            e_r = tl.load(lb + 4)
            e_g = tl.load(lb + 5)
            e_b = tl.load(lb + 6)
            light_reach = tl.load(lb + 7)  # point: OFFSET max(1, |P|inf); directional: unused
            tox = lpx - px
            toy = lpy - py
            toz = lpz - pz
            dist = tl.sqrt(tox * tox + toy * toy + toz * toz)
            lx = tl.where(is_point, tox / dist, lpx)
            ly = tl.where(is_point, toy / dist, lpy)
            lz = tl.where(is_point, toz / dist, lpz)
            falloff = tl.where(is_point, 1.0 / (dist * dist), 1.0)
            s_max = tl.where(is_point, dist - light_reach, inf)
            ndl = nx * lx + ny * ly + nz * lz
            want = hit & (ndl > 0.0)
            _t, occluder, _u2, _v2 = _trace(pairs, root, tris_i, root_ref, stack_ptr, slot,
                                            stride, px, py, pz, lx, ly, lz, zero, s_max, want,
                                            True, EXIT, UNIFORM, VEC, SANITIZE, REGS, TRIS,
                                            SPECULATE, False)
            lit = want & (occluder < 0)
            hx = lx - dx
            hy = ly - dy
            hz = lz - dz
            h_len = tl.sqrt(hx * hx + hy * hy + hz * hz)
            ndh = tl.maximum((nx * hx + ny * hy + nz * hz) / h_len, 0.0)
            spec = spec_norm * _pow(ndh, shin)
            g = falloff * ndl
            c_r += tl.where(lit, w_r * e_r * g * (kd_r * inv_pi + ks_r * spec), 0.0)
            c_g += tl.where(lit, w_g * e_g * g * (kd_g * inv_pi + ks_g * spec), 0.0)
            c_b += tl.where(lit, w_b * e_b * g * (kd_b * inv_pi + ks_b * spec), 0.0)
        # Mirror bounce: the next iteration traces r = normalize(d - 2 (d.n) n) from p_off.
        active = hit & ((kr_r > 0.0) | (kr_g > 0.0) | (kr_b > 0.0))
        dn2 = 2.0 * (dx * nx + dy * ny + dz * nz)
        dx = dx - dn2 * nx
        dy = dy - dn2 * ny
        dz = dz - dn2 * nz
        r_len = tl.sqrt(dx * dx + dy * dy + dz * dz)  # renormalised, as the contract says
        dx = dx / r_len
        dy = dy / r_len
        dz = dz / r_len
        ox = px
        oy = py
        oz = pz
        w_r = w_r * kr_r
        w_g = w_g * kr_g
        w_b = w_b * kr_b
    tl.store(out_ptr + slot * 3 + 0, c_r, mask=live)
    tl.store(out_ptr + slot * 3 + 1, c_g, mask=live)
    tl.store(out_ptr + slot * 3 + 2, c_b, mask=live)


# --------------------------------------------------------------------------------------
# Launchers
# --------------------------------------------------------------------------------------

def triton_available() -> bool:
    return triton is not None


def interpreting() -> bool:
    """True when the kernels run in Triton's CPU interpreter (``TRITON_INTERPRET=1``)."""
    _require_triton()
    return type(_trace_kernel).__name__ == "InterpretedFunction"


def _check_walk(stack_regs: int, tris_per_step: int, loop: str = DEFAULT_LOOP) -> None:
    if loop not in LOOPS:
        raise ValueError(f"loop: expected one of {LOOPS}, got {loop!r}")
    if stack_regs not in (0, 4) or isinstance(stack_regs, bool):
        raise ValueError(f"stack_regs: expected 0 or 4, got {stack_regs!r}")
    if tris_per_step not in (1, 2) or isinstance(tris_per_step, bool):
        raise ValueError(f"tris_per_step: expected 1 or 2, got {tris_per_step!r}")


def _check_refill(refill, programs, block: int, loop: str) -> int:
    """The free lanes at which a program takes new rays (0: no refill) for ``refill``."""
    if refill is None:
        refill = min(DEFAULT_REFILL, block) if loop == "while" else 0
    if isinstance(refill, bool) or not isinstance(refill, int) or not 0 <= refill <= block:
        raise ValueError(f"refill: expected None, 0 (off) or free lanes from 1 to block "
                         f"({block}), got {refill!r}")
    if refill and loop != "while":
        raise ValueError(f"refill: the persistent walk runs the while-while loop, got "
                         f"loop={loop!r} (refill=0 or None for the if-if loop)")
    if programs is not None and (not refill or isinstance(programs, bool)
                                 or not isinstance(programs, int) or programs < 1):
        raise ValueError(f"programs: expected None, or an int >= 1 with refill, got "
                         f"{programs!r} (refill={refill})")
    return refill


def _default_programs(device: torch.device) -> int:
    """Persistent programs that fill the GPU: 32 per SM (the resident-block limit of Hopper
    and Ampere; more would only start once the rays are gone). Interpreted: 4."""
    if device.type != "cuda":
        return 4
    return 32 * torch.cuda.get_device_properties(device).multi_processor_count


def _check_launch(block: int, num_warps: int) -> None:
    for name, x in (("block", block), ("num_warps", num_warps)):
        if isinstance(x, bool) or not isinstance(x, int) or x < 1 or x & (x - 1):
            raise ValueError(f"{name}: expected a power of two, got {x!r}")
    if block < 32 * num_warps:
        raise ValueError(f"block: expected at least 32 lanes per warp ({32 * num_warps} for "
                         f"num_warps={num_warps}), got {block}")


def _device_check(device: torch.device) -> None:
    if not interpreting() and device.type != "cuda":
        raise ValueError(f"origins: the compiled Triton kernels need CUDA tensors, got {device} "
                         "(for the CPU, set TRITON_INTERPRET=1 before importing triton, or use "
                         "course.kernels.flat_bvh.trace_flat_torch)")


def _stack(n: int, block: int, device, bvh: FlatBVH,
           local: bool = False) -> tuple[torch.Tensor, int]:
    """The per-lane stacks: (entries, lanes) int32, lanes = n rounded up to blocks;
    near-child-first traversal pushes at most one entry per interior level (depth - 1).
    local: the kernel keeps its stacks in local memory, so the buffer is a (1, 1)
    placeholder (the pointer argument must exist, nothing reads it)."""
    lanes = max(block, -(-n // block) * block)
    if local:
        return torch.empty(1, 1, dtype=torch.int32, device=device), lanes
    entries = max(1, min(STACK_DEPTH, bvh.depth - 1))
    return torch.empty(entries, lanes, dtype=torch.int32, device=device), lanes


@dataclass(frozen=True)
class TracerKernelInfo:
    """Resources of one compiled tracer kernel: registers, spills (32-bit words), static
    shared memory and local memory per thread in bytes (None under the interpreter), the
    launch's warps and lanes per program.

    Triton reports a kernel's whole local memory as its spills (local bytes / 4), so a
    kernel with ``stack="local"`` would count its 64-entry stack as 64 spills: ``n_spills``
    here is what is left beyond that stack, ``local_bytes`` all of it."""

    name: str
    n_regs: int | None
    n_spills: int | None
    shared_bytes: int | None
    num_warps: int
    block: int
    local_bytes: int | None = None

    def occupancy(self, arch=None):
        """``course.measure.occupancy.occupancy`` of this launch (Hopper preset by default: H100
        and H200 share the SM), or None when the registers are unknown."""
        from course.measure.occupancy import HOPPER_H100, occupancy

        if self.n_regs is None:
            return None
        return occupancy(arch or HOPPER_H100, self.n_regs, 32 * self.num_warps,
                         self.shared_bytes or 0)


def _info(name: str, handle, num_warps: int, block: int,
          stack_words: int = 0) -> TracerKernelInfo:
    """The kernel info of a launch's ``handle``; stack_words: the words of local memory
    the kernel declares itself (its local stack), not spills."""
    def field(obj, key):
        if obj is None:
            return None
        return obj.get(key) if isinstance(obj, dict) else getattr(obj, key, None)

    if handle is not None and field(handle, "n_regs") is None:
        init = getattr(handle, "_init_handles", None)  # binaries load lazily in recent Tritons
        if callable(init):
            init()
    words = field(handle, "n_spills")  # Triton: local memory bytes / 4
    return TracerKernelInfo(name, field(handle, "n_regs"),
                            None if words is None else max(0, words - stack_words),
                            field(field(handle, "metadata"), "shared"), num_warps, block,
                            None if words is None else 4 * words)


def _bvh_args(bvh: FlatBVH, device):
    if not isinstance(bvh, FlatBVH):
        raise TypeError(f"bvh: expected a course.kernels.flat_bvh.FlatBVH, got {type(bvh).__name__}")
    if bvh.nodes.device != device:
        raise ValueError(f"bvh: expected a BVH on {device} like the rays (bvh.to(device)), "
                         f"got {bvh.nodes.device}")
    # pairs has a row even for a one-leaf tree: masked-off lanes of the 16-byte loads read
    # row 0 of every array.
    pairs = bvh.pair_ints if len(bvh.pairs) else torch.zeros(1, 16, dtype=torch.int32,
                                                              device=device)
    return pairs, bvh.nodes, bvh.triangles, bvh.triangle_ints, bvh.root_ref


def trace_flat_triton(bvh: FlatBVH, origins, directions, t_min=0.0, t_max=math.inf, *,
                      any_hit: bool = False, block: int = DEFAULT_BLOCK,
                      num_warps: int = DEFAULT_NUM_WARPS,
                      uniform_branches: bool = DEFAULT_UNIFORM,
                      stack_regs: int = DEFAULT_STACK_REGS,
                      tris_per_step: int = DEFAULT_TRIS_PER_STEP,
                      speculate: bool = DEFAULT_SPECULATE, loop: str = DEFAULT_LOOP,
                      stack: str | None = DEFAULT_STACK, refill: int | None = None,
                      programs: int | None = None, return_info: bool = False):
    """Closest (or any) hit of each ray by the Triton BVH walk (one ray per lane).

    bvh: ``build_flat_bvh(...)`` on the rays' device; origins, directions: (N, 3) float
    (traced in float32); t_min, t_max: numbers or (N,) tensors; any_hit: stop at the first
    hit; block: lanes per program (a power of two, >= 32 num_warps); uniform_branches:
    skip a stage of a step that no lane of the program needs (see ``_trace``);
    stack_regs: the stack's top entries kept in registers (0 or 4); tris_per_step:
    triangle tests per step (1 or 2); speculate: keep traversing while a leaf is tested
    (see ``_trace``); loop: ``"if"``, one TRAVERSE and one INTERSECT stage per step, or
    ``"while"``, traverse while some lane looks for a leaf, then test while some lane has
    one (``_while_while``, the CUDA C kernel's shape; the default); stack: ``"global"``,
    each lane's entries in a scratch buffer, or ``"local"``, in the lane's local memory
    like CUDA C's (compiled only: the interpreter uses the buffer; needs ``stack_regs=0``);
    None (default): ``"local"``, or ``"global"`` with ``stack_regs=4``; refill: a number of
    lanes: persistent programs that take new rays from a global counter whenever at least
    that many of their lanes are free (Aila & Laine's dynamic ray fetch; ``block``: whole
    batches only; needs ``loop="while"``); 0: one program per ``block`` rays; None
    (default): ``DEFAULT_REFILL`` (0) with the while-while loop, 0 with the if-if loop;
    programs: with refill, the programs launched (default: 32 per SM, what fills a Hopper
    or Ampere GPU with one-warp programs). The defaults are the fastest launch measured on
    an H200 on primary and on diffuse rays together; ``refill=8`` is +15% on diffuse rays
    and -10% on primary ones, whose lanes finish together anyway.
    Returns float32 ``Hits``, or ``(Hits, TracerKernelInfo)`` with ``return_info``.
    """
    _require_triton()
    o, d, (t_lo, lo_value), (t_hi, hi_value) = check_ray_bounds(origins, directions, t_min,
                                                                t_max)
    _check_launch(block, num_warps)
    _check_walk(stack_regs, tris_per_step, loop)
    if stack is None:
        stack = "local" if stack_regs == 0 else "global"
    if stack not in STACKS:
        raise ValueError(f"stack: expected 'global', 'local' or None, got {stack!r}")
    if stack == "local" and stack_regs:
        raise ValueError(f"stack_regs: expected 0 with stack='local', got {stack_regs!r}")
    refill = _check_refill(refill, programs, block, loop)
    n, device = o.shape[0], o.device
    _device_check(device)
    pairs, root, _tris_f, tris, root_ref = _bvh_args(bvh, device)
    # One launch (and the refill counter's fill): the kernel itself leaves out the rays
    # that cannot hit (NaN/inf, zero direction, t_max < t_min), and numbers for
    # t_min/t_max stay numbers.
    out_t = torch.empty(n, dtype=torch.float32, device=device)
    out_id = torch.empty(n, dtype=torch.int64, device=device)
    out_u = torch.empty(n, dtype=torch.float32, device=device)
    out_v = torch.empty(n, dtype=torch.float32, device=device)
    handle = None
    compiled = not interpreting()
    local = stack == "local" and compiled  # the interpreter has no local memory
    if n and refill:
        # Persistent programs: the counter hands out the rays (one zeroed int32).
        grid = min(-(-n // block), programs or _default_programs(device))
        buffer, lanes = _stack(grid * block, block, device, bvh, local)
        counter = torch.zeros(1, dtype=torch.int32, device=device)
        with _ieee_quiet():
            handle = _refill_kernel[(grid,)](
                o, d, o if t_lo is None else t_lo, lo_value, o if t_hi is None else t_hi,
                hi_value, pairs, root, tris, root_ref, buffer, counter,
                out_t, out_id, out_u, out_v, n, lanes,
                BLOCK=block, ANY_HIT=bool(any_hit), EXIT=EXIT_SCALE, VEC=compiled,
                SANITIZE=not compiled, REGS=-1 if local else stack_regs, TRIS=tris_per_step,
                SPECULATE=bool(speculate), REFILL=refill, TLO_ARRAY=t_lo is not None,
                THI_ARRAY=t_hi is not None, num_warps=num_warps)
    elif n:
        buffer, lanes = _stack(n, block, device, bvh, local)
        with _ieee_quiet():
            handle = _trace_kernel[(lanes // block,)](
                o, d, o if t_lo is None else t_lo, lo_value, o if t_hi is None else t_hi,
                hi_value, pairs, root, tris, root_ref, buffer,
                out_t, out_id, out_u, out_v, n, lanes,
                BLOCK=block, ANY_HIT=bool(any_hit), EXIT=EXIT_SCALE,
                UNIFORM=bool(uniform_branches), VEC=compiled, SANITIZE=not compiled,
                REGS=-1 if local else stack_regs, TRIS=tris_per_step,  # -1: LOCAL_STACK
                SPECULATE=bool(speculate), WHILE=loop == "while",
                TLO_ARRAY=t_lo is not None, THI_ARRAY=t_hi is not None, num_warps=num_warps)
    hits = Hits(t=out_t, triangle=out_id, u=out_u, v=out_v)
    if return_info:
        name = "any_hit" if any_hit else "closest_hit"
        return hits, _info(name, handle, num_warps, block, STACK_DEPTH if local else 0)
    return hits


# --------------------------------------------------------------------------------------
# The uber kernel
# --------------------------------------------------------------------------------------

_TABLES: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _scene_tables(scene, device, offset: float):
    """Per-face material ids (F,) int32, materials (M, 12) float32 ``kd ks kr shininess``,
    lights (L, 8) float32 ``xyz, is_point, rgb, offset max(1, |P|inf)``, the light count,
    and the ambient and background colours as 6 floats, of a WhittedScene: built once per
    scene, device and offset (cached like its BVH), so a frame launches without host syncs."""
    names = ("vertices", "faces", "material", "kd", "ks", "shininess", "kr", "point_positions",
             "point_intensities", "dir_directions", "dir_irradiance", "ambient", "background")
    for name in names:
        if not isinstance(getattr(scene, name, None), torch.Tensor):
            raise TypeError(f"scene: expected a WhittedScene with a {name!r} tensor, "
                            f"got {type(scene).__name__}")
    key = (str(device), offset)
    try:
        cached = _TABLES.setdefault(scene, {})
    except TypeError:  # not weakly referenceable: no cache
        cached = {}
    if key in cached:
        return cached[key]
    f32 = {"dtype": torch.float32, "device": device}
    mats = torch.zeros(scene.kd.shape[0], 12, **f32)
    mats[:, 0:3], mats[:, 3:6], mats[:, 6:9] = scene.kd, scene.ks, scene.kr
    mats[:, 9] = scene.shininess
    pp = scene.point_positions.to(**f32)
    reach = offset * pp.abs().amax(1).clamp(min=1.0) if len(pp) else pp[:, 0]
    point = torch.cat([pp, torch.ones(len(pp), 1, **f32), scene.point_intensities.to(**f32),
                       reach[:, None]], 1)
    dd = scene.dir_directions.to(**f32)
    direc = torch.cat([dd, torch.zeros(len(dd), 1, **f32), scene.dir_irradiance.to(**f32),
                       torch.zeros(len(dd), 1, **f32)], 1)
    lights = torch.cat([point, direc], 0).contiguous()
    if not len(lights):
        lights = torch.zeros(1, 8, **f32)  # never read: n_lights = 0
    colours = [float(x) for x in torch.cat([scene.ambient, scene.background]).tolist()]
    cached[key] = (scene.material.to(device, torch.int32).contiguous(), mats.contiguous(),
                   lights, len(pp) + len(dd), colours)
    return cached[key]


def render_whitted_triton(scene, origins, directions, max_depth: int = 2, *,
                          offset: float | None = None, block: int = DEFAULT_BLOCK,
                          num_warps: int = DEFAULT_NUM_WARPS, bvh: FlatBVH | None = None,
                          uniform_branches: bool = DEFAULT_UNIFORM, return_info: bool = False):
    """Radiance along each primary ray by the Whitted contract, in one kernel launch.

    scene: a ``course.given.lab3.WhittedScene`` (its BVH is cached per scene object
    unless ``bvh`` is given); origins, directions: (N, 3) float primary rays (unit
    directions, e.g. ``course.core.camera.primary_rays``); max_depth: mirror bounces (2: up to
    two reflected rays); offset: the contract's OFFSET (default: whitted_support's).
    Returns (N, 3) float32 linear RGB, or ``(rgb, TracerKernelInfo)`` with ``return_info``.
    """
    _require_triton()
    if isinstance(max_depth, bool) or not isinstance(max_depth, int) or max_depth < 0:
        raise ValueError(f"max_depth: expected an int >= 0, got {max_depth!r}")
    o, d, _, _ = check_rays(origins, directions, 0.0, math.inf)
    _check_launch(block, num_warps)
    n, device = o.shape[0], o.device
    _device_check(device)
    if offset is None:
        from course.given.lab3 import OFFSET as offset
    if bvh is None:
        bvh = flat_bvh_for(scene).to(device)
    pairs, root, tris_f, tris_i, root_ref = _bvh_args(bvh, device)
    mat_id, mats, lights, n_lights, colours = _scene_tables(scene, device, float(offset))
    out = torch.empty(n, 3, dtype=torch.float32, device=device)
    handle = None
    if n:
        stack, lanes = _stack(n, block, device, bvh)
        compiled = not interpreting()
        with _ieee_quiet():
            handle = _whitted_kernel[(lanes // block,)](
                o, d, out, n, pairs, root, tris_f, tris_i, root_ref, stack, lanes, mat_id,
                mats, lights, *colours, float(offset), N_LIGHTS=n_lights, MAX_DEPTH=max_depth,
                BLOCK=block, EXIT=EXIT_SCALE, UNIFORM=bool(uniform_branches), VEC=compiled,
                SANITIZE=not compiled, REGS=UBER_STACK_REGS, TRIS=UBER_TRIS_PER_STEP,
                SPECULATE=UBER_SPECULATE, num_warps=num_warps)
    if return_info:
        return out, _info("whitted_uber", handle, num_warps, block)
    return out
