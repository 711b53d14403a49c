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
}
