"""Task 4: ``render_persistent``, a fixed pool of ray slots fed from one global queue until
the work runs out.
"""

from __future__ import annotations

import math

import torch

from course.given.lab3 import MAX_DEPTH, WhittedScene, check_pool_size, check_render_inputs

from .whitted import offset_origins, reflect, shade_direct, surface_at


def render_persistent(
    scene: WhittedScene,
    origins: torch.Tensor,
    directions: torch.Tensor,
    trace,
    max_depth: int = MAX_DEPTH,
    pool_size: int = 4096,
):
    """A fixed pool of ray slots that keep taking work from one global queue until done.

    Same arguments and image as :func:`render_whitted`; pool_size: the number of slots
    (lanes), >= 1. Returns ``(image (N, 3), stats)``.

    A work item is ``(pixel, origin, direction, depth, throughput)``; the queue starts with
    the N primary rays. Each **step**:

    1. fill the empty slots from the head of the queue (first in, first out);
    2. stop if no slot holds work;
    3. the busy slots trace, shade (background for misses, ``shade_direct`` for hits) and
       add to their pixels; a mirror hit with ``depth < max_depth`` **appends** its reflected
       ray (depth + 1, throughput ``* kr``) to the tail of the queue;
    4. the slots are free again.

    Nothing may be lost or done twice: every item generated is processed exactly once.
    ``stats`` (plain Python data): ``pool_size``; ``steps``; ``active_lanes`` (list: busy
    slots per step); ``idle_fraction`` = ``1 - sum(active_lanes) / (pool_size * steps)``
    (0.0 when no step ran: no rays);
    ``work_generated`` (primary rays + reflections appended); ``work_processed``;
    ``shadow_rays``.

    Persistent threads (Aila & Laine 2009) replace "one launch per bounce, sized to its
    rays" by one launch of as many workers as the GPU holds at once, each looping "fetch,
    trace, shade, push" until the queue is empty: no relaunch, mixed depths in one batch,
    idle lanes only at the tail.

    Errors (the provided check): ValueError or TypeError naming ``scene`` (not a
    ``WhittedScene``, a scene without ``lights``, a ``material`` index beyond its table),
    ``origins`` or ``directions`` (a wrong shape; TypeError for half precision or a dtype
    other than the scene's), ``trace`` (not callable) or ``max_depth`` (not an int >= 0).
    ValueError or TypeError naming ``pool_size`` unless it is an int >= 1.

    Hints: keep the queue and the pool as dicts of tensors; ``(pool['pixel'] < 0)`` marks
    empty slots; the queue's head index is a Python int.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    n = check_render_inputs(  # noqa: F841 (n: the number of rays, for your code)
        scene, origins, directions, trace, max_depth
    )
    check_pool_size(pool_size)
    raise NotImplementedError("not implemented yet: render_persistent (task 4)")
