"""A test of one property (writes in place, returns ``out``) credits a submission only when
the values are right too: a submission that zeroes what it is given earns nothing there."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

ZEROING = """

def render_rotating_triangle(frame_index, out, period=120):
    out.zero_()  # in place, returned, every pixel written: and all of them wrong
    return out
"""


def test_zeroing_in_place_earns_no_in_place_point(tmp_path):
    submission = tmp_path / "submission"
    shutil.copytree(ROOT / "solutions" / "lab0_interop", submission / "lab0_interop")
    task4 = submission / "lab0_interop" / "frame_loop.py"  # the package's task-4 module
    task4.write_text(task4.read_text() + ZEROING)
    out = tmp_path / "results.json"
    subprocess.run(
        [
            sys.executable,
            "-m",
            "course.tools.cli",
            "grade",
            "--impl",
            str(submission),
            "--lab",
            "0",
            "-k",
            "render_rotating_triangle_writes_in_place",
            "--json",
            str(out),
        ],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
    )
    tests = json.loads(out.read_text())["tests"]
    assert tests, "the in-place test did not run"
    for test in tests:
        assert test["score"] == 0, f"{test['name']} credited a zeroed frame: {test['output']}"
        assert "render_rotating_triangle(2, out): the frame in out" in test["output"], test[
            "output"
        ]
