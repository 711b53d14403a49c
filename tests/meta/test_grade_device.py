"""``rtcourse grade --device``: ``cpu`` (the default) hides CUDA before anything starts it,
so the graders and every sandboxed worker they start (which inherit the environment) grade
on the CPU, as Gradescope does; ``auto`` leaves CUDA as it is, for the ``[cuda]`` cases.

On a GPU machine a student's grade with CUDA visible took 1.7-2.6 times as long
(bench/results/nvidia-h100-80gb-hbm3/grade_oneoff/): the default matters."""

from __future__ import annotations

import os

import pytest

import course.grading.runner
from course.tools.cli import main


@pytest.fixture
def seen(monkeypatch):
    """What the grading run would see: CUDA_VISIBLE_DEVICES when it starts (None: unset)."""
    # cmd_grade sets the variable in this process: setenv records its value (or absence)
    # so that it is restored after the test; a bare delenv of an unset variable records
    # nothing, and CUDA would stay hidden from every later test of the run.
    monkeypatch.setenv("CUDA_VISIBLE_DEVICES", "0")
    monkeypatch.delenv("CUDA_VISIBLE_DEVICES")
    calls = []

    def grade(impl, **kwargs):
        calls.append(os.environ.get("CUDA_VISIBLE_DEVICES"))
        return {"score": 1.0, "max_score": 1.0}

    monkeypatch.setattr(course.grading.runner, "grade", grade)
    return calls


def test_grade_hides_cuda_by_default(seen):
    assert main(["grade", "--lab", "0"]) == 0
    assert seen == [""], f"CUDA_VISIBLE_DEVICES when grading started: {seen}"


def test_grade_device_auto_leaves_cuda_visible(seen):
    assert main(["grade", "--lab", "0", "--device", "auto"]) == 0
    assert seen == [None], f"CUDA_VISIBLE_DEVICES when grading started: {seen}"


def test_grade_device_must_be_cpu_or_auto(seen, capsys):
    with pytest.raises(SystemExit):
        main(["grade", "--device", "cuda"])
    assert "--device" in capsys.readouterr().err and not seen
