"""Task 2: the V-buffer: ``media_at`` (the scene's media at world points) and ``voxelize``
(the media at every froxel's sample point).
"""

from __future__ import annotations

import torch

from course.core.raymath import check_inputs
from course.given.lab5 import (
    ConstantFog,
    HeightFog,
    check_dtype,
    check_grid,
    check_jitter,
    check_scene,
    froxel_sample_coords,
    sample_texture,
)

from .grid import froxel_to_world


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

    Errors: TypeError naming ``scene`` unless it is a Scene; TypeError or ValueError naming
    ``points`` unless it is an (N, 3) float32/float64 tensor.
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
        emissive = emissive + w[:, None] * torch.tensor(medium.emissive, dtype=dtype, device=device)
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

    Errors: TypeError naming ``scene`` unless it is a Scene, or ``grid`` unless it is a
    FroxelGrid; TypeError or ValueError naming ``jitter`` unless it is a number in [0, 1);
    TypeError naming ``dtype`` unless it is torch.float32 or torch.float64.
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
