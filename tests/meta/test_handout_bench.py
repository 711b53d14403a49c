"""The benches in the student handout: they run there, on the student's own labs/.

The handout has no solutions/, so a bench script that imported the references would fail
for every student. Here a handout is released, a lab's reference is copied into its labs/ as
the student's finished code, and that lab's bench runs from the handout folder in its quick
mode on the CPU: it must measure the copy in labs/ and write rows with finite times and
errors. Every bench script must at least answer ``--help`` there.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from course.core.files import lab_source
from course.tools.release import release

ROOT = Path(__file__).resolve().parents[2]
SCRIPTS = sorted(p.name for p in (ROOT / "bench").glob("*.py"))


@pytest.fixture(scope="module")
def handout(tmp_path_factory):
    out = tmp_path_factory.mktemp("handout")
    release(ROOT, out)
    return out


def _run(handout: Path, *args: str, timeout: int = 300) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k != "RTCOURSE_IMPL"}  # the default
    return subprocess.run(
        [sys.executable, *args],
        cwd=handout,
        env=env,
        capture_output=True,
        text=True,
        timeout=timeout,
        check=False,
    )


def test_the_handout_has_the_benches_and_no_solutions(handout):
    assert not (handout / "solutions").exists()
    assert sorted(p.name for p in (handout / "bench").glob("*.py")) == SCRIPTS


# Every script's --help in one interpreter (torch imported once): each runs as __main__ from
# the handout's folder, as `python bench/X.py --help` does, and exits 0 after its usage.
HELP_ALL = """
import contextlib, io, runpy, sys
failed = []
for script in sys.argv[1:]:
    sys.argv = [script, "--help"]
    out = io.StringIO()
    try:
        with contextlib.redirect_stdout(out):
            runpy.run_path(script, run_name="__main__")
        code = 0
    except SystemExit as stop:
        code = stop.code or 0
    if code != 0 or "usage:" not in out.getvalue():
        failed.append(f"{script}: exit {code}: {out.getvalue()[-500:]}")
print("\\n".join(failed) or "all answered")
"""


def test_every_bench_answers_help_in_the_handout(handout):
    proc = _run(handout, "-c", HELP_ALL, *(f"bench/{s}" for s in SCRIPTS), timeout=300)
    assert proc.returncode == 0 and proc.stdout.strip().endswith("all answered"), (
        proc.stdout[-3000:] + proc.stderr[-3000:]
    )


def test_lab3_bench_measures_the_students_code(handout, tmp_path):
    student = lab_source(handout / "labs", "lab3_wavefront")  # a file or a package
    reference = lab_source(ROOT / "solutions", "lab3_wavefront")
    if student.is_dir():  # a finished lab: the reference's files over the skeleton's
        shutil.rmtree(student)
        shutil.copytree(reference, student, ignore=shutil.ignore_patterns("__pycache__"))
    else:
        shutil.copy(reference, student)
    out = tmp_path / "results"
    proc = _run(handout, "bench/lab3_wavefront.py", "--device", "cpu", "--quick", "--out", str(out))
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    data = json.loads((out / "lab3_wavefront.json").read_text())
    loaded = Path(data["metadata"]["lab_file"]).resolve()
    assert loaded in (student.resolve(), (student / "__init__.py").resolve()), loaded
    renders = [r for r in data["rows"] if r["kind"] != "layout"]
    layouts = [r for r in data["rows"] if r["kind"] == "layout"]
    assert {r["organisation"] for r in renders} >= {"wavefront", "uber (eager)"}
    assert len(layouts) == 3, [r["organisation"] for r in data["rows"]]
    for row in renders:
        assert row["seconds"] > 0 and math.isfinite(row["seconds"]), row
        assert math.isfinite(row["max_rel_error"]) and row["max_rel_error"] < 1e-3, row
        assert row["flipped"] == 0.0, row
    for row in layouts:
        assert row["seconds"] > 0 and math.isfinite(row["seconds"]), row
        assert row["same_hit"] == 1.0, row
