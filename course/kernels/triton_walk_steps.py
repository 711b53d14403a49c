"""The steps of one round of the BVH walk: visit a node pair, test a leaf's triangles, pop
or finish, and a program's start. Part of :mod:`course.kernels.triton_walk`.
"""

from __future__ import annotations

from course.kernels.triton_intersect import _jit, tl
from course.kernels.triton_walk_loads import NONE, _dispatch, _f, _load4, _rcp, _row, _slab
from course.kernels.triton_walk_stack import _pop, _push


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
