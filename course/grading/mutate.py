"""Generated mutants: systematic operator mutations of the reference solutions.

The hand-written mutants (:mod:`course.grading.mutants`) are mistakes someone thought of.
This module measures how much of the references' behaviour the graders pin down without
anyone choosing: it walks the source of every function a student writes (those the
skeleton leaves raising ``NotImplementedError``), makes one small change at a time --

  * comparisons: ``<`` <-> ``<=``, ``>`` <-> ``>=``, ``==`` <-> ``!=``, and a flipped side;
  * arithmetic: ``+`` <-> ``-``, ``*`` <-> ``/``, a dropped unary minus;
  * constants: an int nudged by one, a float by 10 % (0.0 becomes 1e-3);
  * precision: ``torch.float64`` -> ``torch.float32``, ``.double()`` -> ``.float()``;
  * rounding: ``floor`` <-> ``ceil``, ``round``/``trunc`` -> ``floor``;
  * dropped ``abs``/``clamp``/``clamp_min``/``clamp_max``/``nan_to_num``;
  * swapped arguments of ``torch.where``/``cross``/``atan2``;
  * ``&`` <-> ``|``, ``and`` <-> ``or``

-- and grades each mutated module on the tests of that function (visible and hidden). A
mutant the tests do not notice *survives*: either a test is missing, or the change does
not alter the contract (an *equivalent* mutant, recorded with its reason in
``solutions/mutants/reviewed/labN.py``). The mutation score of a lab is
``killed / (generated - equivalent)``.

Mutants are identified by ``module:function:kind:n`` where ``n`` counts the sites of that
kind within the function in source order, so a review survives edits elsewhere.

Each mutant runs in a warm worker process that grades one mutant after another in-process
(torch and the test modules are imported once); a mutant that hangs is killed by its
deadline (counted as caught: the real grader's time limit fails it) and the worker is
restarted for the rest.

The mutations themselves are made by :mod:`course.grading.mutate_operators` (re-exported
here); this module plans them per lab, grades them and scores them.
"""

from __future__ import annotations

import ast
import json
import os
import random
import re
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path

from course.core.device import allowed_cpus
from course.core.files import copy_module, lab_source, module_files, relative_name
from course.grading.catalog import functions_of, lab_catalog, skeleton_functions
from course.grading.mutate_operators import Generated, generate
from course.grading.runner import lab_test_files


def _call_graph(tree) -> dict[str, set[str]]:
    """Top-level function name -> top-level names it refers to (the module's call graph)."""
    tops = {n.name for n in tree.body if isinstance(n, (ast.FunctionDef, ast.ClassDef))}
    graph = {}
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.ClassDef)):
            graph[node.name] = {
                n.id
                for n in ast.walk(node)
                if isinstance(n, ast.Name) and n.id in tops and n.id != node.name
            }
    return graph


@dataclass
class LabPlan:
    lab: int
    module: str
    mutants: list[Generated]
    tests: dict[str, list[str]]  # function -> names of the graded tests exercising it
    sources: dict[str, str]  # file (Generated.file) -> the solution's text the mutants apply to


def plan(root, labs=None, *, gpu: bool = False) -> list[LabPlan]:
    """The generated mutants of every lab (or the chosen ones) and their tests; with
    ``gpu``, also the tests that need CUDA (graded only where it is visible)."""
    root = Path(root)
    catalog = lab_catalog(lab_test_files(root, labs))
    plans = []
    for number, info in catalog.items():
        skeleton = lab_source(root / "labs", info.module)  # a file, or a package folder
        solution = lab_source(root / "solutions", info.module)
        if skeleton is None or solution is None:
            continue
        sources = {
            relative_name(solution, f): f.read_text() for f in module_files(solution)
        }  # the module, or its package's files
        tree = ast.Module([n for text in sources.values() for n in ast.parse(text).body], [])
        skeleton_body = [n for f in module_files(skeleton) for n in ast.parse(f.read_text()).body]
        written = {
            n.name
            for n in skeleton_body
            if isinstance(n, (ast.FunctionDef, ast.ClassDef))
            and any(
                isinstance(r, ast.Raise) and "NotImplementedError" in ast.unparse(r)
                for r in ast.walk(n)
            )
        }
        public = skeleton_functions(skeleton)
        graph = _call_graph(tree)
        direct = {
            f: sorted(
                {
                    t.name
                    for t in info.graded(needs=("gpu",) if gpu else ())
                    if f in functions_of(t, public)
                }
            )
            for f in public
        }
        tests = {}
        for name in sorted(written):
            if name in direct:
                tests[name] = direct[name]
            else:  # a private function: graded through the public functions that reach it
                users = [f for f in public if _reaches(graph, f, name)]
                tests[name] = sorted({t for f in users for t in direct.get(f, [])})
        tests = {f: names for f, names in tests.items() if names}
        mutants = [
            m for file, text in sources.items() for m in generate(info.module, text, tests, file)
        ]
        plans.append(LabPlan(number, info.module, mutants, tests, sources))
    return plans


def _reaches(graph, start, target) -> bool:
    seen, stack = set(), [start]
    while stack:
        node = stack.pop()
        if node == target:
            return True
        if node not in seen:
            seen.add(node)
            stack.extend(graph.get(node, ()))
    return False


def load_reviewed(root) -> dict[str, str]:
    """Mutant id -> why it is equivalent (or outside the contract), as reviewed: the
    ``EQUIVALENT`` dicts of ``solutions/mutants/reviewed/lab*.py``."""
    from course.core.files import import_file

    reviewed = {}
    for path in sorted(Path(root, "solutions", "mutants", "reviewed").glob("lab*.py")):
        reviewed |= import_file(path, f"rtcourse_reviewed_{path.stem}").EQUIVALENT
    return reviewed


def sample(plans: list[LabPlan], per_lab: int | None, seed: int) -> list[Generated]:
    """Every mutant, or ``per_lab`` of each lab drawn uniformly with ``seed``."""
    chosen = []
    for p in plans:
        mutants = list(p.mutants)
        if per_lab is not None and len(mutants) > per_lab:
            mutants = random.Random(f"{seed}:{p.module}").sample(mutants, per_lab)
            mutants.sort(key=lambda m: m.id)
        chosen += mutants
    return chosen


# -- running ------------------------------------------------------------------------------


class _Outcome:
    """pytest plugin: did any selected graded test fail, and how many ran."""

    def __init__(self):
        self.failed, self.ran = [], 0

    def pytest_runtest_logreport(self, report):
        if report.when == "call" or report.failed:
            if report.when == "call":
                self.ran += 1
            if report.failed and report.nodeid not in self.failed:
                self.failed.append(report.nodeid)


def _grade_one(root: Path, spec: dict, scratch: Path) -> dict:
    """Worker side: write the mutated module to a fresh folder, run its tests."""
    import contextlib
    import io

    import pytest

    folder = scratch / spec["id"].replace(":", "__")
    folder.mkdir(parents=True, exist_ok=True)
    copy_module(
        lab_source(root / "solutions", spec["module"]), folder, {spec["file"]: spec["source"]}
    )
    keyword = " or ".join(spec["tests"])
    files = [str(f) for f in lab_test_files(root, [spec["module"].split("_")[0][3:]])]
    outcome = _Outcome()
    args = files + [
        "-p",
        "no:cacheprovider",
        "-c",
        str(root / "pyproject.toml"),
        "--rootdir",
        str(root),
        "--impl",
        str(folder),
        "--trusted",
        "-q",
        "-x",
        "-k",
        keyword,
        "-p",
        "no:warnings",
    ]
    log = io.StringIO()
    with contextlib.redirect_stdout(log), contextlib.redirect_stderr(log):
        code = int(pytest.main(args, plugins=[outcome]))
    if code not in (0, 1) or not outcome.ran:
        # a broken grader or an empty selection proves nothing about the mutant
        return {
            "id": spec["id"],
            "killed": False,
            "error": f"pytest exit {code}, {outcome.ran} tests ran: {log.getvalue()[-400:]}",
            "ran": outcome.ran,
            "by": [],
        }
    return {
        "id": spec["id"],
        "killed": bool(outcome.failed),
        "ran": outcome.ran,
        "by": outcome.failed[:1],
    }


def worker_main(root: str, jobs: str, results: str, scratch: str):
    """``python -m course.grading.mutate ROOT JOBS RESULTS SCRATCH``: grade each job (one JSON
    spec a line), appending one JSON line of outcome per job, flushed as it goes
    (:func:`course.grading.warm.serve`)."""
    from course.grading.warm import serve

    serve(jobs, results, lambda spec: _grade_one(Path(root), spec, Path(scratch)))


def _lost(mutant_id: str, why: str) -> dict:
    """A mutant whose worker hung or died on it: caught (the real grader fails it)."""
    return {"id": mutant_id, "killed": True, "ran": 0, "by": [why]}


def run(
    root,
    mutants: list[Generated],
    plans: list[LabPlan],
    *,
    workers: int = 1,
    deadline: float = 300.0,
    progress: bool = False,
    device: str = "cpu",
) -> list[dict]:
    """Grade every mutant with ``workers`` parallel workers; one outcome dict each.
    ``progress`` shows a bar on a terminal; ``device`` as :func:`run_specs`."""
    root = Path(root)
    tests = {(p.module, f): names for p in plans for f, names in p.tests.items()}
    sources = {(p.module, file): text for p in plans for file, text in p.sources.items()}
    specs = [
        {
            "id": m.id,
            "module": m.module,
            "tests": tests[(m.module, m.function)],
            "file": m.file,
            "source": m.apply(sources[(m.module, m.file)]),
        }
        for m in mutants
    ]
    return run_specs(
        root, specs, workers=workers, deadline=deadline, progress=progress, device=device
    )


def run_specs(
    root,
    specs: list[dict],
    *,
    workers: int = 1,
    deadline: float = 300.0,
    progress: bool = False,
    device: str = "cpu",
) -> list[dict]:
    """Grade mutated modules, one outcome dict each (``id``, ``killed``, ``ran``, ``by``,
    ``error`` when the run proves nothing), in ``workers`` warm worker processes. A spec is
    ``{"id", "module": "labN_name", "tests": [-k expressions, or-ed], "file": the mutated
    file as copy_module names it, "source": its mutated text}``. ``device="cpu"`` hides
    CUDA from the workers (many small runs: CUDA's start-up in every worker costs more than
    it saves); ``"auto"`` leaves it visible, so that the graders' ``[cuda]`` cases also run:
    the only way to grade a mistake on a path that only CUDA takes (a CUDA graph)."""
    from tqdm import tqdm

    from course.grading.warm import run_pool

    root = Path(root)
    env = dict(os.environ, OMP_NUM_THREADS="1")
    if device == "cpu":
        env["CUDA_VISIBLE_DEVICES"] = ""
    with tqdm(
        total=len(specs), unit="mutant", disable=not (progress and sys.stderr.isatty())
    ) as bar:
        return run_pool(
            specs,
            lambda jobs, results, tmp: [
                sys.executable,
                "-m",
                "course.grading.mutate",
                str(root),
                jobs,
                results,
                tmp,
            ],
            workers=workers,
            cwd=root,
            env=env,
            deadline=deadline,
            lost=_lost,
            shared=False,
            tick=bar.update,
            scratch_prefix="rtcourse-mutate-",
        )


def score_table(mutants: list[Generated], outcomes: list[dict], reviewed: dict[str, str]):
    """Per lab: generated, killed, equivalent (reviewed survivors), survivors, score."""
    rows = {}
    for m, o in zip(mutants, outcomes):
        row = rows.setdefault(
            m.lab,
            {
                "lab": m.lab,
                "generated": 0,
                "killed": 0,
                "equivalent": 0,
                "survived": [],
                "errors": [],
            },
        )
        row["generated"] += 1
        if o.get("error"):
            row["errors"].append(m.id)
        elif o["killed"]:
            row["killed"] += 1
        elif m.id in reviewed:
            row["equivalent"] += 1
        else:
            row["survived"].append(m.id)
    for row in rows.values():
        live = row["generated"] - row["equivalent"] - len(row["errors"])
        row["score"] = row["killed"] / live if live else 1.0
    return [rows[k] for k in sorted(rows)]


def main_cli(
    root,
    *,
    labs=None,
    per_lab=None,
    seed=0,
    workers=None,
    json_path=None,
    only=None,
    device="cpu",
) -> int:
    """``rtcourse mutants --generated``: print the score table; 1 if a lab is under 90 %."""
    root = Path(root)
    plans = plan(root, labs, gpu=device != "cpu")
    mutants = sample(plans, per_lab, seed)
    if only:
        mutants = [m for m in mutants if re.search(only, m.id)]
    reviewed = load_reviewed(root)
    workers = workers or allowed_cpus()
    total = sum(len(p.mutants) for p in plans)
    how = (
        f"all {total}"
        if per_lab is None
        else f"{len(mutants)} of {total} (<= {per_lab} per lab, seed {seed})"
    )
    if only:
        how = f"{len(mutants)} of {total} (ids matching {only!r})"
    where = "CUDA hidden" if device == "cpu" else "CUDA visible"
    print(f"grading {how} generated mutants with {workers} worker(s), {where}", flush=True)
    started = time.monotonic()
    outcomes = run(root, mutants, plans, workers=workers, progress=True, device=device)
    table = score_table(mutants, outcomes, reviewed)
    print(
        f"\n{'lab':>3} {'generated':>9} {'killed':>6} {'equiv':>5} {'survived':>8} "
        f"{'errors':>6} {'score':>6}"
    )
    for row in table:
        print(
            f"{row['lab']:>3} {row['generated']:>9} {row['killed']:>6} {row['equivalent']:>5} "
            f"{len(row['survived']):>8} {len(row['errors']):>6} {row['score']:>6.1%}"
        )
    errors = [o for o in outcomes if o.get("error")]
    for o in errors[:3]:
        print(f"  error {o['id']}: {o['error']}")
    for row in table:
        for mid in row["survived"]:
            m = next(x for x in mutants if x.id == mid)
            print(f"  survived {mid} (line {m.line}): {m.original!r} -> {m.replacement!r}")
    if json_path:
        Path(json_path).write_text(
            json.dumps(
                {
                    "sampling": how,
                    "device": device,
                    "seconds": round(time.monotonic() - started, 1),
                    "labs": table,
                    "mutants": [dict(asdict(m), **o) for m, o in zip(mutants, outcomes)],
                },
                indent=1,
            )
        )
    return 1 if errors or any(row["score"] < 0.9 for row in table) else 0


if __name__ == "__main__":
    worker_main(*sys.argv[1:5])
