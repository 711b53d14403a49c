"""``rtcourse gradescope OUT.zip``: the course as a Gradescope autograder.

The zip holds, at its top level, what Gradescope asks for::

    setup.sh          run once to build the image: installs CPU torch and the course
    run_autograder    run per submission: collect the lab files, grade them, write results
    rtcourse/         the course: course/, tests/ (with tests/hidden/), labs/, solutions/

``run_autograder`` copies the student's lab files out of the submission (wherever they lie
in it: at the top, under ``labs/``, ...) into a fresh folder: each ``labN_topic.py``, and of
a lab kept as a package the files handed in, laid over the skeleton package
(:func:`collect_submission`). Then it runs
``rtcourse grade --impl FOLDER --json RESULTS/results.json``. The submission is never
trusted: it runs in the sandboxed worker, and, when the autograder runs as root (as on
Gradescope), as the unprivileged user ``rtcourse-student`` that setup.sh creates, which
cannot read the reference solutions. A lab that was not submitted, or fails to import,
scores 0; hidden tests reach results.json with their ``visibility``.

``run_autograder`` sizes torch's thread pools to the container's CPU quota (Gradescope
gives half a CPU by default; torch would start one thread per host core) and sets
glibc's malloc to return large freed blocks (``MALLOC_ARENA_MAX=2``,
``MALLOC_MMAP_THRESHOLD_=1048576``); the memory and CPU each lab needs are in
:mod:`course.grading.budget`, and ``rtcourse gradescope`` prints them.

Environment overrides (for trying the package locally; Gradescope needs none):
``RTCOURSE_SUBMISSION_DIR`` (default /autograder/submission), ``RTCOURSE_RESULTS_DIR``
(/autograder/results), ``RTCOURSE_PYTHON`` (python3), ``RTCOURSE_WORKER_USER``; for
setup.sh ``PYTHON``, ``TORCH_SPEC`` (torch==2.13.0) and ``TORCH_INDEX`` (PyTorch's CPU
wheel index; empty for pip's default).
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import zipfile
from pathlib import Path

from course.core.files import lab_source, module_files
from course.grading.catalog import SUBMISSION_MANIFEST, lab_catalog, lab_file_rank
from course.grading.runner import lab_test_files
from course.tools.release import course_files

PACKAGE = "rtcourse"  # the folder of the zip holding the course
STUDENT_USER = "rtcourse-student"
# What the autograder needs of the repository: the package, its graders (hidden ones
# included), the skeletons and the references. Not the course's own meta-tests.
INCLUDED = ("pyproject.toml", "README.md", "course", "tests", "labs", "solutions")
EXCLUDED = ("tests/meta",)
_MAX_LAB_FILE = 2 * 2**20  # bytes; a larger "lab file" is not source code

SETUP_SH = r"""#!/usr/bin/env bash
# Gradescope runs this once, as root, in /autograder/source, to build the autograder image.
# Like the course's Makefile it installs the CPU build of torch explicitly (the graders run
# on the CPU), then the course from ./rtcourse.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")"
PYTHON="${PYTHON:-python3}"
TORCH_SPEC="${TORCH_SPEC:-torch==2.13.0}"
TORCH_INDEX="${TORCH_INDEX-https://download.pytorch.org/whl/cpu}"
export PIP_DISABLE_PIP_VERSION_CHECK=1 PIP_BREAK_SYSTEM_PACKAGES=1

if ! "$PYTHON" -m pip --version >/dev/null 2>&1; then
    apt-get update && apt-get install -y python3 python3-pip
fi
"$PYTHON" -m pip install ${TORCH_INDEX:+--index-url "$TORCH_INDEX"} "$TORCH_SPEC"
"$PYTHON" -m pip install ./rtcourse

# Student code runs as this user: it cannot read the reference solutions.
id -u @USER@ >/dev/null 2>&1 || useradd --system --no-create-home --shell /usr/sbin/nologin @USER@
"""

RUN_AUTOGRADER = r"""#!/usr/bin/env bash
# Gradescope runs this for every submission, as root. It copies the student's lab files out
# of the submission into a fresh folder and grades them there; the submission runs
# sandboxed (and, as root, as an unprivileged user). Local runs: set
# RTCOURSE_SUBMISSION_DIR and RTCOURSE_RESULTS_DIR (and RTCOURSE_PYTHON).
set -uo pipefail
HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
SOURCE=/autograder/source/@PACKAGE@
if [ -d "$HERE/@PACKAGE@" ]; then SOURCE="$HERE/@PACKAGE@"; fi
SUBMISSION="${RTCOURSE_SUBMISSION_DIR:-/autograder/submission}"
RESULTS="${RTCOURSE_RESULTS_DIR:-/autograder/results}"
PYTHON="${RTCOURSE_PYTHON:-python3}"
LABS=(@LABS@)  # the labs this autograder grades (rtcourse gradescope --lab); empty: all

WORK="$(mktemp -d)"
trap 'rm -rf "$WORK"' EXIT

# torch's thread pools sized to the CPUs this container may use (its cgroup quota: half a
# CPU by default), not to the host's cores: more threads only add time and memory here.
CPUS="$(nproc 2>/dev/null || echo 1)"
QUOTA=max PERIOD=100000
if [ -r /sys/fs/cgroup/cpu.max ]; then  # cgroup v2, else v1
    read -r QUOTA PERIOD < /sys/fs/cgroup/cpu.max
elif [ -r /sys/fs/cgroup/cpu/cpu.cfs_quota_us ]; then
    QUOTA="$(cat /sys/fs/cgroup/cpu/cpu.cfs_quota_us)"
    PERIOD="$(cat /sys/fs/cgroup/cpu/cpu.cfs_period_us)"
fi
if [ "$QUOTA" != max ] && [ "$QUOTA" -gt 0 ] 2>/dev/null; then
    LIMIT=$(( (QUOTA + PERIOD - 1) / PERIOD ))
    if [ "$LIMIT" -lt "$CPUS" ]; then CPUS=$LIMIT; fi
fi
export OMP_NUM_THREADS="${OMP_NUM_THREADS:-$CPUS}" MKL_NUM_THREADS="${MKL_NUM_THREADS:-$CPUS}"
# glibc's malloc keeps freed memory for reuse: a heap arena per allocating thread (two are
# enough here) and, as its mmap threshold rises with each large free, big tensors in the
# heap, where their memory stays after they are freed. A fixed 1 MB threshold gives every
# larger block back to the system when it is freed (Lab 6's peak: 1055 -> 720 MB).
export MALLOC_ARENA_MAX="${MALLOC_ARENA_MAX:-2}"
export MALLOC_MMAP_THRESHOLD_="${MALLOC_MMAP_THRESHOLD_:-1048576}"
mkdir -p "$RESULTS"
rm -f "$RESULTS/results.json"
cd "$SOURCE"

"$PYTHON" -m course.tools.gradescope collect "$SUBMISSION" "$WORK" ${LABS[@]+"${LABS[@]}"}

if [ -z "${RTCOURSE_WORKER_USER+set}" ] && [ "$(id -u)" = 0 ] && id -u @USER@ >/dev/null 2>&1
then
    export RTCOURSE_WORKER_USER=@USER@
fi
if [ -n "${RTCOURSE_WORKER_USER:-}" ]; then
    # The worker user must run this Python: a module it cannot import would fail the
    # student's tests. One line and a non-zero exit, never a score.
    "$PYTHON" -m course.grading.sandbox check-worker "$RTCOURSE_WORKER_USER" || exit 2
    export RTCOURSE_WORKER_CHECKED="$RTCOURSE_WORKER_USER"
    chmod -R go-rwx solutions tests/hidden   # the references and hidden tests: the grader's
    chmod go-rwx "$RESULTS"                  # the results too
    chmod -R a+rX "$WORK"                    # the submission is the worker's to read
fi

"$PYTHON" -m course.tools.cli grade --impl "$WORK" ${LABS[@]+"${LABS[@]}"} \
    --json "$RESULTS/results.json"

if [ ! -s "$RESULTS/results.json" ]; then
    STOPPED="The autograder stopped before it could grade this submission."
    printf '{"score": 0, "output": "%s Please tell the course staff."}\n' "$STOPPED" \
        > "$RESULTS/results.json"
fi
exit 0
"""


def _script(template: str, labs) -> str:
    lab_args = " ".join(f"--lab {int(n)}" for n in sorted(set(labs or ())))
    return (
        template.replace("@PACKAGE@", PACKAGE)
        .replace("@USER@", STUDENT_USER)
        .replace("@LABS@", lab_args)
    )


def package_files(root) -> list[Path]:
    """The repository files the autograder ships, relative to ``root``."""
    files = course_files(root, withheld=EXCLUDED + (".git", ".venv"))
    return [rel for rel in files if rel.parts[0] in INCLUDED]


def _add(archive: zipfile.ZipFile, name: str, data: bytes, executable=False):
    info = zipfile.ZipInfo(name, date_time=(1980, 1, 1, 0, 0, 0))  # reproducible zips
    info.external_attr = (0o100755 if executable else 0o100644) << 16
    info.compress_type = zipfile.ZIP_DEFLATED
    archive.writestr(info, data)


def build_autograder(root, out, labs=None) -> list[str]:
    """Write the Gradescope autograder zip of the course at ``root`` to ``out``; return the
    names it holds. ``labs``: grade only these lab numbers (default: every lab)."""
    root, out = Path(root).resolve(), Path(out).resolve()
    known = lab_catalog(lab_test_files(root))
    missing = sorted(set(labs or ()) - set(known))
    if missing:
        raise ValueError(f"labs: no grader for lab(s) {missing}; the course has {sorted(known)}")
    out.parent.mkdir(parents=True, exist_ok=True)
    names = []
    with zipfile.ZipFile(out, "w") as archive:
        for name, template in (("setup.sh", SETUP_SH), ("run_autograder", RUN_AUTOGRADER)):
            _add(archive, name, _script(template, labs).encode(), executable=True)
            names.append(name)
        for rel in package_files(root):
            name = f"{PACKAGE}/{rel.as_posix()}"
            _add(archive, name, (root / rel).read_bytes())
            names.append(name)
    return names


# ------------------------------------------------------------ inside the autograder


def _ranked(candidates, filename: str, submission: Path) -> list[Path]:
    """The files of ``candidates`` named ``filename`` or a near miss of it ("grid (1).py"),
    best first: the exact name, then the shallowest."""
    stem = filename[:-3]
    ranked = [
        (lab_file_rank(p.name, stem), len(p.relative_to(submission).parts), str(p), p)
        for p in candidates
    ]
    return [p for rank, *_, p in sorted(r for r in ranked if r[0] is not None)]


def _copy_first(paths, target: Path) -> Path | None:
    """Copy the first of ``paths`` that is a regular file of source size to ``target``."""
    for path in paths:
        if not path.is_symlink() and path.is_file() and path.stat().st_size <= _MAX_LAB_FILE:
            target.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(path, target, follow_symlinks=False)
            return path
    return None


def collect_submission(submission, dest, modules, skeletons=None) -> dict[str, Path | None]:
    """Copy the lab files of ``modules`` found in ``submission`` into ``dest``.

    A file may lie anywhere in the submission (students upload single files, their
    ``labs/`` folder or the whole handout); the exact name wins over a near miss an upload
    makes of it ("lab1_intersect (1).py", "Lab1_Intersect.py"), then the shallowest, and
    it is copied under the exact name. Only regular files are copied, never links (a link
    could point at the grader's files).

    A lab kept as a package (its skeleton in ``skeletons``, the grader's ``labs/``, is a
    folder ``module/``) is handed in as the files of it the student edited: ``dest/module/``
    starts as the grader's copy of the skeleton package and each of its files found in the
    submission is laid over it, so a file left out costs only its own tasks. The files are
    taken from the shallowest folder named for the package (``lab2_accel/``, or a near
    miss) where the submission has one, else loose, by name, from anywhere in it (a loose
    ``__init__.py`` is not taken: it may be any package's). A lab none of whose files is in
    the submission is not laid down at all: it is missing, as a single-file lab is.

    Returns each lab file's name as the grader sees it (``lab0_interop.py``,
    ``lab2_accel/grid.py``) -> the file copied (relative to ``submission``), or None where
    the submission has none. The same, with every file the submission holds, goes to
    ``dest/SUBMISSION_MANIFEST``: the grader's messages name the files as handed in, never
    ``dest``.
    """
    submission, dest = Path(submission), Path(dest)
    dest.mkdir(parents=True, exist_ok=True)
    found: dict[str, Path | None] = {}
    handed_in = sorted(
        p
        for p in submission.rglob("*")
        if (p.is_file() or p.is_symlink())
        and not any(
            part.startswith(".") or part == "__MACOSX" for part in p.relative_to(submission).parts
        )
    )
    candidates = [p for p in handed_in if p.suffix == ".py"]
    for module in modules:
        package = lab_source(skeletons, module) if skeletons is not None else None
        if package is None or not package.is_dir():
            target = dest / f"{module}.py"
            path = _copy_first(_ranked(candidates, target.name, submission), target)
            found[target.name] = path.relative_to(submission) if path else None
            continue
        folders = sorted(
            {
                p.parent
                for p in candidates
                if lab_file_rank(p.parent.name + ".py", module) is not None
            },
            key=lambda f: (
                lab_file_rank(f.name + ".py", module),
                len(f.relative_to(submission).parts),
                str(f),
            ),
        )
        files = module_files(package)
        mine: dict[str, Path | None] = {}
        for file in files:
            name = file.relative_to(package).as_posix()
            if folders:
                pool = [p for p in candidates if p.parent == folders[0]]
            else:
                pool = [p for p in candidates if name != "__init__.py"]
            paths = _ranked(pool, Path(name).name, submission)
            chosen = next(
                (
                    p
                    for p in paths
                    if not p.is_symlink() and p.is_file() and p.stat().st_size <= _MAX_LAB_FILE
                ),
                None,
            )
            mine[f"{module}/{name}"] = chosen
        if any(mine.values()):
            for file in files:
                rel = file.relative_to(package)
                chosen = mine[f"{module}/{rel.as_posix()}"]
                target = dest / module / rel
                if _copy_first([chosen] if chosen else [], target) is None:
                    target.parent.mkdir(parents=True, exist_ok=True)
                    shutil.copyfile(file, target)  # the skeleton's: its tasks score 0
        found.update({name: p.relative_to(submission) if p else None for name, p in mine.items()})
    manifest = {
        "files": {name: p.as_posix() if p else None for name, p in found.items()},
        "handed_in": [p.relative_to(submission).as_posix() for p in handed_in],
    }
    (dest / SUBMISSION_MANIFEST).write_text(json.dumps(manifest, indent=1) + "\n")
    return found


def _collect_main(submission: str, dest: str, labs=None) -> int:
    from course.core.files import repo_root

    root = repo_root()
    modules = [lab.module for lab in lab_catalog(lab_test_files(root, labs)).values()]
    found = collect_submission(submission, dest, modules, root / "labs")
    handed_in = {name.split("/")[0] for name, path in found.items() if path}
    for name, path in found.items():
        partial = "/" in name and name.split("/")[0] in handed_in  # a package's file
        print(
            f"{name:<24} "
            + (
                f"found: {path}"
                if path
                else "not in the submission: the skeleton's is graded"
                if partial
                else "not in the submission: its lab scores 0"
            )
        )
    return 0


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m course.tools.gradescope")
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("collect", help="copy a submission's lab files into a folder")
    p.add_argument("submission")
    p.add_argument("dest")
    p.add_argument("--lab", type=int, action="append", help="only this lab's file (repeatable)")
    args = parser.parse_args(argv)
    return _collect_main(args.submission, args.dest, args.lab)


if __name__ == "__main__":
    sys.exit(main())
