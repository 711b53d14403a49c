"""The lecture in the handout: ``release(..., notes=...)`` ships the notebooks executed on
the references, their rendered notes and their figures; a demo that calls an unwritten lab
function shows the reference figure and one line, never a traceback."""

from __future__ import annotations

import json
import os
import textwrap
from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient
from nbformat.v4 import new_code_cell, new_markdown_cell, new_notebook

from course.tools.lecture import (
    FIGURES,
    INDEX,
    Unwritten,
    names_assigned,
    names_read,
    unwritten_function,
)
from course.tools.release import release

ROOT = Path(__file__).resolve().parents[2]
LINE = "write `wave` (Lab 9, task 2) to see your own"

SETUP = textwrap.dedent("""\
    import sys
    from pathlib import Path

    ROOT = next(p for p in [Path.cwd(), *Path.cwd().parents] if (p / "course").is_dir())
    IMPL = ROOT / ("solutions" if (ROOT / "solutions").is_dir() else "labs")
    sys.path[:0] = [str(IMPL), str(ROOT)]

    from course.tools.lecture import show_reference_when_unwritten

    show_reference_when_unwritten(ROOT)

    import lab9_toy as lab""")
DEMO = textwrap.dedent("""\
    import matplotlib.pyplot as plt
    from IPython.display import Markdown, display

    print("a wave of 8 samples")
    display(Markdown("| n | 8 |\\n|---|---|"))   # shown before the demo stops
    fig, ax = plt.subplots(figsize=(2, 1))
    waves = {}
    waves["long"] = lab.wave(8)   # the figure is half drawn when an unwritten wave raises
    ax.plot(waves["long"])
    plt.show()""")


def _toy_course(root: Path):
    """A course of one lab: task 1 is written in the skeleton, task 2 (``wave``) is not,
    and its message names no task (the graders' markers do)."""
    for folder in ("course", "labs", "solutions", "tests", "slides"):
        (root / folder).mkdir(parents=True)
    (root / "pyproject.toml").write_text("")
    (root / "course" / "README.md").write_text("the course package lives here\n")
    given = "def scale(n):\n    return 2 * n\n\n\n"
    (root / "solutions" / "lab9_toy.py").write_text(
        given + "def wave(n):\n    # BEGIN SOLUTION\n"
        "    return [((-1) ** i) * i for i in range(n)]\n    # END SOLUTION\n"
    )
    (root / "labs" / "lab9_toy.py").write_text(  # what the release generates from it
        given + 'def wave(n):\n    raise NotImplementedError("not implemented yet: wave")\n'
    )
    (root / "tests" / "test_lab9_toy.py").write_text(
        textwrap.dedent("""\
        import pytest

        LAB_MODULE = "lab9_toy"
        TASKS = {1: "Scale", 2: "Waves"}


        @pytest.mark.task(1)
        @pytest.mark.points(1)
        def test_scale(impl):
            assert impl.scale(2) == 4


        @pytest.mark.task(2)
        @pytest.mark.points(1)
        def test_wave_alternates(impl):
            assert impl.wave(3) == [0, -1, 2]
        """)
    )
    nbformat.write(
        new_notebook(
            cells=[
                new_markdown_cell("# Toy lecture"),
                new_code_cell(SETUP),
                new_code_cell("print('scale:', lab.scale(21))"),
                new_markdown_cell("## A wave"),
                new_code_cell(DEMO),
                new_code_cell("print('the wave ends at', waves['long'][-1])"),
                new_code_cell("print('after the demo')"),
            ]
        ),
        root / "slides" / "01_toy.ipynb",
    )


@pytest.fixture(scope="module")
def handout(tmp_path_factory):
    course = tmp_path_factory.mktemp("course")
    _toy_course(course)
    out = tmp_path_factory.mktemp("handout") / "handout"
    written = release(course, out, notes=True, log=lambda *_: None)
    return out, written


def test_release_ships_executed_notebooks_notes_and_figures(handout):
    out, written = handout
    assert not (out / "solutions").exists()
    shipped = nbformat.read(out / "slides" / "01_toy.ipynb", as_version=4)
    demo = shipped.cells[4]
    assert any("image/png" in o.get("data", {}) for o in demo.outputs), (
        "the handout's notebook opens with the reference figure"
    )
    assert "the wave ends at -7" in "".join(o.get("text", "") for o in shipped.cells[5].outputs)
    index = json.loads((out / FIGURES / INDEX).read_text())
    pngs = [o["png"] for entry in index.values() for o in entry["outputs"] if "png" in o]
    assert pngs and all((out / FIGURES / p).is_file() for p in pngs)
    notes = (out / "notes" / "01_toy.html").read_text()
    assert "data:image/png;base64," in notes and "the wave ends at -7" in notes
    assert (out / "notes" / "01_toy.slides.html").is_file()
    assert (out / "notes" / "_static" / "reveal" / "reveal.js").is_file()
    assert "reference solutions" in (out / "notes" / "index.html").read_text()
    assert Path("notes/01_toy.html") in written and Path("slides/01_toy.ipynb") in written


def test_unwritten_demo_shows_the_reference_figure_and_one_line(handout):
    out, _ = handout
    notebook = nbformat.read(out / "slides" / "01_toy.ipynb", as_version=4)
    for cell in notebook.cells:
        if cell.cell_type == "code":
            cell.outputs, cell.execution_count = [], None
    bug = new_code_cell("{}['a key that is not there']", metadata={"tags": ["raises-exception"]})
    notebook.cells.append(bug)
    # allow_errors=False: a cell whose reply is an error stops the run, as "run all" does,
    # except the one tagged raises-exception.
    NotebookClient(
        notebook,
        timeout=120,
        kernel_name="python3",
        resources={"metadata": {"path": str(out / "slides")}},
    ).execute()
    cells = [c for c in notebook.cells if c.cell_type == "code"]
    setup, written, demo, after_demo, after, bug = cells
    for cell in (setup, written, demo, after_demo, after):
        errors = [o for o in cell.outputs if o.output_type == "error"]
        assert not errors, f"cell {cell.source[:40]!r} shows an error: {errors}"
    assert "scale: 42" in _text(written), "a written function runs as usual"
    assert _text(demo).strip() == LINE, f"expected the one line {LINE!r}, got {_text(demo)!r}"
    images = [o for o in demo.outputs if "image/png" in o.get("data", {})]
    assert len(images) == 1, "the reference figure, and not the half-drawn one, is shown"
    tables = [o for o in demo.outputs if "text/markdown" in o.get("data", {})]
    assert len(tables) == 1, "the reference's table once, not the stopped cell's as well"
    assert _text(after_demo).strip() == LINE, (
        "a cell that fails on what the demo left unmade (its dict without the key) too"
    )
    assert "after the demo" in _text(after)
    assert [o.ename for o in bug.outputs if o.output_type == "error"] == ["KeyError"], (
        "any other error still shows its traceback"
    )


def _text(cell) -> str:
    return "".join(o.get("text", "") for o in cell.outputs if o.output_type == "stream")


def test_unwritten_function_names_lab_and_task_from_the_message_or_graders():
    namespace = {"__name__": "lab4_march"}
    code = compile(
        "def march_box():\n    raise NotImplementedError("
        "'not implemented yet: march_box (task 1)')\n",
        "labs/lab4_march.py",
        "exec",
    )
    exec(code, namespace)  # noqa: S102  (a stand-in for the skeleton's file)
    try:
        namespace["march_box"]()
    except NotImplementedError as exc:
        try:
            raise TypeError("while plotting") from exc
        except TypeError as outer:
            found = unwritten_function(outer)
    assert found == Unwritten("march_box", 4, 1)
    assert found.line() == "write `march_box` (Lab 4, task 1) to see your own"
    try:
        raise NotImplementedError("torch has no such kernel")
    except NotImplementedError as exc:
        assert unwritten_function(exc) is None, "only a lab file's stub counts"


def test_names_a_cell_assigns_and_reads():
    code = (
        "import numpy as np\nfor i in range(3):\n    rows[i] = f(i)\nstate.x = 1\n"
        "def g():\n    pass\nbest = max(rows)"
    )
    assert names_assigned(code) == {"np", "i", "rows", "state", "g", "best"}
    assert {"range", "rows", "f", "max"} <= names_read(code)
    assert names_assigned("%time x = 1") == set(), "IPython syntax: nothing known"


def _outputs_shown(cell) -> int:
    """Figures, animations and tables a code cell shows."""
    return sum(
        1
        for o in cell.get("outputs", [])
        if o.get("output_type") in ("display_data", "execute_result")
        and set(o.get("data", {})) - {"text/plain"}
    )


def _run_on_skeletons(handout_dir: Path, name: str):
    """Execute the handout's notebook ``name`` from scratch (its labs are the skeletons)
    as "run all" does; return the notebook as shipped and as run."""
    shipped = nbformat.read(handout_dir / "slides" / f"{name}.ipynb", as_version=4)
    run = nbformat.from_dict(json.loads(json.dumps(shipped)))
    for cell in run.cells:
        if cell.cell_type == "code":
            cell.outputs, cell.execution_count = [], None
    NotebookClient(
        run,
        timeout=600,
        kernel_name="python3",
        resources={"metadata": {"path": str(handout_dir / "slides")}},
    ).execute(env={**os.environ, "RTCOURSE_SMALL": "1"})
    return shipped, run


def _assert_every_figure_shown(shipped, run, name):
    lines = 0
    for number, (ref, got) in enumerate(zip(shipped.cells, run.cells)):
        if ref.cell_type != "code":
            continue
        assert not [o for o in got.outputs if o.output_type == "error"], (
            f"{name} cell {number}: an error in the handout before any lab is written"
        )
        assert _outputs_shown(got) == _outputs_shown(ref), (
            f"{name} cell {number}: shows {_outputs_shown(got)} of the references' "
            f"{_outputs_shown(ref)} figures and tables"
        )
        lines += "to see your own" in _text(got)
    assert lines, f"{name}: no demo needed an unwritten function, so nothing was checked"


def test_a_real_lecture_is_whole_in_a_handout_before_any_lab_is_written(tmp_path):
    out = tmp_path / "handout"
    release(ROOT, out, notes=["00_interop"], log=lambda *_: None)
    shipped, run = _run_on_skeletons(out, "00_interop")
    _assert_every_figure_shown(shipped, run, "00_interop")
    assert (out / "notes" / "00_interop.slides.html").is_file()


@pytest.mark.slow
def test_every_lecture_is_whole_in_a_handout_before_any_lab_is_written(tmp_path):
    out = tmp_path / "handout"
    release(ROOT, out, notes=True, log=lambda *_: None)
    for path in sorted((out / "slides").glob("*.ipynb")):
        if path.stem.endswith("_overview"):
            continue  # the lecture plan runs no lab
        shipped, run = _run_on_skeletons(out, path.stem)
        _assert_every_figure_shown(shipped, run, path.stem)
