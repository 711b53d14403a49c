"""Device selection: the same code runs on CUDA when present and on the CPU otherwise.

Precedence: an explicit argument, then the ``RTCOURSE_DEVICE`` environment variable
(``cpu``, ``cuda`` or ``cuda:N``), then CUDA if available, then the CPU.

CPU threads: ``free_cpus()`` counts the cores this process may use (its affinity mask,
not the machine's total) less the load already running on them, and ``set_cpu_threads()``
gives torch that many threads. More threads than free cores makes every parallel torch op
wait for a descheduled worker: on a loaded machine a traversal step can take 100x longer.
"""

from __future__ import annotations

import os

import torch

ENV_VAR = "RTCOURSE_DEVICE"


def allowed_cpus() -> int:
    """The cores this process may run on: its affinity mask where the OS has one (a
    container or ``taskset`` narrows it), else ``os.cpu_count()``."""
    if hasattr(os, "sched_getaffinity"):
        return max(1, len(os.sched_getaffinity(0)))
    return max(1, os.cpu_count() or 1)


def free_cpus() -> int:
    """Cores free for new work: ``allowed_cpus()`` less the 1-minute load average (the
    runnable processes already there), rounded, at least 1 and at most ``allowed_cpus()``.

    The load average is machine-wide; where the process may use only some of the cores it
    is scaled to that share."""
    allowed = allowed_cpus()
    try:
        load = os.getloadavg()[0] * allowed / max(1, os.cpu_count() or allowed)
    except (AttributeError, OSError):  # no load average on this platform
        load = 0.0
    return max(1, min(allowed, round(allowed - load)))


def set_cpu_threads(threads: int | None = None) -> int:
    """Give torch ``threads`` intra-op CPU threads (default: ``free_cpus()``); returns the
    number set. Raises ValueError for a count that is not a positive int."""
    if threads is None:
        threads = free_cpus()
    if not isinstance(threads, int) or isinstance(threads, bool) or threads < 1:
        raise ValueError(f"threads: expected a positive int, got {threads!r}")
    torch.set_num_threads(threads)
    return threads


def available_devices() -> list[str]:
    """The devices a test or benchmark can run on: ``["cpu"]`` plus ``"cuda"`` when present."""
    return ["cpu", "cuda"] if torch.cuda.is_available() else ["cpu"]


def default_device(prefer: str | torch.device | None = None) -> torch.device:
    """The device to compute on.

    prefer: ``"cpu"``, ``"cuda"``, ``"cuda:N"`` or a ``torch.device``; ``None`` consults
        ``RTCOURSE_DEVICE`` and then picks CUDA when available.
    Raises ValueError for a device string torch does not know, a kind the course does not
    support, or a device that is not present on this machine.
    """
    if prefer is not None:
        return _checked(prefer, "prefer")
    if os.environ.get(ENV_VAR):
        return _checked(os.environ[ENV_VAR], ENV_VAR)
    return torch.device("cuda" if torch.cuda.is_available() else "cpu")


def _checked(spec: str | torch.device, name: str) -> torch.device:
    try:
        device = torch.device(spec)
    except (RuntimeError, TypeError) as err:
        raise ValueError(
            f"{name}={spec!r} is not a device; expected 'cpu', 'cuda' or 'cuda:N'"
        ) from err
    if device.type not in ("cpu", "cuda"):
        raise ValueError(f"{name}={spec!r}: the course supports 'cpu' and 'cuda' devices only")
    if device.type == "cuda":
        count = torch.cuda.device_count() if torch.cuda.is_available() else 0
        if count == 0:
            raise ValueError(f"{name}={spec!r}: CUDA is not available on this machine; use 'cpu'")
        if device.index is not None and device.index >= count:
            raise ValueError(
                f"{name}={spec!r}: only {count} CUDA device(s) present (cuda:0..cuda:{count - 1})"
            )
    return device
