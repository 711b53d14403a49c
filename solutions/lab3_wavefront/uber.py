"""Task 3: ``render_uber``, the bounce loop as one fused program over fixed-size lane buffers
(two step functions ``torch.compile`` captures whole).
"""

from __future__ import annotations

import functools
import math

import torch

from course.given.lab3 import (
    MAX_DEPTH,
    WhittedScene,
    check_render_inputs,
    dot,
    normalize,
    offset_scale,
)


# BEGIN SOLUTION
def _uber_shadow_rays(
    vertices,
    faces,
    mat_table,
    point_positions,
    point_intensities,
    dir_directions,
    dir_irradiance,
    eps: float,
    o,
    d,
    t,
    triangle,
    alive,
):
    """Surface and shadow rays of all N lanes x L lights (static shapes, no branches)."""
    hit = alive & (triangle >= 0)
    tri = triangle.clamp(min=0)
    c = vertices[faces[tri]]
    normal = normalize(torch.linalg.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0], dim=-1))
    normal = torch.where((dot(normal, d) > 0)[:, None], -normal, normal)
    p = o + torch.where(hit, t, 0.0)[:, None] * d
    p_off = p + normal * (eps * p.abs().amax(dim=1, keepdim=True).clamp(min=1))
    to = point_positions[None] - p_off[:, None]
    dist = to.norm(dim=-1)
    n, nd = o.shape[0], dir_directions.shape[0]
    l = torch.cat((to / dist[..., None], dir_directions.expand(n, nd, 3)), 1)
    irradiance = torch.cat(
        (point_intensities / (dist**2)[..., None], dir_irradiance.expand(n, nd, 3)), 1
    )
    light_offset = eps * point_positions.abs().amax(dim=1).clamp(min=1)
    t_max = torch.cat(
        (dist - light_offset, torch.full((n, nd), math.inf, dtype=dist.dtype, device=dist.device)),
        1,
    )
    cos = dot(normal[:, None], l)
    needed = hit[:, None] & (cos > 0)
    t_max = torch.where(needed, t_max, -math.inf)  # an empty interval: an idle lane
    return hit, tri, normal, p_off, l, irradiance, cos, needed, t_max


def _uber_shade(
    material,
    kd,
    ks,
    shininess,
    kr,
    ambient,
    background,
    d,
    throughput,
    alive,
    hit,
    tri,
    normal,
    p_off,
    l,
    irradiance,
    cos,
    needed,
    blocked,
    image,
    more: bool,
):
    """Shading and spawning of all N lanes (static shapes, no branches)."""
    m = material[tri]
    s = shininess[m]
    half = normalize(l - d[:, None])
    n_dot_h = dot(normal[:, None], half).clamp(min=0)
    lobe = ((s + 8) / (8 * math.pi))[:, None] * n_dot_h ** s[:, None]
    brdf = kd[m][:, None] / math.pi + ks[m][:, None] * lobe[..., None]
    lit = needed & ~blocked
    direct = ambient * kd[m] + torch.where(
        lit[..., None], irradiance * cos[..., None] * brdf, 0.0
    ).sum(1)
    image = image + throughput * torch.where(
        hit[:, None], direct, torch.where(alive[:, None], background, 0.0)
    )
    alive = hit & (kr[m] > 0).any(dim=1) & more
    throughput = torch.where(alive[:, None], throughput * kr[m], 0.0)
    r = normalize(d - 2 * dot(d, normal)[:, None] * normal)
    return image, throughput, alive, p_off, r


@functools.cache
def _compiled(backend):
    return (
        torch.compile(_uber_shadow_rays, backend=backend, fullgraph=True, dynamic=True),
        torch.compile(_uber_shade, backend=backend, fullgraph=True, dynamic=True),
    )


# END SOLUTION


def render_uber(
    scene: WhittedScene,
    origins: torch.Tensor,
    directions: torch.Tensor,
    trace,
    max_depth: int = MAX_DEPTH,
    compile=False,
) -> torch.Tensor:
    """The bounce loop as one fused program over fixed-size lane buffers.

    Same arguments and image as :func:`render_whitted`; compile: False (eager), True
    (``torch.compile`` with inductor) or a ``torch.compile`` backend, by name (e.g.
    ``"eager"``: capture only) or a callable (``backend=`` of ``torch.compile``). Returns
    (N, 3).

    A GPU uber kernel is one thread per pixel running TRAVERSE -> INTERSECT -> SHADE ->
    (reflect) as a state machine: no ray state goes back to memory between stages, but a
    thread whose ray is done idles until its whole warp is. Write the torch analogue: N
    lanes (and N x L shadow lanes) whose buffers **never change size**. Each bounce:

    1. ``trace`` all N lanes (dead lanes: an empty interval);
    2. a step function builds the hits' surfaces and all N x L shadow rays (an empty
       interval where a lane is dead or ``n . l <= 0``);
    3. ``trace`` all N x L shadow lanes with ``any_hit=True``;
    4. a step function shades, accumulates the image and spawns (``torch.where``).

    The two step functions must contain no data-dependent shapes (no ``x[mask]``,
    ``nonzero``, ``.item()``, ``if`` on tensor values), so ``torch.compile(step,
    backend=..., fullgraph=True)`` captures each as one graph of fixed-size tensors and
    fuses it (the grader inspects the captured graphs); the tracer stays outside (on a GPU
    the Triton uber kernel fuses the traversal too: ``course.kernels.triton_tracer``).

    Errors (the provided check): ValueError or TypeError naming ``scene`` (not a
    ``WhittedScene``, a scene without ``lights``, a ``material`` index beyond its table),
    ``origins`` or ``directions`` (a wrong shape; TypeError for half precision or a dtype
    other than the scene's), ``trace`` (not callable) or ``max_depth`` (not an int >= 0).
    TypeError naming ``compile`` for a value of another type.

    Hints: pass the scene's tensors to the step functions one by one (not the dataclass);
    cache the compiled functions (``functools.cache``) so a second call does not recompile.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    n = check_render_inputs(  # noqa: F841 (n: the number of rays, for your code)
        scene, origins, directions, trace, max_depth
    )
    if not (isinstance(compile, (bool, str)) or callable(compile)):
        raise TypeError(
            f"compile: expected a bool or a torch.compile backend (a name or a "
            f"callable), got {compile!r}"
        )
    # BEGIN SOLUTION (task 3)
    if compile:
        shadow_step, shade_step = _compiled("inductor" if compile is True else compile)
    else:
        shadow_step, shade_step = _uber_shadow_rays, _uber_shade
    lights = scene.num_point_lights + scene.num_dir_lights
    image = torch.zeros(n, 3, dtype=scene.dtype, device=scene.device)
    throughput = torch.ones_like(image)
    alive = torch.ones(n, dtype=torch.bool, device=scene.device)
    o, d = origins, directions
    zeros = torch.zeros(n, dtype=scene.dtype, device=scene.device)
    eps = offset_scale(scene.dtype)
    for depth in range(max_depth + 1):
        hits = trace(scene, o, d, zeros, torch.where(alive, math.inf, -math.inf), False)
        hit, tri, normal, p_off, l, irradiance, cos, needed, t_max = shadow_step(
            scene.vertices,
            scene.faces,
            scene.material,
            scene.point_positions,
            scene.point_intensities,
            scene.dir_directions,
            scene.dir_irradiance,
            eps,
            o,
            d,
            hits.t,
            hits.triangle,
            alive,
        )
        # All N x L shadow lanes are traced; the unneeded ones have an empty interval.
        blocked = trace(
            scene,
            p_off[:, None].expand(n, lights, 3).reshape(-1, 3),
            l.reshape(-1, 3),
            torch.zeros_like(t_max).reshape(-1),
            t_max.reshape(-1),
            True,
        ).hit.reshape(n, lights)
        image, throughput, alive, o, d = shade_step(
            scene.material,
            scene.kd,
            scene.ks,
            scene.shininess,
            scene.kr,
            scene.ambient,
            scene.background,
            d,
            throughput,
            alive,
            hit,
            tri,
            normal,
            p_off,
            l,
            irradiance,
            cos,
            needed,
            blocked,
            image,
            depth < max_depth,
        )
    return image
    # END SOLUTION
