"""What a sandbox worker imports with the grader's rights comes from the grader's paths.

The keeper and every probe run with the grader's rights until a probe drops them, and a
probe imports its test file (and whatever that file imports) before the drop. The worker's
working folder belongs to the submission (with a worker user, it is chowned to it), and
``python -m`` puts the working folder first on ``sys.path``: a ``pytest.py`` the submission
planted there would run with the grader's rights at the next probe. So the folder must be
on no ``sys.path`` of the worker's processes: the keeper's, the submission's server (forked
from it), a probe's; for a fresh worker and one forked from the zygote.
"""

from __future__ import annotations

import os
import sys

import pytest

from course.grading import sandbox, zygote

try:  # a test file's import, as a probe loads it before the drop: found only if planted
    import rtcourse_planted  # noqa: F401
except ImportError:
    pass

LAB = '''
import os
import sys


def paths():
    """This process's working folder and import path."""
    return os.getcwd(), list(sys.path)


def plant(name):
    """A module named like one a test file imports, in the working folder."""
    with open(os.path.join(os.getcwd(), name + ".py"), "w") as f:
        f.write("PLANTED = True\\n")
'''


def probe_paths(lab):
    """A probe: its process's working folder and import path, and whether the module the
    submission planted was imported on the way (by this file's imports, before the drop)."""
    return os.getcwd(), list(sys.path), "rtcourse_planted" in sys.modules


def _clean(cwd: str, path: list[str]) -> bool:
    here = os.path.realpath(cwd)
    return all(os.path.realpath(p or ".") != here for p in path)


@pytest.fixture(params=["fresh", "forked"])
def lab(request, tmp_path, monkeypatch):
    monkeypatch.delenv("RTCOURSE_ZYGOTE", raising=False)
    monkeypatch.setattr(zygote, "_zygote", None)
    monkeypatch.setattr(zygote, "_enabled", False)
    if request.param == "forked":
        if not zygote.supported():
            pytest.skip("the zygote needs Linux pidfds")
        zygote.enable()
    (tmp_path / "lab9_paths.py").write_text(LAB)
    worker = sandbox.Worker(str(tmp_path), memory_bytes=2**30)
    yield sandbox.SandboxedLab("lab9_paths", worker, 60.0)
    worker.stop()
    if zygote._zygote is not None:
        zygote._zygote.close()


def test_the_working_folder_is_on_no_import_path(lab):
    cwd, path = lab.paths()
    assert _clean(cwd, path), (
        f"the submission's process has its working folder {cwd} on sys.path: {path[:4]}"
    )
    lab.plant("rtcourse_planted")
    cwd, path, planted = lab.probe(probe_paths)
    assert _clean(cwd, path) and not planted, (
        f"a probe (grader's rights until it drops them) has its working folder {cwd} on "
        f"sys.path {path[:4]}, or imported the module the submission planted there"
    )
