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
    raise NotImplementedError("not implemented yet: media_at (task 2)")


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
    raise NotImplementedError("not implemented yet: voxelize (task 2)")
