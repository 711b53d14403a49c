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
    # BEGIN SOLUTION (task 1)
    scale = points.abs().amax(dim=1, keepdim=True).clamp(min=1)
    return points + normals * (offset_scale(points.dtype) * scale)
    # END SOLUTION


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
    # BEGIN SOLUTION (task 1)
    return normalize(directions - 2 * dot(directions, normals)[:, None] * normals)
    # END SOLUTION


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
    # BEGIN SOLUTION (task 1)
    if not isinstance(hits, Hits) or len(hits) != n:
        raise TypeError(
            f"hits: expected course.core.types.Hits for {n} rays, got {type(hits).__name__}"
        )
    hit = hits.hit
    tri = hits.triangle.clamp(min=0)
    t = torch.where(hit, hits.t, 0.0)
    points = torch.where(hit[:, None], origins + t[:, None] * directions, 0.0)
    normals = face_normals(scene)[tri]
    # Face the ray: shading and offsets happen on the side the ray arrives from.
    normals = torch.where((dot(normals, directions) > 0)[:, None], -normals, normals)
    normals = torch.where(hit[:, None], normals, 0.0)
    material = torch.where(hit, scene.material[tri], -1)
    return points, normals, material
    # END SOLUTION


# BEGIN SOLUTION
def _light_rays(scene: WhittedScene, p_off: torch.Tensor):
    """Per (hit, light): unit direction to the light (n, L, 3), irradiance (n, L, 3) and the
    shadow ray's t_max (n, L); point lights first, then directional lights."""
    eps = offset_scale(scene.dtype)
    to = scene.point_positions[None] - p_off[:, None]  # (n, P, 3)
    dist = to.norm(dim=-1)
    light_offset = eps * scene.point_positions.abs().amax(dim=1).clamp(min=1)
    n, d = p_off.shape[0], scene.num_dir_lights
    directions = torch.cat((to / dist[..., None], scene.dir_directions.expand(n, d, 3)), 1)
    irradiance = torch.cat(
        (scene.point_intensities / (dist**2)[..., None], scene.dir_irradiance.expand(n, d, 3)), 1
    )
    t_max = torch.cat(
        (dist - light_offset, torch.full((n, d), math.inf, dtype=dist.dtype, device=dist.device)), 1
    )
    return directions, irradiance, t_max


# END SOLUTION


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
    # BEGIN SOLUTION (task 1)
    kd, ks, s = scene.kd[material], scene.ks[material], scene.shininess[material]
    radiance = scene.ambient * kd
    if n == 0:
        return radiance, 0
    p_off = offset_origins(points, normals)
    l, irradiance, t_max = _light_rays(scene, p_off)
    cos = dot(normals[:, None], l)  # (n, L)
    # Only lights above the surface can contribute: only they get a shadow ray.
    row, light = (cos > 0).nonzero(as_tuple=True)
    blocked = trace(
        scene,
        p_off[row],
        l[row, light],
        torch.zeros_like(t_max[row, light]),
        t_max[row, light],
        True,
    ).hit
    lit = torch.zeros_like(cos, dtype=torch.bool)
    lit[row, light] = ~blocked
    half = normalize(l - directions[:, None])  # h = normalize(l + v)
    n_dot_h = dot(normals[:, None], half).clamp(min=0)
    lobe = ((s + 8) / (8 * math.pi))[:, None] * n_dot_h ** s[:, None]
    brdf = kd[:, None] / math.pi + ks[:, None] * lobe[..., None]
    light_sum = torch.where(lit[..., None], irradiance * cos[..., None] * brdf, 0.0).sum(1)
    return radiance + light_sum, int(row.numel())
    # END SOLUTION


# BEGIN SOLUTION
def _is_mirror(scene: WhittedScene, material: torch.Tensor) -> torch.Tensor:
    return (scene.kr[material] > 0).any(dim=1)


# END SOLUTION


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
    # BEGIN SOLUTION (task 1)
    image = torch.zeros(n, 3, dtype=scene.dtype, device=scene.device)
    throughput = torch.ones_like(image)
    alive = torch.ones(n, dtype=torch.bool, device=scene.device)
    o, d = origins, directions
    zeros = torch.zeros(n, dtype=scene.dtype, device=scene.device)
    for depth in range(max_depth + 1):
        # Every lane is traced every bounce; dead lanes get an empty interval.
        hits = trace(scene, o, d, zeros, torch.where(alive, math.inf, -math.inf), False)
        hit = hits.hit & alive
        image = image + torch.where((alive & ~hit)[:, None], throughput * scene.background, 0.0)
        points, normals, material = surface_at(scene, o, d, hits)
        direct, _ = shade_direct(scene, points[hit], normals[hit], d[hit], material[hit], trace)
        image[hit] += throughput[hit] * direct
        alive = hit & _is_mirror(scene, material.clamp(min=0)) & (depth < max_depth)
        throughput = torch.where(alive[:, None], throughput * scene.kr[material.clamp(min=0)], 0.0)
        o = torch.where(alive[:, None], offset_origins(points, normals), o)
        d = torch.where(alive[:, None], reflect(d, normals), d)
        if not bool(alive.any()):
            break
    return image
    # END SOLUTION
