"""The lecture notebooks before the labs are written: reference figures and one line.

In the handout the notebooks import the student's ``labs/``, so a demo cell that calls a
function not written yet would end in a traceback and show no figure. ``rtcourse release``
runs every notebook on the reference solutions and keeps each code cell's figures and
tables in ``slides/figures/`` (:func:`save_reference_outputs`). A notebook's set-up cell
calls :func:`show_reference_when_unwritten`; from then on a cell that stops at an
unwritten lab function prints one line,

    write `march_box` (Lab 4, task 1) to see your own

and shows the reference outputs of that cell instead of a traceback, and the notebook runs
on. A cell that fails because it uses a name that such a cell should have made (a
``NameError``, or any error of a cell that reads a variable a stopped demo assigned, such
as the dict it was filling) is treated the same, with the line of the function that
stopped. Any other error shows its usual traceback. Outputs are found by the cell's
source, so an edited cell has none: it prints the line alone.
"""

from __future__ import annotations

import ast
import base64
import functools
import hashlib
import json
import sys
from dataclasses import dataclass
from pathlib import Path

from course.core.files import lab_source
from course.core.labs import lab_file_number

FIGURES = Path("slides") / "figures"  # under the course root
INDEX = "index.json"
_KEPT = ("image/png", "image/svg+xml", "text/html", "text/markdown", "text/latex", "text/plain")


def cell_key(source: str) -> str:
    """The key of a code cell's reference outputs: a hash of its source."""
    return hashlib.sha256(source.strip().encode()).hexdigest()[:20]


# ------------------------------------------------------------- at release: save outputs


def save_reference_outputs(notebook, name: str, folder) -> dict[str, dict]:
    """Keep the rich outputs (figures, tables, HTML) of every code cell of an executed
    ``notebook``: PNG images as ``folder/<name>_<cell>_<k>.png``, the rest inline. Returns
    the index entries (cell key -> where the outputs came from and what they are)."""
    folder = Path(folder)
    entries = {}
    for number, cell in enumerate(notebook.cells):
        if cell.cell_type != "code":
            continue
        kept = []
        for output in cell.get("outputs", []):
            if output.get("output_type") not in ("display_data", "execute_result"):
                continue
            data = {k: v for k, v in output.get("data", {}).items() if k in _KEPT}
            if "image/png" in data:
                file = f"{name}_{number}_{len(kept)}.png"
                folder.mkdir(parents=True, exist_ok=True)
                (folder / file).write_bytes(base64.b64decode(data.pop("image/png")))
                kept.append({"png": file, "metadata": dict(output.get("metadata", {}))})
            elif set(data) - {"text/plain"}:
                kept.append({"data": data, "metadata": dict(output.get("metadata", {}))})
        if kept:
            entries[cell_key(cell.source)] = {"notebook": name, "cell": number, "outputs": kept}
    return entries


def write_index(folder, entries: dict[str, dict]):
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / INDEX).write_text(json.dumps(entries, indent=1, sort_keys=True) + "\n")


# ---------------------------------------------------- in the notebook: the fallback


@dataclass
class Unwritten:
    function: str  # "march_box", or "FrameDownloader.submit" for a method
    lab: int
    task: int | None

    def line(self) -> str:
        where = f"Lab {self.lab}" + (f", task {self.task}" if self.task is not None else "")
        return f"write `{self.function}` ({where}) to see your own"


def unwritten_function(exc: BaseException, root=None) -> Unwritten | None:
    """The lab function whose ``NotImplementedError`` stopped ``exc`` (itself or the
    exceptions it was raised from), with its lab and task; None for any other error."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        seen.add(id(exc))
        if isinstance(exc, NotImplementedError):
            found = _from_not_implemented(exc, root)
            if found is not None:
                return found
        exc = exc.__cause__ or exc.__context__
    return None


def _from_not_implemented(exc: NotImplementedError, root) -> Unwritten | None:
    frames = []
    tb = exc.__traceback__
    while tb is not None:
        frames.append(tb.tb_frame)
        tb = tb.tb_next
    lab_frames = [f for f in frames if lab_file_number(f.f_code.co_filename) is not None]
    if not lab_frames:
        return None
    from course.grading.catalog import parse_not_implemented

    frame = lab_frames[-1]
    lab = lab_file_number(frame.f_code.co_filename)
    function, task = parse_not_implemented(str(exc))
    function = function or frame.f_code.co_name
    if task is None and root is not None:
        task = _task_from_graders(Path(root), lab, function.split(".")[0])
    return Unwritten(function, lab, task)


def _task_from_graders(root: Path, lab: int, function: str) -> int | None:
    """The task that asks for ``function``, read from the graders' markers in
    ``root/tests`` and the skeleton in ``root/labs`` (None where they do not say)."""
    return _lab_function_tasks(root, lab).get(function)


@functools.cache
def _lab_function_tasks(root: Path, lab: int) -> dict[str, int | None]:
    from course.grading.catalog import function_tasks, lab_catalog

    try:
        info = lab_catalog(sorted((root / "tests").glob(f"test_lab{lab}_*.py"))).get(lab)
        lab_file = lab_source(root / "labs", info.module) if info else None  # file or package
        if lab_file is None:
            return {}
        return function_tasks(info, lab_file)
    except (OSError, SyntaxError, ValueError):
        return {}


def names_assigned(code: str) -> set[str]:
    """Top-level names a cell's code binds or assigns into (``x = ...``, ``x[k] = ...``,
    ``x.a = ...``, loops, imports, definitions); empty where it does not parse."""
    try:
        tree = ast.parse(code)
    except SyntaxError:
        return set()
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Name) and isinstance(node.ctx, (ast.Store, ast.Del)):
            found.add(node.id)
        elif isinstance(node, (ast.Subscript, ast.Attribute)) and isinstance(
            node.ctx, (ast.Store, ast.Del)
        ):
            root = node.value
            while isinstance(root, (ast.Subscript, ast.Attribute)):
                root = root.value
            if isinstance(root, ast.Name):
                found.add(root.id)
        elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            found.add(node.name)
        elif isinstance(node, (ast.Import, ast.ImportFrom)):
            found |= {(a.asname or a.name).split(".")[0] for a in node.names}
    return found


def names_read(code: str) -> set[str]:
    try:
        tree = ast.parse(code)
    except SyntaxError:
        return set()
    return {n.id for n in ast.walk(tree) if isinstance(n, ast.Name) and isinstance(n.ctx, ast.Load)}


class _Fallback:
    """The IPython hooks: remember the running cell's source; on an error caused by an
    unwritten lab function print the line and show the cell's reference outputs."""

    def __init__(self, root: Path):
        self.root = root
        self.folder = root / FIGURES
        self.source = ""
        self.unmade: dict[str, Unwritten] = {}  # names a stopped cell left unmade or partial
        self.handled = False
        self._index = None

    def index(self) -> dict:
        if self._index is None:
            try:
                self._index = json.loads((self.folder / INDEX).read_text())
            except (OSError, ValueError):
                self._index = {}
        return self._index

    def pre_run_cell(self, info):
        self.source = getattr(info, "raw_cell", "") or ""
        self.handled = False

    def post_run_cell(self, result):
        # The cell was shown as the lecture shows it: it did not fail, so "run all" goes on.
        if self.handled and result is not None:
            result.error_in_exec = None
        elif self.unmade and result is not None and result.success:
            for name in names_assigned(self.source):  # made now, by a cell that ran
                self.unmade.pop(name, None)
        self.handled = False

    def cause(self, value, code: str) -> Unwritten | None:
        """The unwritten function this error comes from, or None for an error of its own."""
        found = unwritten_function(value, self.root)
        if found is not None:
            return found
        if isinstance(value, NameError):
            return self.unmade.get(getattr(value, "name", None))
        return next((self.unmade[n] for n in sorted(names_read(code)) if n in self.unmade), None)

    def handle(self, shell, etype, value, tb, tb_offset=None):
        try:
            code = shell.transform_cell(self.source)
        except Exception:  # noqa: BLE001  (a cell IPython cannot transform: use it as typed)
            code = self.source
        found = self.cause(value, code)
        if found is None:
            shell.showtraceback(running_compiled_code=True)
            return
        self.unmade.update(dict.fromkeys(names_assigned(code), found))
        self.handled = True
        if "matplotlib.pyplot" in sys.modules:  # a half-drawn figure of the failed demo
            sys.modules["matplotlib.pyplot"].close("all")
        self.show_reference(found.line())

    def show_reference(self, line: str):
        """``line``, then the reference outputs of the running cell. What the cell showed
        before it stopped (a table or two of the reference's six) is cleared first, so the
        cell reads as the reference's, not as a mix."""
        from IPython.display import Image, clear_output, display, publish_display_data

        entry = self.index().get(cell_key(self.source))
        if entry:
            sys.stdout.flush()
            clear_output()
        print(line)
        sys.stdout.flush()
        for output in (entry or {}).get("outputs", []):
            if "png" in output:
                path = self.folder / output["png"]
                if path.is_file():
                    display(Image(filename=str(path)), metadata=output.get("metadata") or None)
            else:
                publish_display_data(output["data"], output.get("metadata") or {})


def show_reference_when_unwritten(root) -> bool:
    """Install the fallback in the running IPython kernel (a no-op elsewhere, and when it
    is installed already). ``root`` is the course (or handout) folder. Returns whether
    the fallback is active."""
    try:
        from IPython import get_ipython
    except ImportError:
        return False
    shell = get_ipython()
    if shell is None:
        return False
    fallback = getattr(shell, "_rtcourse_fallback", None)
    if fallback is None:
        fallback = _Fallback(Path(root))
        shell._rtcourse_fallback = fallback
        shell.events.register("pre_run_cell", fallback.pre_run_cell)
        shell.events.register("post_run_cell", fallback.post_run_cell)
    fallback.root, fallback.folder = Path(root), Path(root) / FIGURES
    shell.set_custom_exc((Exception,), fallback.handle)
    return True
