"""Task 2: ``moller_trumbore``, Möller & Trumbore's test by Cramer's rule, with a parallel
test relative to the ray's and the triangle's size.
"""

from __future__ import annotations

import math

import torch

from course.core.raymath import check_triangle_inputs, cross, dot, masked_result


def moller_trumbore(origins, directions, v0, v1, v2, t_min=0.0, t_max=math.inf):
    """Möller & Trumbore 1997: solve ``o + t d = v0 + u e1 + v e2`` by Cramer's rule.

    Same arguments and results as :func:`intersect_simple`.

    With ``p = d x e2``, ``det = e1 . p``, ``s = o - v0``, ``q = s x e1``:
    ``u = s . p / det``, ``v = d . q / det``, ``t = e2 . q / det``; inside when
    ``u >= 0, v >= 0, u + v <= 1``.

    The parallel test is *relative*: ``|det| <= eps * |d| |e1| |e2|`` (max-norms) means the
    ray is parallel to the plane to within rounding. The textbook absolute test
    ``|det| < 1e-6`` instead rejects every triangle smaller than about 1e-3 (``det`` scales
    with the triangle's area) and accepts garbage for huge ones.

    Accuracy: not watertight (each triangle computes the shared edge from its own ``v0``).

    Errors: as :func:`intersect_simple`, ValueError or TypeError naming ``origins``,
    ``directions``, ``v0``, ``v1``, ``v2``, ``t_min`` or ``t_max``.

    Hints: ``torch.finfo(dtype).eps``; ``x.abs().amax(-1)`` is a max-norm.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    t_min, t_max = check_triangle_inputs(origins, directions, v0, v1, v2, t_min, t_max)
    raise NotImplementedError("not implemented yet: moller_trumbore (task 2)")
