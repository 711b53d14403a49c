"""``make test`` (the README's test command) says why each skipped test was skipped."""

from __future__ import annotations

import shlex
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _test_recipe() -> list[str]:
    """The pytest options of ``make test``'s command, read from make's dry run."""
    out = subprocess.run(
        ["make", "-s", "-n", "-W", "pyproject.toml", "test"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    line = next(ln for ln in out.splitlines() if " -m pytest" in ln)
    return shlex.split(line.split(" -m pytest", 1)[1])


def test_make_test_prints_the_skip_reasons(tmp_path):
    options = _test_recipe()
    (tmp_path / "test_skip.py").write_text(
        "import pytest\n\n\n@pytest.mark.skip(reason='needs a CUDA device')\n"
        "def test_gpu():\n    pass\n"
    )
    proc = subprocess.run(
        [sys.executable, "-m", "pytest", *options, "test_skip.py"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert "SKIPPED [1] test_skip.py" in proc.stdout and "needs a CUDA device" in proc.stdout, (
        f"make test runs pytest {' '.join(options)}, which does not list skip reasons:\n"
        + proc.stdout
    )
