"""``rtcourse slides``: the lecture notebooks as reveal.js slides and as lecture notes.

Every ``slides/*.ipynb`` (or only the notebooks named) is executed top to bottom
(nbclient, in the notebook's folder, with ``RTCOURSE_SMALL=1`` unless the caller set it:
CPU-sized demos), so every number and figure on a slide comes from the code on it. Each
executed notebook is then written twice:

    NAME.slides.html   reveal.js slides (nbconvert's SlidesExporter)
    NAME.html          a static lecture-notes page (HTMLExporter)

plus ``index.html`` linking them. A cell that raises is kept, error and all, so the
rest of the notebook still renders; the command reports it and fails.

The pages work without a network: reveal.js, MathJax 2 (the version nbconvert's templates
configure), require.js and jQuery are copied from ``course/assets/web`` into ``_static/``
next to the pages, and the pages point there instead of at a CDN (nbconvert's Mermaid
loader, which no lecture uses, is left out).

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
import shutil
import tempfile
import time
from pathlib import Path

import nbformat

_HEADING = re.compile(r"^\s*(#{1,6})\s+(.+?)\s*#*\s*$")

ASSETS = Path(__file__).resolve().parents[1] / "assets" / "web"
STATIC = "_static"  # the pages' folder of browser files, next to them
_REVEAL = f"{STATIC}/reveal"
PAGE_URLS = {  # nbconvert's CDN addresses, replaced by the copies in STATIC
    "reveal_url_prefix": _REVEAL,
    "mathjax_url": f"{STATIC}/mathjax/MathJax.js?config=TeX-AMS_CHTML-full,Safe",
    "require_js_url": f"{STATIC}/requirejs/require.js",
    "jquery_url": f"{STATIC}/jquery/jquery.min.js",
}
# nbconvert's page templates, less the Mermaid module it imports from a CDN.
_TEMPLATE = "rtcourse_offline.html.j2"
# On a slide, a code line of the course's 100 columns fits at 14 px and scrolls if it does not;
# an output keeps its lines (JupyterLab's wrapping splits a number across two lines).
_CSS = """<style type="text/css">
.reveal { --jp-code-font-size: 14px; --jp-cell-prompt-width: 64px; }
.jp-InputArea-editor pre, .jp-RenderedText pre { overflow-x: auto; }
.jp-RenderedText pre { white-space: pre; word-break: normal; overflow-wrap: normal; }
</style>"""
_TEMPLATE_TEXT = (
    "{%- extends 'index.html.j2' -%}\n"
    "{% block html_head_js_mermaidjs %}{% endblock html_head_js_mermaidjs %}\n"
    "{% block html_head_css %}" + _CSS + "{% endblock html_head_css %}\n"
)


def notebooks(root) -> list[Path]:
    """The lecture notebooks in lecture order: the overview first, then by file name."""
    return sorted(
        Path(root, "slides").glob("*.ipynb"),
        key=lambda p: (not p.stem.endswith("_overview"), p.name),
    )


def select_notebooks(root, names=None) -> list[Path]:
    """The notebooks ``names`` picks (a path to a notebook, or a name in ``root/slides``
    with or without ``.ipynb``), in lecture order; every notebook when ``names`` is empty."""
    every = notebooks(root)
    if not names:
        return every
    by_name = (
        {p.stem: p for p in every}
        | {p.name: p for p in every}
        | {str(p.resolve()): p for p in every}
    )
    chosen = []
    for name in names:
        path = Path(name)
        found = by_name.get(str(name))
        if found is None and path.suffix == ".ipynb" and path.is_file():
            found = by_name.get(str(path.resolve()), path.resolve())
        if found is None:
            known = ", ".join(p.stem for p in every) or "none"
            raise ValueError(
                f"notebook {name!r}: no such notebook in "
                f"{Path(root, 'slides')} (there are: {known})"
            )
        if found not in chosen:
            chosen.append(found)
    order = {p: i for i, p in enumerate(every)}
    return sorted(chosen, key=lambda p: (order.get(p, len(order)), p.name))


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
    return sum(
        any(o.get("output_type") == "error" for o in cell.get("outputs", []))
        for cell in notebook.cells
        if cell.cell_type == "code"
    )


def execute(notebook, folder: Path, timeout: float = 600) -> str | None:
    """Run ``notebook`` in place in ``folder``; return why it stopped early, or None."""
    from jupyter_client import KernelManager
    from nbclient import NotebookClient

    env = dict(os.environ)
    env.setdefault("RTCOURSE_SMALL", "1")
    with tempfile.TemporaryDirectory(prefix="rtk") as sockets:
        # The kernel talks over local (Unix) sockets where there are some: over TCP it
        # warns once per notebook that the channel is unencrypted, although nothing but
        # this process connects to it.
        ipc = {"transport": "ipc", "ip": os.path.join(sockets, "k")} if os.name == "posix" else {}
        client = NotebookClient(
            notebook,
            km=KernelManager(kernel_name="python3", **ipc),
            timeout=timeout,
            allow_errors=True,
            resources={"metadata": {"path": str(folder)}},
        )
        try:
            client.execute(env=env)
        except Exception as exc:  # noqa: BLE001  (a cell timeout, a dead kernel: render what ran)
            return f"{type(exc).__name__}: {str(exc).strip().splitlines()[0] if str(exc) else ''}"
    return None


# ------------------------------------------------------------------ offline pages


def copy_static(out) -> Path:
    """Copy the pages' browser files into ``out/_static`` (once: files already there and
    of the same size are kept); return that folder."""
    target = Path(out) / STATIC
    for source in ASSETS.rglob("*"):
        if source.is_file():
            dest = target / source.relative_to(ASSETS)
            if not dest.is_file() or dest.stat().st_size != source.stat().st_size:
                dest.parent.mkdir(parents=True, exist_ok=True)
                shutil.copyfile(source, dest)
    return target


def _exporter(kind):
    import jinja2

    urls = {k: v for k, v in PAGE_URLS.items() if k in kind.class_trait_names()}
    return kind(
        extra_loaders=[jinja2.DictLoader({_TEMPLATE: _TEMPLATE_TEXT})],
        template_file=_TEMPLATE,
        **urls,
    )


def _local_reveal(page: str) -> str:
    """reveal.js's files sit in ``_static/reveal`` without the package's ``dist/`` folder
    (a name that ``.gitignore`` files skip)."""
    return page.replace(f"{_REVEAL}/dist/", f"{_REVEAL}/")


def render_notebook(path: Path, out: Path, *, execute_first=True, notebook=None) -> dict:
    """Execute one notebook (or take ``notebook``, already read) and write its slides and
    notes into ``out``; return its index row."""
    from nbconvert import HTMLExporter, SlidesExporter

    path = Path(path)
    notebook = nbformat.read(path, as_version=4) if notebook is None else notebook
    title = title_of(notebook, path.stem)
    row = {
        "name": path.stem,
        "title": title,
        "slides": f"{path.stem}.slides.html",
        "notes": f"{path.stem}.html",
        "seconds": None,
        "stopped": None,
    }
    if execute_first:
        start = time.perf_counter()
        row["stopped"] = execute(notebook, path.parent)
        row["seconds"] = time.perf_counter() - start
    row["errors"] = error_cells(notebook) + (row["stopped"] is not None)

    resources = {"metadata": {"name": title}}
    slides_exporter = _exporter(SlidesExporter)
    slides_exporter.reveal_scroll, slides_exporter.reveal_theme = True, "white"
    slides, _ = slides_exporter.from_notebook_node(
        with_slide_types(notebook), resources=copy.deepcopy(resources)
    )
    notes, _ = _exporter(HTMLExporter).from_notebook_node(
        notebook, resources=copy.deepcopy(resources)
    )
    out = Path(out)
    copy_static(out)
    (out / row["slides"]).write_text(_local_reveal(slides), encoding="utf-8")
    (out / row["notes"]).write_text(notes, encoding="utf-8")
    return row


def progress_bar(total: int, desc: str):
    """A per-notebook progress bar (``course.core.progress``: tqdm, on a terminal); None when
    output goes elsewhere (a log, a pipe, CI), where callers print a line per notebook."""
    from course.core.progress import progress, progress_enabled

    if not progress_enabled():
        return None
    return progress(total=total, desc=desc, unit="notebook", leave=True)


def render_slides(root, out, *, execute=True, log=print, names=None) -> list[dict]:
    """Render the notebooks ``names`` picks (default: every notebook of ``root/slides``)
    into ``out``; write ``out/index.html``, which also lists the pages of notebooks
    rendered there earlier. Returns the rows of the notebooks rendered now."""
    out = Path(out)
    paths = select_notebooks(root, names)
    if not paths:
        raise SystemExit(f"rtcourse slides: no notebooks in {Path(root, 'slides')}")
    out.mkdir(parents=True, exist_ok=True)
    bar = progress_bar(len(paths), "slides")
    say = log if bar is None else bar.write
    rows = []
    try:
        for step, path in enumerate(paths, 1):
            doing = ("executing and " if execute else "") + "rendering"
            if bar is None:
                say(f"[{step}/{len(paths)}] {path.name}: {doing} ...")
            else:
                bar.set_postfix_str(f"{path.name}: {doing}")
            row = render_notebook(path, out, execute_first=execute)
            rows.append(row)
            seconds = f" in {row['seconds']:.1f} s" if row["seconds"] is not None else ""
            problem = (
                f"; stopped early ({row['stopped']})"
                if row["stopped"]
                else f"; {row['errors']} cell(s) raised"
                if row["errors"]
                else ""
            )
            say(
                f"    {path.name} done{seconds}{problem}"
                if bar is not None
                else f"    done{seconds}{problem}"
            )
            if bar is not None:
                bar.update()
    finally:
        if bar is not None:
            bar.close()
    rendered = {row["name"] for row in rows}
    earlier = [
        {
            "name": p.stem,
            "title": p.stem,
            "slides": f"{p.stem}.slides.html",
            "notes": f"{p.stem}.html",
            "earlier": True,
        }
        for p in notebooks(root)
        if p.stem not in rendered and (out / f"{p.stem}.html").is_file()
    ]
    order = {p.stem: i for i, p in enumerate(notebooks(root))}
    listed = sorted(rows + earlier, key=lambda r: (order.get(r["name"], len(order)), r["name"]))
    write_index(out, listed, executed=execute)
    return rows


def _status(row, executed: bool) -> str:
    if row.get("earlier"):
        return "rendered by an earlier run"
    if not executed:
        return "outputs as saved"
    if row["stopped"]:
        return f"stopped early: {row['stopped']}"
    status = f"executed in {row['seconds']:.1f} s"
    return status + (f", {row['errors']} cell(s) raised" if row["errors"] else "")


def write_index(out: Path, rows: list[dict], *, executed: bool, note: str | None = None):
    """``out/index.html``: one line per lecture, linking its slides and notes. ``note``
    replaces the sentence that says where the outputs come from."""
    esc = html.escape
    items = "".join(
        f'<tr><td>{esc(row["title"])}</td><td><a href="{esc(row["slides"])}">slides</a></td>'
        f'<td><a href="{esc(row["notes"])}">notes</a></td>'
        f"<td>{esc(_status(row, executed))}</td></tr>"
        for row in rows
    )
    small = os.environ.get("RTCOURSE_SMALL", "1")
    if note is None:
        note = (
            f"Outputs and figures come from running every notebook (RTCOURSE_SMALL={small})."
            if executed
            else "Outputs are those saved in the notebooks."
        )
    Path(out, "index.html").write_text(
        "<!doctype html><meta charset=utf-8><title>GPU ray tracing with PyTorch: lectures"
        "</title><style>body{font-family:sans-serif;margin:2em}td,th{padding:.3em 1em;"
        "text-align:left}</style><h1>GPU ray tracing with PyTorch: lectures</h1>"
        "<p>Each lecture as reveal.js slides (arrow keys to move, <kbd>Esc</kbd> for an overview) "
        "and as a static page of lecture notes. "
        + esc(note)
        + "</p><table><tr><th>lecture</th><th></th><th></th><th>outputs</th></tr>"
        + items
        + "</table>",
        encoding="utf-8",
    )
