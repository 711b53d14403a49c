"""The course as a whole: the handout, the grader's verdicts on the skeletons and on
the references, and the mutants every grader must catch."""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

import pytest

from course.core.files import module_files
from course.grading.mutants import catch_mutants, load_mutants
from course.tools.release import release

ROOT = Path(__file__).resolve().parents[2]
MUTANTS = load_mutants(ROOT)


def _rtcourse(*args, cwd, timeout=900):
    return subprocess.run(
        [sys.executable, "-m", "course.tools.cli", *args],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=timeout,
        check=False,
    )


@pytest.fixture(scope="module")
def handout(tmp_path_factory):
    out = tmp_path_factory.mktemp("handout")
    release(ROOT, out)
    return out


def test_handout_holds_no_solutions(handout):
    assert not (handout / "solutions").exists()
    assert not (handout / "tests" / "meta").exists()
    assert (handout / "labs").is_dir() and (handout / "tests").is_dir()
    assert (handout / "README.md").is_file() and (handout / "pyproject.toml").is_file()
    labs = [p for p in (handout / "labs").glob("lab*_*") if p.suffix == ".py" or p.is_dir()]
    assert labs
    for lab in sorted(labs):
        solution = ROOT / "solutions" / lab.name  # a file, or a package folder
        assert solution.exists(), f"{lab.name} has no reference solution"
        assert _public_api(lab) == _public_api(solution), (
            f"{lab.name}: the skeleton's API differs from the solution's"
        )
        assert sum(f.read_text().count("NotImplementedError") for f in module_files(lab)) >= 1


def _public_api(path: Path) -> dict:
    """Public functions, classes and methods with their parameter names (of a lab file and
    its parts, if any)."""
    api = {}

    def visit(nodes, prefix=""):
        for node in nodes:
            if (
                isinstance(node, (ast.FunctionDef, ast.ClassDef))
                and not node.name.startswith("_")
                or isinstance(node, ast.FunctionDef)
                and node.name == "__init__"
            ):
                if isinstance(node, ast.ClassDef):
                    api[prefix + node.name] = "class"
                    visit(node.body, prefix + node.name + ".")
                else:
                    args = node.args
                    api[prefix + node.name] = [
                        a.arg for a in args.posonlyargs + args.args + args.kwonlyargs
                    ]

    for f in module_files(path):
        visit(ast.parse(f.read_text()).body)
    return api


def test_skeletons_score_zero_with_teaching_messages(handout, tmp_path):
    results = tmp_path / "results.json"
    proc = _rtcourse("grade", "--json", str(results), cwd=handout)
    assert results.exists(), proc.stdout[-3000:] + proc.stderr[-3000:]
    data = json.loads(results.read_text())
    assert data["max_score"] > 0 and data["score"] == 0, data["output"]
    assert "total: 0.00" in proc.stdout, "the score table is printed"
    silent = [t["name"] for t in data["tests"] if "not implemented yet" not in t["output"]]
    assert not silent, f"tests failing without 'not implemented yet': {silent[:5]}"


def test_references_score_full_marks(tmp_path):
    results = tmp_path / "results.json"
    proc = _rtcourse("grade", "--impl", "solutions", "--json", str(results), cwd=ROOT)
    data = json.loads(results.read_text())
    lost = [t["name"] for t in data["tests"] if t["status"] != "passed"]
    assert (
        not lost and data["max_score"] > 0 and data["score"] == pytest.approx(data["max_score"])
    ), f"references lost points on {lost}\n{proc.stdout[-3000:]}"


@pytest.fixture(scope="module")
def mutant_outcomes():
    # Whether each mutant fails a test, not its score: warm workers, first failure (the
    # score a mutant keeps is test_task_isolation's concern).
    return catch_mutants(MUTANTS, ROOT, workers=2)


def test_every_lab_ships_mutants():
    labs = {int(p.name.split("_")[0][3:]) for p in (ROOT / "solutions").glob("lab*_*")}
    counts = {lab: sum(m.lab == lab for m in MUTANTS) for lab in labs}
    assert all(n >= 4 for n in counts.values()), f"mutants per lab: {counts}"


def test_a_mutant_that_does_not_parse_is_refused():
    # Deleting a whole statement left an indentation error once: the "mutant" failed to
    # import, so it was caught without testing the mistake it claimed to make.
    from course.grading.mutants import Mutant, apply_mutant

    source = "def f(x):\n    x = x + 0\n    x = x.clamp(-1, 1)\n    return x\n"
    bad = Mutant(
        name="drop",
        module="lab0_x",
        function="f",
        find="x = x.clamp(-1, 1)\n",
        replace="",
        tests="f",
        why="",
    )
    with pytest.raises(ValueError, match="drop: the mutated source does not parse"):
        apply_mutant(bad, source)
    good = Mutant(
        name="keep",
        module="lab0_x",
        function="f",
        find="x.clamp(-1, 1)",
        replace="x",
        tests="f",
        why="",
    )
    assert "x = x\n" in apply_mutant(good, source)


@pytest.mark.parametrize("mutant", MUTANTS, ids=[m.name for m in MUTANTS])
def test_mutant_loses_points(mutant_outcomes, mutant):
    outcome = mutant_outcomes[mutant.name]
    assert not outcome.get("error"), (
        f"{mutant.name}: its -k {mutant.tests!r} proved nothing: {outcome['error']}"
    )
    assert outcome["killed"], (
        f"mutant {mutant.name} ({mutant.why}) passed all {outcome['ran']} tests its -k "
        f"{mutant.tests!r} selects: the grader misses this mistake"
    )
