"""``rtcourse release OUT``: the student handout.

Everything a student needs and nothing they must not see: the reference
solutions, the mutants, the hidden graders (``tests/hidden``) and the tests of the
course itself stay behind. In the handout the graders default to ``labs/`` because
there is no ``solutions/``. The handout also gets ``labs/README.md``, generated from
the graders: each lab's tasks and points, how to test one lab or one function, and
how to see one's score.

With ``notes`` (``rtcourse release`` does it unless ``--no-notes``) the handout also gets
the lecture as the references draw it: every notebook is executed here, on the reference
solutions (``RTCOURSE_SMALL=1``), and shipped with its outputs in ``slides/``, rendered as
slides and lecture notes into ``notes/`` (offline pages, see ``course.tools.slides``), and its
figures and tables are kept per cell in ``slides/figures/``, where a notebook run on the
student's unwritten labs finds them (``course.tools.lecture``).
"""

from __future__ import annotations

import ast
import shutil
import subprocess
import time
from pathlib import Path

from course.core.files import lab_source
from course.grading.catalog import LabInfo, lab_catalog, skeleton_functions
from course.grading.taskdoc import package_files, task_table
from course.tools.skeletons import write as write_skeletons

# Paths (relative to the repository root) that never ship to students.
# tests/contracts names hidden tests and the mutants each one catches: the graders' own notes.
WITHHELD = (
    "solutions",
    "tests/meta",
    "tests/hidden",
    "tests/contracts",
    ".git",
    ".venv",
    ".ci",
    "out",
    "build",
    "dist",
)
_IGNORED_NAMES = (
    "__pycache__",
    ".pytest_cache",
    ".ruff_cache",
    ".ipynb_checkpoints",
    "*.egg-info",
    "results.json",
)
LABS_README = Path("labs") / "README.md"


def _tracked_files(root: Path) -> list[Path] | None:
    try:
        out = subprocess.run(
            ["git", "ls-files", "--cached", "--others", "--exclude-standard"],
            cwd=root,
            capture_output=True,
            text=True,
            check=True,
        ).stdout
    except (OSError, subprocess.CalledProcessError):
        return None
    return [Path(line) for line in out.splitlines() if line]


def _under(rel: Path, prefixes) -> bool:
    parts = rel.as_posix()
    return any(parts == w or parts.startswith(w + "/") for w in prefixes)


def _withheld(rel: Path) -> bool:
    return _under(rel, WITHHELD)


def course_files(root, withheld=WITHHELD) -> list[Path]:
    """Files of the course at ``root`` (git's view when it is a checkout: tracked and
    untracked-but-not-ignored), relative to ``root``, minus the ``withheld`` paths."""
    root = Path(root)
    files = _tracked_files(root)
    if files is None:  # not a git checkout: walk the tree instead
        ignore = shutil.ignore_patterns(*_IGNORED_NAMES)
        files = [
            path.relative_to(root)
            for path in root.rglob("*")
            if path.is_file()
            and not any(ignore("", [part]) for part in path.relative_to(root).parts)
        ]
    return sorted(rel for rel in files if not _under(rel, withheld) and (root / rel).is_file())


def release(root, out, *, notes=False, reference_rows=False, log=print) -> list[Path]:
    """Copy the handout of the course at ``root`` into ``out``; return the files written.
    ``notes``: also ship the executed lecture notebooks, their rendered notes and their
    reference figures (True: every notebook; or a list of notebook names).
    ``reference_rows``: also measure every lab's reference with ``rtcourse bench --quick``
    on the CPU and ship its rows, with a calibration time, as ``bench/reference/labN.csv``:
    the reference points of a student's ``rtcourse bench`` (``course.tools.trade``)."""
    root, out = Path(root).resolve(), Path(out).resolve()
    if out == root or root in out.parents and not _withheld(out.relative_to(root)):
        raise ValueError(f"out: the handout folder {out} must lie outside the course folder")
    written = []
    for rel in course_files(root):
        if (root / "solutions").is_dir() and _under(rel, ("labs",)) and rel.suffix == ".py":
            continue  # the skeletons come from the references, below
        dest = out / rel
        dest.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(root / rel, dest)
        written.append(rel)
    if (root / "solutions").is_dir():
        # The handout's skeletons are generated from the references by the generator that
        # writes the committed labs/ (rtcourse skeletons), never copied by hand.
        written += [Path("labs") / rel for rel in write_skeletons(root / "solutions", out / "labs")]
    if (out / "labs").is_dir():
        (out / LABS_README).write_text(labs_readme(out, hidden_root=root))
        written.append(LABS_README)
    if reference_rows and (root / "solutions").is_dir():
        from course.tools.trade import write_reference_rows

        log("reference rows for rtcourse bench (every lab's reference, --quick, CPU) ...")
        written += write_reference_rows(root, out, log=log)
    if notes:
        written += lecture_notes(root, out, names=None if notes is True else notes, log=log)
    return written


NOTES = Path("notes")


def lecture_notes(root, out, names=None, log=print) -> list[Path]:
    """Execute the lecture notebooks of ``root`` (on its reference solutions) and write
    into the handout ``out``: each executed notebook over ``slides/NAME.ipynb``, its
    slides and notes into ``notes/`` with an index, and its cells' figures and tables into
    ``slides/figures/``. Returns the files written, relative to ``out``. A notebook that
    raises on the references stops the release: its notes would teach an error."""
    import nbformat

    from course.tools.lecture import FIGURES, save_reference_outputs
    from course.tools.lecture import write_index as write_figures
    from course.tools.slides import (
        error_cells,
        execute,
        progress_bar,
        render_notebook,
        select_notebooks,
        write_index,
    )

    root, out = Path(root), Path(out)
    paths = select_notebooks(root, names)
    entries, rows = {}, []
    bar = progress_bar(len(paths), "lecture notes")
    say = log if bar is None else bar.write
    try:
        for step, path in enumerate(paths, 1):
            if bar is None:
                say(
                    f"[{step}/{len(paths)}] lecture notes: executing {path.name} on the "
                    f"references ..."
                )
            notebook = nbformat.read(path, as_version=4)
            start = time.perf_counter()
            stopped = execute(notebook, path.parent)
            if stopped or error_cells(notebook):
                raise RuntimeError(
                    f"{path.name}: "
                    + (
                        f"stopped early ({stopped})"
                        if stopped
                        else f"{error_cells(notebook)} cell(s) raised"
                    )
                    + " on the reference solutions; fix it before a release "
                    "(rtcourse slides shows the error)"
                )
            seconds = time.perf_counter() - start
            entries.update(save_reference_outputs(notebook, path.stem, out / FIGURES))
            shipped = out / "slides" / path.name
            shipped.parent.mkdir(parents=True, exist_ok=True)
            nbformat.write(notebook, shipped)
            row = render_notebook(shipped, out / NOTES, execute_first=False, notebook=notebook)
            rows.append(dict(row, seconds=seconds))
            say(f"    {path.name}: lecture notes in {seconds:.1f} s")
            if bar is not None:
                bar.update()
    finally:
        if bar is not None:
            bar.close()
    write_figures(out / FIGURES, entries)
    write_index(
        out / NOTES,
        rows,
        executed=True,
        note="Outputs and figures are those of the reference solutions, from running "
        "every notebook when this handout was made (RTCOURSE_SMALL=1). Run a "
        "notebook in slides/ to see your own.",
    )
    return sorted(
        p.relative_to(out)
        for folder in (out / NOTES, out / FIGURES)
        for p in folder.rglob("*")
        if p.is_file()
    ) + [Path("slides") / p.name for p in paths]


# ------------------------------------------------------------------ labs/README.md


def _pts(points: float) -> str:
    return f"{points:g}"


def _lab_title(lab_file: Path, number: int) -> str:
    """The first line of the skeleton's docstring ("Lab 0: interop — ..."; of a package's
    ``__init__.py``)."""
    try:
        source = lab_file / "__init__.py" if lab_file.is_dir() else lab_file
        doc = ast.get_docstring(ast.parse(source.read_text())) or ""
    except (OSError, SyntaxError):
        doc = ""
    return doc.strip().splitlines()[0].rstrip(".") if doc.strip() else f"Lab {number}"


def _lab_section(
    root: Path, lab: LabInfo, hidden: LabInfo | None, reference: Path | None = None
) -> list[str]:
    lab_file = lab_source(root / "labs", lab.module) or root / "labs" / f"{lab.module}.py"
    test_file = lab.files[0].relative_to(root).as_posix()
    if lab_file.is_dir():
        handed = ", ".join(f"`{name}`" for name in package_files(lab, lab_file))
        your_file = (
            f"Your files: the package `labs/{lab.module}/` (hand in the files you "
            f"edit: {handed}; one left out is graded as the skeleton's)"
        )
    else:
        your_file = (
            f"Your file: `labs/{lab.module}.py`"
            if lab_file.is_file()
            else f"Your file `labs/{lab.module}.py` is not in this handout yet"
        )
    lines = [
        f"## {_lab_title(lab_file, lab.number)}",
        "",
        f"{your_file} · its grader: `{test_file}` · {_pts(lab.points())} points",
        "",
        *task_table(lab, lab_file, test_file, reference),
    ]
    extra = [t for t in lab.tests if t.needs]
    notes = []
    if extra:
        notes.append(
            f"Tests worth {_pts(sum(t.points for t in extra))} more points run only "
            f"with a CUDA GPU or with `--runslow`; `rtcourse grade` counts them "
            f"only where they run."
        )
    if hidden is not None and hidden.points() > 0:
        more = hidden.points()
        notes.append(
            f"The course's autograder also runs hidden tests of this lab, worth "
            f"{_pts(more)} more point{'s' * (more != 1)}, that are not in this handout. "
            f"They check the same contracts (each function's docstring) on other "
            f"inputs: meet the docstring, not just the visible tests."
        )
    return lines + ([""] + notes if notes else []) + [""]


def _commented(rows) -> str:
    width = max(len(cmd) for cmd, _ in rows) + 2
    return "\n".join(f"{cmd:<{width}}# {why}" for cmd, why in rows)


def labs_readme(root, hidden_root=None) -> str:
    """The handout's ``labs/README.md``, from the graders in ``root/tests`` (and the hidden
    graders of ``hidden_root``, whose points it mentions without shipping them)."""
    from course.grading.runner import lab_test_files

    root = Path(root)
    labs = lab_catalog(sorted((root / "tests").glob("test_lab*_*.py")))
    hidden = {}
    if hidden_root is not None:
        hidden = lab_catalog(
            [f for f in lab_test_files(Path(hidden_root)) if f.parent.name == "hidden"]
        )
    example = next(iter(labs.values()), None)
    first = (
        example.files[0].relative_to(root).as_posix() if example else "tests/test_lab0_interop.py"
    )
    number = example.number if example else 0
    example_file = lab_source(root / "labs", example.module) if example else None
    functions = skeleton_functions(example_file) if example_file else []
    fn = functions[0] if functions else "pack_rgba8"
    test_cmds = _commented(
        [
            (f"python -m pytest {first}", f"all tests of lab {number}"),
            (f"python -m pytest {first} --task 1", "exactly the tests of task 1's points"),
            (f"python -m pytest {first} -k {fn}", "only the tests of one function"),
            (f"python -m pytest {first} -x -k {fn}", "stop at the first failure"),
        ]
    )
    grade_cmds = _commented(
        [
            (f"rtcourse grade --lab {number}", f"per-task score table of lab {number}"),
            ("rtcourse grade", "every lab (the same as `make grade`)"),
            (f"rtcourse grade --lab {number} --json results.json", "also write results.json"),
        ]
    )
    head = f"""# The labs

Generated by `rtcourse release` from the graders in `tests/`: what each lab asks for and
what it is worth.

Each lab is one file here, `labN_topic.py`, or a package folder `labN_topic/` with one
module per topic (the lab's section below says which file holds each task). Fill in every
function that raises `NotImplementedError("not implemented yet: ...")`: its docstring
states the task, the shapes and dtypes, the accuracy contract and hints, and the module
docstring at the top of the file (of a package: its `__init__.py`) explains the lab. Keep
the names, signatures and file names: the grader calls them.

Run every command below from the handout's top folder (the one holding `Makefile`), after
`make test` has created `.venv` once: activate it with `source .venv/bin/activate`, or
type `.venv/bin/python` and `.venv/bin/rtcourse` instead of `python` and `rtcourse`.

## Test one lab, one function

```sh
{test_cmds}
```

The tests run your `labs/` files. A function you have not written yet fails with
"not implemented yet: ..."; a wrong one fails with what was expected, what came back and
where (the first differing pixel, ray or element). `-k` selects the tests whose name
contains the words you give, so `-k pack_rgba8` also runs the tests of `unpack_rgba8`.

## See your score

```sh
{grade_cmds}
```

Your code runs in a separate, sandboxed process with a time limit per test, as it will on
the course's autograder: a crash or an endless loop costs that test, not the run. A test's
points are split evenly over its cases (devices, dtypes, sizes), so a partly working
function earns part of its points.

"""
    sections = []
    solutions = Path(hidden_root if hidden_root is not None else root) / "solutions"
    for number_, lab in labs.items():
        sections += _lab_section(root, lab, hidden.get(number_), lab_source(solutions, lab.module))
    return head + "\n".join(sections)
