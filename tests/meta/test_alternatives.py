"""Correct alternative solutions (``solutions/alternatives/``: float64 inside, another loop
order, another valid tree, another formula) keep every point: a grader that fails one tests
the reference's incidental choices, not what the docstring promises."""

from __future__ import annotations

from pathlib import Path

import pytest

from course.grading.mutants import catch_mutants, load_alternatives

ROOT = Path(__file__).resolve().parents[2]
ALTERNATIVES = load_alternatives(ROOT)


@pytest.fixture(scope="module")
def outcomes():
    # Graded as the shipped mutants are (warm workers, CUDA hidden), but each must pass
    # every test its -k selects, so every selected test runs.
    return catch_mutants(ALTERNATIVES, ROOT, workers=2)


def test_every_lab_has_an_alternative():
    labs = {int(p.name.split("_")[0][3:]) for p in (ROOT / "solutions").glob("lab*_*")}
    missing = labs - {a.lab for a in ALTERNATIVES}
    assert not missing, f"labs without a correct alternative solution: {sorted(missing)}"


@pytest.mark.parametrize("alternative", ALTERNATIVES, ids=[a.name for a in ALTERNATIVES])
def test_alternative_keeps_every_point(outcomes, alternative):
    outcome = outcomes[alternative.name]
    assert not outcome.get("error"), (
        f"{alternative.name}: its -k {alternative.tests!r} proved nothing: {outcome['error']}"
    )
    assert outcome["ran"] > 0, f"{alternative.name}: -k {alternative.tests!r} ran no test"
    assert not outcome["killed"], (
        f"the correct alternative {alternative.name} ({alternative.why}) failed "
        f"{outcome['by']}: that test asks for more than the docstring of "
        f"{alternative.function} promises"
    )
