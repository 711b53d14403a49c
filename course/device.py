"""Device selection: the same code runs on CUDA when present and on the CPU otherwise.

Precedence: an explicit argument, then the ``RTCOURSE_DEVICE`` environment variable
(``cpu``, ``cuda`` or ``cuda:N``), then CUDA if available, then the CPU.
"""

from __future__ import annotations

import os

import torch

ENV_VAR = "RTCOURSE_DEVICE"


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
        raise ValueError(f"{name}={spec!r} is not a device; expected 'cpu', 'cuda' or 'cuda:N'") \
            from err
    if device.type not in ("cpu", "cuda"):
        raise ValueError(f"{name}={spec!r}: the course supports 'cpu' and 'cuda' devices only")
    if device.type == "cuda":
        count = torch.cuda.device_count() if torch.cuda.is_available() else 0
        if count == 0:
            raise ValueError(f"{name}={spec!r}: CUDA is not available on this machine; use 'cpu'")
        if device.index is not None and device.index >= count:
            raise ValueError(f"{name}={spec!r}: only {count} CUDA device(s) present "
                             f"(cuda:0..cuda:{count - 1})")
    return device
