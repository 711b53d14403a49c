"""Lab 2's structure chooser: scene statistics and the rules that pick a structure.

Given code, not exercises (imported through :mod:`course.given.lab2`).
"""

from __future__ import annotations

import math

import torch

from course.core.raymath import check_mesh
from course.core.types import Mesh
from course.given.lab2_blocks import grid_resolutions, triangle_bounds
from course.given.lab2_checks import _positive_int


def scene_statistics(mesh: Mesh) -> dict:
    """Provided: what the structure chooser looks at, in O(F) and without building anything.

    Returns plain Python numbers:

    * ``triangles``: F;
    * ``occupancy``: the fraction of the cells of a lambda = 2 grid over the scene's bounds
      that hold a triangle centre (a surface fills few, a soup many);
    * ``crowding``: the mean number of triangle centres in the cell of a triangle's centre,
      ``sum n_c^2 / sum n_c`` over that grid: about 1-4 when the triangles are spread as
      evenly as their surface allows, hundreds or more when most of them sit in a few
      cells (the teapot in a stadium: the grid's failure, measured before building it);
    * ``size_spread``: the 95th over the 5th percentile of the triangles' bounding-box
      diagonals (huge walls among tiny triangles: the mailbox's and the grid's worry).
    """
    check_mesh(mesh)
    tri_lo, tri_hi = triangle_bounds(mesh)
    lo, hi = tri_lo.amin(0), tri_hi.amax(0)
    extent = (hi - lo).double()
    f = mesh.num_faces
    res = grid_resolutions(extent[None], torch.tensor([f], device=extent.device), 2.0)[0]
    centres = ((tri_lo + tri_hi) / 2 - lo).double()
    cell = torch.where(extent > 0, centres / extent.clamp(min=1e-300) * res, 0.0).floor().long()
    cell = torch.minimum(cell.clamp(min=0), res - 1)
    cid = cell[:, 0] + res[0] * (cell[:, 1] + res[1] * cell[:, 2])
    counts = torch.bincount(cid, minlength=int(res.prod())).double()
    counts = counts[counts > 0]
    size = (tri_hi - tri_lo).double().norm(dim=1)
    q = torch.quantile(
        size[torch.randperm(f, device=size.device)[:100_000]] if f > 100_000 else size,
        torch.tensor([0.05, 0.95], dtype=size.dtype, device=size.device),
    )
    return {
        "triangles": f,
        "occupancy": len(counts) / float(res.prod()),
        "crowding": float((counts * counts).sum() / counts.sum()),
        "size_spread": float(q[1] / q[0]) if q[0] > 0 else math.inf,
    }


CHOOSER_LIMITS = {
    "grid_max_triangles": 50_000,
    "even_crowding": 32.0,
    "even_spread": 30.0,
    "cheap_build_rays_per_triangle": 4.0,
}
"""The chooser's thresholds, from ``bench/lab2_accel.py``: a uniform grid only pays for
itself up to about 50K evenly spread triangles (the lecture's 1-50K); crowding above about
32 triangles per occupied cell (the bunny: 9, the teapot in a stadium: 960 and more) means
the grid's cells do not fit the geometry; below about 4 rays per triangle the build time
dominates the trace time, so the cheapest adequate build wins."""


def choose_structure(mesh: Mesh, rays_hint: int | None = None):
    """Provided: the structure (and knobs) a scene requires, and why: ``(kind, knobs, reason)``.

    mesh: the scene; rays_hint: how many rays will be traced through it (None: many, e.g.
    frames of an image). ``kind`` is one of ``STRUCTURES`` and ``knobs`` go to
    ``build(mesh, kind, **knobs)``; ``reason`` explains the choice in words, with the
    numbers of :func:`scene_statistics`. Builds nothing: it only looks at the triangles.

    The rules, in order (thresholds in ``CHOOSER_LIMITS``, measured by the bench):

    1. Evenly spread (low crowding), similar sizes, at most ~50K triangles: a **uniform
       grid** (lambda = 2): the fastest build, and a short walk.
    2. Crowded (a teapot in a stadium): a uniform grid's cells miss the geometry. Few rays
       per triangle: the **two-level grid** (builds in a few sorts, adapts to the crowd);
       else the **binned-SAH BVH**, which adapts at every level (the LBVH does not: its
       Morton grid spans the whole scene).
    3. Otherwise (large or uneven sizes): a BVH; the **LBVH** when few rays per triangle
       will be traced (its build is a sort), the **SAH** build when many will.

    The **kd-tree** is considered and never chosen here: on this lab's batched traversal it
    builds 5-10x slower than the SAH BVH and traces no faster (bench), so it is the choice
    for none of these scenes.
    """
    stats = scene_statistics(mesh)
    f, crowd, spread = stats["triangles"], stats["crowding"], stats["size_spread"]
    if rays_hint is not None:
        _positive_int(rays_hint, "rays_hint")
    lim = CHOOSER_LIMITS
    few_rays = rays_hint is not None and rays_hint < lim["cheap_build_rays_per_triangle"] * f
    facts = (
        f"{f:,} triangles, crowding {crowd:.1f} triangles per occupied cell, "
        f"{stats['occupancy']:.1%} of the cells occupied, size spread {spread:.0f}x"
        + (f", {rays_hint:,} rays" if rays_hint is not None else ", many rays")
    )
    even = crowd <= lim["even_crowding"]
    if even and spread <= lim["even_spread"] and f <= lim["grid_max_triangles"]:
        return (
            "grid",
            {"density": 2.0},
            (
                f"{facts}: small and evenly spread, so a uniform grid (lambda = 2) fits it: the "
                f"fastest build and a short walk; the kd-tree never pays its build here"
            ),
        )
    if not even:
        if few_rays:
            return (
                "grid2",
                {},
                (
                    f"{facts}: most triangles crowd into a few cells of a uniform grid, and few "
                    f"rays will be traced: a two-level grid gives the crowded cells their own "
                    f"grids at the cost of a few sorts"
                ),
            )
        return (
            "bvh",
            {"method": "sah"},
            (
                f"{facts}: most triangles crowd into a few cells, and many rays will be traced: "
                f"a binned-SAH BVH adapts at every level (the LBVH's Morton grid spans the whole "
                f"scene and would not)"
            ),
        )
    if few_rays:
        return (
            "bvh",
            {"method": "lbvh"},
            (
                f"{facts}: too large or uneven for a uniform grid; with few rays per triangle the "
                f"build dominates, so the LBVH (one sort)"
            ),
        )
    return (
        "bvh",
        {"method": "sah"},
        (
            f"{facts}: too large or uneven for a uniform grid; many rays repay the binned-SAH "
            f"build (fewer nodes per ray than the LBVH)"
        ),
    )
