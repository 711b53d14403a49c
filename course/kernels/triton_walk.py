"""The BVH walk of the Triton tracers, as device functions (given, not an exercise).

How "one ray per thread" maps onto Triton. A Triton program works on a block of lanes in
lock step; control flow is per program, not per lane. So each kernel is a loop that runs
while *any* lane of the program still has work (``tl.max`` of the lanes' alive flags), and
every step is written with per-lane masks: a lane that is done, or has nothing of that
kind to do this step, just has its loads and stores masked off. This is what a CUDA warp
does with divergent branches anyway; the default launch (32 lanes, one warp per program)
makes a program exactly one warp, so the loop condition is a warp vote and the lanes of
different warps never wait for each other.

Each step of the walk does, per lane (see course.kernels.flat_bvh for the layouts and the
contract):

1. TRAVERSE: a lane at an interior node reads its row of ``pairs`` (both children's boxes
   and links: four 16-byte loads, the layout the CUDA C kernel reads), tests both boxes,
   goes to the nearer hit child and pushes the farther; a leaf child becomes pending work;
2. INTERSECT: a lane with pending leaf work tests one triangle (Möller–Trumbore, three
   16-byte loads), or two with ``tris_per_step=2``: not watertight (a ray through a shared
   edge or vertex may miss every triangle around it), while the box tests of TRAVERSE are
   conservative (``_slab``), so every miss is the triangle test's, as in flat_bvh;
3. POP: a lane with no node pops its stack (or finishes when it is empty and its leaf is
   done). With ``speculate`` it does so even while its leaf is being tested, parking at
   most one more leaf: it then takes part in both stages of a step instead of idling
   through one (Aila & Laine's speculative traversal).

Stages no lane needs are skipped (``uniform_branches``): before TRAVERSE and INTERSECT the
program votes over its lanes (``redux.sync``) and branches around the stage when none needs
it, as a warp does when none of its threads takes a branch. ``_while_while`` is the CUDA C
kernel's loop shape instead (Aila & Laine's while-while: traverse while some lane looks for
a leaf, then test while some lane has one).

Loads as CUDA C does them: one 64-bit address per row (``_row``) whose words ``_load4``
reads at constant offsets, and the triangle's inside test as one NaN-propagating min rather
than flags packed into bits. ``bench/sass_loops.py`` counts the instructions per TRAVERSE
and INTERSECT iteration of both kernels; bench/results/nvidia-h200/lab3_rows/ holds them.

The stack. Triton has no per-lane arrays with dynamic indices, so with ``stack="global"``
each lane's stack is a column of a scratch buffer in global memory, ``stack[level,
lane]``: entries of one level of neighbouring lanes are neighbours, so pushes and pops of a
warp at similar depths touch few cache lines (the interleaving CUDA gives local memory). It
is what the CUDA kernel's local-memory stack is, too: both live in L1/L2-cached device
memory. A lane owns its column for the program's lifetime, so nothing needs synchronising.
With ``stack_regs=4`` the top four entries stay in registers (shifted on every push and
pop) and only deeper ones go to the buffer. ``stack="local"`` declares a 64-entry array in
each lane's local memory in inline PTX instead (``_local_stack``), as ``int stack[64]`` is
in CUDA C: no buffer is allocated, and the hardware interleaves the lanes' entries itself.

The launch knobs' defaults are here too (``DEFAULT_*``); their launchers are in
:mod:`course.kernels.triton_tracer` and :mod:`course.kernels.triton_whitted`.
"""

from __future__ import annotations

from course.kernels.flat_bvh import HIT_SLACK, STACK_DEPTH
from course.kernels.triton_intersect import _jit, _store_hits, tl

DEFAULT_BLOCK = 32
DEFAULT_NUM_WARPS = 1
DEFAULT_UNIFORM = True
# The defaults are the launch timed fastest on primary and diffuse rays together
# (bench/results/nvidia-h200/lab3_head_to_head/): while-while, speculative, local stack.
# Refilling free lanes is off: it gains on diffuse rays what it loses on primary ones
# (bench/results/nvidia-h200/lab3_refill/ and lab3_rows/); pass refill=8 for incoherent rays.
DEFAULT_STACK_REGS = 0
DEFAULT_TRIS_PER_STEP = 1
DEFAULT_SPECULATE = True
DEFAULT_LOOP = "while"
DEFAULT_STACK = None  # "local", or "global" when stack_regs keeps entries in registers
DEFAULT_REFILL = 0  # free lanes at which a persistent program takes new rays (0: off)
LOOPS = ("if", "while")
STACKS = ("global", "local")
# The uber kernel's walk, as timed for its frames (bench/results/nvidia-h200/lab3_packed/).
UBER_STACK_REGS, UBER_TRIS_PER_STEP, UBER_SPECULATE = 4, 1, False
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
def _local_stack(like):
    """A 64-entry int32 array in each lane's local memory (what ``int stack[64]`` is in
    CUDA C: interleaved across the warp, cached write-back in L1) and its address: a
    ``.local`` declaration in inline PTX, kept by ptxas because its address is used. 64 is
    flat_bvh's STACK_DEPTH: every FlatBVH is checked at build to need no more."""
    return tl.inline_asm_elementwise(
        "{ .local .align 16 .b32 stk[64]; mov.u64 $0, stk; }",
        "=l,r",
        [like],
        dtype=tl.int64,
        is_pure=False,
        pack=1,
    )


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
            "=r,l,r,r",
            [slot + sp.to(tl.int64) * 4, value, mask.to(tl.int32)],
            dtype=tl.int32,
            is_pure=False,
            pack=1,
        )
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
            "=r,l,r",
            [slot + sp.to(tl.int64) * 4, mask.to(tl.int32)],
            dtype=tl.int32,
            is_pure=False,
            pack=1,
        )
    elif REGS == 0:
        value = tl.load(stack_ptr + sp * stride + slot, mask=mask, other=0)
    else:
        value = s0
        s0 = tl.where(mask, s1, s0)
        s1 = tl.where(mask, s2, s1)
        s2 = tl.where(mask, s3, s2)
        s3 = tl.where(
            mask, tl.load(stack_ptr + (sp - 4) * stride + slot, mask=mask & (sp >= 4), other=0), s3
        )
    return value, sp, s0, s1, s2, s3


@_jit
def _visit(
    pairs,
    stack_ptr,
    slot,
    stride,
    ox,
    oy,
    oz,
    ix,
    iy,
    iz,
    neg_x,
    neg_y,
    neg_z,
    t_lo,
    best_t,
    visit,
    node,
    sp,
    cur,
    s0,
    s1,
    s2,
    s3,
    EXIT: tl.constexpr,
    VEC: tl.constexpr,
    SANITIZE: tl.constexpr,
    REGS: tl.constexpr,
):
    """TRAVERSE for the lanes in ``visit``: one row of ``pairs`` (both children's boxes and
    links, four 16-byte loads); go to the nearer hit child, push the farther. Returns the
    lanes' new ``(node, sp, cur, s0, s1, s2, s3)``; node = cur = -1: pop next."""
    row = _row(pairs, node, 16)  # lanes not in `visit` mask their results
    ax0, ax1, bx0, bx1 = _load4(row, 0, VEC)
    ay0, ay1, by0, by1 = _load4(row, 4, VEC)
    az0, az1, bz0, bz1 = _load4(row, 8, VEC)
    ref_a, ref_b, _ca, _cb = _load4(row, 12, VEC)
    ta, ha = _slab(
        ox,
        oy,
        oz,
        ix,
        iy,
        iz,
        neg_x,
        neg_y,
        neg_z,
        _f(ax0),
        _f(ax1),
        _f(ay0),
        _f(ay1),
        _f(az0),
        _f(az1),
        t_lo,
        best_t,
        EXIT,
        SANITIZE,
    )
    tb, hb = _slab(
        ox,
        oy,
        oz,
        ix,
        iy,
        iz,
        neg_x,
        neg_y,
        neg_z,
        _f(bx0),
        _f(bx1),
        _f(by0),
        _f(by1),
        _f(bz0),
        _f(bz1),
        t_lo,
        best_t,
        EXIT,
        SANITIZE,
    )
    ha = ha & visit
    hb = hb & visit
    b_first = hb & (~ha | (tb < ta))
    both = ha & hb
    sp, s0, s1, s2, s3 = _push(
        stack_ptr, slot, stride, sp, tl.where(b_first, ref_a, ref_b), both, s0, s1, s2, s3, REGS
    )
    node = tl.where(visit, NONE, node)
    node, cur = _dispatch(ha | hb, tl.where(b_first, ref_b, ref_a), node, cur)
    return node, sp, cur, s0, s1, s2, s3


@_jit
def _intersect(
    tris,
    ox,
    oy,
    oz,
    dx,
    dy,
    dz,
    t_lo,
    test,
    cur,
    best_t,
    best_row,
    best_tri,
    best_u,
    best_v,
    VEC: tl.constexpr,
):
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
    inside = (
        tl.minimum(
            tl.minimum(u, v, propagate_nan=tl.PropagateNan.ALL),
            1.0 - (u + v),
            propagate_nan=tl.PropagateNan.ALL,
        )
        >= 0.0
    )
    hit = test & inside & (t >= t_lo) & (t <= best_t) & ((t < best_t) | (tri < best_tri))
    nxt = tl.where(test, tl.where(last != 0, -1, cur + 1), cur)
    return (
        tl.where(hit, t, best_t),
        tl.where(hit, cur, best_row),
        tl.where(hit, tri, best_tri),
        tl.where(hit, u, best_u),
        tl.where(hit, v, best_v),
        hit,
        nxt,
    )


@_jit
def _test_leaves(
    tris,
    ox,
    oy,
    oz,
    dx,
    dy,
    dz,
    t_lo,
    alive,
    cur,
    best_t,
    best_row,
    best_tri,
    best_u,
    best_v,
    ANY_HIT: tl.constexpr,
    VEC: tl.constexpr,
    TRIS: tl.constexpr,
    UNIFORM: tl.constexpr,
):
    """INTERSECT: up to TRIS rows of each lane's pending leaf (``_intersect``); with
    UNIFORM, a test no lane needs is skipped (a vote). Any hit ends a lane's walk. Returns
    ``(alive, cur, best_t, best_row, best_tri, best_u, best_v)``."""
    for _k in tl.static_range(TRIS):
        test = alive & (cur >= 0)
        hit = test & (cur < -1)  # cur >= -1 always: no hit where the test is skipped
        if UNIFORM:
            if tl.max(test.to(tl.int32), axis=0) > 0:
                best_t, best_row, best_tri, best_u, best_v, hit, cur = _intersect(
                    tris,
                    ox,
                    oy,
                    oz,
                    dx,
                    dy,
                    dz,
                    t_lo,
                    test,
                    cur,
                    best_t,
                    best_row,
                    best_tri,
                    best_u,
                    best_v,
                    VEC,
                )
        else:
            best_t, best_row, best_tri, best_u, best_v, hit, cur = _intersect(
                tris,
                ox,
                oy,
                oz,
                dx,
                dy,
                dz,
                t_lo,
                test,
                cur,
                best_t,
                best_row,
                best_tri,
                best_u,
                best_v,
                VEC,
            )
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
def _pop_or_finish(
    stack_ptr,
    slot,
    stride,
    alive,
    node,
    cur,
    sp,
    s0,
    s1,
    s2,
    s3,
    REGS: tl.constexpr,
    SPECULATE: tl.constexpr,
):
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
def _start(
    root,
    root_ref,
    ox,
    oy,
    oz,
    dx,
    dy,
    dz,
    t_lo,
    t_hi,
    alive,
    EXIT: tl.constexpr,
    VEC: tl.constexpr,
    SANITIZE: tl.constexpr,
):
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
    _, in_root = _slab(
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
        EXIT,
        SANITIZE,
    )
    alive = alive & in_root
    node = zero_i + NONE  # the pair row to visit next (or a leaf waiting); NONE: none
    cur = zero_i - 1  # the leaf row to test next; -1: none
    node, cur = _dispatch(alive, zero_i + root_ref, node, cur)
    return ix, iy, iz, neg_x, neg_y, neg_z, alive, node, cur


@_jit
def _while_round(
    pairs,
    tris,
    stack_ptr,
    slot,
    stride,
    ox,
    oy,
    oz,
    dx,
    dy,
    dz,
    ix,
    iy,
    iz,
    neg_x,
    neg_y,
    neg_z,
    t_lo,
    alive,
    node,
    cur,
    sp,
    s0,
    s1,
    s2,
    s3,
    best_t,
    best_row,
    best_tri,
    best_u,
    best_v,
    ANY_HIT: tl.constexpr,
    EXIT: tl.constexpr,
    VEC: tl.constexpr,
    SANITIZE: tl.constexpr,
    REGS: tl.constexpr,
    TRIS: tl.constexpr,
    SPECULATE: tl.constexpr,
):
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
            pairs,
            stack_ptr,
            slot,
            stride,
            ox,
            oy,
            oz,
            ix,
            iy,
            iz,
            neg_x,
            neg_y,
            neg_z,
            t_lo,
            best_t,
            alive & (node >= 0),
            node,
            sp,
            cur,
            s0,
            s1,
            s2,
            s3,
            EXIT,
            VEC,
            SANITIZE,
            REGS,
        )
        alive, node, cur, sp, s0, s1, s2, s3 = _pop_or_finish(
            stack_ptr, slot, stride, alive, node, cur, sp, s0, s1, s2, s3, REGS, SPECULATE
        )
        searching = tl.reduce((alive & (node >= 0) & (cur < 0)).to(tl.int32), 0, _or)
    # INTERSECT while some lane has leaf work (a parked leaf follows its predecessor).
    testing = tl.reduce((alive & (cur >= 0)).to(tl.int32), 0, _or)
    while testing != 0:
        alive, cur, best_t, best_row, best_tri, best_u, best_v = _test_leaves(
            tris,
            ox,
            oy,
            oz,
            dx,
            dy,
            dz,
            t_lo,
            alive,
            cur,
            best_t,
            best_row,
            best_tri,
            best_u,
            best_v,
            ANY_HIT,
            VEC,
            TRIS,
            False,
        )
        node, cur = _start_waiting(alive, node, cur, SPECULATE)
        testing = tl.reduce((alive & (cur >= 0)).to(tl.int32), 0, _or)
    # POP: lanes left with no node go on from their stack (or finish).
    alive, node, cur, sp, s0, s1, s2, s3 = _pop_or_finish(
        stack_ptr, slot, stride, alive, node, cur, sp, s0, s1, s2, s3, REGS, SPECULATE
    )
    return alive, node, cur, sp, s0, s1, s2, s3, best_t, best_row, best_tri, best_u, best_v


@_jit
def _while_while(
    pairs,
    tris,
    stack_ptr,
    slot,
    stride,
    ox,
    oy,
    oz,
    dx,
    dy,
    dz,
    ix,
    iy,
    iz,
    neg_x,
    neg_y,
    neg_z,
    t_lo,
    alive,
    node,
    cur,
    sp,
    s0,
    s1,
    s2,
    s3,
    best_t,
    best_row,
    best_tri,
    best_u,
    best_v,
    ANY_HIT: tl.constexpr,
    EXIT: tl.constexpr,
    VEC: tl.constexpr,
    SANITIZE: tl.constexpr,
    REGS: tl.constexpr,
    TRIS: tl.constexpr,
    SPECULATE: tl.constexpr,
):
    """The walk as rounds of ``_while_round`` while some lane is alive: same state and
    results as the *if-if* loop of ``_trace``."""
    votes = tl.reduce(alive.to(tl.int32), 0, _or)
    while votes != 0:
        (alive, node, cur, sp, s0, s1, s2, s3, best_t, best_row, best_tri, best_u, best_v) = (
            _while_round(
                pairs,
                tris,
                stack_ptr,
                slot,
                stride,
                ox,
                oy,
                oz,
                dx,
                dy,
                dz,
                ix,
                iy,
                iz,
                neg_x,
                neg_y,
                neg_z,
                t_lo,
                alive,
                node,
                cur,
                sp,
                s0,
                s1,
                s2,
                s3,
                best_t,
                best_row,
                best_tri,
                best_u,
                best_v,
                ANY_HIT,
                EXIT,
                VEC,
                SANITIZE,
                REGS,
                TRIS,
                SPECULATE,
            )
        )
        votes = tl.reduce(alive.to(tl.int32), 0, _or)
    return best_t, best_row, best_u, best_v


@_jit
def _trace(
    pairs,
    root,
    tris,
    root_ref,
    stack_ptr,
    slot,
    stride,
    ox,
    oy,
    oz,
    dx,
    dy,
    dz,
    t_lo,
    t_hi,
    alive,
    ANY_HIT: tl.constexpr,
    EXIT: tl.constexpr,
    UNIFORM: tl.constexpr,
    VEC: tl.constexpr,
    SANITIZE: tl.constexpr,
    REGS: tl.constexpr,
    TRIS: tl.constexpr,
    SPECULATE: tl.constexpr,
    WHILE: tl.constexpr,
):
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
        root, root_ref, ox, oy, oz, dx, dy, dz, t_lo, t_hi, alive, EXIT, VEC, SANITIZE
    )
    if REGS == LOCAL_STACK:
        slot = _local_stack(zero_i)
    sp = zero_i
    s0 = zero_i
    s1 = zero_i
    s2 = zero_i
    s3 = zero_i
    if WHILE:
        best_t, best_row, best_u, best_v = _while_while(
            pairs,
            tris,
            stack_ptr,
            slot,
            stride,
            ox,
            oy,
            oz,
            dx,
            dy,
            dz,
            ix,
            iy,
            iz,
            neg_x,
            neg_y,
            neg_z,
            t_lo,
            alive,
            node,
            cur,
            sp,
            s0,
            s1,
            s2,
            s3,
            best_t,
            best_row,
            best_tri,
            best_u,
            best_v,
            ANY_HIT,
            EXIT,
            VEC,
            SANITIZE,
            REGS,
            TRIS,
            SPECULATE,
        )
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
                    pairs,
                    stack_ptr,
                    slot,
                    stride,
                    ox,
                    oy,
                    oz,
                    ix,
                    iy,
                    iz,
                    neg_x,
                    neg_y,
                    neg_z,
                    t_lo,
                    best_t,
                    visit,
                    node,
                    sp,
                    cur,
                    s0,
                    s1,
                    s2,
                    s3,
                    EXIT,
                    VEC,
                    SANITIZE,
                    REGS,
                )
        else:
            node, sp, cur, s0, s1, s2, s3 = _visit(
                pairs,
                stack_ptr,
                slot,
                stride,
                ox,
                oy,
                oz,
                ix,
                iy,
                iz,
                neg_x,
                neg_y,
                neg_z,
                t_lo,
                best_t,
                visit,
                node,
                sp,
                cur,
                s0,
                s1,
                s2,
                s3,
                EXIT,
                VEC,
                SANITIZE,
                REGS,
            )
        # 2. INTERSECT up to TRIS triangles of the pending leaf
        alive, cur, best_t, best_row, best_tri, best_u, best_v = _test_leaves(
            tris,
            ox,
            oy,
            oz,
            dx,
            dy,
            dz,
            t_lo,
            alive,
            cur,
            best_t,
            best_row,
            best_tri,
            best_u,
            best_v,
            ANY_HIT,
            VEC,
            TRIS,
            UNIFORM,
        )
        # 3. POP: a lane with no node and no leaf work pops its stack (or finishes)
        node, cur = _start_waiting(alive, node, cur, SPECULATE)
        alive, node, cur, sp, s0, s1, s2, s3 = _pop_or_finish(
            stack_ptr, slot, stride, alive, node, cur, sp, s0, s1, s2, s3, REGS, SPECULATE
        )
        votes = tl.reduce(alive.to(tl.int32) | ((alive & (node >= 0)).to(tl.int32) << 1), 0, _or)
    return best_t, best_row, best_u, best_v


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
