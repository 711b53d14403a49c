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
    "lab1_intersect:ray_box:const_int:6": (
        "a t_far margin of 2 gamma(4) instead of 2 gamma(3) stays conservative and differs by "
        'about gamma(3) relative; docstring: "a few ``gamma(3)`` is as good: ``t_far`` is graded'
        ' to about 1e-5, and a ray missing the box by less may go either way"'
    ),
    "lab1_intersect:ray_sphere:cmp_GtE_Gt:1": (
        "differs only for radius 0 (or -0.0), a point: a hit needs disc = a (0 - |l|^2) to be "
        "exactly 0, and then both roots c / q and q / a are the same distance up to rounding, so "
        "returning the far root instead of the near one changes t by a few ulps at most"
    ),
    "lab1_intersect:ray_sphere:cmp_GtE_Gt:3": (
        "differs only for radius 0 (or -0.0), where the two roots are the same distance up to "
        "rounding (disc must be exactly 0 for a hit): the far root is only needed when the near"
        " one is out of [t_min, t_max], which then holds for the far one too up to an ulp"
    ),
    "lab1_intersect:register_estimate:const_int:0": (
        "live_values(..., lanes=2) on accounting_inputs(variant), whose tensors have leading "
        "dim 1: a size-1 dim matches any lane count as broadcast, so every tensor counts the "
        "same values per lane and peak_last_use is the same"
    ),
    "lab1_intersect:register_estimate:round_ceil_floor:0": (
        "with one lane every tensor's values per lane is its element count (an integer), so "
        "peak_last_use is an integer and floor equals ceil"
    ),
    "lab1_intersect:watertight:bool_And_Or:0": (
        "entering the fallback also when nothing needs it is a no-op: for float32 with no exact "
        "zero the mask is empty (nothing written), for float64 it recomputes the same products "
        "in the same dtype, bit for bit"
    ),
    "lab1_intersect:watertight:cmp_Lt_LtE:0": (
        "dz <= 0 differs from dz < 0 only for dz = +-0, i.e. a zero direction (dz is the "
        "largest |d| component); then sz = 1 / dz is infinite and ray_ok rejects the ray "
        "whatever the axes"
    ),
    "lab1_intersect:watertight:cmp_Lt_LtE:1": (
        "as cmp_Lt_LtE:0: only a zero direction has dz = +-0, and ray_ok (sz finite) rejects it"
    ),
    "lab1_intersect:watertight:cmp_Lt_LtE:5": (
        "det <= 0 differs only at det == 0, where hit is already False (det != 0); T_abs and "
        "det_abs only feed hit and the outputs are masked by it"
    ),
    "lab1_intersect:watertight:const_int:1": (
        "kx = (kz + 1) % 4 gives 3 only for kz = 2, and torch.take_along_dim wraps the index "
        "(3 reads component 0, as (2 + 1) % 3) in this PyTorch on the CPU, where mutants are "
        "graded: the same axes"
    ),
    "lab1_intersect:watertight:swap_cross:0": (
        "cross(e2, e1) is -cross(e1, e2) exactly, component for component (the same two "
        "products, subtracted the other way round, round symmetrically), so the test "
        "(== 0).all(-1) is the same"
    ),
    "lab1_intersect:woop_unit:const_int:7": (
        "u <= 2 instead of u <= 1 in the x row's early exit: the y row requires v >= 0 and "
        "u + v <= 1, and rounding is monotone (fl(u + v) >= u for v >= 0), so every surviving"
        " hit has u <= 1 anyway; NaN fails both"
    ),
}
