"""Task 1: Whitted building blocks and backward tracing: ``offset_origins``, ``reflect``,
``surface_at``, ``shade_direct`` and ``render_whitted``, one loop over full-size buffers.
"""

from __future__ import annotations

import math

import torch

from course.core.types import Hits
from course.given.lab3 import (
    MAX_DEPTH,
    WhittedScene,
    check_render_inputs,
    check_scene,
    check_surface_inputs,
    check_vectors,
    dot,
    face_normals,
    normalize,
    offset_scale,
)


def offset_origins(points: torch.Tensor, normals: torch.Tensor) -> torch.Tensor:
    """Secondary-ray origins lifted off the surface along its normal.

    points: (N, 3) hit points; normals: (N, 3) unit normals facing the incoming ray; both
    float32 or float64. Returns (N, 3): ``p + n * offset * max(1, |p|_inf)`` with
    ``offset = offset_scale(points.dtype)`` (1e-4 in float32).

    Why: the hit point ``p = o + t d`` is rounded, so it lies a little above or *below* the
    surface. A shadow or reflected ray started there can hit its own triangle at ``t ~ 0``:
    speckled self-shadowing ("acne"). Lifting the origin along the normal by more than the
    rounding error cures it; the rounding grows with the coordinates' magnitude, hence the
    ``max(1, |p|_inf)`` (at 1e5 a fixed offset would vanish in the rounding).

    Errors: ValueError or TypeError naming ``points`` or ``normals`` for a wrong shape or
    unequal lengths; TypeError for float16/bfloat16 (too coarse to hold the offset).

    Hints: ``points.abs().amax(dim=1, keepdim=True).clamp(min=1)``.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    check_vectors(None, points=points, normals=normals)
    raise NotImplementedError("not implemented yet: offset_origins (task 1)")


def reflect(directions: torch.Tensor, normals: torch.Tensor) -> torch.Tensor:
    """Mirror reflection: ``r = d - 2 (d . n) n``, renormalised to unit length.

    directions: (N, 3) unit incoming directions; normals: (N, 3) unit normals. Returns
    (N, 3) unit. The normal component of ``d`` flips, the tangential one stays; the result
    does not depend on which side ``n`` faces (but the *origin* of the reflected ray does:
    it is offset to the side the ray came from). A grazing ``d`` (``d . n = 0``) goes on
    unchanged.

    Errors: ValueError or TypeError naming ``directions`` or ``normals`` (wrong shape or
    unequal lengths).

    Hints: ``dot`` and ``normalize`` are given.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    check_vectors(None, directions=directions, normals=normals)
    raise NotImplementedError("not implemented yet: reflect (task 1)")


def surface_at(scene: WhittedScene, origins: torch.Tensor, directions: torch.Tensor, hits: Hits):
    """What a ray sees at its hit: ``(points, normals, material)``.

    scene: the scene; origins, directions: (N, 3) the rays; hits: their ``Hits`` from
    ``trace``. Returns

    * points: (N, 3) ``o + t d`` at the hit;
    * normals: (N, 3) the unit geometric normal of the hit triangle (``face_normals``),
      **flipped to face the ray** (``n . d <= 0``): shading and offsets happen on the side
      the ray arrives from, whichever way the triangle is wound;
    * material: (N,) int64 ``scene.material[triangle]``.

    Rays that missed get points and normals 0 and material -1 (``t = inf`` must not turn
    into ``inf * 0 = NaN`` anywhere).

    ``hits`` is taken as given: the ``Hits`` of these N rays from ``trace``. Any other value
    is outside the contract (it need not be checked, nor raise any particular error).

    Errors (the provided check): ValueError or TypeError naming ``scene``, ``origins`` or
    ``directions``.

    Hints: ``hits.hit`` is the mask of hits; index with ``hits.triangle.clamp(min=0)`` and
    mask the misses with ``torch.where``.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    check_scene(scene)
    n = check_vectors(  # noqa: F841 (n: the number of rays, for your code)
        scene.vertices, origins=origins, directions=directions
    )
    raise NotImplementedError("not implemented yet: surface_at (task 1)")


def shade_direct(
    scene: WhittedScene,
    points: torch.Tensor,
    normals: torch.Tensor,
    directions: torch.Tensor,
    material: torch.Tensor,
    trace,
):
    """Ambient and direct light at N hits, with a shadow ray per visible light.

    points: (N, 3) hit points ``p`` (not offset); normals: (N, 3) unit, facing the ray;
    directions: (N, 3) the incoming rays' unit directions ``d``; material: (N,) int64;
    trace: the tracer. Returns ``(radiance (N, 3), shadow_rays)``: ``shadow_rays`` (int) is
    the number of shadow rays traced.

    Per the contract (``course.given.lab3``), with ``p_off = offset_origins(p, n)``,
    ``v = -d``, ``s = shininess[m]``::

        L = ambient * kd[m]
          + sum over lights with n . l > 0 and an unblocked shadow ray (p_off, l):
                E (n . l) (kd[m] / pi + ks[m] (s + 8) / (8 pi) max(0, n . h)^s)

    with ``h = normalize(l + v)``. Point light ``i``: ``l = (P_i - p_off) / dist``, ``E = I_i /
    dist^2``; its shadow ray looks for any hit in ``[0, dist - offset * max(1, |P_i|_inf)]``: it
    must **stop short of the light** (a lamp on a wall is not hidden by that wall, and nothing
    behind the lamp shadows it). Directional light ``j``: ``l = dir_directions[j]``, ``E =
    dir_irradiance[j]``, ``t_max = inf``.

    Trace only the shadow rays that can matter: toward lights with ``n . l > 0`` (the
    others cannot contribute) -- all of them in **one** ``trace(..., any_hit=True)`` call.

    Errors (the provided check): ValueError or TypeError naming ``scene``, ``points``,
    ``normals``, ``directions``, ``material`` (not int64, or an index beyond the material
    table) or ``trace`` (not callable); TypeError naming ``points`` for a dtype other than
    the scene's.

    Hints: work on ``(N, L, 3)`` tensors (point lights then directional ones, ``torch.cat``);
    ``(cos > 0).nonzero(as_tuple=True)`` lists the (hit, light) pairs that need a shadow ray.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    n = check_surface_inputs(  # noqa: F841 (n: the number of points, for your code)
        scene, points, normals, directions, material, trace
    )
    raise NotImplementedError("not implemented yet: shade_direct (task 1)")


def render_whitted(
    scene: WhittedScene,
    origins: torch.Tensor,
    directions: torch.Tensor,
    trace,
    max_depth: int = MAX_DEPTH,
) -> torch.Tensor:
    """Backward (Whitted) ray tracing, one loop over bounces on full-size buffers.

    scene; origins, directions: (N, 3) primary rays; trace: the tracer; max_depth: the
    number of reflections a path may take (0: primary rays only). Returns (N, 3) radiance.

    Keep per pixel a ray, a throughput (3,) (the product of the mirrors' ``kr`` so far) and
    an ``alive`` flag. Each bounce ``depth = 0 .. max_depth``:

    1. trace **all N** rays (a dead one with an empty interval, e.g. ``t_max = -inf``);
    2. a live ray that missed adds ``throughput * background``;
    3. a live ray that hit adds ``throughput * shade_direct(...)``;
    4. it lives on if its material reflects (``any(kr > 0)``) and ``depth < max_depth``:
       new ray ``(offset_origins(p, n), reflect(d, n))``, throughput ``*= kr[m]``.

    Adding ``throughput * (direct at each bounce)`` is the recursion ``L = direct + kr *
    L(reflected)`` unrolled. Stop early once no ray is alive.

    Errors (the provided check): ValueError or TypeError naming ``scene`` (not a
    ``WhittedScene``, a scene without ``lights``, a ``material`` index beyond its table),
    ``origins`` or ``directions`` (a wrong shape; TypeError for half precision or a dtype
    other than the scene's), ``trace`` (not callable) or ``max_depth`` (not an int >= 0).

    Hints: ``surface_at``, ``shade_direct`` (on the hits: ``x[hit]``), ``offset_origins``,
    ``reflect``, and ``torch.where(alive[:, None], new, old)`` to update the buffers.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    n = check_render_inputs(  # noqa: F841 (n: the number of rays, for your code)
        scene, origins, directions, trace, max_depth
    )
    raise NotImplementedError("not implemented yet: render_whitted (task 1)")
