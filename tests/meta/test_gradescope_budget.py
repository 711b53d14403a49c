"""The Gradescope budget: the settings ``rtcourse gradescope`` prints follow the recorded
measurements (bench/results/cpu-2cores/grading_cost.json), every lab over Gradescope's
768 MB / half-CPU defaults is told what to set, and ``run_autograder`` sizes torch's
threads to the container's CPU quota."""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import pytest

from course.grading import budget
from course.grading.budget import (
    DEFAULT_MEMORY_MB,
    lab_settings,
    setting_for,
    settings_text,
)
from course.grading.catalog import lab_catalog
from course.grading.runner import lab_test_files
from course.tools.gradescope import RUN_AUTOGRADER, _script

ROOT = Path(__file__).resolve().parents[2]
RECORD = ROOT / "bench" / "results" / "cpu-2cores" / "grading_cost.json"


def test_every_lab_is_measured_and_the_numbers_are_the_recorded_ones():
    rows = {row["lab"]: row for row in json.loads(RECORD.read_text())["rows"]}
    labs = set(lab_catalog(lab_test_files(ROOT)))
    assert labs <= set(rows), f"labs without a recorded grading cost: {sorted(labs - set(rows))}"
    assert set(budget.MEASURED) == set(rows), "course/grading/budget.py and the record differ"
    for lab, (peak, cpu) in budget.MEASURED.items():
        row = rows[lab]
        assert row["score"] == row["max_score"] > 0, f"lab {lab}: the reference lost points"
        assert peak == pytest.approx(row["peak_pss_mb"], abs=0.5), f"lab {lab}: peak memory"
        assert cpu == pytest.approx(row["cpu_seconds"], abs=0.5), f"lab {lab}: CPU seconds"


def test_settings_have_headroom_and_defaults_where_they_suffice():
    small = setting_for(0, peak_mb=400, cpu_seconds=60)
    assert (small.memory_mb, small.cpus, small.timeout_minutes) == (768, 0.5, 10)
    assert small.is_default
    big = setting_for(1, peak_mb=1000, cpu_seconds=60)
    assert big.memory_mb >= 1000 * budget.MEMORY_HEADROOM and big.memory_mb % 256 == 0
    assert not big.is_default
    slow = setting_for(2, peak_mb=400, cpu_seconds=600)  # 15 min at one CPU with headroom
    assert slow.cpus == 1.0 and slow.timeout_minutes == 15
    for row in lab_settings():
        assert row.memory_mb >= min(row.peak_mb * budget.MEMORY_HEADROOM, DEFAULT_MEMORY_MB)
        minutes_at_setting = row.cpu_seconds / min(row.cpus, 1.0) / 60
        assert minutes_at_setting <= row.timeout_minutes


def _table(text: str) -> dict[str, str]:
    """The printed table's rows by their first column (a lab number, or "all")."""
    rows = {}
    for line in text.splitlines():
        words = line.split()
        if words and (words[0].isdigit() or words[0] == "all"):
            rows[words[0]] = line
    return rows


def test_printed_settings_name_every_lab_over_the_defaults():
    rows = _table(settings_text())
    for row in lab_settings():
        line = rows[str(row.lab)]
        memory_column = line.split("MB", 1)[1]  # after the measured peak
        assert f"{row.memory_mb} MB" in memory_column and f"{row.timeout_minutes} min" in line
        if row.memory_mb > DEFAULT_MEMORY_MB:
            assert f"{row.memory_mb} MB (default)" not in line, line
    assert "all" in rows  # the autograder of every lab at once
    one = _table(settings_text([6]))
    assert set(one) == {"6"}, one


def test_readme_states_the_settings_of_every_lab_over_the_defaults():
    readme = (ROOT / "README.md").read_text()
    for row in lab_settings():
        if not row.is_default:
            assert f"| {row.lab} |" in readme and f"{row.memory_mb} MB" in readme, (
                f"README.md should state lab {row.lab}'s Gradescope settings"
            )


@pytest.mark.parametrize(
    ("cpu_max", "affinity", "want"),
    [
        ("50000 100000", None, "1"),  # Gradescope's half CPU
        ("200000 100000", None, "2"),
        ("max 100000", None, None),  # no quota: the CPUs this process may use
        ("max 100000", "0", "1"),
    ],
)
def test_run_autograder_sizes_threads_to_the_cpu_quota(tmp_path, cpu_max, affinity, want):
    script = _script(RUN_AUTOGRADER, [0])
    start = script.index('CPUS="$(nproc')
    part = script[start : script.index("\n", script.index("MALLOC_MMAP_THRESHOLD_="))]
    fake = tmp_path / "cpu.max"
    fake.write_text(cpu_max + "\n")
    part = part.replace("/sys/fs/cgroup/cpu.max", str(fake))
    probe = tmp_path / "probe.sh"
    probe.write_text(
        part + '\necho "$OMP_NUM_THREADS $MKL_NUM_THREADS $MALLOC_ARENA_MAX '
        '$MALLOC_MMAP_THRESHOLD_"\n'
    )
    cmd = ["bash", str(probe)]
    if affinity is not None:
        cmd = ["taskset", "-c", affinity, *cmd]
    env = {
        k: v
        for k, v in os.environ.items()
        if k
        not in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "MALLOC_ARENA_MAX", "MALLOC_MMAP_THRESHOLD_")
    }
    out = subprocess.run(cmd, capture_output=True, text=True, check=True, env=env).stdout.split()
    want = want or str(min(len(os.sched_getaffinity(0)), os.cpu_count()))
    assert out == [want, want, "2", "1048576"], out
