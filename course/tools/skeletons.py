"""``rtcourse skeletons [--check]``: the student skeletons in ``labs/``, generated from the
references in ``solutions/``.

Each lab has one source, its reference, in which the code a student writes is marked
(the convention of nbgrader and otter-grader)::

    def march_box(origins, directions, ...):
        \"\"\"The specification the student reads.\"\"\"
        # Provided: validates the arguments (ValueError/TypeError naming the argument).
        origins, directions = check_inputs(...)
        # BEGIN SOLUTION (task 1)
        ...
        # END SOLUTION

A region inside a function becomes ``raise NotImplementedError("not implemented yet:
march_box (task 1)")`` at the marker's indentation: the function's qualified name
(``FrameLoop.step`` for a method) and the text after ``BEGIN SOLUTION``. A region outside
any function (a private helper or an import only the solution uses) is left out. Every
other line is copied as it is, so the docstrings, signatures, argument checks and given
helpers a student starts from are the reference's own, written once.

A lab is a file ``solutions/labN_topic.py`` or a package ``solutions/labN_topic/``; its
skeleton has the same name under ``labs/``. ``labs/`` is committed (students and the
handout need it) and never edited by hand: ``--check`` fails, naming the file and the
first differing line, when it is not what the references generate (CI runs it), and the
release writes the handout's ``labs/`` with the same generator.
"""

from __future__ import annotations

import ast
import re
from dataclasses import dataclass
from pathlib import Path

BEGIN = re.compile(r"^(?P<indent>[ \t]*)# BEGIN SOLUTION\b(?P<text>.*)$")
END = re.compile(r"^[ \t]*# END SOLUTION\s*$")
_FUNCTIONS = (ast.FunctionDef, ast.AsyncFunctionDef)


class MarkerError(ValueError):
    """A reference's solution markers do not pair up, or a region breaks the file."""


@dataclass(frozen=True)
class Region:
    begin: int  # 1-based line of ``# BEGIN SOLUTION``
    end: int  # 1-based line of ``# END SOLUTION``
    indent: str
    text: str  # what follows ``BEGIN SOLUTION`` on its line ("(task 1)")


def regions(source: str, name: str = "<source>") -> list[Region]:
    """The marked regions of ``source`` in order; ``MarkerError`` (naming ``name`` and the
    line) for a marker without its partner or a region inside another."""
    found, open_ = [], None
    for number, line in enumerate(source.splitlines(), 1):
        begin, end = BEGIN.match(line), END.match(line)
        if begin:
            if open_ is not None:
                raise MarkerError(
                    f"{name}:{number}: BEGIN SOLUTION inside the region opened at line {open_[0]}"
                )
            open_ = (number, begin["indent"], begin["text"].strip())
        elif end:
            if open_ is None:
                raise MarkerError(f"{name}:{number}: END SOLUTION without a BEGIN SOLUTION")
            found.append(Region(open_[0], number, open_[1], open_[2]))
            open_ = None
    if open_ is not None:
        raise MarkerError(f"{name}:{open_[0]}: BEGIN SOLUTION without an END SOLUTION")
    return found


def _enclosing_functions(tree: ast.Module) -> list[tuple[int, int, str]]:
    """``(first line, last line, qualified name)`` of every function and method."""
    spans = []

    def visit(node, prefix):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, _FUNCTIONS):
                name = prefix + child.name
                spans.append((child.lineno, child.end_lineno, name))
                visit(child, name + ".<locals>.")
            elif isinstance(child, ast.ClassDef):
                visit(child, prefix + child.name + ".")
            else:
                visit(child, prefix)

    visit(tree, "")
    return spans


def _stub(region: Region, functions, name: str) -> str | None:
    """The line that replaces ``region``: a ``raise`` inside its innermost function, nothing
    outside any function."""
    inside = [
        (first, qualname) for first, last, qualname in functions if first < region.begin <= last
    ]
    if not inside:
        return None
    qualname = max(inside)[1]
    message = f"not implemented yet: {qualname}" + (f" {region.text}" if region.text else "")
    if '"' in message or "\\" in message:
        raise MarkerError(
            f"{name}:{region.begin}: the text after BEGIN SOLUTION may not hold "
            f"a double quote or a backslash: {region.text!r}"
        )
    return f'{region.indent}raise NotImplementedError("{message}")'


def skeleton_source(source: str, name: str = "<source>") -> str:
    """The student's version of the reference text ``source`` (``name`` in errors)."""
    found = regions(source, name)
    if not found:
        return source
    functions = _enclosing_functions(ast.parse(source, filename=name))
    lines = source.splitlines()
    out: list[str] = []
    at = 0  # lines[:at] are done
    for region in found:
        out += lines[at : region.begin - 1]
        stub = _stub(region, functions, name)
        at = region.end
        if stub is not None:
            out.append(stub)
            continue
        # A block left out keeps the wider of the blank gaps around it, not both.
        before = len(out) - len(_without_trailing_blanks(out))
        after = 0
        while at < len(lines) and not lines[at].strip():
            at, after = at + 1, after + 1
        out += [""] * (max(before, after) - before if at < len(lines) else 0)
    out += lines[at:]
    text = "\n".join(_without_trailing_blanks(out)) + "\n"
    try:
        ast.parse(text, filename=name)
    except SyntaxError as exc:
        raise MarkerError(
            f"{name}: the generated skeleton does not parse (line {exc.lineno}: "
            f"{exc.msg}); a marked region must hold whole statements"
        ) from None
    return text


def _without_trailing_blanks(lines: list[str]) -> list[str]:
    end = len(lines)
    while end and not lines[end - 1].strip():
        end -= 1
    return lines[:end]


def lab_sources(solutions) -> list[Path]:
    """Every reference file that has a skeleton: ``labN_*.py`` files and the ``.py`` files
    of ``labN_*/`` packages under ``solutions`` (not its mutants)."""
    solutions = Path(solutions)
    files = [p for p in solutions.glob("lab*_*.py") if p.is_file()]
    for package in solutions.glob("lab*_*"):
        if package.is_dir() and (package / "__init__.py").is_file():
            files += [p for p in package.rglob("*.py") if "__pycache__" not in p.parts]
    return sorted(files)


def generate(solutions) -> dict[Path, str]:
    """Skeleton text per path relative to ``labs/`` (``lab4_march.py``)."""
    solutions = Path(solutions)
    return {
        path.relative_to(solutions): skeleton_source(path.read_text(), str(path))
        for path in lab_sources(solutions)
    }


def _generated_files(labs: Path) -> list[Path]:
    """What under ``labs`` the generator owns: lab files and the files of lab packages."""
    return lab_sources(labs)


def write(solutions, labs) -> list[Path]:
    """Write the skeletons of ``solutions`` into ``labs``, removing lab files there that no
    reference generates; return the paths written (relative to ``labs``)."""
    labs = Path(labs)
    wanted = generate(solutions)
    for stale in _generated_files(labs):
        if stale.relative_to(labs) not in wanted:
            stale.unlink()
    for rel, text in wanted.items():
        target = labs / rel
        target.parent.mkdir(parents=True, exist_ok=True)
        if not target.is_file() or target.read_text() != text:
            target.write_text(text)
    for folder in sorted(labs.glob("lab*_*"), reverse=True):  # packages left empty
        if folder.is_dir() and not any(p.suffix == ".py" for p in folder.rglob("*")):
            for leftover in sorted(folder.rglob("*"), reverse=True):
                leftover.unlink() if leftover.is_file() else leftover.rmdir()
            folder.rmdir()
    return sorted(wanted)


def differences(solutions, labs) -> list[str]:
    """One line per skeleton under ``labs`` that is not what ``solutions`` generates: the
    file and its first differing line, a missing file, a file no reference generates."""
    labs = Path(labs)
    wanted = generate(solutions)
    problems = []
    for rel, text in wanted.items():
        target = labs / rel
        if not target.is_file():
            problems.append(f"labs/{rel.as_posix()}: missing")
            continue
        have, want = target.read_text().splitlines(), text.splitlines()
        for number, (mine, theirs) in enumerate(zip(have, want, strict=False), 1):
            if mine != theirs:
                problems.append(
                    f"labs/{rel.as_posix()}:{number}: is {mine.strip()!r}, the "
                    f"reference generates {theirs.strip()!r}"
                )
                break
        else:
            if len(have) != len(want):
                number = min(len(have), len(want)) + 1
                problems.append(
                    f"labs/{rel.as_posix()}:{number}: {len(have)} lines, the "
                    f"reference generates {len(want)}"
                )
    for path in _generated_files(labs):
        if path.relative_to(labs) not in wanted:
            problems.append(
                f"labs/{path.relative_to(labs).as_posix()}: no reference in solutions/ generates it"
            )
    return problems


def main(root, check: bool = False, log=print) -> int:
    """``rtcourse skeletons``: regenerate ``labs/`` (or, with ``check``, compare)."""
    root = Path(root)
    solutions, labs = root / "solutions", root / "labs"
    if not solutions.is_dir():
        log(
            f"rtcourse skeletons: no solutions/ in {root} (the handout's labs/ are already "
            f"generated)"
        )
        return 2
    if check:
        problems = differences(solutions, labs)
        for line in problems:
            log(line)
        if problems:
            log(
                "labs/ is generated from solutions/: edit the reference, then run "
                "`rtcourse skeletons`"
            )
            return 1
        log(f"labs/: {len(generate(solutions))} files as the references generate them")
        return 0
    written = write(solutions, labs)
    log(f"labs/: {len(written)} files generated from solutions/")
    return 0
