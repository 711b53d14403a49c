"""The grader's side of the sandbox: a lab module that lives in another process.

``SandboxedLab`` looks like the lab module: ``lab.pack_rgba8(x)`` sends the call
to a warm worker process (:mod:`course.grading.worker`), waits for it under the
current time limit while watching the memory of the worker and of everything it started,
and rebuilds the result as plain tensors. A crash, ``os._exit``, a hang or a memory
blow-up costs the current call (an exception in the test) and the worker is restarted
for the next one.

What a grading run may cost is bounded whatever the submission does:

* **time**: a call that ran out of time is not run again in that run (its later calls
  fail at once with the same message), and each lab has a budget: what its tests run past
  their first ``RTCOURSE_SLOW_TEST`` seconds (default 10) adds up to at most
  ``RTCOURSE_LAB_TIME_BUDGET`` (default 100), and all the submission's code in the lab to
  at most ``RTCOURSE_LAB_TIME_CAP`` (default 600); after either every call fails at once.
  Honest tests take seconds, so they never count; a lab whose every function hangs, or
  sleeps just under the per-test limit, ends after its first timeout (120 s at the
  default limit: 110 s past the first 10 use the budget up);
* **memory**: a reply is at most ``RTCOURSE_REPLY_MB`` (default 256) MB, checked before
  it is read, and decodes to no more; a bigger one fails its test. The worker's tree
  (the submission's children included) shares one memory limit;
* **leftovers**: the worker works in a temporary folder removed when it stops, and every
  process the submission started is killed with it.

Which arguments a kernel may write (``out``, ``*_out``) is read from the reference's
signature (``solutions/`` where it exists, else the skeleton in ``labs/``), never from
the submission's. Text that comes from the worker (errors, what the submission printed)
is cleaned of any line of the hidden graders' source before a student sees it.

``LocalLab`` gives the trusted reference solutions the same interface in-process,
with the same input-mutation check, so tests read the same either way.

With ``RTCOURSE_WORKER_USER`` set (the Gradescope autograder sets it when it runs as root)
the submission runs as that unprivileged user, so it cannot read what only the
grader may (the reference solutions shipped in the autograder) or touch the results.

Threat model
------------
The submission is a student who has read this grader's source (it is open) and whose code
runs, with every right of its own process, in the worker's server and in each probe's
process: it can patch any Python object there, read that process's memory, find and write
its file descriptors, start processes and exit at will. It cannot run code in the
grader's process (this one) or in the worker's keeper, which never import it. So:

* **Verdicts are decided here.** What comes back from the submission's processes is data
  (tensors, numbers, strings, pointers) rebuilt by :mod:`course.grading.wire`, which admits
  no class; every comparison with a reference and every pass or fail is made by the test in
  this process, against inputs and references this process holds. A probe
  (``impl.probe(fn, ...)``) returns what it observed (addresses, values read back, copies
  of frames), never a boolean the test would trust.
* **A reply written by the submission is refused.** Each probe request carries a fresh
  random nonce; the keeper takes it out of the request before the probe's process is
  started, and that process's trusted code adds it to the reply after the probe returned.
  A reply written on the probe's pipe by the submission's code (the "passed" report of a
  forger) does not carry it and fails its test. What this cannot stop: the nonce lives
  in the probe's process while the submission runs there, so a submission that searches
  its own process's memory for it, and fabricates the observations themselves (two equal
  addresses, the values a view would read back), can still pass a probe that watches
  identity rather than values. No check made inside a process the submission controls can
  rule that out; such code is in the submission, for a person to read, and a probe that
  returns values (a frame, a packed word) gains it nothing: the grader compares them with
  its own reference.
* **Hidden graders and results are out of reach.** A probe's function and arguments are
  loaded by the probe's process while it still has the grader's rights, before it drops to
  ``RTCOURSE_WORKER_USER`` and imports the submission; as root the grader withholds
  ``tests/hidden/`` and ``solutions/`` from other users (``worker_user.withhold``), and the
  autograder its results folder. The worker's environment holds no path of the grader's
  (``worker_user.SCRUBBED``). Without a worker user (a student's own ``rtcourse grade``) there is
  nothing to hide: the student owns every file. Hidden lines are still removed from any
  text the worker sends back (:class:`course.grading.sources.Redactor`), a second line of
  defence, not the first.
* **The worker's interpreter must run as the worker user.** ``worker_user.worker_python_problem``
  checks, before grading, that ``RTCOURSE_WORKER_USER`` can run this Python and import the
  standard library and the course's dependencies; otherwise grading stops with one line
  (a missing module would otherwise be scored as the student's failure).
"""

from __future__ import annotations

import os
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from multiprocessing.connection import Connection

from course.grading import wire, zygote
from course.grading.input_check import LocalLab as LocalLab  # the trusted lab, re-exported
from course.grading.input_check import too_large_message
from course.grading.proctree import memory_room, tree_bytes
from course.grading.remote import RemoteCallable, RemoteObject
from course.grading.sandbox_errors import (
    ForgedReply as ForgedReply,
)
from course.grading.sandbox_errors import (
    MemoryLimitExceeded as MemoryLimitExceeded,
)
from course.grading.sandbox_errors import (
    ReplyTooLarge as ReplyTooLarge,
)
from course.grading.sandbox_errors import (
    TimeBudgetExceeded as TimeBudgetExceeded,
)
from course.grading.sandbox_errors import (
    TimeLimitExceeded as TimeLimitExceeded,
)
from course.grading.sandbox_errors import (  # re-exported: the grader catches them from here
    WorkerCrashed as WorkerCrashed,
)
from course.grading.sandbox_errors import (
    _raise_student_error,
)
from course.grading.sources import Redactor, reference_file, reference_signatures
from course.grading.worker_user import _as_user, withhold, worker_env
from course.grading.worker_user import main as check_worker
from course.grading.worker_user import worker_python_problem as worker_python_problem

DEFAULT_LAB_TIME_BUDGET = 100.0  # seconds per lab of what tests run past SLOW_TEST
DEFAULT_SLOW_TEST = 10.0  # seconds of a test's submitted code that never count
DEFAULT_LAB_TIME_CAP = 600.0  # seconds of submitted code per lab, all counted
DEFAULT_REPLY_MB = 256.0
_MEMORY_POLL = 0.2  # seconds between looks at the worker tree's memory
BUDGET_MESSAGE = (
    "the time budget of the lab used up: {why}, so {where} was not run (a "
    "hang or a slow loop in an earlier test?)"
)
BUDGET_STOP_MESSAGE = (
    "the time budget of the lab used up while {where} ran, and it was "
    "stopped: {why} (a hang or a slow loop?)"
)


def _env_float(name, default):
    value = os.environ.get(name)
    return float(value) if value else default


# The worker tree's own Python and torch, before the submission allocates anything.
BASELINE_BYTES = 2**30
# What the grader keeps for itself out of the container's free memory, and the least
# limit a worker gets (below it, the kernel's out-of-memory killer decides: it takes the
# worker's processes first, see the worker's oom_score_adj).
GRADER_RESERVE, MIN_TREE_BYTES = 128 * 2**20, 512 * 2**20


class Worker:
    """One worker serving every lab file of a submission folder, restarted after a failure.

    One process tree for all labs: Python, torch and whatever the labs import are imported
    once per submission, not once per lab; that import is most of what isolation costs.
    The labs of one submission share the server process, so a lab that ends it
    (``os._exit``, a crash) costs the others a restart, never points: each request names
    its lab, whose module is imported again in the fresh process.
    """

    def __init__(
        self,
        folder: str,
        *,
        memory_bytes: int,
        startup_timeout: float = 60.0,
        reply_bytes: int | None = None,
    ):
        self.folder = folder
        self.memory_bytes = memory_bytes
        # The whole tree's limit: the extra memory asked for on top of the baseline, but no
        # more than the container has free (less the grader's reserve).
        room = memory_room()
        self.tree_limit = memory_bytes + BASELINE_BYTES
        if room is not None:
            self.tree_limit = min(self.tree_limit, max(room - GRADER_RESERVE, MIN_TREE_BYTES))
        self.reply_bytes = int(
            reply_bytes or _env_float("RTCOURSE_REPLY_MB", DEFAULT_REPLY_MB) * 2**20
        )
        self.startup_timeout = startup_timeout
        self.proc = None
        self.conn = None  # to the server: calls
        self.control = None  # to the keeper: probes
        self.workdir = None
        self.starting = False
        self.redact = Redactor()
        self.last_seconds = 0.0  # how long the last request ran, start-up excluded
        self.startup_seconds = 0.0  # waited for the worker to start, since the last take
        self.output: list[str] = []  # what the submission printed, since the last take

    # -- process management
    def launch(self):
        """Start the worker without waiting for it: starting Python and torch overlaps
        with whatever the grader does next."""
        user = _as_user(os.environ.get("RTCOURSE_WORKER_USER"))
        self.workdir = tempfile.mkdtemp(prefix="rtcourse-worker-")
        if user:
            os.chown(self.workdir, *user)
        ctl_parent, ctl_child = socket.socketpair()
        data_parent, data_child = socket.socketpair()
        # Compiled kernels in the worker's own folder, never in a cache the grader's
        # environment names (torch sets TORCHINDUCTOR_CACHE_DIR there once the grader has
        # used inductor): a submission must not plant artefacts another student's worker
        # loads, and a worker user could not write to the grader's cache anyway.
        env = dict(
            worker_env(),
            PYTHONUNBUFFERED="1",
            TMPDIR=self.workdir,
            TORCHINDUCTOR_CACHE_DIR=os.path.join(self.workdir, "inductor"),
            TRITON_CACHE_DIR=os.path.join(self.workdir, "triton"),
            PYTORCH_NVML_BASED_CUDA_CHECK="1",
        )
        fds = (ctl_child.fileno(), data_child.fileno())
        argv = [
            *map(str, fds),
            self.folder,
            str(self.memory_bytes),
            str(self.reply_bytes),
            *map(str, user or ()),
        ]
        # Forked from a pre-imported zygote where this process enabled one (grading a
        # class), else a fresh interpreter.
        self.proc = zygote.spawn(argv, fds, self.workdir, env) or subprocess.Popen(
            [sys.executable, "-m", "course.grading.worker", *argv],
            pass_fds=fds,
            stdin=subprocess.DEVNULL,
            env=env,
            cwd=self.workdir,
            start_new_session=True,
        )
        ctl_child.close()
        data_child.close()
        self.control = Connection(ctl_parent.detach())
        self.conn = Connection(data_parent.detach())
        self.starting = True

    def _await_ready(self, deadline):
        reply = self._receive(self.conn, deadline, "starting the worker")
        self.starting = False
        self._keep_output(reply)

    def stop(self):
        """End the worker, everything the submission started, and its folder."""
        for conn in (self.conn, self.control):
            if conn is not None:
                conn.close()
        if self.proc is not None:
            if self.proc.poll() is None:
                self.proc.terminate()  # the keeper kills its tree, then itself
                try:
                    self.proc.wait(timeout=5)
                except subprocess.TimeoutExpired:
                    self.proc.kill()
                    self.proc.wait()
            try:
                os.killpg(self.proc.pid, signal.SIGKILL)  # the rest of its process group
            except OSError:
                pass
        if self.workdir is not None:
            shutil.rmtree(self.workdir, ignore_errors=True)
        self.proc = self.conn = self.control = self.workdir = None
        self.starting = False

    def take_output(self) -> str:
        text = "".join(self.output)
        self.output.clear()
        return self.redact(text)

    def _keep_output(self, reply):
        text = reply.get("output", "")
        if isinstance(text, str):
            self.output.append(text[:8000])

    # -- requests
    def request(self, message: dict, seconds: float, where: str, probe=False) -> dict:
        """Send a call (to the server) or a probe (to the keeper, which runs it in a fresh
        process) and wait ``seconds`` for the reply, counted once the worker is ready."""
        if self.proc is None or self.proc.poll() is not None or self._stale():
            self.stop()
            self.launch()
        if self.starting:
            # Starting Python and torch is the grader's cost, not the test's.
            began = time.monotonic()
            self._await_ready(began + self.startup_timeout)
            self.startup_seconds += time.monotonic() - began
        message["where"] = where
        conn = self.control if probe else self.conn
        started = time.monotonic()
        deadline = started + seconds
        try:
            conn.send_bytes(wire.dumps(message))
        except OSError:
            self._crashed(where)
        try:
            reply = self._receive(conn, deadline, where)
        finally:
            self.last_seconds = time.monotonic() - started
        if "crashed" in reply:
            raise WorkerCrashed(
                f"the submission ended the process of {where} (exit code {reply['crashed']}): "
                f"sys.exit/os._exit or a crash in native code ends the grading of that call"
            )
        self._keep_output(reply)
        return reply

    def _stale(self) -> bool:
        """Between requests the server has nothing to say: if its socket reads (it ended
        after its last reply, or sent more than one), it starts afresh."""
        if self.starting:
            return False
        try:
            return self.conn.poll(0)
        except (EOFError, OSError):
            return True

    def _tree_bytes(self) -> int:
        """Memory of every process below the keeper: the server, a probe, and whatever
        the submission started (orphans are reparented to the keeper)."""
        return tree_bytes(self.proc.pid)

    def _ready(self, conn) -> bool:
        try:
            return conn.poll(0.02)
        except (EOFError, OSError):
            return True  # the next receive reports the crash

    def _crashed(self, where: str):
        try:
            code = self.proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            code = "unknown"
        self.stop()
        if code == -signal.SIGKILL:
            raise WorkerCrashed(
                f"the worker process was killed (SIGKILL) during {where}: the machine ran "
                f"out of memory (the kernel ends the submission's processes first), or the "
                f"submission killed itself"
            )
        raise WorkerCrashed(
            f"the submission ended the worker process (exit code {code}) during {where}: "
            f"sys.exit/os._exit or a crash in native code ends the grading of that call"
        )

    def _receive(self, conn, deadline: float, where: str) -> dict:
        next_look = 0.0
        while not self._ready(conn):
            if self.proc.poll() is not None:
                self._crashed(where)
            now = time.monotonic()
            if self.memory_bytes > 0 and now >= next_look:
                next_look = now + _MEMORY_POLL
                if self._tree_bytes() > self.tree_limit:
                    self.stop()
                    raise MemoryLimitExceeded(
                        f"{where} used more than {self.tree_limit / 2**30:.2f} GiB of "
                        f"memory (the grader's limit on this machine) and was stopped"
                    )
            if now > deadline:
                self.stop()
                raise TimeLimitExceeded(
                    f"{where} did not finish within the time limit and "
                    f"was stopped (an infinite loop?)"
                )
        try:
            # The length comes first: a longer message is refused before it is read.
            data = conn.recv_bytes(self.reply_bytes + 2**20)
        except EOFError:
            self._crashed(where)
        except OSError as exc:
            if "bad message length" not in str(exc):
                self._crashed(where)
            self.stop()
            raise ReplyTooLarge(
                too_large_message(where, self.reply_bytes + 2**20, self.reply_bytes).replace(
                    "returned", "returned more than"
                )
            ) from None
        try:
            reply = wire.loads_plain(data)
        except Exception as exc:  # a reply that is not plain data: a hostile submission
            self.stop()
            raise WorkerCrashed(f"the worker sent a malformed reply during {where}: {exc}") from exc
        finally:
            del data
        if not isinstance(reply, dict):
            self.stop()
            raise WorkerCrashed(f"the worker sent a malformed reply during {where}")
        return reply


class SandboxedLab:
    """A lab module running in a :class:`Worker`; attribute access mirrors the module.

    ``root``: the course folder (its ``solutions/`` or ``labs/`` give the reference's
    signatures, its ``tests/hidden/`` the source no output may show).
    """

    def __init__(self, name: str, worker: Worker, time_limit: float, *, root=None):
        self._name = name
        self._worker = worker
        self._time_limit = time_limit
        self._deadline = None
        self._callable_cache: dict = {}
        self._budget = _env_float("RTCOURSE_LAB_TIME_BUDGET", DEFAULT_LAB_TIME_BUDGET)
        self._slow = _env_float("RTCOURSE_SLOW_TEST", DEFAULT_SLOW_TEST)
        self._cap = _env_float("RTCOURSE_LAB_TIME_CAP", DEFAULT_LAB_TIME_CAP)
        self._spent = 0.0  # submitted code's seconds in this lab
        self._slow_spent = 0.0  # of which past the first SLOW_TEST seconds of their test
        self._test_spent = 0.0  # in the current test
        self._timed_out: dict[str, str] = {}  # where -> the message it failed with
        self._signatures = reference_signatures(reference_file(root, name))
        withhold(root)  # before the worker starts: it may drop to another user
        if root is not None and not worker.redact.lines:
            worker.redact = Redactor(root)

    # The grading plugin resets the clock at the start of every test.
    def _start_clock(self, time_limit=None):
        self._deadline = time.monotonic() + (time_limit or self._time_limit)
        self._test_spent = 0.0

    def _remaining_deadline(self):
        return self._deadline or time.monotonic() + self._time_limit

    def _budget_left(self):
        """Seconds the next call may run before a budget is used up, and why it would be."""
        slow_left = self._budget - self._slow_spent
        if slow_left > 0:  # used up, it stays used up: no test's first seconds are free then
            slow_left += max(0.0, self._slow - self._test_spent)
        cap_left = self._cap - self._spent
        if slow_left <= cap_left:
            return slow_left, (
                f"the tests of this lab that ran longer than {self._slow:.0f} s "
                f"used up the {self._budget:.0f} s allowed past that"
            )
        return cap_left, f"the submission's code ran for {self._cap:.0f} s in this lab"

    def _request(self, message, where, probe=False):
        __tracebackhide__ = True
        if where in self._timed_out:  # it hung once: not again, same message
            raise TimeLimitExceeded(self._timed_out[where])
        left, why = self._budget_left()
        if left <= 0:
            raise TimeBudgetExceeded(BUDGET_MESSAGE.format(why=why, where=where))
        message["lab"] = self._name
        test_left = self._remaining_deadline() - time.monotonic()
        by_budget = left < test_left
        try:
            return self._worker.request(message, max(0.0, min(test_left, left)), where, probe=probe)
        except TimeLimitExceeded as exc:
            if by_budget:
                raise TimeBudgetExceeded(BUDGET_STOP_MESSAGE.format(why=why, where=where)) from None
            self._timed_out[where] = str(exc)
            raise
        finally:
            seconds = self._worker.last_seconds
            before = max(0.0, self._test_spent - self._slow)
            self._spent += seconds
            self._test_spent += seconds
            self._slow_spent += max(0.0, self._test_spent - self._slow) - before
            if self._deadline is not None:  # the test's clock stops while the worker starts
                self._deadline += self._worker.startup_seconds
            self._worker.last_seconds = self._worker.startup_seconds = 0.0

    def _fail(self, reply, where):
        __tracebackhide__ = True
        if "error" in reply:
            _raise_student_error(reply["error"], where, self._worker.redact)

    def _decode(self, value, where="the call"):
        try:
            return wire.decode(
                value,
                make_ref=lambda i, t: RemoteObject(self, i, t),
                limit=self._worker.reply_bytes,
            )
        except wire.TooLarge as exc:
            # The worker checks what it sends, so only a reply written past that check (a
            # hostile submission) decodes too large: its server may be ending right now, so
            # the next call starts a fresh one instead of racing its exit.
            self._worker.stop()
            raise ReplyTooLarge(f"{where}: {exc}, more than a result may hold") from None

    def _positional(self, key):
        """Positional parameter names of ``key`` in the reference (None: unknown)."""
        if self._signatures is None:
            return None
        return self._signatures.get(key, [])

    def _getattr(self, ref, name, where, key):
        cache = (ref, name)
        if cache in self._callable_cache:
            return self._callable_cache[cache]
        reply = self._request({"op": "getattr", "ref": ref, "name": name}, where)
        self._fail(reply, where)
        if reply.get("callable"):
            method = RemoteCallable(self, ref, name, where, key)
            self._callable_cache[cache] = method
            return method
        return self._decode(reply.get("value"), where)

    def __getattr__(self, name):
        if name.startswith("_"):
            raise AttributeError(name)
        return self._getattr(None, name, f"{self._name}.{name}", name)

    def probe(self, fn, *args, **kwargs):
        """Run ``fn(lab_module, *args)`` in a fresh process next to the submission; return
        its plain result."""
        where = f"probe {fn.__name__} of {self._name}"
        nonce = secrets.token_hex(16)
        reply = self._request(
            {
                "op": "probe",
                "probe": wire.encode(fn),
                "ref": None,
                "args": wire.encode(args),
                "kwargs": wire.encode(kwargs),
                "signatures": self._signatures,
                "nonce": nonce,
            },
            where,
            probe=True,
        )
        if not (
            isinstance(reply.get("nonce"), str) and secrets.compare_digest(reply["nonce"], nonce)
        ):
            raise ForgedReply(
                f"the reply to {where} did not come from the probe: the "
                f"submission wrote its own onto the probe's channel, so the "
                f"test fails"
            )
        self._fail(reply, where)
        return self._decode(reply.get("value"), where)

    def __repr__(self):
        return f"<sandboxed lab {self._name} from {self._worker.folder}>"


def main(argv=None) -> int:
    """``python -m course.grading.sandbox check-worker [USER]``: see
    :func:`course.grading.worker_user.main` (run_autograder runs it before grading)."""
    return check_worker(argv)


if __name__ == "__main__":
    sys.exit(main())
