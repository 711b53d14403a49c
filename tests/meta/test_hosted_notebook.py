"""The README's set-up cell for a hosted notebook with a GPU, run as it is written.

A fresh virtual environment gets torch first (the service's preinstalled torch: here the
same build as the one running these tests), then runs the cell against a zip of the course
folder. torch must come out untouched (same version, same files, no CUDA wheels pulled in)
and a lab must grade. Slow-ish: a virtual environment and an install (pip takes the
wheels from its usual index, a local one where there is one).
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest
import torch
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name

from course.tools.release import course_files

ROOT = Path(__file__).resolve().parents[2]
MARKER = "<!-- hosted-setup-cell"
# What the hosted service brings itself: its torch and its notebook front end.
SERVICE_BRINGS = {"torch", "jupyterlab", "ipykernel", "nbconvert", "nbclient", "nbformat"}
# What a zip of the course folder leaves out: the repository's own machinery.
NOT_ZIPPED = (".git", ".venv", ".ci", "out", "build", "dist", "tests/meta")


def hosted_cell() -> str:
    text = (ROOT / "README.md").read_text()
    assert MARKER in text, f"README.md lost the hosted set-up cell (the {MARKER} comment)"
    match = re.search(r"```python\n(.*?)```", text[text.index(MARKER) :], re.DOTALL)
    assert match, "no ```python block after the hosted set-up cell's marker"
    return match.group(1)


def _requirements(lines) -> dict[str, str]:
    reqs = [Requirement(line) for line in lines]
    return {canonicalize_name(r.name): str(r.specifier) for r in reqs if r.marker is None}


def test_hosted_requirements_are_pyproject_less_what_the_service_brings():
    try:
        import tomllib
    except ModuleNotFoundError:
        from pip._vendor import tomli as tomllib
    deps = _requirements(
        tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["dependencies"]
    )
    hosted_file = ROOT / "requirements-hosted.txt"
    hosted = _requirements(
        line
        for line in hosted_file.read_text().splitlines()
        if line.strip() and not line.startswith("#")
    )
    want = {name: spec for name, spec in deps.items() if name not in SERVICE_BRINGS}
    assert hosted == want, (
        f"requirements-hosted.txt should list pyproject's dependencies less "
        f"{sorted(SERVICE_BRINGS)}:\n  missing or different: "
        f"{ {k: v for k, v in want.items() if hosted.get(k) != v} }\n  extra: "
        f"{sorted(set(hosted) - set(want))}"
    )


SNAPSHOT = """\
import hashlib, importlib.metadata as md, json, os, sys, torch
dist = md.distribution("torch")
print(json.dumps({"version": torch.__version__, "file": torch.__file__,
                  "mtime": os.stat(torch.__file__).st_mtime_ns,
                  "record": hashlib.sha256(dist.read_text("RECORD").encode()).hexdigest(),
                  "packages": sorted(d.metadata["Name"] for d in md.distributions())}))
"""


def _run(cmd, *, timeout, **kwargs) -> subprocess.CompletedProcess:
    proc = subprocess.run(
        cmd,
        capture_output=True,
        text=True,
        timeout=timeout,
        check=False,
        stdin=subprocess.DEVNULL,
        **kwargs,
    )
    assert proc.returncode == 0, (
        f"{' '.join(map(str, cmd))} failed ({proc.returncode}):\n"
        + proc.stdout[-3000:]
        + proc.stderr[-3000:]
    )
    return proc


def _snapshot(python, env, cwd) -> dict:
    """torch's version and files, and the installed distributions, seen from ``cwd`` (not
    the course checkout: its egg-info would count as installed)."""
    data = json.loads(_run([python, "-c", SNAPSHOT], timeout=120, env=env, cwd=cwd).stdout)
    data["packages"] = {canonicalize_name(name) for name in data["packages"]}
    return data


def _zip_course(zip_path: Path):
    with zipfile.ZipFile(zip_path, "w", zipfile.ZIP_DEFLATED) as archive:
        for rel in course_files(ROOT, withheld=NOT_ZIPPED):
            archive.write(ROOT / rel, f"handout/{rel.as_posix()}")


def test_hosted_cell_installs_beside_the_preinstalled_torch_and_a_lab_grades(tmp_path):
    cell = hosted_cell()
    handout = tmp_path / "handout"
    cell, n = re.subn(
        r'^HANDOUT = "[^"]*"', f"HANDOUT = {str(handout)!r}", cell, flags=re.MULTILINE
    )
    assert n == 1, 'the cell should set HANDOUT = "..." on a line of its own'
    _zip_course(tmp_path / "handout.zip")

    venv = tmp_path / "venv"
    python = venv / "bin" / "python"
    env = dict(os.environ, TMPDIR=str(tmp_path), PIP_DISABLE_PIP_VERSION_CHECK="1")
    env.pop("VIRTUAL_ENV", None)
    _run([sys.executable, "-m", "venv", str(venv)], timeout=120, env=env)
    torch_spec = f"torch=={torch.__version__}"  # the build these tests run on, as preinstalled
    try:
        _run(
            [python, "-m", "pip", "install", "--quiet", "--no-compile", torch_spec],
            timeout=300,
            env=env,
            cwd=tmp_path,
        )
    except AssertionError as exc:
        pytest.skip(
            f"cannot preinstall {torch_spec} in a fresh environment here: "
            f"{str(exc).splitlines()[-1]}"
        )
    before = _snapshot(python, env, tmp_path)

    _run([python, "-c", cell], timeout=300, env=env, cwd=tmp_path)
    after = _snapshot(python, env, tmp_path)
    for key in ("version", "file", "mtime", "record"):
        assert after[key] == before[key], (
            f"the cell changed torch's {key}: {before[key]!r} -> {after[key]!r}"
        )
    cuda = [name for name in after["packages"] if name.startswith("nvidia")]
    assert not cuda, f"the cell installed CUDA wheels: {cuda}"
    added = after["packages"] - before["packages"]
    assert "gpu-raytracing-course" in added and "trimesh" in added, sorted(added)
    assert not added & {"jupyterlab", "ipykernel", "triton"}, (
        f"the cell installed what the service brings: {sorted(added & SERVICE_BRINGS)}"
    )

    results = tmp_path / "results.json"
    grade = subprocess.run(
        [venv / "bin" / "rtcourse", "grade", "--lab", "0", "--json", str(results)],
        cwd=handout,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    assert grade.returncode == 0 and results.is_file(), grade.stdout[-3000:] + grade.stderr
    data = json.loads(results.read_text())
    assert data["score"] > 0, (
        f"lab 0 scored {data['score']} against the references:\n" + grade.stdout[-3000:]
    )
