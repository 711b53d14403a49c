"""Task 5: ``brute_force_closest_hit`` and the common entry point: ``build`` (provided) and
``closest_hit`` (dispatch, the structure ``"auto"`` picks).
"""

from __future__ import annotations

import torch

from course.core.types import Mesh, Rays
from course.given.lab2 import (
    STRUCTURES,
    as_hits,
    check_memory_budget,
    check_trace_inputs,
    choose_structure,
    intersect_pairs,
    new_closest,
    new_counters,
)

from .bvh_build import build_lbvh, build_sah_bvh
from .bvh_walk import bvh_closest_hit, bvh_closest_hit_stackless
from .grid import build_grid, grid_closest_hit
from .kdtree import build_kdtree, kd_closest_hit
from .two_level import build_two_level_grid, two_level_closest_hit


def brute_force_closest_hit(rays: Rays, mesh: Mesh, intersect, memory_budget_bytes: int = 2**27):
    """The baseline: every ray against every triangle, in tiles.

    Same results as the structures: ``(Hits, counters)`` with ``"steps" = 0`` and
    ``"tests" = F`` for every ray. Tiles of at most ``memory_budget_bytes // 256`` (ray,
    triangle) pairs (its corners, indices and the kernel's temporaries: about 256 bytes in
    float32): all triangles for a chunk of rays, or chunks of triangles for one ray at a
    time. Each tile goes through ``intersect_pairs``, which keeps ties at the lowest
    triangle index.

    Errors (the provided checks): TypeError or ValueError naming ``rays`` (not ``Rays``),
    ``mesh`` (not a ``Mesh``, or another dtype or device than the rays) or ``intersect``
    (not callable); ValueError naming ``memory_budget_bytes`` unless it is an int >= 1.

    Hints: ``intersect_pairs`` does the testing and the tie rule; a tile's pairs
    are ``r.repeat_interleave(len(tri))`` and ``tri.repeat(len(r))``.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    check_trace_inputs(rays, mesh, intersect)
    check_memory_budget(memory_budget_bytes)
    # BEGIN SOLUTION (task 5)
    n, f, device = len(rays), mesh.num_faces, rays.device
    closest = new_closest(n, rays.t_min)
    counters = new_counters(n, device)
    corners = mesh.triangles()
    pairs = max(1, memory_budget_bytes // 256)
    tri_chunk = min(f, pairs)
    ray_chunk = max(1, pairs // tri_chunk)
    for r0 in range(0, n, ray_chunk):
        r = torch.arange(r0, min(n, r0 + ray_chunk), device=device)
        for f0 in range(0, f, tri_chunk):
            tri = torch.arange(f0, min(f, f0 + tri_chunk), device=device)
            intersect_pairs(
                intersect,
                rays,
                corners,
                r.repeat_interleave(len(tri)),
                tri.repeat(len(r)),
                closest,
                counters,
            )
    return as_hits(closest), counters
    # END SOLUTION


def build(mesh: Mesh, kind: str, **knobs) -> dict:
    """A structure of ``kind`` for ``mesh``: ``"grid"`` (:func:`build_grid`), ``"grid2"``
    (:func:`build_two_level_grid`), ``"bvh"`` (:func:`build_sah_bvh`; ``method="lbvh"`` for
    :func:`build_lbvh`) or ``"kd"`` (:func:`build_kdtree`); ``knobs`` go to the builder."""
    if kind == "grid":
        return build_grid(mesh, **knobs)
    if kind == "grid2":
        return build_two_level_grid(mesh, **knobs)
    if kind == "bvh":
        method = knobs.pop("method", "sah")
        if method not in ("sah", "lbvh"):
            raise ValueError(f"method: expected 'sah' or 'lbvh', got {method!r}")
        return (build_sah_bvh if method == "sah" else build_lbvh)(mesh, **knobs)
    if kind == "kd":
        return build_kdtree(mesh, **knobs)
    raise ValueError(f"kind: expected one of {', '.join(STRUCTURES)}, got {kind!r}")


def closest_hit(rays: Rays, mesh: Mesh, structure, intersect, **options):
    """Closest hits of ``rays`` through any structure: the lab's common entry point.

    structure: None (brute force), ``"auto"`` (``choose_structure(mesh, len(rays))``
    picks the kind and knobs, and exactly that one structure is built, with :func:`build`,
    nothing else), or a dict from a ``build_*`` function, dispatched on
    its ``"kind"``: ``grid_closest_hit`` and ``two_level_closest_hit`` (option
    ``mailbox``), ``bvh_closest_hit`` or,
    with ``stackless=True``, ``bvh_closest_hit_stackless``, and ``kd_closest_hit``.
    Returns ``(Hits, counters)``; every structure returns the brute-force hits, so only
    the counters (and the clock) tell them apart.

    Errors: ValueError naming ``structure`` for anything else (another string, a dict of
    another kind) or an option the structure does not take (yours to raise); bad ``rays``
    (not ``Rays``), ``mesh`` (e.g. a float64 mesh with float32 rays) or an ``intersect``
    that is not callable raise the TypeError or ValueError naming them that the called
    function raises (its provided checks).

    Hints: Check ``structure['kind']`` and the options, then call the matching function.
    For ``"auto"``: ``choose_structure`` (provided) names the kind and knobs, ``build``
    builds them.
    """
    # BEGIN SOLUTION (task 5)
    if structure is None:
        return brute_force_closest_hit(rays, mesh, intersect, **options)
    if isinstance(structure, str) and structure == "auto":
        check_trace_inputs(rays, mesh, intersect)
        kind, knobs, _ = choose_structure(mesh, max(1, len(rays)))
        structure = build(mesh, kind, **knobs)
    kind = structure.get("kind") if isinstance(structure, dict) else None
    if kind not in STRUCTURES:
        raise ValueError(
            f"structure: expected None or a dict with kind in "
            f"{', '.join(STRUCTURES)}, got "
            f"{kind if kind is not None else type(structure).__name__!r}"
        )
    allowed = {"grid": {"mailbox"}, "grid2": {"mailbox"}, "bvh": {"stackless"}, "kd": set()}[kind]
    extra = set(options) - allowed
    if extra:
        raise ValueError(
            f"structure: a {kind} takes the options {sorted(allowed)}, got {sorted(extra)}"
        )
    if kind == "grid":
        return grid_closest_hit(rays, mesh, structure, intersect, **options)
    if kind == "grid2":
        return two_level_closest_hit(rays, mesh, structure, intersect, **options)
    if kind == "bvh":
        traverse = bvh_closest_hit_stackless if options.get("stackless") else bvh_closest_hit
        return traverse(rays, mesh, structure, intersect)
    return kd_closest_hit(rays, mesh, structure, intersect)
    # END SOLUTION
