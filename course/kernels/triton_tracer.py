"""BVH traversal as Triton kernels: the closest-hit / any-hit walk (given, not an exercise).

Lab 3 compares ways of organising a tracer. These kernels are the GPU end of that
comparison: ``trace_flat_triton`` is a closest-hit / any-hit BVH walk (what the separate
kernels of a wavefront tracer launch once per bounce), ``render_whitted_triton``
(:mod:`course.kernels.triton_whitted`, re-exported here) the lecture's **uber kernel**: each
lane runs its pixel's whole Whitted recursion in one launch, with no rays written to memory
between the stages.

The walk (one ray per lane, the TRAVERSE / INTERSECT / POP steps, speculation, the stack)
is :mod:`course.kernels.triton_walk`; the launch checks, scratch stacks and kernel info
:mod:`course.kernels.triton_launch`. This module holds the walk's two kernels and their
launcher. The kernel leaves out rays that cannot hit and takes numbers for
``t_min``/``t_max`` as numbers, so a call is one launch (and, with ``refill``, a fill of its
ray counter).

Refilling free lanes (``refill``, off by default). A program whose lanes finish at
different times runs on with most of them idle: on diffuse rays, a warp waits for its
slowest ray. With ``refill=k`` the kernel launches persistent programs (32 per SM) that take
new rays from a global counter whenever ``k`` of their lanes are free (Aila & Laine's
dynamic ray fetch: a prefix sum over the free lanes gives each its ray, one atomic add per
program). It trades the coherence of primary rays, whose lanes finish together anyway, for
busy lanes on incoherent ones: ``refill=8`` is the launch for bounces and the shadow rays of
a path tracer.

Performance contract. The defaults (while-while loop, speculation, the stack in local
memory, stage skipping, 32 lanes in one warp per program) are the launch timed fastest on
primary and diffuse rays together, against the CUDA C tracer (:mod:`course.kernels.cuda_tracer`)
on the same rays in alternating rounds (``bench/lab3_gpu.py``); the target is 80% of its
primary-ray throughput. A one-warp program can hold at most half of an SM's warps (32
programs per SM). The figures (rays/s, the share of CUDA C's throughput, each knob's effect,
instructions per iteration from ``bench/sass_loops.py``) are in bench/results/nvidia-h200/:
``lab3_packed/`` (the knobs), ``lab3_loops/`` and ``lab3_head_to_head/`` (loop shape, stack,
best launches), ``lab3_rows/`` (the SASS of both kernels), ``lab3_refill/`` (refill).

Accuracy contract: that of course.kernels.flat_bvh (float32 slab test with NaN-safe zero
directions, conservative: Ize's widened exit and the best hit widened by ``HIT_SLACK``;
float32 Möller–Trumbore with IEEE division, closed ``[t_min, t_max]``, ties to the lower
triangle index, NaN/inf/zero rays miss). The hits are those of a brute-force float32
Möller–Trumbore, which is not watertight: a ray through a shared edge or vertex may miss
every triangle around it (compiled, where FMA contraction may round ``u, v`` otherwise
than the torch walk, the edge cases may fall the other way). The uber kernel shades by
the contract of course.given.lab3, in float32.

Runs compiled on CUDA, or in Triton's CPU interpreter under ``TRITON_INTERPRET=1`` (set
before ``triton`` is imported; slow, for tiny tests). Importing this module without
Triton works; calling a kernel then raises ImportError.
"""

from __future__ import annotations

import math

import torch

from course.core.types import Hits
from course.kernels.flat_bvh import EXIT_SCALE, STACK_DEPTH, FlatBVH, check_ray_bounds
from course.kernels.triton_intersect import _ieee_quiet, _jit, _require_triton, interpreting, tl
from course.kernels.triton_launch import (
    TracerKernelInfo,
    _bvh_args,
    _check_launch,
    _check_refill,
    _check_walk,
    _default_programs,
    _device_check,
    _info,
    _stack,
    triton_available,
)
from course.kernels.triton_walk import (
    DEFAULT_BLOCK,
    DEFAULT_LOOP,
    DEFAULT_NUM_WARPS,
    DEFAULT_REFILL,
    DEFAULT_SPECULATE,
    DEFAULT_STACK,
    DEFAULT_STACK_REGS,
    DEFAULT_TRIS_PER_STEP,
    DEFAULT_UNIFORM,
    LOCAL_STACK,
    LOOPS,
    NONE,
    STACKS,
    UBER_SPECULATE,
    UBER_STACK_REGS,
    UBER_TRIS_PER_STEP,
    _load_rays,
    _local_stack,
    _or,
    _start,
    _store_row_hits,
    _trace,
    _while_round,
)
from course.kernels.triton_whitted import render_whitted_triton

__all__ = [
    "DEFAULT_BLOCK",
    "DEFAULT_LOOP",
    "DEFAULT_NUM_WARPS",
    "DEFAULT_REFILL",
    "DEFAULT_SPECULATE",
    "DEFAULT_STACK",
    "DEFAULT_STACK_REGS",
    "DEFAULT_TRIS_PER_STEP",
    "DEFAULT_UNIFORM",
    "LOCAL_STACK",
    "LOOPS",
    "STACKS",
    "UBER_SPECULATE",
    "UBER_STACK_REGS",
    "UBER_TRIS_PER_STEP",
    "TracerKernelInfo",
    "interpreting",
    "render_whitted_triton",
    "trace_flat_triton",
    "triton_available",
]


@_jit
def _trace_kernel(
    o_ptr,
    d_ptr,
    tlo_ptr,
    tlo_value,
    thi_ptr,
    thi_value,
    pairs,
    root,
    tris,
    root_ref,
    stack_ptr,
    t_ptr,
    id_ptr,
    u_ptr,
    v_ptr,
    n_rays,
    stride,
    BLOCK: tl.constexpr,
    ANY_HIT: tl.constexpr,
    EXIT: tl.constexpr,
    UNIFORM: tl.constexpr,
    VEC: tl.constexpr,
    SANITIZE: tl.constexpr,
    REGS: tl.constexpr,
    TRIS: tl.constexpr,
    SPECULATE: tl.constexpr,
    WHILE: tl.constexpr,
    TLO_ARRAY: tl.constexpr,
    THI_ARRAY: tl.constexpr,
):
    slot = tl.program_id(0) * BLOCK + tl.arange(0, BLOCK)
    live = slot < n_rays
    ox, oy, oz, dx, dy, dz, t_lo, t_hi, alive = _load_rays(
        o_ptr, d_ptr, tlo_ptr, tlo_value, thi_ptr, thi_value, slot, live, TLO_ARRAY, THI_ARRAY
    )
    t, row, u, v = _trace(
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
        ANY_HIT,
        EXIT,
        UNIFORM,
        VEC,
        SANITIZE,
        REGS,
        TRIS,
        SPECULATE,
        WHILE,
    )
    _store_row_hits(tris, t_ptr, id_ptr, u_ptr, v_ptr, slot, live, t, row, u, v)


@_jit
def _refill_kernel(
    o_ptr,
    d_ptr,
    tlo_ptr,
    tlo_value,
    thi_ptr,
    thi_value,
    pairs,
    root,
    tris,
    root_ref,
    stack_ptr,
    counter,
    t_ptr,
    id_ptr,
    u_ptr,
    v_ptr,
    n_rays,
    stride,
    BLOCK: tl.constexpr,
    ANY_HIT: tl.constexpr,
    EXIT: tl.constexpr,
    VEC: tl.constexpr,
    SANITIZE: tl.constexpr,
    REGS: tl.constexpr,
    TRIS: tl.constexpr,
    SPECULATE: tl.constexpr,
    REFILL: tl.constexpr,
    TLO_ARRAY: tl.constexpr,
    THI_ARRAY: tl.constexpr,
):
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
    node, cur, sp = zero_i + NONE, zero_i - 1, zero_i
    s0, s1, s2, s3 = zero_i, zero_i, zero_i, zero_i
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
                o_ptr,
                d_ptr,
                tlo_ptr,
                tlo_value,
                thi_ptr,
                thi_value,
                fresh,
                take,
                TLO_ARRAY,
                THI_ARRAY,
            )
            nix, niy, niz, nnx, nny, nnz, nalive, nnode, ncur = _start(
                root, root_ref, nox, noy, noz, ndx, ndy, ndz, nlo, nhi, nalive, EXIT, VEC, SANITIZE
            )
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
        done = (ray >= 0) & ~alive
        _store_row_hits(
            tris, t_ptr, id_ptr, u_ptr, v_ptr, ray, done, best_t, best_row, best_u, best_v
        )
        ray = tl.where(done, -1, ray)
        busy = tl.reduce((ray >= 0).to(tl.int32), 0, _or) | more.to(tl.int32)


def trace_flat_triton(
    bvh: FlatBVH,
    origins,
    directions,
    t_min=0.0,
    t_max=math.inf,
    *,
    any_hit: bool = False,
    block: int = DEFAULT_BLOCK,
    num_warps: int = DEFAULT_NUM_WARPS,
    uniform_branches: bool = DEFAULT_UNIFORM,
    stack_regs: int = DEFAULT_STACK_REGS,
    tris_per_step: int = DEFAULT_TRIS_PER_STEP,
    speculate: bool = DEFAULT_SPECULATE,
    loop: str = DEFAULT_LOOP,
    stack: str | None = DEFAULT_STACK,
    refill: int | None = None,
    programs: int | None = None,
    return_info: bool = False,
):
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
    or Ampere GPU with one-warp programs). The defaults are the launch timed fastest on
    primary and diffuse rays together; ``refill=8`` gains on diffuse rays what it loses on
    primary ones, whose lanes finish together anyway (see the module's performance
    contract for the figures' folder).
    Returns float32 ``Hits``, or ``(Hits, TracerKernelInfo)`` with ``return_info``.
    """
    _require_triton()
    o, d, (t_lo, lo_value), (t_hi, hi_value) = check_ray_bounds(origins, directions, t_min, t_max)
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
                o,
                d,
                o if t_lo is None else t_lo,
                lo_value,
                o if t_hi is None else t_hi,
                hi_value,
                pairs,
                root,
                tris,
                root_ref,
                buffer,
                counter,
                out_t,
                out_id,
                out_u,
                out_v,
                n,
                lanes,
                BLOCK=block,
                ANY_HIT=bool(any_hit),
                EXIT=EXIT_SCALE,
                VEC=compiled,
                SANITIZE=not compiled,
                REGS=-1 if local else stack_regs,
                TRIS=tris_per_step,
                SPECULATE=bool(speculate),
                REFILL=refill,
                TLO_ARRAY=t_lo is not None,
                THI_ARRAY=t_hi is not None,
                num_warps=num_warps,
            )
    elif n:
        buffer, lanes = _stack(n, block, device, bvh, local)
        with _ieee_quiet():
            handle = _trace_kernel[(lanes // block,)](
                o,
                d,
                o if t_lo is None else t_lo,
                lo_value,
                o if t_hi is None else t_hi,
                hi_value,
                pairs,
                root,
                tris,
                root_ref,
                buffer,
                out_t,
                out_id,
                out_u,
                out_v,
                n,
                lanes,
                BLOCK=block,
                ANY_HIT=bool(any_hit),
                EXIT=EXIT_SCALE,
                UNIFORM=bool(uniform_branches),
                VEC=compiled,
                SANITIZE=not compiled,
                REGS=-1 if local else stack_regs,
                TRIS=tris_per_step,  # -1: LOCAL_STACK
                SPECULATE=bool(speculate),
                WHILE=loop == "while",
                TLO_ARRAY=t_lo is not None,
                THI_ARRAY=t_hi is not None,
                num_warps=num_warps,
            )
    hits = Hits(t=out_t, triangle=out_id, u=out_u, v=out_v)
    if return_info:
        name = "any_hit" if any_hit else "closest_hit"
        return hits, _info(name, handle, num_warps, block, STACK_DEPTH if local else 0)
    return hits
