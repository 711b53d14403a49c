"""The BVH walk's loops: one if-if round (``_while_round``), the while-while kernel loop
(``_while_while``) and the whole walk of a block of rays (``_trace``). Part of
:mod:`course.kernels.triton_walk`.
"""

from __future__ import annotations

from course.kernels.triton_intersect import _jit, tl
from course.kernels.triton_walk_loads import LOCAL_STACK, _or
from course.kernels.triton_walk_stack import _local_stack
from course.kernels.triton_walk_steps import (
    _pop_or_finish,
    _start,
    _start_waiting,
    _test_leaves,
    _visit,
)


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
