"""Finding the course folder and importing a Python file by its path.

Below everything that loads a lab, a grader or a showcase by file (the benches, the gallery,
the grader): none of them depends on another for it.
"""

from __future__ import annotations

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
