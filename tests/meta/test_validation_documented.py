"""Every argument check a grader asks for is promised in the function's docstring.

A grader that calls ``expect_error(name, impl.fn, ...)`` (directly, or through a wrapper of
the grader that passes ``fn`` on) grades a check the student must write or keep. The
student reads the docstring, so the docstring says it, in one checkable form: a paragraph
that starts with ``Errors`` and names the argument together with the error, e.g.

    Errors: ValueError naming ``pixel`` for an index outside [0, H * W); TypeError naming
    ``key`` unless it is an int64 tensor.

The paragraph must name one of the names the grader accepts and one of the exception types
it accepts (``ValueError``/``TypeError`` unless ``kinds=`` says otherwise). For a class
called as a constructor the ``__init__`` docstring (or the class's) counts.

The graders are read with ``ast`` (nothing runs): ``impl.fn``, ``impl.Class.method``, a
local bound to ``impl.fn``, ``getattr(impl, name)`` with ``name`` from a literal
``parametrize`` or ``for`` list, and a method of a local made by ``impl.Class(...)``; the
argument's name may be a local unpacked from a literal ``for`` list (each name it takes).
A function the grader imports from the course (``from course.given.lab2 import pack_bvh``)
is given code, not the student's: its checks are not the lab's to document.
"""

from __future__ import annotations

import ast
import re
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
DEFAULT_KINDS = ("ValueError", "TypeError")
# Labs whose references are being rewritten by others: checked, reported, not yet failing.
PENDING: dict[int, str] = {}


@dataclass(frozen=True)
class Check:
    """One graded argument check: ``function`` of ``module`` must reject with one of
    ``kinds`` naming one of ``names``; ``where`` is the grader's line."""

    module: str
    function: str
    names: tuple
    kinds: tuple
    where: str


def _graders() -> list[Path]:
    return sorted([*ROOT.glob("tests/test_lab*.py"), *ROOT.glob("tests/hidden/test_lab*.py")])


def _literal_strings(node) -> tuple | None:
    try:
        value = ast.literal_eval(node)
    except ValueError:
        return None
    if isinstance(value, str):
        return (value,)
    if isinstance(value, (tuple, list)) and all(isinstance(v, str) for v in value):
        return tuple(value)
    return None


def _kinds(call: ast.Call) -> tuple:
    for kw in call.keywords:
        if kw.arg == "kinds" and isinstance(kw.value, (ast.Tuple, ast.List)):
            return tuple(e.id for e in kw.value.elts if isinstance(e, ast.Name))
    return DEFAULT_KINDS


def _dotted(node) -> str | None:
    if isinstance(node, ast.Name):
        return node.id
    if isinstance(node, ast.Attribute):
        base = _dotted(node.value)
        return f"{base}.{node.attr}" if base else None
    return None


class _Scope:
    """What the names of one grader function may stand for: lab function names."""

    def __init__(self, fn: ast.FunctionDef, strings: dict):
        self.values: dict[str, list] = {}  # local -> [(line, lab qualnames it is bound to)]
        self.instances: dict[str, set] = {}  # local -> lab classes it is an instance of
        self.strings = strings  # local -> literal strings it may take
        # ``if name == "x": ... return`` ahead of a line: past it, ``name`` is not "x".
        self.returned = [
            (n.end_lineno, n.test.left.id, n.test.comparators[0].value)
            for n in fn.body
            if isinstance(n, ast.If)
            and isinstance(n.test, ast.Compare)
            and isinstance(n.test.left, ast.Name)
            and isinstance(n.test.ops[0], ast.Eq)
            and isinstance(n.test.comparators[0], ast.Constant)
            and isinstance(n.body[-1], ast.Return)
        ]
        for node in sorted(
            (n for n in ast.walk(fn) if isinstance(n, ast.Assign)), key=lambda n: n.lineno
        ):
            if len(node.targets) == 1 and isinstance(node.targets[0], ast.Name):
                name, value = node.targets[0].id, node.value
                if isinstance(value, ast.Call) and _impl_name(value.func):
                    self.instances.setdefault(name, set()).add(_impl_name(value.func))
                else:
                    bound = self.resolve(value, node.lineno)
                    self.values.setdefault(name, []).append((node.lineno, bound))

    def resolve(self, node, line: int) -> set:
        direct = _impl_name(node)
        if direct:
            return {direct}
        if isinstance(node, ast.Name):
            earlier = [bound for at, bound in self.values.get(node.id, ()) if at < line]
            return set(earlier[-1]) if earlier else set()
        if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name):
            return {f"{cls}.{node.attr}" for cls in self.instances.get(node.value.id, ())}
        if (
            isinstance(node, ast.Call)
            and _dotted(node.func) == "getattr"
            and len(node.args) == 2
            and _dotted(node.args[0]) == "impl"
        ):
            key = node.args[1]
            if isinstance(key, ast.Constant) and isinstance(key.value, str):
                return {key.value}
            if isinstance(key, ast.Name):
                ruled_out = {v for end, name, v in self.returned if name == key.id and end < line}
                return set(self.strings.get(key.id, ())) - ruled_out
        return set()


def _string_values(functions: list, constants: dict) -> dict:
    """(function, local) -> the literal strings the local may take: from ``parametrize``,
    ``for`` over a literal, and the arguments of the module's calls of the function."""
    values: dict[tuple, set] = {}
    for fn in functions:
        for dec in fn.decorator_list:
            if isinstance(dec, ast.Call) and (_dotted(dec.func) or "").endswith("parametrize"):
                names = _literal_strings(dec.args[0]) if dec.args else None
                arg = dec.args[1] if len(dec.args) > 1 else None
                strings = _literal_strings(arg) if arg is not None else None
                if strings is None and isinstance(arg, ast.Name):
                    strings = constants.get(arg.id)
                if names and len(names) == 1 and "," not in names[0] and strings:
                    values.setdefault((fn.name, names[0]), set()).update(strings)
        for node in ast.walk(fn):
            if isinstance(node, ast.For) and isinstance(node.target, ast.Name):
                strings = _literal_strings(node.iter)
                if strings is None and isinstance(node.iter, ast.Name):
                    strings = constants.get(node.iter.id)
                if strings:
                    values.setdefault((fn.name, node.target.id), set()).update(strings)
            elif isinstance(node, ast.For) and isinstance(node.target, ast.Tuple):
                for local, strings in _unpacked_strings(node.target, node.iter).items():
                    values.setdefault((fn.name, local), set()).update(strings)
    params = {fn.name: [a.arg for a in fn.args.args] for fn in functions}
    for _ in range(4):  # wrappers of wrappers
        for fn in functions:
            for call in (c for c in ast.walk(fn) if isinstance(c, ast.Call)):
                callee = _dotted(call.func)
                if callee not in params:
                    continue
                bound = list(zip(params[callee], call.args))
                bound += [(kw.arg, kw.value) for kw in call.keywords if kw.arg]
                for param, arg in bound:
                    if isinstance(arg, ast.Constant) and isinstance(arg.value, str):
                        values.setdefault((callee, param), set()).add(arg.value)
                    elif isinstance(arg, ast.Name) and (fn.name, arg.id) in values:
                        values.setdefault((callee, param), set()).update(values[(fn.name, arg.id)])
    return values


def _unpacked_strings(target: ast.Tuple, iterable) -> dict:
    """``for name, x in (("a", 1), ("b", 2))``: local -> the strings it takes, for each
    unpacked local that is a string in every item of a literal iterable."""
    try:
        items = ast.literal_eval(iterable)
    except ValueError:
        return {}
    if not isinstance(items, (tuple, list)) or not all(
        isinstance(item, (tuple, list)) and len(item) == len(target.elts) for item in items
    ):
        return {}
    return {
        elt.id: {item[i] for item in items}
        for i, elt in enumerate(target.elts)
        if isinstance(elt, ast.Name) and items and all(isinstance(item[i], str) for item in items)
    }


def _impl_name(node) -> str | None:
    dotted = _dotted(node)
    return dotted.split(".", 1)[1] if dotted and dotted.startswith("impl.") else None


def _course_imports(tree: ast.Module) -> set[str]:
    """The names a grader imports from the course package at its top level."""
    return {
        alias.asname or alias.name
        for node in tree.body
        if isinstance(node, ast.ImportFrom)
        and node.level == 0
        and (node.module or "").split(".")[0] == "course"
        for alias in node.names
    }


def _checks_in(path: Path) -> tuple[list[Check], list[str]]:
    """The graded argument checks of one grader, and the calls it could not resolve."""
    tree = ast.parse(path.read_text())
    module = next(
        (
            ast.literal_eval(n.value)
            for n in tree.body
            if isinstance(n, ast.Assign)
            and any(getattr(t, "id", "") == "LAB_MODULE" for t in n.targets)
        ),
        None,
    )
    constants = {
        n.targets[0].id: v
        for n in tree.body
        if isinstance(n, ast.Assign)
        and isinstance(n.targets[0], ast.Name)
        and (v := _literal_strings(n.value)) is not None
    }
    functions = [n for n in tree.body if isinstance(n, ast.FunctionDef)]
    given = _course_imports(tree)
    # Wrappers: functions that pass one of their parameters to expect_error as ``fn``.
    wrappers = {}  # name -> (parameter index, parameter name, [(names, kinds)])
    for fn in functions:
        params = [a.arg for a in fn.args.args]
        calls = [
            c
            for c in ast.walk(fn)
            if isinstance(c, ast.Call)
            and _dotted(c.func) == "expect_error"
            and len(c.args) >= 2
            and isinstance(c.args[1], ast.Name)
            and c.args[1].id in params
        ]
        for c in calls:
            entry = wrappers.setdefault(fn.name, (params.index(c.args[1].id), c.args[1].id, []))
            entry[2].append((_literal_strings(c.args[0]), _kinds(c)))
    strings = _string_values(functions, constants)
    checks, unresolved = [], []
    for fn in functions:
        scope = _Scope(fn, {local: v for (owner, local), v in strings.items() if owner == fn.name})
        for call in (c for c in ast.walk(fn) if isinstance(c, ast.Call)):
            name = _dotted(call.func)
            where = f"{path.relative_to(ROOT)}:{call.lineno}"
            if name == "expect_error" and len(call.args) >= 2:
                if (
                    fn.name in wrappers
                    and isinstance(call.args[1], ast.Name)
                    and call.args[1].id == wrappers[fn.name][1]
                ):
                    continue  # checked where the wrapper is called
                names = _literal_strings(call.args[0])
                wanted = [(names, _kinds(call), call.args[1])]
                if (
                    names is None
                    and isinstance(call.args[0], ast.Name)
                    and scope.strings.get(call.args[0].id)
                ):  # each name it takes
                    wanted = [
                        ((n,), _kinds(call), call.args[1])
                        for n in sorted(scope.strings[call.args[0].id])
                    ]
            elif name in wrappers:
                index, param, inner = wrappers[name]
                target = next(
                    (kw.value for kw in call.keywords if kw.arg == param),
                    call.args[index] if len(call.args) > index else None,
                )
                wanted = [(names, kinds, target) for names, kinds in inner]
            else:
                continue
            for names, kinds, target in wanted:
                if (
                    isinstance(target, ast.Name)
                    and target.id in given
                    and target.id not in scope.values
                ):
                    continue  # given code's check, not one the student writes
                targets = scope.resolve(target, call.lineno) if target is not None else set()
                if not names or not targets:
                    unresolved.append(f"{where}: {ast.unparse(call)[:90]}")
                    continue
                checks += [Check(module, t, names, kinds, where) for t in sorted(targets)]
    return checks, unresolved


def _definitions(module: str) -> dict[str, ast.AST]:
    """Qualified name -> definition, over the reference's file or package."""
    base = ROOT / "solutions" / module
    files = sorted(base.glob("*.py")) if base.is_dir() else [base.with_suffix(".py")]
    found = {}
    for file in files:
        for node in ast.parse(file.read_text()).body:
            if isinstance(node, (ast.FunctionDef, ast.ClassDef)):
                found.setdefault(node.name, node)
                if isinstance(node, ast.ClassDef):
                    for sub in node.body:
                        if isinstance(sub, ast.FunctionDef):
                            found.setdefault(f"{node.name}.{sub.name}", sub)
    return found


def errors_paragraphs(docstring: str) -> list[str]:
    """The docstring's paragraphs that start with ``Errors``."""
    paragraphs = re.split(r"\n\s*\n", docstring or "")
    return [p for p in paragraphs if re.match(r"\s*Errors\b", p)]


def documented(check: Check, definitions: dict) -> str | None:
    """None when the reference's docstring promises ``check``, else what is missing."""
    node = definitions.get(check.function)
    if node is None:
        return f"{check.module}.{check.function}: no such definition in solutions/"
    docs = [ast.get_docstring(node) or ""]
    if isinstance(node, ast.ClassDef):
        init = definitions.get(f"{check.function}.__init__")
        docs.insert(0, ast.get_docstring(init) or "" if init else "")
    for paragraph in (p for doc in docs for p in errors_paragraphs(doc)):
        if any(re.search(rf"\b{re.escape(n)}\b", paragraph) for n in check.names) and any(
            re.search(rf"\b{k}\b", paragraph) for k in check.kinds
        ):
            return None
    return (
        f"{check.where}: {check.function} must say in an 'Errors' paragraph of its "
        f"docstring that it raises {' or '.join(check.kinds)} naming "
        f"{' or '.join(f'``{n}``' for n in check.names)}"
    )


def lab_checks(lab: int) -> tuple[list[Check], list[str]]:
    checks, unresolved = [], []
    for path in _graders():
        if re.match(rf"test_lab{lab}_", path.name):
            more, lost = _checks_in(path)
            checks += more
            unresolved += lost
    return checks, unresolved


@pytest.mark.parametrize("lab", range(7))
def test_every_graded_check_is_in_the_docstring(lab):
    checks, unresolved = lab_checks(lab)
    assert checks, f"Lab {lab}: no expect_error call found in its graders"
    missing = []
    for module in sorted({c.module for c in checks}):
        definitions = _definitions(module)
        missing += [
            m
            for c in checks
            if c.module == module and (m := documented(c, definitions)) is not None
        ]
    problems = sorted(set(missing)) + [
        f"{u} (cannot tell which lab function it checks: pass impl.fn, or a local bound to one)"
        for u in unresolved
    ]
    if problems and lab in PENDING:
        pytest.xfail(f"{PENDING[lab]}: {len(problems)} to do, first: {problems[0]}")
    assert not problems, "\n".join(problems)


def test_the_reader_resolves_what_graders_write(tmp_path, monkeypatch):
    grader = tmp_path / "tests" / "test_lab9_toy.py"
    grader.parent.mkdir()
    grader.write_text(
        "from course.given.lab9 import given_fn\n"
        'LAB_MODULE = "lab9_toy"\nNAMES = ("f", "g")\n\n'
        "def bad(render, device):\n    expect_error('x', render, 1, case='x=1')\n\n"
        "@pytest.mark.parametrize('name', NAMES)\n"
        "def test_a(impl, name):\n    fn = getattr(impl, name)\n"
        "    expect_error(('x', 'y'), fn, 0)\n    box = impl.Box(1)\n"
        "    expect_error('z', box.put, 0, kinds=(RuntimeError,))\n"
        "    bad(impl.h, 'cpu')\n    expect_error('w', impl.Box, 0)\n"
        "    for arg, v in (('p', -1.0), ('q', 2)):\n        expect_error(arg, impl.k, v)\n"
        "    expect_error('v', given_fn, 0)\n"
    )
    monkeypatch.setitem(globals(), "ROOT", tmp_path)
    checks, unresolved = _checks_in(grader)
    got = sorted((c.function, c.names, c.kinds) for c in checks)
    assert got == [
        ("Box", ("w",), DEFAULT_KINDS),
        ("Box.put", ("z",), ("RuntimeError",)),
        ("f", ("x", "y"), DEFAULT_KINDS),
        ("g", ("x", "y"), DEFAULT_KINDS),
        ("h", ("x",), DEFAULT_KINDS),
        ("k", ("p",), DEFAULT_KINDS),
        ("k", ("q",), DEFAULT_KINDS),
    ], got
    assert not unresolved
    ok = ast.parse('def h(x):\n    """Do.\n\n    Errors: ValueError naming ``x``.\n    """\n')
    bad = ast.parse('def h(x):\n    """Do. Raises ValueError for a bad ``x``."""\n')
    check = Check("lab9_toy", "h", ("x",), DEFAULT_KINDS, "here")
    assert documented(check, {"h": ok.body[0]}) is None
    assert "Errors" in documented(check, {"h": bad.body[0]})
