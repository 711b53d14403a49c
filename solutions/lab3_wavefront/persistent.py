"""Task 4: ``render_persistent``, a fixed pool of ray slots fed from one global queue until
the work runs out.
"""

from __future__ import annotations

import math

import torch

from course.given.lab3 import MAX_DEPTH, WhittedScene, check_pool_size, check_render_inputs

from .whitted import offset_origins, reflect, shade_direct, surface_at

# BEGIN SOLUTION
# The reference's own function, which the skeleton leaves out, and so its import.
# isort: split
from .whitted import _is_mirror

# END SOLUTION


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
    # BEGIN SOLUTION (task 4)
    device, dtype = scene.device, scene.dtype
    image = torch.zeros(n, 3, dtype=dtype, device=device)
    # The queue: one work item (pixel, origin, direction, depth, throughput) per row.
    queue = {
        "pixel": torch.arange(n, device=device),
        "o": origins,
        "d": directions,
        "depth": torch.zeros(n, dtype=torch.int64, device=device),
        "throughput": torch.ones(n, 3, dtype=dtype, device=device),
    }
    head = 0
    # The pool: pool_size slots; pixel -1 marks an empty slot.
    pool = {
        key: torch.zeros((pool_size, *x.shape[1:]), dtype=x.dtype, device=device)
        for key, x in queue.items()
    }
    pool["pixel"].fill_(-1)
    stats = {
        "pool_size": pool_size,
        "steps": 0,
        "active_lanes": [],
        "work_generated": n,
        "work_processed": 0,
        "shadow_rays": 0,
    }
    while True:
        free = (pool["pixel"] < 0).nonzero()[:, 0]
        take = min(len(free), len(queue["pixel"]) - head)
        if take > 0:  # refill the empty slots from the head of the queue
            for key, slots in pool.items():
                slots[free[:take]] = queue[key][head : head + take]
            head += take
        lane = (pool["pixel"] >= 0).nonzero()[:, 0]
        if len(lane) == 0:
            break
        stats["steps"] += 1
        stats["active_lanes"].append(len(lane))
        stats["work_processed"] += len(lane)
        pixel, o, d = pool["pixel"][lane], pool["o"][lane], pool["d"][lane]
        depth, throughput = pool["depth"][lane], pool["throughput"][lane]
        zeros = torch.zeros(len(lane), dtype=dtype, device=device)
        hits = trace(scene, o, d, zeros, zeros + math.inf, False)
        hit = hits.hit
        image.index_add_(0, pixel[~hit], throughput[~hit] * scene.background)
        points, normals, material = surface_at(scene, o[hit], d[hit], hits[hit])
        direct, shadow_rays = shade_direct(scene, points, normals, d[hit], material, trace)
        stats["shadow_rays"] += shadow_rays
        image.index_add_(0, pixel[hit], throughput[hit] * direct)
        # Spawn: a mirror hit appends its reflected ray to the tail of the queue.
        mirror = _is_mirror(scene, material) & (depth[hit] < max_depth)
        spawned = {
            "pixel": pixel[hit][mirror],
            "o": offset_origins(points[mirror], normals[mirror]),
            "d": reflect(d[hit][mirror], normals[mirror]),
            "depth": depth[hit][mirror] + 1,
            "throughput": throughput[hit][mirror] * scene.kr[material[mirror]],
        }
        stats["work_generated"] += len(spawned["pixel"])
        queue = {key: torch.cat((queue[key][head:], spawned[key])) for key in queue}
        head = 0
        pool["pixel"][lane] = -1  # every slot finished its item this step
    active = stats["active_lanes"]
    stats["idle_fraction"] = 1 - sum(active) / (pool_size * len(active)) if active else 0.0
    return image, stats
    # END SOLUTION
