"""The warm worker pool (course/grading/warm.py) runs every job exactly once: shared by
claims or sharded, through a job past its deadline and a worker that dies mid-job."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

from course.grading.warm import run_pool

ROOT = Path(__file__).resolve().parents[2]

# A warm worker: each job it runs is logged (job id, worker pid) to the job's own log file.
WORKER = """
import json, os, sys, time
from course.grading.warm import serve

def handle(job):
    with open(job["log"], "a") as f:
        f.write(f"{job['id']} {os.getpid()}\\n")
    time.sleep(job.get("sleep", 0.0))
    if job.get("die"):
        os._exit(3)
    return {"value": 2 * job["n"], "pid": os.getpid()}

serve(sys.argv[1], sys.argv[2], handle)
"""


def _pool(specs, workers, **kw):
    env = dict(
        os.environ,
        PYTHONPATH=os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")])),
    )
    return run_pool(
        specs,
        lambda jobs, results, tmp: [sys.executable, "-c", WORKER, jobs, results],
        workers=workers,
        cwd=ROOT,
        env=env,
        lost=lambda job_id, why: {"lost": why},
        **kw,
    )


def _runs(log: Path) -> dict[str, list[int]]:
    runs: dict[str, list[int]] = {}
    for line in log.read_text().splitlines():
        job_id, pid = line.split()
        runs.setdefault(job_id, []).append(int(pid))
    return runs


@pytest.mark.parametrize("shared", [True, False], ids=["claims", "shards"])
def test_every_job_runs_once(tmp_path, shared):
    log = tmp_path / "log"
    specs = [{"id": f"j{n}", "n": n, "log": str(log), "sleep": 0.4} for n in range(9)]
    outcomes = _pool(specs, 3, deadline=60.0, shared=shared)
    runs = _runs(log)
    twice = {k: len(v) for k, v in runs.items() if len(v) != 1}
    assert not twice, f"jobs run more than once (id: times): {twice}"
    assert sorted(runs) == sorted(s["id"] for s in specs), f"jobs never run: {runs}"
    assert [o.get("value") for o in outcomes] == [2 * s["n"] for s in specs], (
        f"one outcome per job, in the jobs' order: {outcomes}"
    )
    # 9 jobs of 0.4 s: a worker's start-up (well under a second) leaves the others time to
    # claim some of them.
    assert len({o["pid"] for o in outcomes}) > 1, "the jobs were spread over the workers"


def test_a_job_past_its_deadline_or_a_death_costs_only_that_job(tmp_path):
    log = tmp_path / "log"
    specs = [{"id": f"j{n}", "n": n, "log": str(log)} for n in range(6)]
    specs[1]["sleep"] = 60.0
    specs[4]["die"] = True
    outcomes = _pool(specs, 2, deadline=3.0)
    assert "timed out after 3 s" in outcomes[1].get("lost", ""), outcomes[1]
    assert "worker exited 3" in outcomes[4].get("lost", ""), outcomes[4]
    for n in (0, 2, 3, 5):
        assert outcomes[n].get("value") == 2 * n, f"job j{n}: {outcomes[n]}"
    twice = {k: len(v) for k, v in _runs(log).items() if len(v) != 1}
    assert not twice, f"jobs run more than once after a restart (id: times): {twice}"
