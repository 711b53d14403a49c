"""References kept in parts (``solutions/lab2_accel.py`` and ``solutions/lab2_accel_parts/``,
see ``course.core.files``): every file of a reference is short, and a reference in parts is
one module with the skeleton's API, as if it were one file.

Not shipped to students (it reads ``solutions/``).
"""

from __future__ import annotations

import ast
import inspect
import sys
import types
from pathlib import Path

import pytest

from course.core.files import (
    copy_module,
    defining_file,
    import_file,
    joined_source,
    module_files,
    module_parts,
)
from course.grading.sandbox import reference_signatures
from course.grading.testing import replaced

ROOT = Path(__file__).resolve().parents[2]
REFERENCES = sorted((ROOT / "solutions").glob("lab*_*.py"))
IN_PARTS = [p for p in REFERENCES if module_parts(p)]
MAX_LINES = 600
# References still in one file of more than MAX_LINES lines: each leaves this set when it is
# split into parts (as Lab 2 was), and no other reference joins it.
NOT_YET_SPLIT = {"lab1_intersect", "lab4_march", "lab5_froxel", "lab6_raster"}


def _lines(path: Path) -> int:
    return len(path.read_text().splitlines())


def test_every_file_of_a_reference_is_short():
    assert IN_PARTS, "no reference kept in parts (solutions/lab2_accel_parts/ expected)"
    long = {str(path.relative_to(ROOT)): _lines(path) for reference in REFERENCES
            if reference.stem not in NOT_YET_SPLIT for path in module_files(reference)
            if _lines(path) > MAX_LINES}
    assert not long, (f"reference files over {MAX_LINES} lines (split the reference into "
                      f"parts, see course/core/files.py): {long}")
    short = sorted(name for name in NOT_YET_SPLIT
                   if all(_lines(f) <= MAX_LINES for f in module_files(
                       ROOT / "solutions" / f"{name}.py")))
    assert not short, f"now at most {MAX_LINES} lines a file: take {short} out of NOT_YET_SPLIT"


def _bound_names(path: Path) -> set[str]:
    """The names a file binds at its top level (defs, classes, imports, assignments)."""
    names = set()
    for node in ast.parse(path.read_text()).body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, (ast.Import, ast.ImportFrom)):
            names |= {(a.asname or a.name).split(".")[0] for a in node.names}
        elif isinstance(node, (ast.Assign, ast.AnnAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            names |= {n.id for t in targets for n in ast.walk(t) if isinstance(n, ast.Name)}
        elif isinstance(node, ast.Delete):
            names -= {t.id for t in node.targets if isinstance(t, ast.Name)}
    return names


def _defined(module) -> set[str]:
    """Public functions and classes the module itself defines (not imported ones)."""
    return {name for name, value in vars(module).items() if not name.startswith("_")
            and inspect.isfunction(value) | inspect.isclass(value)
            and value.__module__ == module.__name__}


@pytest.mark.parametrize("reference", IN_PARTS, ids=[p.stem for p in IN_PARTS])
def test_parts_are_one_module_with_the_skeletons_api(reference):
    lab = import_file(reference, f"parts_{reference.stem}")
    skeleton = import_file(ROOT / "labs" / reference.name, f"parts_skeleton_{reference.stem}")
    public = {n for n in vars(lab) if not n.startswith("_")}
    skeleton_public = {n for n in vars(skeleton) if not n.startswith("_")}
    assert skeleton_public <= public, f"missing: {sorted(skeleton_public - public)}"
    assert _defined(lab) == _defined(skeleton), (
        f"only in the skeleton {sorted(_defined(skeleton) - _defined(lab))}, only in the "
        f"reference {sorted(_defined(lab) - _defined(skeleton))}")
    # Exactly the names its files bind: nothing of the assembly is left over.
    files = module_files(reference)
    bound = set().union(*map(_bound_names, files))
    assert {n for n in vars(lab) if not n.startswith("__")} == bound
    # Each function is defined once, in its part, and lives in the module's namespace.
    seen: dict[str, Path] = {}
    for path in files:
        for node in ast.parse(path.read_text()).body:
            if isinstance(node, (ast.FunctionDef, ast.ClassDef)):
                assert node.name not in seen, f"{node.name} in {seen[node.name]} and {path}"
                seen[node.name] = path
    for name, path in seen.items():
        assert defining_file(reference, name) == path
        value = getattr(lab, name)
        if inspect.isfunction(value):
            assert value.__globals__ is vars(lab), name
            assert Path(value.__code__.co_filename) == path.resolve(), name
            assert inspect.getsource(value).lstrip().startswith(f"def {name}(")


def test_a_replaced_function_is_seen_by_the_other_parts():
    """What the graders' probes rely on (``course.grading.testing.replaced``): ``build``
    (task 5's part) calls the grid builder (task 1's) through the module's globals."""
    lab = import_file(ROOT / "solutions" / "lab2_accel.py", "parts_lab2_replaced")
    assert defining_file(ROOT / "solutions" / "lab2_accel.py", "build") != \
        defining_file(ROOT / "solutions" / "lab2_accel.py", "build_grid")
    marker = {"kind": "grid", "stand-in": True}
    with replaced(lab, {"build_grid": lambda mesh, **knobs: marker}):
        assert lab.build(None, "grid") is marker
    assert lab.build_grid is not None and lab.build_grid.__name__ == "build_grid"


def _toy(tmp_path: Path) -> Path:
    """A toy lab kept in parts: ``scale`` in the first part calls ``offset`` of the second."""
    module = tmp_path / "lab9_toy.py"
    module.write_text('"""Toy lab in parts."""\n\nfrom __future__ import annotations\n\n'
                      "import math\n"
                      "from course.core.files import run_parts as _run_parts\n\n"
                      "_run_parts(globals())\ndel _run_parts\n")
    parts = tmp_path / "lab9_toy_parts"
    parts.mkdir()
    (parts / "task1_scale.py").write_text(
        "# Task 1.\nfrom __future__ import annotations\n\n\n"
        "def scale(x: float, out: list | None = None) -> float:\n    return math.floor(offset(x) * 2)\n")
    (parts / "task10_late.py").write_text("# Task 10: runs last.\nLATE = ORDER + [10]\n")
    (parts / "task2_offset.py").write_text(
        "# Task 2.\nORDER = [1, 2]\n\n\ndef offset(x):\n    return x + 1\n")
    return module


def test_a_toy_module_in_parts(tmp_path):
    module = _toy(tmp_path)
    assert [p.name for p in module_parts(module)] == ["task1_scale.py", "task2_offset.py",
                                                      "task10_late.py"]
    lab = import_file(module, "parts_toy")
    assert lab.scale(1.2) == 4 and lab.LATE == [1, 2, 10] and not hasattr(lab, "_run_parts")
    assert lab.scale.__annotations__ == {"x": "float", "out": "list | None",
                                      "return": "float"}
    with replaced(lab, {"offset": lambda x: x}):
        assert lab.scale(1.2) == 2
    assert defining_file(module, "offset").name == "task2_offset.py"
    with pytest.raises(ValueError, match="found none"):
        defining_file(module, "nothing")
    assert reference_signatures(module) == {"scale": ["x", "out"], "offset": ["x"]}
    # A changed copy keeps the layout; one copied alone fails to import, loudly.
    copy = copy_module(module, tmp_path / "copy",
                       {"lab9_toy_parts/task2_offset.py": "ORDER = []\ndef offset(x):\n    return x\n"})
    assert import_file(copy, "parts_toy_copy").scale(1.2) == 2
    assert (tmp_path / "copy" / "lab9_toy_parts" / "task1_scale.py").read_text() == \
        (module.parent / "lab9_toy_parts" / "task1_scale.py").read_text()
    with pytest.raises(ValueError, match="not files of"):
        copy_module(module, tmp_path / "bad", {"lab9_toy_parts/nothing.py": ""})
    alone = tmp_path / "alone"
    alone.mkdir()
    (alone / module.name).write_text(module.read_text())
    with pytest.raises(ImportError, match="parts .* are missing"):
        import_file(alone / module.name, "parts_toy_alone")
    # Joined into one file (a Gradescope submission), the same module.
    (alone / module.name).write_text(joined_source(module))
    one = import_file(alone / module.name, "parts_toy_joined")
    assert one.scale(1.2) == 4 and one.LATE == [1, 2, 10]
    assert one.scale.__annotations__ == lab.scale.__annotations__


@pytest.mark.parametrize("reference", IN_PARTS, ids=[p.stem for p in IN_PARTS])
def test_a_reference_joined_into_one_file_is_the_same_module(reference, tmp_path):
    lab = import_file(reference, f"parts_{reference.stem}_again")
    path = tmp_path / reference.name
    path.write_text(joined_source(reference))
    one = import_file(path, f"joined_{reference.stem}")
    assert set(vars(one)) == set(vars(lab))
    for name, value in vars(lab).items():
        if inspect.isfunction(value) and value.__module__ == lab.__name__:
            assert inspect.getsource(getattr(one, name)) == inspect.getsource(value), name
        elif isinstance(value, types.ModuleType):
            assert getattr(one, name) is value, name
    sys.modules.pop(f"joined_{reference.stem}", None)
