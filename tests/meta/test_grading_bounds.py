"""The bounds of a grading run, against hostile submissions (``hostile/*/lab8_guard.py`` of
the toy course's lab 8, and ``hostile/*/lab0_interop.py`` of the real Lab 0).

Whatever a submission does, grading ends in bounded time with a valid results.json and
per-test feedback, the grader's memory stays bounded, no temporary folder or process of the
run outlives it, the grader's probes and its output/input split cannot be forged, inputs
changed in place never earn points, and no line of a hidden test reaches what a student
sees. The runs about time get small limits (4 s per test, 8 s per lab for what tests run
past their first second) so that each takes seconds.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest
import torch

HERE = Path(__file__).parent
ROOT = HERE.parent.parent
TIME_LIMIT, BUDGET, SLOW = 4.0, 8.0, 1.0
MARK = "rtcourse-hostile-child-987654"  # in the command line of child_spawner's children
TOY = (
    "honest",
    "hang_everything",
    "near_limit_sleeper",
    "reply_bomb",
    "probe_forger",
    "out_renamer",
    "hidden_leak",
    "child_spawner",
    "input_zeroer",
)
LAB0 = ("input_zeroer", "out_renamer", "probe_forger")  # a hanging Lab 0: the slow test
# Only the runs about time get the small limits; the others keep the default ones, so a
# busy machine cannot make an honest call look like a hang.
TIMED = {
    "RTCOURSE_TIME_LIMIT": str(TIME_LIMIT),
    "RTCOURSE_LAB_TIME_BUDGET": str(BUDGET),
    "RTCOURSE_SLOW_TEST": str(SLOW),
}
ENV = {
    "reply_bomb": {"RTCOURSE_MEMORY_GB": "2"},
    "hang_everything": TIMED,
    "near_limit_sleeper": TIMED,
    "child_spawner": {"RTCOURSE_TIME_LIMIT": "40"},
}


def _unprivileged_user():
    """A user to run the submission as, where this runs as root (as the Gradescope
    autograder does); None elsewhere."""
    if os.geteuid() != 0:
        return None
    import pwd

    # That user must be able to run this Python (not one installed under /root).
    stdlib = Path(os.__file__).resolve().parent
    if not all(p.stat().st_mode & 0o005 == 0o005 for p in (stdlib, *stdlib.parents)):
        return None

    try:
        return pwd.getpwnam("nobody").pw_name
    except KeyError:
        return None


if _unprivileged_user():  # the forger also as the unprivileged worker user
    ENV["probe_forger"] = {"RTCOURSE_WORKER_USER": _unprivileged_user()}

# Runs the grader and records its own peak memory (not its workers').
_WRAPPER = """import resource, sys
from course.tools.cli import main
try:
    code = main(sys.argv[2:])
finally:
    with open(sys.argv[1], "w") as f:
        f.write(str(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss))
sys.exit(code)
"""


def _processes_with(text: str) -> list[str]:
    found = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit() or int(entry) == os.getpid():
            continue
        try:
            with open(f"/proc/{entry}/cmdline", "rb") as f:
                cmdline = f.read().replace(b"\0", b" ").decode(errors="replace")
        except OSError:
            continue
        if text in cmdline:
            found.append(f"{entry}: {cmdline[:200]}")
    return found


def _grade(name, base: Path, hostile: Path, course: Path, lab: int, env: dict) -> dict:
    run = base / f"{name}-lab{lab}"
    tmp = run / "tmp"
    tmp.mkdir(parents=True)
    out, rss = run / "results.json", run / "maxrss"
    full_env = dict(os.environ, RTCOURSE_MEMORY_GB="0.5", RTCOURSE_REPLY_MB="32", TMPDIR=str(tmp))
    for key in (
        "RTCOURSE_TIME_LIMIT",
        "RTCOURSE_LAB_TIME_BUDGET",
        "RTCOURSE_SLOW_TEST",
        "RTCOURSE_LAB_TIME_CAP",
    ):
        full_env.pop(key, None)
    full_env.update(env)
    start = time.monotonic()
    proc = subprocess.run(
        [
            sys.executable,
            "-c",
            _WRAPPER,
            str(rss),
            "grade",
            "--impl",
            str(hostile / name),
            "--lab",
            str(lab),
            "--json",
            str(out),
        ],
        cwd=course,
        env=full_env,
        capture_output=True,
        text=True,
        timeout=400,
        check=False,
    )
    return {
        "proc": proc,
        "seconds": time.monotonic() - start,
        "data": json.loads(out.read_text()) if out.exists() else None,
        "maxrss_kb": int(rss.read_text()) if rss.exists() else None,
        "leftover_files": sorted(
            p.name for p in tmp.iterdir() if not p.name.startswith("pytest-of-")
        ),
    }


# The runs each test reads; only those of the selected tests are graded.
_ALL = [(n, 8) for n in TOY] + [(n, 0) for n in LAB0]
NEEDS = {
    "test_every_toy_run_is_valid_and_leaves_nothing": None,  # its parameter's toy run
    "test_lab0_attacks_earn_nothing": None,  # its parameter's Lab 0 run
    "test_no_process_of_a_run_outlives_it": _ALL,
    "test_hanging_lab_ends_in_its_budget": [("hang_everything", 8)],
    "test_near_limit_sleeper_cannot_multiply_the_limit": [("near_limit_sleeper", 8)],
    "test_reply_bombs_fail_their_tests_not_the_grader": [("reply_bomb", 8)],
    "test_probe_forgery_is_refused": [("probe_forger", 8), ("probe_forger", 0)],
    "test_outputs_come_from_the_reference_signature": [("out_renamer", 8)],
    "test_inputs_changed_in_place_never_earn_points": [("input_zeroer", 8)],
    "test_hidden_source_never_shown": [("hidden_leak", 8)],
}


def _needed(items) -> list[tuple[str, int]]:
    wanted = set()
    for item in items:
        if item.module.__name__ != __name__:
            continue
        needs = NEEDS.get(item.originalname)
        params = getattr(getattr(item, "callspec", None), "params", {})
        if needs is None and "name" in params:  # a test parametrized by submission
            lab = 8 if "toy" in item.originalname else 0
            needs = [(params["name"], lab)]
        wanted |= set(needs or ())
    return [run for run in _ALL if run in wanted]


@pytest.fixture(scope="module")
def runs(request):
    """The hostile submissions the selected tests need, graded two at a time; then what is
    still running."""
    base = Path(tempfile.mkdtemp(prefix="rtcourse-bounds-"))
    base.chmod(0o755)  # an unprivileged worker user reads the submissions here
    try:
        hostile = base / "hostile"  # a private copy: its path names only these runs' processes
        shutil.copytree(HERE / "hostile", hostile)
        course = base / "toycourse"
        shutil.copytree(HERE / "toycourse", course)
        jobs = [
            (name, course if lab == 8 else ROOT, lab, ENV.get(name, {}))
            for name, lab in _needed(request.session.items)
        ]
        with ThreadPoolExecutor(max_workers=2) as pool:
            graded = list(pool.map(lambda job: _grade(job[0], base, hostile, *job[1:]), jobs))
        result = {(name, lab): run for (name, _, lab, _), run in zip(jobs, graded)}
        time.sleep(0.5)
        result["alive"] = _processes_with(str(hostile)) + _processes_with(MARK)
        result["hidden_lines"] = _hidden_lines(course)
        yield result
    finally:
        shutil.rmtree(base, ignore_errors=True)


def _hidden_lines(course: Path) -> set[str]:
    def lines(path):
        return {s for s in (line.strip() for line in path.read_text().splitlines()) if len(s) >= 16}

    visible = set()
    for path in [*course.glob("tests/test_*.py"), *course.glob("solutions/*.py")]:
        visible |= lines(path)
    hidden = set()
    for path in course.glob("tests/hidden/*.py"):
        hidden |= lines(path)
    return hidden - visible


def _valid(run, name):
    proc, data = run["proc"], run["data"]
    assert data is not None, f"{name}: no results.json\n{proc.stdout[-3000:]}\n{proc.stderr}"
    for key in ("score", "max_score", "execution_time", "tests", "output"):
        assert key in data, f"{name}: results.json lacks {key!r}"
    for test in data["tests"]:
        assert set(test) >= {"name", "score", "max_score", "status", "output"}
        if test["status"] == "failed":
            assert test["output"].strip(), f"{name}: {test['name']} failed without feedback"
    assert run["leftover_files"] == [], f"{name}: left behind {run['leftover_files']}"
    return data


def _outputs(data, name_part=""):
    return [t["output"] for t in data["tests"] if name_part in t["name"]]


@pytest.mark.parametrize("name", TOY)
def test_every_toy_run_is_valid_and_leaves_nothing(runs, name):
    data = _valid(runs[(name, 8)], name)
    assert data["max_score"] == pytest.approx(6.0)
    if name == "honest":
        assert data["score"] == pytest.approx(6.0), data["output"]
    elif name == "child_spawner":
        # Right answers everywhere but where its children passed the memory limit together.
        assert data["score"] == pytest.approx(5.0), data["output"]
        assert "memory" in " ".join(_outputs(data, "scale_into")).lower()
    elif name == "near_limit_sleeper":
        assert 0 < data["score"] < 6, data["output"]
    else:
        assert data["score"] == 0, f"{name} earned {data['score']}\n{data['output']}"


@pytest.mark.parametrize("name", LAB0)
def test_lab0_attacks_earn_nothing(runs, name):
    data = _valid(runs[(name, 0)], name)
    assert data["max_score"] > 0
    passed = [t["name"] for t in data["tests"] if t["status"] == "passed"]
    assert data["score"] == 0, f"{name} earned {data['score']} in Lab 0 from {passed}"


def test_no_process_of_a_run_outlives_it(runs):
    assert runs["alive"] == [], "processes left running:\n" + "\n".join(runs["alive"])


def _timed_out(messages) -> set[str]:
    """The calls that ran into the time limit (a later call of one repeats its message)."""
    return {
        line.split(" did not finish")[0]
        for m in messages
        for line in m.splitlines()
        if "did not finish within the time limit" in line
    }


def test_hanging_lab_ends_in_its_budget(runs):
    messages = _outputs(runs[("hang_everything", 8)]["data"])
    assert all(
        "did not finish within the time limit" in m or "time budget of the lab used up" in m
        for m in messages
    ), messages
    # 8 s of budget past the first second of each 4 s test: two timeouts, then the budget
    # ends the third call and every later one fails before it runs.
    assert len(_timed_out(messages)) <= 3, _timed_out(messages)
    # One call was stopped when the budget ran out; every later one was not run at all.
    stopped = [m for m in messages if "time budget of the lab used up while" in m]
    not_run = [m for m in messages if "was not run" in m]
    assert len(stopped) <= 1 and not_run, messages
    # A function that timed out fails at once afterwards, with the same message.
    scale = _outputs(runs[("hang_everything", 8)]["data"], "test_scale[")
    first = next(line for line in scale[0].splitlines() if "did not finish" in line)
    assert all(first in m for m in scale), scale


def test_near_limit_sleeper_cannot_multiply_the_limit(runs):
    data = runs[("near_limit_sleeper", 8)]["data"]
    nap = TIME_LIMIT - 0.4
    messages = _outputs(data)
    passed = sum(t["status"] == "passed" for t in data["tests"])
    budget_failures = sum("time budget of the lab used up" in m for m in messages)
    # A test failed by the budget never ran the submission: of the 10 tests (11 naps of
    # 3.6 s), at most the first four napped; the rest failed at once.
    assert passed <= BUDGET // (nap - SLOW) + 1, data["output"]
    assert passed + budget_failures >= len(data["tests"]) - 1, data["output"]
    assert budget_failures >= len(data["tests"]) - 5, data["output"]
    assert sum("was not run" in m for m in messages) >= len(data["tests"]) - 5, messages


def test_reply_bombs_fail_their_tests_not_the_grader(runs):
    run = runs[("reply_bomb", 8)]
    data = run["data"]
    assert run["maxrss_kb"] is not None and run["maxrss_kb"] < 2 * 2**20, (
        f"the grader peaked at {run['maxrss_kb'] / 2**20:.2f} GB"
    )
    outputs = dict(zip((t["name"] for t in data["tests"]), _outputs(data)))
    text = " ".join(outputs.values())
    assert "more than the 32 MB" in text  # a result over the cap, in the worker
    assert "more than 32 MB" in text  # the memo bomb, counted while decoding
    assert "nested too deeply" in text  # the deep list
    assert "more than" in outputs[next(k for k in outputs if "test_scale[3.0]" in k)]


def test_probe_forgery_is_refused(runs):
    for key in (("probe_forger", 8), ("probe_forger", 0)):
        text = " ".join(_outputs(runs[key]["data"]))
        assert "changed the grader's own code" in text, text[:2000]


def test_outputs_come_from_the_reference_signature(runs):
    text = " ".join(_outputs(runs[("out_renamer", 8)]["data"], "test_scale["))
    assert "modified its input argument(s) 'x'" in text, text


def test_inputs_changed_in_place_never_earn_points(runs):
    data = runs[("input_zeroer", 8)]["data"]
    for test in data["tests"]:
        assert "modified its input argument" in test["output"], test


def test_hidden_source_never_shown(runs):
    run = runs[("hidden_leak", 8)]
    data, hidden = run["data"], runs["hidden_lines"]
    assert hidden, "the toy course's hidden test has no line of its own"
    probe_body = {line for line in hidden if "secret_shape" in line or "lab.as_view" in line}
    shown = [(t["name"], t["output"]) for t in data["tests"] if "hidden" not in t["name"]]
    shown += [
        ("results.json output", data["output"]),
        ("stdout", run["proc"].stdout),
        ("stderr", run["proc"].stderr),
    ]
    for where, text in shown:
        leaked = [line for line in hidden if line in text]
        assert not leaked, f"{where} shows hidden test lines {leaked}"
    for test in data["tests"]:  # not even a hidden test's own output shows its probe
        assert not [line for line in probe_body if line in test["output"]], test


# ------------------------------------------------------------ the same bounds, in-process


def test_decode_counts_what_it_builds():
    from course.grading import wire

    one = wire.loads_plain(wire.dumps(wire.encode(torch.ones(2**18))))  # 1 MB
    with pytest.raises(wire.TooLarge):
        wire.decode([one] * 100, limit=32 * 2**20)  # 100 MB from one tensor's bytes
    assert len(wire.decode([one] * 10, limit=32 * 2**20)) == 10
    deep: list = []
    for _ in range(100000):
        deep = [deep]
    with pytest.raises(wire.TooLarge, match="nested too deeply"):
        wire.decode(deep, limit=32 * 2**20)
    lying = dict(one, shape=(2**40,))  # a shape its bytes do not fill
    with pytest.raises(TypeError, match="bytes of data"):
        wire.decode(lying, limit=32 * 2**20)


def test_outputs_are_the_references_and_hidden_lines_are_removed(tmp_path):
    from course.grading.sandbox import Redactor, reference_signatures

    (tmp_path / "solutions").mkdir()
    (tmp_path / "solutions" / "lab8_guard.py").write_text(
        "def f(x, y_out, *, out=None):\n    pass\n\n"
        "class K:\n    def __init__(self, shape):\n        pass\n\n"
        "    def put(self, frame, out):\n        pass\n\n"
        "    @staticmethod\n    def make(a):\n        pass\n"
    )
    table = reference_signatures(tmp_path / "solutions" / "lab8_guard.py")
    assert table == {
        "f": ["x", "y_out"],
        "K": ["shape"],
        "K.put": ["frame", "out"],
        "K.make": ["a"],
    }
    (tmp_path / "tests" / "hidden").mkdir(parents=True)
    (tmp_path / "tests" / "test_lab8_guard.py").write_text("shared_line_of_both_tests = 1\n")
    (tmp_path / "tests" / "hidden" / "test_lab8_guard_hidden.py").write_text(
        "shared_line_of_both_tests = 1\nsecret_seed_of_the_hidden_test = 1234\n"
    )
    redact = Redactor(tmp_path)
    text = redact("ok\n    secret_seed_of_the_hidden_test = 1234\nshared_line_of_both_tests = 1\n")
    assert "1234" not in text and "shared_line_of_both_tests" in text and "ok" in text


@pytest.mark.slow
def test_hanging_lab_grades_within_three_minutes_at_the_default_limits(tmp_path):
    """Lab 0 with every function hanging, at the default 120 s limit and budgets: one
    timeout, then every call fails at once."""
    shutil.copytree(HERE / "hostile" / "hang_everything", tmp_path / "sub")
    env = {k: v for k, v in os.environ.items() if not k.startswith("RTCOURSE_")}
    env["TMPDIR"] = str(tmp_path)
    start = time.monotonic()
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "course.tools.cli",
            "grade",
            "--impl",
            str(tmp_path / "sub"),
            "--lab",
            "0",
            "--json",
            str(tmp_path / "results.json"),
        ],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    seconds = time.monotonic() - start
    data = json.loads((tmp_path / "results.json").read_text())
    assert data["score"] == 0 and data["tests"], proc.stdout[-2000:]
    assert all(t["output"].strip() for t in data["tests"])
    assert seconds < 180, f"a hanging Lab 0 took {seconds:.0f} s to grade"


@pytest.mark.parametrize("forked", ["0", "1"], ids=["fresh", "forked"])
def test_a_killed_grader_leaves_nothing(tmp_path, forked):
    """The grader itself killed mid-run (SIGKILL: no clean-up of its own): the worker
    notices, ends everything the submission started and removes its folder; with the
    worker forked from the zygote, the zygote goes too, with its folder."""
    course, sub = tmp_path / "course", tmp_path / "sub"
    shutil.copytree(HERE / "toycourse", course)
    shutil.copytree(HERE / "hostile" / "child_spawner", sub)
    (tmp_path / "tmp").mkdir()
    env = dict(
        os.environ, TMPDIR=str(tmp_path / "tmp"), RTCOURSE_TIME_LIMIT="60", RTCOURSE_ZYGOTE=forked
    )
    proc = subprocess.Popen(
        [sys.executable, "-m", "course.tools.cli", "grade", "--impl", str(sub), "--lab", "8"],
        cwd=course,
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        deadline = time.monotonic() + 240
        while not _processes_with(MARK) and time.monotonic() < deadline:
            time.sleep(0.2)  # until the submission's first children run
        assert _processes_with(MARK), "the submission never started its children"
    finally:
        proc.kill()
        proc.wait()
    deadline = time.monotonic() + 30

    def left():  # a worker forked from the zygote does not name the submission's folder
        folders = list((tmp_path / "tmp").glob("rtcourse-*"))
        return _processes_with(str(sub)) + _processes_with(MARK) + folders

    while left() and time.monotonic() < deadline:
        time.sleep(0.2)
    assert not _processes_with(str(sub)) and not _processes_with(MARK)
    assert not list((tmp_path / "tmp").glob("rtcourse-*")), "the worker's and zygote's folders"


# ------------------------------------------------------------ memory of a small container


def test_memory_room_reads_the_container_limit(tmp_path):
    from course.grading.sandbox import memory_room

    meminfo = tmp_path / "meminfo"
    meminfo.write_text("MemTotal:       16000000 kB\nMemAvailable:    8000000 kB\n")
    v2 = tmp_path / "v2"
    v2.mkdir()
    (v2 / "memory.max").write_text("805306368\n")  # Gradescope's 768 MB
    (v2 / "memory.current").write_text(str(400 * 2**20))
    assert memory_room(str(v2), str(meminfo)) == 368 * 2**20
    (v2 / "memory.max").write_text("max\n")
    assert memory_room(str(v2), str(meminfo)) == 8000000 * 1024, "no limit: MemAvailable"
    v1 = tmp_path / "v1" / "memory"
    v1.mkdir(parents=True)
    (v1 / "memory.limit_in_bytes").write_text(str(2**30))
    (v1 / "memory.usage_in_bytes").write_text(str(2**28))
    assert memory_room(str(tmp_path / "v1"), str(meminfo)) == 3 * 2**28
    assert memory_room(str(tmp_path / "none"), str(tmp_path / "none")) is None


def test_worker_limit_fits_the_container(tmp_path, monkeypatch):
    """On a 768 MB container the worker's limit is what the container has free (less the
    grader's reserve), not the default 4 GiB extra; its processes are the kernel's first
    choice when memory runs out."""
    from course.grading import sandbox

    monkeypatch.setattr(sandbox, "memory_room", lambda: 368 * 2**20 + sandbox.GRADER_RESERVE)
    worker = sandbox.Worker(str(tmp_path), memory_bytes=4 * 2**30)
    assert worker.tree_limit == sandbox.MIN_TREE_BYTES, "never below the least limit"
    monkeypatch.setattr(sandbox, "memory_room", lambda: 3 * 2**30)
    assert (
        sandbox.Worker(str(tmp_path), memory_bytes=4 * 2**30).tree_limit
        == 3 * 2**30 - sandbox.GRADER_RESERVE
    )
    monkeypatch.setattr(sandbox, "memory_room", lambda: None)
    assert (
        sandbox.Worker(str(tmp_path), memory_bytes=2**30).tree_limit
        == 2**30 + sandbox.BASELINE_BYTES
    )
    (tmp_path / "lab8_oom.py").write_text(
        "def score():\n    return int(open('/proc/self/oom_score_adj').read())\n"
    )
    lab = sandbox.SandboxedLab("lab8_oom", sandbox.Worker(str(tmp_path), memory_bytes=2**30), 60.0)
    try:
        assert lab.score() == 1000, "the submission's process: the out-of-memory killer's first"
    finally:
        lab._worker.stop()
