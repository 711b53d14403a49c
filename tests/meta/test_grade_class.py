"""``rtcourse grade-class``: a class of mixed layouts graded to the right scores, killed
midway and resumed with no row lost or repeated, the submissions left untouched.

Lab 4's task 1 keeps it short: ten students, each graded in a sandbox as ``rtcourse grade
--impl`` does, in two warm workers.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import signal
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import pytest

from course.core.files import defining_file, lab_source, module_files, relative_name
from course.grading.catalog import lab_catalog
from course.grading.classroom_layouts import describe, find_submissions
from course.grading.classroom_report import read_gradebook
from course.grading.mutants import apply_mutant, load_mutants
from course.grading.runner import lab_test_files

ROOT = Path(__file__).resolve().parents[2]
LAB, MODULE, TASK = 4, "lab4_march", "1"
# task 1's points, visible and hidden tests alike, as the graders declare them
FULL = sum(
    t.points for t in lab_catalog(lab_test_files(ROOT, [LAB]))[LAB].tests if str(t.task) == TASK
)
MUTANT = "march_back_to_front"  # loses points in task 1

GRADESCOPE_METADATA = """\
submission_111:
  :submitters:
  - :name: Gina Gold
    :sid: '111'
    :email: gina@example.edu
  :created_at: 2026-03-01 12:00:00.000000000 -08:00
  :score: 0.0
submission_222:
  :submitters:
  - :name: Hugo Hall
    :sid: '222'
    :email: hugo@example.edu
"""


def _lab_files(kind: str) -> dict[str, str]:
    """The lab's files as a student of ``kind`` hands them in: name as ``copy_module`` keys
    it (``lab4_march.py``, or ``lab4_march/grid.py`` for a lab kept as a package) -> text."""
    solution = lab_source(ROOT / "solutions", MODULE)
    source = solution if kind != "skeleton" else lab_source(ROOT / "labs", MODULE)
    files = {relative_name(source, f): f.read_text() for f in module_files(source)}
    if kind == "mutant":
        mutant = next(m for m in load_mutants(ROOT) if m.name == MUTANT)
        path = defining_file(solution, mutant.function)
        files[relative_name(solution, path)] = apply_mutant(mutant, path.read_text())
    if kind == "crash":
        entry = next(iter(files))  # the module, or its package's __init__.py
        files[entry] += "\nraise RuntimeError('broken at import')\n"
    return files


def _class(folder: Path) -> dict[str, str]:
    """Ten students over every layout; student -> what they handed in."""

    def write(path: Path, text: str):
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)

    def hand_in(dest: Path, kind: str, under: str = ""):
        for name, text in _lab_files(kind).items():
            write(dest / under / name, text)

    hand_in(folder / "alice", "reference")
    hand_in(folder / "bob", "skeleton", "labs")
    hand_in(folder / "gus", "crash")
    write(folder / "hal" / "README.txt", "I forgot the lab file\n")
    for name, kind in (("carol", "reference"), ("dave", "mutant")):
        with zipfile.ZipFile(folder / f"{name}.zip", "w") as archive:
            for file, text in _lab_files(kind).items():
                archive.writestr(f"handout/labs/{file}", text)
    export = folder / "gradescope_export"
    write(export / "submission_metadata.yml", GRADESCOPE_METADATA)
    hand_in(export / "submission_111", "reference")
    hand_in(export / "submission_222", "skeleton")
    # An LMS hands in loose files: a lab kept as a package is laid over the skeleton.
    for prefix, kind in (
        ("evansmith_LATE_20001_30001_", "mutant"),
        ("Fay Lee_20002_assignsubmission_file_", "reference"),
    ):
        for file, text in _lab_files(kind).items():
            if not file.endswith("__init__.py"):
                write(folder / f"{prefix}{Path(file).name}", text)
    return {
        "alice": "reference",
        "bob": "skeleton",
        "gus": "crash",
        "hal": "missing",
        "carol": "reference",
        "dave": "mutant",
        "Gina Gold": "reference",
        "Hugo Hall": "skeleton",
        "evansmith": "mutant",
        "Fay Lee": "reference",
    }


def _hashes(folder: Path) -> dict[str, str]:
    return {
        p.relative_to(folder).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(folder.rglob("*"))
        if p.is_file()
    }


def test_layouts_are_detected(tmp_path):
    expected = _class(tmp_path)
    subs, ignored = find_submissions(tmp_path)
    assert sorted(s.student for s in subs) == sorted(expected)
    assert ignored == []
    assert describe(subs) == (
        "folders: 4, zips: 2, Gradescope export: 2, Canvas files: 1, Moodle files: 1"
    )
    gina = next(s for s in subs if s.student == "Gina Gold")
    assert gina.sid == "111" and gina.kind == "gradescope"


def _command(class_folder, out):
    return [
        sys.executable,
        "-m",
        "course.tools.cli",
        "grade-class",
        str(class_folder),
        "--lab",
        str(LAB),
        "--task",
        TASK,
        "--out",
        str(out),
        "--jobs",
        "2",
    ]


def _snapshot(dest: Path) -> Path:
    """A copy of the course to grade with: the graders cannot change between the runs
    (a changed grader would rightly regrade every student) while the tree is edited."""
    skip = shutil.ignore_patterns("__pycache__", "*.pyc")
    for name in ("course", "tests", "labs", "solutions"):
        shutil.copytree(ROOT / name, dest / name, ignore=skip)
    shutil.copy(ROOT / "pyproject.toml", dest / "pyproject.toml")
    return dest


def test_grade_class_killed_and_resumed(tmp_path):
    class_folder, out = tmp_path / "class", tmp_path / "grades"
    expected = _class(class_folder)
    before = _hashes(class_folder)
    root = _snapshot(tmp_path / "course")
    env = dict(os.environ, RTCOURSE_PROGRESS="0", PYTHONPATH=str(root))

    # A killed machine: the whole process tree goes at once, after the first rows.
    proc = subprocess.Popen(
        _command(class_folder, out),
        cwd=root,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        start_new_session=True,
    )
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and proc.poll() is None:
        if len(list((out / "students").glob("*.json"))) >= 2:
            break
        time.sleep(0.2)
    if proc.poll() is None:
        os.killpg(proc.pid, signal.SIGKILL)
    first_output = proc.communicate()[0].decode(errors="replace")
    finished = {p.name: p.stat().st_mtime_ns for p in (out / "students").glob("*.json")}
    assert finished, first_output
    assert not (out / "gradebook.csv").exists() or len(finished) == len(expected)

    run = subprocess.run(
        _command(class_folder, out), cwd=root, env=env, capture_output=True, text=True, timeout=240
    )
    assert run.returncode == 0, run.stdout + run.stderr
    if len(finished) < len(expected):
        assert f"kept {len(finished)} students" in run.stdout, run.stdout
    for name, mtime in finished.items():  # kept, not graded again
        assert (out / "students" / name).stat().st_mtime_ns == mtime

    rows = read_gradebook(out / "gradebook.csv")
    assert sorted(r["student"] for r in rows) == sorted(expected)  # none lost, none twice
    by = {r["student"]: r for r in rows}
    for student, kind in expected.items():
        row = by[student]
        score = float(row["score"])
        assert float(row["max"]) == FULL, row
        assert float(row[f"{LAB}.{TASK}"]) == score, row
        if kind == "reference":
            assert score == FULL and row["status"] == "graded", row
        elif kind == "mutant":
            assert 0 <= score < FULL and row["status"] == "graded", row
        else:
            assert score == 0, row
            assert (
                row["status"]
                == {"skeleton": "graded", "crash": "import failed", "missing": "missing"}[kind]
            ), row
    assert by["Gina Gold"]["sid"] == "111"
    assert len(list((out / "feedback").glob("*.txt"))) == len(expected)
    assert "broken at import" in (out / "summary.txt").read_text()
    assert _hashes(class_folder) == before  # the submissions were only read

    # A third run grades nothing: every row is kept, with the same scores.
    again = subprocess.run(
        _command(class_folder, out), cwd=root, env=env, capture_output=True, text=True, timeout=120
    )
    assert again.returncode == 0, again.stdout + again.stderr
    assert f"kept {len(expected)} students" in again.stdout
    assert read_gradebook(out / "gradebook.csv") == rows


@pytest.mark.parametrize("name", ["../evil.py", "/abs/lab4_march.py", ".hidden/x.py"])
def test_zip_members_never_leave_the_scratch_folder(tmp_path, name):
    from course.grading.classroom import extract_zip

    archive = tmp_path / "s.zip"
    with zipfile.ZipFile(archive, "w") as z:
        z.writestr(name, "x = 1\n")
        z.writestr(f"ok/{MODULE}.py", "x = 2\n")
    dest = tmp_path / "dest"
    extract_zip(archive, dest)
    written = {p.relative_to(dest).as_posix() for p in dest.rglob("*.py")}
    assert f"ok/{MODULE}.py" in written and ".hidden/x.py" not in written
    outside = [p for p in tmp_path.rglob("*.py") if dest not in p.parents]
    assert outside == []  # an absolute name lands inside dest, "../" is skipped
