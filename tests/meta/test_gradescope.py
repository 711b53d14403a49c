"""The Gradescope autograder package and the hidden graders.

``rtcourse gradescope`` is built into a temporary folder, unpacked, and its
``run_autograder`` is run the way Gradescope runs it, against a fake submission: Lab 0
submitted correctly (under ``labs/``), Lab 1 broken at import, later labs missing. The
current interpreter stands in for the one ``setup.sh`` would install into.
"""

from __future__ import annotations

import json
import os
import shutil
import stat
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

import pytest

from course.core.files import module_files
from course.grading.catalog import SUBMISSION_MANIFEST, lab_catalog, read_manifest
from course.grading.runner import lab_test_files
from course.tools.gradescope import STUDENT_USER, build_autograder, collect_submission
from course.tools.release import release

ROOT = Path(__file__).resolve().parents[2]
HIDDEN = "tests/hidden/test_lab0_hidden.py"


def _unpack(zip_path: Path, dest: Path) -> Path:
    with zipfile.ZipFile(zip_path) as archive:
        archive.extractall(dest)
    return dest


def _run_autograder(package: Path, submission: Path, results: Path, **env) -> dict:
    env = {
        **os.environ,
        "RTCOURSE_SUBMISSION_DIR": str(submission),
        "RTCOURSE_RESULTS_DIR": str(results),
        "RTCOURSE_PYTHON": sys.executable,
        "RTCOURSE_WORKER_USER": "",
        "RTCOURSE_TIME_LIMIT": "60",
        **env,
    }
    proc = subprocess.run(
        ["bash", str(package / "run_autograder")],
        env=env,
        cwd=package,
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    out = results / "results.json"
    assert out.is_file(), f"no results.json\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}"
    return {"proc": proc, "data": json.loads(out.read_text())}


def _lab_scores(data: dict) -> dict[int, tuple[float, float]]:
    scores: dict[int, tuple[float, float]] = {}
    for test in data["tests"]:
        lab = int(test["number"].split(".")[0])
        score, top = scores.get(lab, (0.0, 0.0))
        scores[lab] = (score + test["score"], top + test["max_score"])
    return scores


@pytest.fixture(scope="module")
def package(tmp_path_factory):
    base = tmp_path_factory.mktemp("gradescope")
    names = build_autograder(ROOT, base / "autograder.zip")
    return {
        "names": names,
        "dir": _unpack(base / "autograder.zip", base / "unpacked"),
        "zip": base / "autograder.zip",
    }


@pytest.fixture(scope="module")
def graded(package, tmp_path_factory):
    base = tmp_path_factory.mktemp("submission")
    submission = base / "submission"
    (submission / "labs").mkdir(parents=True)
    shutil.copytree(ROOT / "solutions" / "lab0_interop", submission / "labs" / "lab0_interop")
    (submission / "lab1_intersect").mkdir()
    (submission / "lab1_intersect" / "moller_trumbore.py").write_text(
        "import torch\n\ndef moller_trumbore(:\n    pass\n"
    )  # a syntax error in one file of the package: all of lab 1 fails to import
    (submission / "notes.txt").write_text("not a lab file")
    return _run_autograder(package["dir"], submission, base / "results")


def test_package_layout(package):
    names = set(package["names"])
    with zipfile.ZipFile(package["zip"]) as archive:
        assert set(archive.namelist()) == names
        modes = {i.filename: i.external_attr >> 16 for i in archive.infolist()}
    for script in ("setup.sh", "run_autograder"):
        assert script in names and modes[script] & stat.S_IXUSR, f"{script}: not executable"
    assert f"rtcourse/{HIDDEN}" in names, "the hidden graders ship in the autograder"
    assert "rtcourse/solutions/lab0_interop/__init__.py" in names, (
        "the references ship for instructors"
    )
    packages = [
        f
        for folder in ("labs", "solutions")
        for p in (ROOT / folder).glob("lab*_*")
        if p.is_dir()
        for f in module_files(p)
    ]
    assert packages and all(
        f"rtcourse/{f.relative_to(ROOT).as_posix()}" in names for f in packages
    ), "a lab kept as a package ships with its files"
    assert "rtcourse/pyproject.toml" in names and "rtcourse/course/tools/cli.py" in names
    assert not any(n.startswith(("rtcourse/tests/meta/", "rtcourse/.git/")) for n in names)


def test_scripts_parse_and_setup_installs_cpu_torch(package):
    for script in ("setup.sh", "run_autograder"):
        proc = subprocess.run(
            ["bash", "-n", str(package["dir"] / script)],
            capture_output=True,
            text=True,
            check=False,
        )
        assert proc.returncode == 0, f"{script}: {proc.stderr}"
    setup = (package["dir"] / "setup.sh").read_text()
    assert 'TORCH_SPEC="${TORCH_SPEC:-torch==2.13.0}"' in setup
    assert "pip install ${TORCH_INDEX:+" in setup and "pip install ./rtcourse" in setup
    assert "useradd" in setup and STUDENT_USER in setup
    run = (package["dir"] / "run_autograder").read_text()
    assert "/autograder/submission" in run and "/autograder/results" in run
    assert (
        'course.tools.cli grade --impl "$WORK"' in run and '--json "$RESULTS/results.json"' in run
    )


def test_results_json_is_gradescope_format(graded):
    data = graded["data"]
    for key in ("score", "max_score", "execution_time", "output", "tests"):
        assert key in data, f"results.json lacks {key!r}"
    for test in data["tests"]:
        assert set(test) >= {
            "name",
            "number",
            "score",
            "max_score",
            "status",
            "output",
            "visibility",
        }, f"malformed test entry {test}"
        assert test["status"] in ("passed", "failed")
        assert test["visibility"] in ("visible", "hidden", "after_due_date", "after_published")


def test_submitted_lab_full_marks_others_zero(graded):
    data, proc = graded["data"], graded["proc"]
    scores = _lab_scores(data)
    labs = lab_catalog(lab_test_files(ROOT))
    assert set(scores) == set(labs), f"graded labs {sorted(scores)}, course has {sorted(labs)}"
    score, top = scores[0]
    assert top == pytest.approx(labs[0].points()) and score == pytest.approx(top), (
        f"lab 0 (submitted correctly): {score}/{top}\n{data['output']}"
    )
    for lab, (score, top) in scores.items():
        if lab != 0:
            assert top > 0 and score == 0, f"lab {lab} (broken or missing) scored {score}/{top}"
    assert data["score"] == pytest.approx(scores[0][0])
    lab1 = [t["output"] for t in data["tests"] if t["number"].startswith("1.")]
    assert all("failed to import" in o and "SyntaxError" in o for o in lab1), lab1[0][:2000]
    assert "lab0_interop/packing.py  found: labs/lab0_interop/packing.py" in proc.stdout
    missing = [t["output"] for t in data["tests"] if int(t["number"].split(".")[0]) > 1]
    assert all("must contain the file" in o for o in missing)
    # Named as handed in, never the autograder's temporary folder.
    assert all(" in the submission: " in o and "'notes.txt'" in o for o in missing), missing[0]
    assert "/tmp" not in data["output"] and not any("/tmp" in t["output"] for t in data["tests"])
    package = ROOT / "labs" / "lab0_interop"  # handed in whole: every file graded as its own
    shown = ", ".join(
        repr(f"labs/lab0_interop/{p.relative_to(package).as_posix()}")
        for p in module_files(package)
    )
    assert f"files graded: lab 0: {shown}" in data["output"]
    assert data["extra_data"]["graded_files"]["lab0_interop"] == shown


def test_hidden_tests_graded_with_their_visibility(graded):
    hidden_files = sorted((ROOT / "tests" / "hidden").glob("test_lab*_*.py"))
    catalog = lab_catalog(hidden_files)
    names = {(lab, t.name) for lab, info in catalog.items() for t in info.tests}
    assert {lab for lab, _ in names} >= {0}, "no hidden graders found"
    visible_catalog = lab_catalog(sorted((ROOT / "tests").glob("test_lab*_*.py")))
    clash = {(lab, t.name) for lab, info in visible_catalog.items() for t in info.tests} & names
    assert not clash, f"hidden tests named like visible ones: {sorted(clash)}"

    def hidden_name(result):
        lab = int(result["number"].split(".")[0])
        return any(lab == n_lab and f": {name}[" in result["name"] + "[" for n_lab, name in names)

    tests = graded["data"]["tests"]
    hidden = [t for t in tests if hidden_name(t)]
    assert {int(t["number"].split(".")[0]) for t in hidden} == {lab for lab, _ in names}, (
        "every lab's hidden graders run in the autograder"
    )
    assert all(t["visibility"] == "after_due_date" for t in hidden)
    lab0 = [t for t in hidden if t["number"].startswith("0.")]
    assert lab0 and all(t["status"] == "passed" for t in lab0), (
        "the submitted Lab 0 passes its hidden tests"
    )
    visible = [t for t in tests if t not in hidden]
    assert visible and all(t["visibility"] == "visible" for t in visible)


def test_release_leaves_hidden_tests_out(tmp_path):
    written = release(ROOT, tmp_path / "handout")
    assert not (tmp_path / "handout" / "tests" / "hidden").exists()
    assert not any(p.as_posix().startswith("tests/hidden") for p in written)
    assert (ROOT / HIDDEN).is_file()


def test_collect_submission_takes_lab_files_only(tmp_path):
    sub = tmp_path / "sub"
    (sub / "deep" / "labs").mkdir(parents=True)
    (sub / "labs").mkdir()
    (sub / "labs" / "lab0_interop.py").write_text("A = 1\n")
    (sub / "deep" / "labs" / "lab0_interop.py").write_text("A = 2\n")
    (sub / "lab1_intersect.py").symlink_to(ROOT / "solutions" / "lab1_intersect.py")
    (sub / "helper.py").write_text("")
    found = collect_submission(sub, tmp_path / "work", ["lab0_interop", "lab1_intersect"])
    assert found == {"lab0_interop.py": Path("labs/lab0_interop.py"), "lab1_intersect.py": None}
    assert (tmp_path / "work" / "lab0_interop.py").read_text() == "A = 1\n"
    assert sorted(p.name for p in (tmp_path / "work").iterdir()) == [
        SUBMISSION_MANIFEST,
        "lab0_interop.py",
    ]
    # What the grader's messages name: the files as handed in, and all of them.
    assert read_manifest(tmp_path / "work") == {
        "files": {"lab0_interop.py": "labs/lab0_interop.py", "lab1_intersect.py": None},
        "handed_in": [
            "deep/labs/lab0_interop.py",
            "helper.py",
            "lab1_intersect.py",
            "labs/lab0_interop.py",
        ],
    }


def _skeleton_package(tmp_path) -> Path:
    labs = tmp_path / "labs"
    (labs / "lab9_toy").mkdir(parents=True)
    for name in ("__init__.py", "grid.py", "walk.py"):
        (labs / "lab9_toy" / name).write_text(f"# skeleton {name}\n")
    return labs


def test_collect_lays_package_files_over_the_skeleton(tmp_path):
    labs = _skeleton_package(tmp_path)
    sub = tmp_path / "sub"
    (sub / "handout" / "labs" / "lab9_toy").mkdir(parents=True)
    (sub / "handout" / "labs" / "lab9_toy" / "grid.py").write_text("GRID = 1\n")
    (sub / "grid.py").write_text("LOOSE = 1\n")  # a package folder in the upload wins
    found = collect_submission(sub, tmp_path / "work", ["lab9_toy"], labs)
    assert found == {
        "lab9_toy/__init__.py": None,
        "lab9_toy/grid.py": Path("handout/labs/lab9_toy/grid.py"),
        "lab9_toy/walk.py": None,
    }
    work = tmp_path / "work" / "lab9_toy"
    assert (work / "grid.py").read_text() == "GRID = 1\n"
    assert (work / "walk.py").read_text() == "# skeleton walk.py\n", "left out: the skeleton's"
    assert (work / "__init__.py").read_text() == "# skeleton __init__.py\n"


def test_collect_takes_loose_package_files_by_name(tmp_path):
    labs = _skeleton_package(tmp_path)
    sub = tmp_path / "sub"
    sub.mkdir()
    (sub / "walk (1).py").write_text("WALK = 1\n")  # an upload's near miss
    (sub / "__init__.py").write_text("OTHER = 1\n")  # loose: not taken
    found = collect_submission(sub, tmp_path / "work", ["lab9_toy"], labs)
    assert found["lab9_toy/walk.py"] == Path("walk (1).py")
    assert found["lab9_toy/__init__.py"] is None
    assert (tmp_path / "work" / "lab9_toy" / "walk.py").read_text() == "WALK = 1\n"
    # None of its files handed in: the lab is missing, as a single-file lab is.
    empty = tmp_path / "empty"
    empty.mkdir()
    assert set(collect_submission(empty, tmp_path / "none", ["lab9_toy"], labs).values()) == {None}
    assert not (tmp_path / "none" / "lab9_toy").exists()


def _can_run_as(user: str) -> bool:
    if os.geteuid() != 0:
        return False
    try:
        import pwd

        entry = pwd.getpwnam(user)
        return (
            subprocess.run(
                [sys.executable, "-c", "import torch"],
                user=entry.pw_uid,
                group=entry.pw_gid,
                extra_groups=[],
                capture_output=True,
                timeout=120,
                check=False,
            ).returncode
            == 0
        )
    except (KeyError, OSError, subprocess.SubprocessError):
        return False


CHEAT = """
from pathlib import Path

import course
from course.core.files import import_file

_ref = import_file(Path(course.__file__).resolve().parents[1] / "solutions" / "lab0_interop",
                   "stolen")
globals().update({k: v for k, v in vars(_ref).items() if not k.startswith("__")})
"""


@pytest.mark.skipif(
    not _can_run_as("nobody"), reason="needs root and an interpreter the user 'nobody' can run"
)
def test_submission_cannot_read_the_references(package):
    # The worker user must reach the package and the submission: a world-readable copy.
    base = Path(tempfile.mkdtemp(prefix="rtcourse-gradescope-"))
    try:
        base.chmod(0o755)
        copy = _unpack(package["zip"], base / "package")
        for path in [copy, *copy.rglob("*")]:
            path.chmod(0o755 if path.is_dir() else 0o644)
        sub = base / "submission"
        sub.mkdir()
        (sub / "lab0_interop.py").write_text(CHEAT)
        run = _run_autograder(copy, sub, base / "results", RTCOURSE_WORKER_USER="nobody")
        score, top = _lab_scores(run["data"])[0]
        assert top > 0 and score == 0, f"a submission re-exporting the reference scored {score}"
        assert "Permission denied" in run["data"]["tests"][0]["output"]
    finally:
        shutil.rmtree(base)
