"""A grade no submission can forge, and hidden tests no submission can read.

Submissions written against this (open) grader, graded as the unprivileged worker user the
Gradescope autograder uses, on a private copy of the course:

* ``reply_forger``: writes a made-up "passed" reply onto the pipe a probe reports on and
  exits (Lab 0's view probes, Lab 1's accounting probe);
* ``hidden_reader``: opens the hidden graders (the probe's own file, tests/hidden/) and the
  results path (from the environment and the grader's command line), and prints what it
  read in pieces and reversed.

Each trick must earn exactly what the same submission earns without it, and the honest
reference, copied in as a student's, keeps every point. A worker user that cannot run the
grader's Python stops grading with one line before any score.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

HERE = Path(__file__).parent
ROOT = HERE.parent.parent
COPIED = ("course", "tests", "labs", "solutions", "pyproject.toml")


def _worker_user():
    """``nobody``, where this runs as root and ``nobody`` can run this Python."""
    if os.geteuid() != 0:
        return None
    import pwd

    stdlib = Path(os.__file__).resolve().parent
    if not all(p.stat().st_mode & 0o005 == 0o005 for p in (stdlib, *stdlib.parents)):
        return None
    try:
        return pwd.getpwnam("nobody").pw_name
    except KeyError:
        return None


USER = _worker_user()
NO_USER = "needs root and a user nobody that can run this Python (the autograder's worker)"

# (submission, lab, tasks, the flag that turns its trick off)
RUNS = {
    "forger0": ("reply_forger", 0, (), ("_forge.py", "FORGE")),
    "forger1": ("reply_forger", 1, ("7",), ("_forge.py", "FORGE")),
    **({"reader0": ("hidden_reader", 0, (), ("lab0_interop.py", "READ"))} if USER else {}),
    "reference0": ("reference", 0, (), None),
    "reference1": ("reference", 1, ("7",), None),
}


def _copy_course(base: Path) -> Path:
    course = base / "course"
    for name in COPIED:
        source = ROOT / name
        if source.is_dir():
            shutil.copytree(
                source,
                course / name,
                ignore=shutil.ignore_patterns("meta", "__pycache__", "mutants"),
            )
        else:
            course.mkdir(exist_ok=True)
            shutil.copy(source, course / name)
    return course


def _submission(base: Path, tag: str, name: str, flag, on: bool) -> Path:
    folder = base / "subs" / tag
    if name == "reference":
        shutil.copytree(
            ROOT / "solutions", folder, ignore=shutil.ignore_patterns("__pycache__", "mutants")
        )
    else:
        shutil.copytree(HERE / "hostile" / name, folder)
    if flag and not on:
        path = folder / flag[0]
        path.write_text(path.read_text().replace(f"{flag[1]} = True", f"{flag[1]} = False"))
    return folder


def _grade(base: Path, course: Path, impl: Path, lab: int, tasks, tag: str) -> dict:
    results = base / "results" / tag
    results.mkdir(parents=True)
    results.chmod(0o700)  # as run_autograder leaves it
    out = results / "results.json"
    env = dict(
        os.environ,
        RTCOURSE_RESULTS_DIR=str(results),
        RTCOURSE_TEST_RESULTS=str(out),
        PYTHONPATH=os.pathsep.join([str(course), *filter(None, [os.environ.get("PYTHONPATH")])]),
    )
    if USER:  # the forgers too run as the autograder's worker user, where there is one
        env["RTCOURSE_WORKER_USER"] = USER
    args = [
        sys.executable,
        "-m",
        "course.tools.cli",
        "grade",
        "--impl",
        str(impl),
        "--lab",
        str(lab),
        "--json",
        str(out),
    ]
    for task in tasks:
        args += ["--task", task]
    proc = subprocess.run(
        args, cwd=course, env=env, capture_output=True, text=True, timeout=900, check=False
    )
    assert out.exists(), f"{tag}: no results.json\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}"
    return json.loads(out.read_text())


@pytest.fixture(scope="module")
def graded():
    base = Path(tempfile.mkdtemp(prefix="rtcourse-forgery-"))
    base.chmod(0o755)  # the worker user reads the submissions here
    try:
        course = _copy_course(base)
        jobs = []
        for key, (name, lab, tasks, flag) in RUNS.items():
            for on in (True, False) if flag else (True,):
                tag = f"{key}-{'on' if on else 'off'}"
                jobs.append((tag, _submission(base, tag, name, flag, on), lab, tasks))
        for path in (base / "subs").rglob("*"):
            path.chmod(0o755 if path.is_dir() else 0o644)
        with ThreadPoolExecutor(max_workers=2) as pool:
            data = list(pool.map(lambda j: _grade(base, course, j[1], j[2], j[3], j[0]), jobs))
        yield {tag: d for (tag, *_), d in zip(jobs, data)} | {"course": course}
    finally:
        shutil.rmtree(base, ignore_errors=True)


def _scores(data) -> dict[str, float]:
    return {t["name"]: t["score"] for t in data["tests"]}


def _text(data) -> str:
    return data["output"] + "\n".join(t["output"] for t in data["tests"])


@pytest.mark.parametrize("key", ["forger0", "forger1", "reader0"])
def test_a_trick_earns_what_the_submission_earns_without_it(graded, key):
    if f"{key}-on" not in graded:
        pytest.skip(NO_USER)
    with_trick, without = graded[f"{key}-on"], graded[f"{key}-off"]
    assert _scores(with_trick) == _scores(without), (
        f"{key}: {with_trick['score']} with the trick, {without['score']} without"
    )


def test_forged_replies_are_refused(graded):
    for key in ("forger0", "forger1"):
        data = graded[f"{key}-on"]
        assert data["score"] == 0, f"{key}: {_text(data)[:2000]}"
        assert "did not come from the probe" in _text(data), key


@pytest.mark.skipif(USER is None, reason=NO_USER)
def test_hidden_tests_and_results_are_unreadable(graded):
    data = graded["reader0-on"]
    text = _text(data)
    assert "READ-OK" not in text, text[:3000]
    assert "ENV-SEEN" not in text, "the worker's environment names the results"
    assert "DENIED" in text, "the reader found nothing to try: the test no longer tests"
    hidden = [
        line.strip()
        for path in (graded["course"] / "tests" / "hidden").glob("*.py")
        for line in path.read_text().splitlines()
        if len(line.strip()) >= 24
    ]
    for line in hidden:
        assert line[::-1] not in text and line[: len(line) // 2] not in text.splitlines(), line
    assert data["score"] > 0, "the honest packing should keep its points"


@pytest.mark.parametrize("lab, tasks", [(0, ()), (1, ("7",))])
def test_the_reference_keeps_every_point(graded, lab, tasks):
    data = graded[f"reference{lab}-on"]
    assert data["score"] == pytest.approx(data["max_score"]), _text(data)[:3000]


def _private_python(base: Path) -> Path:
    """This interpreter behind a folder only root may enter (a pyenv under /root)."""
    private = base / "private"
    private.mkdir(mode=0o700)
    venv = Path(sys.prefix)
    (private / "venv").symlink_to(venv, target_is_directory=True)
    return private / "venv" / "bin" / Path(sys.executable).name


def _nobody():
    import pwd

    try:
        return pwd.getpwnam("nobody").pw_name
    except KeyError:
        return None


@pytest.mark.skipif(os.geteuid() != 0 or _nobody() is None, reason="needs root and nobody")
def test_an_unreadable_interpreter_stops_grading_before_a_score(tmp_path):
    if sys.prefix == sys.base_prefix:
        pytest.skip("needs a virtual environment to place behind a private folder")
    tmp_path.chmod(0o755)
    python = _private_python(tmp_path)
    env = dict(os.environ, RTCOURSE_WORKER_USER=_nobody())
    check = subprocess.run(
        [str(python), "-m", "course.grading.sandbox", "check-worker"],
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert check.returncode == 2, check.stdout + check.stderr
    line = check.stderr.strip()
    assert len(line.splitlines()) == 1 and str(python) in line, line
    assert "/usr or /opt" in line and "RTCOURSE_WORKER_USER=" in line, line
    out = tmp_path / "results.json"
    grade = subprocess.run(
        [
            str(python),
            "-m",
            "course.tools.cli",
            "grade",
            "--impl",
            str(ROOT / "solutions"),
            "--lab",
            "0",
            "--json",
            str(out),
        ],
        cwd=ROOT,
        env=dict(env, RTCOURSE_IMPL=""),
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert grade.returncode != 0 and not out.exists(), grade.stdout + grade.stderr
    assert str(python) in grade.stderr, grade.stderr
    if USER:  # this interpreter itself is readable: the check passes
        ok = subprocess.run(
            [sys.executable, "-m", "course.grading.sandbox", "check-worker"],
            env=env,
            capture_output=True,
            text=True,
            timeout=300,
            check=False,
        )
        assert ok.returncode == 0, ok.stderr
