"""A pre-imported process that starts sandbox workers by forking: grading a class pays for
Python, torch and ``torch._dynamo`` once per grading process, not once per student.

A sandbox worker (:mod:`course.grading.worker`) is normally a fresh ``python -m
course.grading.worker`` (:class:`course.grading.sandbox.Worker`): about two CPU seconds of
imports before the first call, for every submission. A grading process that grades many
submissions (``rtcourse grade-class``'s warm processes) calls :func:`enable` once; from then
on each worker is forked from this *zygote*, a process that imported what the worker's
keeper imports and has never run anything else: no submission, no test, no CUDA. The fork
is the worker's keeper, exactly as if started afresh: its own session, working folder,
environment and standard input, only the two sockets the grader gave it open, and the
grader's rights until its children drop them (the zygote runs as the grader does).

The grader talks to the zygote over a Unix socket: a spawn request (the worker's
arguments, working folder and environment, with the two socket ends passed as file
descriptors) is answered with a pidfd of the forked keeper, which :class:`Spawned` wraps
as the ``subprocess.Popen`` subset the sandbox uses (``pid``, ``poll``, ``wait``,
``terminate``, ``kill``); the keeper's exit status is asked of the zygote, which reaped it.
The zygote dies with the grading process (the parent-death signal), and its keepers with
it. Linux only (pidfds); elsewhere, or if the zygote cannot start, workers start afresh.

``RTCOURSE_ZYGOTE=1`` enables it for a one-off ``rtcourse grade`` too (the hostile
submissions' tests run that way as well as without); ``RTCOURSE_ZYGOTE=0`` disables it.
A zygote outlives the students it served: with a worker user (the autograder as root) no
submission can reach it; without one (an instructor's own machine), a submission runs as
the grading process's user and could already tamper with that process itself.
"""

from __future__ import annotations

import json
import os
import select
import shutil
import signal
import socket
import subprocess
import sys
import tempfile

_MAX_MESSAGE = 1 << 20
_PR_SET_PDEATHSIG = 1
_zygote: Zygote | None = None
_enabled = False


def supported() -> bool:
    return sys.platform.startswith("linux") and hasattr(os, "pidfd_open")


def enable():
    """Start workers of this process from a zygote from now on (where :func:`supported`,
    and unless ``RTCOURSE_ZYGOTE=0``); the zygote itself starts now, in the background, so
    its imports overlap the caller's."""
    global _enabled
    _enabled = supported() and os.environ.get("RTCOURSE_ZYGOTE") != "0"
    if _enabled:
        _get()


def _get() -> Zygote | None:
    global _zygote, _enabled
    if not _enabled:
        return None
    if _zygote is None or not _zygote.alive():
        try:
            _zygote = Zygote()
        except OSError:
            _enabled = False  # no zygote on this machine: workers start afresh
            _zygote = None
    return _zygote


def spawn(argv: list[str], fds: tuple[int, int], cwd: str, env: dict) -> Spawned | None:
    """The keeper ``python -m course.grading.worker ARGV`` would be, forked from the
    zygote with the sockets ``fds`` (the first two arguments), or None when workers of this
    process start afresh (the caller then starts one with ``subprocess``)."""
    zygote = _get()
    if zygote is None:
        return None
    try:
        return zygote.spawn(argv, fds, cwd, env)
    except (OSError, ValueError, EOFError):
        zygote.close()
        return None


class Zygote:
    """The grader's end: starts the zygote process and asks it for keepers."""

    def __init__(self):
        ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        from course.grading.worker_user import worker_env

        # Its own temporary folder: importing torch._dynamo makes inductor's cache folder
        # there, which no keeper uses (each reads TMPDIR again: its own worker folder).
        self.tmp = tempfile.mkdtemp(prefix="rtcourse-zygote-")
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "course.grading.zygote", str(theirs.fileno())],
            pass_fds=(theirs.fileno(),),
            stdin=subprocess.DEVNULL,
            env=dict(
                worker_env(),
                PYTHONUNBUFFERED="1",
                PYTORCH_NVML_BASED_CUDA_CHECK="1",
                TMPDIR=self.tmp,
            ),
            cwd=self.tmp,
            start_new_session=True,
        )
        theirs.close()
        self.sock = ours

    def alive(self) -> bool:
        return self.sock is not None and self.proc.poll() is None

    def close(self):
        if self.sock is not None:
            self.sock.close()
            self.sock = None
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()
        shutil.rmtree(self.tmp, ignore_errors=True)

    def _ask(self, request: dict, fds=()) -> tuple[dict, list[int]]:
        data = json.dumps(request).encode()
        socket.send_fds(self.sock, [data], list(fds))
        reply, got, _, _ = socket.recv_fds(self.sock, _MAX_MESSAGE, 1)
        if not reply:
            raise EOFError("the zygote ended")
        return json.loads(reply), got

    def spawn(self, argv, fds, cwd, env) -> Spawned:
        reply, got = self._ask({"spawn": list(argv), "cwd": cwd, "env": env}, fds)
        if "error" in reply or not got:
            for fd in got:
                os.close(fd)
            raise OSError(f"the zygote could not start a worker: {reply.get('error')}")
        return Spawned(self, reply["pid"], got[0])

    def status(self, pid: int) -> int:
        return self._ask({"status": pid})[0]["code"]


class Spawned:
    """A keeper forked by the zygote, seen as the part of ``subprocess.Popen`` the sandbox
    uses. ``pidfd``: readable once the process has ended (not reused like a pid)."""

    def __init__(self, zygote: Zygote, pid: int, pidfd: int):
        self.zygote, self.pid, self.pidfd = zygote, pid, pidfd
        self.returncode: int | None = None

    def _ended(self, timeout: float) -> bool:
        return bool(select.select([self.pidfd], [], [], timeout)[0])

    def poll(self) -> int | None:
        if self.returncode is None and self._ended(0):
            self._collect()
        return self.returncode

    def wait(self, timeout: float | None = None) -> int:
        if self.returncode is None:
            if not self._ended(timeout if timeout is not None else None):
                raise subprocess.TimeoutExpired(f"worker {self.pid}", timeout)
            self._collect()
        return self.returncode

    def _collect(self):
        try:
            self.returncode = self.zygote.status(self.pid)
        except (OSError, EOFError, ValueError, KeyError):
            self.returncode = -signal.SIGKILL  # the zygote went with it: killed
        os.close(self.pidfd)

    def _signal(self, sig):
        if self.returncode is None:
            try:
                signal.pidfd_send_signal(self.pidfd, sig)
            except ProcessLookupError:
                pass

    def terminate(self):
        self._signal(signal.SIGTERM)

    def kill(self):
        self._signal(signal.SIGKILL)


# ---------------------------------------------------------------- the zygote process


def _keep_only(fds: set[int]):
    """Close every descriptor but ``fds``: the keeper must not reach the zygote's socket."""
    for name in os.listdir("/proc/self/fd"):
        fd = int(name)
        if fd not in fds:
            try:
                os.close(fd)
            except OSError:
                pass  # the listing's own descriptor, already closed


def _keeper(request: dict, received: list[int]):
    """In the fork: become the keeper ``python -m course.grading.worker`` would start."""
    argv = list(request["spawn"])
    argv[:2] = map(str, received)  # the sockets' numbers here, not in the grader
    _keep_only({0, 1, 2, *received})
    os.setsid()
    os.chdir(request["cwd"])
    os.environ.clear()
    os.environ.update(request["env"])
    tempfile.tempdir = None  # read TMPDIR again: the worker's own folder
    signal.signal(signal.SIGTERM, signal.SIG_DFL)  # the worker sets its own
    from course.grading.worker import main

    main(argv)


def _prepare():
    """Import what a keeper imports before it forks its server and probes."""
    import torch._dynamo  # noqa: F401  (see worker.main: probes start with it in place)

    from course.grading import (
        wire,  # noqa: F401  (torch)
        worker,  # noqa: F401
    )
    from course.grading.worker import _prctl

    _prctl(_PR_SET_PDEATHSIG, signal.SIGTERM)


def main(argv):
    sock = socket.socket(fileno=int(argv[0]))
    zygote = os.getpid()

    def end(*_):  # the grading process ended or dropped us: our folder goes too
        if os.getpid() == zygote:
            shutil.rmtree(os.environ.get("TMPDIR", ""), ignore_errors=True)
        os._exit(0)

    signal.signal(signal.SIGTERM, end)
    _prepare()
    while True:
        try:
            data, fds, _, _ = socket.recv_fds(sock, _MAX_MESSAGE, 2)
        except OSError:
            end()
        if not data:
            end()
        request = json.loads(data)
        if "status" in request:
            try:
                _, status = os.waitpid(int(request["status"]), 0)
                code = os.waitstatus_to_exitcode(status)
            except ChildProcessError:
                code = -signal.SIGKILL
            socket.send_fds(sock, [json.dumps({"code": code}).encode()], [])
            continue
        pid = os.fork()
        if pid == 0:
            sock.close()
            try:
                _keeper(request, fds)
            finally:
                os._exit(0)
        for fd in fds:
            os.close(fd)
        pidfd = os.pidfd_open(pid)
        socket.send_fds(sock, [json.dumps({"pid": pid}).encode()], [pidfd])
        os.close(pidfd)


if __name__ == "__main__":
    main(sys.argv[1:])
