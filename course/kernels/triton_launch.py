"""Host side of the Triton tracers: launch and knob checks, scratch stacks, the BVH's
arguments and what a compiled kernel reports (:class:`TracerKernelInfo`).

Shared by :mod:`course.kernels.triton_tracer` and :mod:`course.kernels.triton_whitted`;
given code, not an exercise.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from course.kernels.flat_bvh import STACK_DEPTH, FlatBVH
from course.kernels.triton_intersect import interpreting, triton
from course.kernels.triton_walk import DEFAULT_LOOP, DEFAULT_REFILL, LOOPS


def triton_available() -> bool:
    return triton is not None


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
        raise ValueError(
            f"refill: expected None, 0 (off) or free lanes from 1 to block "
            f"({block}), got {refill!r}"
        )
    if refill and loop != "while":
        raise ValueError(
            f"refill: the persistent walk runs the while-while loop, got "
            f"loop={loop!r} (refill=0 or None for the if-if loop)"
        )
    if programs is not None and (
        not refill or isinstance(programs, bool) or not isinstance(programs, int) or programs < 1
    ):
        raise ValueError(
            f"programs: expected None, or an int >= 1 with refill, got "
            f"{programs!r} (refill={refill})"
        )
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
        raise ValueError(
            f"block: expected at least 32 lanes per warp ({32 * num_warps} for "
            f"num_warps={num_warps}), got {block}"
        )


def _device_check(device: torch.device) -> None:
    if not interpreting() and device.type != "cuda":
        raise ValueError(
            f"origins: the compiled Triton kernels need CUDA tensors, got {device} "
            "(for the CPU, set TRITON_INTERPRET=1 before importing triton, or use "
            "course.kernels.flat_bvh.trace_flat_torch)"
        )


def _stack(
    n: int, block: int, device, bvh: FlatBVH, local: bool = False
) -> tuple[torch.Tensor, int]:
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
        return occupancy(
            arch or HOPPER_H100, self.n_regs, 32 * self.num_warps, self.shared_bytes or 0
        )


def _info(name: str, handle, num_warps: int, block: int, stack_words: int = 0) -> TracerKernelInfo:
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
    return TracerKernelInfo(
        name,
        field(handle, "n_regs"),
        None if words is None else max(0, words - stack_words),
        field(field(handle, "metadata"), "shared"),
        num_warps,
        block,
        None if words is None else 4 * words,
    )


def _bvh_args(bvh: FlatBVH, device):
    if not isinstance(bvh, FlatBVH):
        raise TypeError(
            f"bvh: expected a course.kernels.flat_bvh.FlatBVH, got {type(bvh).__name__}"
        )
    if bvh.nodes.device != device:
        raise ValueError(
            f"bvh: expected a BVH on {device} like the rays (bvh.to(device)), "
            f"got {bvh.nodes.device}"
        )
    # pairs has a row even for a one-leaf tree: masked-off lanes of the 16-byte loads read
    # row 0 of every array.
    pairs = (
        bvh.pair_ints if len(bvh.pairs) else torch.zeros(1, 16, dtype=torch.int32, device=device)
    )
    return pairs, bvh.nodes, bvh.triangles, bvh.triangle_ints, bvh.root_ref
