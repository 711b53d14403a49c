"""Scores: collected from pytest reports in the checking process, written once.

The score comes only from the outcomes of the checks this process ran; a
submission's output, files or environment changes cannot add to it.
``results.json`` follows Gradescope's format and is written atomically.
"""

from __future__ import annotations

import json
import os
import re
import tempfile
import time
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path

_OUTPUT_LIMIT = 6000


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


def _lab_number(module_name: str):
    match = re.match(r"lab(\d+)_", module_name or "")
    return int(match.group(1)) if match else None


def _short(text: str) -> str:
    if len(text) <= _OUTPUT_LIMIT:
        return text
    return text[:_OUTPUT_LIMIT // 2] + "\n...\n" + text[-_OUTPUT_LIMIT // 2:]


@dataclass
class ScoreKeeper:
    """A pytest plugin object: pass it to ``pytest.main(plugins=[...])``."""

    results: dict = field(default_factory=dict)
    started: float = field(default_factory=time.monotonic)

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
                nodeid=item.nodeid, lab=_lab_number(lab_module), lab_module=lab_module,
                task=task_no, task_title=titles.get(task_no, ""),
                max_score=marker.args[0] / counts[(item.module.__name__, item.originalname)],
                visibility=hidden.args[0] if hidden else "visible",
            )

    def pytest_runtest_logreport(self, report):
        result = self.results.get(report.nodeid)
        if result is None:
            return
        result.duration += report.duration
        if report.failed:
            result.status, result.score = "failed", 0.0
            text = report.longreprtext
            for title, content in report.sections:
                if "submission output" in title:
                    text += f"\n--- {title} ---\n{content}"
            result.output = _short(result.output + text)
        elif report.skipped:
            # Skipped for lack of hardware or time: not part of this grading run.
            result.status = "skipped"
        elif report.when == "call":
            result.status, result.score = "passed", result.max_score

    # ---------------------------------------------------------------- reports
    def graded(self) -> list[TestResult]:
        return [r for r in self.results.values() if r.status != "skipped"]

    def totals(self):
        graded = self.graded()
        return sum(r.score for r in graded), sum(r.max_score for r in graded)

    def table(self) -> str:
        rows = defaultdict(lambda: [0.0, 0.0, 0, 0, ""])
        for r in self.graded():
            row = rows[(r.lab, r.task)]
            row[0] += r.score
            row[1] += r.max_score
            row[2] += r.status == "passed"
            row[3] += 1
            row[4] = r.task_title
        lines = [f"{'lab':>3}  {'task':>4}  {'title':<34} {'passed':>9}  {'score':>13}"]
        by_lab = defaultdict(lambda: [0.0, 0.0])
        for (lab, task), (score, top, passed, count, title) in sorted(
                rows.items(), key=lambda kv: (kv[0][0] or 0, kv[0][1] or 0)):
            lines.append(f"{lab!s:>3}  {task!s:>4}  {title[:34]:<34} {passed:>4}/{count:<4}  "
                         f"{score:>6.2f}/{top:<6.2f}")
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
            tests.append({
                "name": f"{label}: {name}", "number": number,
                # Unrounded: a task's points split over 66 parametrised tests (cpu and
                # cuda) rounded one by one drift by 4e-4 from the task's points.
                "score": r.score, "max_score": r.max_score,
                "status": "passed" if r.status == "passed" else "failed",
                "output": r.output, "visibility": r.visibility,
            })
        return {"score": round(score, 4), "max_score": round(top, 4),
                "execution_time": round(time.monotonic() - self.started, 2),
                "output": self.table(), "tests": tests}


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

