"""The BVH walk's traversal stack: a column of a scratch buffer with the top entries in
registers, or an array in each lane's local memory (``_local_stack``). Part of
:mod:`course.kernels.triton_walk`.
"""

from __future__ import annotations

from course.kernels.triton_intersect import _jit, tl
from course.kernels.triton_walk_loads import LOCAL_STACK


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
