"""What isolation costs: the full grading suite against the references, in-process
(trusted) and through the sandboxed worker, timed in one run.

    python bench/grading_cost.py [--repeats 2] [--out bench/results/<device>/grading_cost.json]
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from course.bench import ResultTable, device_name


def _grade_seconds(impl: str, trusted: bool) -> tuple[float, float]:
    """(wall seconds, CPU seconds of the grader and all its processes) of one grading."""
    cmd = [sys.executable, "-m", "course.cli", "grade", "--impl", impl]
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


def main():
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--out", default=None)
    args = parser.parse_args()
    table = ResultTable("grading cost: in-process vs sandboxed worker", device="cpu")
    with tempfile.TemporaryDirectory() as tmp:
        copy = Path(tmp) / "submission"
        shutil.copytree(ROOT / "solutions", copy, ignore=shutil.ignore_patterns("mutants"))
        for mode, impl, trusted in (("in-process", "solutions", True),
                                    ("sandboxed", str(copy), False)):
            runs = sorted(_grade_seconds(impl, trusted) for _ in range(args.repeats))
            wall, cpu = runs[len(runs) // 2]
            table.add(mode=mode, seconds=wall, cpu_seconds=cpu, runs=len(runs))
            print(f"{mode:<11} {wall:7.2f} s wall, {cpu:7.2f} s CPU")
    rows = table.rows
    ratio = rows[1]["seconds"] / rows[0]["seconds"]
    cpu_ratio = rows[1]["cpu_seconds"] / rows[0]["cpu_seconds"]
    print(f"sandboxed / in-process = {ratio:.2f} (wall), {cpu_ratio:.2f} (CPU)")
    out = Path(args.out or ROOT / "bench" / "results" / device_name("cpu") / "grading_cost.json")
    table.metadata["ratio_sandboxed_over_in_process"] = ratio
    table.metadata["cpu_ratio_sandboxed_over_in_process"] = cpu_ratio
    table.metadata["cpus"] = len(os.sched_getaffinity(0))
    table.to_json(out)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
