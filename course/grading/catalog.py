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
import json
import re
from dataclasses import dataclass, field
from pathlib import Path

from course.core.files import module_files
from course.core.labs import lab_number


@dataclass(frozen=True)
class LabCall:
    """A test's use of the lab's ``function`` (``impl.f(...)``, or ``lab.f(...)`` in a probe),
    made where the lab's functions named in ``replaced`` are the grader's stand-ins
    (``with replaced(lab, {...}):``), so what ``function`` calls of them is not the lab's."""

    function: str
    replaced: frozenset[str] = frozenset()
    runs: bool = True  # False: made to fail its argument checks (``expect_error``)
    optional: bool = False  # tried, and skipped where it raises NotImplementedError


@dataclass
class GradedTest:
    name: str
    task: int | None
    points: float
    visibility: str = "visible"
    needs: tuple[str, ...] = ()  # "gpu", "slow": not graded on a default CPU run
    calls: frozenset[str] = frozenset()  # names X of ``impl.X`` in the test's body
    uses: tuple[LabCall, ...] = ()  # every call of the lab, in probes too (``_GraderWalk``)


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
    try:
        return ast.literal_eval(node)
    except ValueError:
        raise ValueError(f"line {node.lineno}: a marker's argument {ast.unparse(node)!r} must "
                         f"be a number or a module-level constant (NAME = literal, or one "
                         f"imported from another grader)") from None


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
                found.update({alias.asname or alias.name: theirs[alias.name]
                              for alias in node.names if alias.name in theirs})
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
    info = LabInfo(number=lab_number(module), module=module,
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
                    calls=frozenset(_impl_calls(node, helpers)),
                    uses=_GraderWalk(helpers, values).test(node)))

    helpers = {node.name: node for node in tree.body
               if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))
               and not node.name.startswith("test")}
    values = {t.id: node.value for node in tree.body if isinstance(node, ast.Assign)
              for t in node.targets if isinstance(t, ast.Name)}
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
        if isinstance(n, ast.Attribute) and isinstance(n.value, ast.Name) \
                and n.value.id == "impl":
            found.add(n.attr)
        elif isinstance(n, ast.Name) and n.id in helpers and n.id not in seen:
            seen.add(n.id)
            if not _dispatches(helpers[n.id]):
                found |= _impl_calls(helpers[n.id], helpers, seen)
    return found


def _dispatches(helper) -> bool:
    """Whether a grader helper picks its kernel by name (``getattr(impl, variant)``): what
    it calls depends on the caller's arguments, so it says nothing about one test."""
    return any(isinstance(n, ast.Call) and isinstance(n.func, ast.Name)
               and n.func.id == "getattr" and n.args and isinstance(n.args[0], ast.Name)
               and n.args[0].id == "impl" for n in ast.walk(helper))


_LAB = "<the lab module>"  # what a name bound to the lab (``impl``, a probe's ``lab``) holds
_COLLECTIONS = ("tuple", "list", "set", "frozenset", "dict", "sorted")


class _GraderWalk:
    """What one test calls of the lab, read from the grader's source: ``impl.f`` in the test
    and in the module-level helpers it calls (their parameters bound to the arguments),
    ``lab.f`` in a probe that ``impl.probe(probe, ...)`` runs next to the lab, and
    ``getattr(lab, name)`` where ``name`` is known there. Each call carries the names the
    ``with replaced(lab, {...}):`` blocks around it swap for stand-ins: keys written out, or
    read from a module-level dict, an argument or a comprehension over one. A replacement
    whose names cannot be read (one picked at run time) cuts nothing."""

    def __init__(self, helpers: dict, values: dict):
        self.helpers, self.values = helpers, values  # module-level functions, NAME = value
        self.found: dict[LabCall, None] = {}
        self.seen: set = set()
        self.checks = False  # inside ``expect_error(...)``: the lab's calls stop at checks
        self.optional = False  # inside ``try: ... except NotImplementedError:``

    def _found(self, function: str, cut: frozenset[str]) -> None:
        self.found[LabCall(function, cut, runs=not self.checks,
                           optional=self.optional)] = None

    def test(self, node) -> tuple[LabCall, ...]:
        self.found, self.seen = {}, set()
        self._body(node.body, {"impl": _LAB}, frozenset())
        return tuple(self.found)

    # -- what a name or an expression holds: _LAB, a string, a set of names, or None

    def _value(self, node, env: dict, depth: int = 0):
        if isinstance(node, ast.Constant) and isinstance(node.value, str):
            return node.value
        if isinstance(node, ast.Name):
            if node.id in env:
                return env[node.id]
            if node.id in self.values and depth < 8:
                return self._value(self.values[node.id], {}, depth + 1)
            return None
        return self._names(node, env, depth)

    def _names(self, node, env: dict, depth: int = 0) -> frozenset[str] | None:
        """The names a dict's keys, a list, tuple or set, or a comprehension over one
        hold; None where one of them is not known."""
        if isinstance(node, ast.Name):
            value = self._value(node, env, depth)
            return value if isinstance(value, frozenset) else None
        if isinstance(node, ast.Dict):
            parts = [(v, True) if k is None else (k, False)
                     for k, v in zip(node.keys, node.values)]
        elif isinstance(node, (ast.List, ast.Tuple, ast.Set)):
            parts = [(e.value, True) if isinstance(e, ast.Starred) else (e, False)
                     for e in node.elts]
        elif isinstance(node, (ast.DictComp, ast.ListComp, ast.SetComp, ast.GeneratorExp)):
            key = node.key if isinstance(node, ast.DictComp) else node.elt
            gen = node.generators[0]
            if len(node.generators) != 1 or gen.ifs or not isinstance(gen.target, ast.Name) \
                    or not isinstance(key, ast.Name) or key.id != gen.target.id:
                return None
            parts = [(gen.iter, True)]
        elif isinstance(node, ast.Call) and isinstance(node.func, ast.Name) \
                and node.func.id in _COLLECTIONS and len(node.args) == 1 and not node.keywords:
            parts = [(node.args[0], True)]
        else:
            return None
        names: set[str] = set()
        for part, many in parts:
            value = self._names(part, env, depth) if many else self._value(part, env, depth)
            if isinstance(value, frozenset) and many:
                names |= value
            elif isinstance(value, str) and not many:
                names.add(value)
            else:
                return None
        return frozenset(names)

    def _is_lab(self, node, env: dict) -> bool:
        return isinstance(node, ast.Name) and env.get(node.id) is _LAB

    # -- the walk

    def _helper(self, name: str, env: dict, cut: frozenset[str]) -> None:
        key = (name, tuple(sorted(env.items(), key=str)), cut)
        if key not in self.seen:
            self.seen.add(key)
            self._body(self.helpers[name].body, env, cut)

    def _bind(self, name: str, args, keywords, env: dict, lab_first=False) -> dict:
        """A helper's parameters -> what the call's arguments (or the defaults) hold."""
        spec = self.helpers[name].args
        params = [a.arg for a in (*spec.posonlyargs, *spec.args)]
        bound = dict(zip(params[len(params) - len(spec.defaults):],
                         (self._value(d, {}) for d in spec.defaults)))
        bound.update((a.arg, self._value(d, {})) for a, d in
                     zip(spec.kwonlyargs, spec.kw_defaults) if d is not None)
        if lab_first and params:
            bound[params.pop(0)] = _LAB
        for param, arg in zip(params, args):
            if isinstance(arg, ast.Starred):
                break
            bound[param] = self._value(arg, env)
        names = set(params) | {a.arg for a in spec.kwonlyargs}
        bound.update((k.arg, self._value(k.value, env)) for k in keywords if k.arg in names)
        return bound

    def _body(self, nodes, env: dict, cut: frozenset[str]) -> None:
        for node in nodes:
            self._visit(node, env, cut)

    def _visit(self, node, env: dict, cut: frozenset[str]) -> None:
        if isinstance(node, (ast.With, ast.AsyncWith)):
            inner = cut
            for item in node.items:
                self._visit(item.context_expr, env, cut)
                inner |= self._replacing(item.context_expr, env)
            self._body(node.body, env, inner)
            return
        if isinstance(node, ast.Call) and self._call(node, env, cut):
            return
        if isinstance(node, ast.Try) and any(
                h.type is not None and "NotImplementedError" in ast.unparse(h.type)
                for h in node.handlers):  # what the submission may not have written yet
            optional, self.optional = self.optional, True
            try:
                self._body(node.body, env, cut)
            finally:
                self.optional = optional
            self._body([*node.handlers, *node.orelse, *node.finalbody], env, cut)
            return
        if isinstance(node, ast.Attribute) and self._is_lab(node.value, env):
            if node.attr != "probe":
                self._found(node.attr, cut)
            return
        if isinstance(node, (ast.If, ast.IfExp)):  # a branch on a known name: only it runs
            live = self._truth(node.test, env)
            self._visit(node.test, env, cut)
            for part, runs in ((node.body, live is not False), (node.orelse, live is not True)):
                if runs:
                    self._body(part if isinstance(part, list) else [part], env, cut)
            return
        if isinstance(node, ast.Name) and node.id in self.helpers \
                and isinstance(node.ctx, ast.Load):  # a helper passed on, called later
            spec = self.helpers[node.id].args
            self._helper(node.id, {a.arg: _LAB for a in (*spec.posonlyargs, *spec.args)
                                   if a.arg in ("impl", "lab")}, cut)
            return
        for child in ast.iter_child_nodes(node):
            self._visit(child, env, cut)

    def _call(self, node: ast.Call, env: dict, cut: frozenset[str]) -> bool:
        """Follow a call into a helper or a probe, or read ``getattr(lab, name)``; False for
        any other call (the caller walks its parts)."""
        func, args, keywords = node.func, node.args, node.keywords
        if isinstance(func, ast.Attribute) and func.attr == "probe" \
                and self._is_lab(func.value, env) and args and isinstance(args[0], ast.Name) \
                and args[0].id in self.helpers:
            self._helper(args[0].id, self._bind(args[0].id, args[1:], keywords, env, True), cut)
            rest = args[1:]
        elif isinstance(func, ast.Name) and func.id == "getattr" and len(args) >= 2 \
                and self._is_lab(args[0], env):
            name = self._value(args[1], env)
            if isinstance(name, str):
                self._found(name, cut)
            rest = args[1:]
        elif isinstance(func, ast.Name) and func.id == "expect_error":
            checks, self.checks = self.checks, True
            try:
                for part in (*args, *(k.value for k in keywords)):
                    self._visit(part, env, cut)
            finally:
                self.checks = checks
            return True
        elif isinstance(func, ast.Name) and func.id in self.helpers:
            self._helper(func.id, self._bind(func.id, args, keywords, env), cut)
            rest = args
        else:
            return False
        for part in (*rest, *(k.value for k in keywords)):
            self._visit(part, env, cut)
        return True

    def _truth(self, node, env: dict) -> bool | None:
        """Whether a branch's test holds, where it compares known names (``variant ==
        "woop_unit"``, ``stage in STAGES``); None where it is not known."""
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.Not):
            value = self._truth(node.operand, env)
            return None if value is None else not value
        if isinstance(node, ast.BoolOp):
            values = [self._truth(v, env) for v in node.values]
            stop = isinstance(node.op, ast.Or)  # the value that decides an or (an and: False)
            return stop if stop in values else (None if None in values else not stop)
        if not isinstance(node, ast.Compare) or len(node.ops) != 1:
            return None
        left, right = self._value(node.left, env), self._value(node.comparators[0], env)
        op = node.ops[0]
        if not isinstance(left, str):
            return None
        if isinstance(op, (ast.Eq, ast.NotEq)) and isinstance(right, str):
            return (left == right) == isinstance(op, ast.Eq)
        if isinstance(op, (ast.In, ast.NotIn)) and isinstance(right, frozenset):
            return (left in right) == isinstance(op, ast.In)
        return None

    def _replacing(self, node, env: dict) -> frozenset[str]:
        """The names ``replaced(lab, {...})`` swaps for stand-ins (none when not known)."""
        if not isinstance(node, ast.Call) or len(node.args) < 2:
            return frozenset()
        func = node.func
        name = func.id if isinstance(func, ast.Name) else getattr(func, "attr", None)
        if name != "replaced":
            return frozenset()
        return self._names(node.args[1], env) or frozenset()


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


def _module_body(lab_file) -> list[ast.stmt]:
    """The top-level statements of a lab: of its file, or of every file of its package."""
    return [node for f in module_files(lab_file) for node in ast.parse(f.read_text()).body]


def skeleton_functions(lab_file) -> list[str]:
    """Public functions and classes of a skeleton (a file, or a package's files) that still
    raise NotImplementedError somewhere: what a student writes (a class counts once, by its
    name)."""

    def unfinished(node) -> bool:
        return any(isinstance(n, ast.Raise) and "NotImplementedError" in ast.unparse(n)
                   for n in ast.walk(node))

    return [node.name for node in _module_body(lab_file)
            if isinstance(node, (ast.FunctionDef, ast.ClassDef))
            and not node.name.startswith("_") and unfinished(node)]


def _named(test: GradedTest, functions) -> list[str]:
    """The functions a test's name mentions (the graders' naming rule ``test_<fn>_<what>``)."""
    named = [f for f in functions if re.search(rf"(^test|_){re.escape(f)}(_|$)", test.name)]
    # test_grid_closest_hit_... names grid_closest_hit, not closest_hit.
    return [f for f in named if not any(f != g and f in g for g in named)]


def functions_of(test: GradedTest, functions) -> list[str]:
    """The lab functions a test exercises: those it calls as ``impl.<fn>`` and those its
    name mentions (the graders' naming rule ``test_<fn>_<what>``, which also covers calls
    made through a helper)."""
    named = _named(test, functions)
    return [f for f in functions if f in test.calls or f in named]


def lab_calls(lab_file) -> dict[str, set[str]]:
    """Each top-level function and class of a lab (a file, or every file of a package) ->
    the lab's own top-level functions and classes its body names (calls, and functions
    passed on): what running it runs of the lab."""
    defs = {node.name: node for node in _module_body(lab_file)
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef))}
    return {name: {n.id for n in ast.walk(node) if isinstance(n, ast.Name)
                   and n.id in defs and n.id != name}
            for name, node in defs.items()}


def needed_functions(test: GradedTest, functions, calls: dict[str, set[str]]) -> set[str]:
    """The functions of ``functions`` that a test runs: those it calls (or its name
    mentions) and, through ``calls`` (:func:`lab_calls` of the reference), every lab function
    they call in turn, except those the test replaces with stand-ins around that call."""
    optional = {use.function for use in test.uses if use.optional}
    uses = [use for use in test.uses if not use.optional]
    called = {use.function for use in test.uses}
    uses += [LabCall(f) for f in _named(test, functions) if f not in called]
    uses += [LabCall(f) for f in test.calls if f not in called]
    reached: set[str] = set()
    for use in uses:
        seen, todo = set(), [use.function]
        while todo:
            f = todo.pop()
            if f in seen or f in use.replaced or (f in optional and f != use.function):
                continue
            seen.add(f)
            if use.runs:
                todo += sorted(calls.get(f, ()))
        reached |= seen
    return {f for f in functions if f in reached}


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
            if isinstance(n, ast.Raise) and n.exc is not None \
                    and "NotImplementedError" in ast.unparse(n.exc):
                text = " ".join(c.value for c in ast.walk(n.exc)
                                if isinstance(c, ast.Constant) and isinstance(c.value, str))
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


def lab_tasks(lab: LabInfo, lab_file, reference=None) -> list[TaskInfo]:
    """The tasks of ``lab`` with the functions each asks for and what its tests need from
    other tasks (read from the skeleton ``lab_file`` and the graders): the other tasks'
    functions its tests run, directly or through the lab's functions they call, read from
    ``reference`` (the solution, a file or a package; without it the skeleton, whose given
    code is all that calls there)."""
    exists = Path(lab_file).exists()
    owners = function_tasks(lab, lab_file) if exists else {}
    source = reference if reference is not None and Path(reference).exists() else lab_file
    calls = lab_calls(source) if Path(source).exists() else {}
    tasks = []
    for number, title in sorted(lab.tasks.items()):
        mine = [f for f, t in owners.items() if t == number]
        used: set[str] = set()
        for test in lab.tests:
            if test.task == number:
                used |= needed_functions(test, list(owners), calls)
        needs: dict[int, list[str]] = {}
        for f, task in owners.items():  # in the skeleton's order
            if f in used and task is not None and task != number:
                needs.setdefault(task, []).append(f)
        tasks.append(TaskInfo(number, str(title), lab.points(number), mine,
                              dict(sorted(needs.items()))))
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
    return {"files": {str(k): v if isinstance(v, str) else None
                      for k, v in data["files"].items()},
            "handed_in": [str(p) for p in data.get("handed_in", ()) if isinstance(p, str)]}


def near_misses(folder, module: str) -> list[Path]:
    """Files of ``folder`` that look like ``module.py`` but are not named exactly that."""
    folder = Path(folder)
    if not folder.is_dir():
        return []
    return sorted(p for p in folder.iterdir() if p.is_file()
                  and lab_file_rank(p.name, module) == 1)
