"""Lab 1's contracts: each promise a student function's docstring makes (and the
conventions shared by every kernel, in the lab's docstring, ``lab1_intersect/__init__.py``),
with the grader test that fails when that promise alone is broken and, where one is shipped,
the mutant (``solutions/mutants/lab1.py``) that breaks just it.
``tests/meta/test_contracts.py`` keeps these lists, the graders and the mutants in step."""


def kernel(name: str) -> list:
    """The conventions every triangle kernel promises (the lab's docstring), with its tests."""
    return [
        (
            "hits in the closed interval [t_min, t_max]; t = inf, u = v = 0 for a miss",
            f"test_{name}_degenerate_and_interval_cases",
            None,
        ),
        (
            "parallel rays, zero-area triangles, NaN/inf coordinates miss, never NaN",
            f"test_{name}_degenerate_and_interval_cases",
            None,
        ),
        (
            "t, u, v of the float64 solution for clear-cut pairs, both windings",
            f"test_{name}_matches_float64_reference",
            None,
        ),
        (
            "directions of any length: t in units of |d|, the same hits",
            f"test_{name}_any_direction_length",
            None,
        ),
        (
            "grazing rays, huge and tiny coordinates: the contract's extremes",
            f"test_{name}_extremes",
            None,
        ),
        (
            "ValueError / TypeError naming the argument for malformed input",
            f"test_{name}_matches_float64_reference",
            None,
        ),
    ]


CONTRACTS = {
    "intersect_simple": kernel("intersect_simple")
    + [
        (
            "inside by signed sub-triangle areas (all >= 0)",
            "test_intersect_simple_matches_float64_reference",
            "simple_unsigned_areas",
        ),
        (
            "t == t_max is a hit",
            "test_intersect_simple_degenerate_and_interval_cases",
            "simple_open_t_max",
        ),
        (
            "step 4: accept where 16 eps R^2 |n|_max <= n . n (equality too), "
            "R = |v0 - p|_max + max(|e1|_max, |e2|_max) of absolute values",
            "test_intersect_simple_degenerate_and_interval_cases",
            "simple_reach_without_size",
        ),
    ],
    "moller_trumbore": kernel("moller_trumbore")
    + [
        (
            "q = s x e1 (Cramer's rule as written)",
            "test_moller_trumbore_matches_float64_reference",
            "mt_swapped_cross",
        ),
        (
            "hits before t_min are rejected",
            "test_moller_trumbore_degenerate_and_interval_cases",
            "mt_t_gt_zero",
        ),
        (
            "t == t_min is a hit",
            "test_moller_trumbore_degenerate_and_interval_cases",
            "mt_open_t_min",
        ),
        (
            "inside needs u + v <= 1",
            "test_moller_trumbore_matches_float64_reference",
            "mt_no_u_plus_v",
        ),
        (
            "the parallel test is relative: |det| <= eps |d| |e1| |e2|",
            "test_moller_trumbore_matches_float64_reference",
            "mt_absolute_epsilon",
        ),
        (
            "the parallel tolerance scales with |d|",
            "test_moller_trumbore_any_direction_length",
            "mt_parallel_test_without_direction",
        ),
        (
            "|det| == eps |d| |e1| |e2| exactly is parallel; max-norms of absolute values",
            "test_moller_trumbore_degenerate_and_interval_cases",
            "mt_max_norm_without_abs",
        ),
    ],
    "woop_precompute": [
        (
            "rows map v0, v1, v2 to the unit triangle's corners",
            "test_woop_precompute_maps_to_unit_triangle",
            "woop_rows_swapped",
        ),
        (
            "the third row is the unit normal: v0 + n -> (0, 0, 1)",
            "test_woop_precompute_rounded_once_from_float64",
            "woop_third_row_not_unit",
        ),
        (
            "computed in float64 and rounded once",
            "test_woop_precompute_rounded_once_from_float64",
            "woop_transform_in_input_precision",
        ),
        (
            "each triangle's transform depends on its own corners only (batched as alone)",
            "test_woop_precompute_maps_to_unit_triangle",
            None,
        ),
        (
            "a degenerate triangle gets the zero transform, which every ray misses",
            "test_woop_unit_degenerate_and_interval_cases",
            None,
        ),
        (
            "ValueError / TypeError naming v0, v1 or v2",
            "test_woop_unit_matches_float64_reference",
            None,
        ),
    ],
    "woop_unit": kernel("woop_unit")
    + [
        (
            "y row: reject v < 0",
            "test_woop_unit_matches_float64_reference",
            "woop_no_v_lower_bound",
        ),
        ("t == t_min is a hit", "test_woop_unit_degenerate_and_interval_cases", "woop_open_t_min"),
    ],
    "watertight": kernel("watertight")
    + [
        (
            "edge functions that round to 0 are recomputed in float64 (exact signs)",
            "test_watertight_decides_exactly_near_edges",
            "watertight_no_double_fallback",
        ),
        (
            "the fallback runs where any of U, V, W rounds to 0 (not only U)",
            "test_watertight_decides_exactly_near_edges",
            "watertight_fallback_only_on_u",
        ),
        (
            "T compared with t_min det, t_max det sign-corrected: back faces hit",
            "test_watertight_matches_float64_reference",
            "watertight_no_sign_correction",
        ),
        (
            "t == t_max is a hit",
            "test_watertight_degenerate_and_interval_cases",
            "watertight_open_t_max",
        ),
        (
            "no cracks: a ray through a shared edge or vertex hits a triangle sharing it",
            "test_watertight_has_no_cracks_on_a_closed_mesh",
            None,
        ),
    ],
    "safe_reciprocal": [
        (
            "1/+0 = +inf, 1/-0 = -inf: no epsilon, the sign of zero kept",
            "test_ray_box_matches_slabs",
            "safe_reciprocal_epsilon",
        ),
    ],
    "ray_box": [
        (
            "a ray starting on a slab plane with d = 0: the NaN slab says nothing (fmax/fmin)",
            "test_ray_box_matches_slabs",
            "box_nan_poisons_slabs",
        ),
        (
            "t_near is the latest entry into the slabs",
            "test_ray_box_matches_slabs",
            "box_min_for_t_near",
        ),
        ("a flat box (min == max) is not empty", "test_ray_box_matches_slabs", "box_flat_is_empty"),
        (
            "every |inv_direction| > 0: an infinite direction misses, even from inside the box",
            "test_ray_box_matches_slabs",
            None,
        ),
        ("default t_min = 0: t_near = 0 from inside the box", "test_ray_box_matches_slabs", None),
        (
            "hit = t_near <= t_far: an interval of one point hits",
            "test_ray_box_matches_slabs",
            "box_touching_interval_misses",
        ),
        (
            "conservative: t_far scaled by 1 + 2 gamma(3), rounding never loses a hit",
            "test_ray_box_is_conservative",
            None,
        ),
        ("an empty box and NaN/inf rays never hit", "test_ray_box_ray_sphere_hidden_cases", None),
    ],
    "ray_sphere": [
        (
            "the discriminant as a (r^2 - |l|^2): small spheres far away",
            "test_ray_sphere_small_and_far",
            "sphere_naive_quadratic",
        ),
        (
            "the nearer root in [t_min, t_max], else the farther (rays from inside)",
            "test_ray_sphere_matches_float64",
            "sphere_near_root_only",
        ),
        (
            "a = d . d: directions of any length",
            "test_ray_sphere_matches_float64",
            "sphere_assumes_unit_direction",
        ),
        (
            "a negative radius gives inf",
            "test_ray_sphere_negative_radius_misses",
            "sphere_negative_radius_hits",
        ),
        (
            "NaN/inf origins or directions and a zero direction give inf",
            "test_ray_sphere_matches_float64",
            None,
        ),
    ],
    "closest_hit": [
        (
            "the nearest hit, not the first in index order",
            "test_closest_hit_matches_reference",
            "closest_first_hit",
        ),
        (
            "a tile's local index plus its offset",
            "test_closest_hit_respects_memory_budget",
            "closest_no_chunk_offset",
        ),
        (
            "ties go to the lowest index across tiles (strictly nearer replaces)",
            "test_closest_hit_matches_reference",
            "closest_ties_to_later_chunk",
        ),
        (
            "ties go to the lowest index within a tile",
            "test_closest_hit_matches_reference",
            "closest_ties_to_highest_index",
        ),
        (
            "every triangle tested whatever the budget (the ragged last tile too)",
            "test_closest_hit_respects_memory_budget",
            "closest_drops_ragged_chunk",
        ),
        (
            "ValueError / TypeError naming rays, mesh, variant or memory_budget_bytes",
            "test_closest_hit_closed_mesh_and_errors",
            None,
        ),
    ],
    "op_counts": [
        (
            "cycles_bound = 4 (pairs + |add - mul|), pairs = min(mul, add)",
            "test_op_counts",
            "cycles_bound_without_mad",
        ),
        ("pairs are min(mul, add), not mul", "test_op_counts", "cycles_bound_pairs_are_muls"),
        ("ValueError naming variant for an unknown name", "test_op_counts", None),
    ],
    "register_estimate": [
        ("peak_last_use of live_values, rounded up", "test_register_estimate_and_occupancy", None),
    ],
    "occupancy_for": [
        (
            "the occupancy of block_size threads per block",
            "test_register_estimate_and_occupancy",
            "occupancy_ignores_block_size",
        ),
        (
            "defaults: arch 'g80', block_size 64",
            "test_register_estimate_and_occupancy",
            None,
        ),
        ("ValueError naming variant or arch", "test_register_estimate_and_occupancy", None),
    ],
}
