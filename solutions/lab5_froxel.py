"""Lab 5: the Frostbite froxel pipeline.

Fill in every function that raises ``NotImplementedError`` (the tasks below); the helpers
imported from ``course.given.lab5`` are given. Run the grader for this lab with
``pytest tests/test_lab5_froxel.py`` (add ``-k slice_depths`` for one function). The tests call
your kernels on the CPU and, where present, on CUDA: write device- and dtype-agnostic
tensor code (loops over slices, lights or frames are fine; no loops over froxels or pixels).

Hillaire, "Physically Based and Unified Volumetric Rendering in Frostbite" (SIGGRAPH 2015),
stage by stage: a clip-space volume of froxels (frustum voxels) aligned with screen tiles,
filled with participating media (the V-buffer), lit once per froxel, accumulated over
frames, integrated front to back and applied to the opaque image. ``course.given.lab5_reference``
renders the same scenes by brute force (per pixel, many samples, exact shadows); the grader
compares the two.

Conventions shared by all kernels
---------------------------------
* A scene (:class:`course.given.lab5.Scene`): media (constant fog, height fog, local fog
  volumes with optional density textures), lights (sun with shadow map, point, spot), an
  ambient radiance and opaque boxes that shadow the sun. Physical units throughout.
* A :class:`FroxelGrid` (camera, tile, slices, near, far): volumes have shape
  ``(slices, ny, nx)`` (``[k, j, i]``: slice, tile row from the top, tile column), colour
  last. Froxel coordinates ``(x, y, z)``: ``x = pixel column / tile``, ``y = pixel row / tile``,
  ``z`` the slice coordinate (slice ``k`` spans ``[k, k + 1)``).
* Froxel ``[k, j, i]`` is sampled at ``froxel_sample_coords(grid, jitter)``: its tile's centre
  and the view depth ``z_k + jitter (z_(k+1) - z_k)``, ``jitter`` in [0, 1) (0.5 without
  temporal integration; the Halton sequence ``frame_jitter(frame)`` with it). Material and
  lighting use the same one.
* The view direction at a point p is ``v = (p - eye) / |p - eye|``; the scattering angle of
  light arriving from unit direction ``l`` (toward the light) has ``cos theta = v . l``
  (``g > 0`` scatters forward: bright looking toward the light).
* Everything works in float32 or float64 on the device of its inputs; float16/bfloat16 raise
  TypeError. Bad input raises ValueError/TypeError naming the argument.

Tasks (points)
--------------
1. ``slice_depths``, ``depth_to_slice``, ``froxel_to_world``, ``world_to_froxel``: the grid (2.5)
2. ``media_at``, ``voxelize``: the V-buffer (2)
3. ``henyey_greenstein``, ``schlick_phase``, ``cull_lights``, ``build_shadow_map``,
   ``shadow_lookup``, ``light_froxels``: scattered light per froxel (4)
4. ``extinction_volume``, ``transmittance_volume``, ``sample_light_volume``,
   ``light_transmittance``: volumetric shadows (2)
5. ``reproject``, ``temporal_blend``: temporal integration (2.5)
6. ``slice_integral``, ``integrate_froxels``: final integration (3)
7. ``apply_froxels``: application to the opaque image (1)
8. ``render_froxels``: the whole frame, end to end on your own stages (2.75; each earlier
   task is graded on the grader's inputs, so a mistake there costs its points once there
   and again only here)

Accuracy (asserted by the grader, measured by ``bench/lab5_froxel.py``)
-----------------------------------------------------------------------
* Exact to rounding: the slicing and its inverse, world <-> froxel mapping, the V-buffer at
  its sample points, the lighting at its sample points (without shadows), the per-slice
  integral (any optical depth, 0 to 1e6, with a finite gradient at 0), and the integration
  of a homogeneous medium, independent of the slice count.
* Approximate by design, at the froxel resolution: everything between sample points. A
  tile spans 8 pixels (the phase function, the path length per view depth and the edges
  of fog volumes and shadows are interpolated across it), a slice 43% of its depth at 16
  slices over 0.1 .. 30 m. Against the brute-force reference the grader allows 4-5% of the
  largest radiance (homogeneous fog, height fog), 10% at the silhouette of
  a textured fog volume and 20% at the edges of a sun shadow in fog (a tile of blur).
* Volumetric shadows cover what the scene requires: the media's bounds within the view
  (``volume_bounds``) at a resolution chosen from the media's size
  (``auto_volume_resolution``), and every light's path, point lights' too. The froxel grid
  itself is chosen from the scene (``scene_grid``): a fog volume seen from outside would
  span few fixed 8-pixel tiles and few of 64 slices over 0.1 .. 100 m, and its silhouette,
  interpolated between tile centres, would lose or gain light; by default the tiles shrink
  until every fog volume spans 12 of them and the slices cover the media's depths only
  (scenes with unbounded fog keep 8 px and 0.1 .. 100 m).

Errors against the brute-force reference and a float64 quadrature (per tile size, slice
count, volume resolution, with and without volumetric shadows or temporal integration),
measured by ``bench/lab5_froxel.py``: ``bench/results/cpu-2cores/lab5/`` (GPUs:
``bench/results/<gpu>/lab5/``).
"""

from __future__ import annotations

import math  # noqa: F401  (math.log, math.pi: you will need them)

import torch

from course.core.raymath import check_inputs  # noqa: F401  (given: validates (..., 3) inputs)
from course.given.lab5 import (  # noqa: F401  (given helpers)
    BLEND,
    INTEGRATIONS,
    LIGHT_STEPS,
    MIN_LIGHT_DISTANCE,
    PHASES,
    SCHLICK_K_MAX,
    SLICES,
    ConstantFog,
    DirectionalLight,
    FogVolume,
    FroxelGrid,
    HeightFog,
    LightVolume,
    PointLight,
    Scene,
    SpotLight,
    auto_volume_resolution,
    check_choice,
    check_depths,
    check_dtype,
    check_grid,
    check_images,
    check_jitter,
    check_lights,
    check_phase_inputs,
    check_scene,
    check_volume,
    check_volume_resolution,
    frame_jitter,
    froxel_sample_coords,
    frustum_bounds,
    light_coords,
    light_frame,
    ray_boxes,
    sample_texture,
    scene_grid,
    slice_offset,
    volume_bounds,
)

# ---------------------------------------------------------------------------------------
# Task 1: the froxel grid


def slice_depths(near, far, slices, dtype=torch.float32, device="cpu"):
    """View depths of the slice boundaries: (slices + 1,) of ``dtype``.

    Exponential slicing ``z_k = near (far / near)^(k / slices)``: each slice is the same
    fraction deeper than the last, so froxels stay roughly cube-shaped in view space and
    resolution goes where perspective puts the pixels. ``z_0 = near`` and
    ``z_slices = far`` exactly. Computed in float64, rounded once. ``0 < near < far <
    inf`` and ``slices >= 1`` (``check_depths``), else ValueError naming the argument.
    """
    # BEGIN SOLUTION (task 1)
    check_depths(near, far, slices)
    check_dtype(dtype)
    k = torch.arange(slices + 1, dtype=torch.float64, device=device)
    z = near * torch.exp(k / slices * math.log(far / near))
    z[0], z[-1] = near, far
    return z.to(dtype)
    # END SOLUTION


def depth_to_slice(depth, near, far, slices):
    """The exact inverse of :func:`slice_depths`: the continuous slice coordinate
    ``slices log(depth / near) / log(far / near)`` of view depths ``depth`` (any shape,
    float32/float64); ``-inf`` at depth 0, below 0 in front of ``near``, above ``slices``
    beyond ``far``, ``+inf`` at ``+inf``. ``log(depth) - log(near)`` keeps a tiny ``near``
    (1e-6) as accurate as any other."""
    # BEGIN SOLUTION (task 1)
    check_depths(near, far, slices)
    check_volume(depth, "depth", depth.shape if isinstance(depth, torch.Tensor) else ())
    return (torch.log(depth) - math.log(near)) * (slices / math.log(far / near))
    # END SOLUTION


# BEGIN SOLUTION
def _camera(grid, dtype, device):
    eye, right, up, fwd, (hw, hh) = grid.axes(torch.float64, device)
    return (eye.to(dtype), right.to(dtype), up.to(dtype), fwd.to(dtype), hw, hh)


def _view_dirs(grid, x, y, dtype, device):
    """Directions with unit view depth through froxel coordinates x, y: (..., 3)."""
    _, right, up, fwd, hw, hh = _camera(grid, dtype, device)
    ndc_x = 2 * x * grid.tile / grid.camera.width - 1
    ndc_y = 1 - 2 * y * grid.tile / grid.camera.height
    return fwd + (ndc_x * hw)[..., None] * right + (ndc_y * hh)[..., None] * up
# END SOLUTION


def froxel_to_world(grid, coords):
    """World points of froxel coordinates ``coords`` (..., 3) ``(x, y, z)``: the point at
    the view depth of slice coordinate ``z`` on the ray through pixel
    ``(column, row) = (x, y) * tile``. Returns (..., 3) of ``coords``' dtype."""
    # BEGIN SOLUTION (task 1)
    check_grid(grid)
    check_inputs({"coords": (coords, (3,))})
    check_dtype(coords.dtype, "coords")
    eye = _camera(grid, coords.dtype, coords.device)[0]
    depth = grid.near * torch.exp(coords[..., 2] * (math.log(grid.far / grid.near)
                                                    / grid.slices))
    dirs = _view_dirs(grid, coords[..., 0], coords[..., 1], coords.dtype, coords.device)
    return eye + depth[..., None] * dirs
    # END SOLUTION


def world_to_froxel(grid, points):
    """Froxel coordinates (..., 3) of world ``points`` (..., 3): the inverse of
    :func:`froxel_to_world`. Points at or behind the eye's plane (view depth <= 0) get NaN."""
    # BEGIN SOLUTION (task 1)
    check_grid(grid)
    check_inputs({"points": (points, (3,))})
    check_dtype(points.dtype, "points")
    eye, right, up, fwd, hw, hh = _camera(grid, points.dtype, points.device)
    rel = points - eye
    depth = rel @ fwd
    safe = torch.where(depth > 0, depth, math.nan)
    ndc_x = (rel @ right) / (safe * hw)
    ndc_y = (rel @ up) / (safe * hh)
    x = (ndc_x + 1) * grid.camera.width / (2 * grid.tile)
    y = (1 - ndc_y) * grid.camera.height / (2 * grid.tile)
    z = depth_to_slice(safe, grid.near, grid.far, grid.slices)
    return torch.stack([x, y, z], -1)
    # END SOLUTION


# ---------------------------------------------------------------------------------------
# Task 2: the V-buffer


# BEGIN SOLUTION
def _fog_volume_weight(vol, points):
    """Density multiplier (N,) of a local fog volume at world points (N, 3)."""
    dtype, device = points.dtype, points.device
    center = torch.tensor(vol.center, dtype=dtype, device=device)
    axes = torch.tensor(vol.rotation, dtype=dtype, device=device)
    half = torch.tensor(vol.half_size, dtype=dtype, device=device)
    local = ((points - center) @ axes.T) / half  # [-1, 1]^3 inside the box
    if vol.shape == "box":
        inside = (local.abs() <= 1).all(-1)
    else:
        inside = local.square().sum(-1) <= 1
    weight = inside.to(dtype)
    if vol.density is not None:
        tex = vol.density.to(device=device, dtype=dtype)
        coords = (local + 1) / 2 * torch.tensor(tex.shape, dtype=dtype, device=device)
        weight = weight * sample_texture(tex, coords)
    return weight
# END SOLUTION


def media_at(scene, points):
    """The scene's media at world ``points`` (N, 3): a dict of ``scattering`` (N, 3),
    ``extinction`` (N,), ``emissive`` (N, 3) and ``g`` (N,) in the points' dtype.

    Every medium's coefficients times its density at the point, summed linearly;
    ``g`` is the scattering-weighted mean of the media's ``g`` (weight: mean scattering over
    RGB), 0 where nothing scatters. Height fog: density ``exp(-falloff (y - base))``;
    fog volumes: 1 inside the shape times the density texture, 0 outside.
    """
    # BEGIN SOLUTION (task 2)
    check_scene(scene)
    check_inputs({"points": (points, (3,))})
    check_dtype(points.dtype, "points")
    if points.ndim != 2:
        raise ValueError(f"points: expected shape (N, 3), got {tuple(points.shape)}")
    n, dtype, device = len(points), points.dtype, points.device
    scattering = torch.zeros(n, 3, dtype=dtype, device=device)
    extinction = torch.zeros(n, dtype=dtype, device=device)
    emissive = torch.zeros(n, 3, dtype=dtype, device=device)
    g_weighted = torch.zeros(n, dtype=dtype, device=device)
    for medium in scene.media:
        if isinstance(medium, ConstantFog):
            w = torch.ones(n, dtype=dtype, device=device)
        elif isinstance(medium, HeightFog):
            w = torch.exp(-medium.falloff * (points[:, 1] - medium.base))
        else:
            w = _fog_volume_weight(medium, points)
        sigma_s = torch.tensor(medium.scattering, dtype=dtype, device=device)
        scattering = scattering + w[:, None] * sigma_s
        extinction = extinction + w * medium.extinction
        emissive = emissive + w[:, None] * torch.tensor(medium.emissive, dtype=dtype,
                                                        device=device)
        g_weighted = g_weighted + w * (sigma_s.mean() * medium.g)
    weight = scattering.mean(-1)
    g = torch.where(weight > 0, g_weighted / torch.where(weight > 0, weight, 1.0), 0.0)
    return {"scattering": scattering, "extinction": extinction, "emissive": emissive, "g": g}
    # END SOLUTION


def voxelize(scene, grid, jitter=0.5, dtype=torch.float32, device="cpu"):
    """The V-buffer: :func:`media_at` at every froxel's sample point
    ``froxel_to_world(grid, froxel_sample_coords(grid, jitter))``: the tile's centre, the
    fraction ``jitter`` of the way through the slice in view depth.

    Returns a dict of ``scattering`` (S, ny, nx, 3), ``extinction`` (S, ny, nx),
    ``emissive`` (S, ny, nx, 3), ``g`` (S, ny, nx) of ``dtype`` on ``device``.
    """
    # BEGIN SOLUTION (task 2)
    check_scene(scene)
    check_grid(grid)
    jitter = check_jitter(jitter)
    check_dtype(dtype)
    coords = froxel_sample_coords(grid, jitter, dtype, device)
    media = media_at(scene, froxel_to_world(grid, coords).reshape(-1, 3))
    return {k: v.reshape(*grid.shape, *v.shape[1:]) for k, v in media.items()}
    # END SOLUTION


# ---------------------------------------------------------------------------------------
# Task 3: lighting


def henyey_greenstein(cos_theta, g):
    """Henyey–Greenstein phase function per steradian,
    ``(1 - g^2) / (4 pi (1 + g^2 - 2 g cos theta)^(3/2))``.

    cos_theta: any shape, float32/float64; g: a number or a tensor broadcasting with it,
    in (-1, 1). Normalised over the sphere, mean cosine ``g``; ``1 / (4 pi)`` at g = 0.
    ``cos_theta`` outside [-1, 1] (a dot product of unit vectors a rounding step past
    +-1) is clamped to [-1, 1]: the value is always finite and positive.
    """
    # BEGIN SOLUTION (task 3)
    g = check_phase_inputs(cos_theta, g)
    cos_theta = cos_theta.clamp(-1, 1)
    denom = (1 + g * g - 2 * g * cos_theta).clamp(min=0)
    return (1 - g * g) / (4 * math.pi * denom * denom.sqrt())
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
    k = (1.55 * g - 0.55 * g ** 3).clamp(-SCHLICK_K_MAX, SCHLICK_K_MAX)
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


def build_shadow_map(scene, light, center, radius, resolution, dtype=torch.float32,
                     device="cpu"):
    """The sun's shadow map over the sphere (``center`` (3 numbers), ``radius``): an
    orthographic :class:`LightVolume` of kind "ortho" whose data (R, R) holds, per texel, the
    depth along ``w = -light.direction`` of the first occluder box (inf where none).

    The frame's plane lies beyond every occluder and the sphere toward the sun, so every
    shadow caster is in front of it. Texel ``(i, j)`` traces one ray from its centre.
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
        for corner in torch.cartesian_prod(*[torch.tensor([lo, hi], dtype=torch.float64)
                                             for lo, hi in zip(box.lo, box.hi)]):
            lift = max(lift, float((corner - c) @ toward))
    origin = c + (lift + 1.0) * toward
    u, v, w = (torch.tensor(a, dtype=dtype, device=device) for a in axes)
    texel = (torch.arange(resolution, dtype=dtype, device=device) + 0.5) / resolution * 2 - 1
    a, b = torch.meshgrid(texel, texel, indexing="ij")
    starts = origin.to(device, dtype) + radius * (a[..., None] * u + b[..., None] * v)
    depth = ray_boxes(starts.reshape(-1, 3), w.expand(resolution * resolution, 3),
                      scene.occluders)
    return LightVolume("ortho", tuple(origin.tolist()), axes, float(radius), 0.0, math.inf,
                       depth.reshape(resolution, resolution))
    # END SOLUTION


def shadow_lookup(shadow_map, points):
    """Sun visibility (N,) in {0, 1} of world ``points`` (N, 3): 0 where the nearest texel's
    occluder lies in front of the point by more than a bias of two texels (which keeps the
    occluders' own lit faces from shadowing themselves); 1 outside the map."""
    # BEGIN SOLUTION (task 3)
    if not isinstance(shadow_map, LightVolume) or shadow_map.data.ndim != 2:
        raise TypeError("shadow_map: expected a LightVolume with (R, R) data from "
                        "build_shadow_map")
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
    color = torch.tensor(light.irradiance if isinstance(light, DirectionalLight)
                         else light.intensity, dtype=dtype, device=device)
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


def light_froxels(scene, grid, vbuffer, jitter=0.5, *, phase="hg", volumetric_shadows=True,
                  shadow_resolution=128, volume_resolution=None, light_steps=LIGHT_STEPS):
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
    """
    # BEGIN SOLUTION (task 3)
    check_scene(scene)
    check_grid(grid)
    jitter = check_jitter(jitter)
    check_choice(phase, "phase", PHASES)
    if not isinstance(vbuffer, dict) or not {"scattering", "extinction", "emissive",
                                             "g"} <= set(vbuffer):
        raise TypeError("vbuffer: expected the dict voxelize returns")
    sigma_s = check_volume(vbuffer["scattering"], "vbuffer['scattering']", (*grid.shape, 3))
    dtype, device = sigma_s.dtype, sigma_s.device
    sigma_t = check_volume(vbuffer["extinction"], "vbuffer['extinction']", grid.shape, dtype,
                           device)
    emissive = check_volume(vbuffer["emissive"], "vbuffer['emissive']", (*grid.shape, 3),
                            dtype, device)
    g = check_volume(vbuffer["g"], "vbuffer['g']", grid.shape, dtype, device)
    check_volume_resolution(volume_resolution)
    if isinstance(light_steps, bool) or not isinstance(light_steps, int) or light_steps < 1:
        raise ValueError(f"light_steps: expected an int >= 1, got {light_steps!r}")
    phase_fn = henyey_greenstein if phase == "hg" else schlick_phase

    tile_media = ((sigma_t > 0) | (emissive.amax(-1) > 0)).any(0)  # (ny, nx)
    lit = (sigma_s.amax(-1) > 0) & tile_media  # (S, ny, nx)
    idx = lit.reshape(-1).nonzero()[:, 0]
    source = emissive.clone()
    report = {"froxels": math.prod(grid.shape), "froxels_lit": len(idx),
              "tiles_with_media": int(tile_media.sum()), "light_tiles": [],
              "light_evaluations": 0, "volume_bounds": None, "volume_resolution": 0}
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
            smap = build_shadow_map(scene, light, center, radius, shadow_resolution, dtype,
                                    device)
            e = e * shadow_lookup(smap, p)[:, None]
        if extinction is not None and isinstance(light, PointLight):
            e = e * light_transmittance(extinction, lo, hi, p, light.position,
                                        light_steps)[:, None]
        elif extinction is not None:
            tv = transmittance_volume(extinction, lo, hi, light, resolution,
                                      4 * resolution)
            e = e * sample_light_volume(tv, p)[:, None]
        radiance[sel] += e
    flat = source.reshape(-1, 3)
    flat[idx] += sigma_s.reshape(-1, 3)[idx] * radiance
    return source, report
    # END SOLUTION


# ---------------------------------------------------------------------------------------
# Task 4: volumetric shadow maps


def extinction_volume(scene, lo, hi, resolution, dtype=torch.float32, device="cpu"):
    """Extinction (R, R, R) at the voxel centres of the box ``lo .. hi`` (3 numbers each),
    R = ``resolution``, x the first axis: :func:`media_at` sampled on a world-aligned grid
    around the camera, the input of every light's transmittance volume."""
    # BEGIN SOLUTION (task 4)
    check_scene(scene)
    check_dtype(dtype)
    if isinstance(resolution, bool) or not isinstance(resolution, int) or resolution < 2:
        raise ValueError(f"resolution: expected an int >= 2, got {resolution!r}")
    lo_t = torch.tensor(lo, dtype=dtype, device=device)
    hi_t = torch.tensor(hi, dtype=dtype, device=device)
    if lo_t.shape != (3,) or not bool((lo_t < hi_t).all()):
        raise ValueError(f"hi: expected lo < hi (3 numbers each), got {lo} .. {hi}")
    t = (torch.arange(resolution, dtype=dtype, device=device) + 0.5) / resolution
    grid = torch.stack(torch.meshgrid(t, t, t, indexing="ij"), -1)
    points = lo_t + grid.reshape(-1, 3) * (hi_t - lo_t)
    return media_at(scene, points)["extinction"].reshape(resolution, resolution, resolution)
    # END SOLUTION


# BEGIN SOLUTION
def _sample_extinction(extinction, lo, hi, points):
    """Trilinear extinction at world points (..., 3); 0 outside the box."""
    lo_t = torch.tensor(lo, dtype=points.dtype, device=points.device)
    hi_t = torch.tensor(hi, dtype=points.dtype, device=points.device)
    local = (points - lo_t) / (hi_t - lo_t)
    inside = ((local >= 0) & (local <= 1)).all(-1)
    sizes = torch.tensor(extinction.shape, dtype=points.dtype, device=points.device)
    return torch.where(inside, sample_texture(extinction, local * sizes), 0)
# END SOLUTION


def light_transmittance(extinction, lo, hi, points, position, steps=LIGHT_STEPS):
    """Transmittance (N,) from world ``points`` (N, 3) to a point light at ``position``
    (3 numbers) through the extinction volume (X, Y, Z) over ``lo .. hi`` (trilinear, 0
    outside the box).

    Only the part ``[t0, t1]`` of the segment ``p + t (position - p)``, ``0 <= t <= 1``,
    inside the box is marched (slab test): ``steps`` equal steps, midpoint rule,
    ``exp(-sum_m sigma(mid_m) ds)``, exact for a medium constant along it. 1 where the
    segment misses the box or has zero length (a point on the light); in [0, 1], no NaN.
    A segment lying in the plane of one of the box's faces (a tie between inside and
    outside) may count as either.
    """
    # BEGIN SOLUTION (task 4)
    check_volume(extinction, "extinction", extinction.shape if isinstance(
        extinction, torch.Tensor) and extinction.ndim == 3 else (1, 1, 1))
    check_inputs({"points": (points, (3,))})
    if isinstance(steps, bool) or not isinstance(steps, int) or steps < 1:
        raise ValueError(f"steps: expected an int >= 1, got {steps!r}")
    dtype, device = points.dtype, points.device
    rel = torch.tensor(position, dtype=dtype, device=device) - points
    lo_t = torch.tensor(lo, dtype=dtype, device=device)
    hi_t = torch.tensor(hi, dtype=dtype, device=device)
    inv = torch.reciprocal(rel)
    a, b = (lo_t - points) * inv, (hi_t - points) * inv
    t0 = torch.minimum(a, b).nan_to_num(nan=-math.inf).amax(-1).clamp(min=0)
    t1 = torch.maximum(a, b).nan_to_num(nan=math.inf).amin(-1).clamp(max=1)
    span = torch.nan_to_num(t1 - t0, nan=0.0).clamp(min=0)
    t0 = torch.where(span > 0, t0, 0)
    depth = torch.zeros_like(span)
    for m in range(steps):
        q = points + (t0 + (m + 0.5) / steps * span)[:, None] * rel
        depth = depth + _sample_extinction(extinction, lo, hi, q)
    return torch.exp(-depth * (span * rel.norm(dim=-1) / steps))
    # END SOLUTION


def transmittance_volume(extinction, lo, hi, light, resolution=32, steps=None):
    """A light's transmittance volume: :class:`LightVolume` with data (R, R, K).

    extinction: (X, Y, Z) from :func:`extinction_volume` over ``lo .. hi``, sampled
    trilinearly (0 outside). For the sun an orthographic frame over the bounding sphere of
    the box (``w`` away from the sun, depths ``near .. far`` across the sphere); for a spot
    light a perspective frame on its cone (``extent = tan(outer angle)``, depths 0 ..
    range). Each texel marches its ray from the light side in K - 1 equal steps
    (K = ``steps`` or ``2 resolution``), accumulating optical depth with the midpoint rule:
    ``data[i, j, k] = exp(-sum_{m<k} sigma_t(mid_m) step)``. A point light gets no volume
    (TypeError naming ``light``): :func:`light_transmittance` marches its paths.
    """
    # BEGIN SOLUTION (task 4)
    check_volume(extinction, "extinction", extinction.shape if isinstance(
        extinction, torch.Tensor) and extinction.ndim == 3 else (1, 1, 1))
    if not isinstance(light, (DirectionalLight, SpotLight)):
        raise TypeError(f"light: expected a DirectionalLight or SpotLight (point lights cast "
                        f"no volumetric shadows), got {type(light).__name__}")
    if isinstance(resolution, bool) or not isinstance(resolution, int) or resolution < 1:
        raise ValueError(f"resolution: expected an int >= 1, got {resolution!r}")
    k = steps or 2 * resolution
    dtype, device = extinction.dtype, extinction.device
    texel = (torch.arange(resolution, dtype=dtype, device=device) + 0.5) / resolution * 2 - 1
    a, b = torch.meshgrid(texel, texel, indexing="ij")
    if isinstance(light, DirectionalLight):
        axes = light_frame(tuple(-x for x in light.direction))
        center = torch.tensor([(x + y) / 2 for x, y in zip(lo, hi)], dtype=torch.float64)
        radius = 0.5 * math.dist(lo, hi)
        origin = center + radius * torch.tensor(light.direction, dtype=torch.float64)
        kind, extent, near, far = "ortho", radius, 0.0, 2 * radius
    else:
        axes = light_frame(light.direction)
        origin = torch.tensor(light.position, dtype=torch.float64)
        kind, extent = "persp", math.tan(math.radians(light.outer_deg))
        near, far = 0.0, light.range
    u, v, w = (torch.tensor(x, dtype=dtype, device=device) for x in axes)
    o = origin.to(device, dtype)
    if kind == "ortho":
        starts = o + extent * (a[..., None] * u + b[..., None] * v)
        dirs = w.expand_as(starts)
    else:
        starts = o.expand(resolution, resolution, 3)
        dirs = w + extent * (a[..., None] * u + b[..., None] * v)
        dirs = dirs / dirs.norm(dim=-1, keepdim=True)
    step = (far - near) / (k - 1) if k > 1 else 0.0
    mids = near + (torch.arange(k - 1, dtype=dtype, device=device) + 0.5) * step
    samples = starts[:, :, None] + mids[:, None] * dirs[:, :, None]  # (R, R, K-1, 3)
    sigma = _sample_extinction(extinction, lo, hi, samples)
    depth = torch.cat([torch.zeros(resolution, resolution, 1, dtype=dtype, device=device),
                       torch.cumsum(sigma * step, -1)], -1)
    return LightVolume(kind, tuple(origin.tolist()), axes, float(extent), float(near),
                       float(far), torch.exp(-depth))
    # END SOLUTION


def sample_light_volume(volume, points):
    """Transmittance (N,) toward the light at world ``points`` (N, 3): trilinear in the
    volume's texels and depth samples (clamped at its ends); 1 outside the map laterally
    and behind a spot light."""
    # BEGIN SOLUTION (task 4)
    if not isinstance(volume, LightVolume) or volume.data.ndim != 3:
        raise TypeError("volume: expected a LightVolume with (R, R, K) data from "
                        "transmittance_volume")
    check_inputs({"points": (points, (3,))})
    a, b, depth = light_coords(volume, points)
    r, _, k = volume.data.shape
    inside = (a.abs() <= 1) & (b.abs() <= 1)
    coords = torch.stack([(a + 1) / 2 * r, (b + 1) / 2 * r,
                          (depth - volume.near) / (volume.far - volume.near) * (k - 1) + 0.5],
                         -1)
    t = sample_texture(volume.data.to(points.dtype), torch.where(inside[:, None], coords, 0))
    return torch.where(inside, t, 1.0)
    # END SOLUTION


# ---------------------------------------------------------------------------------------
# Task 5: temporal integration


def reproject(history, prev_grid, grid):
    """The previous frame's volume seen from the current froxels: ``(values, valid)``.

    history: (S, ny, nx) or (S, ny, nx, C) on ``prev_grid``; ``grid``: the current frame's
    grid (same shape, another camera). Each current froxel's centre (jitter 0.5: the tile's
    centre, the slice's middle depth) is moved to world space and into ``prev_grid``'s
    froxel coordinates; ``values`` are the history sampled trilinearly there (shape of
    ``history``; its voxels sit at the froxel centres ``froxel_sample_coords(prev_grid,
    0.5)``, clamped at the border), ``valid`` (S, ny, nx) bool is True only where that
    point lies inside the previous froxel volume (``0 <= x <= nx``, ``0 <= y <= ny``,
    ``0 <= z <= slices``): history from outside the previous frustum is dropped.
    """
    # BEGIN SOLUTION (task 5)
    check_grid(grid)
    if not isinstance(prev_grid, FroxelGrid):
        raise TypeError(f"prev_grid: expected a FroxelGrid, got {type(prev_grid).__name__}")
    if prev_grid.shape != grid.shape:
        raise ValueError(f"prev_grid: expected the shape {grid.shape} of grid, got "
                         f"{prev_grid.shape}")
    if not isinstance(history, torch.Tensor) or history.ndim not in (3, 4) \
            or tuple(history.shape[:3]) != grid.shape:
        raise ValueError(f"history: expected shape {grid.shape} or {grid.shape} + (C,), got "
                         f"{tuple(getattr(history, 'shape', ()))}")
    check_dtype(history.dtype, "history")
    coords = froxel_sample_coords(grid, 0.5, history.dtype, history.device)
    prev = world_to_froxel(prev_grid, froxel_to_world(grid, coords))
    limits = torch.tensor([grid.nx, grid.ny, grid.slices], dtype=history.dtype,
                          device=history.device)
    valid = ((prev >= 0) & (prev <= limits)).all(-1)  # NaN compares False: dropped
    # History voxels sit at the froxel centres: x, y = i + 0.5, j + 0.5, z = k + offset.
    lookup = prev - torch.tensor([0.0, 0.0, slice_offset(grid, 0.5) - 0.5],
                                 dtype=prev.dtype, device=prev.device)
    zyx = torch.where(valid[..., None], lookup.flip(-1), 0)
    return sample_texture(history, zyx), valid
    # END SOLUTION


def temporal_blend(current, history, valid, alpha=BLEND):
    """Exponential moving average: ``history + alpha (current - history)`` where ``valid``
    (broadcast over a trailing colour axis), ``current`` elsewhere. current, history:
    (S, ny, nx) or (S, ny, nx, C) of one dtype; valid: (S, ny, nx) bool; alpha in (0, 1]."""
    # BEGIN SOLUTION (task 5)
    check_volume(current, "current", current.shape if isinstance(current, torch.Tensor)
                 else ())
    check_volume(history, "history", current.shape, current.dtype, current.device)
    if not isinstance(valid, torch.Tensor) or valid.dtype != torch.bool \
            or tuple(valid.shape) != tuple(current.shape[:3]):
        raise ValueError(f"valid: expected a bool tensor of shape {tuple(current.shape[:3])}")
    if isinstance(alpha, bool) or not isinstance(alpha, (int, float)) or not 0 < alpha <= 1:
        raise ValueError(f"alpha: expected a number in (0, 1], got {alpha!r}")
    mask = valid if current.ndim == 3 else valid[..., None]
    return torch.where(mask, history + alpha * (current - history), current)
    # END SOLUTION


# ---------------------------------------------------------------------------------------
# Task 6: final integration


def slice_integral(source, extinction, length):
    """One slice of constant medium: ``(integral, transmittance)``.

    ``integral = int_0^D e^(-sigma_t x) S dx = S D phi(sigma_t D)`` with
    ``phi(x) = (1 - e^(-x)) / x`` (= 1 at 0), the talk's ``(S - S e^(-sigma_t D)) / sigma_t``
    written so it stays exact as ``sigma_t -> 0`` (``S D``, with a finite gradient) and
    for huge ``sigma_t`` (``S / sigma_t``, transmittance 0, no NaN). source (..., C) or
    (...); extinction, length: broadcasting with it (without C), >= 0 (``inf`` allowed):
    a negative one raises ValueError naming it (it would give a transmittance above 1).
    A slice of zero length, or of no medium, is no optical depth even where the other
    factor is ``inf``: ``(0, 1)``, as ``sigma_t = inf`` over ``D = 0``.
    Returns tensors of the broadcast shape (integral with C).
    """
    # BEGIN SOLUTION (task 6)
    for name, x in (("source", source), ("extinction", extinction), ("length", length)):
        if not isinstance(x, torch.Tensor) or not x.is_floating_point():
            raise TypeError(f"{name}: expected a float tensor, got "
                            f"{getattr(x, 'dtype', type(x).__name__)}")
    for name, x in (("extinction", extinction), ("length", length)):
        if bool((x < 0).any()):
            raise ValueError(f"{name}: expected values >= 0, got {int((x < 0).sum())} "
                             f"negative (minimum {x.min().item():.3g})")
    # inf * 0 is no optical depth (written so autograd keeps d tau / d sigma = length).
    finite = torch.where(torch.isinf(length) & (extinction == 0), 0, length)
    tau = torch.where(length == 0, 0, extinction * finite)
    small = tau < 1e-4
    safe = torch.where(small, 1.0, tau)
    # Below 1e-4 the series 1 - x/2 + x^2/6 is exact to float64 rounding.
    phi = torch.where(small, 1 - tau / 2 + tau * tau / 6, -torch.expm1(-safe) / safe)
    factor = length * phi
    if source.ndim == factor.ndim + 1:
        factor = factor[..., None]
    return source * factor, torch.exp(-tau)
    # END SOLUTION


def integrate_froxels(source, extinction, grid, method="energy"):
    """Front-to-back accumulation along every froxel column: ``(inscatter (S, ny, nx, 3),
    transmittance (S, ny, nx))`` from ``near`` to the far boundary of each slice.

    source: (S, ny, nx, 3) light per unit length; extinction: (S, ny, nx). Slice ``k`` of
    column ``(j, i)`` is ``(z_{k+1} - z_k) |dir|`` long along the ray through the tile centre
    (``dir`` with unit view depth). method "energy": ``L += T * slice_integral``, then
    ``T *= e^(-sigma_t D)`` (after: the slice's own medium absorbs only via the integral).
    "naive": ``L += T * S D`` (the talk's leak: no absorption within a slice, so a dense
    slice emits more light than it can). A loop over slices or prefix sums (``cumsum``
    of the optical depths) are both fine; the result is the same to rounding. A negative
    extinction raises ValueError naming ``extinction`` with either method (it would give a
    transmittance above 1).
    """
    # BEGIN SOLUTION (task 6)
    check_grid(grid)
    check_choice(method, "method", INTEGRATIONS)
    check_volume(source, "source", (*grid.shape, 3))
    dtype, device = source.dtype, source.device
    check_volume(extinction, "extinction", grid.shape, dtype, device)
    if bool((extinction < 0).any()):
        raise ValueError(f"extinction: expected values >= 0, got minimum "
                         f"{extinction.min().item():.3g}")
    z = slice_depths(grid.near, grid.far, grid.slices, torch.float64, device)
    j = torch.arange(grid.ny, dtype=torch.float64, device=device) + 0.5
    i = torch.arange(grid.nx, dtype=torch.float64, device=device) + 0.5
    jj, ii = torch.meshgrid(j, i, indexing="ij")
    stretch = _view_dirs(grid, ii, jj, torch.float64, device).norm(dim=-1)  # (ny, nx)
    lengths = ((z[1:] - z[:-1])[:, None, None] * stretch).to(dtype)  # (S, ny, nx)
    # Front to back without a loop over slices: the transmittance in front of slice k is
    # exp(-(sum of the optical depths before it)), an exclusive prefix sum.
    tau = extinction * lengths
    behind = torch.cumsum(tau, 0)
    in_front = torch.exp(-(behind - tau))
    if method == "energy":
        piece, _ = slice_integral(source, extinction, lengths)
    else:
        piece = source * lengths[..., None]
    radiance = torch.cumsum(in_front[..., None] * piece, 0)
    return radiance, torch.exp(-behind)
    # END SOLUTION


# ---------------------------------------------------------------------------------------
# Task 7: application (and task 8, the whole frame)


def apply_froxels(inscatter, transmittance, grid, depth_image, opaque_image, out=None):
    """Fog over the opaque image: ``out = opaque * T(p) + L(p)`` (premultiplied colour/alpha)
    at each pixel's view depth. Returns (H, W, 3), written into ``out`` when given.

    inscatter (S, ny, nx, 3), transmittance (S, ny, nx): :func:`integrate_froxels`'s values
    at the slices' far boundaries; with ``(L, T) = (0, 1)`` at ``near`` they sit on the
    nodes ``z = 0 .. slices`` of the slice coordinate, and across the screen at the tile
    centres. Lookup: trilinear at ``(pixel column + 0.5) / tile, (row + 0.5) / tile`` and
    ``depth_to_slice(depth)`` clamped to ``[0, slices]``: depths beyond ``far`` (and the sky,
    +inf) read the last slice, depths before ``near`` get no fog. depth_image (H, W) view
    depths >= 0 or +inf (NaN or negative depths raise ValueError naming it); opaque_image
    (H, W, 3) of the depths' dtype (else TypeError) and device (``check_images``); NaN/inf
    colours pass through as ``opaque * T + L`` would make them.
    """
    # BEGIN SOLUTION (task 7)
    check_grid(grid)
    dtype = check_images(grid.camera, depth_image, opaque_image)
    device = depth_image.device
    check_volume(inscatter, "inscatter", (*grid.shape, 3), dtype, device)
    check_volume(transmittance, "transmittance", grid.shape, dtype, device)
    h, w = depth_image.shape
    if out is not None:
        check_volume(out, "out", (h, w, 3), dtype, device)
    nodes = torch.cat([torch.cat([torch.zeros(1, grid.ny, grid.nx, 3, dtype=dtype,
                                              device=device), inscatter]),
                       torch.cat([torch.ones(1, grid.ny, grid.nx, dtype=dtype, device=device),
                                  transmittance])[..., None]], -1)  # (S + 1, ny, nx, 4)
    z = depth_to_slice(depth_image, grid.near, grid.far, grid.slices)
    z = torch.nan_to_num(z, nan=0.0, posinf=grid.slices, neginf=0.0).clamp(0, grid.slices)
    rows = ((torch.arange(h, dtype=dtype, device=device) + 0.5) / grid.tile)[:, None]
    cols = ((torch.arange(w, dtype=dtype, device=device) + 0.5) / grid.tile)[None, :]
    coords = torch.stack([z + 0.5, rows.expand(h, w), cols.expand(h, w)], -1)
    values = sample_texture(nodes, coords)  # (H, W, 4)
    result = opaque_image * values[..., 3:] + values[..., :3]
    if out is None:
        return result
    out.copy_(result)
    return out
    # END SOLUTION


def render_froxels(scene, camera, depth_image, opaque_image, *, tile=None, slices=SLICES,
                   near=None, far=None, phase="hg", integration="energy", volumetric_shadows=True,
                   shadow_resolution=128, volume_resolution=None, light_steps=LIGHT_STEPS,
                   temporal=False, frame=0, history=None):
    """One frame of the pipeline: ``(image (H, W, 3), report)``.

    voxelize -> light_froxels -> (temporal: reproject + temporal_blend of the lit source
    and the extinction) -> integrate_froxels -> apply_froxels, on a
    ``scene_grid(scene, camera, tile, slices, near, far)`` (None: the tile size and depth
    range the scene's media need, see there), in the dtype and on the device of the images.
    With ``temporal`` the froxels sample at ``frame_jitter(frame)`` (material and lighting
    alike), and ``history`` (the previous report's ``"history"``, or None) is
    reprojected and blended with weight ``BLEND`` for the new frame.

    The images as :func:`apply_froxels` takes them (checked even without media); bad
    settings (``tile``, ``slices``, ``near``, ``far``, ``phase``, ``integration``,
    ``frame``, ``history``) raise errors naming them.
    A scene without media returns a copy of ``opaque_image`` and does no V-buffer or
    lighting work. ``report``: ``grid``, ``froxels``, ``froxels_lit``, ``tiles_with_media``,
    ``light_tiles``, ``light_evaluations``, ``volume_bounds``, ``volume_resolution`` (as
    :func:`light_froxels`), ``jitter``,
    ``history_valid`` (fraction of froxels that kept history) and ``history`` (a dict
    ``{"grid", "source", "extinction", "frame"}`` for the next frame).
    """
    # BEGIN SOLUTION (task 8)
    check_scene(scene)
    grid = scene_grid(scene, camera, tile, slices, near, far)
    check_images(camera, depth_image, opaque_image)
    check_choice(phase, "phase", PHASES)
    check_choice(integration, "integration", INTEGRATIONS)
    if isinstance(frame, bool) or not isinstance(frame, int) or frame < 0:
        raise ValueError(f"frame: expected an int >= 0, got {frame!r}")
    dtype, device = depth_image.dtype, depth_image.device
    jitter = frame_jitter(frame) if temporal else 0.5
    report = {"grid": grid, "froxels": math.prod(grid.shape), "froxels_lit": 0,
              "tiles_with_media": 0, "light_tiles": [0] * len(scene.lights),
              "light_evaluations": 0, "volume_bounds": None, "volume_resolution": 0,
              "jitter": jitter, "history_valid": 0.0, "history": None}
    if not scene.media:
        return opaque_image.clone(), report
    vbuffer = voxelize(scene, grid, jitter, dtype, device)
    source, light_report = light_froxels(scene, grid, vbuffer, jitter, phase=phase,
                                         volumetric_shadows=volumetric_shadows,
                                         shadow_resolution=shadow_resolution,
                                         volume_resolution=volume_resolution,
                                         light_steps=light_steps)
    report.update(light_report)
    extinction = vbuffer["extinction"]
    if temporal and history is not None:
        if not isinstance(history, dict) or not {"grid", "source", "extinction"} <= set(history):
            raise TypeError("history: expected None or the previous report's 'history' dict")
        prev_source, valid = reproject(history["source"], history["grid"], grid)
        prev_ext, _ = reproject(history["extinction"], history["grid"], grid)
        source = temporal_blend(source, prev_source, valid)
        extinction = temporal_blend(extinction, prev_ext, valid)
        report["history_valid"] = valid.to(torch.float64).mean().item()
    if temporal:
        report["history"] = {"grid": grid, "source": source, "extinction": extinction,
                             "frame": frame}
    inscatter, transmittance = integrate_froxels(source, extinction, grid, integration)
    return apply_froxels(inscatter, transmittance, grid, depth_image, opaque_image), report
    # END SOLUTION
