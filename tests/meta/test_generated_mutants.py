"""``rtcourse mutants --generated`` on the toy course: mutants are generated from the
reference of every function the skeleton leaves unwritten, graded on that function's tests,
and scored with the reviewed equivalents set apart."""

from __future__ import annotations

import dataclasses
import shutil
from pathlib import Path

from course.grading.mutate import generate, plan, run, score_table

HERE = Path(__file__).resolve().parent

SKELETON = '''
def double(x):
    """Task 1."""
    raise NotImplementedError("not implemented yet: double")


def norms(x):
    """Task 2."""
    raise NotImplementedError("not implemented yet: norms")
'''


def _toy(tmp_path) -> Path:
    course = tmp_path / "course"
    shutil.copytree(HERE / "toycourse", course)
    (course / "labs").mkdir()
    (course / "labs" / "lab9_toy.py").write_text(SKELETON)
    return course


def test_generate_covers_each_operator_kind_at_its_source_position():
    source = (
        "def f(x, y):\n"
        "    '''doc 1.5'''\n"
        "    if x.sum() < 0 and y >= 2:\n"
        "        raise ValueError(f'x < {0}')\n"
        "    z = torch.where(x > y, x.abs(), -y) * 2.0 + x.floor()\n"
        "    return z.double().sum(dim=-1)\n"
    )
    mutants = generate("lab9_toy", source, ["f"])
    kinds = {m.kind for m in mutants}
    assert {
        "cmp_Lt_LtE",
        "cmp_GtE_Gt",
        "bool_And_Or",
        "op_Mult_Div",
        "op_Add_Sub",
        "const_float",
        "const_int",
        "drop_abs",
        "drop_neg",
        "swap_where",
        "round_floor_ceil",
        "narrow_double",
    } <= kinds, kinds
    for m in mutants:
        assert source[m.start : m.end] == m.original
        compile(m.apply(source), "<mutant>", "exec")  # every mutant is valid Python
    # neither the docstring, the error branch nor the axis argument is mutated
    assert all(m.line not in (2, 4) for m in mutants)
    assert not any(m.original == "1" and m.line == 6 for m in mutants)
    # ids count sites of one kind within the function, in source order
    assert len({m.id for m in mutants}) == len(mutants)


def test_toy_course_every_mutant_graded_on_its_own_tests(tmp_path):
    course = _toy(tmp_path)
    plans = plan(course)
    assert [p.module for p in plans] == ["lab9_toy"]
    assert plans[0].tests == {"double": ["test_double"], "norms": ["test_norms"]}
    mutants = plans[0].mutants
    assert {m.function for m in mutants} == {"double"}  # norms has nothing to mutate
    outcomes = run(course, mutants, plans, workers=1, deadline=120)
    assert all(o["killed"] for o in outcomes), outcomes
    table = score_table(mutants, outcomes, {})
    assert table[0]["score"] == 1.0 and table[0]["killed"] == len(mutants)


def test_survivors_are_scored_unless_reviewed_equivalent(tmp_path):
    course = _toy(tmp_path)
    # a weak grader: test_double only checks the shape, so a wrong factor survives
    grader = course / "tests" / "test_lab9_toy.py"
    grader.write_text(
        grader.read_text().replace(
            "torch.testing.assert_close(got, 2 * x)", "assert got.shape == x.shape"
        )
    )
    plans = plan(course)
    mutants = [m for m in plans[0].mutants if m.function == "double"]
    outcomes = run(course, mutants, plans, workers=1, deadline=120)
    assert not any(o["killed"] for o in outcomes), outcomes
    table = score_table(mutants, outcomes, {})
    assert table[0]["score"] == 0.0 and len(table[0]["survived"]) == len(mutants)
    reviewed = {mutants[0].id: "reviewed: equivalent for the test's purpose"}
    table = score_table(mutants, outcomes, reviewed)
    assert table[0]["equivalent"] == 1 and len(table[0]["survived"]) == len(mutants) - 1


def test_a_hanging_mutant_is_caught_by_its_deadline(tmp_path):
    course = _toy(tmp_path)
    (course / "solutions" / "lab9_toy.py").write_text(
        (course / "solutions" / "lab9_toy.py")
        .read_text()
        .replace(
            "    return 2 * x\n",
            "    i = 0\n    while i < 2:\n        i = i + 1\n    return i * x\n",
        )
    )
    plans = plan(course)
    hang = [m for m in plans[0].mutants if m.kind == "op_Add_Sub"]
    assert [m.original for m in hang] == ["i + 1"]
    started = __import__("time").monotonic()
    outcomes = run(course, hang, plans, workers=1, deadline=8)
    assert outcomes[0]["killed"] and "timed out" in outcomes[0]["by"][0], outcomes
    assert __import__("time").monotonic() - started < 60


def test_a_selection_that_runs_nothing_is_an_error_not_a_survivor(tmp_path):
    course = _toy(tmp_path)
    plans = plan(course)
    plans[0].tests["double"] = ["test_that_does_not_exist"]
    mutants = plans[0].mutants[:1]
    outcomes = run(course, mutants, plans, workers=1, deadline=120)
    assert "error" in outcomes[0] and not outcomes[0]["killed"], outcomes
    table = score_table(mutants, outcomes, {})
    assert table[0]["errors"] == [mutants[0].id] and not table[0]["survived"]


def test_a_package_reference_is_mutated_in_the_file_defining_the_function(tmp_path):
    course = _toy(tmp_path)
    solution = course / "solutions" / "lab9_toy.py"
    single = plan(course)[0].mutants
    # The same reference kept as a package, ``double`` in a module of its own that the other
    # imports; the skeleton stays one file (either is found).
    text = solution.read_text()
    start, end = text.index("def double"), text.index("def norms")
    package = course / "solutions" / "lab9_toy"
    package.mkdir()
    (package / "twice.py").write_text('"""Task 1."""\n\n\n' + text[start:end].rstrip() + "\n")
    (package / "__init__.py").write_text(
        text[:start] + "from .twice import double\n\n\n" + text[end:]
    )
    solution.unlink()
    plans = plan(course)
    mutants = plans[0].mutants
    assert [(m.id, m.original, m.replacement) for m in mutants] == [
        (m.id, m.original, m.replacement) for m in single
    ], "the same mutants, the same ids"
    assert {m.file for m in mutants} == {"lab9_toy/twice.py"}
    # A change that changes nothing survives: the graded copy is the whole package.
    same = dataclasses.replace(
        mutants[0], id="lab9_toy:double:same:0", replacement=mutants[0].original
    )
    outcomes = run(course, [*mutants, same], plans, workers=1, deadline=120)
    assert all(o["killed"] for o in outcomes[:-1]) and not outcomes[-1]["killed"], outcomes


def test_graders_that_need_cuda_join_the_plan_only_where_cuda_grades(tmp_path):
    """``mutants --generated --device auto`` grades mistakes on paths only CUDA takes
    (Lab 2's cached CUDA graphs): its plan must hold the ``gpu``-marked graders, which a
    CPU plan leaves out (they would be skipped, and a skip catches nothing)."""
    course = _toy(tmp_path)
    grader = course / "tests" / "test_lab9_toy.py"
    grader.write_text(
        grader.read_text() + "\n\n@pytest.mark.task(1)\n@pytest.mark.points(1)\n@pytest.mark.gpu\n"
        "def test_double_on_cuda(impl):\n"
        "    x = torch.arange(5.0, device='cuda')\n"
        "    torch.testing.assert_close(impl.double(x), 2 * x)\n"
    )
    assert plan(course)[0].tests["double"] == ["test_double"]
    assert plan(course, gpu=True)[0].tests["double"] == ["test_double", "test_double_on_cuda"]
