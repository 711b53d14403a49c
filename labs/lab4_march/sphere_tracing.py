"""Task 5: ``sphere_trace``, signed-distance scenes traced with over-relaxation."""

from __future__ import annotations

import math

import torch

from course.given.lab4 import HIT, MISS, UNSURE, check_trace_inputs


def sphere_trace(
    origins, directions, sdf, t_max=100.0, max_steps=128, epsilon=1e-4, relaxation=1.0
):
    """Sphere tracing (Hart 1996) with over-relaxation (Keinert et al. 2014).

    origins, directions: (N, 3); sdf: callable ``points (N, 3) -> (N,)``, a signed distance
    (negative inside; a lower bound of the distance is enough); t_max: finite number > 0,
    rays that get beyond it miss (inf raises ValueError: the relative hit test accepts any
    distance ``|f|`` once ``t >= |f| / epsilon``); max_steps: int >= 1, sdf evaluations per
    ray at most; epsilon: number in (0, 1), the hit tolerance *relative to the distance*;
    relaxation: omega in [1, 2).
    Returns a dict: ``t`` (N,) (the hit's ray parameter, inf unless HIT), ``status`` (N,)
    int64 (``MISS``, ``HIT`` or ``UNSURE``) and ``steps`` (N,) int64 (sdf evaluations).

    From ``t = 0``: evaluate ``f = sdf(o + t d)``; a hit when ``|f| <= epsilon t |d|``
    (the surface is nearer than the ray's footprint: a relative tolerance works at 1e-3 and
    at 1e5 alike); else step ``t += omega |f| / |d|`` (no surface is nearer than ``|f|``).
    A ray starting inside (``f < 0``) steps by ``|f|`` too and finds where it leaves the
    solid. Over-relaxation steps further (omega > 1) while the unbounding spheres of
    consecutive points overlap, ``|f_prev| + |f| >= step``; when they do not, a surface may
    lie in the gap, so the ray goes back to ``t_prev + |f_prev| / |d|`` (the last safe step)
    and continues with omega = 1. A ray past ``t_max`` misses; one still undecided after
    ``max_steps`` evaluations (grazing a surface, where the steps shrink) is ``UNSURE``,
    never a hit. NaN/inf rays, zero directions and NaN distances are misses.

    Errors: ValueError or TypeError naming ``origins`` or ``directions`` as in
    ``ray_box_interval``; TypeError naming ``sdf`` unless it is callable (ValueError when it
    returns a tensor not of shape (N,)); TypeError or ValueError naming ``max_steps`` unless
    it is an int >= 1; ValueError naming ``t_max`` (not a finite number > 0), ``epsilon``
    (not a number in (0, 1)) or ``relaxation`` (not a number in [1, 2)).

    Hints: per-ray state ``t``, ``status``, ``steps``, ``omega``, and for the
    over-relaxation check the previous ``|f|`` and the previous step's world length. Update
    everything with ``torch.where`` on an ``active`` mask; stop the loop early when no ray
    is active.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    origins, directions = check_trace_inputs(
        origins, directions, sdf, t_max, max_steps, epsilon, relaxation
    )
    raise NotImplementedError("not implemented yet: sphere_trace (task 5)")
