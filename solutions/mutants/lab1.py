"""Lab 1 mutants: typical mistakes in ray/primitive intersection, each applied to the
reference solution. Every one must lose points on the tests its ``tests`` expression selects.
"""

from course.grading.mutants import Mutant

M = "lab1_intersect"

MUTANTS = [
    Mutant(
        name="simple_unsigned_areas",
        module=M,
        function="intersect_simple",
        find="a0 = dot(cross(v1 - p, v2 - p), n)\n"
        "    a1 = dot(cross(v2 - p, v0 - p), n)\n"
        "    a2 = dot(cross(v0 - p, v1 - p), n)",
        replace="a0 = cross(v1 - p, v2 - p).norm(dim=-1)\n"
        "    a1 = cross(v2 - p, v0 - p).norm(dim=-1)\n"
        "    a2 = cross(v0 - p, v1 - p).norm(dim=-1)",
        tests="intersect_simple",
        why="unsigned sub-triangle areas are never negative: every point of the plane "
        "counts as inside",
    ),
    Mutant(
        name="mt_swapped_cross",
        module=M,
        function="moller_trumbore",
        find="q = cross(s, e1)",
        replace="q = cross(e1, s)",
        tests="moller_trumbore",
        why="the cross product in the wrong order flips the signs of v and t",
    ),
    Mutant(
        name="mt_t_gt_zero",
        module=M,
        function="moller_trumbore",
        find="(t >= t_min)",
        replace="(t > 0)",
        tests="moller_trumbore",
        why="ignores t_min: hits nearer than t_min, and self-hits of spawned rays",
    ),
    Mutant(
        name="mt_no_u_plus_v",
        module=M,
        function="moller_trumbore",
        find=" & (u + v <= 1)",
        replace="",
        tests="moller_trumbore",
        why="without u + v <= 1 the test accepts the parallelogram beyond the far edge",
    ),
    Mutant(
        name="mt_absolute_epsilon",
        module=M,
        function="moller_trumbore",
        find="det.abs() > eps * scale",
        replace="det.abs() > 1e-6",
        tests="moller_trumbore",
        why="an absolute determinant epsilon rejects every small triangle (det ~ area)",
    ),
    Mutant(
        name="woop_no_v_lower_bound",
        module=M,
        function="woop_unit",
        find="hit &= (v >= 0) & (u + v <= 1)",
        replace="hit &= u + v <= 1",
        tests="woop",
        why="without v >= 0 the test accepts points beyond the edge v0-v1",
    ),
    Mutant(
        name="woop_rows_swapped",
        module=M,
        function="woop_precompute",
        find="cross(e2, n) / area2, cross(n, e1) / area2",
        replace="cross(n, e1) / area2, cross(e2, n) / area2",
        tests="woop",
        why="the first two rows swapped map v1 to (0, 1, 0): u and v trade places",
    ),
    Mutant(
        name="watertight_no_double_fallback",
        module=M,
        function="watertight",
        find="exact = (U == 0) | (V == 0) | (W == 0)",
        replace="exact = torch.zeros_like(U, dtype=torch.bool)",
        tests="watertight",
        why="an edge function that rounds to 0.0 loses its sign: hits just outside an edge",
    ),
    Mutant(
        name="watertight_no_sign_correction",
        module=M,
        function="watertight",
        find="T_abs = torch.where(flip, -T, T)",
        replace="T_abs = T",
        tests="watertight",
        why="comparing T with t_max * |det| without flipping its sign loses every hit on "
        "a triangle seen from the back",
    ),
    Mutant(
        name="box_nan_poisons_slabs",
        module=M,
        function="ray_box",
        find='t_near = torch.fmax(s["t_min"], torch.fmax(torch.fmax(lo[..., 0], lo[..., 1]), '
        "lo[..., 2]))\n"
        '    t_far = torch.fmin(s["t_max"], torch.fmin(torch.fmin(hi[..., 0], hi[..., 1]), '
        "hi[..., 2]))",
        replace='t_near = torch.maximum(s["t_min"], lo.amax(-1))\n'
        '    t_far = torch.minimum(s["t_max"], hi.amin(-1))',
        tests="ray_box",
        why="0 * inf = NaN for a ray starting on a slab plane poisons max/min: the ray "
        "misses a box it runs along",
    ),
    Mutant(
        name="box_min_for_t_near",
        module=M,
        function="ray_box",
        find="torch.fmax(torch.fmax(lo[..., 0], lo[..., 1]), lo[..., 2])",
        replace="torch.fmin(torch.fmin(lo[..., 0], lo[..., 1]), lo[..., 2])",
        tests="ray_box",
        why="t_near is the latest entry into the slabs (max), not the earliest",
    ),
    Mutant(
        name="sphere_naive_quadratic",
        module=M,
        function="ray_sphere",
        find="perp = f - (b / a)[..., None] * directions  # the book's l\n"
        "    disc = a * (r * r - dot(perp, perp))\n"
        "    q = -(b + torch.copysign(torch.sqrt(disc), b))\n"
        "    t0 = c / q\n"
        "    t1 = q / a",
        replace="disc = b * b - a * c\n"
        "    t0 = (-b - torch.sqrt(disc)) / a\n"
        "    t1 = (-b + torch.sqrt(disc)) / a",
        tests="ray_sphere",
        why="b^2 - ac cancels catastrophically for a small sphere far away",
    ),
    Mutant(
        name="closest_first_hit",
        module=M,
        function="closest_hit",
        find="first = torch.where(t == t_near, cols, t.shape[1])",
        replace="first = torch.where(torch.isfinite(t), cols, t.shape[1])",
        tests="closest_hit",
        why="takes the first triangle hit in index order, not the nearest",
    ),
    Mutant(
        name="closest_no_chunk_offset",
        module=M,
        function="closest_hit",
        find="first[:, 0] + f0",
        replace="first[:, 0]",
        tests="closest_hit",
        why="forgets the chunk's offset: triangle indices of later chunks are wrong",
    ),
    Mutant(
        name="closest_ties_to_later_chunk",
        module=M,
        function="closest_hit",
        find="take = t_sel < t_best[rs]",
        replace="take = t_sel <= t_best[rs]",
        tests="closest_hit",
        why="equal t in a later chunk replaces the earlier hit: ties do not go to the "
        "lowest index, and the answer depends on the memory budget",
    ),
    Mutant(
        name="cycles_bound_without_mad",
        module=M,
        function="op_counts",
        find="4 * (pairs + abs(counts.add - counts.mul))",
        replace="4 * (counts.mul + counts.add)",
        tests="op_counts",
        why="counts every mul and add as its own instruction: no mad fusion",
    ),
]

# Written from the docstrings alone, as a student reads them, before looking at the tests:
# closed intervals, documented misses, precision, lengths of directions, ties and tiles.
MUTANTS += [
    Mutant(
        name="simple_open_t_max",
        module=M,
        function="intersect_simple",
        find="& (t <= t_max)",
        replace="& (t < t_max)",
        tests="intersect_simple",
        why="the interval [t_min, t_max] is closed: a hit exactly at t_max is a hit",
    ),
    Mutant(
        name="mt_open_t_min",
        module=M,
        function="moller_trumbore",
        find="(t >= t_min)",
        replace="(t > t_min)",
        tests="moller_trumbore",
        why="the interval is closed: a hit exactly at t_min is a hit",
    ),
    Mutant(
        name="mt_parallel_test_without_direction",
        module=M,
        function="moller_trumbore",
        find="scale = directions.abs().amax(-1) * e1.abs().amax(-1)",
        replace="scale = e1.abs().amax(-1)",
        tests="moller_trumbore",
        why="the parallel tolerance leaves out |d|: short directions (1e-4) lose real hits "
        "at moderate angles, long ones (1e2) let grazing garbage through",
    ),
    Mutant(
        name="woop_open_t_min",
        module=M,
        function="woop_unit",
        find='hit = (t >= s["t_min"])',
        replace='hit = (t > s["t_min"])',
        tests="woop",
        why="the interval is closed: a hit exactly at t_min is a hit",
    ),
    Mutant(
        name="woop_transform_in_input_precision",
        module=M,
        function="woop_precompute",
        find="a, b, c = v0.double(), v1.double(), v2.double()",
        replace="a, b, c = v0, v1, v2",
        tests="woop",
        why="computes the transform in float32 and rounds at every step instead of once "
        "from float64",
    ),
    Mutant(
        name="woop_third_row_not_unit",
        module=M,
        function="woop_precompute",
        find="cross(n, e1) / area2, n), dim=-2)",
        replace="cross(n, e1) / area2, n * area2), dim=-2)",
        tests="woop",
        why="the third row is the unnormalised normal: z' is no longer the signed distance "
        "(t is unchanged, the promised v0 + n -> (0, 0, 1) is not)",
    ),
    Mutant(
        name="watertight_open_t_max",
        module=M,
        function="watertight",
        find="(T_abs <= t_max * det_abs)",
        replace="(T_abs < t_max * det_abs)",
        tests="watertight",
        why="the interval is closed: a hit exactly at t_max is a hit",
    ),
    Mutant(
        name="safe_reciprocal_epsilon",
        module=M,
        function="safe_reciprocal",
        find="return torch.reciprocal(directions)",
        replace="return torch.reciprocal(torch.where(directions == 0, 1e-12, directions))",
        tests="safe_reciprocal or ray_box",
        why="replaces zero components by an epsilon: an axis-parallel ray turns slightly and "
        "-0.0 loses its sign",
    ),
    Mutant(
        name="box_flat_is_empty",
        module=M,
        function="ray_box",
        find="(box_min <= box_max).all(-1)",
        replace="(box_min < box_max).all(-1)",
        tests="ray_box",
        why="a flat box (min == max on an axis) is documented as not empty",
    ),
    Mutant(
        name="box_touching_interval_misses",
        module=M,
        function="ray_box",
        find="(t_near <= t_far) & (t_near < math.inf)",
        replace="(t_near < t_far) & (t_near < math.inf)",
        tests="ray_box",
        why="an interval of one point (a ray through an edge, a flat box) is a hit",
    ),
    Mutant(
        name="sphere_negative_radius_hits",
        module=M,
        function="ray_sphere",
        find="near_ok = (near >= t_min) & (near <= t_max) & (r >= 0)",
        replace="near_ok = (near >= t_min) & (near <= t_max)",
        tests="ray_sphere",
        why="r * r hides the sign: a sphere of negative radius, documented as a miss, hits",
    ),
    Mutant(
        name="sphere_near_root_only",
        module=M,
        function="ray_sphere",
        find="torch.where(near_ok, near, torch.where(far_ok, far, inf))",
        replace="torch.where(near_ok, near, inf)",
        tests="ray_sphere",
        why="a ray starting inside the sphere (or spawned on it with t_min > 0) must find "
        "the far side",
    ),
    Mutant(
        name="sphere_assumes_unit_direction",
        module=M,
        function="ray_sphere",
        find="a = dot(directions, directions)",
        replace="a = torch.ones_like(dot(f, f))",
        tests="ray_sphere",
        why="takes d . d = 1: t is wrong for directions that are not unit length",
    ),
    Mutant(
        name="closest_ties_to_highest_index",
        module=M,
        function="closest_hit",
        find="first = torch.where(t == t_near, cols, t.shape[1]).amin(dim=1, keepdim=True)",
        replace="first = torch.where(t == t_near, cols, -1).amax(dim=1, keepdim=True)",
        tests="closest_hit",
        why="among equal t in a tile takes the last triangle, not the lowest index",
    ),
    Mutant(
        name="closest_drops_ragged_chunk",
        module=M,
        function="closest_hit",
        find="for f0 in range(0, m, tri_chunk):",
        replace="for f0 in range(0, m - tri_chunk + 1, tri_chunk):",
        tests="closest_hit",
        why="loops over whole chunks only: with a small budget the last, shorter chunk of "
        "triangles is never tested",
    ),
    Mutant(
        name="cycles_bound_pairs_are_muls",
        module=M,
        function="op_counts",
        find="pairs = min(counts.mul, counts.add)",
        replace="pairs = counts.mul",
        tests="op_counts",
        why="counts every mul as fused with an add, also when there are fewer adds",
    ),
    Mutant(
        name="occupancy_ignores_block_size",
        module=M,
        function="occupancy_for",
        find="register_estimate(variant), block_size)",
        replace="register_estimate(variant), 64)",
        tests="occupancy",
        why="always computes the occupancy of 64-thread blocks",
    ),
    Mutant(
        name="watertight_fallback_only_on_u",
        module=M,
        function="watertight",
        find="exact = (U == 0) | (V == 0) | (W == 0)",
        replace="exact = U == 0",
        tests="watertight",
        why="runs the double fallback only when U rounds to 0: a ray grazing the edge of V or "
        "W keeps a rounded 0.0 there and is decided by luck",
    ),
    Mutant(
        name="mt_max_norm_without_abs",
        module=M,
        function="moller_trumbore",
        find="scale = directions.abs().amax(-1)",
        replace="scale = directions.amax(-1)",
        tests="moller_trumbore",
        why="the 'max-norm' of d without absolute values is negative for a direction with no "
        "positive component: every near-parallel ray passes the parallel test",
    ),
    Mutant(
        name="simple_reach_without_size",
        module=M,
        function="intersect_simple",
        find="reach = (v0 - p).abs().amax(-1) + size",
        replace="reach = (v0 - p).abs().amax(-1)",
        tests="intersect_simple",
        why="R = |v0 - p|_max alone is 0 at v0: a sliver too thin to resolve passes step 4 "
        "near its first corner",
    ),
]
