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

    Errors: TypeError naming ``grid`` unless it is a FroxelGrid; TypeError naming ``lights``
    (as ``lights[i]``) for an item that is not a DirectionalLight, PointLight or SpotLight.
    """
    raise NotImplementedError("not implemented yet: cull_lights (task 3)")


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
    raise NotImplementedError("not implemented yet: build_shadow_map (task 3)")


def shadow_lookup(shadow_map, points):
    """Sun visibility (N,) in {0, 1} of world ``points`` (N, 3): 0 where the nearest texel's
    occluder lies in front of the point by more than a bias of two texels (which keeps the
    occluders' own lit faces from shadowing themselves); 1 outside the map.

    Errors: TypeError naming ``shadow_map`` unless it is a LightVolume with (R, R) data;
    TypeError or ValueError naming ``points`` unless it is a float tensor of shape (N, 3).
    """
    raise NotImplementedError("not implemented yet: shadow_lookup (task 3)")


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
    raise NotImplementedError("not implemented yet: light_froxels (task 3)")
