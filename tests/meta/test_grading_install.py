"""Grading needs only the core dependencies: the Gradescope image (``rtcourse gradescope``'s
setup.sh installs the course without extras) has no notebook stack, so the grader must run
without one. A grading run here with the notebook packages made unimportable proves it."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
NOTEBOOK_STACK = (
    "nbformat",
    "nbclient",
    "nbconvert",
    "ipykernel",
    "jupyterlab",
    "jupyter_client",
    "jupyter_server",
)

BLOCKER = f"""
import sys
from importlib.abc import MetaPathFinder

class NoNotebooks(MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in {NOTEBOOK_STACK!r}:
            raise ModuleNotFoundError(f"No module named {{name!r}} (not in a grading install)")
        return None

sys.meta_path.insert(0, NoNotebooks())
from course.tools.cli import main
sys.exit(main(sys.argv[1:]))
"""


def test_grading_runs_without_the_notebook_stack(tmp_path):
    results = tmp_path / "results.json"
    proc = subprocess.run(
        [
            sys.executable,
            "-c",
            BLOCKER,
            "grade",
            "--impl",
            "labs",
            "--lab",
            "0",
            "-k",
            "pack_rgba8",
            "--json",
            str(results),
        ],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert results.is_file(), proc.stdout[-2000:] + proc.stderr[-2000:]
    tests = json.loads(results.read_text())["tests"]
    assert tests and all("not implemented yet" in t["output"] for t in tests), tests[:2]
    assert "not in a grading install" not in proc.stdout + proc.stderr


def test_pyproject_keeps_the_notebook_stack_in_its_extra():
    try:
        import tomllib
    except ModuleNotFoundError:  # Python 3.10
        from pip._vendor import tomli as tomllib
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    core = {
        line.split(">")[0].split("=")[0].split("<")[0].strip().lower()
        for line in project["dependencies"]
    }
    assert not core & set(NOTEBOOK_STACK), sorted(core & set(NOTEBOOK_STACK))
    assert f"{project['name']}[notebooks]" in project["optional-dependencies"]["dev"]
