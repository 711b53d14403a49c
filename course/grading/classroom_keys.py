"""The keys that let ``rtcourse grade-class`` keep a student's result across runs.

A result is kept while the submission's files, what grades it and the options are the
same: :func:`submission_hash` (names and bytes of the student's files), :func:`graders_hash`
(what is known before grading: graders, skeleton, reference, meshes, options) and, per
result, :func:`imported_files` (the course modules the grading process had imported,
each with its hash, checked again by :func:`unchanged`).
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import sys
from pathlib import Path

from course.grading.classroom_layouts import Submission


def _digest(items) -> str:
    """sha256 of ``(name, path or bytes)`` pairs, in order; links hash as their target."""
    h = hashlib.sha256()
    for name, item in items:
        h.update(name.encode() + b"\0")
        if isinstance(item, bytes):
            h.update(item)
        elif Path(item).is_symlink():
            h.update(b"link:" + os.readlink(item).encode())
        else:
            with open(item, "rb") as f:
                for block in iter(lambda: f.read(1 << 20), b""):
                    h.update(block)
        h.update(b"\0")
    return h.hexdigest()


def submission_hash(sub: Submission) -> str:
    """The hash of a submission's files (names and bytes)."""
    return _digest(sorted(sub.files.items()))


def graders_hash(root: Path, lab: int, module: str, options: dict) -> str:
    """The hash of what grades lab ``lab`` and is known before grading: its graders (hidden
    ones too), the tests' conftest, pyproject (pytest's options), the course's meshes, the
    skeleton and the reference the grader reads, and the grading ``options``. The course
    modules the grading process imported are hashed apart, per result
    (:func:`imported_files`), so an edit to a course module that does not grade this lab
    regrades nothing."""
    from course.core.files import lab_source, module_files
    from course.grading.runner import lab_test_files

    files = [*lab_test_files(root, [lab]), root / "tests" / "conftest.py", root / "pyproject.toml"]
    files += sorted(p for p in (root / "course" / "assets").glob("*") if p.is_file())
    for folder in ("labs", "solutions"):
        source = lab_source(root / folder, module)
        files += module_files(source) if source is not None else []
    items = [(p.relative_to(root).as_posix(), p) for p in files if p.is_file()]
    items.append(("options", json.dumps(options, sort_keys=True).encode()))
    return _digest(items)


def file_hash(path) -> str:
    return _digest([("", Path(path))])


def imported_files(root: Path) -> dict[str, str]:
    """Every module of the course and of its tests this process has imported -> its hash:
    the code that graded, read after grading."""
    found = {}
    for module in list(sys.modules.values()):
        name = getattr(module, "__file__", None)
        if not name:
            continue
        path = Path(name).resolve()
        for top in ("course", "tests"):
            if path.is_relative_to(root / top) and path.is_file():
                found[path.relative_to(root).as_posix()] = file_hash(path)
    return dict(sorted(found.items()))


def unchanged(root: Path, files: dict, cache: dict) -> bool:
    """Whether every file of ``files`` (relative name -> hash) still has that hash."""
    for name, digest in files.items():
        if name not in cache:
            path = root / name
            cache[name] = file_hash(path) if path.is_file() else None
        if cache[name] != digest:
            return False
    return True


def slug(key: str) -> str:
    """A file name for a student's row: readable, and distinct for distinct keys."""
    text = re.sub(r"[^A-Za-z0-9._-]+", "_", key).strip("._")[:60] or "student"
    return f"{text}-{hashlib.sha256(key.encode()).hexdigest()[:8]}"
