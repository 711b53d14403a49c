"""Every lecture notebook executes top to bottom (small sizes on the CPU)."""

from __future__ import annotations

import os
import re
from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient

ROOT = Path(__file__).resolve().parents[2]
NOTEBOOKS = sorted((ROOT / "slides").glob("*.ipynb"))


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_notebook_executes(path, monkeypatch):
    monkeypatch.setenv("RTCOURSE_SMALL", os.environ.get("RTCOURSE_SMALL", "1"))
    notebook = nbformat.read(path, as_version=4)
    NotebookClient(
        notebook,
        timeout=600,
        kernel_name="python3",
        resources={"metadata": {"path": str(path.parent)}},
    ).execute()
    errors = [
        o
        for cell in notebook.cells
        if cell.cell_type == "code"
        for o in cell.get("outputs", [])
        if o.get("output_type") == "error"
    ]
    assert not errors


def test_every_notebook_that_imports_a_lab_falls_back_to_reference_figures():
    # In the handout a lab is the student's skeleton: without the fallback, a demo of an
    # unwritten function shows a traceback instead of the lecture's figure.
    checked = 0
    for path in NOTEBOOKS:
        code = [c.source for c in nbformat.read(path, as_version=4).cells if c.cell_type == "code"]
        imports = [
            i
            for i, source in enumerate(code)
            if re.search(r"^\s*(import|from)\s+lab\d+_\w+", source, re.MULTILINE)
        ]
        if not imports:
            continue
        installed = [
            i for i, source in enumerate(code) if "show_reference_when_unwritten(ROOT)" in source
        ]
        assert installed and installed[0] <= imports[0], (
            f"{path.name}: call course.tools.lecture.show_reference_when_unwritten(ROOT) in the "
            f"cell that imports the lab (before its first demo)"
        )
        checked += 1
    assert checked >= 7, f"only {checked} notebooks import a lab"
