"""``rtcourse bench`` in the student handout: your point on the plot, on the CPU.

A handout is released with the references' rows (``bench/reference/labN.csv``, what
``rtcourse release`` ships), and for every lab:

* on the untouched skeleton, ``rtcourse bench --lab N --quick`` stops with one line naming
  the first unwritten task (exit status 1, no traceback);
* with the reference copied into ``labs/`` as the student's finished code it writes the
  CSV and the PNG: every knob row of the reference has its twin, times are finite, and
  the errors are the reference's (the same code on the same scenes);
* a shipped mutant (a typical mistake) shows as wrong in its CSV: at some setting its
  error is well above the reference's.
"""

from __future__ import annotations

import math
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from course.core.files import copy_module, defining_file, lab_source, relative_name
from course.grading.mutants import apply_mutant, load_mutants
from course.measure.bench import read_rows_csv
from course.tools.release import release
from course.tools.trade import LABS, REFERENCE_DIR, trade_module

ROOT = Path(__file__).resolve().parents[2]
# A mistake per lab that the lab's bench scenes see (its error column shows it).
MUTANTS = {
    0: "loop_drops_last_frame",
    1: "mt_no_u_plus_v",
    2: "grid_first_hit_ends_walk",
    3: "point_light_without_falloff",
    4: "march_transmittance_first",
    5: "linear_slicing",
    6: "viewport_y_not_flipped",
}


@pytest.fixture(scope="module")
def handout(tmp_path_factory):
    out = tmp_path_factory.mktemp("handout")
    release(ROOT, out, reference_rows=True, log=lambda *_: None)
    return out


def _bench(handout: Path, number: int, out: Path, *extra: str) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k != "RTCOURSE_IMPL"}
    env.update(RTCOURSE_PROGRESS="0", OMP_NUM_THREADS="1")
    return subprocess.run(
        [
            sys.executable,
            "-m",
            "course.tools.cli",
            "bench",
            "--lab",
            str(number),
            "--quick",
            "--device",
            "cpu",
            "--out",
            str(out),
            *extra,
        ],
        cwd=handout,
        env=env,
        capture_output=True,
        text=True,
        timeout=240,
        check=False,
    )


def _rows(out: Path, number: int) -> tuple[list[dict], list[dict]]:
    rows = read_rows_csv(out / f"lab{number}.csv")
    return (
        [r for r in rows if r["impl"] == "yours"],
        [r for r in rows if r["impl"] == "reference"],
    )


def test_the_handout_ships_reference_rows_and_no_solutions(handout):
    assert not (handout / "solutions").exists()
    for number in LABS:
        rows = read_rows_csv(handout / REFERENCE_DIR / f"lab{number}.csv")
        assert rows and all(
            r["impl"] == "reference" and r["calibration_s"] > 0 and math.isfinite(r["seconds"])
            for r in rows
        ), rows[:1]


@pytest.mark.parametrize("number", LABS)
def test_skeleton_stops_then_finished_lab_matches_the_reference(handout, tmp_path, number):
    module = trade_module(number).MODULE
    proc = _bench(handout, number, tmp_path / "skeleton")
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 1, proc.stdout[-2000:] + proc.stderr[-3000:]
    assert len(lines) == 1 and "not implemented yet: " in lines[0] and "(task " in lines[0], (
        proc.stderr[-3000:]
    )
    assert "Traceback" not in proc.stderr

    student = lab_source(handout / "labs", module)
    shutil.rmtree(student) if student.is_dir() else student.unlink()
    copy_module(lab_source(ROOT / "solutions", module), handout / "labs")
    out = tmp_path / "finished"
    proc = _bench(handout, number, out)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    assert (out / f"lab{number}.png").stat().st_size > 0
    assert "shipped" in proc.stdout and "ratio" in proc.stdout, proc.stdout[-2000:]
    yours, reference = _rows(out, number)
    assert reference and {r["setting"] for r in yours} == {r["setting"] for r in reference}
    twins = {r["setting"]: r for r in reference}
    for row in yours:
        assert math.isfinite(row["seconds"]) and row["seconds"] > 0, row
        assert "shipped" in twins[row["setting"]]["seconds_source"]
        want = twins[row["setting"]]["error"]
        assert math.isfinite(row["error"]) and abs(row["error"] - want) <= 1e-6 + 0.05 * want, (
            row["setting"],
            row["error"],
            want,
        )


@pytest.mark.parametrize("number", LABS)
def test_a_mutant_shows_as_wrong(handout, tmp_path, number):
    mutant = next(m for m in load_mutants(ROOT) if m.name == MUTANTS[number])
    solution = lab_source(ROOT / "solutions", mutant.module)
    path = defining_file(solution, mutant.function)
    copy_module(
        solution,
        tmp_path / "mutant",
        {relative_name(solution, path): apply_mutant(mutant, path.read_text())},
    )
    out = tmp_path / "out"
    proc = _bench(handout, number, out, "--impl", str(tmp_path / "mutant"))
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    yours, reference = _rows(out, number)
    twins = {r["setting"]: r["error"] for r in reference}
    worse = [
        r["setting"] for r in yours if not r["error"] <= 2 * twins[r["setting"]] + 1e-3
    ]  # NaN (a crash) counts
    assert worse, f"mutant {mutant.name}: no row's error above the reference's: " + ", ".join(
        f"{r['setting']} {r['error']:.3g}" for r in yours
    )
