"""Task 4: volumetric shadows: ``extinction_volume`` (the media on a world-aligned grid),
``light_transmittance`` (a point light's paths, marched), ``transmittance_volume`` (the sun's
and a spot light's transmittance, precomputed in light space) and ``sample_light_volume``.
"""

from __future__ import annotations

import math

import torch

from course.core.raymath import check_inputs
from course.given.lab5 import (
    LIGHT_STEPS,
    DirectionalLight,
    LightVolume,
    SpotLight,
    check_dtype,
    check_scene,
    check_volume,
    light_coords,
    light_frame,
    sample_texture,
)

from .vbuffer import media_at


def extinction_volume(scene, lo, hi, resolution, dtype=torch.float32, device="cpu"):
    """Extinction (R, R, R) at the voxel centres of the box ``lo .. hi`` (3 numbers each),
    R = ``resolution``, x the first axis: :func:`media_at` sampled on a world-aligned grid
    around the camera, the input of every light's transmittance volume.

    Errors: TypeError naming ``scene`` unless it is a Scene, or ``dtype`` unless it is
    torch.float32 or torch.float64; ValueError naming ``resolution`` unless it is an int
    >= 2, or ``hi`` unless ``lo < hi`` on every axis.
    """
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

    Errors: TypeError or ValueError naming ``extinction`` (not an (X, Y, Z) float32/float64
    tensor) or ``points`` (not a float tensor of shape (..., 3)); ValueError naming
    ``steps`` unless it is an int >= 1.
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

    Errors: TypeError or ValueError naming ``extinction`` unless it is an (X, Y, Z)
    float32/float64 tensor; TypeError naming ``light`` unless it is a DirectionalLight or
    SpotLight; ValueError naming ``resolution`` unless it is an int >= 1.
    """
    raise NotImplementedError("not implemented yet: transmittance_volume (task 4)")


def sample_light_volume(volume, points):
    """Transmittance (N,) toward the light at world ``points`` (N, 3): trilinear in the
    volume's texels and depth samples (clamped at its ends); 1 outside the map laterally
    and behind a spot light.

    Errors: TypeError naming ``volume`` unless it is a LightVolume with (R, R, K) data;
    TypeError or ValueError naming ``points`` unless it is a float tensor of shape (N, 3).
    """
    raise NotImplementedError("not implemented yet: sample_light_volume (task 4)")
