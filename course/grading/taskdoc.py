"""The per-task table of the handout's ``labs/README.md``: for each task its points, every
function it asks for (read from the skeleton's ``NotImplementedError``s), the other tasks
its tests run (directly, or through the lab's own functions, as the reference calls them),
and the commands that run exactly its tests. For a lab kept as a package
(``labs/lab2_accel/``) each function is listed with the file it is written in, the files
the student hands in."""

from __future__ import annotations

import ast
from dataclasses import dataclass
from pathlib import Path

from course.core.files import defining_file, module_files
from course.grading.catalog import GradedTest, LabInfo, functions_of, lab_tasks, named_functions

# --------------------------------------------- what a task's tests run of the other tasks


@dataclass(frozen=True)
class LabCall:
    """A test's use of the lab's ``function`` (``impl.f(...)``, or ``lab.f(...)`` in a probe),
    made where the lab's functions named in ``replaced`` are the grader's stand-ins
    (``with replaced(lab, {...}):``), so what ``function`` calls of them is not the lab's."""

    function: str
    replaced: frozenset[str] = frozenset()
    runs: bool = True  # False: made to fail its argument checks (``expect_error``)
    optional: bool = False  # tried, and skipped where it raises NotImplementedError


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
        self.found[LabCall(function, cut, runs=not self.checks, optional=self.optional)] = None

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
            parts = [(v, True) if k is None else (k, False) for k, v in zip(node.keys, node.values)]
        elif isinstance(node, (ast.List, ast.Tuple, ast.Set)):
            parts = [
                (e.value, True) if isinstance(e, ast.Starred) else (e, False) for e in node.elts
            ]
        elif isinstance(node, (ast.DictComp, ast.ListComp, ast.SetComp, ast.GeneratorExp)):
            key = node.key if isinstance(node, ast.DictComp) else node.elt
            gen = node.generators[0]
            if (
                len(node.generators) != 1
                or gen.ifs
                or not isinstance(gen.target, ast.Name)
                or not isinstance(key, ast.Name)
                or key.id != gen.target.id
            ):
                return None
            parts = [(gen.iter, True)]
        elif (
            isinstance(node, ast.Call)
            and isinstance(node.func, ast.Name)
            and node.func.id in _COLLECTIONS
            and len(node.args) == 1
            and not node.keywords
        ):
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
        bound = dict(
            zip(
                params[len(params) - len(spec.defaults) :],
                (self._value(d, {}) for d in spec.defaults),
            )
        )
        bound.update(
            (a.arg, self._value(d, {}))
            for a, d in zip(spec.kwonlyargs, spec.kw_defaults)
            if d is not None
        )
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
            for h in node.handlers
        ):  # what the submission may not have written yet
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
        if (
            isinstance(node, ast.Name)
            and node.id in self.helpers
            and isinstance(node.ctx, ast.Load)
        ):  # a helper passed on, called later
            spec = self.helpers[node.id].args
            self._helper(
                node.id,
                {a.arg: _LAB for a in (*spec.posonlyargs, *spec.args) if a.arg in ("impl", "lab")},
                cut,
            )
            return
        for child in ast.iter_child_nodes(node):
            self._visit(child, env, cut)

    def _call(self, node: ast.Call, env: dict, cut: frozenset[str]) -> bool:
        """Follow a call into a helper or a probe, or read ``getattr(lab, name)``; False for
        any other call (the caller walks its parts)."""
        func, args, keywords = node.func, node.args, node.keywords
        if (
            isinstance(func, ast.Attribute)
            and func.attr == "probe"
            and self._is_lab(func.value, env)
            and args
            and isinstance(args[0], ast.Name)
            and args[0].id in self.helpers
        ):
            self._helper(args[0].id, self._bind(args[0].id, args[1:], keywords, env, True), cut)
            rest = args[1:]
        elif (
            isinstance(func, ast.Name)
            and func.id == "getattr"
            and len(args) >= 2
            and self._is_lab(args[0], env)
        ):
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


def lab_calls(lab_file) -> dict[str, set[str]]:
    """Each top-level function and class of a lab (a file, or every file of a package) ->
    the lab's own top-level functions and classes its body names (calls, and functions
    passed on): what running it runs of the lab."""
    body = [node for f in module_files(lab_file) for node in ast.parse(f.read_text()).body]
    defs = {
        node.name: node
        for node in body
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef))
    }
    return {
        name: {
            n.id
            for n in ast.walk(node)
            if isinstance(n, ast.Name) and n.id in defs and n.id != name
        }
        for name, node in defs.items()
    }


def needed_functions(test: GradedTest, uses, functions, calls: dict[str, set[str]]) -> set[str]:
    """The functions of ``functions`` that a test runs: those it calls (``uses``, read by
    :func:`grader_uses`), or its name mentions, and, through ``calls`` (:func:`lab_calls` of
    the reference), every lab function they call in turn, except those the test replaces with
    stand-ins around that call."""
    optional = {use.function for use in uses if use.optional}
    called = {use.function for use in uses}
    uses = [use for use in uses if not use.optional]
    uses += [LabCall(f) for f in named_functions(test, functions) if f not in called]
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


def grader_uses(paths) -> dict[str, tuple[LabCall, ...]]:
    """Each test function of the graders ``paths`` (at their top level or in a ``Test``
    class) -> its calls of the lab, read by :class:`_GraderWalk`."""
    uses: dict[str, tuple[LabCall, ...]] = {}
    for path in paths:
        tree = ast.parse(Path(path).read_text(), filename=str(path))
        functions = (ast.FunctionDef, ast.AsyncFunctionDef)
        helpers = {
            n.name: n
            for n in tree.body
            if isinstance(n, functions) and not n.name.startswith("test")
        }
        values = {
            t.id: n.value
            for n in tree.body
            if isinstance(n, ast.Assign)
            for t in n.targets
            if isinstance(t, ast.Name)
        }
        tests = [
            n
            for c in tree.body
            for n in (c.body if isinstance(c, ast.ClassDef) and c.name.startswith("Test") else [c])
            if isinstance(n, functions) and n.name.startswith("test")
        ]
        for node in tests:
            found = _GraderWalk(helpers, values).test(node)
            uses[node.name] = tuple(dict.fromkeys(uses.get(node.name, ()) + found))
    return uses


def runs_through_lab(lab: LabInfo, lab_file, reference=None):
    """``runs(test, functions)`` for :func:`~course.grading.catalog.lab_tasks`: the functions
    a test runs, directly or through the lab's own calls, read from ``reference`` (the
    solution, a file or a package; without one the skeleton ``lab_file``, whose given code is
    all that calls there)."""
    source = reference if reference is not None and Path(reference).exists() else lab_file
    calls = lab_calls(source) if Path(source).exists() else {}
    try:
        uses = grader_uses(lab.files)
    except (OSError, SyntaxError):
        return functions_of

    def runs(test: GradedTest, functions) -> set[str]:
        return needed_functions(test, uses.get(test.name, ()), functions, calls)

    return runs


def lab_task_needs(lab: LabInfo, lab_file, reference=None):
    """:func:`~course.grading.catalog.lab_tasks`, each task's ``needs`` the other tasks'
    functions its tests run through the lab (:func:`runs_through_lab`)."""
    return lab_tasks(lab, lab_file, runs_through_lab(lab, lab_file, reference))


# ------------------------------------------------------------------------- the table


def _pts(points: float) -> str:
    return f"{points:g}"


def _cell(text: str) -> str:
    return str(text).replace("|", "\\|")  # a literal | inside a Markdown table cell


def _you_write(functions: list[str], lab_file: Path) -> str:
    """``f``, ``g`` of a file lab; ``grid.py``: ``f``, ``g`` of a package, by the file each
    function is written in."""
    if not Path(lab_file).is_dir():
        return ", ".join(f"`{f}`" for f in functions)
    files: dict[str, list[str]] = {}
    for f in functions:
        files.setdefault(defining_file(lab_file, f).relative_to(lab_file).as_posix(), []).append(f)
    return "; ".join(
        f"`{name}`: " + ", ".join(f"`{f}`" for f in fns) for name, fns in files.items()
    )


def package_files(lab: LabInfo, lab_file: Path) -> list[str]:
    """The files of a lab package that hold a task's functions (what a student edits and
    hands in), in task order; [] for a lab in one file."""
    if not Path(lab_file).is_dir():
        return []
    return list(
        dict.fromkeys(
            defining_file(lab_file, f).relative_to(lab_file).as_posix()
            for task in lab_tasks(lab, lab_file)
            for f in task.functions
        )
    )


def task_table(lab: LabInfo, lab_file: Path, test_file: str, reference=None) -> list[str]:
    """Markdown lines: the table of ``lab``'s tasks (``test_file``: the grader's path as the
    student types it; ``lab_file``: the skeleton, a file or a package folder; ``reference``:
    the solution, whose calls say what each task's tests run of the other tasks)."""
    lines = [
        "| task | title | points | you write | needs first | run only its tests |",
        "|---:|---|---:|---|---|---|",
    ]
    for task in lab_task_needs(lab, lab_file, reference):
        you_write = _you_write(task.functions, lab_file)
        needs = "; ".join(
            f"task {k} (" + ", ".join(f"`{f}`" for f in fns) + ")" for k, fns in task.needs.items()
        )
        run = (
            f"`python -m pytest {test_file} --task {task.number}` or "
            f"`rtcourse grade --lab {lab.number} --task {task.number}`"
        )
        lines.append(
            f"| {task.number} | {_cell(task.title)} | {_pts(task.points)} | "
            f"{you_write} | {needs} | {run} |"
        )
    return lines
