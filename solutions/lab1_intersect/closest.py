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
    # BEGIN SOLUTION (task 6)
    n, m = len(rays), mesh.num_faces
    pairs = max(1, memory_budget_bytes // (BYTES_PER_PAIR * rays.origins.element_size()))
    tri_chunk = min(m, pairs)
    ray_chunk = max(1, min(n, pairs // tri_chunk))
    corners = mesh.triangles()
    kernel = globals()[variant]
    if variant == "woop_unit":
        transforms = woop_precompute(corners[:, 0], corners[:, 1], corners[:, 2])

    best = Hits.miss(n, dtype=rays.dtype, device=rays.device)
    t_best, tri_best, u_best, v_best = best.t, best.triangle, best.u, best.v
    for r0 in range(0, n, ray_chunk):
        rs = slice(r0, min(n, r0 + ray_chunk))
        o, d = rays.origins[rs, None, :], rays.directions[rs, None, :]
        t_lo, t_hi = rays.t_min[rs, None], rays.t_max[rs, None]
        for f0 in range(0, m, tri_chunk):
            fs = slice(f0, min(m, f0 + tri_chunk))
            if variant == "woop_unit":
                t, u, v = kernel(o, d, transforms[None, fs], t_lo, t_hi)
            else:
                tri = corners[None, fs]
                t, u, v = kernel(o, d, tri[..., 0, :], tri[..., 1, :], tri[..., 2, :], t_lo, t_hi)
            # The nearest triangle of this chunk; among equal t the lowest index.
            cols = torch.arange(t.shape[1], device=t.device)
            t_near = t.amin(dim=1, keepdim=True)
            first = torch.where(t == t_near, cols, t.shape[1]).amin(dim=1, keepdim=True)
            first = first.clamp(max=t.shape[1] - 1)
            t_sel = t.gather(1, first)[:, 0]
            # Strictly nearer only: earlier chunks (lower indices) keep ties.
            take = t_sel < t_best[rs]
            t_best[rs] = torch.where(take, t_sel, t_best[rs])
            tri_best[rs] = torch.where(take, first[:, 0] + f0, tri_best[rs])
            u_best[rs] = torch.where(take, u.gather(1, first)[:, 0], u_best[rs])
            v_best[rs] = torch.where(take, v.gather(1, first)[:, 0], v_best[rs])
    return Hits(t=t_best, triangle=tri_best, u=u_best, v=v_best)
    # END SOLUTION
