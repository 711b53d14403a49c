"""``rtcourse slides``: the lecture notebooks as reveal.js slides and as lecture notes.

Every ``slides/*.ipynb`` is executed top to bottom (nbclient, in the folder ``slides/``,
with ``RTCOURSE_SMALL=1`` unless the caller set it: CPU-sized demos), so every number and
figure on a slide comes from the code on it. Each executed notebook is then written twice:

    NAME.slides.html   reveal.js slides (nbconvert's SlidesExporter)
    NAME.html          a static lecture-notes page (HTMLExporter)

plus ``index.html`` linking them. A cell that raises is kept, error and all, so the
rest of the notebook still renders; the command reports it and fails.

Slide breaks come from each cell's ``metadata.slideshow.slide_type``. Where a notebook
leaves it out, a markdown cell that starts with a heading opens a new slide (``#``/``##``)
or a sub-slide below the current one (``###`` and deeper); this is applied to the
in-memory copy only, never to the notebook file.
"""

from __future__ import annotations

import copy
import html
import os
import re
import time
from pathlib import Path

import nbformat

_HEADING = re.compile(r"^\s*(#{1,6})\s+(.+?)\s*#*\s*$")


def notebooks(root) -> list[Path]:
    """The lecture notebooks in lecture order: the overview first, then by file name."""
    return sorted(Path(root, "slides").glob("*.ipynb"),
                  key=lambda p: (not p.stem.endswith("_overview"), p.name))


def _heading(cell) -> tuple[int, str] | None:
    """(level, text) of the heading a markdown cell starts with, if any."""
    if cell.cell_type != "markdown":
        return None
    first = next((line for line in cell.source.splitlines() if line.strip()), "")
    match = _HEADING.match(first)
    return (len(match.group(1)), match.group(2)) if match else None


def title_of(notebook, default: str) -> str:
    for cell in notebook.cells:
        heading = _heading(cell)
        if heading:
            return heading[1]
    return default


def with_slide_types(notebook):
    """A copy of ``notebook`` where every heading cell without a slide type opens a slide
    (``#``, ``##``) or a sub-slide (deeper headings). Other cells keep their type or none
    (nbconvert's "-": the cell continues the current slide)."""
    notebook = copy.deepcopy(notebook)
    for cell in notebook.cells:
        slideshow = cell.metadata.setdefault("slideshow", {})
        heading = _heading(cell)
        if "slide_type" not in slideshow and heading:
            slideshow["slide_type"] = "slide" if heading[0] <= 2 else "subslide"
        if not slideshow:
            del cell.metadata["slideshow"]
    return notebook


def error_cells(notebook) -> int:
    return sum(any(o.get("output_type") == "error" for o in cell.get("outputs", []))
               for cell in notebook.cells if cell.cell_type == "code")


def execute(notebook, folder: Path, timeout: float = 600) -> str | None:
    """Run ``notebook`` in place in ``folder``; return why it stopped early, or None."""
    from nbclient import NotebookClient

    env = dict(os.environ)
    env.setdefault("RTCOURSE_SMALL", "1")
    client = NotebookClient(notebook, timeout=timeout, kernel_name="python3",
                            allow_errors=True, resources={"metadata": {"path": str(folder)}})
    try:
        client.execute(env=env)
    except Exception as exc:  # noqa: BLE001  (a cell timeout, a dead kernel: render what ran)
        return f"{type(exc).__name__}: {str(exc).strip().splitlines()[0] if str(exc) else ''}"
    return None


def render_notebook(path: Path, out: Path, *, execute_first=True) -> dict:
    """Execute one notebook and write its slides and notes; return its index row."""
    notebook = nbformat.read(path, as_version=4)
    title = title_of(notebook, path.stem)
    row = {"name": path.stem, "title": title, "slides": f"{path.stem}.slides.html",
           "notes": f"{path.stem}.html", "seconds": None, "stopped": None}
    if execute_first:
        start = time.perf_counter()
        row["stopped"] = execute(notebook, path.parent)
        row["seconds"] = time.perf_counter() - start
    row["errors"] = error_cells(notebook) + (row["stopped"] is not None)

    from nbconvert import HTMLExporter, SlidesExporter

    resources = {"metadata": {"name": title}}
    slides, _ = SlidesExporter(reveal_scroll=True).from_notebook_node(
        with_slide_types(notebook), resources=copy.deepcopy(resources))
    notes, _ = HTMLExporter().from_notebook_node(notebook, resources=copy.deepcopy(resources))
    (out / row["slides"]).write_text(slides, encoding="utf-8")
    (out / row["notes"]).write_text(notes, encoding="utf-8")
    return row


def render_slides(root, out, *, execute=True, log=print) -> list[dict]:
    """Render every notebook of ``root/slides`` into ``out``; write ``out/index.html``."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    paths = notebooks(root)
    if not paths:
        raise SystemExit(f"rtcourse slides: no notebooks in {Path(root, 'slides')}")
    rows = []
    for step, path in enumerate(paths, 1):
        log(f"[{step}/{len(paths)}] {path.name}: " + ("executing and " if execute else "")
            + "rendering ...")
        row = render_notebook(path, out, execute_first=execute)
        rows.append(row)
        seconds = f" in {row['seconds']:.1f} s" if row["seconds"] is not None else ""
        problem = (f"; stopped early ({row['stopped']})" if row["stopped"] else
                   f"; {row['errors']} cell(s) raised" if row["errors"] else "")
        log(f"    done{seconds}{problem}")
    _write_index(out, rows, executed=execute)
    return rows


def _status(row, executed: bool) -> str:
    if not executed:
        return "outputs as saved"
    if row["stopped"]:
        return f"stopped early: {row['stopped']}"
    status = f"executed in {row['seconds']:.1f} s"
    return status + (f", {row['errors']} cell(s) raised" if row["errors"] else "")


def _write_index(out: Path, rows: list[dict], *, executed: bool):
    esc = html.escape
    items = "".join(
        f"<tr><td>{esc(row['title'])}</td><td><a href=\"{esc(row['slides'])}\">slides</a></td>"
        f"<td><a href=\"{esc(row['notes'])}\">notes</a></td>"
        f"<td>{esc(_status(row, executed))}</td></tr>" for row in rows)
    small = os.environ.get("RTCOURSE_SMALL", "1")
    (out / "index.html").write_text(
        "<!doctype html><meta charset=utf-8><title>GPU ray tracing with PyTorch: lectures"
        "</title><style>body{font-family:sans-serif;margin:2em}td,th{padding:.3em 1em;"
        "text-align:left}</style><h1>GPU ray tracing with PyTorch: lectures</h1>"
        "<p>Each lecture as reveal.js slides (arrow keys to move, <kbd>Esc</kbd> for an overview) "
        "and as a static page of lecture notes. "
        + (f"Outputs and figures come from running every notebook (RTCOURSE_SMALL={esc(small)})."
           if executed else "Outputs are those saved in the notebooks.")
        + "</p><table><tr><th>lecture</th><th></th><th></th><th>outputs</th></tr>"
        + items + "</table>", encoding="utf-8")
