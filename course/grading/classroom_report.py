"""What ``rtcourse grade-class`` writes once a class is graded, and the summary it prints.

In the output folder:

* ``gradebook.csv``: a row per student (``student, sid, score, max``, one column per task
  ``N.K``, ``status, seconds, source``), written atomically (a temporary file, then
  ``os.replace``): a reader sees the old gradebook or the whole new one;
* ``feedback/<student>.txt``: the score table ``rtcourse grade`` shows a student;
* ``gradebook.json``: every record, test by test;
* ``histogram.png`` and ``summary.txt``: the score histogram, the submissions that failed
  to import and the slowest ones.

Statuses: ``graded``; ``import failed`` (a lab file that does not import); ``crashed``
(every call ended the sandbox's process: ``os._exit`` or a crash at import); ``missing``
(no lab file in the submission); ``error`` (the grading run itself ended abnormally: not
kept, graded again by the next run).
"""

from __future__ import annotations

import csv
import io
import json
import os
import tempfile
from pathlib import Path

_BINS = 10
_BAR = 40  # characters of the longest histogram bar


def write_atomically(path: Path, text: str):
    """Write ``text`` so that readers see either the old file or the whole new one."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}-", dir=path.parent)
    try:
        with os.fdopen(fd, "w", newline="") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def _task_order(key: str):
    parts = key.split(".")
    return tuple(int(p) if p.isdigit() else 10**6 for p in parts)


def gradebook_csv(records: list[dict]) -> str:
    """The gradebook's text: a header and a row per record, tasks in lab/task order."""
    tasks = sorted({t for r in records for t in r.get("tasks", {})}, key=_task_order)
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(["student", "sid", "score", "max", *tasks, "status", "seconds", "source"])
    for r in records:
        writer.writerow(
            [
                r["student"],
                r.get("sid", ""),
                f"{r['score']:g}",
                f"{r['max_score']:g}",
                *(f"{r['tasks'][t][0]:g}" if t in r.get("tasks", {}) else "" for t in tasks),
                r["status"],
                f"{r.get('seconds', 0.0):.1f}",
                r.get("source", ""),
            ]
        )
    return buffer.getvalue()


def histogram(scores: list[float], top: float) -> list[tuple[float, float, int]]:
    """``(low, high, count)`` of ``_BINS`` equal bins over ``[0, top]``; full marks fall in
    the last bin."""
    counts = [0] * _BINS
    for score in scores:
        i = int(score / top * _BINS) if top > 0 else 0
        counts[min(max(i, 0), _BINS - 1)] += 1
    step = top / _BINS if top > 0 else 0.0
    return [(i * step, (i + 1) * step, n) for i, n in enumerate(counts)]


def histogram_text(bins) -> list[str]:
    peak = max((n for *_, n in bins), default=0) or 1
    return [
        f"  {low:6.2f} - {high:6.2f} | {'#' * round(n / peak * _BAR):<{_BAR}} {n}"
        for low, high, n in bins
    ]


def histogram_png(path: Path, scores: list[float], top: float, title: str) -> bool:
    """The histogram as a picture (matplotlib without a display); False if it failed."""
    try:
        import matplotlib

        matplotlib.use("Agg", force=False)
        from matplotlib.figure import Figure

        figure = Figure(figsize=(6, 3.5))
        axes = figure.subplots()
        axes.hist(scores, bins=_BINS, range=(0, top or 1), color="#4c72b0", edgecolor="white")
        axes.set_xlabel("score")
        axes.set_ylabel("students")
        axes.set_title(title)
        figure.tight_layout()
        fd, tmp = tempfile.mkstemp(prefix=".histogram-", suffix=".png", dir=path.parent)
        os.close(fd)
        figure.savefig(tmp, dpi=100)
        os.replace(tmp, path)
        return True
    except Exception:  # noqa: BLE001 (a picture must never cost the gradebook)
        return False


def write_reports(
    out: Path,
    records: list[dict],
    *,
    lab: int,
    total: int,
    seconds: float,
    graded_now: int,
    jobs: int,
    layout: str,
    say=print,
) -> dict:
    """Write every output of the module docstring for ``records`` (sorted by student) into
    ``out``, print the summary through ``say`` and return it as a dict."""
    from course.grading.results import write_json_atomically

    records = sorted(records, key=lambda r: (r["student"], r.get("sid", ""), r["file"]))
    write_atomically(out / "gradebook.csv", gradebook_csv(records))
    for r in records:
        head = f"{r['student']}" + (f" ({r['sid']})" if r.get("sid") else "")
        head += f": lab {lab}, {r['score']:g} / {r['max_score']:g} ({r['status']})"
        write_atomically(
            out / "feedback" / f"{r['file']}.txt", f"{head}\n\n{r.get('output', '')}\n"
        )
    top = max((r["max_score"] for r in records), default=0.0)
    scores = [r["score"] for r in records if r["status"] != "error"]
    bins = histogram(scores, top)
    failed = [r for r in records if r["status"] in ("import failed", "crashed")]
    slowest = sorted(
        (r for r in records if not r.get("kept")), key=lambda r: -r.get("seconds", 0.0)
    )[:5]
    rate = graded_now / seconds * 60 if seconds > 0 else 0.0
    lines = [
        f"lab {lab}: {len(records)} of {total} students graded ({graded_now} in this "
        f"run, {len(records) - graded_now} kept) in {seconds:.1f} s with {jobs} "
        f"worker(s): {rate:.1f} students/minute",
        f"layout: {layout}",
        f"scores (of {top:g}):",
        *histogram_text(bins),
    ]
    counts = {
        s: sum(r["status"] == s for r in records)
        for s in ("graded", "import failed", "crashed", "missing", "error")
    }
    lines.append("status: " + ", ".join(f"{n} {s}" for s, n in counts.items() if n))
    if failed:
        lines.append(f"failed to import or crashed on every call ({len(failed)}):")
        lines += [
            f"  {r['student']}: "
            + (
                r["problems"]
                or ["every call ended the sandbox's process (os._exit or a crash at import?)"]
            )[0][:160]
            for r in failed
        ]
    errors = [r for r in records if r["status"] == "error"]
    if errors:
        lines.append(f"not graded, tried again next run ({len(errors)}):")
        lines += [f"  {r['student']}: {r.get('output', '')[:160]}" for r in errors]
    if slowest:
        lines.append(
            "slowest: " + ", ".join(f"{r['student']} {r.get('seconds', 0):.1f} s" for r in slowest)
        )
    picture = histogram_png(out / "histogram.png", scores, top, f"lab {lab}: scores")
    lines.append(
        f"wrote {out / 'gradebook.csv'}, {out / 'gradebook.json'}, "
        f"{out / 'feedback'}/ ({len(records)} files)"
        + (f", {out / 'histogram.png'}" if picture else "")
    )
    text = "\n".join(lines)
    write_atomically(out / "summary.txt", text + "\n")
    summary = {
        "lab": lab,
        "students": len(records),
        "total": total,
        "graded_now": graded_now,
        "seconds": round(seconds, 2),
        "jobs": jobs,
        "students_per_minute": round(rate, 2),
        "layout": layout,
        "histogram": bins,
        "status": counts,
        "failed_to_import": [r["student"] for r in failed],
        "slowest": [[r["student"], r.get("seconds", 0.0)] for r in slowest],
    }
    write_json_atomically(
        out / "gradebook.json",
        {
            "summary": summary,
            "students": [{k: v for k, v in r.items() if k != "kept"} for r in records],
        },
    )
    say(text)
    return summary


def read_gradebook(path) -> list[dict]:
    """The rows of a ``gradebook.csv`` (for tools and tests)."""
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def load_results(out) -> dict:
    """``gradebook.json`` of an output folder."""
    return json.loads(Path(out, "gradebook.json").read_text())
