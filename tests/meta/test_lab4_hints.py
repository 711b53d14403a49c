"""A hint follows from what was measured: Lab 4's march test names a loop one step short by
its step count, and the compositing order only when the radiance shows that order."""

from __future__ import annotations

import dataclasses
from pathlib import Path

from course.grading.mutants import Mutant, grade_mutant, load_mutants

ROOT = Path(__file__).resolve().parents[2]
TEST = "march_box_homogeneous_and_layered"


def _failures(mutant: Mutant, tmp_path) -> str:
    data = grade_mutant(mutant, ROOT, tmp_path)
    failed = [t["output"] for t in data["tests"] if t["score"] < t["max_score"]]
    assert failed, f"{mutant.name} passed {TEST}"
    return " ".join(" ".join(failed).split())  # the words, wherever a long line wrapped


def test_one_step_short_is_named_by_its_step_count(tmp_path):
    short = Mutant(
        name="march_one_step_short",
        module="lab4_march",
        function="march_box",
        find="for i in range(steps):",
        replace="for i in range(steps - 1):",
        tests=TEST,
        why="the loop stops one step early",
    )
    output = _failures(short, tmp_path)
    assert "samples per ray" in output and "the loop runs `steps` times" in output, output
    assert "before updating T" not in output, output


def test_transmittance_first_is_named_by_its_order(tmp_path):
    mutant = next(m for m in load_mutants(ROOT) if m.name == "march_transmittance_first")
    output = _failures(dataclasses.replace(mutant, tests=TEST), tmp_path)
    assert "one step's transmittance too dark" in output, output
    assert "samples per ray" not in output, output
