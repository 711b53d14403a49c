"""The grader's side of the sandbox: a lab module that lives in another process.

``SandboxedLab`` looks like the lab module: ``lab.pack_rgba8(x)`` sends the call
to a warm worker process (:mod:`course.grading.worker`), waits for it under the
current time limit while watching its memory, and rebuilds the result as plain
tensors. A crash, ``os._exit``, a hang or a memory blow-up costs the current call
(an exception in the test) and the worker is restarted for the next one.

``LocalLab`` gives the trusted reference solutions the same interface in-process,
with the same input-mutation check, so tests read the same either way.

With ``RTCOURSE_WORKER_USER`` set (the Gradescope autograder sets it when it runs as root)
the worker runs as that unprivileged user, so a submission cannot read what only the
grader may (the reference solutions shipped in the autograder) or touch the results.
"""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import time
from multiprocessing.connection import Connection

import torch

from course.grading import wire
from course.grading.worker import call_checked, is_output_name, parameter_names


class WorkerCrashed(RuntimeError):
    """The submission ended or broke the worker process."""


class TimeLimitExceeded(TimeoutError):
    """A call ran past the test's time limit; the worker was killed."""


class MemoryLimitExceeded(MemoryError):
    """A call used more memory than allowed; the worker was killed."""


def _raise_student_error(err: dict, where: str):
    """Re-raise a submission's exception as the closest builtin exception type,
    so ``pytest.raises(ValueError)`` works across the process boundary."""
    __tracebackhide__ = True  # a student's failure report shows their call, not the sandbox
    import builtins

    text = f"{err['type']}: {err['message']}" if err["type"] not in (
        "NotImplementedError",) else err["message"]
    for name in err["kinds"]:
        cls = getattr(builtins, name, None)
        if isinstance(cls, type) and issubclass(cls, Exception) and cls is not Exception:
            if cls is NotImplementedError:
                raise NotImplementedError(err["message"])
            raise cls(f"{text}\n(raised in {where}; traceback from the worker:)\n"
                      f"{err['traceback']}")
    raise RuntimeError(f"{text}\n(raised in {where})\n{err['traceback']}")


def _check_written(written_names, where):
    bad = [n for n in written_names if not is_output_name(n)]
    if bad:
        raise AssertionError(
            f"{where} modified its input argument(s) {', '.join(map(repr, bad))}. Kernels must "
            f"leave their inputs untouched (only an `out` argument may be written): a caller "
            f"that reuses the input would silently get wrong results."
        )


def _copy_back(target: torch.Tensor, value: torch.Tensor):
    with torch.no_grad():
        target.copy_(value.to(target.device))


def _as_user(name: str | None) -> dict:
    """``Popen`` arguments that start the worker as user ``name`` (none when unset)."""
    if not name:
        return {}
    import pwd

    try:
        entry = pwd.getpwnam(name)
    except KeyError:
        raise RuntimeError(f"RTCOURSE_WORKER_USER={name}: no such user") from None
    if os.geteuid() != 0:
        raise RuntimeError(f"RTCOURSE_WORKER_USER={name}: only a grader running as root can "
                           f"start the worker as another user")
    return {"user": entry.pw_uid, "group": entry.pw_gid, "extra_groups": []}


class Worker:
    """One worker process serving every lab file of a submission folder, restarted after a
    failure.

    One process for all labs: Python, torch and whatever the labs import (``torch._dynamo``
    for the op counter and ``torch.compile``, Triton) are imported once per submission, not
    once per lab; that import is most of what isolation costs. The labs of one submission
    share the process, so a lab that ends it (``os._exit``, a crash) costs the others a
    restart, never points: each request names its lab, whose module is imported again in
    the fresh process.
    """

    def __init__(self, folder: str, *, memory_bytes: int, startup_timeout: float = 60.0):
        self.folder = folder
        self.memory_bytes = memory_bytes
        self.startup_timeout = startup_timeout
        self.proc = None
        self.conn = None
        self.starting = False
        self.output: list[str] = []  # what the submission printed, since the last take

    # -- process management
    def launch(self):
        """Start the worker process without waiting for it: starting Python and torch
        overlaps with whatever the grader does next."""
        as_user = _as_user(os.environ.get("RTCOURSE_WORKER_USER"))
        parent, child = socket.socketpair()
        env = dict(os.environ, PYTHONUNBUFFERED="1")
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "course.grading.worker", str(child.fileno()),
             self.folder, str(self.memory_bytes)],
            pass_fds=(child.fileno(),), stdin=subprocess.DEVNULL, env=env,
            **as_user,
        )
        child.close()
        self.conn = Connection(parent.detach())
        self.starting = True

    def _await_ready(self, deadline):
        reply = self._receive(deadline, "starting the worker")
        self.starting = False
        self.output.append(reply.get("output", ""))

    def stop(self):
        if self.proc is not None:
            if self.proc.poll() is None:
                self.proc.kill()
            self.proc.wait()
        if self.conn is not None:
            self.conn.close()
        self.proc = self.conn = None
        self.starting = False

    def take_output(self) -> str:
        text = "".join(self.output)
        self.output.clear()
        return text

    # -- requests
    def request(self, message: dict, deadline: float, where: str) -> dict:
        if self.proc is None or self.proc.poll() is not None:
            self.stop()
            self.launch()
        if self.starting:
            # Starting Python and torch is the grader's cost, not the test's.
            self._await_ready(max(deadline, time.monotonic() + self.startup_timeout))
        self.conn.send_bytes(wire.dumps(message))
        reply = self._receive(deadline, where)
        self.output.append(reply.get("output", ""))
        return reply

    def _resident_bytes(self) -> int:
        try:
            with open(f"/proc/{self.proc.pid}/statm") as f:
                return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
        except (OSError, IndexError, ValueError):
            return 0

    def _ready(self) -> bool:
        try:
            return self.conn.poll(0.02)
        except (EOFError, OSError):
            return True  # the next receive reports the crash

    def _crashed(self, where: str):
        try:
            code = self.proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            code = "unknown"
        self.stop()
        raise WorkerCrashed(
            f"the submission ended the worker process (exit code {code}) during {where}: "
            f"sys.exit/os._exit or a crash in native code ends the grading of that call")

    def _receive(self, deadline: float, where: str) -> dict:
        while not self._ready():
            if self.proc.poll() is not None:
                self._crashed(where)
            if self.memory_bytes > 0 and self._resident_bytes() > self.memory_bytes + 2**30:
                self.stop()
                raise MemoryLimitExceeded(
                    f"{where} used more than {self.memory_bytes / 2**30:.1f} GiB of memory "
                    f"and was stopped")
            if time.monotonic() > deadline:
                self.stop()
                raise TimeLimitExceeded(f"{where} did not finish within the time limit and "
                                        f"was stopped (an infinite loop?)")
        try:
            reply = wire.loads_plain(self.conn.recv_bytes())
        except (EOFError, OSError):
            self._crashed(where)
        except Exception as exc:  # a reply that is not plain data: a hostile submission
            self.stop()
            raise WorkerCrashed(f"the worker sent a malformed reply during {where}: {exc}") \
                from exc
        if not isinstance(reply, dict):
            self.stop()
            raise WorkerCrashed(f"the worker sent a malformed reply during {where}")
        return reply


class SandboxedLab:
    """A lab module running in a :class:`Worker`; attribute access mirrors the module."""

    def __init__(self, name: str, worker: Worker, time_limit: float):
        self._name = name
        self._worker = worker
        self._time_limit = time_limit
        self._deadline = None
        self._callable_cache: dict = {}

    # The grading plugin resets the clock at the start of every test.
    def _start_clock(self, time_limit=None):
        self._deadline = time.monotonic() + (time_limit or self._time_limit)

    def _remaining_deadline(self):
        return self._deadline or time.monotonic() + self._time_limit

    def _request(self, message, where):
        __tracebackhide__ = True
        message["lab"] = self._name
        reply = self._worker.request(message, self._remaining_deadline(), where)
        if "error" in reply:
            _raise_student_error(reply["error"], where)
        return reply

    def _decode(self, value):
        return wire.decode(value, make_ref=lambda i, t: RemoteObject(self, i, t))

    def _getattr(self, ref, name, where):
        key = (ref, name)
        if key in self._callable_cache:
            return self._callable_cache[key]
        reply = self._request({"op": "getattr", "ref": ref, "name": name}, where)
        if reply.get("callable"):
            method = RemoteCallable(self, ref, name, where)
            self._callable_cache[key] = method
            return method
        return self._decode(reply["value"])

    def __getattr__(self, name):
        if name.startswith("_"):
            raise AttributeError(name)
        return self._getattr(None, name, f"{self._name}.{name}")

    def probe(self, fn, *args, **kwargs):
        """Run ``fn(lab_module, *args)`` next to the submission; return its plain result."""
        where = f"probe {fn.__name__} of {self._name}"
        reply = self._request({"op": "probe", "probe": wire.encode(fn), "ref": None,
                               "args": wire.encode(args), "kwargs": wire.encode(kwargs)}, where)
        return self._decode(reply["value"])

    def __repr__(self):
        return f"<sandboxed lab {self._name} from {self._worker.folder}>"


class RemoteCallable:
    def __init__(self, lab: SandboxedLab, ref, name, where):
        self._lab, self._ref, self._name, self._where = lab, ref, name, where

    def __call__(self, *args, **kwargs):
        __tracebackhide__ = True
        reply = self._lab._request(
            {"op": "call", "ref": self._ref, "name": self._name,
             "args": wire.encode(args), "kwargs": wire.encode(kwargs)}, self._where)
        written = reply.get("written", {})
        _check_written(written, self._where)
        for name, (pos, value) in written.items():
            target = kwargs.get(name) if pos is None else args[pos]
            if isinstance(target, torch.Tensor):
                _copy_back(target, self._lab._decode(value))
        return self._lab._decode(reply["value"])


class RemoteObject:
    """An object that stays in the worker (e.g. an instance of a class the lab defines)."""

    def __init__(self, lab: SandboxedLab, ref_id: int, type_name: str):
        self._lab, self._ref, self._type = lab, ref_id, type_name

    def __getattr__(self, name):
        if name.startswith("_"):
            raise AttributeError(name)
        return self._lab._getattr(self._ref, name, f"{self._type}.{name}")

    def __repr__(self):
        return f"<{self._type} in the sandboxed worker>"


class LocalLab:
    """A trusted lab module, called in-process with the same checks as the sandbox."""

    def __init__(self, name: str, module):
        self._name = name
        self._module = module

    def _start_clock(self, time_limit=None):
        pass

    def __getattr__(self, name):
        if name.startswith("_"):
            raise AttributeError(name)
        value = getattr(self._module, name)
        if callable(value) and not isinstance(value, type):
            return _checked(value, f"{self._name}.{name}")
        return value

    def probe(self, fn, *args, **kwargs):
        return fn(self._module, *args, **kwargs)

    def __repr__(self):
        return f"<lab {self._name} from {self._module.__file__}>"


def _checked(fn, where):
    def call(*args, **kwargs):
        result, written = call_checked(fn, args, kwargs, parameter_names(fn, len(args)))
        _check_written(written, where)
        return result

    call.__name__ = getattr(fn, "__name__", "call")
    call.__doc__ = fn.__doc__
    return call
