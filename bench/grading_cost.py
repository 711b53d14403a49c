"""What isolation costs: the full grading suite against the references, in-process
(trusted) and through the sandboxed worker, timed in one run.

    python bench/grading_cost.py [--repeats 2] [--out bench/results/<device>/grading_cost.json]
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from course.bench import ResultTable, device_name


def _grade_seconds(impl: str, trusted: bool) -> float:
    cmd = [sys.executable, "-m", "course.cli", "grade", "--impl", impl]
    if trusted:
        cmd.append("--trusted")
    start = time.perf_counter()
    proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, check=False)
    seconds = time.perf_counter() - start
    if "total:" not in proc.stdout:
        raise RuntimeError(proc.stdout[-2000:] + proc.stderr[-2000:])
    return seconds


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
            times = sorted(_grade_seconds(impl, trusted) for _ in range(args.repeats))
            table.add(mode=mode, seconds=times[len(times) // 2], runs=len(times))
            print(f"{mode:<11} {times[len(times) // 2]:7.2f} s")
    rows = table.rows
    ratio = rows[1]["seconds"] / rows[0]["seconds"]
    print(f"sandboxed / in-process = {ratio:.2f}")
    out = Path(args.out or ROOT / "bench" / "results" / device_name("cpu") / "grading_cost.json")
    table.metadata["ratio_sandboxed_over_in_process"] = ratio
    table.to_json(out)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
