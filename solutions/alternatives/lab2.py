"""Lab 2: correct alternatives (see ``solutions/alternatives/__init__.py``)."""

from course.grading.mutants import Mutant

M = "lab2_accel"

ALTERNATIVES = [
    Mutant(
        name="sah_last_of_tied_splits",
        module=M,
        function="build_sah_bvh",
        find="best_cost, best = cost.min(dim=1)",
        replace="best_cost, last = cost.flip(1).min(dim=1)\n"
        "        best = cost.shape[1] - 1 - last  # of equally cheap splits, the last",
        tests="sah_bvh",
        why="'take the cheapest (axis, k)' says nothing of ties: another valid BVH of the "
        "same SAH cost where two splits cost the same",
    ),
]
