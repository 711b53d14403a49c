"""Task 3: scattered light per froxel: the phase functions (``henyey_greenstein``,
``schlick_phase``), the tile light lists (``cull_lights``), the sun's shadow map
(``build_shadow_map``, ``shadow_lookup``) and ``light_froxels``, which lights the V-buffer.
"""

from __future__ import annotations

import math

import torch

from course.core.raymath import check_inputs
from course.given.lab5 import (
    LIGHT_STEPS,
    MIN_LIGHT_DISTANCE,
    PHASES,
    SCHLICK_K_MAX,
    DirectionalLight,
    LightVolume,
    PointLight,
    SpotLight,
    auto_volume_resolution,
    check_choice,
    check_dtype,
    check_grid,
    check_jitter,
    check_lights,
    check_phase_inputs,
    check_scene,
    check_volume,
    check_volume_resolution,
    froxel_sample_coords,
    frustum_bounds,
    light_coords,
    light_frame,
    ray_boxes,
    volume_bounds,
)

from .grid import froxel_to_world
from .volumetric_shadows import (
    extinction_volume,
    light_transmittance,
    sample_light_volume,
    transmittance_volume,
)

# BEGIN SOLUTION
# A function of the reference's own, not in the skeleton: so is its import (a block
# of its own).
# isort: split
from .grid import _camera

# END SOLUTION


def henyey_greenstein(cos_theta, g):
    """Henyey–Greenstein phase function per steradian,
    ``(1 - g^2) / (4 pi (1 + g^2 - 2 g cos theta)^(3/2))``.

    cos_theta: any shape, float32/float64; g: a number or a tensor broadcasting with it,
    in (-1, 1). Normalised over the sphere, mean cosine ``g``; ``1 / (4 pi)`` at g = 0.
    ``cos_theta`` outside [-1, 1] (a dot product of unit vectors a rounding step past
    +-1) is clamped to [-1, 1]: the value is always finite and positive, also at the peak
    as ``|g| -> 1`` (where ``1 + g^2 - 2 g`` loses every digit: write the denominator as
    ``(1 - g)^2 + 2 g (1 - cos)`` for g >= 0, ``(1 + g)^2 - 2 g (1 + cos)`` for g < 0).

    Errors: TypeError naming ``cos_theta`` unless it is a float32/float64 tensor; TypeError
    naming ``g`` unless it is a number or a tensor of the cos_theta's dtype and device;
    ValueError naming ``g`` for a value outside (-1, 1).
    """
    # BEGIN SOLUTION (task 3)
    g = check_phase_inputs(cos_theta, g)
    cos_theta = cos_theta.clamp(-1, 1)
    # Non-negative terms: no cancellation at the peak.
    denom = torch.where(
        g >= 0, (1 - g) ** 2 + 2 * g * (1 - cos_theta), (1 + g) ** 2 - 2 * g * (1 + cos_theta)
    )
    return (1 - g) * (1 + g) / (4 * math.pi * denom * denom.sqrt())
    # END SOLUTION


def schlick_phase(cos_theta, g):
    """Schlick's approximation of Henyey–Greenstein, ``(1 - k^2) / (4 pi (1 - k cos)^2)``
    with ``k = 1.55 g - 0.55 g^3`` clamped to ``|k| <= SCHLICK_K_MAX`` (``k`` reaches 1
    at g = 0.9986: without the clamp a forward peak becomes a delta and then negative).
    Normalised over the sphere for every ``g`` in (-1, 1); ``cos_theta`` is clamped to
    [-1, 1] like :func:`henyey_greenstein`'s."""
    # BEGIN SOLUTION (task 3)
    g = check_phase_inputs(cos_theta, g)
    cos_theta = cos_theta.clamp(-1, 1)
    k = (1.55 * g - 0.55 * g**3).clamp(-SCHLICK_K_MAX, SCHLICK_K_MAX)
    return (1 - k * k) / (4 * math.pi * (1 - k * cos_theta).square())
    # END SOLUTION


def cull_lights(grid, lights, device="cpu"):
    """Tile light lists: (L, ny, nx) bool, True where light ``l`` may reach tile ``(j, i)``.

    A tile's froxels fill a frustum: four side planes through the eye and the tile's pixel
    edges, closed by the ``near`` and ``far`` depths. A point or spot light reaches
    nothing beyond its ``range``: it is listed wherever its sphere ``(position, range)``
    is not entirely outside one of the six planes (signed distance >= -range for all six:
    conservative, never drops a tile the sphere touches). A sphere exactly tangent to a
    plane (distance exactly -range), or within rounding of it (the planes may be computed
    in float32: about 1e-7 of the light's distance from the eye), may go either way: the
    light gives nothing at its range. Directional lights are listed everywhere.

    Errors: TypeError naming ``grid`` unless it is a FroxelGrid; TypeError naming ``lights``
    (as ``lights[i]``) for an item that is not a DirectionalLight, PointLight or SpotLight.
    """
    # BEGIN SOLUTION (task 3)
    check_grid(grid)
    lights = check_lights(lights)
    eye, right, up, fwd, hw, hh = _camera(grid, torch.float64, device)
    w, h, t = grid.camera.width, grid.camera.height, grid.tile
    x0 = 2 * torch.arange(grid.nx, dtype=torch.float64, device=device) * t / w - 1
    x1 = 2 * (torch.arange(grid.nx, dtype=torch.float64, device=device) + 1) * t / w - 1
    y0 = 1 - 2 * torch.arange(grid.ny, dtype=torch.float64, device=device) * t / h
    y1 = 1 - 2 * (torch.arange(grid.ny, dtype=torch.float64, device=device) + 1) * t / h
    result = torch.ones(len(lights), grid.ny, grid.nx, dtype=torch.bool, device=device)
    for n, light in enumerate(lights):
        if isinstance(light, DirectionalLight):
            continue
        p = torch.tensor(light.position, dtype=torch.float64, device=device) - eye
        px, py, pz = p @ right, p @ up, p @ fwd  # view coordinates, pz = view depth
        r = light.range
        # Inward signed distances to the side planes X = x hw Z and Y = y hh Z.
        left = (px - x0 * hw * pz) / torch.sqrt(1 + (x0 * hw) ** 2)
        right_d = (x1 * hw * pz - px) / torch.sqrt(1 + (x1 * hw) ** 2)
        top = (y0 * hh * pz - py) / torch.sqrt(1 + (y0 * hh) ** 2)
        bottom = (py - y1 * hh * pz) / torch.sqrt(1 + (y1 * hh) ** 2)
        cols = (left >= -r) & (right_d >= -r)
        rows = (top >= -r) & (bottom >= -r)
        depth = bool(pz >= grid.near - r) and bool(pz <= grid.far + r)
        result[n] = rows[:, None] & cols[None, :] & depth
    return result
    # END SOLUTION


def build_shadow_map(scene, light, center, radius, resolution, dtype=torch.float32, device="cpu"):
    """The sun's shadow map over the sphere (``center`` (3 numbers), ``radius``): an
    orthographic :class:`LightVolume` of kind "ortho" whose data (R, R) holds, per texel, the
    depth along ``w = -light.direction`` of the first occluder box (inf where none).

    The frame's plane lies beyond every occluder and the sphere toward the sun, so every
    shadow caster is in front of it. Texel ``(i, j)`` traces one ray from its centre.

    Errors: TypeError naming ``scene`` unless it is a Scene, ``light`` unless it is a
    DirectionalLight, or ``dtype`` unless it is torch.float32 or torch.float64; ValueError
    naming ``resolution`` unless it is an int >= 1, or ``radius`` unless it is > 0.
    """
    # BEGIN SOLUTION (task 3)
    check_scene(scene)
    if not isinstance(light, DirectionalLight):
        raise TypeError(f"light: expected a DirectionalLight, got {type(light).__name__}")
    check_dtype(dtype)
    if isinstance(resolution, bool) or not isinstance(resolution, int) or resolution < 1:
        raise ValueError(f"resolution: expected an int >= 1, got {resolution!r}")
    if not radius > 0:
        raise ValueError(f"radius: expected a number > 0, got {radius!r}")
    axes = light_frame(tuple(-x for x in light.direction))
    c = torch.tensor(center, dtype=torch.float64)
    toward = torch.tensor(light.direction, dtype=torch.float64)
    lift = radius
    for box in scene.occluders:
        for corner in torch.cartesian_prod(
            *[torch.tensor([lo, hi], dtype=torch.float64) for lo, hi in zip(box.lo, box.hi)]
        ):
            lift = max(lift, float((corner - c) @ toward))
    origin = c + (lift + 1.0) * toward
    u, v, w = (torch.tensor(a, dtype=dtype, device=device) for a in axes)
    texel = (torch.arange(resolution, dtype=dtype, device=device) + 0.5) / resolution * 2 - 1
    a, b = torch.meshgrid(texel, texel, indexing="ij")
    starts = origin.to(device, dtype) + radius * (a[..., None] * u + b[..., None] * v)
    depth = ray_boxes(starts.reshape(-1, 3), w.expand(resolution * resolution, 3), scene.occluders)
    return LightVolume(
        "ortho",
        tuple(origin.tolist()),
        axes,
        float(radius),
        0.0,
        math.inf,
        depth.reshape(resolution, resolution),
    )
    # END SOLUTION


def shadow_lookup(shadow_map, points):
    """Sun visibility (N,) in {0, 1} of world ``points`` (N, 3): 0 where the nearest texel's
    occluder lies in front of the point by more than a bias of two texels (which keeps the
    occluders' own lit faces from shadowing themselves); 1 outside the map.

    Errors: TypeError naming ``shadow_map`` unless it is a LightVolume with (R, R) data;
    TypeError or ValueError naming ``points`` unless it is a float tensor of shape (N, 3).
    """
    # BEGIN SOLUTION (task 3)
    if not isinstance(shadow_map, LightVolume) or shadow_map.data.ndim != 2:
        raise TypeError("shadow_map: expected a LightVolume with (R, R) data from build_shadow_map")
    check_inputs({"points": (points, (3,))})
    a, b, depth = light_coords(shadow_map, points)
    res = shadow_map.data.shape[0]
    i = ((a + 1) / 2 * res).floor()
    j = ((b + 1) / 2 * res).floor()
    inside = (i >= 0) & (i < res) & (j >= 0) & (j < res)
    ii = torch.where(inside, i, 0).long()
    jj = torch.where(inside, j, 0).long()
    occluder = shadow_map.data.to(points.dtype)[ii, jj]
    bias = 4 * shadow_map.extent / res
    return (~inside | (depth <= occluder + bias)).to(points.dtype)
    # END SOLUTION


# BEGIN SOLUTION
def _light_radiance(light, points, dtype):
    """Irradiance (N, 3) arriving at ``points`` from ``light`` and unit directions (N, 3)
    toward it (no shadows)."""
    device = points.device
    color = torch.tensor(
        light.irradiance if isinstance(light, DirectionalLight) else light.intensity,
        dtype=dtype,
        device=device,
    )
    if isinstance(light, DirectionalLight):
        to_light = torch.tensor(light.direction, dtype=dtype, device=device).expand_as(points)
        return color.expand(len(points), 3), to_light
    rel = torch.tensor(light.position, dtype=dtype, device=device) - points
    dist = rel.norm(dim=-1)
    to_light = rel / dist.clamp(min=MIN_LIGHT_DISTANCE)[:, None]
    falloff = torch.where(dist < light.range, 1 / dist.clamp(min=MIN_LIGHT_DISTANCE) ** 2, 0)
    if isinstance(light, SpotLight):
        axis = torch.tensor(light.direction, dtype=dtype, device=device)
        cos_axis = -(to_light @ axis)
        lo, hi = math.cos(math.radians(light.outer_deg)), math.cos(math.radians(light.inner_deg))
        s = ((cos_axis - lo) / (hi - lo)).clamp(0, 1)
        falloff = falloff * s * s * (3 - 2 * s)
    return falloff[:, None] * color, to_light


# END SOLUTION


def light_froxels(
    scene,
    grid,
    vbuffer,
    jitter=0.5,
    *,
    phase="hg",
    volumetric_shadows=True,
    shadow_resolution=128,
    volume_resolution=None,
    light_steps=LIGHT_STEPS,
):
    """Light scattered toward the camera per unit length at every froxel, plus emission:
    ``(source (S, ny, nx, 3), report)``.

    ``source = sigma_s (ambient + sum_l phase(v . l_dir, g) E_l vis_l T_l) + emissive`` at the
    same sample points as :func:`voxelize` with this ``jitter``; ``vbuffer`` is its result
    (its dtype and device are the output's). ``E_l``: the sun's irradiance, ``I / d^2``
    (d >= MIN_LIGHT_DISTANCE, 0 beyond ``range``) for point lights, times the cone's
    smoothstep for spots; ``vis``: the sun's shadow map (``build_shadow_map`` over the
    bounding sphere of ``frustum_bounds(grid)`` at ``shadow_resolution``) when the light has
    ``shadows`` and the scene has occluders (point and spot lights cast no opaque shadows);
    ``T``: volumetric shadows when ``volumetric_shadows``, through the media inside
    ``volume_bounds(scene, grid)`` (none when it is None): one :func:`extinction_volume`
    over that box at ``volume_resolution`` (None: ``auto_volume_resolution(scene, lo, hi)``),
    then for the sun and spots :func:`transmittance_volume` at the same resolution with
    ``4 resolution`` depth samples (a fog volume's faces cost up to half a step of optical
    depth each: twice the default's samples halve that) read by :func:`sample_light_volume`,
    for point lights :func:`light_transmittance` with ``light_steps`` steps from the froxel
    to the light.

    Only what the scene requires: tiles whose froxels hold no medium are not lit; within
    the others only froxels with ``sigma_s > 0`` are, and each light only in the tiles of
    its list (:func:`cull_lights`); no volume is built without lights or without media in
    view. ``report``: ``froxels`` (total), ``froxels_lit``, ``tiles_with_media``,
    ``light_tiles`` (per light, tiles where it was evaluated), ``light_evaluations``
    (froxel-light pairs evaluated), ``volume_bounds`` (the extinction volume's ``(lo, hi)``,
    None when none was built) and ``volume_resolution`` (0 when none was built).

    Errors: TypeError naming ``scene`` unless it is a Scene, or ``grid`` unless it is a
    FroxelGrid; TypeError or ValueError naming ``jitter`` (not a number in [0, 1));
    ValueError naming ``phase`` (not ``"hg"`` or ``"schlick"``), ``volume_resolution``
    (neither None nor an int >= 2) or ``light_steps`` (not an int >= 1); TypeError naming
    ``vbuffer`` unless it is a dict with the keys :func:`voxelize` returns, and TypeError or
    ValueError naming ``vbuffer['...']`` for an entry not of its shape (float32/float64, the
    scattering's dtype and device).
    """
    # BEGIN SOLUTION (task 3)
    check_scene(scene)
    check_grid(grid)
    jitter = check_jitter(jitter)
    check_choice(phase, "phase", PHASES)
    if not isinstance(vbuffer, dict) or not {"scattering", "extinction", "emissive", "g"} <= set(
        vbuffer
    ):
        raise TypeError("vbuffer: expected the dict voxelize returns")
    sigma_s = check_volume(vbuffer["scattering"], "vbuffer['scattering']", (*grid.shape, 3))
    dtype, device = sigma_s.dtype, sigma_s.device
    sigma_t = check_volume(
        vbuffer["extinction"], "vbuffer['extinction']", grid.shape, dtype, device
    )
    emissive = check_volume(
        vbuffer["emissive"], "vbuffer['emissive']", (*grid.shape, 3), dtype, device
    )
    g = check_volume(vbuffer["g"], "vbuffer['g']", grid.shape, dtype, device)
    check_volume_resolution(volume_resolution)
    if isinstance(light_steps, bool) or not isinstance(light_steps, int) or light_steps < 1:
        raise ValueError(f"light_steps: expected an int >= 1, got {light_steps!r}")
    phase_fn = henyey_greenstein if phase == "hg" else schlick_phase

    tile_media = ((sigma_t > 0) | (emissive.amax(-1) > 0)).any(0)  # (ny, nx)
    lit = (sigma_s.amax(-1) > 0) & tile_media  # (S, ny, nx)
    idx = lit.reshape(-1).nonzero()[:, 0]
    source = emissive.clone()
    report = {
        "froxels": math.prod(grid.shape),
        "froxels_lit": len(idx),
        "tiles_with_media": int(tile_media.sum()),
        "light_tiles": [],
        "light_evaluations": 0,
        "volume_bounds": None,
        "volume_resolution": 0,
    }
    lists = cull_lights(grid, scene.lights, device)
    if len(idx) == 0:
        report["light_tiles"] = [0] * len(scene.lights)
        return source, report

    coords = froxel_sample_coords(grid, jitter, dtype, device).reshape(-1, 3)[idx]
    points = froxel_to_world(grid, coords)
    eye = torch.tensor(grid.camera.eye, dtype=dtype, device=device)
    view = points - eye
    view = view / view.norm(dim=-1, keepdim=True)
    g_lit = g.reshape(-1)[idx]
    ambient = torch.tensor(scene.ambient, dtype=dtype, device=device)
    radiance = ambient.expand(len(idx), 3).clone()

    view_lo, view_hi = frustum_bounds(grid)
    center = tuple((a + b) / 2 for a, b in zip(view_lo, view_hi))
    radius = 0.5 * math.dist(view_lo, view_hi)
    extinction = None
    bounds = volume_bounds(scene, grid) if volumetric_shadows and scene.lights else None
    if bounds is not None:
        lo, hi = bounds
        resolution = volume_resolution or auto_volume_resolution(scene, lo, hi)
        extinction = extinction_volume(scene, lo, hi, resolution, dtype, device)
        report["volume_bounds"], report["volume_resolution"] = bounds, resolution
    tile_of = idx % (grid.ny * grid.nx)
    for n, light in enumerate(scene.lights):
        in_list = lists[n].reshape(-1)[tile_of]
        report["light_tiles"].append(int((lists[n] & tile_media).sum()))
        sel = in_list.nonzero()[:, 0]
        report["light_evaluations"] += len(sel)
        if len(sel) == 0:
            continue
        p = points[sel]
        e, to_light = _light_radiance(light, p, dtype)
        e = e * phase_fn((view[sel] * to_light).sum(-1), g_lit[sel])[:, None]
        if isinstance(light, DirectionalLight) and light.shadows and scene.occluders:
            smap = build_shadow_map(scene, light, center, radius, shadow_resolution, dtype, device)
            e = e * shadow_lookup(smap, p)[:, None]
        if extinction is not None and isinstance(light, PointLight):
            e = e * light_transmittance(extinction, lo, hi, p, light.position, light_steps)[:, None]
        elif extinction is not None:
            tv = transmittance_volume(extinction, lo, hi, light, resolution, 4 * resolution)
            e = e * sample_light_volume(tv, p)[:, None]
        radiance[sel] += e
    flat = source.reshape(-1, 3)
    flat[idx] += sigma_s.reshape(-1, 3)[idx] * radiance
    return source, report
    # END SOLUTION
