"""The course without Triton (macOS, native Windows: no wheels there). ``import course``
never imports Triton; with Triton hidden, every course module still imports, a fused
kernel says what it needs, and every Triton test passes or skips with a one-line reason.

Triton is hidden from a subprocess by a path finder that does not see it, so that
``import triton`` and ``importlib.util.find_spec("triton")`` behave as on a machine
without it.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
TRITON_TESTS = sorted(
    str(p.relative_to(ROOT))
    for pattern in ("tests/test_triton_*.py", "tests/meta/test_triton_*.py")
    for p in ROOT.glob(pattern)
)

HIDE_TRITON = """\
import sys
from importlib.machinery import PathFinder

class _NoTriton(PathFinder):
    @classmethod
    def find_spec(cls, name, path=None, target=None):
        if name == "triton" or name.startswith("triton."):
            return None
        return PathFinder.find_spec(name, path, target)

sys.meta_path = [_NoTriton if f is PathFinder else f for f in sys.meta_path]
"""

IMPORT_ALL = """\
import importlib, json, pkgutil, sys
import course
modules = [m.name for m in pkgutil.walk_packages(course.__path__, "course.")]
imported_triton = []
for name in modules:
    if not name.startswith("course.kernels.triton_"):
        importlib.import_module(name)
        if "triton" in sys.modules and not imported_triton:
            imported_triton.append(name)
for name in modules:
    importlib.import_module(name)
message = None
try:
    import course.kernels.triton_intersect as ti
    ti.interpreting()
except ImportError as exc:
    message = str(exc)
print(json.dumps({"modules": modules, "imported_triton": imported_triton,
                  "message": message}))
"""

RUN_TESTS = """\
import json, sys
import pytest

class Outcomes:
    def __init__(self):
        self.rows = []

    def pytest_runtest_logreport(self, report):
        if report.when == "call" or report.outcome != "passed":
            reason = report.longrepr[2] if report.skipped else None
            self.rows.append((report.nodeid, report.when, report.outcome, reason))

outcomes = Outcomes()
code = pytest.main(["-q", "-p", "no:cacheprovider", *sys.argv[1:]], plugins=[outcomes])
print("OUTCOMES " + json.dumps({"code": int(code), "rows": outcomes.rows}))
"""


def _run(script: str, *args, hide=True, timeout=300) -> str:
    proc = subprocess.run(
        [sys.executable, "-c", (HIDE_TRITON if hide else "") + script, *args],
        check=False,
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=timeout,
    )
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    return proc.stdout


def test_import_course_does_not_import_triton():
    data = json.loads(_run(IMPORT_ALL, hide=False).splitlines()[-1])
    assert not data["imported_triton"], (
        f"importing {data['imported_triton'][0]} imported triton: only course.kernels.triton_* may"
    )


def test_course_modules_import_without_triton():
    data = json.loads(_run(IMPORT_ALL).splitlines()[-1])
    assert "course.kernels.triton_intersect" in data["modules"]
    assert data["message"] and "triton" in data["message"], (
        f"a fused kernel without Triton should raise an ImportError naming it, got "
        f"{data['message']!r}"
    )


def test_triton_tests_skip_with_a_reason_without_triton():
    assert TRITON_TESTS, "no Triton test files found"
    out = _run(RUN_TESTS, *TRITON_TESTS)
    data = json.loads(out.split("OUTCOMES ", 1)[1])
    failed = [row for row in data["rows"] if row[2] == "failed"]
    assert not failed and data["code"] == 0, (
        f"without Triton these failed: {[row[0] for row in failed]}\n{out[-3000:]}"
    )
    skipped = [row for row in data["rows"] if row[2] == "skipped"]
    for nodeid, _, _, reason in skipped:
        assert reason and "\n" not in reason.strip(), f"{nodeid}: skip reason {reason!r}"
    assert any("triton" in reason.lower() for *_, reason in skipped), (
        "no test skipped for want of Triton: are the Triton tests still guarded?"
    )
