"""Lab 2's contracts: each promise a student function's docstring makes (and the conventions
every walk shares, in the lab's docstring, ``lab2_accel/__init__.py``), with the grader test
that fails when that promise alone is broken and, where one is shipped, the mutant
(``solutions/mutants/lab2.py``) that breaks just it. ``tests/meta/test_contracts.py`` keeps
these lists, the graders and the mutants in step."""

CONTRACTS = {
    # Task 1: the uniform grid
    "grid_resolution": [
        (
            "r_i = round(k * extent_i), not its floor",
            "test_grid_resolution_and_build",
            "fresh_grid_resolution_truncates",
        ),
        (
            "k = (lambda N / prod extent_i) ** (1/3): about lambda N nearly cubic cells",
            "test_grid_resolution_and_build",
            None,
        ),
        (
            "a thin axis (k * extent_i < 1) gets one cell and k is solved again over the others",
            "test_grid_resolution_and_build",
            "fresh_grid_resolution_k_not_resolved",
        ),
        (
            "at most max_cells: lambda N is capped before k is solved",
            "test_grid_resolution_and_build",
            None,
        ),
        ("a flat axis (extent 0) gets one cell", "test_grid_resolution_and_build", None),
        (
            "Python ints >= 1; ValueError naming extent or density",
            "test_grid_resolution_and_build",
            None,
        ),
    ],
    "build_grid": [
        (
            "a triangle goes into every cell its (padded) bounds overlap, up to the last one",
            "test_grid_resolution_and_build",
            "grid_cells_one_short",
        ),
        (
            "cell (x, y, z) has the linear index x + rx * (y + ry * z)",
            "test_grid_resolution_and_build",
            "fresh_grid_cell_index_z_fastest",
        ),
        (
            "CSR lists: cell_start the exclusive prefix sum of cell_count, triangles ascending",
            "test_grid_resolution_and_build",
            None,
        ),
        (
            "tri_cell_lo/hi: exactly the box of cells each triangle is listed in",
            "test_grid_resolution_and_build",
            None,
        ),
        (
            "the box contains the scene, padded relative to its size (a tiny scene too)",
            "test_grid_resolution_and_build",
            None,
        ),
        (
            "ValueError naming resolution; mesh with NaN/inf vertices named",
            "test_builders_reject_nonfinite_vertices",
            None,
        ),
    ],
    "grid_closest_hit": [
        (
            "steps: exactly the cells the ray crosses up to its hit, t_max or the grid's exit",
            "test_grid_steps_are_the_cells_crossed",
            None,
        ),
        (
            "stepping up, the next boundary is the cell's upper face lo + (cell + 1) w",
            "test_grid_closest_hit_matches_brute_force",
            "dda_lower_face_when_stepping_up",
        ),
        (
            "step along the axis of the smallest t_next, by that axis's sign(d)",
            "test_grid_closest_hit_matches_brute_force",
            "dda_step_sign_of_x",
        ),
        (
            "a hit ends the walk only inside the cell: reach(best_t) < t_out",
            "test_grid_closest_hit_matches_brute_force",
            "grid_first_hit_ends_walk",
        ),
        (
            "ends at a cell only if reach(best_t) < t_out: ties at vertices on cell boundaries",
            "test_grid_exact_at_vertices_and_edges",
            "grid_exit_without_slack",
        ),
        (
            "mailbox: skip a triangle iff the ray's previous cell lies in its box of cells",
            "test_grid_mailboxing",
            "mailbox_never_updated",
        ),
        (
            "mailbox: no previous cell at the start (-1): the first cell tests everything",
            "test_grid_closest_hit_matches_brute_force",
            "fresh_grid_mailbox_starts_at_cell_zero",
        ),
        (
            "+-0 direction components, rays on cell boundaries, in planes, far from the origin",
            "test_grid_dda_extremes",
            None,
        ),
        (
            "counters steps/tests/skipped (N,) int64; ValueError/TypeError naming the argument",
            "test_grid_closest_hit_matches_brute_force",
            None,
        ),
    ],
    # Task 2: the BVH builds
    "morton_codes": [
        (
            "interleave x highest: bit i of qx to bit 3i + 2, qy to 3i + 1, qz to 3i",
            "test_morton_codes",
            "morton_z_highest",
        ),
        (
            "q clamped to [0, 2^bits - 1]: the upper face does not carry into another axis",
            "test_morton_codes",
            "morton_no_clamp",
        ),
        (
            "q = floor((p - lo) / (hi - lo) * 2^bits)",
            "test_morton_codes",
            "fresh_morton_scale_two_bits_minus_one",
        ),
        ("q = 0 on a flat axis (hi == lo); ValueError naming points", "test_morton_codes", None),
    ],
    "build_lbvh": [
        (
            "a range splits at its highest differing Morton bit (the middle only for equal codes)",
            "test_lbvh_structure_and_quality",
            "lbvh_split_in_the_middle",
        ),
        (
            "the BVH dict: depth-first layout, boxes bound their children, each triangle once",
            "test_lbvh_structure_and_quality",
            None,
        ),
        (
            "mesh with NaN/inf vertices named; ValueError naming leaf_size",
            "test_builders_reject_nonfinite_vertices",
            None,
        ),
    ],
    "build_sah_bvh": [
        (
            "the cost A(left) N(left) + A(right) N(right): areas weighted by counts",
            "test_sah_bvh_structure_and_quality",
            "sah_cost_without_counts",
        ),
        (
            "nodes of at most leaf_size triangles become leaves",
            "test_sah_bvh_structure_and_quality",
            "fresh_sah_leaves_one_over",
        ),
        (
            "the BVH dict; coincident triangles split in the middle, so the build ends",
            "test_sah_bvh_structure_and_quality",
            None,
        ),
        (
            "ValueError naming bins; mesh with NaN/inf vertices named",
            "test_sah_bvh_structure_and_quality",
            None,
        ),
    ],
    # Task 3: BVH traversal
    "bvh_closest_hit": [
        (
            "push the far child first, so the near one is popped next",
            "test_bvh_stack_traversal",
            "bvh_far_child_first",
        ),
        (
            "cull a popped node only if its entry t is beyond reach(best_t), not best_t",
            "test_bvh_traversal_extremes",
            "fresh_bvh_cull_without_reach",
        ),
        (
            "brute force's hits at vertices and edges (ties to the lowest index)",
            "test_bvh_walks_exact_at_vertices_and_edges",
            None,
        ),
        (
            "rays missing the root visit nothing; ValueError naming mesh or bvh",
            "test_bvh_stack_traversal",
            None,
        ),
    ],
    "bvh_skip_indices": [
        (
            "skip[i] = last(i) + 1, the first node after the subtree, not one further",
            "test_bvh_stackless_traversal",
            "stackless_skip_off_by_one",
        ),
        (
            "skip[i] = last(i) + 1, not the subtree's last leaf",
            "test_bvh_stackless_traversal",
            "skip_is_last_not_after",
        ),
        (
            "M (past the end) for the subtrees that end the array",
            "test_bvh_stackless_traversal",
            None,
        ),
    ],
    "bvh_closest_hit_stackless": [
        (
            "boxes tested against [t_min, min(t_max, reach(best_t))]: no leaf beyond the hit",
            "test_bvh_stackless_traversal",
            "fresh_stackless_no_cull_by_closest_hit",
        ),
        (
            "a missed box skips its subtree: only the leaves whose box is hit are tested",
            "test_bvh_stackless_traversal",
            None,
        ),
        (
            "brute force's hits at vertices and edges, +-0 components, NaN rays",
            "test_bvh_walks_exact_at_vertices_and_edges",
            None,
        ),
    ],
    # Task 4: the kd-tree
    "build_kdtree": [
        (
            "every node splits at a cheapest event iff that strictly beats a leaf and depth and "
            "leaf_size allow; each child holds exactly the triangles its side of the event lists",
            "test_kdtree_every_node_follows_the_sah",
            None,
        ),
        (
            "a triangle straddling the split goes to both children",
            "test_kdtree_build",
            "kd_straddler_one_side",
        ),
        (
            "cost = traversal + intersect * (...) / A_node; split only if it beats a leaf",
            "test_kdtree_build",
            "fresh_kd_cost_without_traversal",
        ),
        (
            "the empty bonus only for a split with an empty side",
            "test_kdtree_build",
            "fresh_kd_bonus_always",
        ),
        (
            "the cheapest event over the three axes, planes strictly inside the node's box",
            "test_kdtree_build",
            None,
        ),
        (
            "max_depth=0 gives a single leaf; ValueError naming max_depth",
            "test_kdtree_build",
            None,
        ),
        (
            "the SAH cuts empty space away: few tests per ray at the teapot in a stadium",
            "test_kdtree_build",
            None,
        ),
    ],
    "kd_pack": [
        (
            "word 1: leftOffset bits 0-28, splitAxis 29-30, leaf bit 31 (C bit-fields)",
            "test_kd_pack_unpack",
            "kd_pack_leaf_in_bit_zero",
        ),
        (
            "inner node: leftOffset = left - i (relative)",
            "test_kd_pack_unpack",
            "fresh_kd_pack_absolute_left",
        ),
        (
            "word 0: split's float32 bits, or a leaf's count; ValueError for a 29-bit overflow",
            "test_kd_pack_unpack",
            None,
        ),
    ],
    "kd_unpack": [
        (
            "mask before shifting: >> on a leaf's negative word copies the sign bit",
            "test_kd_pack_unpack",
            "fresh_kd_unpack_unmasked_shift",
        ),
        (
            "the inverse of kd_pack: split, axis, absolute left, first, count",
            "test_kd_pack_unpack",
            None,
        ),
    ],
    "kd_closest_hit": [
        (
            "early exit only if reach(best_t) < the leaf's t_far",
            "test_kd_closest_hit",
            "kd_early_exit_anywhere",
        ),
        (
            "t_split <= 0 (plane behind, or at the origin): the near child only",
            "test_kd_closest_hit",
            "kd_plane_behind_ignored",
        ),
        (
            "a ray starting on the plane (t_split = 0) visits only the side it goes into",
            "test_kdtree_build",
            "fresh_kd_plane_at_origin_not_near_only",
        ),
        (
            "a ray lying in the plane (NaN) visits both children; ties at vertices in planes",
            "test_kd_exact_at_vertices_and_edges",
            None,
        ),
        (
            "a ray lying in the plane visits the lower child first, then the upper one: "
            "no early exit in between",
            "test_kd_rays_in_a_split_plane_visit_both_children",
            "kd_in_plane_exits_early",
        ),
    ],
    # Task 5: the entry point
    "brute_force_closest_hit": [
        (
            "every (ray, triangle) pair of a tile is tested",
            "test_closest_hit_entry_point",
            "fresh_brute_force_pairs_misaligned",
        ),
        (
            "steps = 0, tests = F; ValueError naming memory_budget_bytes",
            "test_closest_hit_entry_point",
            None,
        ),
    ],
    "closest_hit": [
        (
            "stackless=True dispatches to bvh_closest_hit_stackless",
            "test_closest_hit_entry_point",
            "fresh_closest_hit_ignores_stackless",
        ),
        (
            "'auto' builds exactly the structure choose_structure picks, nothing else",
            "test_auto_builds_only_its_choice",
            "auto_builds_a_fallback_too",
        ),
        (
            "ValueError naming structure for another kind or an option it does not take",
            "test_closest_hit_entry_point",
            None,
        ),
    ],
    # Task 6: the two-level grid
    "build_two_level_grid": [
        (
            "sub_of -1 for plain cells; sub_resolution exactly grid_resolution of the small "
            "triangles; top grid at density 1/16; big from one top cell wide; boxes padded a "
            "little, tight sub-cell lists",
            "test_build_two_level_grid_sub_grids_exactly",
            None,
        ),
        (
            "big triangles (a top cell wide) stay in the direct lists, never in a sub-grid",
            "test_two_level_build",
            "two_level_big_triangles_in_sub_grids",
        ),
        (
            "a sub-grid iff a top cell holds MORE than min_triangles small triangles",
            "test_two_level_build",
            "fresh_two_level_sub_grid_at_min_triangles",
        ),
        (
            "sub-grid boxes: their small triangles' bounds clipped to the top cell",
            "test_two_level_build",
            "fresh_two_level_sub_box_not_clipped",
        ),
        (
            "the top grid as build_grid at top_density; sub resolutions by the heuristic",
            "test_two_level_build",
            None,
        ),
        (
            "ValueError naming top_density, density or min_triangles",
            "test_two_level_build",
            None,
        ),
    ],
    "two_level_closest_hit": [
        (
            "steps on plain top cells: exactly the cells crossed, as the uniform grid's walk",
            "test_two_level_steps_on_plain_cells",
            None,
        ),
        (
            "the mailbox trusts a previous top cell only if it was plain (or the triangle big)",
            "test_two_level_mailboxing_and_work",
            "two_level_mailbox_after_crowded_cell",
        ),
        (
            "a sub-grid walk ends only at a hit inside its sub cell",
            "test_two_level_matches_brute_force",
            "two_level_sub_walk_stops_at_any_hit",
        ),
        (
            "sub cell ids start at sub_cell_base of their sub-grid",
            "test_two_level_matches_brute_force",
            "two_level_sub_cell_without_base",
        ),
        (
            "brute force's hits at vertices on top and sub cell boundaries",
            "test_two_level_exact_at_vertices_and_edges",
            None,
        ),
        (
            "mailboxing changes the tests, never the hits; few tests at the teapot",
            "test_two_level_mailboxing_and_work",
            None,
        ),
    ],
    # Task 7: the fixed-shape walk
    "bvh_closest_hit_fast": [
        (
            "a leaf's slots: all of first .. first + count - 1",
            "test_fast_bvh_matches_brute_force",
            "fast_leaf_slots_one_short",
        ),
        (
            "any_hit: a ray stops at its first hit",
            "test_fast_bvh_any_hit_and_knobs",
            "fast_any_hit_never_stops",
        ),
        (
            "the array of the ray's own octant: near child first",
            "test_fast_bvh_matches_brute_force",
            "fast_far_child_first",
        ),
        (
            "among equal t the lowest triangle index",
            "test_fast_bvh_matches_brute_force",
            "fast_tie_to_highest_index",
        ),
        (
            "a missed box jumps to skip, over its subtree",
            "test_fast_bvh_matches_brute_force",
            "fast_miss_descends",
        ),
        (
            "boxes against [t_min, min(t_max, reach(best_t))]: culled by the closest hit",
            "test_fast_bvh_matches_brute_force",
            "fast_no_cull_by_closest_hit",
        ),
        (
            "culled through reach(best_t), not best_t: ties at vertices",
            "test_fast_bvh_exact_at_vertices_and_edges",
            "fast_cull_without_slack",
        ),
        (
            "the knobs (check_every, compact, walk) never change the hits or counters",
            "test_fast_bvh_any_hit_and_knobs",
            None,
        ),
        (
            'compile="reduce-overhead" with a walk: cached CUDA graphs of padded sizes; a '
            "compaction goes on with the rays still running, never the padding (CUDA only)",
            "test_fast_bvh_cached_graphs_compact",
            None,
        ),
    ],
}
