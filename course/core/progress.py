"""Progress bars for long work (grading, the demo gallery, benchmarks), through tqdm.

Shown only when the output is a terminal, so logs, CI and notebooks stay clean;
``RTCOURSE_PROGRESS=1`` forces the bars on and ``RTCOURSE_PROGRESS=0`` off.
"""

from __future__ import annotations

import os
import sys


def progress_enabled(stream=None) -> bool:
    """Whether bars are drawn on ``stream`` (stderr by default)."""
    forced = os.environ.get("RTCOURSE_PROGRESS")
    if forced in ("0", "1"):
        return forced == "1"
    stream = stream if stream is not None else (sys.__stderr__ or sys.stderr)
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):
        return False


def progress(
    iterable=None, *, total=None, desc: str = "", unit: str = "it", leave=False, file=None
):
    """A tqdm bar on ``file`` (stderr by default) over ``iterable`` (or one to update by
    hand with ``total``), drawn only when :func:`progress_enabled` for that stream."""
    from tqdm import tqdm

    stream = file if file is not None else (sys.__stderr__ or sys.stderr)
    return tqdm(
        iterable,
        total=total,
        desc=desc,
        unit=unit,
        leave=leave,
        file=stream,
        disable=not progress_enabled(stream),
    )


def terminal_stream():
    """A second handle on the terminal behind stderr, or None when stderr is not one (or
    bars are off). pytest captures file descriptor 2 while tests run; a bar drawn from
    inside a test session writes here to stay visible."""
    import os

    stream = sys.__stderr__ or sys.stderr
    if not progress_enabled(stream):
        return None
    try:
        return os.fdopen(os.dup(stream.fileno()), "w", buffering=1)
    except (OSError, ValueError, AttributeError):
        return None
