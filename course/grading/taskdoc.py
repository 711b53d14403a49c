"""The per-task table of the handout's ``labs/README.md``: for each task its points, every
function it asks for (read from the skeleton's ``NotImplementedError``s), the earlier tasks
its tests run (directly, or through the lab's own functions, as the reference calls them),
and the commands that run exactly its tests. For a lab kept as a package
(``labs/lab2_accel/``) each function is listed with the file it is written in, the files
the student hands in."""

from __future__ import annotations

from pathlib import Path

from course.core.files import defining_file
from course.grading.catalog import LabInfo, lab_tasks


def _pts(points: float) -> str:
    return f"{points:g}"


def _cell(text: str) -> str:
    return str(text).replace("|", "\\|")  # a literal | inside a Markdown table cell


def _you_write(functions: list[str], lab_file: Path) -> str:
    """``f``, ``g`` of a file lab; ``grid.py``: ``f``, ``g`` of a package, by the file each
    function is written in."""
    if not Path(lab_file).is_dir():
        return ", ".join(f"`{f}`" for f in functions)
    files: dict[str, list[str]] = {}
    for f in functions:
        files.setdefault(defining_file(lab_file, f).relative_to(lab_file).as_posix(),
                         []).append(f)
    return "; ".join(f"`{name}`: " + ", ".join(f"`{f}`" for f in fns)
                     for name, fns in files.items())


def package_files(lab: LabInfo, lab_file: Path) -> list[str]:
    """The files of a lab package that hold a task's functions (what a student edits and
    hands in), in task order; [] for a lab in one file."""
    if not Path(lab_file).is_dir():
        return []
    return list(dict.fromkeys(defining_file(lab_file, f).relative_to(lab_file).as_posix()
                              for task in lab_tasks(lab, lab_file) for f in task.functions))


def task_table(lab: LabInfo, lab_file: Path, test_file: str, reference=None) -> list[str]:
    """Markdown lines: the table of ``lab``'s tasks (``test_file``: the grader's path as the
    student types it; ``lab_file``: the skeleton, a file or a package folder; ``reference``:
    the solution, whose calls say what each task's tests run of the other tasks)."""
    lines = ["| task | title | points | you write | needs first | run only its tests |",
             "|---:|---|---:|---|---|---|"]
    for task in lab_tasks(lab, lab_file, reference):
        you_write = _you_write(task.functions, lab_file)
        needs = "; ".join(f"task {k} (" + ", ".join(f"`{f}`" for f in fns) + ")"
                          for k, fns in task.needs.items())
        run = (f"`python -m pytest {test_file} --task {task.number}` or "
               f"`rtcourse grade --lab {lab.number} --task {task.number}`")
        lines.append(f"| {task.number} | {_cell(task.title)} | {_pts(task.points)} | "
                     f"{you_write} | {needs} | {run} |")
    return lines
