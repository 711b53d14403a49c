"""Task 6: ``closest_hit``, the nearest hit of every ray among a mesh's triangles by brute
force, in tiles of rays x triangles that fit a memory budget.
"""

from __future__ import annotations

import torch

from course.core.types import Hits, Mesh, Rays
from course.given.lab1 import BYTES_PER_PAIR, check_closest_hit_inputs

# The triangle kernels of the lab (``VARIANTS``), picked by name: ``globals()[variant]``.
from .moller_trumbore import moller_trumbore  # noqa: F401
from .simple import intersect_simple  # noqa: F401
from .watertight import watertight  # noqa: F401
from .woop import woop_precompute, woop_unit  # noqa: F401


def closest_hit(
    rays: Rays, mesh: Mesh, variant: str = "moller_trumbore", memory_budget_bytes: int = 2**28
) -> Hits:
    """The nearest hit of every ray among all triangles of ``mesh``, by brute force.

    rays: N rays; mesh: F triangles, same dtype and device; variant: the name of a
    triangle kernel of this lab (see ``VARIANTS``). Returns ``Hits`` (N,): ``t`` (inf
    where missed), ``triangle`` (-1 where missed), ``u, v`` (0 where missed).

    Memory: a kernel call on ``n`` rays x ``m`` triangles makes temporaries of ``n m`` pairs,
    so the work goes in tiles of at most ``P = memory_budget_bytes // (BYTES_PER_PAIR *
    element size)`` pairs: ``m = min(F, P)`` triangles and ``max(1, P // m)`` rays per tile
    (all triangles at once when they fit, else chunks of triangles for one ray at a time).
    Each tile is reduced to its nearest hit per ray; its local triangle index plus the
    tile's offset replaces the running best only when strictly nearer, so ties in ``t`` go
    to the lowest triangle index whatever the tiling.

    Errors (the provided check): ValueError or TypeError naming ``rays`` (not ``Rays``),
    ``mesh`` (not a ``Mesh``, or another dtype or device), ``variant`` (not in ``VARIANTS``)
    or ``memory_budget_bytes`` (not a positive int).

    Hints: ``globals()[variant]`` is the kernel; ``mesh.triangles()`` gives (F, 3, 3)
    corners; ``Hits.miss(n, dtype, device)`` is the starting value; for the lowest index
    among equal t, take the min over ``torch.where(t == t_min_row, index, large)``.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    check_closest_hit_inputs(rays, mesh, variant, memory_budget_bytes)
    raise NotImplementedError("not implemented yet: closest_hit (task 6)")
