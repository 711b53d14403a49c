"""Task 5: boxes and spheres: ``safe_reciprocal`` (``1 / d`` keeping the sign of zero),
``ray_box`` (the slab test) and ``ray_sphere`` (the quadratic, without cancellation).
"""

from __future__ import annotations

import math

import torch

from course.core.raymath import check_inputs, dot, gamma


def safe_reciprocal(directions):
    """``1 / d`` per component, keeping the sign of zero: ``1/+0 = +inf``, ``1/-0 = -inf``.

    directions: (..., 3) float. IEEE division already does this; the point of the
    function is that nothing replaces zeros by a small epsilon (which would turn an
    axis-parallel ray into a slightly tilted one) or drops the sign of ``-0.0``.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    check_inputs({"directions": (directions, (3,))})
    raise NotImplementedError("not implemented yet: safe_reciprocal (task 5)")


def ray_box(origins, inv_directions, box_min, box_max, t_min=0.0, t_max=math.inf):
    """Slab test of rays against axis-aligned boxes (Kay & Kajiya; Ize 2013).

    origins, inv_directions: (..., 3) float, ``inv_directions = safe_reciprocal(d)``;
    box_min, box_max: (..., 3) float; t_min, t_max: numbers or tensors broadcastable with
    the result. Returns ``(t_near, t_far, hit)`` of the broadcast shape: the parametric
    interval of the ray inside the box clipped to ``[t_min, t_max]`` (float, meaningful where
    ``hit``) and ``hit`` (bool)::

        hit = (t_near <= t_far) & (t_near < inf) & finite origin
              & every |inv_direction| > 0 (no NaN, no infinite direction) & box_min <= box_max

    Per axis the slab gives ``t0 = (min - o) / d``, ``t1 = (max - o) / d``, ordered by
    min/max; the box interval is the intersection of the three slabs and ``[t_min, t_max]``.
    * Axis-parallel rays: ``1/±0 = ±inf`` puts the slab at ``[-inf, inf]`` (inside it) or
      entirely at one infinity (outside it). On the far side that is ``[-inf, -inf]``
      (``t_far = -inf``: miss); on the near side ``[inf, inf]``, so ``t_near = t_far = inf``
      with ``t_max = inf``, where ``inf <= inf`` holds: hence ``t_near < inf`` above.
    * A ray starting *on* a slab plane with ``d = 0`` gives ``0 * inf = NaN``: that slab
      says nothing, so the reduction over the slabs drops NaN (``fmax``/``fmin``).
    * Conservative: ``t_far`` is scaled by ``1 + 2 gamma(3)`` (Ize 2013, "Robust BVH Ray
      Traversal"), so rounding never turns a hit into a miss (a few ``gamma(3)`` is as good:
      ``t_far`` is graded to about 1e-5, and a ray missing the box by less may go either
      way); an empty box (``min > max`` on any axis; a flat box ``min == max`` is not empty)
      and a ray with NaN/inf components never hit.

    Errors: ValueError or TypeError naming ``origins``, ``inv_directions``, ``box_min``,
    ``box_max``, ``t_min`` or ``t_max`` (the provided check).

    Hints: ``torch.minimum``/``maximum`` keep NaN, ``torch.fmin``/``fmax`` drop it.
    """
    # Provided: validates the arguments; s: {name: tensor}, the scalars in the kernel's dtype.
    _, s = check_inputs(
        {
            "origins": (origins, (3,)),
            "inv_directions": (inv_directions, (3,)),
            "box_min": (box_min, (3,)),
            "box_max": (box_max, (3,)),
        },
        {"t_min": t_min, "t_max": t_max},
    )
    raise NotImplementedError("not implemented yet: ray_box (task 5)")


def ray_sphere(origins, directions, center, radius, t_min=0.0, t_max=math.inf):
    """Nearest intersection of rays with spheres in ``[t_min, t_max]``; ``inf`` for a miss.

    origins, directions, center: (..., 3) float; radius: number or tensor (...) float.
    Returns ``t`` of the broadcast shape.

    ``|f + t d|^2 = r^2`` with ``f = o - c``: ``a t^2 + 2 b t + c = 0``, ``a = d.d``,
    ``b = f.d``, ``c = f.f - r^2``. Two precision fixes (Ray Tracing Gems, ch. 7):
    * the discriminant ``b^2 - a c`` cancels catastrophically for a small sphere far away;
      the equal ``a (r^2 - |l|^2)`` with ``l = f - (b/a) d`` (the part of ``f``
      perpendicular to the ray) does not;
    * ``q = -(b + sign(b) sqrt(disc))``, roots ``c / q`` and ``q / a``: no subtraction of
      nearly equal numbers for the smaller root.
    The nearer root in ``[t_min, t_max]`` wins, else the farther (a ray starting inside the
    sphere, or spawned on it with ``t_min > 0``, finds the far side). NaN/inf origins or
    directions, a zero direction and a negative radius give ``inf``, never NaN.

    Errors: ValueError or TypeError naming ``origins``, ``directions``, ``center``,
    ``radius``, ``t_min`` or ``t_max`` (the provided check).

    Hints: ``torch.copysign(x, b)`` is ``sign(b) |x|`` with a sign for zero.
    """
    # Provided: validates the arguments; s: {name: tensor}, the scalars in the kernel's dtype.
    _, s = check_inputs(
        {"origins": (origins, (3,)), "directions": (directions, (3,)), "center": (center, (3,))},
        {"radius": radius, "t_min": t_min, "t_max": t_max},
    )
    raise NotImplementedError("not implemented yet: ray_sphere (task 5)")
