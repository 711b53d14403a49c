"""The handout's ``labs/README.md`` and a student's first step with it: write one function
pair from its docstring, and the README's command for its task scores exactly the points
of its tests."""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

import pytest

from course.core.files import module_files
from course.grading.catalog import lab_catalog
from course.grading.runner import lab_test_files
from course.tools.release import LABS_README, release

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def handout(tmp_path_factory):
    out = tmp_path_factory.mktemp("handout")
    release(ROOT, out)
    return out


def test_readme_lists_every_lab_task_and_points(handout):
    text = (handout / LABS_README).read_text()
    labs = lab_catalog(sorted((handout / "tests").glob("test_lab*_*.py")))
    assert labs, "the handout has no graders"
    for number, lab in labs.items():
        assert (
            f"`labs/{lab.module}.py`" in text or f"`labs/{lab.module}/`" in text
        ) and f"{lab.points():g} points" in text
        for task, title in lab.tasks.items():
            title = title.replace("|", "\\|")
            assert f"| {task} | {title} | {lab.points(task):g} |" in text, (
                f"lab {number} task {task} missing from labs/README.md"
            )
    for command in ("python -m pytest tests/test_lab", " -k ", "rtcourse grade --lab "):
        assert command in text


def test_readme_counts_hidden_points_without_shipping_them(handout):
    hidden = lab_catalog([f for f in lab_test_files(ROOT) if f.parent.name == "hidden"])
    text = (handout / LABS_README).read_text()
    assert not (handout / "tests" / "hidden").exists()
    for lab in hidden.values():
        assert f"worth {lab.points():g} more point" in text


def _function_source(path: Path, names) -> dict[str, str]:
    """The source of each function of ``names`` in a lab file (or in its package's files)."""
    found = {}
    for source in (f.read_text() for f in module_files(path)):
        found.update(
            {
                node.name: ast.get_source_segment(source, node)
                for node in ast.parse(source).body
                if isinstance(node, ast.FunctionDef) and node.name in names
            }
        )
    return found


def test_one_task_raises_the_score_by_its_points(handout, tmp_path):
    # The student writes pack_rgba8 and unpack_rgba8 (here: the reference's bodies).
    names = ("pack_rgba8", "unpack_rgba8")
    lab_file = handout / "labs" / "lab0_interop" / "packing.py"  # task 1's module
    text = lab_file.read_text()
    skeleton = _function_source(lab_file, names)
    for name, solution in _function_source(
        ROOT / "solutions" / "lab0_interop" / lab_file.name, names
    ).items():
        text = text.replace(skeleton[name], solution)
    lab_file.write_text(text)

    # The README's command for the task: exactly task 1's tests run.
    command = "rtcourse grade --lab 0 --task 1"
    assert f"`{command}`" in (handout / LABS_README).read_text()
    results = tmp_path / "results.json"
    proc = subprocess.run(
        [sys.executable, "-m", "course.tools.cli", *command.split()[1:], "--json", str(results)],
        cwd=handout,
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    assert results.exists(), proc.stdout[-3000:] + proc.stderr[-3000:]
    data = json.loads(results.read_text())
    lab = lab_catalog([handout / "tests" / "test_lab0_interop.py"])[0]
    # Tests that call only these functions (the bad-input test also needs linear_to_srgb8).
    earned = sum(t.points for t in lab.graded(1) if t.calls and t.calls <= set(names))
    assert earned > 0
    assert data["score"] == pytest.approx(earned), proc.stdout[-3000:]
    assert data["max_score"] == pytest.approx(lab.points(1))
    assert f"lab 0: {earned:.2f} / {lab.points(1):.2f}" in proc.stdout
    # The task that lost points shows its first failure under its row, not a log.
    assert "task 1: write `linear_to_srgb8` (not implemented yet)" in proc.stdout, proc.stdout
    assert len(proc.stdout.strip().splitlines()) <= 12, proc.stdout


def test_handout_holds_the_generated_skeletons(tmp_path):
    """The release writes labs/ with the generator that writes the committed labs/ (a
    handout of its own: other tests here copy references into theirs)."""
    from course.tools.skeletons import differences

    release(ROOT, tmp_path / "handout")
    assert not differences(ROOT / "solutions", tmp_path / "handout" / "labs")
    assert not (tmp_path / "handout" / "solutions").exists()
