"""The pytest plugin every grader runs under (enabled in pyproject's addopts).

It provides
  * ``--impl labs|solutions|PATH``: which implementation the tests load
    (also ``RTCOURSE_IMPL``); only ``solutions`` runs in-process, everything else
    runs in a sandboxed worker (see :mod:`course.grading.sandbox`);
  * the ``impl`` fixture: the lab module named by the test module's ``LAB_MODULE``;
  * the ``device`` parametrisation: ``cpu`` always, ``cuda`` when present;
  * markers ``points(n)``, ``task(k)``, ``visibility(v)``, ``gpu``, ``slow``.

Tests under ``tests/hidden/`` are the instructor's hidden tests: ``rtcourse release`` leaves
them out of the handout, ``rtcourse gradescope`` ships them, and unless marked otherwise
Gradescope shows them to students only after the due date.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest
import torch

from course.grading.sandbox import LocalLab, SandboxedLab, Worker
from course.grading.wire import import_file

MARKERS = (
    "points(n): the test is graded and worth n points",
    "task(k): the lab task (1, 2, ...) the test grades",
    ("visibility(v): when Gradescope shows the test to students: visible (default), hidden, "
     "after_due_date or after_published"),
    "gpu: needs a CUDA device",
    "slow: long-running; skipped unless --runslow",
)


def pytest_addoption(parser):
    group = parser.getgroup("rtcourse", "GPU ray tracing course grader")
    group.addoption("--impl", default=os.environ.get("RTCOURSE_IMPL"),
                    help="implementation to grade: solutions (the default where it exists), "
                         "labs (the default in the student handout), or a folder holding a "
                         "student's lab files")
    group.addoption("--trusted", action="store_true",
                    default=os.environ.get("RTCOURSE_TRUSTED") == "1",
                    help="run the implementation in-process (only for code you trust)")
    group.addoption("--time-limit", type=float,
                    default=float(os.environ.get("RTCOURSE_TIME_LIMIT", "120")),
                    help="seconds of student code per test (sandboxed runs)")
    group.addoption("--memory-limit", type=float,
                    default=float(os.environ.get("RTCOURSE_MEMORY_GB", "4")),
                    help="GiB of extra memory the student code may use (sandboxed runs)")
    group.addoption("--runslow", action="store_true", help="also run tests marked slow")


def pytest_configure(config):
    for marker in MARKERS:
        config.addinivalue_line("markers", marker)


VISIBILITIES = ("visible", "hidden", "after_due_date", "after_published")
HIDDEN_DEFAULT = "after_due_date"  # tests in a hidden/ folder unless marked otherwise


def pytest_collection_modifyitems(config, items):
    has_cuda = torch.cuda.is_available()
    for item in items:
        visibility = item.get_closest_marker("visibility")
        if visibility is None and item.path.parent.name == "hidden":
            item.add_marker(pytest.mark.visibility(HIDDEN_DEFAULT))
        elif visibility is not None and (len(visibility.args) != 1
                                         or visibility.args[0] not in VISIBILITIES):
            raise pytest.UsageError(f"{item.nodeid}: visibility{visibility.args} must be one "
                                    f"of {', '.join(VISIBILITIES)}")
        if "slow" in item.keywords and not config.getoption("--runslow"):
            item.add_marker(pytest.mark.skip(reason="slow test: run with --runslow"))
        if "gpu" in item.keywords and not has_cuda:
            item.add_marker(pytest.mark.skip(reason="needs a CUDA device"))


def pytest_generate_tests(metafunc):
    if "device" in metafunc.fixturenames:
        devices = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])
        metafunc.parametrize("device", devices)


def default_impl(root: Path) -> str:
    """``solutions`` in the course repository, ``labs`` in the student handout."""
    return "solutions" if (root / "solutions").is_dir() else "labs"


def resolve_impl(config) -> tuple[Path, bool]:
    """The folder holding the lab files, and whether it is trusted."""
    root = Path(config.rootpath)
    impl = config.getoption("--impl") or default_impl(root)
    if impl in ("solutions", "labs"):
        folder = root / impl
    else:
        folder = Path(impl).expanduser().resolve()
        if (folder / "labs").is_dir() and not any(folder.glob("lab*_*.py")):
            folder = folder / "labs"  # a copy of the whole handout
    trusted = impl == "solutions" or config.getoption("--trusted")
    return folder, trusted


class _Labs:
    """Lab modules loaded for this session; one warm worker serves every sandboxed lab."""

    def __init__(self, config):
        self.config = config
        self.folder, self.trusted = resolve_impl(config)
        self.loaded: dict[str, object] = {}
        self.worker: Worker | None = None

    def get(self, name: str):
        if name not in self.loaded:
            path = self.folder / f"{name}.py"
            if not path.is_file():
                pytest.fail(f"no {name}.py in {self.folder}: the submission must contain "
                            f"the file {name}.py", pytrace=False)
            if self.trusted:
                self.loaded[name] = LocalLab(name, import_file(path, f"trusted_{name}"))
            else:
                limit = self.config.getoption("--time-limit")
                if self.worker is None:
                    self.worker = Worker(str(self.folder), memory_bytes=int(
                        self.config.getoption("--memory-limit") * 2**30))
                self.loaded[name] = SandboxedLab(name, self.worker, limit)
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
    names = {getattr(item.module, "LAB_MODULE", None) for item in session.items
             if hasattr(item, "module") and "impl" in getattr(item, "fixturenames", ())}
    present = sorted(n for n in names if n and (labs.folder / f"{n}.py").is_file())
    if present:
        labs.get(present[0])._worker.launch()


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
    """Attach what the submission printed to the report of the phase that ran it."""
    outcome = yield
    worker = getattr(item.stash.get(_LAB_KEY, None), "_worker", None)
    if worker is not None:
        text = worker.take_output()
        if text.strip():
            outcome.get_result().sections.append((f"submission output {call.when}", text))
