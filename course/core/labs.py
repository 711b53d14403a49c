"""Which implementation of a lab to run and where its files are.

An implementation is a folder of lab modules: ``solutions/`` (the references, in the course
repository), ``labs/`` (the student's, and the only one in the handout) or any folder holding
lab files (a submission, a copy of the handout). Everything that runs a lab (the grader, the
benches, the gallery, ``rtcourse``) picks the folder here, so the course repository runs the
references and the handout the student's code without being told.

A lab is a module ``labN_topic``: one file ``labN_topic.py`` or a package folder
``labN_topic/``. It is loaded by its path (:func:`course.core.files.import_file`), never
imported by name: ``solutions`` and ``labs`` are not packages of the course.
"""

from __future__ import annotations

import re
from pathlib import Path

IMPLS = ("solutions", "labs")  # the folders of the course root an implementation names
_LAB = re.compile(r"lab(\d+)(?:_|$)")  # labN_topic, or labN alone (bench/showcase/labN.py)


def lab_number(name) -> int | None:
    """The number of the lab a module or file name starts with: ``lab2_accel``,
    ``lab2_accel.py`` and ``lab2`` give 2; None for any other name (a grader
    ``test_lab2_accel.py`` included: strip its ``test_`` first)."""
    match = _LAB.match(str(name or ""))
    return int(match.group(1)) if match else None


def lab_file_number(path) -> int | None:
    """The lab whose source ``path`` is part of: a file ``labN_topic.py``, or any file of a
    package folder ``labN_topic/``; None for anything else (a grader, a course module)."""
    path = Path(path)
    if path.suffix != ".py":
        return None
    if (number := lab_number(path.stem)) is not None and "_" in path.stem:
        return number
    return lab_number(path.parent.name) if "_" in path.parent.name else None


def default_impl(root) -> str:
    """``solutions`` where the course root has it (the course repository), else ``labs``
    (the student handout)."""
    return "solutions" if (Path(root) / "solutions").is_dir() else "labs"


def implementation_folder(root, impl: str | None = None, *, must_exist: bool = True) -> Path:
    """The folder of lab modules that ``impl`` names in the course at ``root``.

    ``impl``: None for :func:`default_impl`; ``"solutions"`` or ``"labs"`` for that folder of
    ``root``; anything else is a folder path (``~`` expanded, relative to the current folder).
    A folder holding a whole course copy (its own ``labs/`` and no lab file) means that
    copy's ``labs/``. With ``must_exist`` a folder that is not there raises
    FileNotFoundError saying which folder was asked for and what to pass instead.
    """
    root = Path(root)
    impl = impl or default_impl(root)
    if impl in IMPLS:
        folder = root / impl
    else:
        folder = Path(impl).expanduser().resolve()
        if (folder / "labs").is_dir() and not any(folder.glob("lab*_*")):
            folder = folder / "labs"  # a copy of the whole handout
    if must_exist and not folder.is_dir():
        hint = (
            " (the student handout has no reference solutions: use labs)"
            if impl == "solutions"
            else ""
        )
        raise FileNotFoundError(
            f"impl {impl!r}: no folder {folder}{hint}; expected labs, "
            f"solutions or a folder holding lab files"
        )
    return folder


def lab_path(folder, name: str) -> Path:
    """The source of the lab ``name`` in ``folder``: the file ``name.py`` or the package
    folder ``name/`` (:func:`course.core.files.lab_source`). ``name`` is a module name
    (``lab1_intersect``) or a lab prefix (``lab1``); FileNotFoundError when the folder has
    no such lab."""
    from course.core.files import lab_source

    folder = Path(folder)
    found = lab_source(folder, name)
    if found is None:  # a prefix: the first labN_topic file or package of the folder
        stems = sorted(
            {p.stem for p in folder.glob(f"{name}_*") if p.suffix == ".py" or p.is_dir()}
        )
        found = next(filter(None, (lab_source(folder, stem) for stem in stems)), None)
    if found is None:
        raise FileNotFoundError(
            f"no lab module {name!r} in {folder} (expected {name}.py or a package folder {name}/)"
        )
    return found


def load_lab(name: str, impl: str | None = None, root=None):
    """Import the lab ``name`` (``lab1_intersect`` or ``lab1``) of the implementation
    ``impl`` (see :func:`implementation_folder`) of the course at ``root`` (default: the
    course folder the current folder lies in). Trusted code only: this runs the lab in the
    calling process; the grader runs anything but the references in its sandbox instead."""
    from course.core.files import import_file, repo_root

    folder = implementation_folder(repo_root() if root is None else root, impl)
    path = lab_path(folder, name)
    return import_file(path, f"{folder.name}_{path.stem}")
