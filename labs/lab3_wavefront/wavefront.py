"""Task 2: ``render_wavefront``, the tracer as separate stages (generate, trace, shade, spawn)
over a compacted queue of live rays, optionally sorted by material.
"""

from __future__ import annotations

import math

import torch

from course.given.lab3 import MAX_DEPTH, StageClock, WhittedScene, check_render_inputs

from .whitted import offset_origins, reflect, shade_direct, surface_at


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
    raise NotImplementedError("not implemented yet: render_wavefront (task 2)")
