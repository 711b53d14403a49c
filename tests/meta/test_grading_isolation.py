"""Hostile submissions against the grader.

Each folder under ``hostile/`` holding ``lab9_toy.py`` is a submission of the toy lab 9
(``toycourse/``; lab 8 is the bounds' toy lab, see test_grading_bounds.py):
task 1 (``double``, 1 point) is honest everywhere; task 2 (``norms``, 2 points)
attacks the grader. For every attack the grader must finish, write a valid
results.json, give the attack 0 and the honest task its point (unless the
attack happens at import, which costs the whole module).

Every other submission (in name order) is graded with its worker forked from the
pre-imported zygote (``RTCOURSE_ZYGOTE=1``, as ``rtcourse grade-class`` grades), the rest
with a fresh interpreter (as a one-off ``rtcourse grade``): both ways hold against attacks.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest
import torch

from course.grading import wire

HERE = Path(__file__).parent
HOSTILE = sorted(p.name for p in (HERE / "hostile").iterdir() if (p / "lab9_toy.py").is_file())
FORKED = set(HOSTILE[1::2])  # graded with workers forked from the zygote
AT_IMPORT = {"os_exit_at_import", "sys_exit_at_import", "raise_at_import"}


def _grade(name: str, base: Path) -> dict:
    course = base / name / "course"
    shutil.copytree(HERE / "toycourse", course)
    out = base / name / "out" / "results.json"
    env = dict(
        os.environ,
        RTCOURSE_TIME_LIMIT="8",
        RTCOURSE_MEMORY_GB="1",
        RTCOURSE_TEST_RESULTS=str(out),
        RTCOURSE_TEST_CWD=str(course),
        RTCOURSE_ZYGOTE="1" if name in FORKED else "0",
    )
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "course.tools.cli",
            "grade",
            "--impl",
            str(HERE / "hostile" / name),
            "--lab",
            "9",
            "--json",
            str(out),
        ],
        cwd=course,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    return {"proc": proc, "json": out, "cwd_json": course / "results.json"}


@pytest.fixture(scope="module")
def graded(tmp_path_factory):
    base = tmp_path_factory.mktemp("hostile")
    with ThreadPoolExecutor(max_workers=2) as pool:
        runs = dict(zip(HOSTILE, pool.map(lambda n: _grade(n, base), HOSTILE)))
    return runs


def _task_scores(data: dict) -> dict:
    scores = {}
    for test in data["tests"]:
        task = test["number"]
        score, top = scores.get(task, (0.0, 0.0))
        scores[task] = (score + test["score"], top + test["max_score"])
    return scores


@pytest.mark.parametrize(
    "name", HOSTILE, ids=[f"{n}-{'forked' if n in FORKED else 'fresh'}" for n in HOSTILE]
)
def test_grader_survives_and_scores_honestly(graded, name):
    run = graded[name]
    proc = run["proc"]
    assert run["json"].exists(), f"{name}: no results.json\n{proc.stdout}\n{proc.stderr}"
    data = json.loads(run["json"].read_text())
    for key in ("score", "max_score", "execution_time", "tests"):
        assert key in data, f"{name}: results.json lacks {key!r}"
    for test in data["tests"]:
        assert set(test) >= {
            "name",
            "number",
            "score",
            "max_score",
            "status",
            "output",
            "visibility",
        }, f"{name}: malformed test entry {test}"
    scores = _task_scores(data)
    assert data["max_score"] == pytest.approx(3.0), f"{name}: max_score {data['max_score']}"
    if name == "honest":
        assert data["score"] == pytest.approx(3.0), data["output"]
        return
    assert scores["9.2"][0] == 0, f"{name}: the hostile task scored {scores['9.2']}"
    if name in AT_IMPORT:
        assert data["score"] == 0, f"{name}: {data['output']}"
    else:
        assert scores["9.1"][0] == pytest.approx(1.0), (
            f"{name}: the honest task lost its point\n{data['output']}"
        )


def test_fake_results_are_overwritten(graded):
    run = graded["fake_results"]
    data = json.loads(run["json"].read_text())
    assert data["score"] == pytest.approx(1.0)


def test_failures_explain_themselves(graded):
    outputs = {
        name: " ".join(t["output"] for t in json.loads(run["json"].read_text())["tests"])
        for name, run in graded.items()
    }
    assert "time limit" in outputs["hang_in_task"]
    assert "exit code 0" in outputs["os_exit_in_task"]
    assert "sys.exit(0)" in outputs["sys_exit_in_task"]
    assert "failed to import" in outputs["raise_at_import"]
    assert "memory" in outputs["memory_hog"].lower()
    assert "modified its input argument" in outputs["mutates_input"]


def test_student_output_is_captured_not_mixed(tmp_path):
    course = tmp_path / "course"
    shutil.copytree(HERE / "toycourse", course)
    sub = tmp_path / "sub"
    sub.mkdir()
    (sub / "lab9_toy.py").write_text(
        "import torch\nprint('IMPORT-NOISE')\n"
        "def double(x):\n    print('DOUBLE-NOISE')\n    return 2 * x\n"
        "def norms(x):\n    print('NORMS-NOISE')\n    return x.sum(-1)\n"
    )
    out = tmp_path / "results.json"
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "course.tools.cli",
            "grade",
            "--impl",
            str(sub),
            "--lab",
            "9",
            "--json",
            str(out),
        ],
        cwd=course,
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    for noise in ("IMPORT-NOISE", "DOUBLE-NOISE"):
        assert noise not in proc.stdout + proc.stderr, "student output leaked into the grader's"
    tests = {t["number"]: t for t in json.loads(out.read_text())["tests"]}
    assert "NORMS-NOISE" in tests["9.2"]["output"], "the failing test should show what it printed"


@pytest.mark.parametrize(
    "tensor",
    [
        torch.tensor(0.5).expand(1).contiguous(),  # stride 0 on a size-1 dim
        torch.arange(6.0).reshape(2, 3).T,  # non-contiguous
        torch.tensor(3, dtype=torch.int64),  # 0-d
        torch.ones(2, 2, dtype=torch.bfloat16),  # no numpy dtype
        torch.empty(0, 3),  # empty
    ],
    ids=["stride0", "transposed", "scalar", "bf16", "empty"],
)
def test_tensors_cross_the_wire_unchanged(tensor):
    back = wire.decode(wire.loads_plain(wire.dumps(wire.encode(tensor))))
    assert type(back) is torch.Tensor and back.dtype == tensor.dtype
    assert back.shape == tensor.shape and torch.equal(back, tensor)


def test_expanded_and_strided_arguments_are_checked_bit_for_bit():
    """An expanded argument (stride 0, as a one-ray batch's broadcast t_min) or a strided
    view is compared by its bits without an error, and a change to it is seen."""
    from course.grading.input_check import call_checked

    one = torch.tensor(0.5).expand(1)
    column = torch.rand(3, 4)[:, 1]
    result, changed, error = call_checked(lambda a, b: a + b, (one, column), {})
    assert error is None and changed == [], (error, changed)

    def writes(a):
        a.copy_(torch.full_like(a, -0.0))

    _, changed, error = call_checked(writes, (torch.zeros(3, 4)[:, 2],), {})
    assert error is None and [c.position for c in changed] == [0], "+0.0 -> -0.0 is a change"
