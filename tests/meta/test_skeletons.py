"""Skeletons (``labs/``) against references (``solutions/``): the code a skeleton provides
inside a function it leaves unwritten (argument checks, given helpers) is the reference's
own, statement for statement, so a student starts from the same calls, with the same
results kept (``_, s = check_inputs(...)``, not a bare ``check_inputs(...)``)."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from course.core.files import module_files

ROOT = Path(__file__).resolve().parents[2]
SKELETONS = sorted((ROOT / "labs").glob("lab*_*.py"))
_SIMPLE = (ast.Expr, ast.Assign, ast.AnnAssign, ast.AugAssign)


def _functions(path: Path) -> dict[str, ast.AST]:
    """Top-level functions and methods of a lab file (and of its parts, if any)."""
    found = {}
    for node in (n for f in module_files(path)
                 for n in ast.parse(f.read_text(), filename=str(f)).body):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            found[node.name] = node
        elif isinstance(node, ast.ClassDef):
            found.update({f"{node.name}.{m.name}": m for m in node.body
                          if isinstance(m, (ast.FunctionDef, ast.AsyncFunctionDef))})
    return found


def _statements(fn) -> list[str]:
    """The simple statements of ``fn``'s body (docstring left out), at any depth."""
    body = fn.body[1:] if ast.get_docstring(fn) else fn.body
    return [ast.unparse(s) for stmt in body for s in ast.walk(stmt) if isinstance(s, _SIMPLE)]


def _unwritten(fn) -> bool:
    return any(isinstance(n, ast.Raise) and n.exc is not None
               and "NotImplementedError" in ast.unparse(n.exc) for n in ast.walk(fn))


@pytest.mark.parametrize("skeleton", SKELETONS, ids=[p.stem for p in SKELETONS])
def test_provided_code_is_the_references(skeleton):
    reference = _functions(ROOT / "solutions" / skeleton.name)
    mine = _functions(skeleton)
    public = {n for n in mine if not n.startswith("_")}
    theirs_public = {n for n in reference if not n.startswith("_")}
    assert public == theirs_public, (
        f"{skeleton.name}: public functions only in the skeleton "
        f"{sorted(public - theirs_public)}, only in the reference "
        f"{sorted(theirs_public - public)}")
    for name, fn in mine.items():
        if not _unwritten(fn) or name not in reference:
            continue
        theirs = set(_statements(reference[name]))
        extra = [line for line in _statements(fn) if line not in theirs]
        assert not extra, (f"{skeleton.name}: {name} provides {extra[0]!r}, which the "
                           f"reference does not do (a provided call must be the reference's, "
                           f"with the same results kept)")
