"""The skeletons in ``labs/`` are generated from the marked references in ``solutions/``
(``course.tools.skeletons``): the committed ones are exactly what the references generate,
a hand edit is caught, and the markers mean what the module says."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from course.tools.skeletons import MarkerError, differences, skeleton_source, write

ROOT = Path(__file__).resolve().parents[2]


def test_committed_skeletons_are_generated():
    problems = differences(ROOT / "solutions", ROOT / "labs")
    assert not problems, "\n".join(
        problems + ["run `rtcourse skeletons` after editing a reference"]
    )


def _course_copy(tmp_path) -> Path:
    copy = tmp_path / "course"
    shutil.copytree(
        ROOT / "solutions", copy / "solutions", ignore=shutil.ignore_patterns("__pycache__")
    )
    shutil.copytree(ROOT / "labs", copy / "labs", ignore=shutil.ignore_patterns("__pycache__"))
    (copy / "tests").mkdir()
    (copy / "pyproject.toml").write_text("")
    return copy


def _check(folder: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "course.tools.cli", "skeletons", "--check"],
        cwd=folder,
        capture_output=True,
        text=True,
        timeout=120,
    )


def test_check_names_a_hand_edit(tmp_path):
    copy = _course_copy(tmp_path)
    assert _check(copy).returncode == 0
    # A lab file or a module of a lab package: the first skeleton with a stub.
    skeleton = next(
        p
        for p in sorted((copy / "labs").rglob("*.py"))
        if "raise NotImplementedError" in p.read_text()
    )
    lines = skeleton.read_text().splitlines(keepends=True)
    number = next(i for i, line in enumerate(lines) if "raise NotImplementedError" in line)
    lines[number] = lines[number].replace("raise NotImplementedError", "return None  #")
    skeleton.write_text("".join(lines))
    proc = _check(copy)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    where = skeleton.relative_to(copy).as_posix()
    assert f"{where}:{number + 1}:" in proc.stdout, proc.stdout
    write(copy / "solutions", copy / "labs")  # regenerating repairs it
    assert _check(copy).returncode == 0


def test_check_names_a_stray_and_a_missing_file(tmp_path):
    copy = _course_copy(tmp_path)
    (copy / "labs" / "lab9_extra.py").write_text("x = 1\n")
    removed = sorted((copy / "labs").rglob("*.py"))[0]  # a lab file or a package's module
    removed.unlink()
    out = _check(copy).stdout
    assert "labs/lab9_extra.py: no reference" in out, out
    assert f"{removed.relative_to(copy).as_posix()}: missing" in out, out


REFERENCE = '''"""A lab."""

import math


# BEGIN SOLUTION
def _helper(x):
    return x * 2
# END SOLUTION


def double(x):
    """Twice x."""
    if x is None:
        raise ValueError("x: expected a number")
    # BEGIN SOLUTION (task 1)
    y = _helper(x)
    return y
    # END SOLUTION


class Loop:
    def step(self, i):
        """One step."""
        # BEGIN SOLUTION (task 2)
        return math.sqrt(i)
        # END SOLUTION
'''

SKELETON = '''"""A lab."""

import math


def double(x):
    """Twice x."""
    if x is None:
        raise ValueError("x: expected a number")
    raise NotImplementedError("not implemented yet: double (task 1)")


class Loop:
    def step(self, i):
        """One step."""
        raise NotImplementedError("not implemented yet: Loop.step (task 2)")
'''


def test_regions_become_stubs_or_disappear():
    assert skeleton_source(REFERENCE) == SKELETON


def test_a_file_without_markers_is_copied():
    assert skeleton_source("x = 1\n\n\ny = 2\n") == "x = 1\n\n\ny = 2\n"


@pytest.mark.parametrize(
    ("text", "says"),
    [
        ("# BEGIN SOLUTION\nx = 1\n", "1: BEGIN SOLUTION without an END SOLUTION"),
        ("x = 1\n# END SOLUTION\n", "2: END SOLUTION without a BEGIN SOLUTION"),
        ("# BEGIN SOLUTION\n# BEGIN SOLUTION\n# END SOLUTION\n", "2: BEGIN SOLUTION inside"),
        (
            'def f():\n    # BEGIN SOLUTION ("x")\n    return 1\n    # END SOLUTION\n',
            "may not hold a double quote",
        ),
        ("if True:\n# BEGIN SOLUTION\n    x = 1\n# END SOLUTION\n", "does not parse"),
    ],
)
def test_bad_markers_are_named(text, says):
    with pytest.raises(MarkerError, match=r"lab\.py"):
        skeleton_source(text, "lab.py")
    with pytest.raises(MarkerError) as info:
        skeleton_source(text, "lab.py")
    assert says in str(info.value)


def test_every_stub_names_its_task():
    """What a student runs into first: each stub says which function and which task."""
    for path in sorted((ROOT / "labs").rglob("lab*.py")) + sorted(
        (ROOT / "labs").glob("lab*_*/*.py")
    ):
        for number, line in enumerate(path.read_text().splitlines(), 1):
            if "raise NotImplementedError(" in line:
                assert "(task " in line, f"{path.relative_to(ROOT)}:{number}: {line.strip()}"
