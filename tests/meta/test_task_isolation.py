"""Each task is graded on its own: a mistake in one task's function costs points in that
task only, not again in the later tasks that build on its results.

The graders give a later task the results of the earlier ones it needs (structures built by
the grader, given building blocks, the reference's visibility buffer) and grade the lab's
whole chain in one small end-to-end task (``END_TO_END`` in the grader), which a mistake
anywhere may also cost. Here a shipped mutant of an early task is graded on the tests of
every task that used to carry such a mistake further, and may lose points only in its own
task and the end-to-end one; where the end-to-end test names the step that is wrong (Labs 3,
5 and 6), the name must be the mutated one. Labs 1 and 4 have no end-to-end task: their later
tasks run on given kernels (Lab 1's closest_hit on a given Möller–Trumbore, Lab 4's step
integral and its single scattering in a given march).
"""

from __future__ import annotations

import ast
import dataclasses
from collections import defaultdict
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

from course.grading.mutants import grade_mutant, load_mutants

ROOT = Path(__file__).resolve().parents[2]
MUTANTS = {m.name: m for m in load_mutants(ROOT)}


@dataclasses.dataclass(frozen=True)
class Case:
    mutant: str  # a shipped mutant (solutions/mutants/labN.py)
    task: int  # the task of the function it breaks
    tests: str  # -k: its own tests and those of the later tasks that use its results
    names: str | None = None  # what the end-to-end failure must name as the wrong step


CASES = [
    # Lab 0: the packing (task 1) fed the rotating triangle and the frame loop (task 4).
    Case("pack_bgra_order", 1, "pack_rgba8 or render_rotating or FrameLoop"),
    # Lab 1: Möller–Trumbore (task 2), closest_hit's default variant (task 6).
    Case("mt_no_u_plus_v", 2, "moller_trumbore_matches or closest_hit"),
    # Lab 4: march_box (task 1), which task 2's whole marches and task 3's single
    # scattering used to run.
    Case("march_transmittance_first", 1, "march_box or segment_integral or single_scatter"),
    # Lab 2: the grid builder (task 1) fed the grid walk, closest_hit (task 5) and the
    # two-level grid's top level (task 6).
    Case(
        "grid_cells_one_short",
        1,
        "grid_resolution_and_build or grid_dda or "
        "closest_hit_entry or two_level_build or counters_show",
    ),
    # Lab 3: the direct shading (task 1) fed every renderer (tasks 1, 2 and 4).
    Case(
        "specular_not_normalised",
        1,
        "shade_direct_matches or render_whitted_matches or "
        "render_wavefront_matches or render_persistent_matches or whole_tracer",
        names="shade_direct",
    ),
    # Lab 5: the V-buffer's phase g (task 2) fed every whole frame, once graded under
    # task 7 with the application.
    Case(
        "g_not_scattering_weighted",
        2,
        "voxelize or media_at or apply_froxels or render_froxels",
        names="voxelize",
    ),
    # Lab 6: the fill rule (task 2) fed rasterize (task 3) and everything after it.
    Case(
        "no_fill_rule",
        2,
        "coverage_fill or rasterize_visibility or "
        "perspective_correct_exact or hybrid or rasterize_mesh",
    ),
]

SLOW_CASES = [
    # Lab 1: an absolute determinant test in Möller–Trumbore (task 2) under closest_hit.
    Case("mt_absolute_epsilon", 2, "moller_trumbore or closest_hit"),
    # Lab 4: the back-to-front update in march_box (task 1) under tasks 2 and 3.
    Case("march_back_to_front", 1, "march_box or segment_integral or single_scatter"),
    # Lab 2: the DDA (task 1) under closest_hit, 'auto' and the two-level walk.
    Case(
        "dda_lower_face_when_stepping_up",
        1,
        "grid_dda or closest_hit_entry or auto_builds "
        "or two_level_matches or two_level_mailboxing or counters_show",
    ),
    # Lab 3: the normal offset (task 1), used by the shading and by every bounce.
    Case(
        "no_normal_offset",
        1,
        "offset_origins or render_whitted or render_wavefront or render_persistent or whole_tracer",
        names="offset_origins",
    ),
    # Lab 6: no near-plane clipping (task 1) under rasterize_mesh, shading and shadows.
    Case(
        "no_near_plane_clipping",
        1,
        "clip_triangles or perspective_correct_exact or shade_flat or hybrid or rasterize_mesh",
        names="clip_triangles",
    ),
]


def end_to_end_task(lab: int) -> int | None:
    """The grader's ``END_TO_END`` task number (None: the lab has none)."""
    path = next((ROOT / "tests").glob(f"test_lab{lab}_*.py"))
    for node in ast.parse(path.read_text()).body:
        if isinstance(node, ast.Assign) and any(
            isinstance(t, ast.Name) and t.id == "END_TO_END" for t in node.targets
        ):
            return ast.literal_eval(node.value)
    return None


def grade(case: Case, tmp_path: Path) -> dict:
    mutant = dataclasses.replace(MUTANTS[case.mutant], tests=case.tests)
    return grade_mutant(mutant, ROOT, tmp_path / case.mutant)


def check_isolated(case: Case, data: dict) -> None:
    lab = MUTANTS[case.mutant].lab
    e2e = end_to_end_task(lab)
    lost, failed = defaultdict(float), defaultdict(list)
    for test in data["tests"]:
        task = int(test["number"].split(".")[1])
        lost[task] += test["max_score"] - test["score"]
        if test["score"] < test["max_score"]:
            failed[task].append(test["name"])
    assert lost[case.task] > 0, (
        f"mutant {case.mutant} (lab {lab}, task {case.task}) lost no points in its own "
        f"task: {data['output']}"
    )
    elsewhere = {t: names for t, names in failed.items() if t not in (case.task, e2e)}
    assert not elsewhere, (
        f"mutant {case.mutant} of lab {lab} task {case.task} also costs points in other "
        f"tasks (they must get the earlier tasks' results given): {elsewhere}"
    )
    if case.names is not None:
        outputs = [
            t["output"]
            for t in data["tests"]
            if t["number"] == f"{lab}.{e2e}" and t["score"] < t["max_score"]
        ]
        assert outputs, f"mutant {case.mutant}: the end-to-end task passed"
        # A long line of feedback wraps: compare the words, not where the lines break.
        assert any(
            f"the step that is wrong: {case.names}" in " ".join(o.split()) for o in outputs
        ), (
            f"mutant {case.mutant}: the end-to-end failure must name {case.names} as the "
            f"wrong step: {outputs[0][:600]}"
        )


def _run(cases, tmp_path):
    with ThreadPoolExecutor(max_workers=2) as pool:
        results = list(pool.map(lambda c: grade(c, tmp_path), cases))
    for case, data in zip(cases, results):
        check_isolated(case, data)


def test_every_chained_lab_has_an_end_to_end_task():
    for lab in (2, 3, 5, 6):
        task = end_to_end_task(lab)
        assert task is not None, f"lab {lab}: no END_TO_END task (the lab's whole chain)"
        assert task == max(
            ast.literal_eval(
                next(
                    n.value
                    for n in ast.parse(
                        next((ROOT / "tests").glob(f"test_lab{lab}_*.py")).read_text()
                    ).body
                    if isinstance(n, ast.Assign)
                    and any(isinstance(t, ast.Name) and t.id == "TASKS" for t in n.targets)
                )
            )
        ), f"lab {lab}: the end-to-end task should be the last task"


def test_an_early_mistake_costs_its_own_task_only(tmp_path):
    _run(CASES, tmp_path)


@pytest.mark.slow
def test_more_early_mistakes_cost_their_own_task_only(tmp_path):
    _run(SLOW_CASES, tmp_path)
