"""What grading a whole class costs: ``rtcourse grade-class`` on N synthetic submissions of
a lab, against ``rtcourse grade --impl FOLDER`` of the same submissions one at a time.

The class (``--n`` students, default 100) cycles through: the reference copied in as
student code, the skeleton, each shipped mutant of the lab (applied with
``course.grading.mutants.apply_mutant``), and once each a hang at import (``while True:
pass``), a hang in a function and a crash at import (``os._exit``). Recorded per lab:

* ``bulk``: wall and CPU seconds of the whole ``grade-class`` run (CPU: user + system of
  the process tree, every process waited for), students per minute, and per student
  ``wall * jobs / n`` and ``cpu / n``;
* ``one_off``: wall and CPU seconds of ``rtcourse grade --impl FOLDER --lab N`` of one
  submission of each kind (reference, skeleton, a mutant), run in the same session, and
  the bulk cost of those same students (their seconds in the warm worker);
* ``ratio``: bulk cost per student / mean one-off cost (the goal: at most 1/3), by wall
  time and by CPU time (the steadier one on a shared machine);
* ``same_scores``: whether each one-off grade gave the score the bulk run gave.

    python bench/grade_class.py [--n 100] [--lab 2 --lab 5] [--jobs J] [--task K]
                                [--time-limit S] [--device cpu|auto]
                                [--out bench/results/cpu-2cores/grade_class]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shlex
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from course.core.device import allowed_cpus  # noqa: E402
from course.core.files import copy_module, defining_file, lab_source, relative_name  # noqa: E402
from course.grading.catalog import skeleton_functions  # noqa: E402
from course.grading.classroom import lab_module  # noqa: E402
from course.grading.classroom_report import read_gradebook  # noqa: E402
from course.grading.mutants import apply_mutant, load_mutants  # noqa: E402

SPECIAL = ("hang_import", "hang_function", "crash_import")


def _entry_file(copy: Path) -> Path:
    """The file a lab copy starts from: the module, or its package's ``__init__.py``."""
    return copy / "__init__.py" if copy.is_dir() else copy


def make_class(folder: Path, lab: int, n: int) -> dict[str, str]:
    """``n`` students of lab ``lab`` in ``folder`` (one folder each); student -> kind."""
    module = lab_module(ROOT, lab)
    solution, skeleton = lab_source(ROOT / "solutions", module), lab_source(ROOT / "labs", module)
    mutants = []
    for mutant in (m for m in load_mutants(ROOT) if m.module == module):
        try:  # a mutant that no longer applies to the reference is left out, and said
            apply_mutant(mutant, defining_file(solution, mutant.function).read_text())
            mutants.append(mutant)
        except ValueError as exc:
            print(f"  left out: {exc}", flush=True)
    cycle = ["reference", "skeleton", *(f"mutant:{m.name}" for m in mutants)]
    kinds = list(SPECIAL[: max(0, min(3, n - 2))])
    kinds += [cycle[i % len(cycle)] for i in range(n - len(kinds))]
    first = skeleton_functions(skeleton)[0]
    students = {}
    for i, kind in enumerate(kinds):
        student = f"s{i:03d}_{kind.split(':')[0]}"
        dest = folder / student
        dest.mkdir(parents=True)
        if kind == "skeleton":
            copy_module(skeleton, dest)
        elif kind.startswith("mutant:"):
            mutant = next(m for m in mutants if m.name == kind.split(":", 1)[1])
            path = defining_file(solution, mutant.function)
            copy_module(
                solution,
                dest,
                {relative_name(solution, path): apply_mutant(mutant, path.read_text())},
            )
        else:
            entry = _entry_file(copy_module(solution, dest))
            text = entry.read_text()
            # after the module's __future__ import, which must come first
            future = "from __future__ import annotations\n"
            head, body = text.split(future, 1) if future in text else ("", text)
            head += future if future in text else ""
            if kind == "hang_import":
                entry.write_text(head + "while True:\n    pass\n" + body)
            elif kind == "crash_import":
                entry.write_text(head + "import os\nos._exit(3)\n" + body)
            elif kind == "hang_function":
                entry.write_text(
                    text + f"\n\ndef {first}(*args, **kwargs):\n    while True:\n        pass\n"
                )
        students[student] = kind
    return students


def _run(cmd, env) -> tuple[float, float, subprocess.CompletedProcess]:
    """Wall and CPU seconds (user + system of the waited-for process tree) of ``cmd``."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    started = time.monotonic()
    proc = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, check=False)
    wall = time.monotonic() - started
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu, proc


def bench_lab(lab: int, n: int, jobs: int, tasks, time_limit, scratch: Path, device="cpu") -> dict:
    folder, out = scratch / f"class{lab}", scratch / f"grades{lab}"
    students = make_class(folder, lab, n)
    env = dict(os.environ, RTCOURSE_PROGRESS="0")
    if device == "cpu":  # the one-off grades too: the same machine for both
        env["CUDA_VISIBLE_DEVICES"] = ""
    selection = [a for t in tasks for a in ("--task", str(t))]
    limit = ["--time-limit", str(time_limit)] if time_limit else []
    cmd = [
        sys.executable,
        "-m",
        "course.tools.cli",
        "grade-class",
        str(folder),
        "--lab",
        str(lab),
        "--out",
        str(out),
        "--jobs",
        str(jobs),
        "--device",
        device,
        *selection,
        *limit,
    ]
    print(f"lab {lab}: grading {n} students in bulk ({jobs} workers)", flush=True)
    wall, cpu, proc = _run(cmd, env)
    if proc.returncode != 0:
        raise SystemExit(f"grade-class failed:\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}")
    rows = {r["student"]: r for r in read_gradebook(out / "gradebook.csv")}
    by_kind: dict[str, list[float]] = {}
    for student, kind in students.items():
        by_kind.setdefault(kind.split(":")[0], []).append(float(rows[student]["seconds"]))
    one_off = []
    # One-off grades of one student of each ordinary kind, as a student would run them.
    picks = {}
    for student, kind in students.items():
        picks.setdefault(kind.split(":")[0], student)
    one_env = dict(env, **({"RTCOURSE_TIME_LIMIT": str(time_limit)} if time_limit else {}))
    for kind in ("reference", "skeleton", "mutant"):
        if kind not in picks:
            continue
        student = picks[kind]
        json_path = scratch / f"one{lab}_{student}.json"
        cmd1 = [
            sys.executable,
            "-m",
            "course.tools.cli",
            "grade",
            "--impl",
            str(folder / student),
            "--lab",
            str(lab),
            "--json",
            str(json_path),
            *selection,
        ]
        print(f"lab {lab}: one-off grade of {student}", flush=True)
        w1, c1, done = _run(cmd1, one_env)
        if not json_path.is_file():
            print(f"  no results: {(done.stdout + done.stderr)[-1500:]}", flush=True)
            continue
        score = json.loads(json_path.read_text())["score"]
        one_off.append(
            {
                "student": student,
                "kind": kind,
                "wall_s": round(w1, 2),
                "cpu_s": round(c1, 2),
                "score": score,
                "bulk_score": float(rows[student]["score"]),
                "bulk_seconds": float(rows[student]["seconds"]),
            }
        )
    if not one_off:
        raise SystemExit(f"lab {lab}: no one-off grade wrote its results")
    one_wall = sum(o["wall_s"] for o in one_off) / len(one_off)
    one_cpu = sum(o["cpu_s"] for o in one_off) / len(one_off)
    same_wall = sum(o["bulk_seconds"] for o in one_off) / len(one_off)
    return {
        "lab": lab,
        "n": n,
        "jobs": jobs,
        "device": device,
        "tasks": list(tasks),
        "time_limit": time_limit,
        "kinds": {k: len(v) for k, v in by_kind.items()},
        "bulk": {
            "wall_s": round(wall, 2),
            "cpu_s": round(cpu, 2),
            "students_per_minute": round(n / wall * 60, 2),
            "per_student_wall_x_jobs_s": round(wall * jobs / n, 2),
            "per_student_cpu_s": round(cpu / n, 2),
            "mean_seconds_by_kind": {k: round(sum(v) / len(v), 2) for k, v in by_kind.items()},
        },
        "one_off": one_off,
        "ratio": {
            "same_students_bulk_over_one_off_wall": round(same_wall / one_wall, 3),
            "class_per_student_over_one_off_wall": round(wall * jobs / n / one_wall, 3),
            "class_per_student_over_one_off_cpu": round(cpu / n / one_cpu, 3),
        },
        "same_scores": all(o["score"] == o["bulk_score"] for o in one_off),
        "summary": (out / "summary.txt").read_text(),
    }


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=100)
    parser.add_argument("--lab", type=int, action="append")
    parser.add_argument("--jobs", type=int, default=None)
    parser.add_argument(
        "--task", action="append", default=[], help="grade only this task of each lab (repeatable)"
    )
    parser.add_argument(
        "--time-limit",
        type=float,
        default=None,
        help="seconds per test of student code (the grader's default: 120)",
    )
    parser.add_argument(
        "--device",
        choices=("cpu", "auto"),
        default="cpu",
        help="cpu hides CUDA from bulk and one-off grades alike; auto leaves it visible",
    )
    parser.add_argument("--out", default=str(ROOT / "bench/results/cpu-2cores/grade_class"))
    args = parser.parse_args(argv)
    labs, jobs = args.lab or [2, 5], args.jobs or allowed_cpus()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    command = "python bench/grade_class.py " + shlex.join(
        argv if argv is not None else sys.argv[1:]
    )
    results = []
    with tempfile.TemporaryDirectory(prefix="rtcourse-bench-class-") as scratch:
        for lab in labs:
            row = bench_lab(
                lab, args.n, jobs, args.task, args.time_limit, Path(scratch), args.device
            )
            results.append(row)
            print(json.dumps({k: v for k, v in row.items() if k != "summary"}, indent=1))
            print(row["summary"])
            data = {
                "command": command,
                "machine": f"{os.cpu_count()} cores, "
                f"{allowed_cpus()} usable, load {os.getloadavg()[0]:.1f} at the end",
                "labs": results,
            }
            (out / "grade_class.json").write_text(json.dumps(data, indent=1) + "\n")
    (out / "command.txt").write_text(command + "\n")
    print(f"wrote {out / 'grade_class.json'}")


if __name__ == "__main__":
    main()
