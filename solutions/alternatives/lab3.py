"""Lab 3: correct alternatives (see ``solutions/alternatives/__init__.py``)."""

from course.grading.mutants import Mutant

M = "lab3_wavefront"

ALTERNATIVES = [
    Mutant(
        name="reflect_float64_inside",
        module=M,
        function="reflect",
        find="return normalize(directions - 2 * dot(directions, normals)[:, None] * normals)",
        replace="d, n = directions.to(torch.float64), normals.to(torch.float64)\n"
        "    return normalize(d - 2 * dot(d, n)[:, None] * n).to(directions.dtype)",
        tests="reflect",
        why="the reflection and its normalisation in float64, rounded once: more accurate",
    ),
]
