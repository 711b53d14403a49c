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

``--kept-since COMMIT`` (with ``--resume``): after the references or the graders changed,
keep of the resumed outcomes only the caught mutants (and the reviewed equivalents) whose
function is the same at
``COMMIT`` (the commit the resumed run graded) and now (its code, docstring aside; ids
number a function's sites, so an unchanged function keeps its ids); grade the rest again:
the survivors (a new test may catch them now) and every mutant of a changed function. A
test only ever added or strengthened keeps a caught mutant caught; one relaxed since needs
its function's mutants graded again by hand (``rtcourse mutants --generated --only``).

At the end: the score table over every outcome in the files, as ``rtcourse mutants
--generated`` prints it (reviewed equivalents from ``solutions/mutants/reviewed/labN.py``).
"""

from __future__ import annotations

import argparse
import ast
import json
import subprocess
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


def _code(source: str | None, name: str) -> str | None:
    """The code of the top-level function or class ``name`` in ``source``, docstring
    aside (``ast.dump``), or None where there is none."""
    if source is None:
        return None
    for node in ast.parse(source).body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            if node.name == name:
                body = node.body[1:] if ast.get_docstring(node) is not None else node.body
                return ast.dump(ast.Module(body, []))
    return None


def kept_since(done: dict[str, dict], commit: str, reviewed) -> dict[str, dict]:
    """Of ``done`` (outcomes by id), the caught mutants and the ``reviewed`` equivalents
    whose function's code is the same at ``commit`` and in the working tree."""
    texts: dict[tuple[str, str], str | None] = {}

    def text(rev: str, path: str) -> str | None:
        if (rev, path) not in texts:
            if rev:
                shown = subprocess.run(
                    ["git", "show", f"{rev}:{path}"], cwd=ROOT, capture_output=True, text=True
                )
                texts[rev, path] = shown.stdout if shown.returncode == 0 else None
            else:
                texts[rev, path] = (ROOT / path).read_text() if (ROOT / path).is_file() else None
        return texts[rev, path]

    kept = {}
    for mutant_id, row in done.items():
        path = f"solutions/{row['file']}"
        then = _code(text(commit, path), row["function"])
        settled = row.get("killed") or mutant_id in reviewed
        if settled and then is not None and then == _code(text("", path), row["function"]):
            kept[mutant_id] = row
    return kept


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", required=True, help="JSON lines file the outcomes are appended to")
    p.add_argument("--resume", nargs="*", default=[], help="outcome files already graded")
    p.add_argument("--labs", nargs="*", type=int, default=None)
    p.add_argument("--workers", type=int, default=None, help="default: the usable cores")
    p.add_argument("--budget", type=float, default=None, help="seconds to start chunks in")
    p.add_argument("--deadline", type=float, default=120.0, help="seconds per mutant")
    p.add_argument("--chunk", type=int, default=None, help="mutants per chunk")
    p.add_argument(
        "--kept-since", default=None, help="commit the resumed outcomes graded (see above)"
    )
    args = p.parse_args(argv)
    started = time.monotonic()
    workers = args.workers or allowed_cpus()
    chunk = args.chunk or 16 * workers
    plans = plan(ROOT, args.labs)
    mutants = sample(plans, None, 0)
    done = read_outcomes(args.resume)
    if args.kept_since:
        done = kept_since(done, args.kept_since, load_reviewed(ROOT))
    done.update(read_outcomes([args.out]))
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
