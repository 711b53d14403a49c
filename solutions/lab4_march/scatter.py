"""Task 3: single scattering of a directional light: ``henyey_greenstein`` (the phase
function), ``shadow_transmittance`` (toward the light) and ``march_single_scatter`` (the
in-scattered light, marched by ``march_box``).
"""

from __future__ import annotations

import math

import torch

from course.core.raymath import dot
from course.given.lab4 import check_phase_inputs, check_scatter_inputs, check_shadow_inputs

from .march import check_density_defined, evaluate, march_box, ray_box_interval


def henyey_greenstein(cos_theta, g):
    """The Henyey–Greenstein phase function, normalised over the sphere.

    cos_theta: (...) float, the cosine between the light's direction of travel and the
    scattered light's direction of travel (for a camera ray ``d`` and a light *toward*
    ``l``: ``cos_theta = d . l``, both unit); g: number or tensor in (-1, 1) that
    broadcasts, the mean cosine (g > 0 scatters forward: the medium glows around the
    light). Returns (...) float:

        p = (1 - g^2) / (4 pi (1 + g^2 - 2 g cos_theta)^(3/2)),   int p dw = 1.

    ``cos_theta`` outside [-1, 1] (unit vectors' dot product a rounding step past +-1) is
    clamped to [-1, 1], so the value stays finite and positive.
    ``g = 0`` is isotropic, ``1 / (4 pi)``. The denominator is computed as a sum of
    non-negative terms, ``(1 - g)^2 + 2 g (1 - cos)`` for g >= 0 and
    ``(1 + g)^2 - 2 g (1 + cos)`` for g < 0, so it does not cancel at the peak when
    |g| -> 1 (there ``1 + g^2 - 2 g`` loses every digit).

    Errors: TypeError naming ``cos_theta`` unless it is a float tensor; TypeError naming
    ``g`` unless it is a number or a tensor of the cos_theta's dtype and device; ValueError
    naming ``g`` for a value outside (-1, 1).

    Hints: compute both denominators and pick with ``torch.where(g >= 0, ...)``;
    ``(1 - g) * (1 + g)`` for the numerator; ``base * base.sqrt()`` is ``base^(3/2)``.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    g = check_phase_inputs(cos_theta, g)
    # BEGIN SOLUTION (task 3)
    cos_theta = cos_theta.clamp(-1, 1)
    base = torch.where(
        g >= 0, (1 - g) ** 2 + 2 * g * (1 - cos_theta), (1 + g) ** 2 - 2 * g * (1 + cos_theta)
    )
    return (1 - g) * (1 + g) / (4 * math.pi * base * base.sqrt())
    # END SOLUTION


def shadow_transmittance(points, light_direction, box_min, box_max, density, steps=16):
    """Transmittance from each point toward a directional light, to where it leaves the box.

    points: (N, 3) float; light_direction: (3,), toward the light (any length);
    box_min, box_max: (3,); density: callable or grid (NaN values raise ValueError);
    steps: int >= 0. Returns (N,): ``exp(-sum_k sigma_k dt)``, a midpoint-rule march of
    ``steps`` equal steps over the part of the ray ``p + t l`` (unit ``l``, ``t >= 0``)
    inside the box: exact for a homogeneous medium with one step, second order for a
    smooth one. Points whose light ray misses the box, NaN points and ``steps = 0`` give 1
    (unshadowed).

    Errors: TypeError or ValueError naming ``points`` (not an (N, 3) float tensor),
    ``box_min`` / ``box_max`` as in ``ray_box_interval``, ``light_direction`` (not a finite,
    non-zero (3,) tensor of the points' dtype and device or 3 numbers), ``density`` (as in
    ``march_box``: ValueError for negative or NaN values) or ``steps`` (not an int >= 0).

    Hints: ``ray_box_interval`` from the points along the (already unit, from the
    provided check) light direction; loop over the steps summing ``sigma * dt`` (0 where the
    ray misses the box); ``exp`` at the end.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    points, light, box_min, box_max = check_shadow_inputs(
        points, light_direction, box_min, box_max, density, steps
    )
    if isinstance(density, torch.Tensor):
        check_density_defined(density)
    # BEGIN SOLUTION (task 3)
    light = light.expand_as(points)
    t_near, t_far, hit = ray_box_interval(points, light, box_min, box_max)
    rel = torch.where(hit[:, None], points - box_min, 0)
    size = box_max - box_min
    dt = (t_far - t_near) / max(steps, 1)
    depth = torch.zeros_like(dt)
    for k in range(steps):
        offset = rel + (t_near + (k + 0.5) * dt)[:, None] * light
        sigma = evaluate(
            density, "density", box_min + offset, torch.where(size > 0, offset / size, 0.5)
        )
        depth = depth + torch.where(hit, sigma, 0) * dt
    return torch.exp(-depth)
    # END SOLUTION


def march_single_scatter(
    origins,
    directions,
    box_min,
    box_max,
    density,
    albedo,
    light_direction,
    light_irradiance=1.0,
    g=0.0,
    steps=64,
    shadow_steps=16,
    *,
    integrator="exact",
    min_transmittance=0.0,
):
    """Single scattering of a directional light in a box, marched like :func:`march_box`.

    origins, directions: (N, 3); box_min, box_max: (3,); density: callable or grid (the
    extinction sigma_t); albedo: number or (C,) tensor in [0, 1], ``sigma_s / sigma_t``
    (else ValueError);
    light_direction: (3,), toward the light; light_irradiance: number or (C,) tensor, the
    light's irradiance E; g: Henyey–Greenstein parameter; steps, shadow_steps: ints >= 0.
    Returns ``march_box``'s dict; radiance is (N, C) when albedo or irradiance has
    channels. The transmittance is the view ray's, for compositing a background.

    The in-scattered source at a sample x is

        S(x) = albedo sigma(x) p(d . l) E T_light(x),

    ``T_light`` from :func:`shadow_transmittance` (``shadow_steps`` steps toward the light),
    and the march integrates S as an emission: ``march_box(..., emission=S)``. With the
    exact integrator a step adds ``T albedo p E T_light (1 - e^{-sigma ds})`` (Hillaire's
    formula). The phase depends only on the ray for a directional light. Cost per ray:
    ``steps * (shadow_steps + 2)`` density evaluations.

    Errors: ValueError or TypeError naming the arguments ``march_box`` checks (``origins``,
    ``directions``, ``box_min``, ``box_max``, ``density``, ``steps``, ``integrator``,
    ``min_transmittance``); ``albedo`` or ``light_irradiance`` (TypeError for a tensor that
    is not (C,) of the rays' dtype and device, ValueError for anything else but a number >=
    0; ValueError for an albedo outside [0, 1]); ``g`` as in ``henyey_greenstein``;
    ``shadow_steps`` (not an int >= 0); ``light_direction`` as in ``shadow_transmittance``.

    Hints: the phase is one value per ray, from ``dot(unit d, light)`` (``dot`` is
    imported from ``course.core.raymath``; ``torch.nan_to_num`` it for degenerate rays). Write
    ``source(points)`` inside this function (a closure over the phase, the light, ...) and
    pass it to ``march_box`` as the emission; multiply by ``factor`` last ((C,) for colour).
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    origins, directions, box_min, box_max, light, factor = check_scatter_inputs(
        origins,
        directions,
        box_min,
        box_max,
        density,
        albedo,
        light_direction,
        light_irradiance,
        g,
        steps,
        shadow_steps,
        integrator,
        min_transmittance,
    )
    bad = torch.as_tensor(albedo, dtype=torch.float64)
    if not bool(((bad >= 0) & (bad <= 1)).all()):
        raise ValueError(
            f"albedo: expected values in [0, 1] (sigma_s / sigma_t: a medium "
            f"scatters at most what it removes), got {albedo!r}"
        )
    # BEGIN SOLUTION (task 3)
    unit = directions / directions.norm(dim=-1, keepdim=True)
    phase = henyey_greenstein(torch.nan_to_num(dot(unit, light)), g)  # (N,)
    size = torch.where(box_max > box_min, box_max - box_min, 1)

    def source(points):  # (N, 3) world points, one per ray, in ray order
        local = torch.where(box_max > box_min, (points - box_min) / size, 0.5)  # flat: middle
        sigma = evaluate(density, "density", points, local)
        lit = shadow_transmittance(points, light, box_min, box_max, density, shadow_steps)
        scattered = sigma * phase * lit
        if isinstance(factor, torch.Tensor):
            return scattered[:, None] * factor
        return scattered * factor

    return march_box(
        origins,
        directions,
        box_min,
        box_max,
        density,
        source,
        steps,
        integrator=integrator,
        min_transmittance=min_transmittance,
    )
    # END SOLUTION
