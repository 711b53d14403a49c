"""Finding the course folder, importing a Python file by its path, and the files of a
module kept in parts.

Below everything that loads a lab, a grader or a showcase by file (the benches, the gallery,
the grader): none of them depends on another for it.

A module in parts (a long reference solution: ``solutions/lab2_accel.py``) is one file that
the graders load by path, and the folder ``<its name>_parts/`` beside it, whose files it runs
in its own namespace (:func:`run_parts`). Whatever reads such a module's source, rather than
importing it, finds its files with :func:`module_files` and the file of one of its
functions with :func:`defining_file`; :func:`copy_module` writes a (changed) copy of it,
:func:`joined_source` its text as one file (what a student hands in).
"""

from __future__ import annotations

import ast
import importlib.util
import re
import sys
from pathlib import Path

PARTS = "_parts"  # solutions/lab2_accel.py keeps its parts in solutions/lab2_accel_parts/


def repo_root(command: str = "rtcourse") -> Path:
    """The course checkout (or handout) this command runs in: the folder holding tests/.
    ``command`` names the command in the error ("rtcourse release")."""
    here = Path.cwd().resolve()
    for folder in (here, *here.parents):
        if (folder / "tests").is_dir() and (folder / "pyproject.toml").is_file():
            return folder
    raise SystemExit(f"{command}: run this inside the course folder (no tests/ and "
                     f"pyproject.toml in {here} or above it)")


def import_file(path, name=None):
    """Import a Python file as a module (cached by path)."""
    path = str(Path(path).resolve())
    name = name or "rtcourse_file_" + Path(path).stem
    module = sys.modules.get(name)
    if module is not None and getattr(module, "__file__", None) == path:
        return module
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    try:
        spec.loader.exec_module(module)
    except BaseException:
        sys.modules.pop(name, None)
        raise
    return module


def _run_order(path: Path):
    """Part files run in name order, numbers by value (``task2_`` before ``task10_``)."""
    return [int(t) if t.isdigit() else t for t in re.split(r"(\d+)", path.name)]


def module_parts(path) -> list[Path]:
    """The part files of the module file ``path`` (the ``*.py`` files of the folder
    ``<stem>_parts`` beside it), in the order the module runs them; ``[]`` for a module
    in one file."""
    path = Path(path)
    folder = path.with_name(path.stem + PARTS)
    return sorted((p for p in folder.glob("*.py") if p.is_file()), key=_run_order)


def module_files(path) -> list[Path]:
    """Every source file of the module file ``path``: the file itself, then its parts."""
    return [Path(path), *module_parts(path)]


def _top_level_names(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(), filename=str(path))
    return {node.name for node in tree.body
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef))}


def defining_file(path, name: str) -> Path:
    """The file of the module ``path`` (the file itself or one of its parts) whose top
    level defines the function or class ``name`` (``Class.method``: its class's file)."""
    top = name.split(".")[0]
    files = [f for f in module_files(path) if top in _top_level_names(f)]
    if len(files) != 1:
        where = "none" if not files else " and ".join(str(f) for f in files)
        raise ValueError(f"{name!r}: expected one file of {path} defining {top!r}, found "
                         f"{where}")
    return files[0]


def run_parts(namespace: dict) -> None:
    """Run the parts of the module whose globals are ``namespace`` (the module calls
    ``run_parts(globals())``) in that namespace, in order: together they are one module,
    whose functions see each other (and whatever replaces one of them) through its
    globals. Each part is compiled with its own file name, so tracebacks and
    ``inspect.getsource`` of a function show the part's lines."""
    path = Path(namespace["__file__"]).resolve()
    parts = module_parts(path)
    if not parts:  # a module copied without its parts would define nothing: say so
        raise ImportError(f"{path}: its parts ({path.stem}{PARTS}/*.py beside it) are missing; "
                          f"copy the module with them (course.core.files.copy_module)")
    for part in parts:
        code = compile(part.read_bytes(), str(part), "exec", dont_inherit=True)
        exec(code, namespace)  # noqa: S102  (a module's own part)


_FUTURE = "from __future__ import annotations\n"
_CALL = ("from course.core.files import run_parts as _run_parts\n",
         "_run_parts(globals())\n", "del _run_parts\n")


def joined_source(path) -> str:
    """The module file ``path`` and its parts as the text of one module file, as a student
    hands a lab in (a Gradescope submission is one file per lab): the parts' texts, less
    their ``from __future__`` line (the module's own), in place of its ``run_parts`` call."""
    path = Path(path)
    text, parts = path.read_text(), module_parts(path)
    if not parts:
        return text
    lines = text.splitlines(keepends=True)
    if not all(lines.count(line) == 1 for line in _CALL) or _FUTURE not in lines:
        raise ValueError(f"{path}: expected {_FUTURE.strip()!r} and the lines "
                         f"{[line.strip() for line in _CALL]} once each")
    joined = []
    for line in lines:
        if line == _CALL[1]:
            for part in parts:
                body = [x for x in part.read_text().splitlines(keepends=True) if x != _FUTURE]
                joined += ["\n\n"] * (part != parts[0]) + body
        elif line not in _CALL:
            joined.append(line)
    return "".join(joined)


def copy_module(path, folder, texts=None) -> Path:
    """Copy the module file ``path`` and its parts into ``folder`` (in the same layout);
    ``texts`` maps a file's name relative to the module's folder (``lab2_accel.py``,
    ``lab2_accel_parts/task1_grid.py``) to the text written instead of that file's.
    Returns the module's copy."""
    path, folder = Path(path), Path(folder)
    texts = dict(texts or {})
    for source in module_files(path):
        name = source.relative_to(path.parent).as_posix()
        target = folder / name
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_text(texts.pop(name) if name in texts else source.read_text())
    if texts:
        raise ValueError(f"copy_module: {sorted(texts)} are not files of {path}")
    return folder / path.name
