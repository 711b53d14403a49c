"""GPU occupancy: how many warps an SM keeps resident for a kernel's resource use.

Occupancy = active warps / maximum warps per SM. A block is resident only when the SM has
room for *all* of it: its warps (warp slots), its registers (the register file) and its
shared memory. The smallest of those limits, and the hardware's cap on resident blocks,
decides how many blocks run at once::

    warps/block  = ceil(threads / warp_size)    (slots reserved: rounded up to the
                                                 warp allocation unit)
    blocks/SM    = min(by registers, by shared memory, max_warps // warps/block, max_blocks)
    occupancy    = blocks/SM * warps/block / max_warps

Registers are allocated in units, which is where the lecture's staircase comes from:

* compute capability 1.x allocates them **per block**:
  ``regs/block = round_up(regs * warp_size * warps/block, reg_alloc_unit)`` and
  ``blocks = regs_per_sm // regs/block``;
* 2.x and later allocate them **per warp**, each warp on one of the SM's register
  partitions: ``regs/warp = round_up(regs * warp_size, reg_alloc_unit)``,
  ``warps = (regs_per_sm / partitions // regs/warp) * partitions``,
  ``blocks = warps // warps/block``.

This is the formula of NVIDIA's occupancy calculator (``cuda_occupancy.h`` and the
spreadsheet before it); the presets take their numbers from it and from the CUDA C
Programming Guide's "Technical Specifications per Compute Capability" table.

A configuration whose single block does not fit (e.g. 255 registers x 1024 threads needs
261 120 registers, the SM has 65 536) gets **0 blocks**, as ``cudaOccupancy*`` reports it;
such a launch fails with "too many resources requested for launch". Arguments a kernel
cannot have at all (more registers per thread than the ISA addresses, blocks larger than
the maximum) raise ``ValueError``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

KB = 1024

# The order in which equally binding limits are named: the register file first, since the
# lecture's point is that registers are what a kernel author controls.
LIMITS = ("registers", "shared memory", "warps", "blocks")


@dataclass(frozen=True, kw_only=True)
class GPUArch:
    """Per-SM resources of one GPU generation, and how it allocates them.

    reg_alloc_unit: registers are handed out in multiples of this (per block or per warp,
        see reg_alloc_granularity).
    warp_alloc_granularity: a block's warp count is rounded up to this (2 on 1.x: a
        32-thread block occupies two warp slots there).
    register_partitions: register file slices (one per warp scheduler) a warp's registers
        must fit in whole; only used with per-warp allocation.
    reserved_shared_per_block: shared memory the driver keeps per resident block (8.0+).
    """

    name: str
    compute_capability: str
    regs_per_sm: int
    max_regs_per_block: int
    max_regs_per_thread: int
    max_warps_per_sm: int
    max_blocks_per_sm: int
    max_threads_per_block: int
    warp_size: int = 32
    reg_alloc_unit: int
    reg_alloc_granularity: Literal["warp", "block"]
    warp_alloc_granularity: int = 1
    register_partitions: int = 4
    shared_mem_per_sm: int
    shared_alloc_unit: int
    max_shared_per_block: int
    reserved_shared_per_block: int = 0


G80 = GPUArch(
    # The lecture's worked example: 8192 registers, 24 warps, 8 blocks per SM.
    name="G80",
    compute_capability="1.0",
    regs_per_sm=8192,
    max_regs_per_block=8192,
    max_regs_per_thread=124,
    max_warps_per_sm=24,
    max_blocks_per_sm=8,
    max_threads_per_block=512,
    reg_alloc_unit=256,
    reg_alloc_granularity="block",
    warp_alloc_granularity=2,
    register_partitions=1,
    shared_mem_per_sm=16 * KB,
    shared_alloc_unit=512,
    max_shared_per_block=16 * KB,
)

GT200 = GPUArch(
    # GTX 260/280, the GPU of the lecture's 40 M rays/s figure.
    name="GT200",
    compute_capability="1.3",
    regs_per_sm=16384,
    max_regs_per_block=16384,
    max_regs_per_thread=124,
    max_warps_per_sm=32,
    max_blocks_per_sm=8,
    max_threads_per_block=512,
    reg_alloc_unit=512,
    reg_alloc_granularity="block",
    warp_alloc_granularity=2,
    register_partitions=1,
    shared_mem_per_sm=16 * KB,
    shared_alloc_unit=512,
    max_shared_per_block=16 * KB,
)

FERMI = GPUArch(
    # GF100 with the 48 KB shared / 16 KB L1 split. NVIDIA's calculator rounds 21, 22, 29,
    # 30, 37, 38, 45 and 46 registers per thread to 128-register units on Fermi; this model
    # uses the usual 64.
    name="Fermi",
    compute_capability="2.0",
    regs_per_sm=32768,
    max_regs_per_block=32768,
    max_regs_per_thread=63,
    max_warps_per_sm=48,
    max_blocks_per_sm=8,
    max_threads_per_block=1024,
    reg_alloc_unit=64,
    reg_alloc_granularity="warp",
    register_partitions=2,
    shared_mem_per_sm=48 * KB,
    shared_alloc_unit=128,
    max_shared_per_block=48 * KB,
)

KEPLER = GPUArch(
    # GK110 (K20/K40), 48 KB shared / 16 KB L1.
    name="Kepler",
    compute_capability="3.5",
    regs_per_sm=65536,
    max_regs_per_block=65536,
    max_regs_per_thread=255,
    max_warps_per_sm=64,
    max_blocks_per_sm=16,
    max_threads_per_block=1024,
    reg_alloc_unit=256,
    reg_alloc_granularity="warp",
    shared_mem_per_sm=48 * KB,
    shared_alloc_unit=256,
    max_shared_per_block=48 * KB,
)

VOLTA = GPUArch(
    # V100 with the largest shared memory carve-out.
    name="Volta",
    compute_capability="7.0",
    regs_per_sm=65536,
    max_regs_per_block=65536,
    max_regs_per_thread=255,
    max_warps_per_sm=64,
    max_blocks_per_sm=32,
    max_threads_per_block=1024,
    reg_alloc_unit=256,
    reg_alloc_granularity="warp",
    shared_mem_per_sm=96 * KB,
    shared_alloc_unit=256,
    max_shared_per_block=96 * KB,
)

AMPERE_A100 = GPUArch(
    name="Ampere A100",
    compute_capability="8.0",
    regs_per_sm=65536,
    max_regs_per_block=65536,
    max_regs_per_thread=255,
    max_warps_per_sm=64,
    max_blocks_per_sm=32,
    max_threads_per_block=1024,
    reg_alloc_unit=256,
    reg_alloc_granularity="warp",
    shared_mem_per_sm=164 * KB,
    shared_alloc_unit=128,
    max_shared_per_block=163 * KB,
    reserved_shared_per_block=1 * KB,
)

HOPPER_H100 = GPUArch(
    name="Hopper H100",
    compute_capability="9.0",
    regs_per_sm=65536,
    max_regs_per_block=65536,
    max_regs_per_thread=255,
    max_warps_per_sm=64,
    max_blocks_per_sm=32,
    max_threads_per_block=1024,
    reg_alloc_unit=256,
    reg_alloc_granularity="warp",
    shared_mem_per_sm=228 * KB,
    shared_alloc_unit=128,
    max_shared_per_block=227 * KB,
    reserved_shared_per_block=1 * KB,
)

PRESETS: dict[str, GPUArch] = {
    "g80": G80,
    "gt200": GT200,
    "fermi": FERMI,
    "kepler": KEPLER,
    "volta": VOLTA,
    "ampere_a100": AMPERE_A100,
    "hopper_h100": HOPPER_H100,
}


@dataclass(frozen=True)
class Occupancy:
    """Resident blocks and warps per SM for one kernel configuration.

    blocks_by_*: how many blocks each resource alone would allow; blocks_by_shared is None
    when the kernel uses no shared memory. limiters names every limit equal to
    blocks_per_sm, most telling first (see LIMITS).
    """

    arch: str
    regs_per_thread: int
    block_size: int
    shared_per_block: int
    warps_per_block: int
    registers_per_block: int
    blocks_by_registers: int
    blocks_by_shared: int | None
    blocks_by_warps: int
    blocks_by_max_blocks: int
    blocks_per_sm: int
    active_warps: int
    max_warps: int
    occupancy: float
    limiters: tuple[str, ...]

    @property
    def limiter(self) -> str:
        """The limit that decides blocks_per_sm (the first of several that tie)."""
        return self.limiters[0]

    def as_row(self) -> dict[str, object]:
        """A flat dict for notebook tables."""
        return {
            "registers": self.regs_per_thread,
            "threads/block": self.block_size,
            "shared/block": self.shared_per_block,
            "blocks/SM": self.blocks_per_sm,
            "warps/SM": self.active_warps,
            "occupancy": self.occupancy,
            "limited by": " + ".join(self.limiters),
        }


def occupancy(
    arch: GPUArch, regs_per_thread: int, block_size: int, shared_per_block: int = 0
) -> Occupancy:
    """Blocks, warps and occupancy per SM of `arch` for one kernel configuration.

    regs_per_thread: registers the compiler gave the kernel (``ptxas -v``), 1..max.
    block_size: threads per block, 1..arch.max_threads_per_block.
    shared_per_block: bytes of static + dynamic shared memory per block.
    """
    _check_arguments(arch, regs_per_thread, block_size, shared_per_block)
    warps_per_block = -(-block_size // arch.warp_size)
    # Warp slots and registers are reserved for the rounded-up count (2 warps on 1.x).
    warps_allocated = _round_up(warps_per_block, arch.warp_alloc_granularity)
    registers_per_block, by_registers = _register_limit(arch, regs_per_thread, warps_allocated)
    by_shared = _shared_limit(arch, shared_per_block)
    limits = {
        "registers": by_registers,
        "shared memory": by_shared,
        "warps": arch.max_warps_per_sm // warps_allocated,
        "blocks": arch.max_blocks_per_sm,
    }
    blocks = min(n for n in limits.values() if n is not None)
    return Occupancy(
        arch=arch.name,
        regs_per_thread=regs_per_thread,
        block_size=block_size,
        shared_per_block=shared_per_block,
        warps_per_block=warps_per_block,
        registers_per_block=registers_per_block,
        blocks_by_registers=by_registers,
        blocks_by_shared=by_shared,
        blocks_by_warps=limits["warps"],
        blocks_by_max_blocks=limits["blocks"],
        blocks_per_sm=blocks,
        active_warps=blocks * warps_per_block,
        max_warps=arch.max_warps_per_sm,
        occupancy=blocks * warps_per_block / arch.max_warps_per_sm,
        limiters=tuple(name for name in LIMITS if limits[name] == blocks),
    )


def occupancy_table(
    arch: GPUArch, block_size: int, regs_list: list[int], shared_per_block: int = 0
) -> list[dict[str, object]]:
    """One `Occupancy.as_row()` per register count: the lecture's table for any GPU."""
    return [occupancy(arch, regs, block_size, shared_per_block).as_row() for regs in regs_list]


def _check_arguments(
    arch: GPUArch, regs_per_thread: int, block_size: int, shared_per_block: int
) -> None:
    if not 1 <= regs_per_thread <= arch.max_regs_per_thread:
        raise ValueError(
            f"regs_per_thread must be in 1..{arch.max_regs_per_thread} on {arch.name}, "
            f"got {regs_per_thread}"
        )
    if not 1 <= block_size <= arch.max_threads_per_block:
        raise ValueError(
            f"block_size must be in 1..{arch.max_threads_per_block} threads on {arch.name}, "
            f"got {block_size}"
        )
    if not 0 <= shared_per_block <= arch.max_shared_per_block:
        raise ValueError(
            f"shared_per_block must be in 0..{arch.max_shared_per_block} bytes on {arch.name}, "
            f"got {shared_per_block}"
        )


def _register_limit(arch: GPUArch, regs: int, warps_per_block: int) -> tuple[int, int]:
    """(registers allocated per block, blocks the register file holds)."""
    if arch.reg_alloc_granularity == "block":
        per_block = _round_up(regs * arch.warp_size * warps_per_block, arch.reg_alloc_unit)
        if per_block > arch.max_regs_per_block:
            return per_block, 0
        return per_block, arch.regs_per_sm // per_block
    per_warp = _round_up(regs * arch.warp_size, arch.reg_alloc_unit)
    # The launch check assumes the block's warps are spread over every partition.
    assumed = per_warp * _round_up(warps_per_block, arch.register_partitions)
    if assumed > arch.max_regs_per_block:
        return per_warp * warps_per_block, 0
    # A warp's registers live in one partition: only whole warps fit in each slice.
    warps_per_partition = arch.regs_per_sm // arch.register_partitions // per_warp
    warps = warps_per_partition * arch.register_partitions
    return per_warp * warps_per_block, warps // warps_per_block


def _shared_limit(arch: GPUArch, shared: int) -> int | None:
    """Blocks the shared memory holds; None when the kernel uses none."""
    if shared == 0:
        return None
    per_block = _round_up(shared, arch.shared_alloc_unit) + arch.reserved_shared_per_block
    return arch.shared_mem_per_sm // per_block


def _round_up(value: int, unit: int) -> int:
    return -(-value // unit) * unit
