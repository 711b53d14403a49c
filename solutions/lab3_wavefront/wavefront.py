"""Task 2: ``render_wavefront``, the tracer as separate stages (generate, trace, shade, spawn)
over a compacted queue of live rays, optionally sorted by material.
"""

from __future__ import annotations

import math

import torch

from course.given.lab3 import MAX_DEPTH, StageClock, WhittedScene, check_render_inputs

from .whitted import offset_origins, reflect, shade_direct, surface_at

# BEGIN SOLUTION
# The reference's own function, which the skeleton leaves out, and so its import.
# isort: split
from .whitted import _is_mirror

# END SOLUTION


def render_wavefront(
    scene: WhittedScene,
    origins: torch.Tensor,
    directions: torch.Tensor,
    trace,
    max_depth: int = MAX_DEPTH,
    sort_by_material: bool = False,
):
    """The tracer as separate stages over a compacted queue of live rays.

    Same arguments and image as :func:`render_whitted`; sort_by_material: sort the shading
    queue by material before shading. Returns ``(image (N, 3), stats)``.

    The queue holds, per live ray, its pixel index, origin, direction and throughput. Stages:

    * **generate**: the queue of the N primary rays;
    * **trace**: closest hits of the queue's rays (one ``trace`` call);
    * **shade**: misses add ``throughput * background`` to their pixels (``index_add_``) and
      leave the queue (compaction); the hits are optionally sorted by material (coherent
      shading: on a GPU, a warp whose rays share a material takes one branch) and add
      ``throughput * shade_direct(...)``;
    * **spawn**: only mirror hits with ``depth < max_depth`` stay (compaction again), with
      their reflected rays and throughput ``*= kr``.

    Repeat trace -> shade -> spawn for ``depth = 0 .. max_depth`` or until the queue is empty.
    ``stats`` (plain Python data), one list entry per bounce that traced rays:

    ===================  =======================================================
    ``closest_rays``     rays traced in the trace stage (the queue's length)
    ``hits``             of those, rays that hit something
    ``shadow_rays``      shadow rays traced by the shade stage
    ``reflected_rays``   rays spawned for the next bounce
    ``material_runs``    runs of equal material in the shading queue as it is shaded:
                         in the rays' order when not sorted (compaction keeps the
                         order), the number of distinct materials when sorted
    ``seconds``          ``{"generate", "trace", "shade", "spawn"}``: seconds per stage
                         (``StageClock`` does it; shadow rays count as shading)
    ===================  =======================================================

    Errors: as :func:`render_whitted`, ValueError or TypeError naming ``scene`` (also for
    a scene without ``lights`` or a ``material`` index beyond its table), ``origins``,
    ``directions``, ``trace`` or ``max_depth``; TypeError naming ``sort_by_material``
    unless it is a bool.

    Hints: compact with a mask, ``x = x[keep]``, applied to *every* per-ray tensor alike;
    ``torch.argsort(material, stable=True)`` sorts; ``clock = StageClock(device)`` and
    ``with clock("trace"): ...``.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    n = check_render_inputs(  # noqa: F841 (n: the number of rays, for your code)
        scene, origins, directions, trace, max_depth
    )
    if not isinstance(sort_by_material, bool):
        raise TypeError(f"sort_by_material: expected a bool, got {sort_by_material!r}")
    # BEGIN SOLUTION (task 2)
    clock = StageClock(scene.device)
    stats = {
        "closest_rays": [],
        "hits": [],
        "shadow_rays": [],
        "reflected_rays": [],
        "material_runs": [],
        "seconds": clock.seconds,
    }
    with clock("generate"):
        image = torch.zeros(n, 3, dtype=scene.dtype, device=scene.device)
        pixel = torch.arange(n, device=scene.device)
        o, d = origins, directions
        throughput = torch.ones(n, 3, dtype=scene.dtype, device=scene.device)
    for depth in range(max_depth + 1):
        if len(pixel) == 0:
            break
        with clock("trace"):
            zeros = torch.zeros(len(pixel), dtype=scene.dtype, device=scene.device)
            hits = trace(scene, o, d, zeros, zeros + math.inf, False)
        with clock("shade"):
            hit = hits.hit
            image.index_add_(0, pixel[~hit], throughput[~hit] * scene.background)
            pixel, o, d, throughput, hits = pixel[hit], o[hit], d[hit], throughput[hit], hits[hit]
            points, normals, material = surface_at(scene, o, d, hits)
            if sort_by_material:
                # Rays of one material next to each other: coherent shading (and on a GPU,
                # warps that take one branch).
                order = torch.argsort(material, stable=True)
                pixel, d, throughput = pixel[order], d[order], throughput[order]
                points, normals, material = points[order], normals[order], material[order]
            direct, shadow_rays = shade_direct(scene, points, normals, d, material, trace)
            image.index_add_(0, pixel, throughput * direct)
        with clock("spawn"):
            mirror = _is_mirror(scene, material) & (depth < max_depth)
            pixel, throughput = pixel[mirror], throughput[mirror] * scene.kr[material[mirror]]
            o = offset_origins(points[mirror], normals[mirror])
            d = reflect(d[mirror], normals[mirror])
        runs = 1 + int((material[1:] != material[:-1]).sum()) if len(material) else 0
        stats["closest_rays"].append(len(hit))
        stats["hits"].append(len(material))
        stats["shadow_rays"].append(shadow_rays)
        stats["reflected_rays"].append(len(pixel))
        stats["material_runs"].append(runs)
    stats["seconds"] = dict(clock.seconds)
    return image, stats
    # END SOLUTION
