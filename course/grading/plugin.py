"""The pytest plugin every grader runs under (enabled in pyproject's addopts).

It provides
  * ``--impl labs|solutions|PATH``: which implementation the tests load
    (also ``RTCOURSE_IMPL``); only ``solutions`` runs in-process, everything else
    runs in a sandboxed worker (see :mod:`course.grading.sandbox`);
  * the ``impl`` fixture: the lab module named by the test module's ``LAB_MODULE``;
  * the ``device`` parametrisation: ``cpu`` always, ``cuda`` when present;
  * markers ``points(n)``, ``task(k)``, ``visibility(v)``, ``gpu``, ``slow``;
  * ``--task K`` / ``--task N.K``: only the tests that award task K's points (of lab N);
  * short feedback: a failing graded test shows its teaching message and the student's
    line (:mod:`course.grading.feedback`); ``-v`` or ``--feedback full`` shows pytest's
    whole traceback;
  * submission problems said once: a missing ``--impl`` folder is a usage error, a
    missing lab file (or a near miss of its name) and a lab file that does not import are
    one line each, and every test of that lab fails with that one reason.

Tests under ``tests/hidden/`` are the instructor's hidden tests: ``rtcourse release`` leaves
them out of the handout, ``rtcourse gradescope`` ships them, and unless marked otherwise
Gradescope shows them to students only after the due date.
"""

from __future__ import annotations

import linecache
import os
import re
import traceback
from functools import cache
from pathlib import Path

import pytest
import torch

from course.core.files import import_file, lab_source, module_files
from course.core.labs import default_impl, implementation_folder
from course.core.labs import lab_number as module_lab_number
from course.grading.catalog import function_tasks, lab_file_rank, read_grader, read_manifest
from course.grading.feedback import IMPORT_FAILED, Feedback, short_feedback
from course.grading.sandbox import LocalLab, SandboxedLab, Worker

MARKERS = (
    "points(n): the test is graded and worth n points",
    "task(k): the lab task (1, 2, ...) the test grades",
    (
        "visibility(v): when Gradescope shows the test to students: visible (default), hidden, "
        "after_due_date or after_published"
    ),
    "gpu: needs a CUDA device",
    "slow: long-running; skipped unless --runslow",
)


def pytest_addoption(parser):
    group = parser.getgroup("rtcourse", "GPU ray tracing course grader")
    group.addoption(
        "--impl",
        default=os.environ.get("RTCOURSE_IMPL"),
        help="implementation to grade: solutions (the default where it exists), "
        "labs (the default in the student handout), or a folder holding a "
        "student's lab files",
    )
    group.addoption(
        "--trusted",
        action="store_true",
        default=os.environ.get("RTCOURSE_TRUSTED") == "1",
        help="run the implementation in-process (only for code you trust)",
    )
    group.addoption(
        "--time-limit",
        type=float,
        default=float(os.environ.get("RTCOURSE_TIME_LIMIT", "120")),
        help="seconds of student code per test (sandboxed runs)",
    )
    group.addoption(
        "--memory-limit",
        type=float,
        default=float(os.environ.get("RTCOURSE_MEMORY_GB", "4")),
        help="GiB of extra memory the student code may use (sandboxed runs)",
    )
    group.addoption("--runslow", action="store_true", help="also run tests marked slow")
    group.addoption(
        "--task",
        action="append",
        default=[],
        metavar="[N.]K",
        help="run only the tests that award task K's points (of lab N: --task 4.2); repeatable",
    )
    group.addoption(
        "--feedback",
        choices=("short", "full"),
        default=None,
        help="failing graded tests: short (the message and your line; the "
        "default) or full (pytest's traceback with the test's source and "
        "tensors; also with -v)",
    )


def pytest_configure(config):
    for marker in MARKERS:
        config.addinivalue_line("markers", marker)
    impl = config.getoption("--impl", None)
    if impl and impl not in ("solutions", "labs") and not Path(impl).expanduser().is_dir():
        raise pytest.UsageError(
            f"--impl {impl}: no such folder (give the folder that holds "
            f"your lab files, or labs / solutions)"
        )
    for spec in config.getoption("--task", None) or ():
        parse_task(spec)
    if os.environ.get("RTCOURSE_ZYGOTE") == "1":
        from course.grading import zygote

        zygote.enable()


def parse_task(spec: str) -> tuple[int | None, int]:
    """``"2"`` -> (None, 2); ``"4.2"`` -> (4, 2)."""
    match = re.fullmatch(r"\s*(?:(\d+)\.)?(\d+)\s*", str(spec))
    if not match:
        raise pytest.UsageError(
            f"--task {spec}: expected a task number K or LAB.K (e.g. --task 2 or --task 4.2)"
        )
    return (int(match.group(1)) if match.group(1) else None), int(match.group(2))


def lab_number(item) -> int | None:
    return module_lab_number(getattr(getattr(item, "module", None), "LAB_MODULE", ""))


def awards_task(item, specs) -> bool:
    """Whether ``item`` is a graded test of one of the tasks ``specs`` ((lab, task) pairs,
    lab None for any lab): exactly the tests whose points make up those tasks' points."""
    points, task = item.get_closest_marker("points"), item.get_closest_marker("task")
    if points is None or task is None or not task.args:
        return False
    lab = lab_number(item)
    return any(task.args[0] == k and n in (None, lab) for n, k in specs)


VISIBILITIES = ("visible", "hidden", "after_due_date", "after_published")
HIDDEN_DEFAULT = "after_due_date"  # tests in a hidden/ folder unless marked otherwise


def pytest_collection_modifyitems(config, items):
    specs = [parse_task(s) for s in config.getoption("--task") or ()]
    if specs:
        keep = [item for item in items if awards_task(item, specs)]
        if not keep:
            raise pytest.UsageError(
                f"--task {' '.join(config.getoption('--task'))}: no graded test of "
                f"{' or '.join(_task_name(n, k) for n, k in specs)}"
                f" among the {len(items)} tests collected (check the lab and task numbers "
                f"in labs/README.md)"
            )
        config.hook.pytest_deselected(items=[i for i in items if i not in keep])
        items[:] = keep
    has_cuda = torch.cuda.is_available()
    for item in items:
        visibility = item.get_closest_marker("visibility")
        if visibility is None and item.path.parent.name == "hidden":
            item.add_marker(pytest.mark.visibility(HIDDEN_DEFAULT))
        elif visibility is not None and (
            len(visibility.args) != 1 or visibility.args[0] not in VISIBILITIES
        ):
            raise pytest.UsageError(
                f"{item.nodeid}: visibility{visibility.args} must be one "
                f"of {', '.join(VISIBILITIES)}"
            )
        if "slow" in item.keywords and not config.getoption("--runslow"):
            item.add_marker(pytest.mark.skip(reason="slow test: run with --runslow"))
        if "gpu" in item.keywords and not has_cuda:
            item.add_marker(pytest.mark.skip(reason="needs a CUDA device"))
    if not long_feedback(config):
        for item in items:
            if isinstance(item, pytest.Function) and item.get_closest_marker("points"):
                item.repr_failure = _plain_failure_report.__get__(item)


def _plain_failure_report(item, excinfo):
    """pytest's report of a graded test's failure, which the short feedback replaces
    (``_give_feedback``): a plain traceback, cheap to build, where pytest's own parses the
    source of every frame (most of the time a failing skeleton took to grade)."""
    return excinfo.getrepr(style="native")


def pytest_generate_tests(metafunc):
    if "device" in metafunc.fixturenames:
        devices = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])
        metafunc.parametrize("device", devices)


def resolve_impl(config) -> tuple[Path, bool]:
    """The folder holding the lab files, and whether it is trusted."""
    root = Path(config.rootpath)
    impl = config.getoption("--impl") or default_impl(root)
    folder = implementation_folder(root, impl, must_exist=False)  # a missing file says it
    trusted = impl == "solutions" or config.getoption("--trusted")
    return folder, trusted


_LISTED = 12  # files of a submission named when its lab file is not among them


def shown_folder(folder: Path) -> str:
    """How messages name the submission ``folder``: "the submission" where it is one that
    ``rtcourse gradescope`` collected (a temporary folder the student never saw), else its
    path relative to the current folder where it lies below it."""
    if read_manifest(folder) is not None:
        return "the submission"
    try:
        return f"{Path(folder).resolve().relative_to(Path.cwd().resolve()).as_posix()}/"
    except ValueError:
        return f"{folder}/"


def handed_in(folder: Path) -> list[str]:
    """The files of a submission as the student handed them in: the collected upload's (its
    manifest), else the files at the top of ``folder``."""
    manifest = read_manifest(folder)
    if manifest is not None:
        return manifest["handed_in"]
    folder = Path(folder)
    if not folder.is_dir():
        return []
    return sorted(
        p.name + "/" * p.is_dir()
        for p in folder.iterdir()
        if not p.name.startswith((".", "__pycache__"))
    )


def missing_file(folder: Path, name: str) -> str:
    """The one line for a lab file (or package folder) that is not in the submission: the
    submission as the student knows it, and the files it does hold (near misses of the
    name first)."""
    text = (
        f"no {name}.py in {shown_folder(folder)}: the submission must contain the file "
        f"{name}.py (or the folder {name}/ of a lab kept as a package)"
    )
    files = handed_in(folder)
    close = [f for f in files if lab_file_rank(f.rsplit("/", 1)[-1], name) == 1]
    if close:
        return text + (f" (found {', '.join(map(repr, close))}: rename it to {name}.py)")
    if not files:
        return text + "; it holds no files"
    more = f" and {len(files) - _LISTED} more" if len(files) > _LISTED else ""
    return text + f"; it holds {', '.join(map(repr, files[:_LISTED]))}{more}"


def graded_as(folder: Path, name: str) -> str | None:
    """What was graded as the lab ``name``, named as the student handed it in: "'lab4_march
    (1).py'", or the files of a package handed in; None where the lab is not there."""
    manifest = read_manifest(folder)
    if manifest is not None:
        files = manifest["files"]
        mine = [(k, v) for k, v in files.items() if k == f"{name}.py" or k.startswith(f"{name}/")]
        taken = [v for _, v in mine if v is not None]
        if not taken:
            return None
        if any("/" in k for k, _ in mine):
            left = len(mine) - len(taken)
            return ", ".join(map(repr, taken)) + (
                f" (the skeleton's other {left} file{'s' * (left != 1)})" if left else ""
            )
        return repr(taken[0])
    path = lab_source(folder, name)
    if path is None:
        return None
    return f"{shown_folder(folder)}{path.name}" + ("/" if path.is_dir() else "")


def syntax_problem(path: Path, name: str) -> str | None:
    """A lab file, or a file of a lab package, that cannot even be compiled, in one line
    naming the file (compiling runs none of it)."""
    for file in module_files(path):
        shown = f"{name}.py" if file == path else f"{name}/{file.relative_to(path).as_posix()}"
        try:
            compile(file.read_bytes(), str(file), "exec", dont_inherit=True)
        except SyntaxError as exc:
            return (
                f"{shown} failed to import: {type(exc).__name__}: {exc.msg} "
                f"({shown}, line {exc.lineno})"
            )
        except (ValueError, RecursionError, MemoryError) as exc:
            return f"{shown} failed to import: {type(exc).__name__}: {exc}"
    return None


class _Labs:
    """Lab modules loaded for this session; one warm worker serves every sandboxed lab."""

    def __init__(self, config):
        self.config = config
        self.folder, self.trusted = resolve_impl(config)
        self.loaded: dict[str, object] = {}
        self.worker: Worker | None = None
        self.problems: dict[str, str] = {}  # lab module -> why none of its tests can pass

    def get(self, name: str):
        if name in self.problems:
            pytest.fail(self.problems[name], pytrace=False)
        if name not in self.loaded:
            path = lab_source(self.folder, name)  # name.py, or the package folder name/
            if path is None:
                self.problems[name] = missing_file(self.folder, name)
            elif not self.trusted:
                problem = syntax_problem(path, name)
                if problem:
                    self.problems[name] = problem
            if name in self.problems:
                pytest.fail(self.problems[name], pytrace=False)
            if self.trusted:
                try:
                    module = import_file(path, f"trusted_{name}")
                except Exception as exc:  # noqa: BLE001 (a lab file may raise anything)
                    self.problems[name] = _import_problem_text(name, exc, path)
                    pytest.fail(self.problems[name], pytrace=False)
                self.loaded[name] = LocalLab(name, module)
            else:
                limit = self.config.getoption("--time-limit")
                if self.worker is None:
                    self.worker = Worker(
                        str(self.folder),
                        memory_bytes=int(self.config.getoption("--memory-limit") * 2**30),
                    )
                self.loaded[name] = SandboxedLab(
                    name, self.worker, limit, root=self.config.rootpath
                )
        return self.loaded[name]

    def close(self):
        if self.worker is not None:
            self.worker.stop()


_LABS_KEY = pytest.StashKey()


def _labs(config) -> _Labs:
    if _LABS_KEY not in config.stash:
        config.stash[_LABS_KEY] = _Labs(config)
    return config.stash[_LABS_KEY]


def pytest_collection_finish(session):
    """Start the sandboxed worker now: it imports torch while the first tests set up."""
    labs = _labs(session.config)
    if labs.trusted:
        return
    names = {
        getattr(item.module, "LAB_MODULE", None)
        for item in session.items
        if hasattr(item, "module") and "impl" in getattr(item, "fixturenames", ())
    }
    present = sorted(n for n in names if n and lab_source(labs.folder, n) is not None)
    for name in present:
        try:
            labs.get(name)._worker.launch()
            return
        except pytest.fail.Exception:  # a broken lab file: its tests say why
            continue


def _import_problem_text(name: str, exc: BaseException, path: Path) -> str:
    """One line for a trusted lab that raised while importing: the error and its line (the
    file of a lab package that raised)."""
    files = {str(f): f for f in module_files(path)}
    frames = [f for f in traceback.extract_tb(exc.__traceback__) if f.filename in files]
    shown = f"{name}.py"
    if frames and files[frames[-1].filename] != path:
        shown = f"{name}/{files[frames[-1].filename].relative_to(path).as_posix()}"
    where = f" ({shown}, line {frames[-1].lineno})" if frames else ""
    return f"{name}.py failed to import: {type(exc).__name__}: {exc}{where}"


def pytest_unconfigure(config):
    if _LABS_KEY in config.stash:
        config.stash[_LABS_KEY].close()


@pytest.fixture(scope="session")
def _rtcourse_labs(request):
    return _labs(request.config)


@pytest.fixture
def impl(request, _rtcourse_labs):
    """The lab module under test (named by the test module's ``LAB_MODULE``)."""
    name = getattr(request.module, "LAB_MODULE", None)
    if name is None:
        pytest.fail(f"{request.module.__name__} must define LAB_MODULE", pytrace=False)
    lab = _rtcourse_labs.get(name)
    lab._start_clock()
    request.node.stash[_LAB_KEY] = lab
    return lab


_LAB_KEY = pytest.StashKey()


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    """Attach what the submission printed to the report of the phase that ran it, and
    give a failing graded test its short feedback."""
    outcome = yield
    report = outcome.get_result()
    worker = getattr(item.stash.get(_LAB_KEY, None), "_worker", None)
    if worker is not None:
        text = worker.take_output()
        if text.strip():
            report.sections.append((f"submission output {call.when}", text))
    if report.failed and call.excinfo is not None and item.get_closest_marker("points") is not None:
        _give_feedback(item, call, report)


def long_feedback(config) -> bool:
    """pytest's own report: with ``--feedback full``, ``-v`` or an explicit ``--tb`` style."""
    choice = config.getoption("--feedback", None)
    if choice is not None:
        return choice == "full"
    return config.getoption("verbose", 0) > 0 or config.getoption("tbstyle", "auto") != "auto"


@cache
def _function_tasks(test_file: str, root: str, module: str) -> dict:
    """What the lab's skeleton asks for, per task (empty where it cannot be read)."""
    skeleton = lab_source(Path(root) / "labs", module)
    try:
        return function_tasks(read_grader(test_file), skeleton) if skeleton else {}
    except (OSError, SyntaxError, ValueError):
        return {}


def _frames(excinfo) -> list[tuple[str, int, str, str]]:
    """``(file, line, function, source line)`` of each traceback entry. The line as a
    printed traceback shows it, from linecache: pytest's ``entry.statement`` parses the
    whole file per frame (most of a failing skeleton's grading time)."""
    frames = []
    for entry in excinfo.traceback:
        source = linecache.getline(str(entry.path), entry.lineno + 1).strip()
        frames.append((str(entry.path), entry.lineno + 1, entry.name, source))
    return frames


def _header(item, task) -> str:
    title = getattr(item.module, "TASKS", {}).get(task, "")
    lab = lab_number(item)
    where = (f"lab {lab} " if lab is not None else "") + (f"task {task}" if task else "")
    return f"{item.name}: {where}" + (f" ({title})" if title else "")


def _give_feedback(item, call, report):
    labs = _labs(item.config)
    module = getattr(item.module, "LAB_MODULE", "")
    task_marker = item.get_closest_marker("task")
    task = task_marker.args[0] if task_marker and task_marker.args else None
    exc = call.excinfo.value
    tasks = _function_tasks(str(item.path), str(item.config.rootpath), module)
    if module in labs.problems and str(exc) == labs.problems[module]:
        feedback = Feedback(labs.problems[module], problem=labs.problems[module])
    else:
        feedback = short_feedback(
            exc=exc,
            frames=_frames(call.excinfo),
            test_file=item.path,
            folder=labs.folder,
            task=task,
            task_of=tasks.get,
            lab_module=module,
            header=_header(item, task),
        )
    if IMPORT_FAILED in str(exc) and module and module not in labs.problems:
        labs.problems[module] = feedback.text  # the rest of the lab's tests fail at once
    problem = labs.problems.get(module)
    if problem is not None and (feedback.problem or str(exc) == problem):
        report.user_properties.append(("problem", problem))
    report.user_properties.append(("feedback", feedback.text))
    pictures = getattr(exc, "pictures", None)
    if pictures:
        report.user_properties.append(("pictures", [str(p) for p in pictures]))
    if not long_feedback(item.config):
        report.longrepr = feedback.text


def pytest_terminal_summary(terminalreporter, config):
    """Each submission problem once, after the failures it caused."""
    labs = config.stash.get(_LABS_KEY, None)
    if labs is not None and labs.problems:
        terminalreporter.section("submission problems")
        for text in labs.problems.values():
            terminalreporter.write_line(text)


def _task_name(lab, task) -> str:
    """ "task 2" or "task 2 of lab 4" (a ``--task`` given as ``N.K``)."""
    return f"task {task}" + (f" of lab {lab}" if lab is not None else "")
