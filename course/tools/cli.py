"""``rtcourse``: demo, grade, bench, mutants, release, gradescope, slides, skeletons."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

_COMMAND = ["rtcourse"]  # the command that runs ("rtcourse release"), named in its errors


def _root() -> Path:
    from course.core.files import repo_root

    return repo_root(_COMMAND[0])


def cmd_demo(args):
    from course.core.device import default_device
    from course.core.labs import implementation_folder
    from course.tools.gallery import build_gallery

    root = _root()
    device = str(default_device(args.device))
    try:
        folder = implementation_folder(root, args.impl)
    except FileNotFoundError as exc:
        raise SystemExit(f"rtcourse demo: {exc}") from None
    rows = build_gallery(root, folder, device, Path(args.out), args.size)
    print(f"\n{'lab':>3}  {'status':<22} {'seconds':>8}")
    for row in rows:
        print(f"{row['lab']:>3}  {row['status']:<22} {row['seconds']:>8.2f}")
    print(f"\ngallery: {Path(args.out).resolve() / 'index.html'}")


def cmd_grade(args):
    if args.device == "cpu":
        # Before anything starts CUDA: the graders (this process) and every sandboxed
        # worker it starts (they inherit the environment) see no GPU.
        import os

        os.environ["CUDA_VISIBLE_DEVICES"] = ""
    from course.grading.runner import grade

    data = grade(
        args.impl,
        labs=args.lab,
        json_path=args.json,
        keyword=args.k,
        trusted=args.trusted,
        quiet=not args.verbose,
        tasks=args.task,
    )
    return 0 if data["max_score"] > 0 else 1


def cmd_grade_class(args):
    from course.grading.classroom import grade_class
    from course.tools.gradescope import collect_submission

    try:
        grade_class(
            args.submissions,
            args.lab,
            collect=collect_submission,
            out=args.out,
            jobs=args.jobs,
            device=args.device,
            tasks=args.task,
            keyword=args.k,
            time_limit=args.time_limit,
        )
    except ValueError as exc:
        raise SystemExit(f"rtcourse grade-class: {exc}") from None
    except KeyboardInterrupt:
        return 130
    return 0


def cmd_mutants(args):
    from course.core.device import allowed_cpus
    from course.grading.mutants import catch_mutants, load_mutants

    root = _root()
    if args.generated:
        from course.grading.mutate import main_cli

        return main_cli(
            root,
            labs=args.lab,
            per_lab=args.sample,
            seed=args.seed,
            workers=args.workers,
            json_path=args.json,
            only=args.only,
            device=args.device,
        )
    mutants = [m for m in load_mutants(root) if not args.lab or m.lab in args.lab]
    outcomes = catch_mutants(mutants, root, workers=args.workers or allowed_cpus())
    survivors = 0
    for mutant in mutants:
        outcome = outcomes[mutant.name]
        caught = outcome["killed"] and not outcome.get("error")
        survivors += not caught
        verdict = (
            f"caught by {outcome['by'][0]}"
            if caught
            else f"SURVIVED ({outcome.get('error') or str(outcome['ran']) + ' tests passed'})"
        )
        print(f"lab {mutant.lab} {mutant.name:<32} {verdict.splitlines()[0]}: {mutant.why}")
    return 1 if survivors else 0


def _notebook_stack(command: str) -> None:
    """Stop with one line when the notebooks extra (a grading install leaves it out) is not
    installed and ``command`` needs it."""
    import importlib.util

    missing = [
        m
        for m in ("nbformat", "nbclient", "nbconvert", "ipykernel")
        if importlib.util.find_spec(m) is None
    ]
    if missing:
        raise SystemExit(
            f"{command}: needs the lecture notebooks' packages ({', '.join(missing)} "
            f"missing): pip install -e '.[notebooks]' (make test installs them)"
        )


def cmd_bench(args):
    from course.tools.trade import NotWritten, run

    try:
        result = run(
            args.lab,
            impl=args.impl,
            device=args.device,
            quick=args.quick,
            out=args.out,
            root=_root(),
        )
    except NotWritten as exc:
        raise SystemExit(f"rtcourse bench --lab {args.lab}: {exc}") from None
    except (FileNotFoundError, ValueError) as exc:
        raise SystemExit(f"rtcourse bench: {exc}") from None
    print(result.table)
    print(
        f"\nrows: {result.csv}"
        + (f"\nplot: {result.png}" if result.png else "")
        + f"\n({result.seconds:.1f} s)"
    )
    return 0


def cmd_release(args):
    from course.tools.release import release

    if args.notes:
        _notebook_stack("rtcourse release (--no-notes needs none)")
    # The reference rows of rtcourse bench take well under a minute (every lab, --quick):
    # always shipped, so a student's bench has the reference to stand beside.
    files = release(_root(), args.out, notes=args.notes, reference_rows=True)
    print(f"wrote {len(files)} files of the student handout to {Path(args.out).resolve()}")


def cmd_gradescope(args):
    from course.grading.budget import settings_text
    from course.tools.gradescope import build_autograder

    try:
        names = build_autograder(_root(), args.out, labs=args.lab)
    except ValueError as exc:
        raise SystemExit(f"rtcourse gradescope: {exc}") from None
    print(f"wrote the Gradescope autograder ({len(names)} files) to {Path(args.out).resolve()}")
    print("\n" + settings_text(args.lab))


def cmd_slides(args):
    _notebook_stack("rtcourse slides")
    from course.tools.slides import render_slides

    try:
        rows = render_slides(_root(), Path(args.out), execute=args.execute, names=args.notebooks)
    except ValueError as exc:
        raise SystemExit(f"rtcourse slides: {exc}") from None
    print(f"\nslides and lecture notes: {Path(args.out).resolve() / 'index.html'}")
    return 1 if any(row["errors"] for row in rows) else 0


def cmd_skeletons(args):
    from course.tools.skeletons import main as skeletons

    return skeletons(_root(), check=args.check)


def main(argv=None):
    parser = argparse.ArgumentParser(prog="rtcourse", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("demo", help="render each lab's showcase into a gallery")
    p.add_argument("--device", default=None, help="cpu or cuda (default: cuda when present)")
    p.add_argument("--out", default="out", help="output folder (default: out/)")
    p.add_argument("--impl", default=None, help="solutions (default) or labs or a folder")
    p.add_argument("--size", type=int, default=256, help="image size in pixels")
    p.set_defaults(func=cmd_demo)

    p = sub.add_parser("grade", help="grade an implementation; print scores, write JSON")
    p.add_argument(
        "--impl", default=None, help="labs, solutions or a folder with a student's lab files"
    )
    p.add_argument("--lab", type=int, action="append", help="grade only this lab (repeatable)")
    p.add_argument("--json", default=None, help="write Gradescope results.json here")
    p.add_argument("-k", default=None, help="pytest -k expression selecting tests")
    p.add_argument(
        "--task",
        action="append",
        metavar="K",
        help="grade only task K (of each --lab; or N.K for lab N): exactly the "
        "tests that award its points (repeatable)",
    )
    p.add_argument(
        "--trusted",
        action="store_true",
        help="run the implementation in-process (only for code you trust)",
    )
    p.add_argument(
        "--device",
        choices=("cpu", "auto"),
        default="cpu",
        help="cpu hides CUDA from the graders: the Gradescope grade, and faster on a GPU "
        "machine (default); auto also runs every test's [cuda] case where CUDA is present",
    )
    p.add_argument(
        "-v",
        "--verbose",
        action="store_true",
        help="also print pytest's whole log with full tracebacks",
    )
    p.set_defaults(func=cmd_grade)

    p = sub.add_parser(
        "grade-class",
        help="grade a folder of a class's submissions: gradebook CSV, feedback per student, JSON",
    )
    p.add_argument(
        "submissions",
        help="a folder (or zip) with one folder or zip per student, "
        "a Gradescope export, or Canvas/Moodle/Blackboard files",
    )
    p.add_argument("--lab", type=int, required=True, help="the lab graded")
    p.add_argument(
        "--jobs",
        "-j",
        type=int,
        default=None,
        help="warm grading processes (default: the usable cores)",
    )
    p.add_argument(
        "--out",
        default=None,
        help="output folder (default: grades/labN); run again with the same one to resume",
    )
    p.add_argument(
        "--device",
        choices=("cpu", "auto"),
        default="cpu",
        help="cpu hides CUDA from the graders (default: grading is process "
        "start-up and small kernels); auto lets them use it",
    )
    p.add_argument("-k", default=None, help="pytest -k expression selecting tests")
    p.add_argument("--task", action="append", metavar="K", help="grade only task K")
    p.add_argument(
        "--time-limit",
        type=float,
        default=None,
        help="seconds of student code per test (default: the grader's, 120)",
    )
    p.set_defaults(func=cmd_grade_class)

    p = sub.add_parser("mutants", help="grade every mutant; each must lose points")
    p.add_argument("--lab", type=int, action="append")
    p.add_argument(
        "--generated",
        action="store_true",
        help="systematic operator mutations of the references; a score per lab",
    )
    p.add_argument(
        "--sample",
        type=int,
        default=None,
        help="with --generated: at most this many mutants per lab, drawn with --seed",
    )
    p.add_argument("--seed", type=int, default=0)
    p.add_argument(
        "--workers", type=int, default=None, help="parallel workers (default: the usable cores)"
    )
    p.add_argument(
        "--only", default=None, help="with --generated: only mutants whose id matches this regex"
    )
    p.add_argument("--json", default=None, help="with --generated: write the table here")
    p.add_argument(
        "--device",
        choices=("cpu", "auto"),
        default="cpu",
        help="with --generated: cpu hides CUDA from the graders (default); auto lets the "
        "[cuda] cases run too, for mistakes on paths only CUDA takes",
    )
    p.set_defaults(func=cmd_mutants)

    p = sub.add_parser(
        "bench",
        help="your point on the plot: a lab's knobs timed on your "
        "code and the reference; CSV, Pareto plot, table",
    )
    p.add_argument(
        "--lab",
        type=int,
        required=True,
        choices=range(7),
        metavar="N",
        help="the lab measured (0 .. 6)",
    )
    p.add_argument(
        "--impl",
        default="labs",
        help="labs (yours, the default), solutions or a folder of lab files",
    )
    p.add_argument("--device", default=None, help="cpu or cuda (default: cuda when present)")
    p.add_argument(
        "--quick", action="store_true", help="small sizes (under two minutes on a CPU core)"
    )
    p.add_argument("--out", default=None, help="output folder (default: out/bench/labN)")
    p.set_defaults(func=cmd_bench)

    p = sub.add_parser("release", help="write the student handout")
    p.add_argument("out", help="output folder")
    p.add_argument(
        "--notes",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="run the lecture notebooks on the references and ship their outputs, "
        "figures and rendered notes (default; --no-notes: the notebooks as saved)",
    )
    p.set_defaults(func=cmd_release)

    p = sub.add_parser("gradescope", help="build a Gradescope autograder zip")
    p.add_argument("out", help="the zip file to write, e.g. autograder.zip")
    p.add_argument(
        "--lab",
        type=int,
        action="append",
        help="grade only this lab (repeatable; default: every lab)",
    )
    p.set_defaults(func=cmd_gradescope)

    p = sub.add_parser("slides", help="render slides/*.ipynb to reveal.js slides and notes")
    p.add_argument(
        "notebooks",
        nargs="*",
        metavar="NOTEBOOK",
        help="render only these (a name in slides/ such as 04_march, or a path)",
    )
    p.add_argument("--out", default="out/slides", help="output folder (default: out/slides)")
    p.add_argument(
        "--execute",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="run the notebooks first (RTCOURSE_SMALL=1 unless set; default)",
    )
    p.set_defaults(func=cmd_slides)

    p = sub.add_parser("skeletons", help="generate labs/ from the marked references in solutions/")
    p.add_argument(
        "--check",
        action="store_true",
        help="change nothing; exit 1 naming the first differing line of each "
        "skeleton that is not what the references generate",
    )
    p.set_defaults(func=cmd_skeletons)

    args = parser.parse_args(argv)
    _COMMAND[0] = f"rtcourse {args.command}"
    return args.func(args) or 0


if __name__ == "__main__":
    sys.exit(main())
