"""Finding the course folder, importing a Python file or package by its path, and the files
of a lab kept as a package.

Below everything that loads a lab, a grader or a showcase by file (the benches, the gallery,
the grader): none of them depends on another for it.

A lab module ``labN_topic`` is one file ``labN_topic.py`` or a package folder
``labN_topic/`` (``solutions/lab2_accel/``: an ``__init__.py`` that re-exports what its
modules define). :func:`lab_source` finds either in a folder, :func:`import_file` imports
either by its path. Whatever reads a lab's source rather than importing it finds its files
with :func:`module_files` and the file of one of its functions with :func:`defining_file`;
:func:`copy_module` writes a (changed) copy of it.
"""

from __future__ import annotations

import ast
import importlib.util
import sys
from pathlib import Path


def repo_root(command: str = "rtcourse") -> Path:
    """The course checkout (or handout) this command runs in: the folder holding tests/.
    ``command`` names the command in the error ("rtcourse release")."""
    here = Path.cwd().resolve()
    for folder in (here, *here.parents):
        if (folder / "tests").is_dir() and (folder / "pyproject.toml").is_file():
            return folder
    raise SystemExit(
        f"{command}: run this inside the course folder (no tests/ and "
        f"pyproject.toml in {here} or above it)"
    )


def lab_source(folder, name: str) -> Path | None:
    """The source of the module ``name`` in ``folder``: the file ``name.py``, else the
    package folder ``name/`` (one holding ``__init__.py``); None when neither is there."""
    folder = Path(folder)
    file, package = folder / f"{name}.py", folder / name
    if file.is_file():
        return file
    if (package / "__init__.py").is_file():
        return package
    return None


def _package(path: Path) -> Path | None:
    """The package folder ``path`` names (the folder or its ``__init__.py``), else None."""
    if path.is_dir():
        return path
    if path.name == "__init__.py":
        return path.parent
    return None


def _drop(name: str) -> None:
    """Forget the module ``name`` and its submodules (``name.grid``, ...)."""
    for key in [k for k in sys.modules if k == name or k.startswith(name + ".")]:
        sys.modules.pop(key, None)


def import_file(path, name=None):
    """Import a Python file, or a package by its folder, as the module ``name`` (cached by
    path). A package's modules import each other relatively (``from .grid import ...``) and
    become ``name.grid`` and so on; importing another path under the same name, or an
    import that fails, leaves none of the old or half-made submodules behind."""
    path = Path(path).resolve()
    package = _package(path)
    init = package / "__init__.py" if package else path
    name = name or "rtcourse_file_" + (package.name if package else path.stem)
    module = sys.modules.get(name)
    if module is not None and getattr(module, "__file__", None) == str(init):
        return module
    _drop(name)
    spec = importlib.util.spec_from_file_location(
        name, init, submodule_search_locations=[str(package)] if package else None
    )
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    try:
        spec.loader.exec_module(module)
    except BaseException:
        _drop(name)
        raise
    return module


def module_files(path) -> list[Path]:
    """Every source file of the module ``path``: the file itself, or a package's ``.py``
    files (its ``__init__.py`` first, then the others by path)."""
    path = Path(path)
    package = _package(path)
    if package is None:
        return [path]
    files = sorted(
        p
        for p in package.rglob("*.py")
        if p.is_file() and "__pycache__" not in p.relative_to(package).parts
    )
    return sorted(files, key=lambda p: p.relative_to(package) != Path("__init__.py"))


def _top_level_names(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(), filename=str(path))
    return {
        node.name
        for node in tree.body
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef))
    }


def defining_file(path, name: str) -> Path:
    """The file of the module ``path`` (the file itself, or one of a package's files) whose
    top level defines the function or class ``name`` (``Class.method``: its class's file)."""
    top = name.split(".")[0]
    files = [f for f in module_files(path) if top in _top_level_names(f)]
    if len(files) != 1:
        where = "none" if not files else " and ".join(str(f) for f in files)
        raise ValueError(f"{name!r}: expected one file of {path} defining {top!r}, found {where}")
    return files[0]


def relative_name(path, file) -> str:
    """``file``'s name as :func:`copy_module` keys it: relative to the folder holding the
    module ``path`` (``lab1_intersect.py``, ``lab2_accel/grid.py``)."""
    path = Path(path)
    base = (_package(path) or path).parent
    return Path(file).relative_to(base).as_posix()


def copy_module(path, folder, texts=None) -> Path:
    """Copy the module ``path`` (a file, or a package with all its files) into ``folder``;
    ``texts`` maps a file's :func:`relative_name` (``lab2_accel.py``,
    ``lab2_accel/grid.py``) to the text written instead of that file's (a mutant). Returns
    the copy's path: the file, or the package folder."""
    path, folder = Path(path), Path(folder)
    package = _package(path)
    texts = dict(texts or {})
    for source in module_files(path):
        name = relative_name(path, source)
        target = folder / name
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_text(texts.pop(name) if name in texts else source.read_text())
    if texts:
        raise ValueError(f"copy_module: {sorted(texts)} are not files of {path}")
    return folder / (package.name if package else path.name)
