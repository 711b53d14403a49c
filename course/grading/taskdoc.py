"""The per-task table of the handout's ``labs/README.md``: for each task its points, every
function it asks for (read from the skeleton's ``NotImplementedError``s), the earlier tasks
its tests need, and the commands that run exactly its tests."""

from __future__ import annotations

from pathlib import Path

from course.grading.catalog import LabInfo, lab_tasks


def _pts(points: float) -> str:
    return f"{points:g}"


def _cell(text: str) -> str:
    return str(text).replace("|", "\\|")  # a literal | inside a Markdown table cell


def task_table(lab: LabInfo, lab_file: Path, test_file: str) -> list[str]:
    """Markdown lines: the table of ``lab``'s tasks (``test_file``: the grader's path as the
    student types it)."""
    lines = ["| task | title | points | you write | needs first | run only its tests |",
             "|---:|---|---:|---|---|---|"]
    for task in lab_tasks(lab, lab_file):
        you_write = ", ".join(f"`{f}`" for f in task.functions)
        needs = "; ".join(f"task {k} (" + ", ".join(f"`{f}`" for f in fns) + ")"
                          for k, fns in task.needs.items())
        run = (f"`python -m pytest {test_file} --task {task.number}` or "
               f"`rtcourse grade --lab {lab.number} --task {task.number}`")
        lines.append(f"| {task.number} | {_cell(task.title)} | {_pts(task.points)} | "
                     f"{you_write} | {needs} | {run} |")
    return lines
