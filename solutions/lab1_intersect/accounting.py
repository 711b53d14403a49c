"""Task 7: the lecture's accounting, measured on the lab's own kernels: ``op_counts``
(floating-point operations per test), ``register_estimate`` (values alive at once) and
``occupancy_for`` (the occupancy those registers allow).
"""

from __future__ import annotations

import math

from course.given.lab1 import accounting_inputs

# The triangle kernels of the lab (``VARIANTS``), picked by name: ``globals()[variant]``.
from .moller_trumbore import moller_trumbore  # noqa: F401
from .simple import intersect_simple  # noqa: F401
from .watertight import watertight  # noqa: F401
from .woop import woop_unit  # noqa: F401


def op_counts(variant: str) -> dict:
    """Floating-point operations of one test of ``variant`` (a name in ``VARIANTS``).

    Runs ``course.measure.accounting.count_ops`` on the lab's kernel (imported here:
    ``globals()[variant]``) with ``accounting_inputs(variant)`` and one lane. Returns the
    counts as a dict with the keys ``mul, add, div, sqrt, fma, compare, abs, select,
    other`` and ``cycles_bound``, the lecture's lower bound
    ``4 * (N_mul + |N_add - N_mul|)`` with ``N_mul`` read as the number of mul/add pairs a
    mad can fuse, ``min(mul, add)``.

    Errors: ValueError naming ``variant`` for a name not in ``VARIANTS``
    (``accounting_inputs`` raises it: call it first).

    Hints: ``from course.measure.accounting import count_ops``;
    ``count_ops(fn, *args, lanes=1)`` returns an ``OpCounts`` with the fields named above.
    """
    # BEGIN SOLUTION (task 7)
    from course.measure.accounting import count_ops

    args = accounting_inputs(variant)  # validates the name first
    counts = count_ops(globals()[variant], *args, lanes=1)
    result = {
        key: getattr(counts, key)
        for key in ("mul", "add", "div", "sqrt", "fma", "compare", "abs", "select", "other")
    }
    pairs = min(counts.mul, counts.add)
    result["cycles_bound"] = 4 * (pairs + abs(counts.add - counts.mul))
    return result
    # END SOLUTION


def register_estimate(variant: str) -> int:
    """Registers one thread of ``variant`` needs, estimated from the values alive at once.

    ``course.measure.accounting.live_values`` on ``accounting_inputs(variant)`` (one lane); its
    ``peak_last_use`` (every value dies at its last use, as a register allocator frees it),
    rounded up.

    Errors: ValueError naming ``variant`` for a name not in ``VARIANTS``.

    Hints: ``from course.measure.accounting import live_values``; ``math.ceil``.
    """
    # BEGIN SOLUTION (task 7)
    from course.measure.accounting import live_values

    args = accounting_inputs(variant)  # validates the name first
    live = live_values(globals()[variant], *args, lanes=1)
    return math.ceil(live.peak_last_use)
    # END SOLUTION


def occupancy_for(variant: str, arch: str = "g80", block_size: int = 64):
    """Occupancy of a kernel running ``variant`` with ``register_estimate(variant)``
    registers per thread on ``arch`` (a name in ``course.measure.occupancy.PRESETS``) with
    ``block_size`` threads per block: a ``course.measure.occupancy.Occupancy``.

    Errors: ValueError naming ``variant`` (not in ``VARIANTS``) or ``arch`` (not a preset).

    Hint: ``from course.measure.occupancy import PRESETS, occupancy``.
    """
    # BEGIN SOLUTION (task 7)
    from course.measure.occupancy import PRESETS, occupancy

    if arch not in PRESETS:
        raise ValueError(f"arch: expected one of {', '.join(PRESETS)}, got {arch!r}")
    return occupancy(PRESETS[arch], register_estimate(variant), block_size)
    # END SOLUTION
