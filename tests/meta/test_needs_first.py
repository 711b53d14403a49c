"""The "needs first" column of the handout's ``labs/README.md``: the other tasks whose
functions a task's tests run, directly or through the lab's own functions (read from the
reference), less those a test replaces with the grader's stand-ins.

Statically for every lab; by grading for the tasks whose tests reach another task's
function only through the student's own code (Lab 4 task 1: ``march_box`` calls
``segment_integral``; Lab 6 task 3: ``rasterize`` calls task 2's ``bounding_boxes`` and
``coverage``): the skeleton with the task's functions written (the reference's) fails
without a listed task and passes with them.
"""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

from course.core.files import copy_module, defining_file, lab_source, relative_name
from course.grading.catalog import lab_catalog
from course.grading.runner import lab_test_files
from course.grading.taskdoc import grader_uses, lab_task_needs, task_table
from course.tools.release import labs_readme

ROOT = Path(__file__).resolve().parents[2]
LABS = lab_catalog(sorted((ROOT / "tests").glob("test_lab*_*.py")))


def _tasks(number: int):
    lab = LABS[number]
    return {
        t.number: t
        for t in lab_task_needs(
            lab, lab_source(ROOT / "labs", lab.module), lab_source(ROOT / "solutions", lab.module)
        )
    }


def test_a_task_needs_what_its_tests_run_through_the_lab():
    # The test calls march_box; the reference's march_box calls segment_integral (task 2).
    assert _tasks(4)[1].needs == {2: ["segment_integral"]}
    # rasterize's memory test runs the lab's own bounding_boxes and coverage.
    needs = _tasks(6)[3].needs
    assert set(needs) == {2} and {"bounding_boxes", "coverage"} <= set(needs[2])


def test_a_replaced_function_is_not_needed():
    # march_single_scatter runs on the given march_box and sample_grid (tasks 1 and 2):
    # only its shadow march's own calls remain.
    needs = _tasks(4)[3].needs
    assert "march_box" not in needs.get(1, []) and 2 not in needs


def test_every_task_needs_only_other_tasks_functions():
    for number in LABS:
        tasks = _tasks(number)
        owners = {f: t.number for t in tasks.values() for f in t.functions}
        for task in tasks.values():
            for other, functions in task.needs.items():
                assert other != task.number and other in tasks, (number, task.number, other)
                assert all(owners[f] == other for f in functions), (number, task.number)


def test_the_readme_lists_the_needs():
    text = labs_readme(ROOT, hidden_root=ROOT)
    row = next(
        line for line in text.splitlines() if line.startswith("| 1 |") and "`march_box`" in line
    )
    assert "task 2 (`segment_integral`)" in row, row
    lab = LABS[4]
    table = task_table(
        lab,
        lab_source(ROOT / "labs", lab.module),
        "tests/test_lab4_march.py",
        lab_source(ROOT / "solutions", lab.module),
    )
    assert any("task 2 (`segment_integral`)" in line for line in table[2:3])


GRADER = """
import pytest
from course.grading.testing import replaced

LAB_MODULE = "lab9_toy"
TASKS = {1: "a", 2: "b"}
GIVEN = {"inner": "given_inner"}


def given_inner(x):
    return x


def probe_outer(lab, x):
    with replaced(lab, {name: globals()[GIVEN[name]] for name in GIVEN}):
        return lab.outer(x)


def run(impl, name, x):
    if name == "other":
        return impl.other(x)
    return getattr(impl, name)(x)


@pytest.mark.task(1)
@pytest.mark.points(1)
def test_outer_given(impl):
    impl.probe(probe_outer, 1)
    run(impl, "outer", 2)
    try:
        impl.maybe(1)
    except NotImplementedError:
        pass


@pytest.mark.task(1)
@pytest.mark.points(1)
def test_checks(impl):
    expect_error("x", impl.outer, -1)
"""


def test_the_grader_walk(tmp_path):
    path = tmp_path / "test_lab9_toy.py"
    path.write_text(GRADER)
    tests = grader_uses([path])
    uses = {
        (u.function, tuple(sorted(u.replaced)), u.runs, u.optional)
        for u in tests["test_outer_given"]
    }
    assert uses == {
        ("outer", ("inner",), True, False),
        ("outer", (), True, False),
        ("maybe", (), True, True),
    }
    assert [(u.function, u.runs) for u in tests["test_checks"]] == [("outer", False)]


# ------------------------------------------------------------------ graded


def _submission(number: int, tasks, folder: Path) -> Path:
    """The skeleton of lab ``number`` with the reference's functions of ``tasks``."""
    lab = LABS[number]
    skeleton = lab_source(ROOT / "labs", lab.module)
    reference = lab_source(ROOT / "solutions", lab.module)
    info = _tasks(number)
    texts: dict[str, str] = {}
    for name in (f for k in tasks for f in info[k].functions):
        mine, theirs = defining_file(skeleton, name), defining_file(reference, name)
        key = relative_name(skeleton, mine)
        text = texts.get(key, mine.read_text())
        segments = []
        for source in (text, theirs.read_text()):
            node = next(n for n in ast.parse(source).body if getattr(n, "name", None) == name)
            segments.append(ast.get_source_segment(source, node))
        texts[key] = text.replace(segments[0], segments[1])
    return copy_module(skeleton, folder, texts)


def _grade(folder: Path, written: dict[int, list[int]]) -> dict[int, tuple[float, float]]:
    """Grade, in one run, each lab of ``written`` (lab -> the tasks written) on the tests of
    ``GRADED``; lab -> (score, max score)."""
    folder.mkdir(parents=True)
    cmd = [
        sys.executable,
        "-m",
        "course.tools.cli",
        "grade",
        "--impl",
        str(folder),
        "--trusted",
        "-k",
        " or ".join(keyword for *_, keyword in GRADED),
        "--json",
        str(folder / "results.json"),
    ]
    for number, task, _ in GRADED:
        _submission(number, written[number], folder)
        cmd += ["--lab", str(number), "--task", f"{number}.{task}"]
    proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=300, check=False)
    out = folder / "results.json"
    assert out.exists(), proc.stdout[-3000:] + proc.stderr[-3000:]
    scores: dict[int, tuple[float, float]] = {}
    for test in json.loads(out.read_text())["tests"]:
        number = int(test["number"].split(".")[0])
        score, top = scores.get(number, (0.0, 0.0))
        scores[number] = (score + test["score"], top + test["max_score"])
    return scores


# (lab, task, -k of its tests that reach another task only through the lab's own code)
GRADED = [(4, 1, "march_box_homogeneous"), (6, 3, "rasterize_visibility")]


@pytest.mark.skipif(not lab_test_files(ROOT, [4, 6]), reason="no graders of labs 4 and 6")
def test_the_listed_tasks_are_needed_and_enough(tmp_path):
    needs = {number: sorted(_tasks(number)[task].needs) for number, task, _ in GRADED}
    assert all(needs.values()), f"the column lists nothing: {needs}"
    # Run 0: every listed task written; run i: each lab without its i-th listed task.
    runs = [{number: [task, *needs[number]] for number, task, _ in GRADED}]
    for i in range(max(map(len, needs.values()))):
        runs.append(
            {
                number: [task, *(k for j, k in enumerate(needs[number]) if j != i)]
                for number, task, _ in GRADED
            }
        )
    with ThreadPoolExecutor(max_workers=2) as pool:
        results = list(pool.map(lambda i: _grade(tmp_path / f"run{i}", runs[i]), range(len(runs))))
    for number, task, _ in GRADED:
        score, top = results[0][number]
        assert top > 0 and score == pytest.approx(top), (
            f"lab {number} task {task} with tasks {runs[0][number]} written: {score}/{top}"
        )
        for i, left_out in enumerate(needs[number], start=1):
            score, top = results[i][number]
            assert score < top, (
                f"lab {number} task {task} passed without task {left_out}, "
                f"which the README says it needs"
            )
