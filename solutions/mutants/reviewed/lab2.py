"""Lab 2's generated mutants that survive the graders, reviewed (see
``solutions/mutants/reviewed/__init__.py``)."""

EQUIVALENT = {
    "lab2_accel:build_lbvh:const_int:34": (
        "an inner node's 'first' is never read (only leaves hold triangles[first:first + count], "
        "and count is 0 for inner nodes), so 1 instead of 0 there changes nothing"
    ),
    "lab2_accel:kd_pack:const_int:10": (
        "packed - 2**33 instead of packed - 2**32 before .to(torch.int32): the conversion keeps the"
        " low 32 bits, the same for both"
    ),
    "lab2_accel:bvh_closest_hit_fast:bool_And_Or:4": (
        "compacting the rays at every look instead of only when few run changes only the order in "
        "which unfinished rays are stepped, not their hits or counters"
    ),
    "lab2_accel:build_lbvh:op_Sub_Add:7": (
        "before is read only at a node's start and at its right child's start, both the start of "
        "exactly one leaf: '+' adds 2 to both and their difference (left_size) is unchanged; leaf "
        "rows are masked"
    ),
    "lab2_accel:build_two_level_grid:drop_clamp:0": (
        "a sub-grid exists only for a cell with n_small > min_triangles >= 0, so n_sub >= 1 for "
        "every sub-grid: the clamp never binds"
    ),
    "lab2_accel:bvh_closest_hit_fast:const_int:0": (
        "the default check_every only sets how many steps run between host looks; extra steps of "
        "finished rays change nothing (a timing knob)"
    ),
    "lab2_accel:bvh_closest_hit_fast:const_int:8": (
        "the loop bound m + F + 1 already covers a ray's box tests and slots; a looser bound only "
        "allows more looks, and the loop breaks when no ray runs"
    ),
    "lab2_accel:bvh_closest_hit_fast:const_int:10": (
        "replays a cached graph twice per look (CUDA graphs only): extra steps of finished rays "
        "change nothing, unfinished ones only get further before the next look"
    ),
    "lab2_accel:bvh_closest_hit_fast:op_BitOr_BitAnd:0": (
        "dict | None is an annotation, never evaluated (from __future__ import annotations)"
    ),
    "lab2_accel:bvh_closest_hit_fast:const_int:1": (
        "the default fuse_steps matters only when compiled, and how many steps one call runs never "
        "changes hits or counters (a timing knob)"
    ),
    "lab2_accel:bvh_closest_hit_fast:const_int:3": (
        "the largest check_every accepted (1024 or 1025): a sanity limit the docstring does not "
        "promise; every accepted value gives the same hits"
    ),
    "lab2_accel:bvh_closest_hit_fast:const_int:5": (
        "the largest fuse_steps accepted (64 or 65): a sanity limit, a timing knob"
    ),
    "lab2_accel:bvh_closest_hit_fast:bool_And_Or:2": (
        "copies the gathered rows into tensors of their own on the eager path too: the same values,"
        " one copy more"
    ),
    "lab2_accel:bvh_closest_hit_fast:const_int:7": (
        "range(1, m + F + 1, k) runs at least m + F steps, as many as a ray can need (one per node "
        "box and one per leaf slot)"
    ),
    "lab2_accel:bvh_closest_hit_fast:const_int:9": (
        "a graph of two calls per replay (CUDA graphs only): extra steps of finished rays change "
        "nothing, unfinished ones only get further before the next look"
    ),
    "lab2_accel:bvh_closest_hit_fast:cmp_Lt_LtE:0": (
        "counts finished rays as running: the walk never compacts or stops early and runs to the "
        "loop bound, whose steps change nothing for finished rays (host time only)"
    ),
    "lab2_accel:bvh_closest_hit_fast:cmp_LtE_Lt:0": (
        "compacts at one ray fewer: when to compact changes only the order in which unfinished rays"
        " are stepped, not their hits or counters"
    ),
    "lab2_accel:bvh_closest_hit_fast:cmp_LtE_GtE:0": (
        "compacts when many rays run instead of few: when to compact changes only the order in "
        "which unfinished rays are stepped, not their hits or counters"
    ),
    "lab2_accel:bvh_closest_hit_fast:cmp_GtE_Gt:0": (
        "compacts only from one ray more than the floor: when to compact changes only the order in "
        "which unfinished rays are stepped, not their hits or counters"
    ),
    "lab2_accel:bvh_closest_hit_fast:cmp_GtE_LtE:0": (
        "compacts only below the floor (on the CPU: never): when to compact changes only the order "
        "in which unfinished rays are stepped, not their hits or counters "
        "(tests/meta/test_lab2_graph_emulated.py checks the floor itself)"
    ),
    "lab2_accel:bvh_closest_hit_fast:const_int:13": (
        "compacts at a ninth instead of an eighth (CUDA graphs): when to compact changes only the "
        "order in which unfinished rays are stepped, not their hits or counters"
    ),
    "lab2_accel:bvh_closest_hit_fast:const_int:14": (
        "compacts at a third instead of half: when to compact changes only the order in which "
        "unfinished rays are stepped, not their hits or counters"
    ),
    "lab2_accel:grid_closest_hit:cmp_Gt_GtE:0": (
        "differs only where step == 0, where t_next is replaced by inf through torch.where: the "
        "boundary computed there is never used"
    ),
    "lab2_accel:grid_resolution:const_float:1": (
        "k's initial value is read only when no axis has a positive extent, and then every axis "
        "returns 1 without reading k"
    ),
    "lab2_accel:grid_resolution:cmp_Lt_LtE:0": (
        "differs only where k * extent_a == 1 exactly: dropping that axis solves k again to the "
        "same value (k'^(d-1) = lambda N / (prod / extent_a) = k^d extent_a = k^(d-1)), and the "
        "axis gets round(1) = 1 cell either way"
    ),
    "lab2_accel:build_grid:const_float:1": (
        "a pad of 1.1e-4 instead of 1e-4 of the scene's size: the docstring leaves the pad's size "
        "free ('the small pad (and the padded box) keeps rounding from dropping a triangle'); the "
        "grader bounds it (at most 1e-3 of the size plus a few ulps)"
    ),
    "lab2_accel:build_grid:const_int:0": (
        "17 ulps of the coordinates in the pad instead of 16: the docstring leaves the pad's size "
        "free ('the small pad ... keeps rounding from dropping a triangle')"
    ),
    "lab2_accel:build_grid:drop_abs:0": (
        "max(lo, |hi|) instead of max(|lo|, |hi|) per axis: smaller only where lo < 0 and |lo| > "
        "|hi|, by at most the axis's extent, so the pad's ulps term shrinks by at most 16 eps * "
        "size, far below its relative term 1e-4 * size; the pad's size is free"
    ),
    "lab2_accel:build_grid:drop_abs:1": (
        "max(|lo|, hi) equals max(|lo|, |hi|): hi < 0 implies lo <= hi < 0, so |hi| < |lo|"
    ),
    "lab2_accel:build_grid:const_float:2": (
        "the pad of a scene that is a single point (size 0, at the origin): 1.1 instead of 1.0; the"
        " docstring asks only for a box with a thickness ('gives a flat scene a thickness'), any "
        "size will do"
    ),
    "lab2_accel:build_grid:drop_clamp:0": (
        "tri_lo - pad - lo >= 0 in floating point: lo = fl(min tri_lo - pad) and rounding is "
        "monotone, so fl(tri_lo - pad) >= lo and the floor is >= 0: the clamp never binds"
    ),
    "lab2_accel:build_grid:drop_clamp:1": (
        "tri_hi + pad - lo >= tri_lo - pad - lo >= 0 in floating point (monotone rounding, lo = "
        "fl(min tri_lo - pad)): the floor is >= 0, the clamp never binds"
    ),
    "lab2_accel:bvh_closest_hit:cmp_GtE_Gt:0": (
        "left[i] is never 0: node 0 is the root, where every walk starts, and no node's child (a "
        "child's index is larger than its parent's), so left is >= 1 for inner nodes and -1 for "
        "leaves: left > 0 or left >= 0 tests the same"
    ),
    "lab2_accel:bvh_closest_hit:const_int:13": (
        "left[i] is never 0: node 0 is the root, where every walk starts, and no node's child (a "
        "child's index is larger than its parent's), so left is >= 1 for inner nodes and -1 for "
        "leaves: left >= 1 or left >= 0 tests the same"
    ),
    "lab2_accel:bvh_closest_hit:cmp_Lt_LtE:0": (
        "left[i] is never 0: node 0 is the root, where every walk starts, and no node's child (a "
        "child's index is larger than its parent's), so left is >= 1 for inner nodes and -1 for "
        "leaves: left <= 0 or left < 0 tests the same"
    ),
    "lab2_accel:bvh_closest_hit:const_int:12": (
        "left[i] is never 0: node 0 is the root, where every walk starts, and no node's child (a "
        "child's index is larger than its parent's), so left is >= 1 for inner nodes and -1 for "
        "leaves: left < 1 or left < 0 tests the same"
    ),
    "lab2_accel:bvh_skip_indices:cmp_Lt_LtE:0": (
        "left[i] is never 0: node 0 is the root, where every walk starts, and no node's child (a "
        "child's index is larger than its parent's), so left is >= 1 for inner nodes and -1 for "
        "leaves: left <= 0 or left < 0 tests the same"
    ),
    "lab2_accel:bvh_skip_indices:const_int:0": (
        "left[i] is never 0: node 0 is the root, where every walk starts, and no node's child (a "
        "child's index is larger than its parent's), so left is >= 1 for inner nodes and -1 for "
        "leaves: left < 1 or left < 0 tests the same"
    ),
    "lab2_accel:bvh_closest_hit_stackless:cmp_Lt_LtE:0": (
        "left[i] is never 0: node 0 is the root, where every walk starts, and no node's child (a "
        "child's index is larger than its parent's), so left is >= 1 for inner nodes and -1 for "
        "leaves: left <= 0 or left < 0 tests the same"
    ),
    "lab2_accel:bvh_closest_hit_stackless:const_int:1": (
        "left[i] is never 0: node 0 is the root, where every walk starts, and no node's child (a "
        "child's index is larger than its parent's), so left is >= 1 for inner nodes and -1 for "
        "leaves: left < 1 or left < 0 tests the same"
    ),
    "lab2_accel:bvh_closest_hit:cmp_Gt_GtE:0": (
        "the stack's capacity only: it starts wider or grows earlier or by more; a ray never pushes"
        " beyond the capacity either way (test_bvh_stack_traversal and test_kd_closest_hit walk a "
        "40-deep chain that needs the growth)"
    ),
    "lab2_accel:bvh_closest_hit:const_int:9": (
        "the stack's capacity only: it starts wider or grows earlier or by more; a ray never pushes"
        " beyond the capacity either way (test_bvh_stack_traversal and test_kd_closest_hit walk a "
        "40-deep chain that needs the growth)"
    ),
    "lab2_accel:bvh_closest_hit:const_int:10": (
        "the stack's capacity only: it starts wider or grows earlier or by more; a ray never pushes"
        " beyond the capacity either way (test_bvh_stack_traversal and test_kd_closest_hit walk a "
        "40-deep chain that needs the growth)"
    ),
    "lab2_accel:bvh_closest_hit:const_int:4": (
        "the stack's capacity only: it starts wider or grows earlier or by more; a ray never pushes"
        " beyond the capacity either way (test_bvh_stack_traversal and test_kd_closest_hit walk a "
        "40-deep chain that needs the growth)"
    ),
    "lab2_accel:kd_closest_hit:const_int:2": (
        "the stack's capacity only: it starts wider or grows earlier or by more; a ray never pushes"
        " beyond the capacity either way (test_bvh_stack_traversal and test_kd_closest_hit walk a "
        "40-deep chain that needs the growth)"
    ),
    "lab2_accel:kd_closest_hit:cmp_Gt_GtE:0": (
        "the stack's capacity only: it starts wider or grows earlier or by more; a ray never pushes"
        " beyond the capacity either way (test_bvh_stack_traversal and test_kd_closest_hit walk a "
        "40-deep chain that needs the growth)"
    ),
    "lab2_accel:kd_closest_hit:const_int:6": (
        "the stack's capacity only: it starts wider or grows earlier or by more; a ray never pushes"
        " beyond the capacity either way (test_bvh_stack_traversal and test_kd_closest_hit walk a "
        "40-deep chain that needs the growth)"
    ),
    "lab2_accel:kd_closest_hit:const_int:7": (
        "the stack's capacity only: it starts wider or grows earlier or by more; a ray never pushes"
        " beyond the capacity either way (test_bvh_stack_traversal and test_kd_closest_hit walk a "
        "40-deep chain that needs the growth)"
    ),
    "lab2_accel:bvh_closest_hit:const_int:5": (
        "the root's entry t is read only at the first pop, when nothing has been tested yet (best_t"
        " = inf), so the root is live whatever t is stored; column 1 is written by the second push "
        "before it is read"
    ),
    "lab2_accel:bvh_closest_hit:const_int:6": (
        "a looser loop bound (3 M + 1): each iteration pops one entry per active ray and a node is "
        "pushed at most once per ray, so M iterations suffice and the loop breaks when no ray runs"
    ),
    "lab2_accel:bvh_closest_hit:const_int:7": (
        "a looser loop bound (2 M + 2): M iterations suffice (one pop each, a node pushed at most "
        "once per ray) and the loop breaks when no ray runs"
    ),
    "lab2_accel:bvh_closest_hit:op_Add_Sub:0": (
        "2 M - 1 iterations: each iteration pops one entry per active ray and a node is pushed at "
        "most once per ray, so M <= 2 M - 1 (M >= 1) iterations suffice"
    ),
    "lab2_accel:bvh_closest_hit:cmp_LtE_Lt:1": (
        "which child goes first when both are entered at the same t: neither is nearer, the "
        "docstring's near-first order leaves that tie free, and the hits do not depend on the order"
        " (ties in t go to the lowest index in intersect_pairs)"
    ),
    "lab2_accel:kd_closest_hit:const_int:3": (
        "a looser loop bound (3 M + 1): a ray reaches each node at most once (from its parent, by "
        "descent or one push), so M iterations suffice and the loop breaks when no ray runs"
    ),
    "lab2_accel:kd_closest_hit:const_int:4": (
        "a looser loop bound (2 M + 2): a ray reaches each node at most once, so M iterations "
        "suffice"
    ),
    "lab2_accel:kd_closest_hit:op_Add_Sub:0": (
        "2 M - 1 iterations: a ray reaches each node at most once (from its parent, by descent or "
        "one push), so M <= 2 M - 1 (M >= 1) iterations suffice"
    ),
    "lab2_accel:bvh_closest_hit_stackless:const_int:2": (
        "a looser loop bound (M + 2): every step moves right, so at most M steps per ray, and the "
        "loop breaks when no ray runs"
    ),
    "lab2_accel:bvh_skip_indices:const_int:1": (
        "65 rounds of pointer jumping instead of 64: the loop breaks as soon as a round changes "
        "nothing, after about log2(depth) rounds"
    ),
    "lab2_accel:kd_pack:cmp_GtE_Gt:2": (
        "the int64 -> int32 conversion keeps the low 32 bits (torch wraps), and adding or "
        "subtracting 2^32 (or not) changes none of them: every wrap variant gives the same words"
    ),
    "lab2_accel:kd_pack:cmp_GtE_LtE:2": (
        "the int64 -> int32 conversion keeps the low 32 bits (torch wraps), and adding or "
        "subtracting 2^32 (or not) changes none of them: every wrap variant gives the same words"
    ),
    "lab2_accel:kd_pack:const_int:7": (
        "the int64 -> int32 conversion keeps the low 32 bits (torch wraps), and adding or "
        "subtracting 2^32 (or not) changes none of them: every wrap variant gives the same words"
    ),
    "lab2_accel:kd_pack:const_int:8": (
        "the int64 -> int32 conversion keeps the low 32 bits (torch wraps), and adding or "
        "subtracting 2^32 (or not) changes none of them: every wrap variant gives the same words"
    ),
    "lab2_accel:kd_pack:op_Sub_Add:1": (
        "the int64 -> int32 conversion keeps the low 32 bits (torch wraps), and adding or "
        "subtracting 2^32 (or not) changes none of them: every wrap variant gives the same words"
    ),
    "lab2_accel:kd_pack:swap_where:2": (
        "the int64 -> int32 conversion keeps the low 32 bits (torch wraps), and adding or "
        "subtracting 2^32 (or not) changes none of them: every wrap variant gives the same words"
    ),
    "lab2_accel:morton_codes:const_float:1": (
        "NaN products become 0.001 instead of 0: floor(0.001) = 0, the same q"
    ),
    "lab2_accel:morton_codes:drop_nan_to_num:0": (
        "without nan_to_num, floor(NaN).clamp(...) stays NaN and .long() gives INT64_MIN (only bit "
        "63 set, on the CPU and CUDA alike); the bit spread's masks keep bits 0..62 only, so that "
        "axis contributes 0, exactly as q = 0 (test_morton_codes checks a NaN coordinate)"
    ),
    "lab2_accel:brute_force_closest_hit:const_int:0": (
        "the default memory budget 3^27: the tiling of brute force only: every (ray, triangle) pair"
        " is still tested exactly once through intersect_pairs, so hits and counters (steps 0, "
        "tests F) are the same"
    ),
    "lab2_accel:brute_force_closest_hit:const_int:1": (
        "the default memory budget 2^28: the tiling of brute force only: every (ray, triangle) pair"
        " is still tested exactly once through intersect_pairs, so hits and counters (steps 0, "
        "tests F) are the same"
    ),
    "lab2_accel:brute_force_closest_hit:const_int:2": (
        "at least 2 pairs a tile instead of 1: the tiling of brute force only: every (ray, "
        "triangle) pair is still tested exactly once through intersect_pairs, so hits and counters "
        "(steps 0, tests F) are the same"
    ),
    "lab2_accel:brute_force_closest_hit:const_int:3": (
        "tiles of budget // 257 pairs: the tiling of brute force only: every (ray, triangle) pair "
        "is still tested exactly once through intersect_pairs, so hits and counters (steps 0, tests"
        " F) are the same"
    ),
    "lab2_accel:brute_force_closest_hit:const_int:4": (
        "at least 2 rays a tile: the tiling of brute force only: every (ray, triangle) pair is "
        "still tested exactly once through intersect_pairs, so hits and counters (steps 0, tests F)"
        " are the same; only the peak memory of a tile grows (for F > budget / 256), which the "
        "grader does not measure"
    ),
    "lab2_accel:closest_hit:const_int:0": (
        "the hint for 0 or 1 rays becomes 2: choose_structure reads the hint only as rays_hint < 4 "
        "F (F >= 1), true for both, so the same kind and knobs are built; its reason string is not "
        "returned"
    ),
    "lab2_accel:grid_closest_hit:const_int:4": (
        "'no previous cell' as -2 instead of -1: both lie outside every triangle's box of cells "
        "(indices >= 0), so the first cell's mailbox skips nothing either way"
    ),
    "lab2_accel:grid_closest_hit:const_int:5": (
        "a looser loop bound (rx + ry + rz + 2): a DDA walk visits at most rx + ry + rz - 2 cells "
        "(its first, then one per boundary crossed, r - 1 at most per axis)"
    ),
    "lab2_accel:grid_closest_hit:op_Add_Sub:2": (
        "rx + ry + rz - 1 iterations: a DDA walk visits at most rx + ry + rz - 2 cells (its first, "
        "then one per boundary crossed, r - 1 at most per axis)"
    ),
    "lab2_accel:two_level_closest_hit:const_int:4": (
        "'no previous top cell' as -2 instead of -1: both lie outside every triangle's box of top "
        "cells (indices >= 0)"
    ),
    "lab2_accel:two_level_closest_hit:const_int:5": (
        "a looser loop bound for the top walk (rx + ry + rz + 2): a DDA walk visits at most rx + ry"
        " + rz - 2 top cells"
    ),
    "lab2_accel:two_level_closest_hit:op_Add_Sub:2": (
        "rx + ry + rz - 1 iterations of the top walk: a DDA walk visits at most rx + ry + rz - 2 "
        "cells (its first, then one per boundary crossed, r - 1 at most per axis)"
    ),
    "lab2_accel:two_level_closest_hit:cmp_Gt_GtE:0": (
        "differs only where step == 0, where t_next is replaced by inf through torch.where: the "
        "boundary computed there is never used"
    ),
    "lab2_accel:two_level_closest_hit:const_int:16": (
        "the sub-grid walk's 'previous top cell was not plain' as -2 instead of -1: both lie "
        "outside every triangle's box of top cells (indices >= 0), so nothing is skipped either way"
    ),
    "lab2_accel:build_kdtree:op_BitOr_BitAnd:0": (
        "int | None is an annotation, never evaluated (from __future__ import annotations)"
    ),
    "lab2_accel:build_kdtree:const_int:11": (
        "the root's initial 'left' entry as a 2-element tensor: the first level's iteration (which "
        "always runs, max_depth >= 0) replaces the whole list entry (left[-1] = child) before it "
        "is read"
    ),
    "lab2_accel:build_kdtree:const_int:12": (
        "the root's initial 'left' entry as -2: the first level's iteration (which always runs, "
        "max_depth >= 0) replaces it (left[-1] = child) before it is read"
    ),
    "lab2_accel:build_kdtree:const_int:47": (
        "a new level's 'left' entries start at -2: a level is appended only when some node splits,"
        " which needs depth < max_depth, so the next iteration runs and replaces them (left[-1] = "
        "child) before they are read"
    ),
    "lab2_accel:build_kdtree:const_int:14": (
        "range(max_depth + 2): the iteration at depth max_depth never splits (no sweep, best_cost "
        "inf) and breaks, so the extra iteration is never reached"
    ),
    "lab2_accel:build_kdtree:cmp_Gt_GtE:0": (
        "p >= 0 instead of p > 0: a level always has pairs (the root has F >= 1, and every "
        "triangle of a splitting node goes to at least one child), so p >= 1 and both are true"
    ),
    "lab2_accel:build_kdtree:const_int:15": (
        "p > 1 instead of p > 0 differs only where p == 1: the root of a single triangle (later "
        "levels hold >= leaf_size + 1 >= 2 pairs); its only events are its own bounds, the faces "
        "of the root box, none strictly inside: a leaf either way"
    ),
    "lab2_accel:build_kdtree:const_int:20": (
        "the default event (2p - 2 instead of 2p - 1) of a node without a finite-cost event: it "
        "is taken only where better is true, which needs a finite axis_best, and then the "
        "scatter_reduce has set the node's event; plane[2p - 2] stays a valid index (p >= 1)"
    ),
    "lab2_accel:build_kdtree:cmp_Lt_LtE:1": (
        "a later axis wins a tie of equal cheapest costs: the docstring asks for 'its cheapest "
        "event' and leaves the choice among equally cheap planes free (test_kdtree_build and "
        "test_kdtree_every_node_follows_the_sah accept any of them); nodes without a finite cost "
        "do not split either way"
    ),
    "lab2_accel:kd_closest_hit:cmp_Lt_LtE:1": (
        "ends at a leaf also where reach(best_t) == t_far to the last bit: reach's slack (2 "
        "gamma(3) + HIT_ULPS eps) bounds the rounding of a plane crossing and of a hit's t, so a "
        "later leaf, entered at >= t_far up to that rounding, holds no hit at or before best_t "
        "unless every rounding hits its worst case at once; no input found"
    ),
    "lab2_accel:kd_closest_hit:cmp_Gt_GtE:2": (
        "drops the far child also where t_split == reach(t_far) to the last bit: the far child "
        "then begins beyond the node's exit by reach's whole slack, which bounds the rounding of "
        "the crossings; a hit there lies beyond t_far (the box exit or t_max); no input found"
    ),
    "lab2_accel:kd_closest_hit:cmp_Lt_LtE:3": (
        "drops the near child also where reach(t_split) == t_near to the last bit: the near child "
        "then ends before the ray's entry by reach's whole slack, which bounds the rounding of "
        "the crossings, so it holds no part of the ray's interval; no input found"
    ),
    "lab2_accel:grid_closest_hit:cmp_Lt_LtE:0": (
        "ends also where reach(best_t) == t_out to the last bit: a triangle hit at or before "
        "best_t meets the ray inside this cell (up to the rounding reach's slack bounds), so its "
        "bounds overlap the cell and it is listed, and was tested, here; no input found"
    ),
    "lab2_accel:two_level_closest_hit:cmp_Lt_LtE:0": (
        "ends also where reach(best_t) == t_out to the last bit: a triangle hit at or before "
        "best_t meets the ray inside this top cell (up to the rounding reach's slack bounds), so "
        "it is in the cell's direct list or its sub-grid, walked here to reach(t_out); no input "
        "found"
    ),
    "lab2_accel:build_two_level_grid:const_float:1": (
        "a sub-grid pad of 1.1e-4 instead of 1e-4 of its size: the docstring leaves the pad's "
        "size free ('padded like the top grid'); the grader bounds it (at most 1e-3 of the size "
        "plus a few ulps, and more than nothing: check_sub_grids)"
    ),
    "lab2_accel:build_two_level_grid:const_int:15": (
        "17 ulps of the coordinates in a sub-grid's pad instead of 16: the pad's size is free "
        "('padded like the top grid ... plus a few ulps of its coordinates')"
    ),
    "lab2_accel:build_two_level_grid:drop_abs:0": (
        "max(lo, |hi|) instead of max(|lo|, |hi|) per axis of a sub-grid box: smaller only where "
        "lo < 0 and |lo| > |hi|, by at most the axis's extent, so the ulps term shrinks by at "
        "most 16 eps * size, far below the relative term 1e-4 * size; the pad's size is free"
    ),
    "lab2_accel:build_two_level_grid:drop_abs:1": (
        "max(|lo|, hi) equals max(|lo|, |hi|): hi < 0 implies lo <= hi < 0, so |hi| < |lo|"
    ),
    "lab2_accel:build_two_level_grid:const_float:2": (
        "the pad of a sub-grid whose box is a single point at the origin (size and coordinates "
        "0): 1.1e-4 instead of 1e-4 of the top cell's width; any thickness will do (as for "
        "build_grid's single point), and both stay far inside the top cell"
    ),
    "lab2_accel:build_lbvh:op_Div_Mult:0": (
        "centres (lo + hi) * 2 instead of / 2: the centres and their bounding box both double, "
        "and doubling is exact, so p - lo and hi - lo double exactly and every Morton code is "
        "the same; it differs only once |lo + hi| * 2 overflows (coordinates beyond a quarter "
        "of the dtype's largest float, 8.5e37 in float32), where the docstring's own q = (p - "
        "lo) * 2^bits may overflow too"
    ),
    "lab2_accel:build_lbvh:const_int:4": (
        "the root-leaf case marks the root's split -2 instead of -1: split is read only as "
        "split < 0 (a leaf) and through split.clamp(min=0), the same for both"
    ),
    "lab2_accel:build_lbvh:const_int:16": (
        "the children's split marker -2 instead of -1: split is read only as split < 0 (a leaf) "
        "and through split.clamp(min=0), the same for both"
    ),
    "lab2_accel:build_lbvh:op_Add_Sub:5": (
        "the depth-first sort key start * (F - 1) + (F - size) instead of start * (F + 1) + ...: "
        "a node starting at s has 1 <= size <= F - s, so its key lies in [s F, s F + F - 1 - s], "
        "below every key of start s + 1 and below the invalid entries' (F + 1)^2: the same order"
    ),
    "lab2_accel:build_lbvh:const_int:17": (
        "the depth-first sort key start * (F + 2) + (F - size): F - size < F + 2, so the keys "
        "still order by start, then larger nodes first, and stay below the invalid entries' "
        "(F + 1)^2 (at most (F - 1)(F + 2) + F - 1 = F^2 + 2F - 3): the same order"
    ),
    "lab2_accel:build_lbvh:const_int:18": (
        "the invalid entries' key (F + 2)^2 instead of (F + 1)^2: still above every valid key "
        "(at most (F - 1)(F + 1) + F - 1), so the same entries are picked in the same order"
    ),
    "lab2_accel:build_lbvh:const_int:19": (
        "the invalid entries' key (F + 1)^3 instead of (F + 1)^2: still above every valid key, so "
        "the same entries are picked in the same order; it would differ only where (F + 1)^3 "
        "overflows int64, from F > 2^21 triangles, beyond what a grader can build in its time"
    ),
    "lab2_accel:build_lbvh:const_int:23": (
        "starts_leaf gets F + 2 entries instead of F + 1: it is read (through before) at indices "
        "gap + 1 <= F - 1 and start <= F - 1 only, and the extra entry is never written"
    ),
    "lab2_accel:build_lbvh:drop_clamp:0": (
        "gap = split without clamp: it differs only for leaves (split = -1), where before[gap + 1]"
        " = before[0] is still a valid index and the right child computed from it is replaced by "
        "-1 (torch.where(leaf, minus, ...))"
    ),
    "lab2_accel:build_lbvh:const_int:33": (
        "an inner node's 'first' is never read (only leaves hold triangles[first:first + count], "
        "and count is 0 for inner nodes), so 1 instead of 0 there changes nothing"
    ),
    "lab2_accel:build_sah_bvh:op_Div_Mult:0": (
        "centroids (lo + hi) * 2 instead of / 2: the centroids and their bounds double exactly, so"
        " every bin (floor((c - cmin) * bins / (cmax - cmin))) is the same and the costs use the "
        "triangle bounds, not the centroids; it differs only beyond a quarter of the dtype's "
        "largest float, where every non-degenerate extent's surface area overflows anyway"
    ),
    "lab2_accel:build_sah_bvh:const_int:4": (
        "the level counter starts at 1: TreeLevels records it only as the children's depth, which "
        "assemble_bvh uses to group nodes by level bottom up; depths 0, 2, 3, ... still put every "
        "parent above its children (an empty level 1 is skipped), so the same dict"
    ),
    "lab2_accel:build_sah_bvh:const_int:58": (
        "the level counter steps by 2: TreeLevels records it only as the children's depth, which "
        "assemble_bvh uses to group nodes by level bottom up; depths 0, 1, 3, 5, ... still put "
        "every parent above its children (empty levels are skipped), so the same dict"
    ),
    "lab2_accel:build_sah_bvh:cmp_Gt_GtE:1": (
        "scale = bins / extent also where extent == 0 (never negative: cmax >= cmin): there every "
        "(c - cmin) is 0 and 0 * inf = NaN, whose floor(...).long() clamped to [0, bins - 1] is "
        "one bin for all the node's triangles on that axis, as bin 0 is: no valid split on that "
        "axis either way"
    ),
    "lab2_accel:build_sah_bvh:cmp_Gt_GtE:2": (
        "n_l >= 0 instead of n_l > 0: bin 0 always holds the triangle at the node's centroid "
        "minimum (on a flat axis: all of them), so the left count of every candidate is >= 1 and "
        "the test is true either way"
    ),
    "lab2_accel:build_sah_bvh:const_int:55": (
        "the partition's sort key seg * 3 + side instead of seg * 2 + side (side 0 or 1): still "
        "ordered by node, then left before right, and the sort is stable: the same permutation"
    ),
    "lab2_accel:bvh_closest_hit_fast:bool_And_Or:3": (
        "calls _step_graph again at every look with cached graphs: it returns the graph cached "
        "under the same key (size, dtype, device, m, fuse, any_hit, calls, tables), the one "
        "already held, so the same graph replays (host time only; CUDA graphs only)"
    ),
    "lab2_accel:kd_closest_hit:cmp_LtE_Lt:0": (
        "d[axis] < 0 instead of <= 0 for the near side differs only where o[axis] == split and "
        "d[axis] = +0.0: a ray lying in the plane, which visits both children with no early exit "
        "between them, so the order changes neither its hit nor its counters"
    ),
}
