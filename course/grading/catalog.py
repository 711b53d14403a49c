"""What each lab asks for, read from its grader without running it.

A grader ``tests/test_labN_topic.py`` declares ``LAB_MODULE``, ``TASKS`` (task number ->
title) and marks every graded test with ``task(k)`` and ``points(n)``. This module reads
those from the source (``ast``), so the handout README, the Gradescope package and the
lecture overview can list tasks and points without importing torch or collecting tests.

Points are per test function (``results.py`` splits them over its parametrisations), so a
task is worth the sum of its functions' points. Tests marked ``gpu`` or ``slow`` are
skipped on a plain CPU run and counted apart.
"""

from __future__ import annotations

import ast
import re
from dataclasses import dataclass, field
from pathlib import Path


@dataclass
class GradedTest:
    name: str
    task: int | None
    points: float
    visibility: str = "visible"
    needs: tuple[str, ...] = ()  # "gpu", "slow": not graded on a default CPU run
    calls: frozenset[str] = frozenset()  # names X of ``impl.X`` in the test's body


@dataclass
class LabInfo:
    number: int
    module: str  # LAB_MODULE: the file a submission must contain, without .py
    tasks: dict[int, str]
    tests: list[GradedTest] = field(default_factory=list)
    files: list[Path] = field(default_factory=list)

    def points(self, task=None, *, hidden=None) -> float:
        """Points graded on a CPU run, for one task or all; ``hidden`` filters by visibility."""
        return sum(t.points for t in self.graded(task, hidden=hidden))

    def graded(self, task=None, *, hidden=None) -> list[GradedTest]:
        return [t for t in self.tests if not t.needs and (task is None or t.task == task)
                and (hidden is None or (t.visibility != "visible") == hidden)]


def _mark(node) -> tuple[str, list] | None:
    """``pytest.mark.NAME(args)`` or ``mark.NAME(args)`` or a bare ``pytest.mark.NAME``."""
    call = node if isinstance(node, ast.Call) else None
    target = call.func if call else node
    if not isinstance(target, ast.Attribute):
        return None
    owner = target.value
    if (isinstance(owner, ast.Attribute) and owner.attr == "mark") or (
            isinstance(owner, ast.Name) and owner.id == "mark"):
        return target.attr, (call.args if call else [])
    return None


def _marks(decorators, constants) -> dict[str, object]:
    found = {}
    for node in decorators:
        mark = _mark(node)
        if mark is None:
            continue
        name, args = mark
        found[name] = _value(args[0], constants) if args else True
    return found


def _value(node, constants):
    if isinstance(node, ast.Name) and node.id in constants:
        return constants[node.id]
    return ast.literal_eval(node)


def _constants(tree) -> dict[str, object]:
    """Module-level ``NAME = literal`` assignments."""
    constants = {}
    for node in tree.body:
        if isinstance(node, ast.Assign) and len(node.targets) == 1 and isinstance(
                node.targets[0], ast.Name):
            try:
                constants[node.targets[0].id] = ast.literal_eval(node.value)
            except ValueError:
                pass
    return constants


def _module_marks(tree, constants) -> dict[str, object]:
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(
                isinstance(t, ast.Name) and t.id == "pytestmark" for t in node.targets):
            value = node.value
            items = value.elts if isinstance(value, (ast.List, ast.Tuple)) else [value]
            return _marks(items, constants)
    return {}


def read_grader(path) -> LabInfo:
    """The lab a grader module tests: its module name, tasks and graded tests."""
    path = Path(path)
    tree = ast.parse(path.read_text(), filename=str(path))
    constants = _constants(tree)
    module = constants.get("LAB_MODULE")
    match = re.match(r"lab(\d+)_", module or "")
    if not match:
        raise ValueError(f"{path}: LAB_MODULE must name a module labN_topic, got {module!r}")
    info = LabInfo(number=int(match.group(1)), module=module,
                   tasks=dict(constants.get("TASKS", {})), files=[path])
    base = _module_marks(tree, constants)

    def visit(nodes, inherited):
        for node in nodes:
            if isinstance(node, ast.ClassDef) and node.name.startswith("Test"):
                visit(node.body, {**inherited, **_marks(node.decorator_list, constants)})
            elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) \
                    and node.name.startswith("test"):
                marks = {**inherited, **_marks(node.decorator_list, constants)}
                if "points" not in marks:
                    continue
                try:
                    points = float(marks["points"])
                except (TypeError, ValueError):
                    raise ValueError(f"{path}:{node.lineno}: points({marks['points']!r}) "
                                     f"must be a number") from None
                info.tests.append(GradedTest(
                    name=node.name, task=marks.get("task"), points=points,
                    visibility=marks.get("visibility", "visible"),
                    needs=tuple(m for m in ("gpu", "slow") if m in marks),
                    calls=frozenset(n.attr for n in ast.walk(node)
                                    if isinstance(n, ast.Attribute)
                                    and isinstance(n.value, ast.Name) and n.value.id == "impl")))

    visit(tree.body, base)
    return info


def lab_catalog(test_files) -> dict[int, LabInfo]:
    """Lab number -> :class:`LabInfo`, merging every grader file of a lab."""
    labs: dict[int, LabInfo] = {}
    for path in test_files:
        info = read_grader(path)
        if info.number not in labs:
            labs[info.number] = info
            continue
        lab = labs[info.number]
        if lab.module != info.module:
            raise ValueError(f"{path}: LAB_MODULE {info.module!r} differs from "
                             f"{lab.module!r} of {lab.files[0]}")
        lab.tasks = {**info.tasks, **lab.tasks}
        lab.tests += info.tests
        lab.files.append(path)
    return dict(sorted(labs.items()))


def skeleton_functions(lab_file) -> list[str]:
    """Public functions and classes of a skeleton that still raise NotImplementedError
    somewhere: what a student writes (a class counts once, by its name)."""
    tree = ast.parse(Path(lab_file).read_text())

    def unfinished(node) -> bool:
        return any(isinstance(n, ast.Raise) and "NotImplementedError" in ast.unparse(n)
                   for n in ast.walk(node))

    return [node.name for node in tree.body
            if isinstance(node, (ast.FunctionDef, ast.ClassDef))
            and not node.name.startswith("_") and unfinished(node)]


def functions_of(test: GradedTest, functions) -> list[str]:
    """The lab functions a test exercises: those it calls as ``impl.<fn>`` and those its
    name mentions (the graders' naming rule ``test_<fn>_<what>``, which also covers calls
    made through a helper)."""
    return [f for f in functions if f in test.calls
            or re.search(rf"(^test|_){re.escape(f)}(_|$)", test.name)]
