"""Scores: collected from pytest reports in the checking process, written once.

The score comes only from the outcomes of the checks this process ran; a
submission's output, files or environment changes cannot add to it.
``results.json`` follows Gradescope's format and is written atomically. Each test's
output there is the short feedback of :mod:`course.grading.feedback` (message first, at
most ``OUTPUT_LIMIT`` characters of text); a test whose images differ also shows the
expected, the submitted and the difference picture inline (``output_format: "html"``).
"""

from __future__ import annotations

import base64
import html
import io
import json
import os
import tempfile
import time
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path

from course.core.labs import lab_number
from course.grading.feedback import HINT

OUTPUT_LIMIT = 1024  # characters of text per test in results.json
_PRINTED_LIMIT = 300  # of those, at most this much of what the submission printed
_THUMBNAIL = 128  # pixels: the inline pictures' longer side


@dataclass
class TestResult:
    nodeid: str
    lab: int | None
    lab_module: str
    task: int | None
    task_title: str
    max_score: float
    score: float = 0.0
    status: str = "failed"
    output: str = ""
    duration: float = 0.0
    visibility: str = "visible"
    message: str = ""  # the short feedback of its first failure
    printed: str = ""  # what the submission printed while it ran
    pictures: list = field(default_factory=list)  # expected, got, difference PNGs
    problem: str = ""  # the submission problem that failed it (missing/broken lab file)


def _lab_number(module_name: str):
    return lab_number(module_name)


def _cap(text: str, limit: int) -> str:
    """``text`` cut to ``limit`` characters from its start (the message comes first)."""
    if len(text) <= limit:
        return text
    return text[: limit - 18].rstrip() + "\n... (cut short)"


def _properties(report) -> dict:
    return dict(getattr(report, "user_properties", ()) or ())


def _thumbnail_html(path: str) -> str:
    """An inline ``<img>`` of a small copy of the PNG at ``path`` ("" if unreadable)."""
    try:
        from PIL import Image

        with Image.open(path) as image:
            image.thumbnail((_THUMBNAIL, _THUMBNAIL), Image.NEAREST)
            buffer = io.BytesIO()
            image.save(buffer, format="PNG", optimize=True)
    except (OSError, ValueError):
        return ""
    data = base64.b64encode(buffer.getvalue()).decode("ascii")
    title = html.escape(Path(path).stem)
    # Plain tags only: Gradescope sanitises HTML output and may drop styling.
    return (
        f'<span>{title}: <img alt="{title}" width="{_THUMBNAIL}" '
        f'src="data:image/png;base64,{data}"></span> '
    )


@dataclass(eq=False)  # hashable: pluggy keeps plugins in sets
class ScoreKeeper:
    """A pytest plugin object: pass it to ``pytest.main(plugins=[...])``."""

    results: dict = field(default_factory=dict)
    started: float = field(default_factory=time.monotonic)
    problems: dict = field(default_factory=dict)  # submission problems, each said once
    collect_errors: list = field(default_factory=list)  # graders that failed to load
    graded_files: dict = field(default_factory=dict)  # lab module -> what was graded as it
    show_progress: bool = True
    progress_stream: object = None  # where the bars go (course.core.progress.terminal_stream)
    _bar: object = None
    _bar_lab: object = None
    _left: dict = field(default_factory=dict)  # lab -> tests still to report

    def pytest_collection_finish(self, session):
        # After -k/-m deselection: only the tests that run count.
        # points(n) is worth n for the test function, split over its parametrisations,
        # so a machine with CUDA (two devices) has the same maximum as one without.
        items = session.items
        counts = defaultdict(int)
        for item in items:
            if item.get_closest_marker("points") is not None:
                counts[(item.module.__name__, item.originalname)] += 1
        for item in items:
            marker = item.get_closest_marker("points")
            if marker is None:
                continue
            task = item.get_closest_marker("task")
            task_no = task.args[0] if task else None
            lab_module = getattr(item.module, "LAB_MODULE", "")
            titles = getattr(item.module, "TASKS", {})
            hidden = item.get_closest_marker("visibility")
            self.results[item.nodeid] = TestResult(
                nodeid=item.nodeid,
                lab=_lab_number(lab_module),
                lab_module=lab_module,
                task=task_no,
                task_title=titles.get(task_no, ""),
                max_score=marker.args[0] / counts[(item.module.__name__, item.originalname)],
                visibility=hidden.args[0] if hidden else "visible",
            )
        self._left = defaultdict(int)
        for r in self.results.values():
            self._left[r.lab] += 1
        self.graded_files = self._graded_files(session.config)

    def _graded_files(self, config) -> dict:
        """Each graded lab module -> the file(s) graded as it, as the student handed them in
        (``course.grading.plugin.graded_as``); a lab not handed in is left out."""
        try:
            from course.grading.plugin import graded_as, resolve_impl

            folder, _ = resolve_impl(config)
        except (ImportError, ValueError, AttributeError):
            return {}
        found = {}
        for module in sorted(
            {r.lab_module for r in self.results.values() if r.lab_module},
            key=lambda m: (_lab_number(m) or 0, m),
        ):
            shown = graded_as(folder, module)
            if shown is not None:
                found[module] = shown
        return found

    def pytest_collectreport(self, report):
        if report.failed:
            text = report.longreprtext.strip().splitlines()
            self.collect_errors.append(f"{report.nodeid}: " + (text[-1] if text else "error"))

    def pytest_runtest_logreport(self, report):
        result = self.results.get(report.nodeid)
        if result is None:
            return
        result.duration += report.duration
        props = _properties(report)
        if report.failed:
            first = result.status != "failed" or not result.message
            result.status, result.score = "failed", 0.0
            if first:
                result.message = props.get("feedback") or _cap(report.longreprtext, 600)
                result.pictures = list(props.get("pictures", ()))
            if props.get("problem"):
                result.problem = props["problem"]
                self.problems.setdefault(result.lab_module, props["problem"])
            for title, content in report.sections:
                if "submission output" in title:
                    result.printed += content
        elif report.skipped:
            # Skipped for lack of hardware or time: not part of this grading run.
            result.status = "skipped"
        elif report.when == "call":
            result.status, result.score = "passed", result.max_score
        if report.when == "teardown" or (report.when == "setup" and not report.passed):
            self._advance(result)
        result.output = self._output(result)

    def _advance(self, result):
        """One more test of ``result``'s lab reported: the lab's progress bar moves on."""
        if not self.show_progress:
            return
        from course.core.progress import progress

        if self._bar_lab != result.lab:
            self.close_progress()
            self._bar = progress(
                total=self._left.get(result.lab, 0),
                desc=f"lab {result.lab}",
                unit="test",
                file=self.progress_stream,
            )
            self._bar_lab = result.lab
        self._bar.update(1)

    def close_progress(self):
        if self._bar is not None:
            self._bar.close()
        self._bar, self._bar_lab = None, None

    def pytest_sessionfinish(self, session):
        self.close_progress()

    @staticmethod
    def _output(result: TestResult) -> str:
        """The test's text for results.json: the message first, at most OUTPUT_LIMIT."""
        if result.status != "failed":
            return ""
        text = result.message
        if result.printed.strip():
            printed = _cap(result.printed.strip(), _PRINTED_LIMIT)
            text += f"\n--- what your code printed ---\n{printed}"
        return _cap(text, OUTPUT_LIMIT)

    # ---------------------------------------------------------------- reports
    def graded(self) -> list[TestResult]:
        return [r for r in self.results.values() if r.status != "skipped"]

    def totals(self):
        graded = self.graded()
        return sum(r.score for r in graded), sum(r.max_score for r in graded)

    def table(self) -> str:
        """Per task: tests passed and points; under each task that lost points, the
        message of its first failure. Submission problems come first, once each."""
        rows = defaultdict(lambda: [0.0, 0.0, 0, 0, "", ""])
        for r in self.graded():
            row = rows[(r.lab, r.task)]
            row[0] += r.score
            row[1] += r.max_score
            row[2] += r.status == "passed"
            row[3] += 1
            row[4] = r.task_title
            if r.status == "failed" and not row[5] and not r.problem:
                row[5] = r.message
        lines = []
        if self.graded_files:
            lines += [
                "files graded: "
                + "; ".join(
                    f"lab {_lab_number(m)}: {shown}" for m, shown in self.graded_files.items()
                ),
                "",
            ]
        if self.problems or self.collect_errors:
            lines += ["submission problems (each fails every test of its lab):"]
            lines += [f"  {text}" for text in self.problems.values()]
            lines += [f"  grader not loaded: {text}" for text in self.collect_errors]
            lines.append("")
        width = max([len("title"), *(len(row[4]) for row in rows.values())])  # never clipped
        lines += [f"{'lab':>3}  {'task':>4}  {'title':<{width}} {'passed':>9}  {'score':>13}"]
        by_lab = defaultdict(lambda: [0.0, 0.0])
        for (lab, task), (score, top, passed, count, title, message) in sorted(
            rows.items(), key=lambda kv: (kv[0][0] or 0, kv[0][1] or 0)
        ):
            lines.append(
                f"{lab!s:>3}  {task!s:>4}  {title:<{width}} {passed:>4}/{count:<4}  "
                f"{score:>6.2f}/{top:<6.2f}"
            )
            if message:
                body = [line for line in message.splitlines() if line != HINT]
                lines += [f"{'':11}{line}" for line in body]  # bounded by feedback
            by_lab[lab][0] += score
            by_lab[lab][1] += top
        lines.append("")
        for lab, (score, top) in sorted(by_lab.items(), key=lambda kv: kv[0] or 0):
            lines.append(f"lab {lab}: {score:.2f} / {top:.2f}")
        score, top = self.totals()
        lines.append(f"total: {score:.2f} / {top:.2f}")
        return "\n".join(lines)

    def to_gradescope(self) -> dict:
        score, top = self.totals()
        tests = []
        for r in self.graded():
            number = f"{r.lab}.{r.task}" if r.lab is not None else ""
            name = r.nodeid.split("::", 1)[-1]
            label = f"Lab {r.lab} task {r.task}"
            if r.task_title:
                label += f" ({r.task_title})"
            test = {
                "name": f"{label}: {name}",
                "number": number,
                # Unrounded: a task's points split over 66 parametrised tests (cpu and
                # cuda) rounded one by one drift by 4e-4 from the task's points.
                "score": r.score,
                "max_score": r.max_score,
                "status": "passed" if r.status == "passed" else "failed",
                "output": r.output,
                "visibility": r.visibility,
            }
            pictures = [_thumbnail_html(p) for p in r.pictures] if r.output else []
            if any(pictures):
                test["output"] = f"<pre>{html.escape(r.output)}</pre><div>{''.join(pictures)}</div>"
                test["output_format"] = "html"
            tests.append(test)
        return {
            "score": round(score, 4),
            "max_score": round(top, 4),
            "execution_time": round(time.monotonic() - self.started, 2),
            "output": self.table(),
            "tests": tests,
            "extra_data": {
                "graded_files": dict(self.graded_files),
                # each failing every test of its lab: a missing file, an import that failed
                "problems": [*self.problems.values(), *self.collect_errors],
            },
        }


def write_json_atomically(path, data: dict):
    """Write ``data`` so that readers see either the old file or the whole new one."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=".results-", dir=path.parent)
    try:
        with os.fdopen(fd, "w") as f:
            json.dump(data, f, indent=2)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
