"""``rtcourse grade``: run the graders, print the score table, write results.json.

Quiet by default: a progress bar per lab (on a terminal), then the table with each
task's points and the first failure message of every task that lost points. ``-v``
(``quiet=False``) prints pytest's whole log as well.
"""

from __future__ import annotations

import os
from pathlib import Path

from course.core.files import repo_root
from course.core.labs import implementation_folder, lab_number


class GradeError(SystemExit):
    """A grading run that cannot start or selects nothing: one line, a non-zero exit."""


def lab_test_files(root: Path, labs=None) -> list[Path]:
    """The graders ``tests/test_labN_*.py`` and, where present (not in the student
    handout), the hidden graders ``tests/hidden/test_labN_*.py``, for the chosen labs
    (all by default)."""
    files = sorted((root / "tests").glob("test_lab*_*.py"))
    files += sorted((root / "tests" / "hidden").glob("test_lab*_*.py"))
    if labs:
        wanted = {int(n) for n in labs}
        files = [f for f in files if lab_number(f.name.removeprefix("test_")) in wanted]
    return files


def graded_files(root: Path, folder: Path, test_files) -> str:
    """Lines naming, for each lab kept as a package in ``folder`` (a submission), the files
    graded as handed in and those that are the skeleton's (``root/labs``: left out of the
    submission, or unchanged), so a student sees which of their files were graded; empty
    when no graded lab is a package."""
    from course.core.files import lab_source, module_files
    from course.grading.catalog import lab_catalog

    lines = []
    for lab in lab_catalog(test_files).values():
        mine, skeleton = lab_source(folder, lab.module), lab_source(root / "labs", lab.module)
        if mine is None or skeleton is None or not mine.is_dir() or not skeleton.is_dir():
            continue
        theirs, same = [], []
        for file in module_files(mine):
            rel = file.relative_to(mine)
            given = skeleton / rel
            unchanged = given.is_file() and given.read_bytes() == file.read_bytes()
            (same if unchanged else theirs).append(rel.as_posix())
        lines.append(
            f"{lab.module}/: graded as handed in: {', '.join(theirs) or 'none'}; "
            f"as the skeleton gives them (left out or unchanged): "
            f"{', '.join(same) or 'none'}"
        )
    return "".join(line + "\n" for line in lines) + ("\n" if lines else "")


def task_specs(labs, tasks) -> list[str]:
    """``--task`` values for pytest: ``K`` of each chosen lab (``N.K``), or as given."""
    specs = []
    for task in tasks or ():
        task = str(task)
        if "." in task or not labs:
            specs.append(task)
        else:
            specs += [f"{int(n)}.{task}" for n in labs]
    return specs


def _selection(labs, keyword, tasks) -> str:
    parts = [f"lab {', '.join(map(str, labs))}" if labs else "every lab"]
    if tasks:
        parts.append(f"task {', '.join(map(str, tasks))}")
    if keyword:
        parts.append(f"-k {keyword!r}")
    return ", ".join(parts)


def grade(
    impl: str | None = None,
    *,
    labs=None,
    json_path=None,
    keyword=None,
    trusted=False,
    quiet=True,
    extra_args=(),
    tasks=None,
) -> dict:
    """Grade ``impl`` and return the Gradescope dictionary (also written to ``json_path``).

    ``tasks``: task numbers K (of each lab in ``labs``) or ``"N.K"``; only the tests that
    award those tasks' points run. Raises :class:`GradeError` (one line, exit status 2)
    for a folder that does not exist and for a selection that matches no graded test.
    """
    root = repo_root("rtcourse grade")
    if impl and impl not in ("solutions", "labs") and not Path(impl).expanduser().is_dir():
        raise GradeError(
            f"rtcourse grade: --impl {impl}: no such folder (give the folder "
            f"that holds your lab files, or labs / solutions)"
        )
    files = lab_test_files(root, labs)
    if not files:
        raise GradeError(f"rtcourse grade: no graders found for lab {labs} in {root / 'tests'}")
    user = os.environ.get("RTCOURSE_WORKER_USER")
    if (
        not trusted
        and impl != "solutions"
        and user
        and os.environ.get("RTCOURSE_WORKER_CHECKED") != user
    ):  # run_autograder checked
        from course.grading.worker_user import worker_python_problem

        try:
            problem = worker_python_problem()
        except RuntimeError as exc:  # no such user, or not root
            problem = str(exc)
        if problem:  # before any test: a broken interpreter is never the student's score
            raise GradeError(f"rtcourse grade: {problem}")
    import pytest

    from course.grading.results import ScoreKeeper, write_json_atomically

    args = [str(f) for f in files] + [
        "-p",
        "no:cacheprovider",
        "-c",
        str(root / "pyproject.toml"),
        "--rootdir",
        str(root),
    ]
    if impl:
        args += ["--impl", impl]
    # Quiet: no pytest log at all, the table says it all; -v: pytest's log, long tracebacks.
    args += ["-p", "no:terminal"] if quiet else ["-rf", "--feedback", "full"]
    if trusted:
        args.append("--trusted")
    if keyword:
        args += ["-k", keyword]
    for spec in task_specs(labs, tasks):
        args += ["--task", spec]
    args += list(extra_args)
    from course.core.progress import terminal_stream

    stream = terminal_stream() if quiet else None  # looked up before pytest captures fd 2
    keeper = ScoreKeeper(show_progress=stream is not None, progress_stream=stream)
    try:
        code = pytest.main(args, plugins=[keeper])
    finally:
        keeper.close_progress()
        if stream is not None:
            stream.close()
    if code == 5:
        raise GradeError(
            f"rtcourse grade: no graded test matches {_selection(labs, keyword, tasks)}"
        )
    if code == 4:  # pytest printed why (e.g. --task names a task with no tests)
        raise GradeError(
            f"rtcourse grade: nothing graded ({_selection(labs, keyword, tasks)}; "
            f"see the error above)"
        )
    data = keeper.to_gradescope()
    if impl and impl not in ("solutions", "labs"):
        folder = implementation_folder(root, impl, must_exist=False)
        data["output"] = graded_files(root, folder, files) + data["output"]
    if code not in (0, 1):  # interrupted, internal or usage error: say so in the output
        data["output"] += f"\n(the test run ended abnormally: pytest exit code {int(code)})"
    print()
    print(data["output"])
    if json_path:
        write_json_atomically(json_path, data)
    return data
