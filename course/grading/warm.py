"""Warm worker processes: many grading jobs, one after another, in processes that import
torch, pytest and the graders once.

Starting Python, importing torch and pytest and collecting a lab's graders costs seconds per
grading run; a job that reuses a warm process pays it once per worker instead of once per
job. Generated and shipped mutants (:mod:`course.grading.mutate`) and whole classes of
submissions (:mod:`course.grading.classroom`) are graded this way.

A *job* is a JSON-able dict with an ``id``. The parent talks to each worker through two
files, so nothing a job prints, and no crash, can garble what the parent reads:

* ``JOBS``: one JSON job a line, written before the worker starts; in a pool with a shared
  claims folder, a first line ``{"claims": FOLDER}`` names it (in the file, not on the
  worker's command line, so that no worker command can leave it out: a worker without it
  would run every job of the pool);
* ``RESULTS``: the worker appends ``{"id": ..., "started": true}`` before a job and the
  job's outcome (a dict with its ``id`` and no ``started``) after it, each line flushed.

A worker that runs one job past ``deadline`` seconds is killed and started again for the
jobs left; the job it was running then, or when it died, gets ``lost(id, why)`` as its
outcome. With a shared *claims* folder (:func:`run_pool`'s default) every worker of a pool
is handed every job and takes the next one that no other worker has claimed, so a slow job
holds up only its own worker.

Workers die with the process that started them (Linux: the parent-death signal; elsewhere
they notice between jobs), so a killed grading run leaves no worker behind.
"""

from __future__ import annotations

import hashlib
import json
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path

_POLL = 0.25  # seconds between looks at a worker's results file


def _die_with_parent():
    """Have the kernel kill this process when its parent ends (Linux), so a worker never
    outlives a grading run that was killed."""
    if sys.platform.startswith("linux"):
        import ctypes

        try:
            ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
        except (OSError, AttributeError):
            pass


def _claim(claims: Path, job_id: str) -> bool:
    """Take ``job_id`` for this worker: True for exactly one worker of the pool."""
    name = hashlib.sha256(job_id.encode()).hexdigest()[:32]
    try:
        os.close(os.open(claims / name, os.O_CREAT | os.O_EXCL | os.O_WRONLY))
        return True
    except FileExistsError:
        return False


def serve(jobs: str, results: str, handle: Callable[[dict], dict], claims: str | None = None):
    """Worker side: run ``handle(job)`` for each job of the file ``jobs`` (only those it
    can claim, where ``claims`` or the file's header names a claims folder), appending to
    ``results`` as the module docstring says."""
    _die_with_parent()
    parent = os.getppid()
    specs = [json.loads(line) for line in Path(jobs).read_text().splitlines() if line.strip()]
    if specs and "id" not in specs[0]:  # the pool's header: its claims folder
        claims = claims or specs.pop(0).get("claims")
    with open(results, "a") as out:
        for spec in specs:
            if os.getppid() != parent:  # no parent-death signal on this system
                return
            if claims and not _claim(Path(claims), spec["id"]):
                continue
            out.write(json.dumps({"id": spec["id"], "started": True}) + "\n")
            out.flush()
            outcome = dict(handle(spec))
            outcome["id"] = spec["id"]
            outcome.pop("started", None)
            out.write(json.dumps(outcome) + "\n")
            out.flush()


def _rows(path: Path, offset: int) -> tuple[list[dict], int]:
    """The whole lines appended to ``path`` since ``offset``, and the new offset."""
    with open(path, "rb") as f:
        f.seek(offset)
        data = f.read()
    end = data.rfind(b"\n") + 1
    rows = [json.loads(line) for line in data[:end].splitlines() if line.strip()]
    return rows, offset + end


def _tail(path: Path, limit: int = 2000) -> str:
    try:
        return path.read_text(errors="replace")[-limit:]
    except OSError:
        return ""


def run_queue(
    specs: list[dict],
    command: Callable[[str, str, str], list[str]],
    *,
    cwd,
    env: dict,
    deadline: float,
    scratch,
    lost: Callable[[str, str], dict],
    claims: str | None = None,
    tick: Callable[[int], None] = lambda n: None,
    stop: threading.Event | None = None,
) -> list[dict]:
    """Parent side of one worker process: run it over ``specs``, restarting it after a job
    that ran past ``deadline`` seconds or a death, and return the outcomes of the jobs it
    ran (every job of ``specs`` without ``claims``), in the order they finished.

    ``command(jobs, results, tmp)`` is the worker's argv; ``tick(n)`` is told of every ``n``
    jobs finished; ``stop``, once set, kills the worker and returns what finished."""
    done: dict[str, dict] = {}
    order: list[str] = []
    remaining = list(specs)
    while remaining and not (stop and stop.is_set()):
        with tempfile.TemporaryDirectory(dir=scratch) as tmp:
            jobs, results, log = (
                Path(tmp, "jobs.jsonl"),
                Path(tmp, "results.jsonl"),
                Path(tmp, "worker.log"),
            )
            header = [{"claims": claims}] if claims else []
            jobs.write_text("".join(json.dumps(s) + "\n" for s in header + remaining))
            results.touch()
            with open(log, "wb") as log_file:
                proc = subprocess.Popen(
                    command(str(jobs), str(results), tmp),
                    cwd=cwd,
                    env=env,
                    stdin=subprocess.DEVNULL,
                    stdout=log_file,
                    stderr=subprocess.STDOUT,
                    start_new_session=True,
                )
            current, since, offset, killed = None, time.monotonic(), 0, False

            def read(results=results):
                nonlocal current, since, offset
                rows, offset = _rows(results, offset)
                finished = 0
                for row in rows:
                    if row.get("started"):
                        current, since = row["id"], time.monotonic()
                    else:
                        if row["id"] not in done:
                            order.append(row["id"])
                            finished += 1
                        done[row["id"]] = row
                        current = None if current == row["id"] else current
                tick(finished)

            while proc.poll() is None:
                time.sleep(_POLL)
                read()
                if stop is not None and stop.is_set():
                    _kill(proc)
                    return [done[i] for i in order]
                if current and time.monotonic() - since > deadline:
                    _kill(proc)
                    killed = True
                    done[current] = _given_up(lost, current, f"timed out after {deadline:.0f} s")
                    order.append(current)
                    tick(1)
                    current = None
            read()
            if current is not None:  # it died while running this job
                done[current] = _given_up(lost, current, f"worker exited {proc.returncode}")
                order.append(current)
                tick(1)
            elif proc.returncode != 0 and not killed:
                started_none = not any(s["id"] in done for s in remaining)
                if claims:
                    if started_none:
                        raise RuntimeError(
                            f"a warm worker exited {proc.returncode} before "
                            f"its first job:\n{_tail(log)}"
                        )
                else:  # blame the next job, so the queue always moves on
                    first = next(s for s in remaining if s["id"] not in done)
                    done[first["id"]] = _given_up(
                        lost, first["id"], f"worker exited {proc.returncode}"
                    )
                    order.append(first["id"])
                    tick(1)
        if claims:
            taken = {p.name for p in Path(claims).iterdir()}
            remaining = [
                s
                for s in remaining
                if s["id"] not in done
                and hashlib.sha256(s["id"].encode()).hexdigest()[:32] not in taken
            ]
        else:
            remaining = [s for s in remaining if s["id"] not in done]
    return [done[i] for i in order]


def _given_up(lost: Callable[[str, str], dict], job_id: str, why: str) -> dict:
    """``lost``'s outcome for a job that ran past its deadline or whose worker died, naming
    the job as every outcome does."""
    return dict(lost(job_id, why), id=job_id)


def _kill(proc: subprocess.Popen):
    """End a worker and whatever it started in its session."""
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except OSError:
        proc.kill()
    proc.wait()


def run_pool(
    specs: list[dict],
    command: Callable[[str, str, str], list[str]],
    *,
    workers: int,
    cwd,
    env: dict,
    deadline: float,
    lost: Callable[[str, str], dict],
    shared: bool = True,
    tick: Callable[[int], None] = lambda n: None,
    scratch_prefix: str = "rtcourse-warm-",
) -> list[dict]:
    """Run ``specs`` in ``workers`` warm workers; one outcome per job, in ``specs``' order.

    ``shared``: every worker takes the next unclaimed job (a slow job holds up only its own
    worker); otherwise job ``i`` goes to worker ``i % workers``. An interrupt
    (KeyboardInterrupt) kills every worker before it propagates."""
    from concurrent.futures import ThreadPoolExecutor

    workers = max(1, min(workers, len(specs) or 1))
    stop = threading.Event()
    with tempfile.TemporaryDirectory(prefix=scratch_prefix) as scratch:
        claims = None
        if shared:
            claims = str(Path(scratch, "claims"))
            os.mkdir(claims)
        shards = [specs] * workers if shared else [specs[i::workers] for i in range(workers)]
        with ThreadPoolExecutor(max_workers=workers) as pool:
            futures = [
                pool.submit(
                    run_queue,
                    shard,
                    command,
                    cwd=cwd,
                    env=env,
                    deadline=deadline,
                    scratch=scratch,
                    lost=lost,
                    claims=claims,
                    tick=tick,
                    stop=stop,
                )
                for shard in shards
                if shard
            ]
            try:
                parts = [f.result() for f in futures]
            except BaseException:
                stop.set()  # before the pool waits for its threads: they kill their workers
                raise
    by_id = {row["id"]: row for part in parts for row in part}
    return [by_id.get(s["id"]) or lost(s["id"], "not run (its worker ended first)") for s in specs]
