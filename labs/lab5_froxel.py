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
    raise NotImplementedError("not implemented yet: slice_depths (task 1)")


def depth_to_slice(depth, near, far, slices):
    """The exact inverse of :func:`slice_depths`: the continuous slice coordinate
    ``slices log(depth / near) / log(far / near)`` of view depths ``depth`` (any shape,
    float32/float64); ``-inf`` at depth 0, below 0 in front of ``near``, above ``slices``
    beyond ``far``, ``+inf`` at ``+inf``. ``log(depth) - log(near)`` keeps a tiny ``near``
    (1e-6) as accurate as any other."""
    raise NotImplementedError("not implemented yet: depth_to_slice (task 1)")


def froxel_to_world(grid, coords):
    """World points of froxel coordinates ``coords`` (..., 3) ``(x, y, z)``: the point at
    the view depth of slice coordinate ``z`` on the ray through pixel
    ``(column, row) = (x, y) * tile``. Returns (..., 3) of ``coords``' dtype."""
    raise NotImplementedError("not implemented yet: froxel_to_world (task 1)")


def world_to_froxel(grid, points):
    """Froxel coordinates (..., 3) of world ``points`` (..., 3): the inverse of
    :func:`froxel_to_world`. Points at or behind the eye's plane (view depth <= 0) get NaN."""
    raise NotImplementedError("not implemented yet: world_to_froxel (task 1)")


# ---------------------------------------------------------------------------------------
# Task 2: the V-buffer


def media_at(scene, points):
    """The scene's media at world ``points`` (N, 3): a dict of ``scattering`` (N, 3),
    ``extinction`` (N,), ``emissive`` (N, 3) and ``g`` (N,) in the points' dtype.

    Every medium's coefficients times its density at the point, summed linearly;
    ``g`` is the scattering-weighted mean of the media's ``g`` (weight: mean scattering over
    RGB), 0 where nothing scatters. Height fog: density ``exp(-falloff (y - base))``;
    fog volumes: 1 inside the shape times the density texture, 0 outside.
    """
    raise NotImplementedError("not implemented yet: media_at (task 2)")


def voxelize(scene, grid, jitter=0.5, dtype=torch.float32, device="cpu"):
    """The V-buffer: :func:`media_at` at every froxel's sample point
    ``froxel_to_world(grid, froxel_sample_coords(grid, jitter))``: the tile's centre, the
    fraction ``jitter`` of the way through the slice in view depth.

    Returns a dict of ``scattering`` (S, ny, nx, 3), ``extinction`` (S, ny, nx),
    ``emissive`` (S, ny, nx, 3), ``g`` (S, ny, nx) of ``dtype`` on ``device``.
    """
    raise NotImplementedError("not implemented yet: voxelize (task 2)")


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
    raise NotImplementedError("not implemented yet: henyey_greenstein (task 3)")


def schlick_phase(cos_theta, g):
    """Schlick's approximation of Henyey–Greenstein, ``(1 - k^2) / (4 pi (1 - k cos)^2)``
    with ``k = 1.55 g - 0.55 g^3`` clamped to ``|k| <= SCHLICK_K_MAX`` (``k`` reaches 1
    at g = 0.9986: without the clamp a forward peak becomes a delta and then negative).
    Normalised over the sphere for every ``g`` in (-1, 1); ``cos_theta`` is clamped to
    [-1, 1] like :func:`henyey_greenstein`'s."""
    raise NotImplementedError("not implemented yet: schlick_phase (task 3)")


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
    raise NotImplementedError("not implemented yet: cull_lights (task 3)")


def build_shadow_map(scene, light, center, radius, resolution, dtype=torch.float32,
                     device="cpu"):
    """The sun's shadow map over the sphere (``center`` (3 numbers), ``radius``): an
    orthographic :class:`LightVolume` of kind "ortho" whose data (R, R) holds, per texel, the
    depth along ``w = -light.direction`` of the first occluder box (inf where none).

    The frame's plane lies beyond every occluder and the sphere toward the sun, so every
    shadow caster is in front of it. Texel ``(i, j)`` traces one ray from its centre.
    """
    raise NotImplementedError("not implemented yet: build_shadow_map (task 3)")


def shadow_lookup(shadow_map, points):
    """Sun visibility (N,) in {0, 1} of world ``points`` (N, 3): 0 where the nearest texel's
    occluder lies in front of the point by more than a bias of two texels (which keeps the
    occluders' own lit faces from shadowing themselves); 1 outside the map."""
    raise NotImplementedError("not implemented yet: shadow_lookup (task 3)")


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
    raise NotImplementedError("not implemented yet: light_froxels (task 3)")


# ---------------------------------------------------------------------------------------
# Task 4: volumetric shadow maps


def extinction_volume(scene, lo, hi, resolution, dtype=torch.float32, device="cpu"):
    """Extinction (R, R, R) at the voxel centres of the box ``lo .. hi`` (3 numbers each),
    R = ``resolution``, x the first axis: :func:`media_at` sampled on a world-aligned grid
    around the camera, the input of every light's transmittance volume."""
    raise NotImplementedError("not implemented yet: extinction_volume (task 4)")


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
    raise NotImplementedError("not implemented yet: light_transmittance (task 4)")


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
    raise NotImplementedError("not implemented yet: transmittance_volume (task 4)")


def sample_light_volume(volume, points):
    """Transmittance (N,) toward the light at world ``points`` (N, 3): trilinear in the
    volume's texels and depth samples (clamped at its ends); 1 outside the map laterally
    and behind a spot light."""
    raise NotImplementedError("not implemented yet: sample_light_volume (task 4)")


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
    raise NotImplementedError("not implemented yet: reproject (task 5)")


def temporal_blend(current, history, valid, alpha=BLEND):
    """Exponential moving average: ``history + alpha (current - history)`` where ``valid``
    (broadcast over a trailing colour axis), ``current`` elsewhere. current, history:
    (S, ny, nx) or (S, ny, nx, C) of one dtype; valid: (S, ny, nx) bool; alpha in (0, 1]."""
    raise NotImplementedError("not implemented yet: temporal_blend (task 5)")


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
    raise NotImplementedError("not implemented yet: slice_integral (task 6)")


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
    raise NotImplementedError("not implemented yet: integrate_froxels (task 6)")


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
    raise NotImplementedError("not implemented yet: apply_froxels (task 7)")


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
    raise NotImplementedError("not implemented yet: render_froxels (task 8)")
