"""Lab 1 mutants: typical mistakes in ray/primitive intersection, each applied to the
reference solution. Every one must lose points on the tests its ``tests`` expression selects.
"""

from course.grading.mutants import Mutant

M = "lab1_intersect"

MUTANTS = [
    Mutant(name="simple_unsigned_areas", module=M, function="intersect_simple",
           find="a0 = dot(cross(v1 - p, v2 - p), n)\n"
                "    a1 = dot(cross(v2 - p, v0 - p), n)\n"
                "    a2 = dot(cross(v0 - p, v1 - p), n)",
           replace="a0 = cross(v1 - p, v2 - p).norm(dim=-1)\n"
                   "    a1 = cross(v2 - p, v0 - p).norm(dim=-1)\n"
                   "    a2 = cross(v0 - p, v1 - p).norm(dim=-1)",
           tests="intersect_simple",
           why="unsigned sub-triangle areas are never negative: every point of the plane "
               "counts as inside"),
    Mutant(name="mt_swapped_cross", module=M, function="moller_trumbore",
           find="q = cross(s, e1)", replace="q = cross(e1, s)", tests="moller_trumbore",
           why="the cross product in the wrong order flips the signs of v and t"),
    Mutant(name="mt_t_gt_zero", module=M, function="moller_trumbore",
           find="(t >= t_min)", replace="(t > 0)", tests="moller_trumbore",
           why="ignores t_min: hits nearer than t_min, and self-hits of spawned rays"),
    Mutant(name="mt_no_u_plus_v", module=M, function="moller_trumbore",
           find=" & (u + v <= 1)", replace="", tests="moller_trumbore",
           why="without u + v <= 1 the test accepts the parallelogram beyond the far edge"),
    Mutant(name="mt_absolute_epsilon", module=M, function="moller_trumbore",
           find="det.abs() > eps * scale", replace="det.abs() > 1e-6", tests="moller_trumbore",
           why="an absolute determinant epsilon rejects every small triangle (det ~ area)"),
    Mutant(name="woop_no_v_lower_bound", module=M, function="woop_unit",
           find="hit &= (v >= 0) & (u + v <= 1)", replace="hit &= u + v <= 1", tests="woop",
           why="without v >= 0 the test accepts points beyond the edge v0-v1"),
    Mutant(name="woop_rows_swapped", module=M, function="woop_precompute",
           find="cross(e2, n) / area2, cross(n, e1) / area2",
           replace="cross(n, e1) / area2, cross(e2, n) / area2", tests="woop",
           why="the first two rows swapped map v1 to (0, 1, 0): u and v trade places"),
    Mutant(name="watertight_no_double_fallback", module=M, function="watertight",
           find="exact = (U == 0) | (V == 0) | (W == 0)",
           replace="exact = torch.zeros_like(U, dtype=torch.bool)", tests="watertight",
           why="an edge function that rounds to 0.0 loses its sign: hits just outside an edge"),
    Mutant(name="watertight_no_sign_correction", module=M, function="watertight",
           find="T_abs = torch.where(flip, -T, T)", replace="T_abs = T", tests="watertight",
           why="comparing T with t_max * |det| without flipping its sign loses every hit on "
               "a triangle seen from the back"),
    Mutant(name="box_nan_poisons_slabs", module=M, function="ray_box",
           find='t_near = torch.fmax(s["t_min"], torch.fmax(torch.fmax(lo[..., 0], lo[..., 1]), '
                'lo[..., 2]))\n'
                '    t_far = torch.fmin(s["t_max"], torch.fmin(torch.fmin(hi[..., 0], hi[..., 1]), '
                'hi[..., 2]))',
           replace='t_near = torch.maximum(s["t_min"], lo.amax(-1))\n'
                   '    t_far = torch.minimum(s["t_max"], hi.amin(-1))',
           tests="ray_box",
           why="0 * inf = NaN for a ray starting on a slab plane poisons max/min: the ray "
               "misses a box it runs along"),
    Mutant(name="box_min_for_t_near", module=M, function="ray_box",
           find="torch.fmax(torch.fmax(lo[..., 0], lo[..., 1]), lo[..., 2])",
           replace="torch.fmin(torch.fmin(lo[..., 0], lo[..., 1]), lo[..., 2])",
           tests="ray_box",
           why="t_near is the latest entry into the slabs (max), not the earliest"),
    Mutant(name="sphere_naive_quadratic", module=M, function="ray_sphere",
           find="perp = f - (b / a)[..., None] * directions  # the book's l\n"
                "    disc = a * (r * r - dot(perp, perp))\n"
                "    q = -(b + torch.copysign(torch.sqrt(disc), b))\n"
                "    t0 = c / q\n"
                "    t1 = q / a",
           replace="disc = b * b - a * c\n"
                   "    t0 = (-b - torch.sqrt(disc)) / a\n"
                   "    t1 = (-b + torch.sqrt(disc)) / a",
           tests="ray_sphere",
           why="b^2 - ac cancels catastrophically for a small sphere far away"),
    Mutant(name="closest_first_hit", module=M, function="closest_hit",
           find="first = torch.where(t == t_near, cols, t.shape[1])",
           replace="first = torch.where(t < math.inf, cols, t.shape[1])",
           tests="closest_hit",
           why="takes the first triangle hit in index order, not the nearest"),
    Mutant(name="closest_no_chunk_offset", module=M, function="closest_hit",
           find="first[:, 0] + f0", replace="first[:, 0]", tests="closest_hit",
           why="forgets the chunk's offset: triangle indices of later chunks are wrong"),
    Mutant(name="closest_ties_to_later_chunk", module=M, function="closest_hit",
           find="take = t_sel < t_best[rs]", replace="take = t_sel <= t_best[rs]",
           tests="closest_hit",
           why="equal t in a later chunk replaces the earlier hit: ties do not go to the "
               "lowest index, and the answer depends on the memory budget"),
    Mutant(name="cycles_bound_without_mad", module=M, function="op_counts",
           find="4 * (pairs + abs(counts.add - counts.mul))",
           replace="4 * (counts.mul + counts.add)", tests="op_counts",
           why="counts every mul and add as its own instruction: no mad fusion"),
]
