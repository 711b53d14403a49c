"""The occupancy calculator against the lecture's table and NVIDIA's formula worked by hand."""

import pytest

from course.measure.occupancy import (
    G80,
    HOPPER_H100,
    PRESETS,
    GPUArch,
    occupancy,
    occupancy_table,
)

# The lecture: 8192 registers per SM, 8x8 = 64-thread blocks.
LECTURE_TABLE = [  # (registers per thread, blocks per SM, warps per SM)
    (40, 3, 6),
    (32, 4, 8),
    (24, 5, 10),
    (20, 6, 12),
    (16, 8, 16),
]


@pytest.mark.parametrize("regs, blocks, warps", LECTURE_TABLE)
def test_lecture_table_at_each_step(regs, blocks, warps):
    occ = occupancy(G80, regs, block_size=8 * 8)
    assert (occ.blocks_per_sm, occ.active_warps) == (blocks, warps)
    assert occ.limiter == "registers"
    assert occ.occupancy == pytest.approx(warps / 24)


@pytest.mark.parametrize("regs, blocks, _warps", LECTURE_TABLE)
def test_lecture_table_one_register_more_loses_a_block(regs, blocks, _warps):
    # 64 threads x 41 registers = 2624, rounded to 2816 (11 units of 256): 8192 // 2816 = 2.
    assert occupancy(G80, regs + 1, block_size=64).blocks_per_sm < blocks


def test_lecture_table_register_rounding_per_block():
    occ = occupancy(G80, 41, block_size=64)
    assert occ.registers_per_block == 2816
    assert occ.blocks_by_registers == 2


def test_g80_small_blocks_take_two_warp_slots():
    # 1.x reserves warps in pairs: a 32-thread block costs 2 of the 24 slots, but runs 1 warp.
    occ = occupancy(G80, 8, block_size=32)
    assert occ.blocks_by_warps == 12
    assert occ.blocks_per_sm == 8 and occ.limiter == "blocks"
    assert occ.active_warps == 8


def test_lecture_budget_of_the_intersection_kernel():
    # 23 registers (ray 6, vertices 9, t/u/v 3, ...): 64 x 23 = 1472 -> 1536 -> 5 blocks.
    assert occupancy(G80, 23, 64).blocks_per_sm == 5


def test_table_rows():
    rows = occupancy_table(G80, 64, [40, 32, 24, 20, 16])
    assert [row["blocks/SM"] for row in rows] == [3, 4, 5, 6, 8]
    assert [row["warps/SM"] for row in rows] == [6, 8, 10, 12, 16]
    assert rows[-1]["limited by"] == "registers + blocks"


# Hopper: 65536 registers in 4 partitions of 16384, allocated per warp in units of 256.


def test_hopper_32_registers_256_threads_is_full():
    # 32 x 32 = 1024 registers/warp; 16384 // 1024 = 16 warps per partition -> 64 warps;
    # 64 // 8 warps per block = 8 blocks, exactly the 64 warp slots.
    occ = occupancy(HOPPER_H100, 32, 256)
    assert occ.blocks_per_sm == 8
    assert occ.active_warps == 64
    assert occ.occupancy == 1.0
    assert occ.limiters == ("registers", "warps")


def test_hopper_64_registers_128_threads_is_half():
    # 2048 registers/warp; 16384 // 2048 = 8 warps per partition -> 32 warps -> 8 blocks of 4.
    occ = occupancy(HOPPER_H100, 64, 128)
    assert (occ.blocks_per_sm, occ.active_warps) == (8, 32)
    assert occ.occupancy == 0.5
    assert occ.limiter == "registers"
    assert occ.blocks_by_warps == 16


def test_hopper_168_registers_is_an_exact_number_of_units():
    # 168 x 32 = 5376 = 21 x 256: no rounding. 16384 // 5376 = 3 warps per partition -> 12
    # warps -> one 8-warp block.
    occ = occupancy(HOPPER_H100, 168, 256)
    assert occ.registers_per_block == 5376 * 8
    assert (occ.blocks_per_sm, occ.active_warps) == (1, 8)
    assert occ.occupancy == pytest.approx(8 / 64)


def test_hopper_register_rounding_to_units():
    # 33 x 32 = 1056 -> 1280 registers/warp; 16384 // 1280 = 12 per partition -> 48 warps.
    occ = occupancy(HOPPER_H100, 33, 256)
    assert (occ.blocks_per_sm, occ.active_warps) == (6, 48)


def test_hopper_warps_fit_per_partition_not_per_sm():
    # 80 x 32 = 2560/warp: 65536 // 2560 = 25 warps for the whole file, but each 16384-register
    # partition holds only 6, so 24 one-warp blocks.
    occ = occupancy(HOPPER_H100, 80, 32)
    assert occ.blocks_per_sm == 24
    assert occ.limiter == "registers"


def test_hopper_block_that_cannot_fit_gets_zero_blocks():
    # 255 x 32 = 8160 -> 8192/warp x 32 warps = 262144 > 65536: the launch would fail.
    occ = occupancy(HOPPER_H100, 255, 1024)
    assert occ.blocks_per_sm == 0
    assert occ.active_warps == 0
    assert occ.occupancy == 0.0
    assert occ.limiter == "registers"


def test_hopper_shared_memory_limit():
    # 48 KB + 1 KB reserved per block: 228 KB // 49 KB = 4 blocks.
    occ = occupancy(HOPPER_H100, 32, 256, shared_per_block=48 * 1024)
    assert occ.blocks_by_shared == 4
    assert occ.blocks_per_sm == 4 and occ.limiter == "shared memory"
    assert occ.occupancy == 0.5


def test_no_shared_memory_is_no_limit():
    assert occupancy(HOPPER_H100, 32, 256).blocks_by_shared is None


@pytest.mark.parametrize(
    "kwargs, argument",
    [
        ({"regs_per_thread": 256, "block_size": 256}, "regs_per_thread"),
        ({"regs_per_thread": 0, "block_size": 256}, "regs_per_thread"),
        ({"regs_per_thread": 32, "block_size": 1025}, "block_size"),
        ({"regs_per_thread": 32, "block_size": 0}, "block_size"),
        ({"regs_per_thread": 32, "block_size": 256, "shared_per_block": -1}, "shared_per_block"),
        (
            {"regs_per_thread": 32, "block_size": 256, "shared_per_block": 228 * 1024},
            "shared_per_block",
        ),
    ],
)
def test_invalid_arguments_name_the_argument(kwargs, argument):
    with pytest.raises(ValueError, match=argument):
        occupancy(HOPPER_H100, **kwargs)


def test_g80_refuses_blocks_above_512_threads():
    with pytest.raises(ValueError, match="block_size"):
        occupancy(G80, 16, 1024)


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_presets_reach_full_occupancy_with_few_registers(name):
    arch = PRESETS[name]
    assert isinstance(arch, GPUArch)
    occ = occupancy(arch, 8, 256)
    assert occ.occupancy == 1.0, occ
    assert occ.limiter == "warps"


def test_presets_are_looked_up_by_lowercase_name():
    assert PRESETS["hopper_h100"] is HOPPER_H100
    assert PRESETS["g80"] is G80
    assert {"gt200", "fermi", "kepler", "volta", "ampere_a100"} <= set(PRESETS)
