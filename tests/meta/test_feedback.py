"""What a student reads when something fails: short messages first, submission problems
said once, task selection that matches the points, pictures when images differ.

Most checks grade tiny submissions of the toy lab (``toycourse/``) in a subprocess; the
task-selection check collects every lab's graders once without running them.
"""

from __future__ import annotations

import html
import json
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest
import torch

from course.core.files import lab_source
from course.grading.catalog import function_tasks, lab_catalog, lab_file_rank, skeleton_stubs
from course.grading.feedback import MAX_LINES, short_feedback
from course.grading.results import OUTPUT_LIMIT, ScoreKeeper
from course.grading.results import TestResult as Result
from course.grading.runner import lab_test_files
from course.grading.testing import ImageMismatch, assert_image_close
from course.tools.release import labs_readme

HERE = Path(__file__).parent
ROOT = HERE.parents[1]

WRONG = """\
import torch


def double(x):
    print("debugging " * 400)
    y = 3 * x
    return y


def norms(x):
    raise NotImplementedError("not implemented yet: norms (task 2)")
"""


# A grader of the toy lab that compares an image: its failure must come with pictures.
IMAGE_GRADER = """\
import pytest
import torch

from course.grading.testing import assert_image_close

LAB_MODULE = "lab9_toy"
TASKS = {3: "an image"}


@pytest.mark.task(3)
@pytest.mark.points(1)
def test_double_image(impl):
    image = torch.linspace(0, 0.4, 48).reshape(4, 4, 3)
    assert_image_close(impl.double(image), 2 * image, rtol=1e-6, name="double(image)")
"""


@pytest.fixture(scope="module")
def toy(tmp_path_factory):
    """The toy course and submissions: wrong, syntax error, misnamed, empty."""
    base = tmp_path_factory.mktemp("feedback")
    course = base / "course"
    shutil.copytree(HERE / "toycourse", course)
    (course / "tests" / "test_lab9_image.py").write_text(IMAGE_GRADER)
    subs = {}
    for name, files in {
        "wrong": {"lab9_toy.py": WRONG},
        "syntax": {"lab9_toy.py": "import torch\n\ndef double(x)\n    return x\n"},
        "misnamed": {"lab9_toy (1).py": WRONG},
        "import": {"lab9_toy.py": "import torch\nimport not_a_module_xyz\n"},
        "empty": {},
    }.items():
        folder = base / name
        folder.mkdir()
        for file, text in files.items():
            (folder / file).write_text(text)
        subs[name] = folder
    return course, subs


def _run(args, cwd, timeout=300, progress="0", **env):
    env = dict(os.environ, RTCOURSE_TIME_LIMIT="30", RTCOURSE_PROGRESS=progress, **env)
    return subprocess.run(
        [sys.executable, *args],
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        timeout=timeout,
        check=False,
    )


def _failure_blocks(stdout: str) -> dict[str, list[str]]:
    """Test name -> the lines pytest prints for its failure (between the ___ headers)."""
    blocks, name = {}, None
    for line in stdout.splitlines():
        header = re.match(r"^_{3,} (?:ERROR at \w+ of )?(\S+) _{3,}$", line)
        if header:
            name = header.group(1)
            blocks[name] = []
        elif re.match(r"^={3,} ", line):
            name = None
        elif name:
            blocks[name].append(line)
    return blocks


def test_pytest_failure_is_short_and_message_first(toy):
    course, subs = toy
    proc = _run(
        [
            "-m",
            "pytest",
            "tests/test_lab9_toy.py",
            "--impl",
            str(subs["wrong"]),
            "-p",
            "no:cacheprovider",
        ],
        course,
    )
    blocks = _failure_blocks(proc.stdout)
    assert set(blocks) == {"test_double[cpu]", "test_norms[cpu]"}, proc.stdout[-3000:]
    for lines in blocks.values():
        shown = [ln for ln in lines if not ln.startswith("---") and "Captured" not in ln]
        body = [ln for ln in shown if "debugging" not in ln]
        assert len(body) <= MAX_LINES, "\n".join(lines)
    assert blocks["test_norms[cpu]"][0] == "task 2: write `norms` (not implemented yet)"
    double = blocks["test_double[cpu]"]
    assert double[0] == "test_double[cpu]: lab 9 task 1 (double)"
    assert "not close" in double[1], double
    assert not any("def test_double" in ln or "tensor([" in ln for ln in double), double
    verbose = _run(
        [
            "-m",
            "pytest",
            "tests/test_lab9_toy.py",
            "--impl",
            str(subs["wrong"]),
            "-p",
            "no:cacheprovider",
            "-v",
            "-k",
            "double",
        ],
        course,
    )
    assert "def test_double" in verbose.stdout, "-v should bring back pytest's traceback"


def test_grade_prints_first_failure_per_task_and_caps_results_json(toy, tmp_path):
    course, subs = toy
    results = tmp_path / "results.json"
    pictures = tmp_path / "pictures"
    proc = _run(
        [
            "-m",
            "course.tools.cli",
            "grade",
            "--impl",
            str(subs["wrong"]),
            "--lab",
            "9",
            "--json",
            str(results),
        ],
        course,
        RTCOURSE_FAILURE_DIR=str(pictures),
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    lines = proc.stdout.strip().splitlines()
    assert len(lines) <= 24, proc.stdout  # a table, not a log
    row = next(i for i, ln in enumerate(lines) if re.match(r"\s+9\s+1\s+double", ln))
    assert "not close" in "\n".join(lines[row + 1 : row + 4])
    assert any("task 2: write `norms` (not implemented yet)" in ln for ln in lines)
    data = json.loads(results.read_text())
    for test in data["tests"]:
        text = test["output"]
        if test.get("output_format") == "html":  # the text, then the pictures
            text = html.unescape(text.split("<pre>", 1)[1].split("</pre>", 1)[0])
        assert len(text) <= OUTPUT_LIMIT, test["output"]
    outputs = {t["name"].split(": ", 1)[1]: t["output"] for t in data["tests"]}
    assert outputs["test_norms[cpu]"] == "task 2: write `norms` (not implemented yet)"
    double = outputs["test_double[cpu]"]
    assert double.startswith("test_double[cpu]: lab 9 task 1") and "not close" in double
    assert "what your code printed" in double  # after the message, cut short
    # The image test: three pictures on disk, named in the message, inline in results.json.
    image = next(t for t in data["tests"] if "test_double_image" in t["name"])
    assert image["output_format"] == "html" and image["output"].startswith("<pre>")
    assert image["output"].count("data:image/png;base64,") == 3
    written = sorted(p.name for p in pictures.rglob("*.png"))
    assert written == ["difference.png", "expected.png", "got.png"], written
    folder = next(pictures.rglob("got.png")).parent
    assert str(folder) in image["output"] and str(folder) in proc.stdout


def test_submission_problems_are_said_once(toy, tmp_path):
    course, subs = toy
    start = time.monotonic()
    missing = _run(["-m", "course.tools.cli", "grade", "--impl", str(tmp_path / "nowhere")], course)
    assert missing.returncode != 0 and time.monotonic() - start < 10
    assert missing.stderr.strip().splitlines() == [
        (
            f"rtcourse grade: --impl {tmp_path / 'nowhere'}: no such folder (give the folder "
            f"that holds your lab files, or labs / solutions)"
        )
    ]
    pytest_missing = _run(
        [
            "-m",
            "pytest",
            "tests/test_lab9_toy.py",
            "--impl",
            str(tmp_path / "nowhere"),
            "-p",
            "no:cacheprovider",
        ],
        course,
    )
    assert pytest_missing.returncode == 4 and "no such folder" in pytest_missing.stderr

    for name, needle in (
        ("empty", "no lab9_toy.py in"),
        ("misnamed", "found 'lab9_toy (1).py': rename it to lab9_toy.py"),
        (
            "syntax",
            ("lab9_toy.py failed to import: SyntaxError: expected ':' (lab9_toy.py, line 3)"),
        ),
        (
            "import",
            (
                "lab9_toy.py failed to import: ModuleNotFoundError: No "
                "module named 'not_a_module_xyz' (at import/lab9_toy.py:2"
            ),
        ),
    ):
        results = tmp_path / f"{name}.json"
        proc = _run(
            [
                "-m",
                "course.tools.cli",
                "grade",
                "--impl",
                str(subs[name]),
                "--lab",
                "9",
                "--json",
                str(results),
            ],
            course,
        )
        assert proc.stdout.count(needle) == 1, proc.stdout
        data = json.loads(results.read_text())
        assert data["score"] == 0 and all(needle in t["output"] for t in data["tests"])
        assert len({t["output"] for t in data["tests"]}) == 1  # one reason for every test

    typo = _run(
        [
            "-m",
            "course.tools.cli",
            "grade",
            "--impl",
            str(subs["wrong"]),
            "--lab",
            "9",
            "-k",
            "dubble",
        ],
        course,
    )
    assert typo.returncode != 0 and "no graded test matches" in typo.stderr
    no_task = _run(
        [
            "-m",
            "course.tools.cli",
            "grade",
            "--impl",
            str(subs["wrong"]),
            "--lab",
            "9",
            "--task",
            "7",
        ],
        course,
    )
    assert no_task.returncode != 0 and "no graded test of task 7 of lab 9" in no_task.stderr


def test_grade_task_runs_exactly_that_task(toy, tmp_path):
    course, _ = toy
    results = tmp_path / "results.json"
    _run(
        [
            "-m",
            "course.tools.cli",
            "grade",
            "--impl",
            "solutions",
            "--lab",
            "9",
            "--task",
            "2",
            "--json",
            str(results),
        ],
        course,
    )
    data = json.loads(results.read_text())
    assert {t["number"] for t in data["tests"]} == {"9.2"}
    assert data["max_score"] == pytest.approx(2.0) and data["score"] == pytest.approx(2.0)
    # The progress bar of the lab's tests (forced on: here stderr is a pipe, not a terminal).
    shown = _run(
        ["-m", "course.tools.cli", "grade", "--impl", "solutions", "--lab", "9", "--task", "2"],
        course,
        progress="1",
    )
    assert "lab 9:" in shown.stderr and "/1 [" in shown.stderr, shown.stderr


PROBE = """
import json, os
from course.grading.plugin import awards_task, parse_task

def pytest_collection_finish(session):
    points = {}
    for item in session.items:
        m = item.get_closest_marker("points")
        if m is None or "gpu" in item.keywords or "slow" in item.keywords:
            continue
        task = item.get_closest_marker("task")
        key = (item.module.__name__, item.originalname)
        points.setdefault(key, [m.args[0], 0, task.args[0] if task else None, item])[1] += 1
    out = {}
    for spec in json.loads(os.environ["TASK_SPECS"]):
        chosen = [item for item in session.items if awards_task(item, [parse_task(spec)])
                  and "gpu" not in item.keywords and "slow" not in item.keywords]
        out[spec] = sum(points[(i.module.__name__, i.originalname)][0]
                        / points[(i.module.__name__, i.originalname)][1] for i in chosen)
    with open(os.environ["TASK_OUT"], "w") as f:
        json.dump(out, f)
"""


def test_task_option_selects_exactly_each_tasks_points(tmp_path):
    files = lab_test_files(ROOT)
    labs = lab_catalog(files)
    specs = [f"{n}.{k}" for n, lab in labs.items() for k in lab.tasks]
    (tmp_path / "task_probe.py").write_text(PROBE)
    out = tmp_path / "points.json"
    env = dict(
        os.environ,
        TASK_SPECS=json.dumps(specs),
        TASK_OUT=str(out),
        PYTHONPATH=os.pathsep.join(filter(None, [str(tmp_path), os.environ.get("PYTHONPATH")])),
    )
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "pytest",
            *map(str, files),
            "--collect-only",
            "-q",
            "-p",
            "task_probe",
            "-p",
            "no:cacheprovider",
        ],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    assert out.is_file(), proc.stdout[-3000:] + proc.stderr[-3000:]
    got = json.loads(out.read_text())
    for n, lab in labs.items():
        for k in lab.tasks:
            assert got[f"{n}.{k}"] == pytest.approx(lab.points(k)), (
                f"--task {n}.{k} selects {got[f'{n}.{k}']} points, the task is worth "
                f"{lab.points(k)}"
            )


def test_every_not_implemented_belongs_to_a_listed_task():
    labs = lab_catalog(lab_test_files(ROOT))
    readme = labs_readme(ROOT, hidden_root=ROOT)
    for number, lab in labs.items():
        skeleton = lab_source(ROOT / "labs", lab.module)  # a file, or a package folder
        owners = function_tasks(lab, skeleton)
        assert set(owners) == {s.name for s in skeleton_stubs(skeleton)}
        section = readme.split(f"## Lab {number}", 1)[1].split("\n## ", 1)[0]
        for fn, task in owners.items():
            assert task in lab.tasks, (
                f"lab {number}: `{fn}` raises NotImplementedError but "
                f"belongs to no task (task {task})"
            )
            row = next(ln for ln in section.splitlines() if ln.startswith(f"| {task} |"))
            assert f"`{fn}`" in re.split(r"(?<!\\)\|", row)[4], (
                f"lab {number} task {task} omits `{fn}`"
            )
            assert f"--task {task}`" in row
    # Tasks are graded on their own (a task's tests are given the earlier tasks' results):
    # the end-to-end tasks need earlier ones, Lab 3's task 6 the student's tracer (task 1's
    # render_whitted and the blocks it calls); tests/meta/test_needs_first.py checks the rest.
    lab3 = readme.split("## Lab 3", 1)[1].split("\n## ", 1)[0]
    assert re.search(r"\| 6 \|[^\n]*\| task 1 \([^)]*`render_whitted`\) \|", lab3), (
        "Lab 3 task 6 (end to end) needs task 1"
    )
    lab4 = readme.split("## Lab 4", 1)[1].split("\n## ", 1)[0]
    assert not re.search(r"\| 2 \|[^\n]*\| task 1 ", lab4), "Lab 4 task 2 is graded on its own"


def test_unwritten_dependency_names_its_task():
    text = short_feedback(
        exc=NotImplementedError("not implemented yet: march_box (task 1)"),
        frames=[],
        test_file="tests/test_lab4_march.py",
        folder="labs",
        task=2,
        task_of={}.get,
    ).text
    assert text == (
        "needs `march_box` (task 1) first: this test of task 2 calls it, and it "
        "is not implemented yet"
    )
    mine = short_feedback(
        exc=NotImplementedError("not implemented yet: FrameDownloader.submit"),
        frames=[],
        test_file="t.py",
        folder="labs",
        task=3,
        task_of={"FrameDownloader": 3}.get,
    ).text
    assert mine == "task 3: write `FrameDownloader.submit` (not implemented yet)"


def test_near_miss_lab_file_names():
    for name in (
        "lab1_intersect (1).py",
        "Lab1_Intersect.py",
        "lab1_intersect-2.py",
        "lab1_intersect copy.py",
    ):
        assert lab_file_rank(name, "lab1_intersect") == 1, name
    assert lab_file_rank("lab1_intersect.py", "lab1_intersect") == 0
    assert lab_file_rank("lab1_intersects.py", "lab1_intersect") is None
    assert lab_file_rank("lab2_accel.py", "lab1_intersect") is None


def test_image_mismatch_writes_three_pictures_and_html(tmp_path, monkeypatch):
    monkeypatch.setenv("RTCOURSE_FAILURE_DIR", str(tmp_path))
    expected = torch.rand(12, 16, 3, generator=torch.Generator().manual_seed(3))
    got = expected.clone()
    got[4:6, 5:9] += 0.5
    assert_image_close(expected.clone(), expected, name="same", atol=1e-6)
    with pytest.raises(ImageMismatch) as info:
        assert_image_close(got, expected, name="render(scene)", atol=1e-3, where="pixel")
    exc = info.value
    assert [Path(p).name for p in exc.pictures] == ["expected.png", "got.png", "difference.png"]
    assert all(Path(p).is_file() and Path(p).parent.is_relative_to(tmp_path) for p in exc.pictures)
    assert str(Path(exc.pictures[0]).parent) in str(exc) and "8 of 16" not in str(exc)
    assert str(exc).startswith("render(scene): 24 of 576 values are off")
    from PIL import Image

    diff = Image.open(exc.pictures[2]).convert("RGB")
    # Scaled by 16 (nearest) to 256 pixels wide, over an 18-pixel strip naming the picture.
    assert diff.size == (256, 192 + 18) and diff.getpixel((6 * 16 + 8, 5 * 16 + 8)) == (255, 32, 32)
    assert diff.getpixel((6 * 16, 5 * 16)) == diff.getpixel((6 * 16 + 15, 5 * 16 + 15))
    # One folder per run under the chosen folder; a long test name is not clipped.
    run = Path(exc.pictures[0]).parents[2]
    assert run.parent == tmp_path and run.name.startswith("run-"), exc.pictures[0]
    long_name = "render(" + "x" * 90 + ")"
    with pytest.raises(ImageMismatch) as info:
        assert_image_close(got, expected, name=long_name, atol=1e-3)
    assert Path(info.value.pictures[0]).parent.name == long_name.replace("(", "_").rstrip(")")
    ids = torch.arange(20).reshape(4, 5)
    with pytest.raises(ImageMismatch):  # an id buffer, compared exactly, as (N,) rays
        assert_image_close(
            ids.flatten().flip(0),
            ids.flatten(),
            name="ids",
            exact=True,
            kind="id",
            image_shape=(4, 5),
            folder=tmp_path / "ids",
        )
    assert (tmp_path / "ids" / "difference.png").is_file()

    keeper = ScoreKeeper(show_progress=False)
    result = Result(
        nodeid="tests/test_lab6_x.py::test_y[cpu]",
        lab=6,
        lab_module="lab6_raster",
        task=3,
        task_title="t",
        max_score=1.0,
        message=str(exc),
        pictures=exc.pictures,
    )
    result.output = keeper._output(result)
    keeper.results[result.nodeid] = result
    test = keeper.to_gradescope()["tests"][0]
    assert test["output_format"] == "html" and test["output"].startswith("<pre>render(scene)")
    assert test["output"].count("data:image/png;base64,") == 3


def test_progress_only_on_a_terminal(monkeypatch):
    from course.core.progress import progress, progress_enabled

    monkeypatch.delenv("RTCOURSE_PROGRESS", raising=False)

    class Pipe:
        def isatty(self):
            return False

    assert not progress_enabled(Pipe())
    monkeypatch.setenv("RTCOURSE_PROGRESS", "1")
    assert progress_enabled(Pipe())
    monkeypatch.setenv("RTCOURSE_PROGRESS", "0")
    assert list(progress(range(3), desc="x")) == [0, 1, 2]

    from course.measure.bench import ResultTable

    monkeypatch.setenv("RTCOURSE_PROGRESS", "1")
    table = ResultTable("sweep", device="cpu", total=2)
    table.add(x=1)
    assert table._bar is not None and table._bar.n == 1
    table.add(x=2)
    assert table._bar.n == 2 and len(table.rows) == 2


def test_bad_mesh_file_is_named(tmp_path):
    from course.core.scenes import load_mesh

    for suffix, data in (
        (".obj", b"v 0 0 0\nf 1 2 3 4 5\nv nonsense\x00\xff"),
        (".glb", b"glTF\x02\x00\x00\x00garbage"),
        (".ply", b"ply\nformat binary_little_endian 1.0\nelement vertex 9\n"),
        (".xyz", b"1 2 3\n"),
    ):
        path = tmp_path / f"broken{suffix}"
        path.write_bytes(data)
        with pytest.raises(ValueError) as info:
            load_mesh(path)
        message = str(info.value)
        assert str(path) in message and suffix.lstrip(".").upper() in message.upper(), message


def test_camera_rejects_degenerate_up():
    from course.core.camera import Camera

    with pytest.raises(ValueError, match="up.*zero"):
        Camera(eye=(0, 0, 3), target=(0, 0, 0), up=(0, 0, 0))
    with pytest.raises(ValueError, match="up.*parallel"):
        Camera(eye=(0, 0, 3), target=(0, 0, 0), up=(0, 0, 2))


def test_commands_name_themselves_outside_the_course(tmp_path):
    proc = _run(["-m", "course.tools.cli", "release", str(tmp_path / "out")], tmp_path, timeout=60)
    assert proc.returncode != 0
    assert proc.stderr.strip().startswith("rtcourse release: run this inside the course"), (
        proc.stderr
    )


def test_student_line_from_the_worker_traceback(tmp_path):
    lab = tmp_path / "labs" / "lab1_intersect.py"
    text = (
        "IndexError: index 9 is out of bounds\n(raised in lab1_intersect.moller_trumbore; "
        "traceback from the worker:)\nTraceback (most recent call last):\n"
        '  File "/site/course/grading/worker.py", line 180, in _serve\n'
        "    result = fn(*args)\n"
        f'  File "{lab}", line 42, in moller_trumbore\n'
        "    t = e[9]\n"
        "IndexError: index 9 is out of bounds\n"
    )
    frames = [(str(ROOT / "tests" / "test_lab1_intersect.py"), 120, "test_x", "impl.f()")]
    feedback = short_feedback(
        exc=IndexError(text),
        frames=frames,
        test_file=ROOT / "tests" / "test_lab1_intersect.py",
        folder=lab.parent,
        task=2,
        task_of={}.get,
        header="test_x[cpu]: lab 1 task 2 (Möller–Trumbore)",
    ).text
    assert feedback.splitlines() == [
        "test_x[cpu]: lab 1 task 2 (Möller–Trumbore)",
        "IndexError: index 9 is out of bounds",
        "your code: labs/lab1_intersect.py:42 in moller_trumbore: t = e[9]",
        "checked at tests/test_lab1_intersect.py:120",
        "(the full traceback with the test's source and tensors: add -v)",
    ]


def test_gradescope_accepts_a_renamed_upload(tmp_path):
    from course.tools.gradescope import collect_submission

    sub = tmp_path / "submission"
    (sub / "labs").mkdir(parents=True)
    (sub / "Lab0_Interop (1).py").write_text("A = 1\n")
    (sub / "lab1_intersect (2).py").write_text("B = 1\n")
    (sub / "labs" / "lab1_intersect.py").write_text("C = 1\n")  # the exact name wins
    found = collect_submission(sub, tmp_path / "work", ["lab0_interop", "lab1_intersect"])
    assert found == {
        "lab0_interop.py": Path("Lab0_Interop (1).py"),
        "lab1_intersect.py": Path("labs/lab1_intersect.py"),
    }
    assert (tmp_path / "work" / "lab0_interop.py").read_text() == "A = 1\n"
    assert (tmp_path / "work" / "lab1_intersect.py").read_text() == "C = 1\n"


def test_a_long_hint_is_wrapped_never_cut():
    hint = (
        "march_box (homogeneous box): radiance against q (1 - e^(-sigma D)) / sigma. " * 8
        + "The last words of the hint."
    )
    text = short_feedback(
        exc=AssertionError(hint),
        frames=[],
        test_file="tests/test_x.py",
        folder=None,
        task=1,
        task_of=lambda fn: None,
    ).text
    lines = text.splitlines()
    assert " ".join(" ".join(lines).split()).count("The last words of the hint.") == 1, text
    assert all(len(line) <= 100 for line in lines), text
    assert not any(line.endswith("...") for line in lines), text


def test_grade_table_shows_whole_task_titles_and_whole_hints():
    keeper = ScoreKeeper(show_progress=False)
    title = "Exact voxel walk with empty-space skipping (3D DDA over macro cells)"
    hint = "\n".join(f"line {i} of the hint" for i in range(9))
    for nodeid, task, message in (
        ("tests/test_lab4_x.py::test_a[cpu]", 4, hint),
        ("tests/test_lab4_x.py::test_b[cpu]", 1, ""),
    ):
        result = Result(
            nodeid=nodeid,
            lab=4,
            lab_module="lab4_march",
            task=task,
            task_title=title if task == 4 else "t",
            max_score=1.0,
            message=message,
        )
        result.status = "failed" if message else "passed"
        keeper.results[nodeid] = result
    table = keeper.table()
    assert title in table, table
    assert "line 8 of the hint" in table, table


def test_collected_submission_is_named_as_handed_in(toy, tmp_path):
    """Graded from the autograder's temporary folder, the messages, the table and
    results.json name the files as the student handed them in, never that folder."""
    course, _ = toy
    uploads = {
        "renamed": {"labs/lab9_toy (1).py": (course / "solutions" / "lab9_toy.py").read_text()},
        "wrong name": {"lab9.py": "A = 1\n", "notes.txt": "notes\n"},
    }
    for name, files in uploads.items():
        upload, work = tmp_path / name / "upload", tmp_path / name / "work"
        for file, text in files.items():
            (upload / file).parent.mkdir(parents=True, exist_ok=True)
            (upload / file).write_text(text)
        collect = _run(
            ["-m", "course.tools.gradescope", "collect", str(upload), str(work), "--lab", "9"],
            course,
        )
        assert collect.returncode == 0, collect.stderr
        results = tmp_path / name / "results.json"
        proc = _run(
            [
                "-m",
                "course.tools.cli",
                "grade",
                "--impl",
                str(work),
                "--lab",
                "9",
                "--json",
                str(results),
            ],
            course,
        )
        data = json.loads(results.read_text())
        texts = [proc.stdout, data["output"], *(t["output"] for t in data["tests"])]
        assert not any(str(work) in text for text in texts), proc.stdout
        if name == "renamed":
            assert data["score"] == data["max_score"] > 0, proc.stdout
            assert "files graded: lab 9: 'labs/lab9_toy (1).py'" in proc.stdout
            assert data["extra_data"]["graded_files"] == {"lab9_toy": "'labs/lab9_toy (1).py'"}
        else:
            needle = (
                "no lab9_toy.py in the submission: the submission must contain the file "
                "lab9_toy.py (or the folder lab9_toy/ of a lab kept as a package); it "
                "holds 'lab9.py', 'notes.txt'"
            )
            assert proc.stdout.count(needle) == 1, proc.stdout
            assert all(needle in t["output"] for t in data["tests"])
            assert data["extra_data"]["graded_files"] == {}


def test_missing_lab_file_lists_the_folder(tmp_path, monkeypatch):
    from course.grading.plugin import graded_as, missing_file

    folder = tmp_path / "mine"
    folder.mkdir()
    (folder / "lab4_march.txt").write_text("")
    (folder / "lab4.py").write_text("")
    monkeypatch.chdir(tmp_path)
    assert missing_file(folder, "lab4_march") == (
        "no lab4_march.py in mine/: the submission must contain the file lab4_march.py (or "
        "the folder lab4_march/ of a lab kept as a package); it holds 'lab4.py', "
        "'lab4_march.txt'"
    )
    (folder / "Lab4_March (1).py").write_text("")
    assert missing_file(folder, "lab4_march").endswith(
        "(found 'Lab4_March (1).py': rename it to lab4_march.py)"
    )
    assert graded_as(folder, "lab4_march") is None
    (folder / "lab4_march").mkdir()
    (folder / "lab4_march" / "__init__.py").write_text("")
    assert graded_as(folder, "lab4_march") == "mine/lab4_march/"


def test_collected_package_names_its_files(tmp_path):
    from course.grading.plugin import graded_as, missing_file
    from course.tools.gradescope import collect_submission

    labs = tmp_path / "labs" / "lab9_toy"
    labs.mkdir(parents=True)
    for name in ("__init__.py", "grid.py", "walk.py"):
        (labs / name).write_text("X = 0\n")
    upload = tmp_path / "upload"
    (upload / "lab9_toy").mkdir(parents=True)
    (upload / "lab9_toy" / "grid.py").write_text("X = 1\n")
    (upload / "README.md").write_text("")
    work = tmp_path / "work"
    collect_submission(upload, work, ["lab9_toy", "lab8_guard"], tmp_path / "labs")
    assert graded_as(work, "lab9_toy") == "'lab9_toy/grid.py' (the skeleton's other 2 files)"
    assert missing_file(work, "lab8_guard").startswith("no lab8_guard.py in the submission:")
    assert missing_file(work, "lab8_guard").endswith("it holds 'README.md', 'lab9_toy/grid.py'")


def _depth_test_without_check(pixel, key, out):
    out[pixel] = key  # no range check: an index past the end is torch's IndexError
    return out


def test_expect_error_names_the_expected_error_when_another_comes():
    from course.grading.testing import expect_error

    out = torch.zeros(4, dtype=torch.int64)
    with pytest.raises(AssertionError) as caught:
        expect_error(
            "pixel",
            _depth_test_without_check,
            torch.tensor([3, 10]),
            torch.tensor([1, 2]),
            out,
            kinds=(ValueError,),
            case="a pixel index out of range",
        )
    text = str(caught.value)
    assert text.startswith(
        "_depth_test_without_check: expected ValueError naming `pixel` "
        "(a pixel index out of range), got IndexError: "
    ), text
    assert "at test_feedback.py:" in text and "out[pixel] = key" in text, text
    # A TypeError where only a ValueError is accepted says the same; with the default
    # kinds a TypeError naming the argument passes.
    with pytest.raises(
        AssertionError,
        match=r"expected ValueError naming `key` \(x\), got "
        r"TypeError: key: no",
    ):
        expect_error("key", _raises, TypeError("key: no"), kinds=(ValueError,), case="x")
    expect_error("key", _raises, TypeError("key: expected int64"))
    # An unwritten function keeps its own message: "not implemented yet" is no mistake.
    with pytest.raises(NotImplementedError):
        expect_error("pixel", _raises, NotImplementedError("not implemented yet: f (task 1)"))


def _raises(exc):
    raise exc


def test_expect_error_finds_the_line_in_the_workers_traceback(tmp_path):
    from course.grading.testing import expect_error

    lab = tmp_path / "labs" / "lab6_raster" / "visibility.py"
    text = (
        "RuntimeError: index 10 is out of bounds for dimension 0 with size 4\n"
        "(raised in lab6_raster.depth_test; traceback from the worker:)\n"
        "Traceback (most recent call last):\n"
        '  File "/site/course/grading/worker.py", line 180, in _serve\n'
        "    result = fn(*args)\n"
        f'  File "{lab}", line 97, in depth_test\n'
        '    out.scatter_reduce_(0, pixel, key, reduce="amin")\n'
    )
    with pytest.raises(AssertionError) as caught:
        expect_error(
            "pixel",
            _raises,
            RuntimeError(text),
            kinds=(ValueError,),
            case="a pixel index out of range",
        )
    assert str(caught.value).splitlines()[0] == (
        "_raises: expected ValueError naming `pixel` (a pixel index out of range), got "
        "RuntimeError: index 10 is out of bounds for dimension 0 with size 4 at "
        'visibility.py:97 in depth_test: out.scatter_reduce_(0, pixel, key, reduce="amin"); '
        "check the argument first and raise with a message that names it"
    ), caught.value
