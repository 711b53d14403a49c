"""Lab 5: correct alternatives (see ``solutions/alternatives/__init__.py``)."""

from course.grading.mutants import Mutant

M = "lab5_froxel"

ALTERNATIVES = [
    Mutant(
        name="slice_depths_by_power",
        module=M,
        function="slice_depths",
        find="z = near * torch.exp(k / slices * math.log(far / near))",
        replace="z = near * (far / near) ** (k / slices)",
        tests="slice_depths",
        why="near (far / near)^(k / n) is the same exponential spacing; in float64 it "
        "differs from exp(k/n log(far/near)) by ulps of float64, invisible once rounded",
    ),
    Mutant(
        name="depth_to_slice_log_of_ratio",
        module=M,
        function="depth_to_slice",
        find="return (torch.log(depth) - math.log(near)) * (slices / math.log(far / near))",
        replace="return torch.log(depth / near) / math.log(far / near) * slices",
        tests="depth_to_slice",
        why="log(depth / near) / log(far / near) * n: the same inverse, rounded differently",
    ),
]
