"""Lab 6: correct alternatives (see ``solutions/alternatives/__init__.py``)."""

from course.grading.mutants import Mutant

M = "lab6_raster"

ALTERNATIVES = [
    Mutant(
        name="rasterize_chunks_last_first",
        module=M,
        function="rasterize",
        find="""    K, first = screen.shape[0], 0
    while first < K:
        before = int(ends[first - 1]) if first else 0
        last = max(first + 1, int(torch.searchsorted(ends, before + per_chunk, right=True)))
        chunk = screen[first:last]""",
        replace="""    K, first, spans = screen.shape[0], 0, []
    while first < K:
        before = int(ends[first - 1]) if first else 0
        last = max(first + 1, int(torch.searchsorted(ends, before + per_chunk, right=True)))
        spans.append((first, last))
        first = last
    for first, last in reversed(spans):  # the depth test's minimum ignores the order
        chunk = screen[first:last]""",
        tests="rasterize",
        why="the same chunks drawn last first: an atomic minimum of (depth, id) keys gives "
        "the same buffer in any order",
    ),
    Mutant(
        name="edge_functions_float64_inside",
        module=M,
        function="edge_functions",
        find="a = tri[..., [1, 2, 0], :2]",
        replace="if tri.dtype != torch.float64:  # the work in float64, rounded once\n"
        "        dtype = torch.result_type(tri, px)\n"
        "        return edge_functions(tri.double(), px.double(), py.double()).to(dtype)\n"
        "    a = tri[..., [1, 2, 0], :2]",
        tests="coverage",
        why="the edge functions of the corners in float64, rounded once: still exactly "
        "opposite on a shared edge (rounding is symmetric), more accurate",
    ),
]
