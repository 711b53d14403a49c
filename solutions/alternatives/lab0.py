"""Lab 0: correct alternatives (see ``solutions/alternatives/__init__.py``)."""

from course.grading.mutants import Mutant

M = "lab0_interop"

ALTERNATIVES = [
    Mutant(
        name="numpy_view_by_asarray",
        module=M,
        function="framebuffer_to_numpy",
        find="return fb.numpy()",
        replace="return np.asarray(fb)",
        tests="framebuffer_to_numpy",
        why="np.asarray of a CPU tensor is a view of the same memory, as fb.numpy() is",
    ),
]
