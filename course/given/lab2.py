"""Lab 2's given code in one import: input checks and tree plumbing shared by its skeleton
and reference.

Given code, not exercises: the lab's skeleton and its reference import these (``from
course.given.lab2 import ...``), so there is one copy of them. They live in parts:

* :mod:`course.given.lab2_checks`   constants (structure kinds, counters) and input checks
* :mod:`course.given.lab2_blocks`   triangle bounds, slab test, ranges, pair batches, counters
* :mod:`course.given.lab2_bvh`      BVH assembly from levels, ray octants, the packed walk
* :mod:`course.given.lab2_chooser`  scene statistics and the structure chooser

``check_mesh`` is :func:`course.core.raymath.check_mesh`.
"""

from __future__ import annotations

from course.core.raymath import check_mesh
from course.given.lab2_blocks import (
    add_count,
    as_hits,
    expand_ranges,
    grid_resolutions,
    intersect_pairs,
    moller_trumbore_rows,
    new_closest,
    new_counters,
    pair_chunks,
    slab_test,
    surface_area,
    test_ranges,
    triangle_bounds,
)
from course.given.lab2_bvh import TreeLevels, assemble_bvh, check_walk, pack_bvh, ray_octants
from course.given.lab2_checks import (
    COUNTERS,
    MAX_PAIRS,
    OFFSET_BITS,
    STRUCTURE_KEYS,
    STRUCTURES,
    _positive_int,
    check_bins,
    check_grid_inputs,
    check_kd_fields,
    check_kd_knobs,
    check_leaf_size,
    check_links,
    check_memory_budget,
    check_morton_inputs,
    check_packed,
    check_resolution,
    check_structure,
    check_trace_inputs,
    check_two_level_knobs,
)
from course.given.lab2_chooser import CHOOSER_LIMITS, choose_structure, scene_statistics

__all__ = [
    "CHOOSER_LIMITS",
    "COUNTERS",
    "MAX_PAIRS",
    "OFFSET_BITS",
    "STRUCTURES",
    "STRUCTURE_KEYS",
    "TreeLevels",
    "_positive_int",
    "add_count",
    "as_hits",
    "assemble_bvh",
    "check_bins",
    "check_grid_inputs",
    "check_kd_fields",
    "check_kd_knobs",
    "check_leaf_size",
    "check_links",
    "check_memory_budget",
    "check_mesh",
    "check_morton_inputs",
    "check_packed",
    "check_resolution",
    "check_structure",
    "check_trace_inputs",
    "check_two_level_knobs",
    "check_walk",
    "choose_structure",
    "expand_ranges",
    "grid_resolutions",
    "intersect_pairs",
    "moller_trumbore_rows",
    "new_closest",
    "new_counters",
    "pack_bvh",
    "pair_chunks",
    "ray_octants",
    "scene_statistics",
    "slab_test",
    "surface_area",
    "test_ranges",
    "triangle_bounds",
]
