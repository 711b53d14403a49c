"""Every generated mutant of every lab, graded in resumable chunks.

    python bench/all_mutants.py --out OUTCOMES.jsonl [--resume A.jsonl ...] [--labs 0 2]
        [--workers J] [--budget SECONDS] [--deadline SECONDS] [--chunk N]

``rtcourse mutants --generated`` grades a set in one pool and reports at the end; the whole
set (over 3,000 mutants, 1-20 s of one core each) outlasts a single sitting on most
machines. Here the mutants are graded in chunks of ``N`` (default 16 per worker); after each
chunk its outcomes are appended to ``--out``, one JSON line per mutant, so a run stopped at
any point keeps what it finished and a later run given ``--resume`` (the same or earlier
files) grades only the rest. ``--budget`` stops starting chunks when the next one would not
finish in time (estimated from the last). A mutant that hangs past ``--deadline`` counts as
caught, as the real grader's deadline fails it.

At the end: the score table over every outcome in the files, as ``rtcourse mutants
--generated`` prints it (reviewed equivalents from ``solutions/mutants/reviewed/labN.py``).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import asdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from course.core.device import allowed_cpus
from course.grading.mutate import load_reviewed, plan, run, sample, score_table


def read_outcomes(paths) -> dict[str, dict]:
    """Outcomes by mutant id, later files and lines winning."""
    done = {}
    for path in paths:
        if Path(path).exists():
            for line in Path(path).read_text().splitlines():
                if line.strip():
                    row = json.loads(line)
                    done[row["id"]] = row
    return done


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", required=True, help="JSON lines file the outcomes are appended to")
    p.add_argument("--resume", nargs="*", default=[], help="outcome files already graded")
    p.add_argument("--labs", nargs="*", type=int, default=None)
    p.add_argument("--workers", type=int, default=None, help="default: the usable cores")
    p.add_argument("--budget", type=float, default=None, help="seconds to start chunks in")
    p.add_argument("--deadline", type=float, default=120.0, help="seconds per mutant")
    p.add_argument("--chunk", type=int, default=None, help="mutants per chunk")
    args = p.parse_args(argv)
    started = time.monotonic()
    workers = args.workers or allowed_cpus()
    chunk = args.chunk or 16 * workers
    plans = plan(ROOT, args.labs)
    mutants = sample(plans, None, 0)
    done = read_outcomes([*args.resume, args.out])
    todo = [m for m in mutants if m.id not in done]
    # Lab 0's tests time copies and frame loops (~10x the others): start them first so the
    # last chunk is not one lab's slow tail.
    todo.sort(key=lambda m: (m.lab != 0, m.lab, m.id))
    print(
        f"{len(mutants)} generated, {len(mutants) - len(todo)} already graded, "
        f"{len(todo)} to grade with {workers} workers",
        flush=True,
    )
    last = 0.0
    with open(args.out, "a") as out:
        for i in range(0, len(todo), chunk):
            elapsed = time.monotonic() - started
            if args.budget and elapsed + 1.2 * last > args.budget:
                print(f"budget: stopping with {len(todo) - i} left", flush=True)
                break
            part = todo[i : i + chunk]
            t0 = time.monotonic()
            outcomes = run(ROOT, part, plans, workers=workers, deadline=args.deadline)
            last = time.monotonic() - t0
            for m, o in zip(part, outcomes):
                row = dict(asdict(m), **o)
                row.pop("source", None)
                done[m.id] = row
                out.write(json.dumps(row) + "\n")
            out.flush()
            print(
                f"chunk {i // chunk}: {len(part)} in {last:.0f} s "
                f"({sum(not o['killed'] for o in outcomes)} survived)",
                flush=True,
            )
    graded = [m for m in mutants if m.id in done]
    table = score_table(graded, [done[m.id] for m in graded], load_reviewed(ROOT))
    print(
        f"\n{'lab':>3} {'generated':>9} {'graded':>6} {'killed':>6} {'equiv':>5} "
        f"{'survived':>8} {'errors':>6} {'score':>6}"
    )
    per_lab = {p.lab: len(p.mutants) for p in plans}
    for row in table:
        print(
            f"{row['lab']:>3} {per_lab[row['lab']]:>9} {row['generated']:>6} "
            f"{row['killed']:>6} {row['equivalent']:>5} {len(row['survived']):>8} "
            f"{len(row['errors']):>6} {row['score']:>6.1%}"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
