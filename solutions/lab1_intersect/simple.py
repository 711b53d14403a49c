"""Task 1: ``intersect_simple``, the lecture's first test: intersect the plane, then test
the point by the signed areas of the sub-triangles.
"""

from __future__ import annotations

import math

import torch

from course.core.raymath import check_triangle_inputs, cross, dot, masked_result


def intersect_simple(origins, directions, v0, v1, v2, t_min=0.0, t_max=math.inf):
    """The lecture's first test: intersect the plane, then test the point by areas.

    origins, directions: (..., 3) float; v0, v1, v2: (..., 3) float, the corners;
    t_min, t_max: numbers or tensors broadcastable with the result.
    Returns ``(t, u, v)`` of the broadcast shape.

    1. The plane through the triangle has the (unnormalised) normal ``n = e1 x e2``,
       ``e1 = v1 - v0``, ``e2 = v2 - v0``; the ray meets it at
       ``t = n . (v0 - o) / (n . d)`` (no hit when ``n . d == 0``: parallel ray).
    2. At ``p = o + t d``, the three sub-triangles ``(p, v1, v2)``, ``(p, v2, v0)``,
       ``(p, v0, v1)`` have signed areas ``A_i = n . ((vj - p) x (vk - p)) / 2|n|``;
       ``p`` is inside when all three are >= 0.
    3. The barycentrics are the area ratios ``u = A_1 / A``, ``v = A_2 / A`` with the full
       area ``A = |n| / 2`` (compared in units of ``|n|^2`` to avoid square roots).
    4. A ray nearly parallel to the plane crosses it far away (``t`` up to ~1e7 for
       ``cos = 1e-7``). There the differences ``vj - p`` round to almost the same vector, the
       areas to noise of size ``eps |v - p|^2 |n|`` (often exactly 0, which passes ``>= 0``):
       a false hit. Accept only where ``16 eps R^2 |n|_max <= n . n``, with
       ``R = |v0 - p|_max + max(|e1|_max, |e2|_max)`` bounding every ``|vi - p|_max`` and
       ``eps = torch.finfo(dtype).eps``: beyond about ``1 / sqrt(16 eps)`` triangle sizes
       (700 in float32) the test cannot tell inside from outside. It costs real hits only on
       slivers (``|n| < 64 eps |e|_max^2``).

    Accuracy: not watertight (neighbouring triangles round ``p`` and their areas
    differently), and ``p`` carries the error of ``t`` into the inside test.

    Errors (the provided check): ValueError or TypeError naming ``origins``,
    ``directions``, ``v0``, ``v1``, ``v2``, ``t_min`` or ``t_max`` for a wrong shape, a
    non-float dtype, mixed dtypes or devices, or shapes that do not broadcast.

    Hints: ``cross`` and ``dot`` are provided; build the hit mask from the
    comparisons and finish with ``masked_result(hit, t, u, v)``.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    t_min, t_max = check_triangle_inputs(origins, directions, v0, v1, v2, t_min, t_max)
    # BEGIN SOLUTION (task 1)
    e1, e2 = v1 - v0, v2 - v0
    n = cross(e1, e2)
    # Per triangle, for step 4: its size and the rounding scale of its areas.
    size = torch.maximum(e1.abs().amax(-1), e2.abs().amax(-1))
    noise = 16 * torch.finfo(n.dtype).eps * n.abs().amax(-1)
    nn = dot(n, n)
    denom = dot(n, directions)
    t = dot(n, v0 - origins) / denom
    p = origins + t[..., None] * directions
    a0 = dot(cross(v1 - p, v2 - p), n)
    a1 = dot(cross(v2 - p, v0 - p), n)
    a2 = dot(cross(v0 - p, v1 - p), n)
    # Step 4: the areas' rounding error, ~eps |v - p|^2 |n|, must stay below n . n.
    reach = (v0 - p).abs().amax(-1) + size
    resolved = noise * reach * reach <= nn
    inv_area = 1 / nn
    hit = (denom != 0) & resolved & (a0 >= 0) & (a1 >= 0) & (a2 >= 0) & (t >= t_min) & (t <= t_max)
    return masked_result(hit, t, a1 * inv_area, a2 * inv_area)
    # END SOLUTION
