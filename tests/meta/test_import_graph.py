"""The import graph of course/, labs/ and solutions/: arrows only point down, no circles.

Read from the source with ast (imports inside functions count; relative imports are resolved),
so a lazy import cannot hide an upward arrow. Three rules:

1. A module imports only its own room and the rooms below it (``ALLOWED``); nothing imports
   the command line (``course.tools.cli``).
2. No circle between modules, lazy imports included.
3. Nothing imports ``solutions`` (or ``labs``): the grader loads a lab from its file by name,
   and a lab takes what an earlier lab made as a callable argument. A lab kept as a package
   (``solutions/lab2_accel/``) imports its own parts, and only those.

The rooms' modules are listed in CONTRIBUTING.md's layout; a lab's given code may be kept in
parts (``course/given/lab2_checks.py`` ...), which import each other, never another lab's.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

# Room -> the rooms its modules may import besides their own. Read it bottom-up: core is the
# floor; each line may only name rooms listed above it.
ALLOWED = {
    "core": set(),  # the framework: nothing of the course
    "given": {"core"},  # each lab's given code
    "measure": {"core"},  # timing, op counts, occupancy
    "kernels": {"core", "given", "measure"},  # fuse a lab's given work; report occupancy
    "grading": {"core", "given", "measure", "kernels"},  # imports what it measures
    "tools": {"core", "given", "measure", "kernels", "grading"},  # rtcourse and what it builds
    "labs": {"core", "given", "measure"},  # student skeletons
    "solutions": {"core", "given", "measure"},  # references: the same API as labs/
    "mutants": {"grading"},  # solutions/mutants/labN.py, solutions/alternatives/labN.py
}
ROOMS = ("core", "given", "measure", "kernels", "grading", "tools")
CLI = "course.tools.cli"


def module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def sources() -> dict[str, Path]:
    files = [p for p in (ROOT / "course").rglob("*.py") if "assets" not in p.parts]
    files += list((ROOT / "labs").glob("*.py")) + list((ROOT / "solutions").rglob("*.py"))
    return {module_name(p): p for p in sorted(files)}


def imports(name: str, path: Path) -> list[tuple[int, str]]:
    """``(line, dotted module)`` of every import in the file, at any depth."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                up = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(up + ([node.module] if node.module else []))
            # "from course.kernels import trace" imports the module course.kernels.trace.
            found += [(node.lineno, f"{base}.{a.name}") for a in node.names]
            found.append((node.lineno, base))
    return found


def resolve(target: str, modules) -> str | None:
    """The course/labs/solutions module a dotted import names (longest known prefix)."""
    parts = target.split(".")
    for n in range(len(parts), 0, -1):
        if ".".join(parts[:n]) in modules:
            return ".".join(parts[:n])
    return None


def room(name: str) -> str | None:
    parts = name.split(".")
    if parts[0] == "course":
        return parts[1] if len(parts) > 1 and parts[1] in ROOMS else "course"
    if parts[0] == "solutions" and len(parts) > 1 and parts[1] in ("mutants", "alternatives"):
        return "mutants"  # changes to the references, as data for the grader's meta tests
    return parts[0]


def given_lab(name: str) -> str:
    """``course.given.lab5_reference`` -> ``lab5``: the lab a given module belongs to."""
    return name.split(".")[2].split("_")[0]


@pytest.fixture(scope="module")
def graph():
    mods = sources()
    edges = {}
    for name, path in mods.items():
        edges[name] = sorted(
            {
                (line, dep)
                for line, t in imports(name, path)
                if (dep := resolve(t, mods)) and dep != name and not name.startswith(dep + ".")
            }
        )  # a package's own parents
    return mods, edges


def test_the_table_itself_points_down():
    order = list(ALLOWED)
    for i, (r, below) in enumerate(ALLOWED.items()):
        assert below <= set(order[:i]), f"ALLOWED[{r!r}] names a room listed after it"


def test_every_module_of_course_sits_in_a_named_room(graph):
    mods, _ = graph
    loose = [m for m in mods if room(m) == "course" and m != "course"]
    assert not loose, f"modules outside a named room of course/: {loose}"
    for r in ROOMS:
        doc = ast.get_docstring(ast.parse((ROOT / "course" / r / "__init__.py").read_text()))
        assert doc, f"course/{r}/__init__.py: no opening docstring saying what the room holds"


def test_imports_point_down(graph):
    mods, edges = graph
    bad = []
    for name, deps in edges.items():
        src = room(name)
        for line, dep in deps:
            where = f"{mods[name].relative_to(ROOT)}:{line} imports {dep}"
            dst = room(dep)
            if dep == CLI:
                bad.append(f"{where}: nothing imports the command line")
            elif dst in ("solutions", "labs", "mutants") and src != "mutants":
                if dep.split(".")[:2] != name.split(".")[:2]:  # a lab package's own parts
                    bad.append(f"{where}: labs and solutions are loaded by file name, not imported")
            elif name == "course" or dep == "course":
                if name == "course":
                    bad.append(f"{where}: course/__init__.py imports nothing")
            elif src == dst:
                if src == "given" and given_lab(name) != given_lab(dep):
                    bad.append(f"{where}: one lab's given code imports another lab's")
            elif dst not in ALLOWED.get(src, set()):
                bad.append(
                    f"{where}: {src} may import only {sorted(ALLOWED.get(src, ())) or 'nothing'}"
                )
    assert not bad, "imports that point up or sideways:\n  " + "\n  ".join(bad)


def test_no_circles(graph):
    _, edges = graph
    succ = {m: sorted({d for _, d in deps}) for m, deps in edges.items()}
    state, stack, cycles = {}, [], []

    def visit(m):
        state[m] = "open"
        stack.append(m)
        for d in succ.get(m, ()):
            if state.get(d) == "open":
                cycles.append(stack[stack.index(d) :] + [d])
            elif d not in state:
                visit(d)
        stack.pop()
        state[m] = "done"

    for m in sorted(succ):
        if m not in state:
            visit(m)
    assert not cycles, "import circles:\n  " + "\n  ".join(" -> ".join(c) for c in cycles)


def test_the_check_sees_lazy_relative_and_upward_imports(tmp_path):
    """The reader itself: an import inside a function and a relative one are both found."""
    f = tmp_path / "m.py"
    f.write_text("def f():\n    from ..grading import wire\n    import course.tools.cli\n")
    global ROOT
    saved, ROOT = ROOT, tmp_path
    try:
        found = {t for _, t in imports("course.core.m", f)}
    finally:
        ROOT = saved
    assert {"course.grading.wire", "course.grading", "course.tools.cli"} <= found
    assert room("course.core.m") == "core" and "grading" not in ALLOWED["core"]


def test_bench_scripts_never_import_solutions():
    """bench/ ships in the student handout, which has no solutions/: a bench script imports
    ``course`` and loads a lab through its resolver (``course.core.labs``,
    ``course.measure.bench.load_lab``), never by importing ``solutions`` or ``labs``."""
    bad = []
    for path in sorted((ROOT / "bench").rglob("*.py")):
        for line, target in imports(module_name(path), path):
            if target.split(".")[0] in ("solutions", "labs"):
                bad.append(f"{path.relative_to(ROOT)}:{line} imports {target}")
    assert not bad, "bench scripts that import a lab instead of loading it:\n  " + "\n  ".join(bad)
