"""The contract lists (``tests/contracts/labN.py``) stay in step with the labs, the graders
and the mutants.

A contract list names, per student function, every promise its docstring makes and the
grader test that fails when that promise alone is broken, with the shipped mutant that
breaks just it where there is one. Here:

* every public function a lab's skeleton leaves to the student has a list;
* every test a list names is a test of that lab's graders (visible or hidden);
* every mutant a list names is shipped for that lab, and every shipped mutant of the lab
  is named by some promise (a mistake breaks a promise the docstring makes);
* the named test fails on the named mutant: graded with ``catch_mutants`` on that test
  alone (``-k``), CUDA hidden, as ``rtcourse mutants`` grades them.
"""

from __future__ import annotations

import ast
import dataclasses
from pathlib import Path

import pytest

from course.core.files import import_file
from course.core.labs import lab_path
from course.grading.catalog import skeleton_functions
from course.grading.mutants import catch_mutants, load_mutants

ROOT = Path(__file__).resolve().parents[2]
# every lab with a contract list (tests/contracts/labN.py) -> its package
LABS = {
    int(path.stem[3:]): lab_path(ROOT / "solutions", path.stem).name
    for path in sorted((ROOT / "tests" / "contracts").glob("lab*.py"))
}


def contracts(lab: int) -> dict:
    return import_file(
        ROOT / "tests" / "contracts" / f"lab{lab}.py", f"rtcourse_contracts_lab{lab}"
    ).CONTRACTS


def grader_tests(lab: int) -> set[str]:
    names = set()
    for path in [
        *ROOT.glob(f"tests/test_lab{lab}_*.py"),
        *ROOT.glob(f"tests/hidden/test_lab{lab}_*.py"),
    ]:
        names |= {
            n.name
            for n in ast.parse(path.read_text()).body
            if isinstance(n, ast.FunctionDef) and n.name.startswith("test_")
        }
    return names


def entries(lab: int):
    for function, promises in contracts(lab).items():
        for promise, test, mutant in promises:
            yield function, promise, test, mutant


@pytest.mark.parametrize("lab", sorted(LABS))
def test_every_student_function_has_a_contract(lab):
    skeleton = ROOT / "labs" / LABS[lab]
    skeleton = skeleton if skeleton.is_dir() else skeleton.with_suffix(".py")
    wanted = set(skeleton_functions(skeleton))
    listed = contracts(lab)
    assert wanted - set(listed) == set(), (
        f"Lab {lab}: no contract list for {sorted(wanted - set(listed))} in "
        f"tests/contracts/lab{lab}.py"
    )
    assert set(listed) - wanted == set(), (
        f"Lab {lab}: contract lists for functions the skeleton does not ask for: "
        f"{sorted(set(listed) - wanted)}"
    )
    empty = [f for f, promises in listed.items() if not promises]
    assert not empty, f"Lab {lab}: empty contract lists: {empty}"


@pytest.mark.parametrize("lab", sorted(LABS))
def test_named_tests_and_mutants_exist(lab):
    tests = grader_tests(lab)
    shipped = {m.name for m in load_mutants(ROOT) if m.lab == lab}
    missing = [
        f"{fn}: {promise!r} names the test {test!r}, which no grader of Lab {lab} defines"
        for fn, promise, test, _ in entries(lab)
        if test not in tests
    ]
    missing += [
        f"{fn}: {promise!r} names the mutant {mutant!r}, not shipped for Lab {lab}"
        for fn, promise, _, mutant in entries(lab)
        if mutant and mutant not in shipped
    ]
    named = {mutant for *_, mutant in entries(lab) if mutant}
    missing += [
        f"mutant {m!r} breaks no promise of tests/contracts/lab{lab}.py"
        for m in sorted(shipped - named)
    ]
    assert not missing, "\n".join(missing)


@pytest.mark.parametrize("lab", sorted(LABS))
def test_each_promise_test_fails_on_its_mutant(lab):
    by_name = {m.name: m for m in load_mutants(ROOT) if m.lab == lab}
    pairs = sorted({(mutant, test) for *_, test, mutant in entries(lab) if mutant in by_name})
    runs = [
        dataclasses.replace(by_name[mutant], name=f"{mutant}@{test}", tests=test)
        for mutant, test in pairs
    ]
    outcomes = catch_mutants(runs, ROOT)
    survived = [
        f"{name}: the test passes on the mutant"
        + (f" ({outcome['error']})" if outcome.get("error") else "")
        for name, outcome in outcomes.items()
        if not outcome.get("killed")
    ]
    assert not survived, (
        f"Lab {lab}: a promise's test does not catch the mistake that "
        f"breaks it:\n" + "\n".join(survived)
    )
