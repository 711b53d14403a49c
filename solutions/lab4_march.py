"""Lab 4: ray marching.

Fill in every function that raises ``NotImplementedError`` (the tasks below); the helpers
marked "provided" are given. Run the grader for this lab with
``pytest tests/test_lab4_march.py`` (add ``-k march_box`` for one function). The tests call
your kernels on the CPU and, where present, on CUDA: write device- and dtype-agnostic
tensor code, and compare your numbers with the analytic references in the docstrings.

A participating medium inside an axis-aligned box, seen along rays: how much light does a
ray collect, and how much of the background still shines through? Every kernel here works
on a batch of N rays at once (no Python loop over rays; loops over steps, voxels and
sphere-tracing iterations are fine), on the device and in the dtype of its inputs.

Conventions shared by all kernels
---------------------------------
* Rays: ``origins (N, 3)`` and ``directions (N, 3)`` float (one of them may be a single
  ``(3,)`` shared by all rays). Directions need not be unit length: ray parameters ``t``
  (box entry and exit, sphere-tracing hits) are in units of ``|d|`` as in Lab 1, but every
  integral is over **world length** ``ds = |d| dt``. Rays start at ``t = 0``.
* The box: ``box_min, box_max`` (3,) (tensors of the rays' dtype and device, or sequences
  of numbers), closed. A grid ``(X, Y, Z)`` spans the box: voxel ``(i, j, k)`` covers
  ``box_min + [i, i+1] x [j, j+1] x [k, k+1] * voxel_size``, ``grid[i, j, k]`` is its value
  (x is the first axis, z the last).
* A medium: ``density`` (the extinction coefficient sigma_t, per unit length, >= 0) and
  ``emission`` (emitted radiance per unit length, q) are each a callable
  ``f(points (N, 3)) -> (N,)`` (emission may return ``(N, C)`` for C colour channels)
  evaluated at world points, or a grid tensor ``(X, Y, Z)`` (emission also
  ``(X, Y, Z, C)``) sampled with trilinear interpolation (:func:`sample_grid`).
* Emission–absorption: the radiance leaving the medium toward the ray's origin is
  ``L = int_0^D T(s) q(s) ds`` with transmittance ``T(s) = exp(-int_0^s sigma)``; a
  background ``L_bg`` behind the box adds ``T(D) L_bg`` (premultiplied colour/alpha).
* Degenerate rays are cases, not errors: rays that miss the box, NaN/inf origins or
  directions and zero directions integrate nothing (radiance 0, transmittance 1, no NaN).
  Malformed input (wrong shape, integer dtype, mixed dtypes or devices, an unknown
  integrator, a negative step count) raises ``ValueError``/``TypeError`` naming the argument.
* Every float dtype works, float16 and bfloat16 included: results come back in the
  inputs' dtype, never NaN, and are checked loosely there (about 2e-2 relative for
  float16 and 6e-2 for bfloat16 on a march); float32 and float64 meet the contracts below.

Tasks (points)
--------------
1. ``ray_box_interval``, ``sample_grid``, ``march_box``: the lecture's box ray marcher
   with front-to-back compositing, early termination and jittered offsets       (3)
2. ``segment_integral``: the energy-conserving per-step integral, exact for
   piecewise-constant media, against the Riemann sum                             (3)
3. ``henyey_greenstein``, ``shadow_transmittance``, ``march_single_scatter``:
   single scattering of a directional light                                      (3)
4. ``voxel_walk``, ``build_occupancy``: exact integration over a voxel grid with a
   3D DDA, and empty-space skipping over macro cells                             (3)
5. ``sphere_trace``: signed-distance scenes, with over-relaxation                 (3)

Accuracy (asserted by the grader)
---------------------------------
* ``march_box``, "riemann": first order, the error halves when the steps double (each
  step counts its sample as if nothing in front of it within the step absorbed).
* ``march_box``, "exact": exact to rounding for media constant over each step (any step
  count, even 1); second order for smooth media (midpoint rule).
* ``voxel_walk``: the optical depth is the exact sum over the voxels crossed, to float
  rounding, with no step count; a box at 1e5 keeps float32's relative accuracy.
* ``sphere_trace``: a hit when ``|f| <= epsilon t |d|``, the error of ``t`` relative to
  the distance, for scenes near and far.

Errors, samples per ray and speeds measured by ``bench/lab4_march.py``:
``bench/results/cpu-2cores/lab4/lab4_march.md`` (GPUs: ``bench/results/<gpu>/lab4/``).
"""

from __future__ import annotations

import math  # noqa: F401  (math.pi, math.inf: you will need them)

import torch

from course.core.raymath import check_inputs, dot  # noqa: F401  (dot: given, for the tasks)
from course.given.lab4 import (  # noqa: F401  (given helpers)
    HIT,
    INTEGRATORS,
    MISS,
    UNSURE,
    as_box,
    as_vector,
    check_count,
    check_field,
    check_grid_inputs,
    check_integrator,
    check_march_inputs,
    check_number,
    check_occupancy_inputs,
    check_phase_inputs,
    check_ray_box_inputs,
    check_rays,
    check_scatter_inputs,
    check_segment_inputs,
    check_shadow_inputs,
    check_trace_inputs,
    check_voxel_inputs,
    sdf_box,
    sdf_sphere,
    sdf_union,
    unit_light,
)
from course.given.lab4_fields import field_values

# ---------------------------------------------------------------------------------------
# Provided helpers (not tasks): input checks, field evaluation, SDF primitives. Each task
# starts with one check_* call that raises ValueError/TypeError naming a bad argument.


def evaluate(field, name: str, points: torch.Tensor, local: torch.Tensor,
             channels: bool = False) -> torch.Tensor:
    """A field's values at N points: ``field(points)`` for a callable (world points, checked
    by ``field_values``), ``sample_grid(field, local)`` for a grid (box coordinates in
    [0, 1]^3). Returns (N,), or also (N, C) when ``channels``, in the points' dtype."""
    if isinstance(field, torch.Tensor):
        return sample_grid(field, local)
    return field_values(field, name, points, channels)


# ---------------------------------------------------------------------------------------
# Task 1: the box ray marcher


def ray_box_interval(origins, directions, box_min, box_max):
    """Where each ray is inside the box: the slab test (Kay & Kajiya).

    origins, directions: (N, 3) float; box_min, box_max: (3,).
    Returns ``(t_near, t_far, hit)``, (N,) each: the parametric interval of the ray inside
    the closed box, clipped to ``t >= 0`` (a ray starting inside has ``t_near = 0``), and
    ``hit = t_near <= t_far`` (bool). Where ``hit`` is False, ``t_near = t_far = 0``.

    Per axis the slab gives ``t = (box_min - o) / d`` and ``(box_max - o) / d``;
    ``1 / ±0 = ±inf`` puts an axis-parallel ray's slab at ``[-inf, inf]`` (inside it) or at
    infinity (outside it: a miss). A ray starting exactly on a slab plane with ``d = 0``
    there gives ``0 * inf = NaN``: that slab says nothing, so the reduction over slabs
    drops NaN (``torch.fmax``/``fmin``). Rays with NaN/inf components or ``d = 0`` miss.
    The differences ``box - o`` come first, so a box far from the world origin keeps the
    relative accuracy of its size.

    Hints: ``torch.reciprocal`` keeps the sign of zero; reduce over the three slabs
    with ``torch.fmax``/``torch.fmin`` (they ignore NaN) and clip ``t_near`` at 0; build the
    validity mask with ``torch.isfinite``; return ``torch.where(hit, t, 0)``.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    origins, directions, box_min, box_max = check_ray_box_inputs(origins, directions,
                                                                 box_min, box_max)
    # BEGIN SOLUTION (task 1)
    inv = torch.reciprocal(directions)
    t0 = (box_min - origins) * inv
    t1 = (box_max - origins) * inv
    lo, hi = torch.minimum(t0, t1), torch.maximum(t0, t1)
    zero = torch.zeros((), dtype=origins.dtype, device=origins.device)
    t_near = torch.fmax(torch.fmax(torch.fmax(lo[:, 0], lo[:, 1]), lo[:, 2]), zero)
    t_far = torch.fmin(torch.fmin(hi[:, 0], hi[:, 1]), hi[:, 2])
    valid = (torch.isfinite(origins).all(-1) & torch.isfinite(directions).all(-1)
             & (directions != 0).any(-1))
    hit = valid & (t_near <= t_far) & torch.isfinite(t_far)
    return torch.where(hit, t_near, zero), torch.where(hit, t_far, zero), hit
    # END SOLUTION


def sample_grid(grid, uvw):
    """Trilinear interpolation of a cell-centred grid at box coordinates.

    grid: (X, Y, Z) or (X, Y, Z, C) float; uvw: (..., 3) float of the grid's dtype, the
    points' coordinates in the box scaled to [0, 1]^3 (``(p - box_min) / (box_max - box_min)``).
    Returns (...) or (..., C).

    ``grid[i, j, k]`` sits at the centre of its voxel, ``uvw = ((i, j, k) + 0.5) / (X, Y, Z)``
    (``align_corners=False`` in ``torch.nn.functional.grid_sample`` terms). Between centres
    the value is trilinear; within half a voxel of a face, and outside the box, the
    coordinates are clamped to the nearest centre (``padding_mode="border"``), so a constant
    grid is constant all the way to the faces. NaN coordinates give 0.

    Watch the axis order: x indexes the grid's *first* axis. ``grid_sample`` would want
    the grid as ``(1, C, Z, Y, X)`` (depth first) and coordinates ``2 uvw - 1`` in (x, y, z)
    order.

    Hints: ``u = uvw * (X, Y, Z) - 0.5`` is the continuous index (voxel centres at the
    integers); clamp it to ``[0, n - 1]``; ``i0 = floor(u)`` clamped to ``[0, n - 2]`` (mind
    ``n = 1``), ``f = u - i0``, ``i1 = min(i0 + 1, n - 1)``. Gather the 8 corners from
    ``grid.reshape(-1, ...)`` at ``(ix * Y + iy) * Z + iz`` and weight each by ``f`` or
    ``1 - f`` per axis. Compare with ``grid_sample`` yourself as the docstring describes.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    check_grid_inputs(grid, uvw)
    # BEGIN SOLUTION (task 1)
    sizes = torch.tensor(grid.shape[:3], device=grid.device)
    finite = torch.isfinite(uvw).all(-1)
    # Continuous index: voxel centres at the integers 0 .. n-1.
    u = torch.nan_to_num(uvw, nan=0.0) * sizes - 0.5
    u = torch.minimum(u.clamp(min=0), (sizes - 1).to(u.dtype))
    i0 = torch.minimum(u.floor().long(), (sizes - 2).clamp(min=0))
    f = u - i0
    i1 = torch.minimum(i0 + 1, sizes - 1)
    # The 8 corners at once: bit a of corner c picks i1 (weight f) or i0 (weight 1 - f).
    upper = (torch.arange(8, device=grid.device)[:, None] >> torch.arange(3, device=grid.device)
             ) & 1 == 1  # (8, 3)
    index = torch.where(upper, i1[..., None, :], i0[..., None, :])  # (..., 8, 3)
    weight = torch.where(upper, f[..., None, :], 1 - f[..., None, :]).prod(-1)  # (..., 8)
    linear = (index[..., 0] * grid.shape[1] + index[..., 1]) * grid.shape[2] + index[..., 2]
    values = grid.reshape(-1, *grid.shape[3:])[linear]  # (..., 8) or (..., 8, C)
    if grid.ndim == 4:
        return torch.where(finite[..., None], (weight[..., None] * values).sum(-2), 0)
    return torch.where(finite, (weight * values).sum(-1), 0)
    # END SOLUTION


def march_box(origins, directions, box_min, box_max, density, emission=None, steps=64, *,
              integrator="exact", min_transmittance=0.0, jitter=False, seed=0):
    """The lecture's ray marcher: a fixed number of steps through a volume in a box.

    origins, directions: (N, 3) float; box_min, box_max: (3,); density: callable or grid
    (X, Y, Z); emission: None (a purely absorbing medium), callable, or grid (X, Y, Z) or
    (X, Y, Z, C); steps: int >= 0, the same for every ray.
    Returns a dict of tensors on the rays' device:
      ``radiance`` (N,) or (N, C): the emitted light reaching the origin,
      ``transmittance`` (N,): ``T`` at the end of the march (what the background keeps),
      ``samples`` (N,) int64: the steps the ray took (density evaluations).

    1. ``[t_near, t_far]`` from :func:`ray_box_interval`; ``steps`` equal steps of
       ``dt = (t_far - t_near) / steps`` (world length ``ds = |d| dt``).
    2. Step i samples the medium at ``t_near + (i + xi) dt``: ``xi = 1/2`` (midpoint), or
       with ``jitter`` one offset ``xi`` in [0, 1] per ray, the same for all its steps,
       drawn on the CPU from a generator seeded with ``seed`` (the same offsets on every
       device).
    3. Front to back: ``(w, T_step) = segment_integral(sigma_i, ds, integrator)``, then
       ``L += T * q_i * w`` and only then ``T *= T_step``: the sample is seen through
       everything in front of it (``w`` already accounts for the step itself).
    4. Early termination: a ray whose ``T`` has dropped below ``min_transmittance`` stops
       (no more samples); the loop ends when no ray is left. The light it ignores is at
       most ``min_transmittance * max(q / sigma)`` (exact integrator).

    Grids are sampled at box coordinates computed as ``((o - box_min) + t d) / size``,
    never from the absolute point, so a box far from the origin keeps its accuracy;
    callables get world points. The density is an extinction coefficient, >= 0: a grid or
    a callable with negative values raises ValueError naming ``density`` (the provided check
    and ``evaluate`` do it). Rays that miss (and NaN/inf rays) sample nothing:
    radiance 0, transmittance 1, samples 0. ``steps = 0`` is an empty march.

    Hints: ``ray_box_interval`` gives the span. Keep ``rel = o - box_min`` (0 for
    missed rays) and sample at ``offset = rel + t d``: ``local = offset / size`` for grids,
    ``box_min + offset`` for callables; the provided ``evaluate(field, name, points, local,
    channels)`` does the rest (it calls your ``sample_grid``). Mask inactive rays with
    ``torch.where`` *before* ``segment_integral``. The radiance is (N,) or (N, C) as the
    emission's values are; with no emission (or no step) return zeros of that shape.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    origins, directions, box_min, box_max = check_march_inputs(
        origins, directions, box_min, box_max, density, emission, steps, integrator,
        min_transmittance)
    # BEGIN SOLUTION (task 1)
    n = origins.shape[0]
    like = {"dtype": origins.dtype, "device": origins.device}
    t_near, t_far, hit = ray_box_interval(origins, directions, box_min, box_max)
    # Missed rays march a harmless point (the box's corner) along a zero-length span.
    rel = torch.where(hit[:, None], origins - box_min, 0)
    d = torch.where(hit[:, None], directions, 0)
    size = box_max - box_min
    dt = (t_far - t_near) / max(steps, 1)
    ds = dt * d.norm(dim=-1)
    if jitter:
        generator = torch.Generator().manual_seed(seed)
        xi = torch.rand(n, generator=generator, dtype=torch.float64).to(**like)
    else:
        xi = torch.full((n,), 0.5, **like)
    radiance = 0  # (N,) or (N, C): the emission's first evaluation decides
    transmittance = torch.ones(n, **like)
    samples = torch.zeros(n, dtype=torch.int64, device=origins.device)
    for i in range(steps):
        active = hit & (transmittance >= min_transmittance)
        if not bool(active.any()):
            break
        t = t_near + (i + xi) * dt
        offset = rel + t[:, None] * d
        local = torch.where(size > 0, offset / size, 0.5)
        points = box_min + offset
        sigma = torch.where(active, evaluate(density, "density", points, local), 0)
        weight, t_seg = segment_integral(sigma, torch.where(active, ds, 0), integrator)
        if emission is not None:
            q = evaluate(emission, "emission", points, local, channels=True)
            if q.ndim == 2:  # colour channels
                weight, seen, active_q = weight[:, None], transmittance[:, None], active[:, None]
            else:
                seen, active_q = transmittance, active
            radiance = radiance + seen * weight * torch.where(active_q, q, 0)
        transmittance = transmittance * t_seg
        samples += active
    if not isinstance(radiance, torch.Tensor):  # nothing emitted: zeros of the right shape
        centre = torch.full((n, 3), 0.5, **like)
        channels = () if emission is None else evaluate(
            emission, "emission", box_min + centre * size, centre, channels=True).shape[1:]
        radiance = torch.zeros(n, *channels, **like)
    return {"radiance": radiance, "transmittance": transmittance, "samples": samples}
    # END SOLUTION


# ---------------------------------------------------------------------------------------
# Task 2: the per-step integral


def segment_integral(sigma, length, integrator="exact"):
    """One step of emission–absorption through a medium constant over the step.

    sigma: extinction >= 0 (may be +inf); length: the step's world length >= 0 (finite);
    numbers or float tensors that broadcast (a negative value raises ValueError naming it:
    the transmittance would exceed 1; the provided check does it). Returns ``(weight,
    transmittance)`` of the broadcast shape: a source ``q`` constant over the step adds
    ``T_before * q * weight`` to the radiance, and then ``T`` is multiplied by
    ``transmittance = exp(-sigma length)``.

    ``"exact"``: ``weight = int_0^D e^{-sigma x} dx = (1 - e^{-sigma D}) / sigma``, the
    energy-conserving integral (Hillaire 2015), exact for a medium constant over the step.
    Written as ``D f(sigma D)`` with ``f(x) = -expm1(-x) / x``: no cancellation for small
    ``x``, ``f(0) = 1`` (vacuum: emission times length; ``0 / 0`` is not an answer) and
    ``f(inf) = 0`` (an opaque step gives ``1 / sigma -> 0``, not ``inf - inf``).
    ``sigma = inf`` over ``length = 0`` is no step at all: weight 0, transmittance 1.

    ``"riemann"``: ``weight = D``, the naive sum, which ignores the absorption inside the
    step: it overestimates by ``sigma D / (1 - e^{-sigma D})`` (first order in the step)
    and emits more than a black body could (``q = c sigma`` gives ``L > c``).

    Hints: ``x = sigma * length`` (but 0 where ``length == 0``); ``torch.expm1``;
    ``torch.where(x > 0, ..., 1)`` keeps the 0 / 0 of the unused branch out of the result.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    sigma, length = check_segment_inputs(sigma, length, integrator)
    # BEGIN SOLUTION (task 2)
    x = torch.where(length == 0, 0, sigma * length)  # inf * 0 is no step, not NaN
    transmittance = torch.exp(-x)
    if integrator == "riemann":
        return length.expand_as(x), transmittance
    ratio = torch.where(x > 0, -torch.expm1(-x) / x, 1)
    return length * ratio, transmittance
    # END SOLUTION


# ---------------------------------------------------------------------------------------
# Task 3: single scattering


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

    Hints: compute both denominators and pick with ``torch.where(g >= 0, ...)``;
    ``(1 - g) * (1 + g)`` for the numerator; ``base * base.sqrt()`` is ``base^(3/2)``.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    g = check_phase_inputs(cos_theta, g)
    # BEGIN SOLUTION (task 3)
    cos_theta = cos_theta.clamp(-1, 1)
    base = torch.where(g >= 0, (1 - g) ** 2 + 2 * g * (1 - cos_theta),
                       (1 + g) ** 2 - 2 * g * (1 + cos_theta))
    return (1 - g) * (1 + g) / (4 * math.pi * base * base.sqrt())
    # END SOLUTION


def shadow_transmittance(points, light_direction, box_min, box_max, density, steps=16):
    """Transmittance from each point toward a directional light, to where it leaves the box.

    points: (N, 3) float; light_direction: (3,), toward the light (any length);
    box_min, box_max: (3,); density: callable or grid; steps: int >= 0.
    Returns (N,): ``exp(-sum_k sigma_k dt)``, a midpoint-rule march of ``steps`` equal
    steps over the part of the ray ``p + t l`` (unit ``l``, ``t >= 0``) inside the box:
    exact for a homogeneous medium with one step, second order for a smooth one. Points
    whose light ray misses the box, NaN points and ``steps = 0`` give 1 (unshadowed).

    Hints: ``ray_box_interval`` from the points along the (already unit, from the
    provided check) light direction; loop over the steps summing ``sigma * dt`` (0 where the
    ray misses the box); ``exp`` at the end.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    points, light, box_min, box_max = check_shadow_inputs(points, light_direction, box_min,
                                                          box_max, density, steps)
    # BEGIN SOLUTION (task 3)
    light = light.expand_as(points)
    t_near, t_far, hit = ray_box_interval(points, light, box_min, box_max)
    rel = torch.where(hit[:, None], points - box_min, 0)
    size = box_max - box_min
    dt = (t_far - t_near) / max(steps, 1)
    depth = torch.zeros_like(dt)
    for k in range(steps):
        offset = rel + (t_near + (k + 0.5) * dt)[:, None] * light
        sigma = evaluate(density, "density", box_min + offset,
                         torch.where(size > 0, offset / size, 0.5))
        depth = depth + torch.where(hit, sigma, 0) * dt
    return torch.exp(-depth)
    # END SOLUTION


def march_single_scatter(origins, directions, box_min, box_max, density, albedo,
                         light_direction, light_irradiance=1.0, g=0.0, steps=64,
                         shadow_steps=16, *, integrator="exact", min_transmittance=0.0):
    """Single scattering of a directional light in a box, marched like :func:`march_box`.

    origins, directions: (N, 3); box_min, box_max: (3,); density: callable or grid (the
    extinction sigma_t); albedo: number in [0, 1] or (C,) tensor, ``sigma_s / sigma_t``;
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

    Hints: the phase is one value per ray, from ``dot(unit d, light)`` (``dot`` is
    imported from ``course.core.raymath``; ``torch.nan_to_num`` it for degenerate rays). Write
    ``source(points)`` inside this function (a closure over the phase, the light, ...) and
    pass it to ``march_box`` as the emission; multiply by ``factor`` last ((C,) for colour).
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    origins, directions, box_min, box_max, light, factor = check_scatter_inputs(
        origins, directions, box_min, box_max, density, albedo, light_direction,
        light_irradiance, g, steps, shadow_steps, integrator, min_transmittance)
    # BEGIN SOLUTION (task 3)
    unit = directions / directions.norm(dim=-1, keepdim=True)
    phase = henyey_greenstein(torch.nan_to_num(dot(unit, light)), g)  # (N,)
    size = torch.where(box_max > box_min, box_max - box_min, 1)

    def source(points):  # (N, 3) world points, one per ray, in ray order
        sigma = evaluate(density, "density", points, (points - box_min) / size)
        lit = shadow_transmittance(points, light, box_min, box_max, density, shadow_steps)
        scattered = sigma * phase * lit
        if isinstance(factor, torch.Tensor):
            return scattered[:, None] * factor
        return scattered * factor

    return march_box(origins, directions, box_min, box_max, density, source, steps,
                     integrator=integrator, min_transmittance=min_transmittance)
    # END SOLUTION


# ---------------------------------------------------------------------------------------
# Task 4: exact voxel walk and empty-space skipping


def build_occupancy(density, macro_cell=1, emission=None):
    """Which macro cells hold any medium: the acceleration grid of empty-space skipping.

    density: (X, Y, Z) float grid; macro_cell: int >= 1, the macro cell's edge in voxels;
    emission: optional (X, Y, Z) or (X, Y, Z, C) grid (emitting voxels are not empty).
    Returns (ceil(X/m), ceil(Y/m), ceil(Z/m)) bool: True where some voxel of the macro
    cell has ``density > 0`` or non-zero emission (a max over m^3 blocks; the last block
    of an axis may be partial).

    Hints: ``torch.nn.functional.max_pool3d`` on a float copy of the mask, shaped
    (1, 1, X, Y, Z), with ``kernel_size = stride = macro_cell`` and ``ceil_mode=True``.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    check_occupancy_inputs(density, macro_cell, emission)
    # BEGIN SOLUTION (task 4)
    busy = density > 0
    if emission is not None:
        nonzero = emission != 0
        busy = busy | (nonzero.any(-1) if emission.ndim == 4 else nonzero)
    pooled = torch.nn.functional.max_pool3d(busy[None, None].float(), macro_cell,
                                            stride=macro_cell, ceil_mode=True)
    return pooled[0, 0] > 0
    # END SOLUTION


def voxel_walk(origins, directions, box_min, box_max, density, emission=None, occupancy=None,
               macro_cell=1):
    """Exact emission–absorption through a piecewise-constant voxel grid (3D DDA).

    origins, directions: (N, 3); box_min, box_max: (3,); density: (X, Y, Z) grid >= 0,
    constant over each voxel (nearest, not trilinear); emission: None or (X, Y, Z) /
    (X, Y, Z, C) grid, constant per voxel; occupancy: None (no skipping) or the bool grid
    of :func:`build_occupancy` for ``macro_cell``.
    Returns a dict: ``optical_depth`` (N,), ``transmittance`` (N,) ``= exp(-optical_depth)``,
    ``radiance`` (N,) or (N, C), ``steps`` (N,) int64 (cells stepped through: voxels or
    skipped macro cells) and ``samples`` (N,) int64 (voxels whose density was read).

    Amanatides & Woo: from the entry voxel, step to the neighbour across the nearest
    boundary plane ahead. Each boundary's ``t`` is computed afresh from the integer voxel
    index, ``(index * voxel - (o - box_min)) / d`` (no accumulated increments, no absolute
    coordinates), so the segments telescope to the chord and each is integrated exactly
    (:func:`segment_integral`, "exact"): no step count to choose.

    Skipping: a voxel whose macro cell is empty is crossed together with its whole macro
    cell in one step, to the macro cell's exit plane; the indices on the other axes are
    re-located from the exit point (clamped into the macro cell, never backwards). A fine
    step is the same move with a block of one voxel. Every iteration advances at least one
    index, so ``X + Y + Z + 1`` iterations finish every ray.

    Ties: a ray lying exactly in a voxel plane (a zero direction component) belongs to the
    voxel on the plane's positive side, ``floor((o - box_min) / voxel)``; where the ray
    crosses several planes at one ``t`` (an edge or a corner), it steps one axis at a time
    with zero-length segments in between.

    Hints: per-ray state ``cell`` (N, 3) int64, ``t`` (N,) and ``active`` (N,) bool;
    ``step = torch.sign(d).long()``. In each iteration: the block ``[block_lo, block_hi]``
    (the voxel, or its macro cell when ``occupancy`` says it is empty), the plane ahead on
    each axis (``block_hi + 1`` or ``block_lo``), its ``t`` (inf where ``step == 0``), the
    exit ``t`` and axis (``amin``/``argmin``), the segment, then the move. Only
    ``torch.where`` updates: no Python loop over rays.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    origins, directions, box_min, box_max = check_voxel_inputs(
        origins, directions, box_min, box_max, density, emission, occupancy, macro_cell)
    # BEGIN SOLUTION (task 4)
    n = origins.shape[0]
    like = {"dtype": origins.dtype, "device": origins.device}
    sizes = torch.tensor(density.shape, device=origins.device)
    voxel = (box_max - box_min) / sizes
    t, t_end, hit = ray_box_interval(origins, directions, box_min, box_max)
    hit = hit & (voxel > 0).all()
    # Missed rays get a harmless finite ray; they never become active.
    rel = torch.where(hit[:, None], origins - box_min, 0)
    d = torch.where(hit[:, None], directions, 1)
    length = d.norm(dim=-1)
    step = torch.sign(d).long()  # +0.0 and -0.0 both give 0: never cross a plane of that axis
    inv = torch.reciprocal(d)
    cell = torch.floor((rel + t[:, None] * d) / voxel).long()
    cell = torch.minimum(cell.clamp(min=0), sizes - 1)

    depth = torch.zeros(n, **like)
    transmittance = torch.ones(n, **like)
    channels = tuple(emission.shape[3:]) if emission is not None else ()
    radiance = torch.zeros(n, *channels, **like)
    steps_taken = torch.zeros(n, dtype=torch.int64, device=origins.device)
    samples = torch.zeros_like(steps_taken)
    flat = density.reshape(-1)
    ny, nz = density.shape[1], density.shape[2]
    inf = torch.full((), math.inf, **like)
    active = hit & (t < t_end)
    for _ in range(int(sizes.sum()) + 1):
        active = active & (cell >= 0).all(-1) & (cell < sizes).all(-1) & (t < t_end)
        if not bool(active.any()):
            break
        index = torch.minimum(cell.clamp(min=0), sizes - 1)
        if occupancy is None:
            skip = torch.zeros(n, dtype=torch.bool, device=origins.device)
        else:
            macro = index // macro_cell
            skip = ~occupancy[macro[:, 0], macro[:, 1], macro[:, 2]]
        # The block being crossed: one voxel, or the whole (empty) macro cell.
        block_lo = torch.where(skip[:, None], (index // macro_cell) * macro_cell, index)
        block_hi = torch.where(skip[:, None], torch.minimum(
            (index // macro_cell + 1) * macro_cell, sizes) - 1, index)
        ahead = torch.where(step > 0, block_hi + 1, block_lo)  # index of the plane ahead
        t_axis = torch.where(step != 0, (ahead * voxel - rel) * inv, inf)
        t_exit = torch.minimum(t_axis.amin(-1), t_end)
        axis = t_axis.argmin(-1)
        seg = torch.where(active, (t_exit - t).clamp(min=0) * length, 0)
        sample = active & ~skip
        linear = (index[:, 0] * ny + index[:, 1]) * nz + index[:, 2]
        sigma = torch.where(sample, flat[linear], 0)
        depth = depth + sigma * seg
        if emission is not None:
            q = emission.reshape(-1, *channels)[linear]
            weight, t_seg = segment_integral(sigma, seg, "exact")
            seen = transmittance * weight
            if channels:
                radiance = radiance + seen[:, None] * torch.where(sample[:, None], q, 0)
            else:
                radiance = radiance + seen * torch.where(sample, q, 0)
            transmittance = transmittance * t_seg
        steps_taken += active
        samples += sample
        # Leave the block across the exit plane on `axis`; on the other axes go where the
        # exit point lies, kept inside the block and never backwards (rounding).
        located = torch.floor((rel + t_exit[:, None] * d) / voxel).long()
        located = torch.minimum(torch.maximum(located, block_lo), block_hi)
        located = torch.where(step > 0, torch.maximum(located, index),
                              torch.where(step < 0, torch.minimum(located, index), index))
        across = torch.where(step > 0, block_hi + 1, block_lo - 1)
        on_axis = torch.nn.functional.one_hot(axis, 3).bool()
        cell = torch.where(active[:, None], torch.where(on_axis, across, located), cell)
        t = torch.where(active, t_exit, t)
    return {"optical_depth": depth, "transmittance": torch.exp(-depth), "radiance": radiance,
            "steps": steps_taken, "samples": samples}
    # END SOLUTION


# ---------------------------------------------------------------------------------------
# Task 5: sphere tracing


def sphere_trace(origins, directions, sdf, t_max=100.0, max_steps=128, epsilon=1e-4,
                 relaxation=1.0):
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

    Hints: per-ray state ``t``, ``status``, ``steps``, ``omega``, and for the
    over-relaxation check the previous ``|f|`` and the previous step's world length. Update
    everything with ``torch.where`` on an ``active`` mask; stop the loop early when no ray
    is active.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    origins, directions = check_trace_inputs(origins, directions, sdf, t_max, max_steps,
                                             epsilon, relaxation)
    # BEGIN SOLUTION (task 5)
    n = origins.shape[0]
    like = {"dtype": origins.dtype, "device": origins.device}
    length = directions.norm(dim=-1)
    valid = (torch.isfinite(origins).all(-1) & torch.isfinite(directions).all(-1)
             & (length > 0) & torch.isfinite(length))
    o = torch.where(valid[:, None], origins, 0)
    d = torch.where(valid[:, None], directions, 0)
    t = torch.zeros(n, **like)
    status = torch.full((n,), MISS, dtype=torch.int64, device=origins.device)
    steps = torch.zeros(n, dtype=torch.int64, device=origins.device)
    omega = torch.full((n,), float(relaxation), **like)
    prev_radius = torch.zeros(n, **like)
    prev_step = torch.zeros(n, **like)  # world length of the last step
    active = valid
    for _ in range(max_steps):
        active = active & (t <= t_max)
        if not bool(active.any()):
            break
        f = sdf(o + t[:, None] * d)
        if not isinstance(f, torch.Tensor) or f.shape != (n,):
            raise ValueError(f"sdf: the callable must return a tensor of shape ({n},), got "
                             + (str(tuple(f.shape)) if isinstance(f, torch.Tensor)
                                else type(f).__name__))
        f = f.to(origins.dtype)
        steps += active
        radius = f.abs()
        lost = active & torch.isnan(f)
        fail = active & (omega > 1) & (radius + prev_radius < prev_step)
        hit = active & ~fail & (radius <= epsilon * t * length)
        status = torch.where(hit, HIT, status)
        active = active & ~hit & ~lost
        # Over-relaxation failed: back to the last safe point, plain steps from now on.
        advance = torch.where(fail, (prev_radius - prev_step) / length, omega * radius / length)
        t = torch.where(active, t + advance, t)
        prev_step = torch.where(fail, prev_radius, omega * radius)
        prev_radius = torch.where(fail, prev_radius, radius)
        omega = torch.where(fail, 1, omega)
    status = torch.where(active, torch.where(t > t_max, MISS, UNSURE), status)
    t = torch.where(status == HIT, t, math.inf)
    return {"t": t, "status": status, "steps": steps}
    # END SOLUTION
