"""Lab 1: correct alternatives (see ``solutions/alternatives/__init__.py``)."""

from course.grading.mutants import Mutant

M = "lab1_intersect"

ALTERNATIVES = [
    Mutant(
        name="mt_divide_by_det",
        module=M,
        function="moller_trumbore",
        find="u = dot(s, p) * inv_det\n"
        "    q = cross(s, e1)\n"
        "    v = dot(directions, q) * inv_det\n"
        "    t = dot(e2, q) * inv_det",
        replace="u = dot(s, p) / det\n"
        "    q = cross(s, e1)\n"
        "    v = dot(directions, q) / det\n"
        "    t = dot(e2, q) / det",
        tests="moller_trumbore",
        why="three divisions instead of one reciprocal and three products: rounded "
        "differently (by an ulp or so), the same solution",
    ),
    Mutant(
        name="mt_float64_inside",
        module=M,
        function="moller_trumbore",
        find="""e1, e2 = v1 - v0, v2 - v0
    p = cross(directions, e2)
    det = dot(e1, p)
    scale = directions.abs().amax(-1) * e1.abs().amax(-1) * e2.abs().amax(-1)
    eps = torch.finfo(det.dtype).eps
    not_parallel = det.abs() > eps * scale
    inv_det = 1 / det
    s = origins - v0
    u = dot(s, p) * inv_det
    q = cross(s, e1)
    v = dot(directions, q) * inv_det
    t = dot(e2, q) * inv_det
    inside = (u >= 0) & (v >= 0) & (u + v <= 1)
    hit = not_parallel & inside & (t >= t_min) & (t <= t_max)
    return masked_result(hit, t, u, v)""",
        replace="""dtype = v0.dtype
    eps = torch.finfo(dtype).eps  # "parallel to within rounding" of the inputs' dtype
    o, d, a, b, c = (x.to(torch.float64) for x in (origins, directions, v0, v1, v2))
    e1, e2 = b - a, c - a
    p = cross(d, e2)
    det = dot(e1, p)
    scale = d.abs().amax(-1) * e1.abs().amax(-1) * e2.abs().amax(-1)
    not_parallel = det.abs() > eps * scale
    s = o - a
    q = cross(s, e1)
    u, v, t = (x.to(dtype) for x in (dot(s, p) / det, dot(d, q) / det, dot(e2, q) / det))
    inside = (u >= 0) & (v >= 0) & (u + v <= 1)
    hit = not_parallel & inside & (t >= t_min) & (t <= t_max)
    return masked_result(hit, t, u, v)""",
        tests="moller_trumbore",
        why="the whole solve in float64 and each of t, u, v rounded once to the inputs' "
        "dtype (inside and interval tests on the rounded values, as the reference's): more "
        "accurate, the same contract",
    ),
]
