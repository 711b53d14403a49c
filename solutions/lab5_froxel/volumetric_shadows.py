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

    Errors: TypeError or ValueError naming ``extinction`` (not an (X, Y, Z) float32/float64
    tensor) or ``points`` (not a float tensor of shape (..., 3)); ValueError naming
    ``steps`` unless it is an int >= 1.
    """
    # BEGIN SOLUTION (task 4)
    check_volume(
        extinction,
        "extinction",
        extinction.shape
        if isinstance(extinction, torch.Tensor) and extinction.ndim == 3
        else (1, 1, 1),
    )
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

    Errors: TypeError or ValueError naming ``extinction`` unless it is an (X, Y, Z)
    float32/float64 tensor; TypeError naming ``light`` unless it is a DirectionalLight or
    SpotLight; ValueError naming ``resolution`` unless it is an int >= 1.
    """
    # BEGIN SOLUTION (task 4)
    check_volume(
        extinction,
        "extinction",
        extinction.shape
        if isinstance(extinction, torch.Tensor) and extinction.ndim == 3
        else (1, 1, 1),
    )
    if not isinstance(light, (DirectionalLight, SpotLight)):
        raise TypeError(
            f"light: expected a DirectionalLight or SpotLight (point lights cast "
            f"no volumetric shadows), got {type(light).__name__}"
        )
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
    depth = torch.cat(
        [
            torch.zeros(resolution, resolution, 1, dtype=dtype, device=device),
            torch.cumsum(sigma * step, -1),
        ],
        -1,
    )
    return LightVolume(
        kind,
        tuple(origin.tolist()),
        axes,
        float(extent),
        float(near),
        float(far),
        torch.exp(-depth),
    )
    # END SOLUTION


def sample_light_volume(volume, points):
    """Transmittance (N,) toward the light at world ``points`` (N, 3): trilinear in the
    volume's texels and depth samples (clamped at its ends); 1 outside the map laterally
    and behind a spot light.

    Errors: TypeError naming ``volume`` unless it is a LightVolume with (R, R, K) data;
    TypeError or ValueError naming ``points`` unless it is a float tensor of shape (N, 3).
    """
    # BEGIN SOLUTION (task 4)
    if not isinstance(volume, LightVolume) or volume.data.ndim != 3:
        raise TypeError(
            "volume: expected a LightVolume with (R, R, K) data from transmittance_volume"
        )
    check_inputs({"points": (points, (3,))})
    a, b, depth = light_coords(volume, points)
    r, _, k = volume.data.shape
    inside = (a.abs() <= 1) & (b.abs() <= 1)
    coords = torch.stack(
        [
            (a + 1) / 2 * r,
            (b + 1) / 2 * r,
            (depth - volume.near) / (volume.far - volume.near) * (k - 1) + 0.5,
        ],
        -1,
    )
    t = sample_texture(volume.data.to(points.dtype), torch.where(inside[:, None], coords, 0))
    return torch.where(inside, t, 1.0)
    # END SOLUTION
