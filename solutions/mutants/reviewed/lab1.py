"""Lab 1's generated mutants that survive the graders, reviewed (see
``solutions/mutants/reviewed/__init__.py``)."""

EQUIVALENT = {
    "lab1_intersect:ray_box:const_int:5": (
        "a t_far margin of 3 gamma(3) instead of 2 stays conservative and differs by about gamma(3)"
        " relative: only rays missing the box by that much change, which the contract lets go "
        "either way (the docstring says so)"
    ),
    "lab1_intersect:closest_hit:drop_clamp:0": (
        "the lab's kernels return t = inf, never NaN, for misses (masked_result), so some column "
        "always equals the row minimum (column 0 when all are inf): the clamp never binds"
    ),
    "lab1_intersect:woop_precompute:cmp_Gt_GtE:0": (
        "area2 == 0 makes n / area2 NaN (0/0) or inf, so the transform is not finite and the "
        "isfinite check zeroes it anyway"
    ),
    "lab1_intersect:closest_hit:const_int:0": (
        "default memory_budget_bytes 2**28 -> 3**28 changes the tiling only, and the result "
        'does not depend on it: docstring: "ties in ``t`` go to the lowest triangle index '
        'whatever the tiling"'
    ),
    "lab1_intersect:closest_hit:const_int:1": (
        "default memory_budget_bytes 2**28 -> 2**29 changes the tiling only, and the result "
        'does not depend on it: docstring: "ties in ``t`` go to the lowest triangle index '
        'whatever the tiling"'
    ),
    "lab1_intersect:closest_hit:const_int:2": (
        "pairs floor 1 -> 2 (only when the budget is below one pair) changes the tiling only, "
        'and the result does not depend on it: docstring: "ties in ``t`` go to the lowest '
        'triangle index whatever the tiling"'
    ),
    "lab1_intersect:closest_hit:const_int:3": (
        "ray_chunk floor 1 -> 2 changes the tiling only, and the result does not depend on it:"
        ' docstring: "ties in ``t`` go to the lowest triangle index whatever the tiling"'
    ),
    "lab1_intersect:closest_hit:op_Sub_Add:0": (
        "same as closest_hit:drop_clamp:0: some column always equals the row minimum, so the "
        "clamp (whatever its bound) never binds"
    ),
}
