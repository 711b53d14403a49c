"""The Gradescope settings each lab's autograder needs, from measurements.

Gradescope runs an autograder in a container with 768 MB of memory and half a CPU by
default, and stops it after 10 minutes (up to 40 can be set); a container over its memory
is killed, and the student sees "Killed" and 0 points. ``bench/grading_cost.py`` grades
each lab's reference with the autograder of ``rtcourse gradescope --lab N``, pinned to
one core, and records the peak memory of the whole process tree (PSS) and the CPU time
(``bench/results/cpu-2cores/grading_cost.json``). :data:`MEASURED` holds those numbers;
:func:`lab_settings` turns them into settings with headroom for a student's solution,
and ``rtcourse gradescope`` prints them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

DEFAULT_MEMORY_MB = 768
DEFAULT_CPUS = 0.5
DEFAULT_TIMEOUT_MINUTES = 10
MAX_TIMEOUT_MINUTES = 40
# A student's solution may use more memory and time than the reference; the memory was
# sampled (a short spike can be missed); Gradescope's CPUs may be slower than ours.
MEMORY_HEADROOM = 1.25
TIME_HEADROOM = 1.5
MEMORY_STEP_MB = 256

# lab: (peak PSS of the grading process tree in MB, CPU seconds at one core), the
# reference as the submission, CUDA hidden: bench/results/cpu-2cores/grading_cost.json.
MEASURED: dict[int, tuple[float, float]] = {
    0: (729.9, 7.1),
    1: (941.4, 15.4),
    2: (1040.9, 27.3),
    3: (815.7, 21.2),
    4: (670.1, 11.7),
    5: (780.7, 11.7),
    6: (863.7, 14.1),
}
MEASURED_WITH = "torch 2.13.0+cpu, 2026-12-05"  # the run's torch and date, for the printout


@dataclass(frozen=True)
class LabSetting:
    lab: int
    peak_mb: float  # measured, the reference as the submission
    cpu_seconds: float
    memory_mb: int  # the container memory to set (at least)
    cpus: float  # the CPUs to set
    timeout_minutes: int

    @property
    def is_default(self) -> bool:
        return (
            self.memory_mb <= DEFAULT_MEMORY_MB
            and self.cpus <= DEFAULT_CPUS
            and self.timeout_minutes <= DEFAULT_TIMEOUT_MINUTES
        )


def setting_for(lab: int, peak_mb: float, cpu_seconds: float) -> LabSetting:
    """The settings for a measured autograder: memory with headroom in steps of 256 MB
    (768 MB at least), half a CPU while that keeps the run within the default timeout,
    else one (grading is sequential: more CPUs do not shorten it), and the timeout."""
    memory = max(
        DEFAULT_MEMORY_MB, math.ceil(peak_mb * MEMORY_HEADROOM / MEMORY_STEP_MB) * MEMORY_STEP_MB
    )
    needed = cpu_seconds * TIME_HEADROOM / 60  # minutes at one full CPU
    cpus = DEFAULT_CPUS if needed / DEFAULT_CPUS <= DEFAULT_TIMEOUT_MINUTES else 1.0
    timeout = max(DEFAULT_TIMEOUT_MINUTES, math.ceil(needed / min(cpus, 1.0)))
    return LabSetting(lab, peak_mb, cpu_seconds, memory, cpus, timeout)


def lab_settings(labs=None) -> list[LabSetting]:
    """The settings of each measured lab among ``labs`` (default: every measured lab)."""
    wanted = sorted(MEASURED) if not labs else sorted({int(n) for n in labs})
    return [setting_for(n, *MEASURED[n]) for n in wanted if n in MEASURED]


def autograder_setting(labs) -> LabSetting | None:
    """One autograder grading several labs runs them one after another in one process
    tree: the largest lab's memory, the labs' CPU time added up."""
    rows = lab_settings(labs)
    if not rows:
        return None
    return setting_for(-1, max(r.peak_mb for r in rows), sum(r.cpu_seconds for r in rows))


def settings_text(labs=None) -> str:
    """The table ``rtcourse gradescope`` prints: what to set in the assignment's
    Autograder Settings on Gradescope."""
    rows = lab_settings(labs)
    if not rows:
        return "Gradescope settings: no lab of these has been measured (bench/grading_cost.py)."

    def mark(value, default, text):
        return text + (" (default)" if value <= default else "")

    measured = f" ({MEASURED_WITH})" if MEASURED_WITH else ""
    lines = [
        (
            "Gradescope settings for the assignment's Autograder Settings, from the "
            f"references\ngraded at one core{measured}:"
        ),
        (f"{'lab':>5}  {'peak memory':>11}  {'CPU time':>8}   {'memory':<16} {'CPUs':<15} timeout"),
    ]
    combined = autograder_setting(labs) if len(rows) > 1 else None
    for row in rows + ([combined] if combined else []):
        name = "all" if row.lab < 0 else str(row.lab)
        lines.append(
            f"{name:>5}  {row.peak_mb:8.0f} MB  {row.cpu_seconds:6.0f} s   "
            f"{mark(row.memory_mb, DEFAULT_MEMORY_MB, f'{row.memory_mb} MB'):<16} "
            f"{mark(row.cpus, DEFAULT_CPUS, f'{row.cpus:g}'):<15} "
            + mark(row.timeout_minutes, DEFAULT_TIMEOUT_MINUTES, f"{row.timeout_minutes} min")
        )
    over = [r for r in rows if not r.is_default]
    if combined:
        lines.append(
            "  (all: one autograder grading these labs one after another, estimated\n"
            "  from their rows; one autograder per lab is what was measured)"
        )
    if over:
        lines.append(
            "Set these where they differ from the defaults: over its memory the "
            "container is\nkilled, and the student sees 'Killed' and 0 points."
        )
    return "\n".join(lines)
