"""``rtcourse release OUT``: the student handout.

Everything a student needs and nothing they must not see: the reference
solutions, the mutants and the tests of the course itself stay behind. In the
handout the graders default to ``labs/`` because there is no ``solutions/``.
"""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

# Paths (relative to the repository root) that never ship to students.
WITHHELD = ("solutions", "tests/meta", ".git", ".venv", ".ci", "out", "build", "dist")
_IGNORED_NAMES = ("__pycache__", ".pytest_cache", ".ruff_cache", ".ipynb_checkpoints",
                  "*.egg-info", "results.json")


def _tracked_files(root: Path) -> list[Path] | None:
    try:
        out = subprocess.run(["git", "ls-files", "--cached", "--others", "--exclude-standard"],
                             cwd=root, capture_output=True, text=True, check=True).stdout
    except (OSError, subprocess.CalledProcessError):
        return None
    return [Path(line) for line in out.splitlines() if line]


def _withheld(rel: Path) -> bool:
    parts = rel.as_posix()
    return any(parts == w or parts.startswith(w + "/") for w in WITHHELD)


def release(root, out) -> list[Path]:
    """Copy the handout of the course at ``root`` into ``out``; return the files written."""
    root, out = Path(root).resolve(), Path(out).resolve()
    if out == root or root in out.parents and not _withheld(out.relative_to(root)):
        raise ValueError(f"out: the handout folder {out} must lie outside the course folder")
    files = _tracked_files(root)
    if files is None:  # not a git checkout: walk the tree instead
        ignore = shutil.ignore_patterns(*_IGNORED_NAMES)
        files = []
        for path in root.rglob("*"):
            rel = path.relative_to(root)
            if path.is_file() and not _withheld(rel) and not ignore(str(path.parent),
                                                                     [path.name]):
                files.append(rel)
    written = []
    for rel in files:
        if _withheld(rel) or not (root / rel).is_file():
            continue
        dest = out / rel
        dest.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(root / rel, dest)
        written.append(rel)
    return written
