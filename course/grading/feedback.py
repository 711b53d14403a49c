"""The short feedback of a failing graded test: the message first, at most 15 lines.

A student needs the grader's teaching message (what was expected, what came back, where,
by how much) and the line of their own code that raised, not pytest's dump of the test's
source and its tensors. :func:`short_feedback` builds that text from a failure; the
grading plugin shows it in place of pytest's traceback (``-v`` brings the long one back),
``rtcourse grade`` prints the first of each task and ``results.json`` carries it.
"""

from __future__ import annotations

import re
import textwrap
from dataclasses import dataclass
from pathlib import Path

from course.grading.catalog import parse_not_implemented

MAX_LINES = 15  # lines of a failure's text, a long line counted once however it wraps
_MESSAGE_LINES = 10
_WRAP = 100  # columns: a long line is wrapped here, never cut (a hint ends where it ends)
_LINE_WIDTH = 4000  # a line longer than this is a dump, not a hint: only this is clipped
HINT = "(the full traceback with the test's source and tensors: add -v)"

# A frame of a traceback printed by Python (the worker's traceback travels as text).
_FRAME = re.compile(r'^\s*File "(?P<file>[^"]+)", line (?P<line>\d+), in (?P<name>\S+)\s*$')
# What a sandboxed error appends after the student's message (course.grading.sandbox).
_RAISED_IN = re.compile(r"\n\(raised in ([^;)]*)[;)]")
IMPORT_FAILED = "the lab module failed to import: "


@dataclass
class Feedback:
    text: str  # the short text, message first
    problem: str | None = None  # a submission problem shared by every test of a lab


def _clip(line: str) -> str:
    return line if len(line) <= _LINE_WIDTH else line[: _LINE_WIDTH - 3] + "..."


def _wrap(line: str) -> str:
    """``line`` wrapped at :data:`_WRAP` columns (whole words; continuation lines indented
    under the first), as one string: the caller counts it as one line."""
    if len(line) <= _WRAP:
        return line
    indent = line[: len(line) - len(line.lstrip())]
    return "\n".join(
        textwrap.wrap(
            line,
            _WRAP,
            subsequent_indent=indent + "  ",
            break_long_words=False,
            break_on_hyphens=False,
        )
    )


def _message_lines(text: str) -> list[str]:
    """The teaching part of an exception's text: without the worker's traceback and
    without the tensor dumps pytest's assertion rewriting adds (``+  where ...``)."""
    lines = []
    for i, line in enumerate(text.strip("\n").splitlines()):
        stripped = line.strip()
        if not stripped:
            continue
        if i and (stripped.startswith("+") or "tensor([" in line or "array([" in line):
            continue  # pytest's "+  where x = tensor([...])" explanations
        lines.append(_wrap(_clip(line.rstrip())))
    if len(lines) > _MESSAGE_LINES:
        more = len(lines) - _MESSAGE_LINES + 1
        lines = lines[: _MESSAGE_LINES - 1] + [f"... ({more} more lines with -v)"]
    return lines


def frame_in(frames, folder) -> str | None:
    """The last ``(file, line, function, source)`` frame inside ``folder``, formatted."""
    folder = Path(folder).resolve() if folder else None
    found = None
    for file, line, name, source in frames:
        try:
            path = Path(file).resolve()
        except (OSError, ValueError):
            continue
        if folder is not None and folder in path.parents:
            where = f"{folder.name}/{path.relative_to(folder).as_posix()}"
            found = f"{where}:{line} in {name}" + (f": {source.strip()}" if source else "")
    return _clip(found) if found else None


def text_frames(text: str) -> list[tuple[str, int, str, str]]:
    """Frames of a traceback printed as text (``File "...", line N, in fn`` + source)."""
    lines = text.splitlines()
    frames = []
    for i, line in enumerate(lines):
        match = _FRAME.match(line)
        if match:
            source = lines[i + 1] if i + 1 < len(lines) and not _FRAME.match(lines[i + 1]) else ""
            frames.append((match["file"], int(match["line"]), match["name"], source))
    return frames


def import_problem(module: str, text: str, folder) -> str:
    """One line for a lab file that failed to import: its error and the line."""
    message = text.split(IMPORT_FAILED, 1)[-1]
    head = _RAISED_IN.split(message)[0].strip().splitlines()
    head = head[0] if head else "an error"
    where = frame_in(text_frames(text), folder)
    line = ""
    syntax = re.search(r"\(([^()]*\.py), line (\d+)\)", head)
    if syntax:
        line = f" ({module}.py, line {syntax.group(2)})"
    elif where:
        line = f" (at {where})"
    return _clip(f"{module}.py failed to import: {head}{line}")


def short_feedback(
    *,
    exc: BaseException,
    frames,
    test_file,
    folder,
    task,
    task_of,
    lab_module: str = "",
    header: str = "",
) -> Feedback:
    """The short text of a failure.

    ``exc`` is the exception; ``frames`` the grader-side traceback as ``(file, line,
    function, source)``; ``test_file`` the grader's file; ``folder`` the submission's folder;
    ``task`` the task the test grades; ``task_of(fn)`` the task that asks for a lab
    function (None if unknown); ``header`` names the test and its task.
    """
    text = str(exc)
    kind = type(exc).__name__
    if isinstance(exc, NotImplementedError) or text.startswith("not implemented yet"):
        fn, stated = parse_not_implemented(text)
        if fn is not None:
            owner = stated if stated is not None else task_of(fn.split(".")[0])
            if owner is not None and task is not None and owner != task:
                return Feedback(
                    f"needs `{fn}` (task {owner}) first: this test of task {task} "
                    f"calls it, and it is not implemented yet"
                )
            return Feedback(
                f"task {owner if owner is not None else task}: write `{fn}` (not implemented yet)"
            )
    if IMPORT_FAILED in text:
        problem = import_problem(lab_module or "the lab", text, folder)
        return Feedback(problem, problem=problem)
    own = _RAISED_IN.split(text, maxsplit=1)
    message = own[0]
    if not isinstance(exc, AssertionError) and kind != "Failed" and not message.startswith(kind):
        message = f"{kind}: {message}"
    lines = ([header] if header else []) + _message_lines(message)
    yours = frame_in(text_frames(text), folder) or frame_in(frames, folder)
    if yours:
        lines.append(f"your code: {yours}")
    elif len(own) > 1:
        lines.append(f"raised in {own[1]}")
    grader = [f for f in frames if Path(f[0]).name == Path(test_file).name]
    if grader:
        lines.append(
            f"checked at {Path(test_file).parent.name}/{Path(test_file).name}:{grader[-1][1]}"
        )
    lines.append(HINT)
    if len(lines) > MAX_LINES:  # keep the hint line; the message lines are each whole
        lines = lines[: MAX_LINES - 1] + lines[-1:]
    return Feedback("\n".join(lines))
