"""What the grader reads from the course folder's source, never running it: which arguments
of a lab's functions are outputs (the reference's signatures), and the lines of the hidden
graders that no text shown to a student may hold (:class:`Redactor`).
"""

from __future__ import annotations

import ast
from pathlib import Path

from course.core.files import lab_source, module_files

# ------------------------------------------------------------ what the student may see


class Redactor:
    """Removes every line of the hidden graders' source from text shown to students."""

    def __init__(self, root=None):
        self.lines: set[str] = set()
        if root is None:
            return
        root = Path(root)
        visible = set()
        for path in [
            *root.glob("tests/test_*.py"),
            *(
                f
                for p in [*root.glob("labs/lab*"), *root.glob("solutions/lab*")]
                for f in module_files(p)
                if f.suffix == ".py"
            ),
        ]:
            visible |= _source_lines(path)
        for path in root.glob("tests/hidden/*.py"):
            self.lines |= _source_lines(path) - visible

    def __call__(self, text: str) -> str:
        if not self.lines or not text:
            return text
        out = []
        for line in text.splitlines(keepends=True):
            stripped = line.strip()
            if any(hidden in stripped for hidden in self._candidates(stripped)):
                out.append("[a line of a hidden test was removed]\n")
            else:
                out.append(line)
        return "".join(out)

    def _candidates(self, stripped):
        if stripped in self.lines:
            return (stripped,)
        if len(stripped) < 16:
            return ()
        return [h for h in self.lines if h in stripped]


def _source_lines(path) -> set[str]:
    try:
        text = Path(path).read_text(errors="replace")
    except OSError:
        return set()
    return {line.strip() for line in text.splitlines() if len(line.strip()) >= 16}


# ------------------------------------------------------------ the reference's signatures


def reference_file(root, name: str) -> Path | None:
    """The file whose signatures say which arguments are outputs: the reference
    (course repository, Gradescope package), else the skeleton (student handout)."""
    if root is None:
        return None
    for folder in ("solutions", "labs"):
        path = lab_source(Path(root) / folder, name)  # name.py, or the package name/
        if path is not None:
            return path
    return None


def reference_signatures(path) -> dict[str, list[str]] | None:
    """Positional parameter names of every function, class (its ``__init__``) and method
    (``Class.method``) of a lab file (and of its parts, for a reference kept in parts), read
    from its source without running it."""
    if path is None:
        return None
    body = [n for f in module_files(path) for n in ast.parse(f.read_text()).body]
    table: dict[str, list[str]] = {}

    def names(fn, drop_first):
        params = [a.arg for a in fn.args.posonlyargs + fn.args.args]
        return params[1:] if drop_first else params

    for node in body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            table[node.name] = names(node, False)
        elif isinstance(node, ast.ClassDef):
            table[node.name] = []
            for item in node.body:
                if isinstance(item, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    static = any(
                        isinstance(d, ast.Name) and d.id == "staticmethod"
                        for d in item.decorator_list
                    )
                    key = node.name if item.name == "__init__" else f"{node.name}.{item.name}"
                    table[key] = names(item, not static)
    return table
