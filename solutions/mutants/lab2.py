"""Lab 2 mutants: typical mistakes in acceleration structures, each applied to the
reference solution. Every one must lose points on the tests its ``tests`` expression selects.

Only mistakes the grader can see are listed: a wrong hit (compared with brute force), a
wrong count, a wrong bit, or a tree whose SAH cost or traversal work is measurably worse.
(A correct but slower variant, such as SAH bins bounded by centroids instead of triangle
bounds, costs about 5% and is not a mutant.)
"""

from course.grading.mutants import Mutant

M = "lab2_accel"
GRID = "grid_closest_hit or grid_dda or grid_mailboxing"
GRID2 = "two_level_matches or two_level_mailboxing"  # the traversal's tests

MUTANTS = [
    Mutant(
        name="grid_cells_one_short",
        module=M,
        function="build_grid",
        find="c_hi = torch.minimum(torch.floor((tri_hi + pad - lo) / cell).long()"
        ".clamp(min=0), top)",
        replace="c_hi = torch.minimum(torch.floor((tri_hi + pad - lo) / cell).long().clamp(min=0) "
        "- 1, top).clamp(min=c_lo)",
        tests="grid_resolution_and_build",
        why="an off-by-one in the last cell of a triangle's box: a triangle that reaches "
        "into the next cell is not listed there, and rays through that cell miss it",
    ),
    Mutant(
        name="dda_lower_face_when_stepping_up",
        module=M,
        function="grid_closest_hit",
        find="boundary = lo + (cell + (step > 0).long()) * width",
        replace="boundary = lo + cell * width",
        tests=GRID,
        why="off by one cell: stepping up, the next boundary is the cell's upper face "
        "lo + (cell + 1) w, not its lower face",
    ),
    Mutant(
        name="dda_step_sign_of_x",
        module=M,
        function="grid_closest_hit",
        find="cell = cell.scatter_add(1, axis, step.gather(1, axis))",
        replace="cell = cell.scatter_add(1, axis, step[:, :1])",
        tests=GRID,
        why="steps the chosen axis with the x axis's direction: the walk leaves the ray",
    ),
    Mutant(
        name="grid_first_hit_ends_walk",
        module=M,
        function="grid_closest_hit",
        find='done = (reach(closest["t"][ray]) < t_out) | (t_out >= t_end)',
        replace='done = (closest["t"][ray] < math.inf) | (t_out >= t_end)',
        tests=GRID,
        why="the classic grid bug: a triangle spanning cells is hit beyond the current "
        "cell, and stopping there misses a nearer triangle in the next cell",
    ),
    Mutant(
        name="mailbox_never_updated",
        module=M,
        function="grid_closest_hit",
        find="        prev = cell\n",
        replace="",
        tests=GRID,
        why="the mailbox (the previous cell) is never updated: every cell re-tests the "
        "triangles it shares with the last one",
    ),
    Mutant(
        name="morton_z_highest",
        module=M,
        function="morton_codes",
        find="for axis, shift in ((0, 2), (1, 1), (2, 0)):",
        replace="for axis, shift in ((0, 0), (1, 1), (2, 2)):",
        tests="morton",
        why="interleaves z into the highest bit of each triple instead of x",
    ),
    Mutant(
        name="morton_no_clamp",
        module=M,
        function="morton_codes",
        find=".clamp(0, 2**bits - 1)",
        replace="",
        tests="morton",
        why="a point on the box's upper face quantises to 2^bits and carries into the "
        "next axis's bit",
    ),
    Mutant(
        name="lbvh_split_in_the_middle",
        module=M,
        function="build_lbvh",
        find="same = differ == 0",
        replace="same = differ >= 0",
        tests="lbvh",
        why="halves every range instead of splitting at the highest differing Morton bit: "
        "valid, but the boxes overlap and the SAH cost grows 40-70%",
    ),
    Mutant(
        name="sah_cost_without_counts",
        module=M,
        function="build_sah_bvh",
        find="surface_area(left_lo[..., :-1, :], left_hi[..., :-1, :]) * n_l\n"
        "            + surface_area(right_lo[..., 1:, :], right_hi[..., 1:, :]) * n_r\n",
        replace="surface_area(left_lo[..., :-1, :], left_hi[..., :-1, :])\n"
        "            + surface_area(right_lo[..., 1:, :], right_hi[..., 1:, :])\n",
        tests="sah_bvh",
        why="minimises the children's areas without weighting them by their triangle "
        "counts: splits off slivers, a much deeper and costlier tree",
    ),
    Mutant(
        name="bvh_far_child_first",
        module=M,
        function="bvh_closest_hit",
        find="for push, t_push, ok in ((far, t_far, hit_far), (near, t_near, hit_near)):",
        replace="for push, t_push, ok in ((near, t_near, hit_near), (far, t_far, hit_far)):",
        tests="bvh_stack_traversal",
        why="pushes the near child first, so the far one is popped first: still correct, "
        "but the far side is searched before the hit that would cull it",
    ),
    Mutant(
        name="stackless_skip_off_by_one",
        module=M,
        function="bvh_skip_indices",
        find="return last + 1",
        replace="return last + 2",
        tests="stackless or bvh_traversal_extremes",
        why="the skip link jumps one node too far: it skips the next sibling subtree",
    ),
    Mutant(
        name="kd_early_exit_anywhere",
        module=M,
        function="kd_closest_hit",
        find='exit_early = leaf & ~no_exit & (reach(closest["t"][ray]) < t_far)',
        replace='exit_early = leaf & ~no_exit & (closest["t"][ray] < math.inf)',
        tests="kd_closest_hit or kdtree_build",
        why="stops at the first leaf with a hit, even one beyond the leaf: a straddling "
        "triangle hides a nearer one in the next leaf",
    ),
    Mutant(
        name="kd_plane_behind_ignored",
        module=M,
        function="kd_closest_hit",
        find="near_only = ~in_plane & ((t_split > reach(tf)) | (t_split <= 0))",
        replace="near_only = ~in_plane & (t_split > reach(tf))",
        tests="kd_closest_hit or kdtree_build",
        why="a plane behind the ray (or at t = -inf for d = -0.0) sends it to the far child "
        "only: it never visits the side it is on",
    ),
    Mutant(
        name="kd_straddler_one_side",
        module=M,
        function="build_kdtree",
        find="below, above = r_start < best_event[s], r_end > best_event[s]",
        replace="below, above = r_start < best_event[s], r_start >= best_event[s]",
        tests="kdtree_build",
        why="a triangle straddling the plane goes below only: rays in the upper child miss it",
    ),
    Mutant(
        name="kd_pack_leaf_in_bit_zero",
        module=M,
        function="kd_pack",
        find='word1 = offset | (tree["axis"].clamp(min=0) << OFFSET_BITS) | (leaf.long() << 31)',
        replace='word1 = (offset << 3) | (tree["axis"].clamp(min=0) << 1) | leaf.long()',
        tests="kd_pack",
        why="packs the fields in the opposite order (leaf in bit 0): another layout than "
        "the C bit-fields the GPU code reads",
    ),
    Mutant(
        name="two_level_big_triangles_in_sub_grids",
        module=M,
        function="build_two_level_grid",
        find="big = (tri_hi - tri_lo).amax(dim=1) >= width.amin()",
        replace="big = torch.zeros(mesh.num_faces, dtype=torch.bool, device=device)",
        tests="two_level_build or two_level_mailboxing",
        why="puts the stadium's floor into the teapot's sub-grid: its box becomes the whole "
        "floor of the top cell, and the teapot falls into one or two sub cells again",
    ),
    Mutant(
        name="two_level_mailbox_after_crowded_cell",
        module=M,
        function="two_level_closest_hit",
        find="                seen &= prev_plain[owner] | big[tri]\n",
        replace="",
        tests=GRID2,
        why="trusts the mailbox after a crowded top cell: a small triangle whose sub cells "
        "the ray did not cross there was never tested, and is skipped here",
    ),
    Mutant(
        name="two_level_sub_walk_stops_at_any_hit",
        module=M,
        function="_walk_sub_grids",
        find='done = (reach(closest["t"][ray]) < t_out) | (t_out >= s_out)',
        replace='done = (closest["t"][ray] < math.inf) | (t_out >= s_out)',
        tests=GRID2,
        why="the classic grid bug, one level down: a hit found in a sub cell may lie "
        "beyond it, with a nearer triangle in the next sub cell",
    ),
    Mutant(
        name="two_level_sub_cell_without_base",
        module=M,
        function="_walk_sub_grids",
        find="cell_id = base + cell[:, 0] + res[:, 0] * (cell[:, 1] + res[:, 1] * cell[:, 2])",
        replace="cell_id = cell[:, 0] + res[:, 0] * (cell[:, 1] + res[:, 1] * cell[:, 2])",
        tests=GRID2,
        why="indexes every sub-grid's cells from 0: all sub-grids read the first one's lists",
    ),
    Mutant(
        name="fast_leaf_slots_one_short",
        module=M,
        function="_fast_step",
        find="end = torch.where(into_leaf, first + count, end)",
        replace="end = torch.where(into_leaf, first + count - 1, end)",
        tests="fast_bvh",
        why="a leaf's slot range stops one short: the last triangle of every leaf is never tested",
    ),
    Mutant(
        name="fast_any_hit_never_stops",
        module=M,
        function="_fast_step",
        find="node = torch.where(best_tri >= 0, m, node)",
        replace="node = node",
        tests="fast_bvh",
        why="any-hit mode keeps searching after the first hit: a shadow ray costs as much "
        "as a closest-hit ray",
    ),
    Mutant(
        name="fast_far_child_first",
        module=M,
        function="_start",
        find="ints[0] = base[ray_octants(directions)]",
        replace="ints[0] = base[7 - ray_octants(directions)]",
        tests="fast_bvh",
        why="walks the array of the opposite octant, far child first: correct hits (where "
        "that octant is packed), but the near side's hit never culls the far side",
    ),
    Mutant(
        name="fast_tie_to_highest_index",
        module=M,
        function="_fast_step",
        find="((t == best_t) & (index < best_tri))",
        replace="((t == best_t) & (index > best_tri))",
        tests="fast_bvh",
        why="among hits at the same t keeps the highest triangle index, not brute force's lowest",
    ),
    Mutant(
        name="fast_miss_descends",
        module=M,
        function="_fast_step",
        find="torch.where(down, node + 1, skip)",
        replace="torch.where(active, node + 1, skip)",
        tests="fast_bvh",
        why="goes to node + 1 after a missed box too, instead of skipping its subtree: "
        "right hits, but the walk tests every triangle",
    ),
    Mutant(
        name="fast_no_cull_by_closest_hit",
        module=M,
        function="_fast_step",
        find="t_in, t_out = t_min, torch.minimum(t_max, reach(best_t))",
        replace="t_in, t_out = t_min, t_max",
        tests="fast_bvh",
        why="tests boxes against [t_min, t_max] only: boxes behind the closest hit are "
        "still entered (right hits, wasted work)",
    ),
    Mutant(
        name="fast_cull_without_slack",
        module=M,
        function="_fast_step",
        find="t_in, t_out = t_min, torch.minimum(t_max, reach(best_t))",
        replace="t_in, t_out = t_min, torch.minimum(t_max, best_t)",
        tests="fast_bvh_exact_at_vertices",
        why="culls a box entered at the closest hit's t, rounding included: at a vertex the "
        "triangle brute force picks (ties to the lowest index) may be in that box",
    ),
    Mutant(
        name="grid_exit_without_slack",
        module=M,
        function="grid_closest_hit",
        find='done = (reach(closest["t"][ray]) < t_out) | (t_out >= t_end)',
        replace='done = (closest["t"][ray] <= t_out) | (t_out >= t_end)',
        tests="grid_exact_at_vertices",
        why="ends in a cell whose exit the hit reaches only up to rounding: a ray through a "
        "vertex on a cell boundary misses the next cell's tie with a lower index",
    ),
    Mutant(
        name="auto_builds_a_fallback_too",
        module=M,
        function="closest_hit",
        find="        structure = build(mesh, kind, **knobs)\n",
        replace='        fallback = build(mesh, "bvh", method="lbvh")  # just in case\n'
        '        structure = build(mesh, kind, **knobs) if kind != "bvh" else fallback\n',
        tests="auto_builds_only_its_choice",
        why="builds an LBVH 'just in case' next to the chosen structure (and uses it for "
        "every BVH pick): the scene pays for a structure it did not ask for",
    ),
    # Fresh mistakes, written from the docstrings
    Mutant(
        name="skip_is_last_not_after",
        module=M,
        function="bvh_skip_indices",
        find="return last + 1",
        replace="return last",
        tests="stackless or bvh_traversal_extremes",
        why="skip[i] is the first node AFTER the subtree (last(i) + 1), not its last leaf",
    ),
    Mutant(
        name="fresh_grid_resolution_truncates",
        module=M,
        function="grid_resolution",
        find="max(1, round(extent[a] * k))",
        replace="max(1, int(extent[a] * k))",
        tests="grid_resolution",
        why="r_i = round(k * extent_i), not its floor: truncating gives up to a cell less per "
        "axis (2.9 -> 2), far fewer cells than lambda N",
    ),
    Mutant(
        name="fresh_grid_resolution_k_not_resolved",
        module=M,
        function="grid_resolution",
        find="        if not thin:\n            break\n",
        replace="        break\n",
        tests="grid_resolution",
        why="a thin axis gets one cell but k is not solved again over the other axes: a flat "
        "scene gets far fewer than lambda N cells",
    ),
    Mutant(
        name="fresh_grid_cell_index_z_fastest",
        module=M,
        function="build_grid",
        find="cell_id = x + res[0] * (y + res[1] * z)",
        replace="cell_id = z + res[2] * (y + res[1] * x)",
        tests="grid_resolution_and_build",
        why="numbers the cells z fastest: the documented linear index is x + rx * (y + ry * z), "
        "and a walk that uses it reads another cell's list",
    ),
    Mutant(
        name="fresh_grid_mailbox_starts_at_cell_zero",
        module=M,
        function="grid_closest_hit",
        find="prev = torch.full_like(cell, -1)  # no previous cell: nothing is in the mailbox",
        replace="prev = torch.zeros_like(cell)",
        tests=GRID,
        why="the mailbox starts as cell (0, 0, 0) instead of 'none': a ray's first cell skips "
        "every triangle that is also listed in the corner cell",
    ),
    Mutant(
        name="fresh_morton_scale_two_bits_minus_one",
        module=M,
        function="morton_codes",
        find="scale = torch.where(extent > 0, 2.0**bits / extent, torch.zeros_like(extent))",
        replace="scale = torch.where(extent > 0, (2.0**bits - 1) / extent, "
        "torch.zeros_like(extent))",
        tests="morton",
        why="quantises with 2^bits - 1 steps instead of q = floor((p - lo) / (hi - lo) * 2^bits)",
    ),
    Mutant(
        name="fresh_sah_leaves_one_over",
        module=M,
        function="build_sah_bvh",
        find="inner = end - start > leaf_size",
        replace="inner = end - start > leaf_size + 1",
        tests="sah_bvh",
        why="keeps a node of leaf_size + 1 triangles as a leaf: 'nodes of at most this many "
        "triangles become leaves' (the other off-by-one, >= leaf_size, never ends for "
        "leaf_size = 1: a node of one triangle splits forever)",
    ),
    Mutant(
        name="fresh_bvh_cull_without_reach",
        module=M,
        function="bvh_closest_hit",
        find='live = t_node <= reach(closest["t"][ray])',
        replace='live = t_node <= closest["t"][ray]',
        tests="bvh_traversal_extremes or bvh_walks_exact",
        why="culls a node entered at the closest hit's t up to rounding: at a vertex the "
        "triangle brute force picks (ties to the lowest index) may be in that node",
    ),
    Mutant(
        name="fresh_stackless_no_cull_by_closest_hit",
        module=M,
        function="bvh_closest_hit_stackless",
        find='t_hi = torch.minimum(rays.t_max[ray], reach(closest["t"][ray]))',
        replace="t_hi = rays.t_max[ray]",
        tests="stackless",
        why="tests boxes against [t_min, t_max] only: boxes behind the closest hit are still "
        "entered (right hits, wasted work)",
    ),
    Mutant(
        name="fresh_kd_cost_without_traversal",
        module=M,
        function="_kd_sweep",
        find="        traversal_cost\n        + intersect_cost\n",
        replace="        intersect_cost\n",
        tests="kdtree_build",
        why="the SAH cost without the traversal constant: splits that cost more than a leaf "
        "look cheaper, the tree grows too deep",
    ),
    Mutant(
        name="fresh_kd_bonus_always",
        module=M,
        function="_kd_sweep",
        find="* (1 - empty_bonus * empty)",
        replace="* (1 - empty_bonus)",
        tests="kdtree_build",
        why="takes the empty-side bonus off every split, not only the ones with an empty side",
    ),
    Mutant(
        name="fresh_kd_pack_absolute_left",
        module=M,
        function="kd_pack",
        find='offset = torch.where(leaf, tree["first"], tree["left"] - index)',
        replace='offset = torch.where(leaf, tree["first"], tree["left"])',
        tests="kd_pack",
        why="stores the lower child's absolute index as leftOffset instead of left - i",
    ),
    Mutant(
        name="fresh_kd_unpack_unmasked_shift",
        module=M,
        function="kd_unpack",
        find="word0, word1 = packed[:, 0], packed[:, 1].long() & 0xFFFFFFFF",
        replace="word0, word1 = packed[:, 0], packed[:, 1].long()",
        tests="kd_pack",
        why="shifts the signed word: >> on a leaf's negative word copies the sign bit, so "
        "leaf = (word1 >> 31) == 1 is never true",
    ),
    Mutant(
        name="fresh_kd_plane_at_origin_not_near_only",
        module=M,
        function="kd_closest_hit",
        find="near_only = ~in_plane & ((t_split > reach(tf)) | (t_split <= 0))",
        replace="near_only = ~in_plane & ((t_split > reach(tf)) | (t_split < 0))",
        tests="kd_closest_hit or kdtree_build",
        why="a ray starting on the split plane (t_split = 0) visits the far child, the one "
        "behind it, with the whole rest of the interval",
    ),
    Mutant(
        name="fresh_two_level_sub_grid_at_min_triangles",
        module=M,
        function="build_two_level_grid",
        find="dense = n_small > min_triangles",
        replace="dense = n_small >= min_triangles",
        tests="two_level_build",
        why="a cell gets a sub-grid with exactly min_triangles small triangles: the docstring "
        "says more than min_triangles",
    ),
    Mutant(
        name="fresh_two_level_sub_box_not_clipped",
        module=M,
        function="build_two_level_grid",
        find='box_lo = torch.maximum(inf.scatter_reduce(0, index, tri_lo[tri], "amin"), cell_lo)',
        replace='box_lo = inf.scatter_reduce(0, index, tri_lo[tri], "amin")',
        tests="two_level_build",
        why="the sub-grid's box is its triangles' bounds, not clipped to the top cell: it "
        "spills into the neighbours and wastes sub cells there",
    ),
    Mutant(
        name="fresh_brute_force_pairs_misaligned",
        module=M,
        function="brute_force_closest_hit",
        find="r.repeat_interleave(len(tri)),",
        replace="r.repeat(len(tri)),",
        tests="closest_hit_entry_point",
        why="pairs r.repeat with tri.repeat: the tile tests ray i against triangle i only, "
        "not every (ray, triangle) pair",
    ),
    Mutant(
        name="fresh_closest_hit_ignores_stackless",
        module=M,
        function="closest_hit",
        find='traverse = bvh_closest_hit_stackless if options.get("stackless") '
        "else bvh_closest_hit",
        replace="traverse = bvh_closest_hit",
        tests="closest_hit_entry_point",
        why="accepts stackless=True but always walks with the stack",
    ),
    Mutant(
        name="kd_in_plane_exits_early",
        module=M,
        function="kd_closest_hit",
        find='exit_early = leaf & ~no_exit & (reach(closest["t"][ray]) < t_far)',
        replace='exit_early = leaf & (reach(closest["t"][ray]) < t_far)',
        tests="kd_rays_in_a_split_plane",
        why="a ray lying in a split plane exits early in the first child it visits (whose "
        "interval is the whole one), before the other child that alone lists a nearer "
        "triangle",
    ),
]
