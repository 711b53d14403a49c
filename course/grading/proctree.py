"""The processes below a pid, read from ``/proc`` (Linux): listing, memory, killing.

One home for what both sides of the sandbox need: the grader (:mod:`course.grading.sandbox`)
watches the memory of the worker's whole tree, and the worker's keeper
(:mod:`course.grading.worker`) kills and reaps whatever a submission started. Standard
library only: the keeper imports it before it forks.
"""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path


def children(pid) -> list[int]:
    """The pids whose parent is ``pid`` (every thread's children); [] when it is gone."""
    found = []
    try:
        tids = os.listdir(f"/proc/{pid}/task")
    except OSError:
        return found
    for tid in tids:
        try:
            with open(f"/proc/{pid}/task/{tid}/children") as f:
                found += [int(p) for p in f.read().split()]
        except OSError:
            pass
    return found


def tree(pid, limit: int = 10000) -> list[int]:
    """``pid`` and its descendants, parents first (at most ``limit``)."""
    out, todo = [], [pid]
    while todo and len(out) < limit:
        p = todo.pop()
        out.append(p)
        todo += children(p)
    return out


def process_bytes(pid) -> int:
    """Proportional resident size (shared pages split between their users), else RSS."""
    try:
        with open(f"/proc/{pid}/smaps_rollup") as f:
            for line in f:
                if line.startswith("Pss:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        with open(f"/proc/{pid}/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, IndexError, ValueError):
        return 0


def tree_bytes(pid, limit: int = 4096) -> int:
    """Memory (:func:`process_bytes`) of every process below ``pid``, ``pid`` itself not
    counted, looking at no more than ``limit`` processes."""
    total, todo, seen = 0, children(pid), 0
    while todo and seen < limit:
        p = todo.pop()
        seen += 1
        total += process_bytes(p)
        todo += children(p)
    return total


def kill_descendants(timeout: float = 10.0) -> None:
    """SIGKILL every process below this one and reap them, until none is left (or
    ``timeout`` seconds pass). A child subreaper gets the orphans of its tree too."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        pids = children(os.getpid())
        for pid in pids:
            for p in tree(pid):
                try:
                    os.kill(p, signal.SIGKILL)
                except OSError:
                    pass
        while True:
            try:
                pid, _ = os.waitpid(-1, os.WNOHANG)
            except ChildProcessError:
                return
            if pid == 0:
                break
        if not pids:
            time.sleep(0.01)


def memory_room(cgroup: str = "/sys/fs/cgroup", meminfo: str = "/proc/meminfo") -> int | None:
    """Bytes of memory still free to this process's container: its cgroup's limit less its
    usage (cgroup v2, else v1), and at most the kernel's ``MemAvailable``; None when neither
    is known. A grading container (Gradescope's: 768 MB) is far below the default limit."""
    free = []
    for limit, usage in (
        ("memory.max", "memory.current"),
        ("memory/memory.limit_in_bytes", "memory/memory.usage_in_bytes"),
    ):
        try:
            text = Path(cgroup, limit).read_text().strip()
            if text != "max" and int(text) < 2**60:  # v1 says "no limit" with a huge number
                free.append(int(text) - int(Path(cgroup, usage).read_text()))
            break
        except (OSError, ValueError):
            continue
    try:
        for line in Path(meminfo).read_text().splitlines():
            if line.startswith("MemAvailable:"):
                free.append(int(line.split()[1]) * 1024)
    except (OSError, ValueError, IndexError):
        pass
    return max(0, min(free)) if free else None
