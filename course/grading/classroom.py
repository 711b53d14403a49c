"""``rtcourse grade-class``: grade a whole class's submissions of one lab.

A folder of submissions in (one folder or zip per student, a Gradescope export, or the flat
files of Canvas, Moodle or Blackboard: :mod:`course.grading.classroom_layouts`); out, in
``--out``: ``gradebook.csv`` (a row per student: score, maximum, the score of every task,
status, seconds), ``feedback/<student>.txt`` (the text ``rtcourse grade`` shows a student),
``gradebook.json`` (every result, test by test) and a score histogram
(:mod:`course.grading.classroom_report`).

Fast: ``jobs`` warm grading processes (:mod:`course.grading.warm`) import torch, pytest
and the graders once and grade one student after another, each exactly as
``rtcourse grade --impl FOLDER`` does: the submission's code runs in its own sandboxed
worker process with the grader's time and memory limits, so a hostile or hanging
submission costs only its own row. What does not depend on a submission (the imports, the
graders' collection, the skeleton, the hash of the graders) is prepared once.

Nothing lost: each student's result is written, atomically, to ``students/<name>.json`` as
soon as it is graded, keyed by a hash of the submission's files and of everything that
grades it: the graders, skeleton, reference and options and every course module the
grading process had imported (:mod:`course.grading.classroom_keys`). Run again after an
interruption (Ctrl-C, a crash, a killed machine), the same command keeps every result whose
key still matches and grades only the rest: a changed submission or grader is graded
again. Submissions are only read: their lab files are copied to a scratch folder and
graded there. A grading run that ended abnormally (the grading process died or hung,
which the sandbox's limits should make impossible) is shown in the gradebook but never
kept, so the next run tries that student again.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import sys
import time
import zipfile
from pathlib import Path

from course.grading.classroom_keys import (
    graders_hash,
    imported_files,
    slug,
    submission_hash,
    unchanged,
)
from course.grading.classroom_layouts import Submission, describe, find_submissions

RESULT_VERSION = 1
_MAX_FILE = 2 * 2**20  # bytes: a larger "lab file" is not source code
_MAX_ZIP = 64 * 2**20  # bytes: a larger archive is not a lab submission
_MAX_MEMBERS = 2000
_KEPT = (".py", ".zip", ".yml")  # what a class folder's zip holds that grading reads
_CRASHED = "ended the worker process"  # the sandbox's message for a call that ended it
DEFAULT_STUDENT_TIMEOUT = 1800.0  # seconds: past the sandbox's own caps, a grader fault


# ---------------------------------------------------------------- copies


def _safe_member(name: str) -> str | None:
    """A zip member's path made relative and safe, or None for one to skip."""
    parts = [p for p in name.replace("\\", "/").split("/") if p not in ("", ".")]
    if (
        not parts
        or ".." in parts
        or ":" in parts[0]
        or any(p.startswith(".") or p == "__MACOSX" for p in parts)
    ):
        return None
    return "/".join(parts)


def extract_zip(path: Path, dest: Path, suffixes=(".py",)) -> int:
    """Extract the members of ``path`` ending in ``suffixes`` into ``dest``: never outside
    it, no links, none over the size limits. Returns how many were written; a zip that
    cannot be read writes none."""
    count = 0
    try:
        if path.stat().st_size > _MAX_ZIP:
            return 0
        with zipfile.ZipFile(path) as archive:
            for info in archive.infolist()[:_MAX_MEMBERS]:
                name = _safe_member(info.filename)
                limit = _MAX_ZIP if name and name.lower().endswith(".zip") else _MAX_FILE
                if (
                    info.is_dir()
                    or name is None
                    or info.file_size > limit
                    or not name.lower().endswith(suffixes)
                ):
                    continue
                target = dest / name
                target.parent.mkdir(parents=True, exist_ok=True)
                with archive.open(info) as src, open(target, "wb") as out:
                    out.write(src.read(limit + 1)[:limit])
                count += 1
    except (zipfile.BadZipFile, OSError, RuntimeError, ValueError, NotImplementedError):
        pass  # an unreadable archive hands in nothing: the grader says the lab is missing
    return count


def stage(sub: Submission, work: Path, module: str, skeletons: Path, collect) -> dict:
    """Copy ``sub``'s lab files into ``work/impl`` (what is graded) through ``work/raw``
    (its Python files and the contents of its zips): the submission is only read.
    ``collect(raw, impl, [module], skeletons)`` is the autograder's collection of a
    submission's lab files over the skeleton. Returns what it found."""
    raw, impl = work / "raw", work / "impl"
    shutil.rmtree(work, ignore_errors=True)
    raw.mkdir(parents=True)
    for name, path in sorted(sub.files.items()):
        safe = _safe_member(name)
        if safe is None or path.is_symlink() or not path.is_file():
            continue
        if safe.lower().endswith(".zip"):
            extract_zip(path, raw / safe[:-4])
        elif safe.lower().endswith(".py") and path.stat().st_size <= _MAX_FILE:
            target = raw / safe
            target.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(path, target, follow_symlinks=False)
    found = collect(raw, impl, [module], skeletons)
    return {name: str(path) if path else None for name, path in found.items()}


# ---------------------------------------------------------------- the warm process


def _tasks(data: dict) -> dict[str, list[float]]:
    """``"N.K"`` -> [score, max] summed over the task's tests."""
    table: dict[str, list[float]] = {}
    for test in data.get("tests", ()):
        row = table.setdefault(test.get("number") or "?", [0.0, 0.0])
        row[0] += test["score"]
        row[1] += test["max_score"]
    return {k: [round(s, 4), round(m, 4)] for k, (s, m) in sorted(table.items())}


def grade_job(spec: dict) -> dict:
    """Warm-process side: grade one staged submission as ``rtcourse grade --impl`` does
    (sandboxed), write its result file atomically and return a short outcome. A run that
    ended abnormally is returned with status ``error`` and not written."""
    import contextlib
    import io

    from course.grading.results import write_json_atomically
    from course.grading.runner import GradeError, grade

    started = time.monotonic()
    log = io.StringIO()
    data, error = None, ""
    with contextlib.redirect_stdout(log), contextlib.redirect_stderr(log):
        try:
            data = grade(
                spec["impl"],
                labs=[spec["lab"]],
                keyword=spec.get("keyword"),
                tasks=spec.get("tasks"),
                quiet=True,
                extra_args=spec.get("extra", ()),
            )
        except GradeError as exc:
            error = str(exc)
        except Exception as exc:  # noqa: BLE001 (a grader fault costs this row only)
            error = f"the grader failed: {type(exc).__name__}: {exc}"
    seconds = round(time.monotonic() - started, 2)
    record = dict(spec["meta"], seconds=seconds, version=RESULT_VERSION)
    if data is None or "ended abnormally" in data.get("output", ""):
        record.update(
            status="error",
            score=0.0,
            max_score=0.0,
            tasks={},
            problems=[],
            output=error or (data or {}).get("output", "") or log.getvalue()[-2000:],
            tests=[],
        )
        return {"status": "error", "record": record}
    problems = list(data.get("extra_data", {}).get("problems", ()))
    if not any(spec["meta"]["found"].values()):
        status = "missing"
    elif any("failed to import" in p for p in problems):
        status = "import failed"
    elif data["tests"] and all(_CRASHED in t.get("output", "") for t in data["tests"]):
        status = "crashed"  # e.g. os._exit at import: every call ended the process
    else:
        status = "graded"
    record.update(
        status=status,
        score=data["score"],
        max_score=data["max_score"],
        tasks=_tasks(data),
        problems=problems,
        output=data["output"],
        tests=data["tests"],
        graded_by=imported_files(Path.cwd().resolve()),
    )
    write_json_atomically(spec["result"], record)
    return {"status": status, "seconds": seconds}


# ---------------------------------------------------------------- the class


def lab_module(root: Path, lab: int) -> str:
    """The module name of lab ``lab`` (``lab4_march``), read from its graders."""
    from course.grading.catalog import lab_catalog
    from course.grading.runner import lab_test_files

    catalog = lab_catalog(lab_test_files(root, [lab]))
    if lab not in catalog:
        raise ValueError(f"no graders for lab {lab} in {root / 'tests'}")
    return catalog[lab].module


def _class_folder(submissions: Path, work: Path) -> Path:
    """The class folder itself, or a zip of it extracted into ``work`` (its Python files,
    zips and Gradescope metadata only)."""
    if submissions.is_dir():
        return submissions
    if submissions.is_file() and submissions.suffix.lower() == ".zip":
        folder = work / "class"
        shutil.rmtree(folder, ignore_errors=True)
        extract_zip(submissions, folder, _KEPT)
        tops = (
            [p for p in folder.iterdir() if not p.name.startswith(".")] if folder.is_dir() else []
        )
        return tops[0] if len(tops) == 1 and tops[0].is_dir() else folder
    raise ValueError(f"{submissions}: no such folder or zip of submissions")


def grading_env(device: str, jobs: int) -> dict:
    """The warm processes' environment. ``device="cpu"`` hides CUDA from the graders (and
    so from the sandboxed submissions they start): a class is graded in many short runs of
    small kernels, where starting CUDA in every process and launching tiny kernels costs
    more than the GPU saves (on an H100 machine, 100 students of Lab 2 took 80 s with CUDA
    hidden and over 170 s with it visible: bench/results/nvidia-h100-80gb-hbm3/grade_class/).
    Each process gets an equal share of the cores for torch."""
    env = dict(os.environ, RTCOURSE_PROGRESS="0", PYTHONUNBUFFERED="1")
    if device == "cpu":
        env["CUDA_VISIBLE_DEVICES"] = ""
    from course.core.device import allowed_cpus

    threads = str(max(1, allowed_cpus() // max(1, jobs)))
    for name in ("OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        env.setdefault(name, threads)
    return env


def grade_class(
    submissions,
    lab: int,
    *,
    collect,
    out=None,
    jobs: int | None = None,
    device: str = "cpu",
    tasks=None,
    keyword: str | None = None,
    time_limit: float | None = None,
    student_timeout: float = DEFAULT_STUDENT_TIMEOUT,
    say=print,
) -> dict:
    """Grade every submission of lab ``lab`` in the class folder (or zip) ``submissions``;
    write the gradebook, feedback and results into ``out`` (default ``grades/labN``) and
    return the summary (:func:`course.grading.classroom_report.write_reports`).

    ``collect``: the autograder's collection of a submission's lab files
    (``course.tools.gradescope.collect_submission``). ``jobs``: warm grading processes
    (default: the usable cores). ``device``: ``cpu`` (CUDA hidden, the default: see
    :func:`grading_env`) or ``auto`` (the graders' own choice). ``tasks``/``keyword``/
    ``time_limit``: as ``rtcourse grade``'s ``--task``/``-k``/``--time-limit``. Raises
    ValueError for a folder with no submissions or a lab with no graders; a
    KeyboardInterrupt propagates after the finished rows are written."""
    from course.core.device import allowed_cpus
    from course.core.files import repo_root
    from course.core.progress import progress
    from course.grading.classroom_report import write_reports
    from course.grading.runner import task_specs
    from course.grading.warm import run_pool

    if device not in ("cpu", "auto"):
        raise ValueError(f"--device {device}: expected cpu or auto")
    root = repo_root("rtcourse grade-class")
    out = Path(out or Path("grades") / f"lab{lab}").resolve()
    work = out / ".work"
    (out / "students").mkdir(parents=True, exist_ok=True)
    jobs = max(1, jobs or allowed_cpus())
    started = time.monotonic()

    folder = _class_folder(Path(submissions).expanduser().resolve(), work)
    subs, ignored = find_submissions(folder)
    say(f"layout: {describe(subs)} ({len(subs)} submissions in {folder})")
    if ignored:
        say(
            f"ignored {len(ignored)} entries that name no student: "
            f"{', '.join(ignored[:5])}{' ...' if len(ignored) > 5 else ''}"
        )
    module = lab_module(root, lab)
    extra = ["--time-limit", str(time_limit)] if time_limit else []
    options = {
        "lab": lab,
        "tasks": task_specs([lab], tasks),
        "keyword": keyword,
        "time_limit": time_limit,
        "device": device,
    }
    graders = graders_hash(root, lab, module, options)

    records, specs, hashes = {}, [], {}
    for sub in subs:
        name = slug(sub.key)
        result = out / "students" / f"{name}.json"
        key = hashlib.sha256((submission_hash(sub) + graders).encode()).hexdigest()
        try:
            kept = json.loads(result.read_text())
            if (
                kept.get("key") == key
                and kept.get("version") == RESULT_VERSION
                and unchanged(root, kept.get("graded_by", {}), hashes)
            ):
                records[name] = dict(kept, kept=True)
                continue
        except (OSError, ValueError):
            pass
        meta = {
            "student": sub.student,
            "sid": sub.sid,
            "kind": sub.kind,
            "source": sub.source,
            "key": key,
            "file": name,
        }
        specs.append(
            {
                "id": name,
                "result": str(result),
                "lab": lab,
                "keyword": keyword,
                "tasks": tasks,
                "extra": extra,
                "meta": meta,
                "sub": sub,
            }
        )
    if records:
        say(
            f"kept {len(records)} students graded by an earlier run (same files, same "
            f"graders); grading the other {len(specs)}"
        )
    for spec in specs:  # copies first: grading never reads the class folder
        sub = spec.pop("sub")
        spec["impl"] = str(work / spec["id"] / "impl")
        spec["meta"]["found"] = stage(sub, work / spec["id"], module, root / "labs", collect)

    def lost(job_id: str, why: str) -> dict:
        return {"status": "error", "why": f"the grading process {why}"}

    interrupted = False
    outcomes = []
    if specs:
        say(f"grading {len(specs)} submissions of lab {lab} with {jobs} worker(s), device {device}")
        env = grading_env(device, jobs)
        bar = progress(total=len(specs), desc=f"lab {lab}", unit="student", leave=True)
        try:
            outcomes = run_pool(
                specs,
                lambda j, r, tmp: [sys.executable, "-m", "course.grading.classroom", j, r],
                workers=jobs,
                cwd=root,
                env=env,
                deadline=student_timeout,
                lost=lost,
                tick=bar.update,
                scratch_prefix="rtcourse-class-",
            )
        except KeyboardInterrupt:
            interrupted = True
        finally:
            bar.close()
    for spec, outcome in zip(specs, outcomes):
        result = Path(spec["result"])
        if outcome.get("record"):  # graded abnormally: shown, not kept
            records[spec["id"]] = outcome["record"]
        elif outcome["status"] == "error" or not result.is_file():
            records[spec["id"]] = dict(
                spec["meta"],
                status="error",
                score=0.0,
                max_score=0.0,
                tasks={},
                problems=[],
                tests=[],
                seconds=0.0,
                output=outcome.get("why", ""),
            )
        else:
            records[spec["id"]] = json.loads(result.read_text())
    if interrupted:  # whatever finished before the interrupt was written: show it
        for spec in specs:
            result = Path(spec["result"])
            if spec["id"] not in records and result.is_file():
                records[spec["id"]] = json.loads(result.read_text())
    shutil.rmtree(work, ignore_errors=True)
    summary = write_reports(
        out,
        [records[k] for k in sorted(records)],
        lab=lab,
        total=len(subs),
        seconds=time.monotonic() - started,
        graded_now=len(outcomes),
        jobs=jobs,
        layout=describe(subs),
        say=say,
    )
    if interrupted:
        say(
            f"interrupted: {len(records)} of {len(subs)} students graded and kept; run the "
            f"same command again to grade the rest"
        )
        raise KeyboardInterrupt
    return summary


def main(argv=None) -> int:
    """``python -m course.grading.classroom JOBS RESULTS``: a warm grading process."""
    from course.grading import zygote
    from course.grading.warm import serve

    argv = sys.argv[1:] if argv is None else argv
    zygote.enable()  # every student's worker forked from one pre-imported process
    serve(argv[0], argv[1], grade_job)
    return 0


if __name__ == "__main__":
    sys.exit(main())
