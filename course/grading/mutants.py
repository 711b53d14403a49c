"""Mutants: typical student mistakes, applied to a reference solution.

A grader is only as good as the mistakes it catches. Each lab lists its
mutants in ``solutions/mutants/labN.py``; :func:`grade_mutant` writes the
mutated module (with its parts, where it is kept in parts) into a scratch folder
and grades it on the tests of the function it breaks (the ``tests`` ``-k``
expression), in a fresh process; :func:`catch_mutants` only asks whether each mutant
fails a test, for many mutants at once and much faster (warm workers, first failure).
"""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class Mutant:
    """Replace ``find`` (exactly once, inside ``function``) by ``replace``."""

    name: str
    module: str
    function: str
    find: str
    replace: str
    tests: str
    why: str

    @property
    def lab(self) -> int:
        return int(self.module.split("_")[0].removeprefix("lab"))


def load_mutants(root) -> list[Mutant]:
    """All mutants shipped under ``root/solutions/mutants``."""
    return _load(root, "mutants", "MUTANTS")


def load_alternatives(root) -> list[Mutant]:
    """The correct alternative solutions under ``root/solutions/alternatives``: changes to
    the reference that every grader must accept (no test they select may fail)."""
    return _load(root, "alternatives", "ALTERNATIVES")


def _load(root, folder: str, name: str) -> list[Mutant]:
    from course.core.files import import_file

    found = []
    for path in sorted(Path(root, "solutions", folder).glob("lab*.py")):
        found += getattr(import_file(path, f"rtcourse_{folder}_{path.stem}"), name)
    return found


def _function_span(source: str, qualname: str) -> tuple[int, int]:
    """Character span of a (possibly ``Class.method``) definition in ``source``."""
    tree = ast.parse(source)
    nodes = tree.body
    node = None
    for part in qualname.split("."):
        node = next(
            (
                n
                for n in nodes
                if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef))
                and n.name == part
            ),
            None,
        )
        if node is None:
            raise ValueError(f"mutant: no definition {qualname!r} in the solution")
        nodes = node.body
    lines = source.splitlines(keepends=True)
    start = sum(len(line) for line in lines[: node.lineno - 1])
    end = sum(len(line) for line in lines[: node.end_lineno])
    return start, end


def apply_mutant(mutant: Mutant, source: str) -> str:
    """The solution's source with the mistake applied."""
    start, end = _function_span(source, mutant.function)
    body = source[start:end]
    count = body.count(mutant.find)
    if count != 1:
        raise ValueError(
            f"mutant {mutant.name}: {mutant.find!r} occurs {count} times in "
            f"{mutant.function}, expected exactly once"
        )
    mutated = source[:start] + body.replace(mutant.find, mutant.replace) + source[end:]
    try:  # a mistake a student makes, not a file that does not import
        ast.parse(mutated)
    except SyntaxError as error:
        raise ValueError(
            f"mutant {mutant.name}: the mutated source does not parse "
            f"({error.msg}, line {error.lineno})"
        ) from None
    return mutated


def grade_mutant(mutant: Mutant, root, workdir, timeout: float = 600) -> dict:
    """Grade the mutated solution on its tests; return the results dictionary. The
    mistake goes into the file that defines ``mutant.function`` (the module, or one of
    its package's files: the others are copied unchanged)."""
    from course.core.files import copy_module, defining_file, lab_source, relative_name

    root, workdir = Path(root), Path(workdir)
    solution = lab_source(root / "solutions", mutant.module)
    path = defining_file(solution, mutant.function)
    name = relative_name(solution, path)
    copy_module(solution, workdir, {name: apply_mutant(mutant, path.read_text())})
    out = workdir / "results.json"
    # The mutant is our own code: grade it in-process in the child for speed.
    cmd = [
        sys.executable,
        "-m",
        "course.tools.cli",
        "grade",
        "--impl",
        str(workdir),
        "--trusted",
        "--lab",
        str(mutant.lab),
        "-k",
        mutant.tests,
        "--json",
        str(out),
    ]
    proc = subprocess.run(
        cmd, cwd=root, capture_output=True, text=True, timeout=timeout, check=False
    )
    if not out.exists():
        raise RuntimeError(
            f"grading mutant {mutant.name} wrote no results:\n"
            f"{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}"
        )
    return json.loads(out.read_text())


def catch_mutants(
    mutants: list[Mutant], root, *, workers: int = 2, deadline: float = 300.0
) -> dict[str, dict]:
    """Whether each mutant fails one of its tests: ``{name: outcome}`` with ``killed``,
    ``ran`` (tests run), ``by`` (the first failing test) and ``error`` when the run proves
    nothing (a broken grader, a ``-k`` that selects no test).

    Graded like the generated mutants (course.grading.mutate): ``workers`` warm processes
    that import torch and the graders once and grade one mutant after another in-process,
    each stopped at its first failing test, CUDA hidden; a mutant that hangs past
    ``deadline`` seconds counts as caught (the real grader's time limit fails it). The 129
    shipped mutants take ~1 minute on 2 cores this way, ~6 minutes with :func:`grade_mutant`
    (a fresh process each, every selected test scored)."""
    from course.core.files import defining_file, lab_source, relative_name
    from course.grading.mutate import run_specs

    root = Path(root)
    specs = []
    for mutant in mutants:
        solution = lab_source(root / "solutions", mutant.module)
        path = defining_file(solution, mutant.function)
        specs.append(
            {
                "id": mutant.name,
                "module": mutant.module,
                "tests": [f"({mutant.tests})"],
                "file": relative_name(solution, path),
                "source": apply_mutant(mutant, path.read_text()),
            }
        )
    outcomes = run_specs(root, specs, workers=max(1, workers), deadline=deadline)
    return {spec["id"]: outcome for spec, outcome in zip(specs, outcomes)}
