"""What grading costs on Gradescope: per lab, the autograder that ``rtcourse gradescope
--lab N`` builds, run as Gradescope runs it (``run_autograder``, the reference solution as
the submission, sandboxed), pinned to one core with CUDA hidden. Recorded per lab:

* ``peak_pss_mb``: the peak memory of the whole process tree (the script, the grader, the
  sandboxed worker and anything they start), the sum of each process's PSS (proportional
  set size, from ``/proc/PID/smaps_rollup``: shared pages split between their users, so
  the sum is what the container's memory limit sees), sampled every ``--interval`` s
  (``at_peak``: each process's share at the peak);
* ``cpu_seconds``: user + system time of the tree (every process is waited for);
* ``seconds``: wall time at one core;
* ``score`` / ``max_score``: the reference must get every point.

Gradescope's default container has 768 MB and half a CPU (a 10-minute timeout): each lab
over 768 MB or 5 CPU-minutes needs other settings, which ``rtcourse gradescope`` prints
from :mod:`course.grading.budget` (copy a new run's numbers there).

    python bench/grading_cost.py [--lab N ...] [--cpus 0] [--out PATH]

The autograder is pinned to ``--cpus`` (core 0); this script's memory sampler is not, so
that it never takes the autograder's core.

Linux only (``/proc``, ``taskset``). ``--isolation [--repeats 2]`` measures instead what
the sandbox costs: the whole suite against the references, in-process (trusted) and
through the sandboxed worker (``grading_isolation.json``).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shlex
import shutil
import subprocess
import sys
import tempfile
import threading
import time
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from course.core.files import copy_module, lab_source
from course.grading.catalog import lab_catalog
from course.grading.runner import lab_test_files
from course.measure.bench import ResultTable
from course.tools.gradescope import build_autograder


def _children() -> dict[int, list[int]]:
    kids: dict[int, list[int]] = {}
    for entry in os.scandir("/proc"):
        if not entry.name.isdigit():
            continue
        try:
            stat = Path(entry.path, "stat").read_text()
        except OSError:
            continue
        ppid = int(stat.rsplit(")", 1)[1].split()[1])
        kids.setdefault(ppid, []).append(int(entry.name))
    return kids


def _command(pid: int) -> str:
    try:
        words = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")
    except OSError:
        return "?"
    text = " ".join(_portable(w.decode(errors="replace"), i) for i, w in enumerate(words) if w)
    return text if len(text) <= 80 else text[:77] + "..."


def _portable(word: str, index: int) -> str:
    """A command-line word as any machine would write it: the program by its name, paths in
    the temporary folder as ``$TMPDIR/...`` (the record names no folder of this machine)."""
    if index == 0 and word.startswith("/"):
        return Path(word).name
    tmp = tempfile.gettempdir().rstrip("/") + "/"
    return "$TMPDIR/" + word[len(tmp) :] if word.startswith(tmp) else word


def tree_pss(pid: int) -> dict[int, tuple[int, int, str]]:
    """PID -> (PSS bytes, anonymous PSS bytes, command) of ``pid`` and its descendants."""
    kids, todo, found = _children(), [pid], {}
    while todo:
        p = todo.pop()
        todo += kids.get(p, [])
        try:
            fields = dict(
                line.split(":", 1)
                for line in Path(f"/proc/{p}/smaps_rollup").read_text().splitlines()[1:]
            )
        except (OSError, ValueError):  # exited between the listing and the read
            continue
        found[p] = (
            int(fields["Pss"].split()[0]) * 1024,
            int(fields.get("Pss_Anon", "0 kB").split()[0]) * 1024,
            _command(p),
        )
    return found


class PeakSampler(threading.Thread):
    """Samples the tree's summed PSS; keeps the peak and the processes at the peak."""

    def __init__(self, pid: int, interval: float):
        super().__init__(daemon=True)
        self.pid, self.interval, self.peak, self.at_peak = pid, interval, 0, {}
        self.done = threading.Event()

    def run(self):
        while not self.done.is_set():
            tree = tree_pss(self.pid)
            total = sum(pss for pss, _, _ in tree.values())
            if total > self.peak:
                self.peak, self.at_peak = total, tree
            self.done.wait(self.interval)


def measure_lab(lab: int, module: str, work: Path, interval: float, cpus: str) -> dict:
    """Build lab ``lab``'s autograder, grade the reference with it, return the row."""
    folder = work / f"lab{lab}"
    shutil.rmtree(folder, ignore_errors=True)
    build_autograder(ROOT, folder / "autograder.zip", labs=[lab])
    source = folder / "source"
    with zipfile.ZipFile(folder / "autograder.zip") as archive:
        archive.extractall(source)
    submission, results = folder / "submission", folder / "results"
    submission.mkdir()
    # As a student hands it in: the lab's file, or every file of its package.
    copy_module(lab_source(ROOT / "solutions", module), submission)
    env = dict(
        os.environ,
        CUDA_VISIBLE_DEVICES="",
        RTCOURSE_SUBMISSION_DIR=str(submission),
        RTCOURSE_RESULTS_DIR=str(results),
        RTCOURSE_PYTHON=sys.executable,
    )
    for name in (
        "OMP_NUM_THREADS",
        "MKL_NUM_THREADS",
        "MALLOC_ARENA_MAX",
        "MALLOC_MMAP_THRESHOLD_",
    ):
        env.pop(name, None)  # run_autograder sets them as on Gradescope
    cmd = ["bash", str(source / "run_autograder")]
    if cpus and shutil.which("taskset"):
        cmd = ["taskset", "-c", cpus, *cmd]
    start = time.perf_counter()
    proc = subprocess.Popen(
        cmd, env=env, cwd=folder, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
    )
    sampler = PeakSampler(proc.pid, interval)
    sampler.start()
    output = proc.stdout.read()
    _, status, usage = os.wait4(proc.pid, 0)
    seconds = time.perf_counter() - start
    sampler.done.set()
    sampler.join()
    proc.returncode = os.waitstatus_to_exitcode(status)
    path = results / "results.json"
    data = json.loads(path.read_text()) if path.is_file() else {}
    if proc.returncode != 0 or not data.get("max_score"):
        raise RuntimeError(f"lab {lab}: the autograder failed\n{output[-4000:]}")
    processes = [
        {"command": command, "pss_mb": pss / 2**20, "anon_pss_mb": anon / 2**20}
        for pss, anon, command in sorted(sampler.at_peak.values(), reverse=True)
    ]
    return {
        "lab": lab,
        "peak_pss_mb": sampler.peak / 2**20,
        "cpu_seconds": usage.ru_utime + usage.ru_stime,
        "seconds": seconds,
        "score": data["score"],
        "max_score": data["max_score"],
        "largest_process_rss_mb": usage.ru_maxrss / 1024,
        "at_peak": processes,
    }


def _grade_seconds(impl: str, trusted: bool) -> tuple[float, float]:
    """(wall seconds, CPU seconds of the grader and all its processes) of one grading."""
    cmd = [sys.executable, "-m", "course.tools.cli", "grade", "--impl", impl]
    if trusted:
        cmd.append("--trusted")
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, check=False)
    seconds = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if "total:" not in proc.stdout:
        raise RuntimeError(proc.stdout[-2000:] + proc.stderr[-2000:])
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return seconds, cpu


def isolation(repeats: int, out: Path):
    """The whole suite in-process vs sandboxed: what isolation costs."""
    table = ResultTable("grading cost: in-process vs sandboxed worker", device="cpu")
    with tempfile.TemporaryDirectory() as tmp:
        copy = Path(tmp) / "submission"
        shutil.copytree(ROOT / "solutions", copy, ignore=shutil.ignore_patterns("mutants"))
        for mode, impl, trusted in (
            ("in-process", "solutions", True),
            ("sandboxed", str(copy), False),
        ):
            runs = sorted(_grade_seconds(impl, trusted) for _ in range(repeats))
            wall, cpu = runs[len(runs) // 2]
            table.add(mode=mode, seconds=wall, cpu_seconds=cpu, runs=len(runs))
            print(f"{mode:<11} {wall:7.2f} s wall, {cpu:7.2f} s CPU")
    rows = table.rows
    table.metadata["ratio_sandboxed_over_in_process"] = rows[1]["seconds"] / rows[0]["seconds"]
    table.metadata["cpu_ratio_sandboxed_over_in_process"] = (
        rows[1]["cpu_seconds"] / rows[0]["cpu_seconds"]
    )
    table.metadata["cpus"] = len(os.sched_getaffinity(0))
    print(f"wrote {table.to_json(out)}")


def main():
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--lab", type=int, action="append", help="only this lab (repeatable)")
    parser.add_argument("--cpus", default="0", help="taskset CPU list (default: core 0)")
    parser.add_argument("--interval", type=float, default=0.1, help="PSS sampling, seconds")
    parser.add_argument(
        "--out",
        default=None,
        help="default: bench/results/cpu-2cores/"
        "grading_cost.json (grading_isolation.json with --isolation)",
    )
    parser.add_argument(
        "--isolation", action="store_true", help="in-process vs sandboxed, the whole suite, instead"
    )
    parser.add_argument("--repeats", type=int, default=2, help="with --isolation")
    args = parser.parse_args()
    if not (ROOT / "solutions").is_dir():  # the student handout
        raise SystemExit(
            "grading_cost: it grades the reference solutions with the Gradescope "
            "autograder (rtcourse gradescope), and this folder has no solutions/; "
            "run it in the course repository"
        )
    results = ROOT / "bench" / "results" / "cpu-2cores"
    if args.isolation:
        return isolation(args.repeats, Path(args.out or results / "grading_isolation.json"))
    import torch

    labs = lab_catalog(lab_test_files(ROOT, args.lab))
    table = ResultTable(
        "grading cost per lab: Gradescope's autograder, reference submitted",
        device="cpu",
        total=len(labs),
    )
    with tempfile.TemporaryDirectory() as tmp:
        for number, info in sorted(labs.items()):
            row = measure_lab(number, info.module, Path(tmp), args.interval, args.cpus)
            table.add(**row)
            print(
                f"lab {number}: {row['peak_pss_mb']:7.1f} MB peak PSS, "
                f"{row['cpu_seconds']:7.1f} s CPU, {row['seconds']:7.1f} s wall, "
                f"score {row['score']:g}/{row['max_score']:g}",
                flush=True,
            )
    table.metadata.update(
        cpus=args.cpus,
        torch=torch.__version__,
        interval_s=args.interval,
        command=shlex.join([Path(sys.executable).name, *sys.argv]),
        note="run_autograder of `rtcourse gradescope --lab N` with the reference as the "
        "submission, CUDA hidden, pinned to one core; PSS of the whole process tree, "
        "sampled. Wall time is on a shared machine: cpu_seconds is the steadier number.",
    )
    out = table.to_json(args.out or results / "grading_cost.json")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
