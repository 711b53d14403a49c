"""The pass-through table in Lab 1's docstring is the bench's output, re-run here.

``python bench/lab1_intersect.py --device cpu --crack-table`` prints the table; the lab's
docstring, in ``solutions/lab1_intersect/__init__.py`` and in the student's
``labs/lab1_intersect/__init__.py``, quotes it verbatim, so every crack figure a student reads
is one the bench produces on this checkout.
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

import torch

REPO = Path(__file__).resolve().parents[2]
DOCSTRING = "lab1_intersect/__init__.py"  # the lab's docstring, under solutions/ and labs/


def _bench():
    spec = importlib.util.spec_from_file_location(
        "bench_lab1", REPO / "bench" / "lab1_intersect.py"
    )
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    return bench


def _quoted_table(text: str) -> str:
    """The block from "Pass-throughs (" to the line that ends the table's notes."""
    start = text.index("Pass-throughs (")
    end = text.index("zero-area triangles ", start)
    return text[start : text.index("\n", end)]


def test_docstring_crack_table_is_the_benchs_output():
    torch.manual_seed(0)
    bench = _bench()
    measured = bench.crack_table(ico_level=2, device=torch.device("cpu"))
    for folder in ("solutions", "labs"):
        text = (REPO / folder / DOCSTRING).read_text()
        quoted = _quoted_table(text)
        if quoted != measured:
            diff = [
                f"  docstring: {a}\n  bench:     {b}"
                for a, b in zip(quoted.splitlines(), measured.splitlines())
                if a != b
            ]
            raise AssertionError(
                f"{folder}/{DOCSTRING}: the pass-through table differs from "
                f"`python bench/lab1_intersect.py --device cpu --crack-table`; paste the "
                f"bench's output. Differing lines:\n" + "\n".join(diff[:8])
            )


def _quoted_far_table(text: str) -> str:
    """The block from "Far field (" to the table's closing rule."""
    lines = text[text.index("Far field (") :].splitlines()
    rules = [i for i, line in enumerate(lines) if line.startswith("========")]
    return "\n".join(lines[: rules[2] + 1])


def test_docstring_far_field_table_is_the_benchs_output():
    spec = importlib.util.spec_from_file_location("bench_lab1_far", REPO / "bench" / "lab1_far.py")
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    measured = bench.table(bench.measure(bench.load_lab("lab1_intersect", "solutions", REPO)))
    for folder in ("solutions", "labs"):
        quoted = _quoted_far_table((REPO / folder / DOCSTRING).read_text())
        assert quoted == measured, (
            f"{folder}/{DOCSTRING}: the far-field table differs from `python "
            f"bench/lab1_far.py`; paste the bench's output.\n{quoted}\n---\n{measured}"
        )
