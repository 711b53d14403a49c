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
import copy
import json
import re
from dataclasses import dataclass, field
from pathlib import Path

from course.core.files import module_files
from course.core.labs import lab_number


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

    def graded(self, task=None, *, hidden=None, needs=()) -> list[GradedTest]:
        """The graded tests (of ``task``; hidden or visible ones) that need nothing beyond
        ``needs`` (e.g. ``("gpu",)`` where CUDA is visible)."""
        return [
            t
            for t in self.tests
            if set(t.needs) <= set(needs)
            and (task is None or t.task == task)
            and (hidden is None or (t.visibility != "visible") == hidden)
        ]


def _mark(node) -> tuple[str, list] | None:
    """``pytest.mark.NAME(args)`` or ``mark.NAME(args)`` or a bare ``pytest.mark.NAME``."""
    call = node if isinstance(node, ast.Call) else None
    target = call.func if call else node
    if not isinstance(target, ast.Attribute):
        return None
    owner = target.value
    if (isinstance(owner, ast.Attribute) and owner.attr == "mark") or (
        isinstance(owner, ast.Name) and owner.id == "mark"
    ):
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
    try:
        return ast.literal_eval(node)
    except ValueError:
        raise ValueError(
            f"line {node.lineno}: a marker's argument {ast.unparse(node)!r} must "
            f"be a number or a module-level constant (NAME = literal, or one "
            f"imported from another grader)"
        ) from None


def _constants(tree) -> dict[str, object]:
    """Module-level ``NAME = literal`` assignments."""
    constants = {}
    for node in tree.body:
        if (
            isinstance(node, ast.Assign)
            and len(node.targets) == 1
            and isinstance(node.targets[0], ast.Name)
        ):
            try:
                constants[node.targets[0].id] = ast.literal_eval(node.value)
            except ValueError:
                pass
    return constants


def _module_marks(tree, constants) -> dict[str, object]:
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(
            isinstance(t, ast.Name) and t.id == "pytestmark" for t in node.targets
        ):
            value = node.value
            items = value.elts if isinstance(value, (ast.List, ast.Tuple)) else [value]
            return _marks(items, constants)
    return {}


def _imported_constants(tree, path: Path) -> dict[str, object]:
    """Constants a grader imports from another grader (``from test_lab6_raster import
    END_TO_END``, as a hidden grader does), read from that file's source."""
    found = {}
    for node in tree.body:
        if not isinstance(node, ast.ImportFrom) or not node.module or node.level:
            continue
        stem = node.module.split(".")[-1]
        for folder in (path.parent, path.parent.parent):
            source = folder / f"{stem}.py"
            if stem.startswith("test_") and source.is_file() and source != path:
                theirs = _constants(ast.parse(source.read_text(), filename=str(source)))
                found.update(
                    {
                        alias.asname or alias.name: theirs[alias.name]
                        for alias in node.names
                        if alias.name in theirs
                    }
                )
                break
    return found


def read_grader(path) -> LabInfo:
    """The lab a grader module tests: its module name, tasks and graded tests."""
    path = Path(path)
    tree = ast.parse(path.read_text(), filename=str(path))
    constants = {**_imported_constants(tree, path), **_constants(tree)}
    module = constants.get("LAB_MODULE")
    if lab_number(module) is None:
        raise ValueError(f"{path}: LAB_MODULE must name a module labN_topic, got {module!r}")
    info = LabInfo(
        number=lab_number(module),
        module=module,
        tasks=dict(constants.get("TASKS", {})),
        files=[path],
    )
    base = _module_marks(tree, constants)

    def visit(nodes, inherited):
        for node in nodes:
            if isinstance(node, ast.ClassDef) and node.name.startswith("Test"):
                visit(node.body, {**inherited, **_marks(node.decorator_list, constants)})
            elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and node.name.startswith(
                "test"
            ):
                marks = {**inherited, **_marks(node.decorator_list, constants)}
                if "points" not in marks:
                    continue
                try:
                    points = float(marks["points"])
                except (TypeError, ValueError):
                    raise ValueError(
                        f"{path}:{node.lineno}: points({marks['points']!r}) must be a number"
                    ) from None
                info.tests.append(
                    GradedTest(
                        name=node.name,
                        task=marks.get("task"),
                        points=points,
                        visibility=marks.get("visibility", "visible"),
                        needs=tuple(m for m in ("gpu", "slow") if m in marks),
                        calls=frozenset(_impl_calls(node, helpers)),
                    )
                )

    helpers = {
        node.name: node
        for node in tree.body
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))
        and not node.name.startswith("test")
    }
    try:
        visit(tree.body, base)
    except ValueError as exc:
        if str(exc).startswith("line "):
            raise ValueError(f"{path}:{exc}") from None
        raise
    return info


def _impl_calls(node, helpers, seen=None) -> set[str]:
    """Names X of ``impl.X`` in ``node``'s body and in the grader's module-level helper
    functions it calls (``march(impl, ...)`` calls ``impl.march_box``), transitively."""
    seen = set() if seen is None else seen
    found = set()
    for n in ast.walk(node):
        if isinstance(n, ast.Attribute) and isinstance(n.value, ast.Name) and n.value.id == "impl":
            found.add(n.attr)
        elif isinstance(n, ast.Name) and n.id in helpers and n.id not in seen:
            seen.add(n.id)
            if not _dispatches(helpers[n.id]):
                found |= _impl_calls(helpers[n.id], helpers, seen)
    return found


def _dispatches(helper) -> bool:
    """Whether a grader helper picks its kernel by name (``getattr(impl, variant)``): what
    it calls depends on the caller's arguments, so it says nothing about one test."""
    return any(
        isinstance(n, ast.Call)
        and isinstance(n.func, ast.Name)
        and n.func.id == "getattr"
        and n.args
        and isinstance(n.args[0], ast.Name)
        and n.args[0].id == "impl"
        for n in ast.walk(helper)
    )


_CATALOGS: dict[tuple, dict[int, LabInfo]] = {}


def lab_catalog(test_files) -> dict[int, LabInfo]:
    """Lab number -> :class:`LabInfo`, merging every grader file of a lab. Kept per process,
    keyed by the files' paths, sizes and modification times (parsing every grader takes a
    second or more, and a warm grading process grades one submission after another); each
    call gets its own copy."""
    files = [Path(f) for f in test_files]
    try:
        key = tuple((str(f), f.stat().st_mtime_ns, f.stat().st_size) for f in files)
    except OSError:
        return _read_catalog(files)
    if key not in _CATALOGS:
        _CATALOGS[key] = _read_catalog(files)
    return copy.deepcopy(_CATALOGS[key])


def _read_catalog(test_files) -> dict[int, LabInfo]:
    labs: dict[int, LabInfo] = {}
    for path in test_files:
        info = read_grader(path)
        if info.number not in labs:
            labs[info.number] = info
            continue
        lab = labs[info.number]
        if lab.module != info.module:
            raise ValueError(
                f"{path}: LAB_MODULE {info.module!r} differs from {lab.module!r} of {lab.files[0]}"
            )
        lab.tasks = {**info.tasks, **lab.tasks}
        lab.tests += info.tests
        lab.files.append(path)
    return dict(sorted(labs.items()))


def _module_body(lab_file) -> list[ast.stmt]:
    """The top-level statements of a lab: of its file, or of every file of its package."""
    return [node for f in module_files(lab_file) for node in ast.parse(f.read_text()).body]


def skeleton_functions(lab_file) -> list[str]:
    """Public functions and classes of a skeleton (a file, or a package's files) that still
    raise NotImplementedError somewhere: what a student writes (a class counts once, by its
    name)."""

    def unfinished(node) -> bool:
        return any(
            isinstance(n, ast.Raise) and "NotImplementedError" in ast.unparse(n)
            for n in ast.walk(node)
        )

    return [
        node.name
        for node in _module_body(lab_file)
        if isinstance(node, (ast.FunctionDef, ast.ClassDef))
        and not node.name.startswith("_")
        and unfinished(node)
    ]


def named_functions(test: GradedTest, functions) -> list[str]:
    """The functions a test's name mentions (the graders' naming rule ``test_<fn>_<what>``)."""
    named = [f for f in functions if re.search(rf"(^test|_){re.escape(f)}(_|$)", test.name)]
    # test_grid_closest_hit_... names grid_closest_hit, not closest_hit.
    return [f for f in named if not any(f != g and f in g for g in named)]


def functions_of(test: GradedTest, functions) -> list[str]:
    """The lab functions a test exercises: those it calls as ``impl.<fn>`` and those its
    name mentions (the graders' naming rule ``test_<fn>_<what>``, which also covers calls
    made through a helper)."""
    named = named_functions(test, functions)
    return [f for f in functions if f in test.calls or f in named]


# --------------------------------------------------------- what each task asks for

_NOT_YET = re.compile(r"not implemented yet:\s*([A-Za-z_][\w.]*)(?:[^()]*\(task (\d+)\))?")


def parse_not_implemented(message: str) -> tuple[str | None, int | None]:
    """``("moller_trumbore", 2)`` from "not implemented yet: moller_trumbore (task 2)"; the
    task is None where the message names none, both are None for another message."""
    match = _NOT_YET.search(message or "")
    if not match:
        return None, None
    return match.group(1), int(match.group(2)) if match.group(2) else None


@dataclass
class Stub:
    """A ``raise NotImplementedError(...)`` in a skeleton: what the student writes there."""

    name: str  # the module-level function or class it sits in
    qualname: str  # "FrameDownloader.submit" for a method
    task: int | None  # the task its message names ("(task 2)"), if any
    line: int


def skeleton_stubs(lab_file) -> list[Stub]:
    """Every ``NotImplementedError`` a skeleton (a file, or a package's files) raises, with
    the function (public or private, method or function) it belongs to; ``line`` is in the
    file that raises it."""
    stubs = []

    def scan(node, owner: str, qualname: str):
        for n in ast.walk(node):
            if (
                isinstance(n, ast.Raise)
                and n.exc is not None
                and "NotImplementedError" in ast.unparse(n.exc)
            ):
                text = " ".join(
                    c.value
                    for c in ast.walk(n.exc)
                    if isinstance(c, ast.Constant) and isinstance(c.value, str)
                )
                stubs.append(Stub(owner, qualname, parse_not_implemented(text)[1], n.lineno))

    for node in _module_body(lab_file):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            scan(node, node.name, node.name)
        elif isinstance(node, ast.ClassDef):
            for item in node.body:
                if isinstance(item, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    scan(item, node.name, f"{node.name}.{item.name}")
    return stubs


def function_tasks(lab: LabInfo, lab_file) -> dict[str, int | None]:
    """Each function (or class) the skeleton asks for -> the task that asks for it: the task
    its ``NotImplementedError`` names, else the first task whose tests exercise it (None when
    neither says)."""
    stubs = skeleton_stubs(lab_file)
    names = list(dict.fromkeys(s.name for s in stubs))
    owners: dict[str, int | None] = {}
    for name in names:
        stated = [s.task for s in stubs if s.name == name and s.task is not None]
        tested = [t.task for t in lab.tests if t.task is not None and functions_of(t, [name])]
        owners[name] = min(stated) if stated else (min(tested) if tested else None)
    return owners


@dataclass
class TaskInfo:
    number: int
    title: str
    points: float
    functions: list[str]  # what this task asks the student to write
    needs: dict[int, list[str]]  # other tasks whose functions its tests run


def lab_tasks(lab: LabInfo, lab_file, runs=None) -> list[TaskInfo]:
    """The tasks of ``lab`` with the functions each asks for and what its tests need from
    other tasks (read from the skeleton ``lab_file`` and the graders): the other tasks'
    functions its tests run, ``runs(test, functions)`` (default: those a test calls or
    names, :func:`functions_of`; the handout's table follows the lab's own calls too,
    :func:`course.grading.taskdoc.runs_through_lab`)."""
    owners = function_tasks(lab, lab_file) if Path(lab_file).exists() else {}
    runs = runs or functions_of
    tasks = []
    for number, title in sorted(lab.tasks.items()):
        mine = [f for f, t in owners.items() if t == number]
        used: set[str] = set()
        for test in lab.tests:
            if test.task == number:
                used |= set(runs(test, list(owners)))
        needs: dict[int, list[str]] = {}
        for f, task in owners.items():  # in the skeleton's order
            if f in used and task is not None and task != number:
                needs.setdefault(task, []).append(f)
        tasks.append(
            TaskInfo(number, str(title), lab.points(number), mine, dict(sorted(needs.items())))
        )
    return tasks


_COPY_SUFFIX = re.compile(r"(\s*\(\d+\)|\s*-\s*copy|\s+copy|[\s_-]+\d+|\s*-\s*\d+)$")


def lab_file_rank(filename: str, module: str) -> int | None:
    """0 when ``filename`` is ``module.py``; 1 for a near miss a student (or an upload
    site) makes of it: other letter case, a copy suffix ("lab1_intersect (1).py",
    "lab1_intersect-2.py", "lab1_intersect copy.py"), spaces for underscores; else None."""
    if filename == f"{module}.py":
        return 0
    if not filename.lower().endswith(".py"):
        return None
    stem = filename[:-3].strip()
    for _ in range(2):
        stem = _COPY_SUFFIX.sub("", stem)
    normal = re.sub(r"[\s-]+", "_", stem.lower())
    return 1 if normal == module.lower() else None


# What ``rtcourse gradescope``'s collect step writes next to the lab files it copies out of
# a submission: each lab file's path as handed in, and every file handed in.
SUBMISSION_MANIFEST = ".rtcourse-submission.json"


def read_manifest(folder) -> dict | None:
    """The collect step's record in ``folder`` (``{"files": {lab file: path as handed in,
    or None}, "handed_in": [paths]}``), or None where the folder is not a collected
    submission."""
    try:
        data = json.loads((Path(folder) / SUBMISSION_MANIFEST).read_text())
    except (OSError, ValueError):
        return None
    if not isinstance(data, dict) or not isinstance(data.get("files"), dict):
        return None
    return {
        "files": {str(k): v if isinstance(v, str) else None for k, v in data["files"].items()},
        "handed_in": [str(p) for p in data.get("handed_in", ()) if isinstance(p, str)],
    }


def near_misses(folder, module: str) -> list[Path]:
    """Files of ``folder`` that look like ``module.py`` but are not named exactly that."""
    folder = Path(folder)
    if not folder.is_dir():
        return []
    return sorted(p for p in folder.iterdir() if p.is_file() and lab_file_rank(p.name, module) == 1)
