"""Sandbox workers forked from the pre-imported zygote (``course.grading.zygote``) are the
workers a fresh interpreter would be: same answers, nothing of the zygote reachable, every
process gone when the worker stops, a crash reported with its exit code, and a dead zygote
replaced. (The hostile submissions' tests run with the zygote too: ``RTCOURSE_ZYGOTE=1``
in test_grading_isolation.py.)"""

from __future__ import annotations

import os
import signal
import time

import pytest
import torch

from course.grading import sandbox, zygote

pytestmark = pytest.mark.skipif(not zygote.supported(), reason="the zygote needs Linux pidfds")

LAB = '''
import os

import torch


def double(x):
    return 2 * x


def descriptors():
    """What this process holds open: fd -> what it points at."""
    out = {}
    for name in os.listdir("/proc/self/fd"):
        try:
            out[int(name)] = os.readlink(f"/proc/self/fd/{name}")
        except OSError:
            pass
    return out


def family():
    """This process, its parent (the keeper) and the keeper's parent."""
    keeper = os.getppid()
    with open(f"/proc/{keeper}/stat") as f:
        above = int(f.read().rsplit(")", 1)[1].split()[1])
    return os.getpid(), keeper, above


def leave():
    os._exit(7)


def folders():
    """Where this process writes temporary files and compiled kernels."""
    import tempfile

    from torch._inductor.runtime.cache_dir_utils import cache_dir

    return tempfile.gettempdir(), cache_dir(), os.environ.get("TRITON_CACHE_DIR", "")
'''


@pytest.fixture
def forked(tmp_path, monkeypatch):
    """Workers of this test forked from a fresh zygote."""
    monkeypatch.delenv("RTCOURSE_ZYGOTE", raising=False)
    monkeypatch.setattr(zygote, "_zygote", None)
    monkeypatch.setattr(zygote, "_enabled", False)
    zygote.enable()
    (tmp_path / "lab9_fork.py").write_text(LAB)
    workers = []

    def lab():
        worker = sandbox.Worker(str(tmp_path), memory_bytes=2**30)
        workers.append(worker)
        return sandbox.SandboxedLab("lab9_fork", worker, 60.0)

    yield lab
    for worker in workers:
        worker.stop()
    tmp = zygote._zygote.tmp
    zygote._zygote.close()
    assert not os.path.exists(tmp), "the zygote's folder goes with it"


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    with open(f"/proc/{pid}/stat") as f:
        return f.read().rsplit(")", 1)[1].split()[0] != "Z"


def test_forked_worker_answers_as_a_fresh_one(forked):
    lab = forked()
    x = torch.arange(5.0)
    assert torch.equal(lab.double(x), 2 * x)
    assert isinstance(lab._worker.proc, zygote.Spawned), "the worker came from the zygote"
    server, keeper, above = lab.family()
    assert keeper == lab._worker.proc.pid and above == zygote._zygote.proc.pid, (
        "server -> keeper -> zygote"
    )
    assert os.getpgid(keeper) == keeper, "the keeper leads its own session, as a fresh one"
    workdir = lab._worker.workdir
    tmp, inductor, triton = lab.folders()
    # Inductor's cache: the worker's own folder, never the zygote's or the grader's (torch
    # names one in this process's environment once it has used inductor), which every
    # student's worker would share.
    want = workdir + os.sep
    assert tmp == workdir and inductor.startswith(want) and triton.startswith(want), (
        f"temporary files in the worker's own folder {workdir} and inductor's and Triton's "
        f"caches under it, not the zygote's {zygote._zygote.tmp}: got {tmp}, {inductor}, "
        f"{triton}"
    )


def test_the_submission_cannot_reach_the_zygote(forked):
    lab = forked()
    lab.double(torch.ones(2))
    zpid = zygote._zygote.proc.pid
    theirs = {os.readlink(f"/proc/{zpid}/fd/{n}") for n in os.listdir(f"/proc/{zpid}/fd")}
    sockets = {link for link in theirs if link.startswith("socket:")}
    held = set(lab.descriptors().values())
    assert sockets and not (held & sockets), (
        f"the submission's process holds the zygote's sockets {held & sockets}"
    )


def test_stop_leaves_nothing_and_a_crash_has_its_code(forked):
    lab = forked()
    server, keeper, _ = lab.family()
    lab._worker.stop()
    deadline = time.monotonic() + 5
    while (_alive(server) or _alive(keeper)) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not _alive(server) and not _alive(keeper), "stop() ends the keeper and its server"
    with pytest.raises(sandbox.WorkerCrashed, match="exit code 7"):
        lab.leave()
    assert torch.equal(lab.double(torch.ones(2)), torch.full((2,), 2.0)), "and starts afresh"


def test_a_dead_zygote_is_replaced(forked):
    lab = forked()
    first = zygote._zygote.proc.pid
    lab.double(torch.ones(1))
    os.kill(first, signal.SIGKILL)
    zygote._zygote.proc.wait()
    # The keeper it forked dies with it (its parent-death signal); the next call starts a
    # worker from a new zygote.
    lab = forked()
    assert torch.equal(lab.double(torch.ones(1)), torch.full((1,), 2.0))
    assert zygote._zygote.proc.pid != first
    assert isinstance(lab._worker.proc, zygote.Spawned)
