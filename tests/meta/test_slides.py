"""``rtcourse slides`` and the lecture overview notebook."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import nbformat
from nbformat.v4 import new_code_cell, new_markdown_cell, new_notebook

from course.core.labs import lab_number
from course.tools.slides import error_cells, execute, with_slide_types

ROOT = Path(__file__).resolve().parents[2]
OVERVIEW = ROOT / "slides" / "00_overview.ipynb"


def test_heading_cells_open_slides_without_touching_the_notebook():
    nb = new_notebook(
        cells=[
            new_markdown_cell("# Title\ntext"),
            new_code_cell("x = 1"),
            new_markdown_cell("\n## Part"),
            new_markdown_cell("### Detail"),
            new_markdown_cell("no heading here"),
            new_markdown_cell("## Kept", metadata={"slideshow": {"slide_type": "fragment"}}),
        ]
    )
    types = [c.metadata.get("slideshow", {}).get("slide_type") for c in with_slide_types(nb).cells]
    assert types == ["slide", None, "slide", "subslide", None, "fragment"]
    assert "slideshow" not in nb.cells[0].metadata, "the input notebook must stay as it was"


def _toy_course(root: Path):
    (root / "tests").mkdir(parents=True)
    (root / "pyproject.toml").write_text("")
    (root / "slides").mkdir()
    nbformat.write(
        new_notebook(
            cells=[
                new_markdown_cell("# Toy lecture\nintro"),
                new_code_cell(
                    "import os\nprint('SMALL=' + os.environ.get('RTCOURSE_SMALL', 'unset'))"
                ),
                new_markdown_cell("## A figure"),
                new_code_cell(
                    "import matplotlib.pyplot as plt\nplt.plot([0, 1], [1, 0])\nplt.show()"
                ),
            ]
        ),
        root / "slides" / "01_toy.ipynb",
    )
    nbformat.write(
        new_notebook(
            cells=[
                new_markdown_cell("# Broken"),
                new_code_cell("1 / 0"),
                new_markdown_cell("## After the error"),
            ]
        ),
        root / "slides" / "02_broken.ipynb",
    )


def _slides(root: Path, *args):
    return subprocess.run(
        [sys.executable, "-m", "course.tools.cli", "slides", "--out", "out", *args],
        cwd=root,
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )


def test_rtcourse_slides_executes_and_renders(tmp_path):
    _toy_course(tmp_path)
    proc = _slides(tmp_path)
    out = tmp_path / "out"
    assert proc.returncode == 1, "a notebook with an error must fail the command\n" + proc.stdout
    assert "1 cell(s) raised" in proc.stdout
    index = (out / "index.html").read_text()
    for name in ("01_toy", "02_broken"):
        assert f'href="{name}.slides.html"' in index and f'href="{name}.html"' in index
    slides = (out / "01_toy.slides.html").read_text()
    assert "reveal" in slides and slides.count("<section") >= 2
    # A long code line scrolls inside its slide; an output line is never wrapped mid-number.
    assert ".jp-RenderedText pre { white-space: pre;" in slides
    assert ".jp-InputArea-editor pre, .jp-RenderedText pre { overflow-x: auto; }" in slides
    notes = (out / "01_toy.html").read_text()
    assert "SMALL=1" in notes, "notebooks run with RTCOURSE_SMALL=1 by default"
    assert "data:image/png;base64," in notes, "the figure is produced by the code and embedded"
    broken = (out / "02_broken.html").read_text()
    assert "ZeroDivisionError" in broken and "After the error" in broken
    assert "Toy lecture" in index and "raised" in index
    # The kernels run over local sockets: no warning per notebook about unencrypted TCP.
    assert "without encryption" not in proc.stdout + proc.stderr


def test_rtcourse_slides_no_execute_keeps_saved_outputs(tmp_path):
    _toy_course(tmp_path)
    proc = _slides(tmp_path, "--no-execute")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "SMALL=1" not in (tmp_path / "out" / "01_toy.html").read_text(), "not executed"
    assert "outputs as saved" in (tmp_path / "out" / "index.html").read_text()


def test_overview_is_saved_clean_and_executes_quickly():
    notebook = nbformat.read(OVERVIEW, as_version=4)
    code = [c for c in notebook.cells if c.cell_type == "code"]
    assert code and all(not c.outputs and c.execution_count is None for c in code), (
        "save the overview without outputs"
    )
    text = "\n".join(c.source for c in notebook.cells).lower()
    for part in (
        "interop",
        "why ray tracing",
        "intersection",
        "acceleration structures",
        "organising the tracer",
        "ray marching",
        "froxel",
        "rasteriz",
    ):
        assert part in text, f"the lecture plan does not mention {part!r}"
    start = time.perf_counter()
    stopped = execute(notebook, OVERVIEW.parent)
    seconds = time.perf_counter() - start
    assert stopped is None and error_cells(notebook) == 0
    assert seconds < 20, f"the overview took {seconds:.1f} s to execute"
    shown = "".join(
        o.get("data", {}).get("text/markdown", "")
        for c in notebook.cells
        if c.cell_type == "code"
        for o in c.outputs
    )
    for lab in sorted((ROOT / "labs").glob("lab*_*")):  # lab files and lab packages
        name = f"{lab.name}/" if lab.is_dir() else lab.name
        assert f"labs/{name}" in shown, f"the lab table misses {name}"
    present = {lab_number(p.name) for p in (ROOT / "labs").glob("lab*_*")}
    assert shown.count("*planned*") == len(set(range(7)) - present)
    assert any("image/png" in o.get("data", {}) for c in code for o in c.outputs), (
        "the overview draws its occupancy figure"
    )
