"""Who runs the submission: the worker user (``RTCOURSE_WORKER_USER``), what of the grader's
environment and files it never sees, and the check that it can run the grader's interpreter
before any grading (an interpreter under a mode-700 home would fail every test as if the
student's code had: never a score, one line and exit 2 instead)."""

from __future__ import annotations

import os
import subprocess
import sys


def _as_user(name: str | None):
    """(uid, gid) the submission runs as (None when unset)."""
    if not name:
        return None
    import pwd

    try:
        entry = pwd.getpwnam(name)
    except KeyError:
        raise RuntimeError(f"RTCOURSE_WORKER_USER={name}: no such user") from None
    if os.geteuid() != 0:
        raise RuntimeError(
            f"RTCOURSE_WORKER_USER={name}: only a grader running as root can "
            f"start the worker as another user"
        )
    return entry.pw_uid, entry.pw_gid


# Names of the grader's environment the worker never sees: where the results and the
# submission lie, the test node running (a hidden test's name) and the course's own paths.
SCRUBBED = (
    "RTCOURSE_RESULTS_DIR",
    "RTCOURSE_SUBMISSION_DIR",
    "RTCOURSE_TEST_RESULTS",
    "RTCOURSE_TEST_CWD",
    "RTCOURSE_FAILURE_DIR",
    "RTCOURSE_PYTHON",
    "PYTEST_CURRENT_TEST",
    "PYTEST_ADDOPTS",
    "OLDPWD",
)
# What the worker user must import for grading to mean anything: a few modules of the
# standard library that the course and its dependencies import lazily, and the course.
WORKER_IMPORTS = (
    "html",
    "json",
    "email.message",
    "decimal",
    "fractions",
    "sqlite3",
    "xml.etree.ElementTree",
    "numpy",
    "torch",
    "scipy",
    "matplotlib",
    "trimesh",
    "networkx",
    "PIL",
    "mpmath",
    "tqdm",
    "course.grading.worker",
)


def worker_env() -> dict:
    """The grader's environment less what the worker must not see."""
    return {k: v for k, v in os.environ.items() if k not in SCRUBBED}


def withhold(root) -> list[str]:
    """As root with a worker user: take every right of other users on the hidden graders
    and the references of the course at ``root``; return the folders changed."""
    if root is None or not os.environ.get("RTCOURSE_WORKER_USER") or os.geteuid() != 0:
        return []
    changed = []
    for sub in ("tests/hidden", "solutions"):
        path = os.path.join(str(root), sub)
        if os.path.isdir(path) and os.stat(path).st_mode & 0o077:
            os.chmod(path, os.stat(path).st_mode & 0o700)
            changed.append(path)
    return changed


def worker_python_problem(user: str | None = None, python: str | None = None) -> str | None:
    """One line saying why ``user`` (default ``RTCOURSE_WORKER_USER``) cannot run the
    worker's interpreter and import what grading needs, or None when it can (or when no
    other user runs the worker)."""
    user = os.environ.get("RTCOURSE_WORKER_USER") if user is None else user
    if not user:
        return None
    uid, gid = _as_user(user)
    python = python or sys.executable
    code = (
        "import importlib, sys\n"
        f"for name in {WORKER_IMPORTS!r}:\n"
        "    try:\n        importlib.import_module(name)\n"
        "    except ImportError as exc:\n"
        "        sys.exit(f'cannot import {name}: {exc}')\n"
    )
    why = None
    try:
        proc = subprocess.run(
            [python, "-c", code],
            user=uid,
            group=gid,
            extra_groups=[],
            cwd="/",
            env=worker_env(),
            stdin=subprocess.DEVNULL,
            capture_output=True,
            text=True,
            timeout=300,
            check=False,
        )
        if proc.returncode != 0:
            lines = (proc.stderr or proc.stdout).strip().splitlines()
            why = lines[-1] if lines else f"exit status {proc.returncode}"
    except (OSError, subprocess.SubprocessError) as exc:
        why = f"{type(exc).__name__}: {exc}"
    if why is None:
        return None
    return (
        f"the worker user {user} cannot run the grader's Python {python} ({why[:200]}): "
        f"install the course in an interpreter under /usr or /opt, or make this one and "
        f"its packages readable by {user} (chmod -R o+rX on its folder and o+x on the "
        f"folders above it), or set RTCOURSE_WORKER_USER= (empty) to run the submission "
        f"as the grader's own user, which gives up hiding the reference solutions, the "
        f"hidden tests and the results from it"
    )


def main(argv=None) -> int:
    """``python -m course.grading.sandbox check-worker [USER]``: exit 2 with one line when
    the worker user cannot run this interpreter (run_autograder runs it before grading)."""
    argv = sys.argv[1:] if argv is None else argv
    if not argv or argv[0] != "check-worker":
        print("usage: python -m course.grading.sandbox check-worker [USER]", file=sys.stderr)
        return 2
    try:
        problem = worker_python_problem(argv[1] if len(argv) > 1 else None)
    except RuntimeError as exc:
        problem = str(exc)
    if problem:
        print(f"rtcourse: {problem}", file=sys.stderr)
        return 2
    return 0
