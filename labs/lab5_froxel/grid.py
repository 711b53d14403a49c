"""Task 1: the froxel grid: ``slice_depths``, ``depth_to_slice`` (exponential slicing and its
inverse), ``froxel_to_world`` and ``world_to_froxel`` (froxel coordinates <-> world points).
"""

from __future__ import annotations

import math

import torch

from course.core.raymath import check_inputs
from course.given.lab5 import check_depths, check_dtype, check_grid, check_volume


def slice_depths(near, far, slices, dtype=torch.float32, device="cpu"):
    """View depths of the slice boundaries: (slices + 1,) of ``dtype``.

    Exponential slicing ``z_k = near (far / near)^(k / slices)``: each slice is the same
    fraction deeper than the last, so froxels stay roughly cube-shaped in view space and
    resolution goes where perspective puts the pixels. ``z_0 = near`` and
    ``z_slices = far`` exactly. Computed in float64, rounded once. ``0 < near < far <
    inf`` and ``slices >= 1`` (``check_depths``), else ValueError naming the argument.

    Errors: ValueError naming ``slices`` (not an int >= 1); TypeError or ValueError naming
    ``near`` (not a number in (0, inf)) or ``far`` (not a number in (near, inf)); TypeError
    naming ``dtype`` unless it is torch.float32 or torch.float64.
    """
    raise NotImplementedError("not implemented yet: slice_depths (task 1)")


def depth_to_slice(depth, near, far, slices):
    """The exact inverse of :func:`slice_depths`: the continuous slice coordinate
    ``slices log(depth / near) / log(far / near)`` of view depths ``depth`` (any shape,
    float32/float64); ``-inf`` at depth 0, below 0 in front of ``near``, above ``slices``
    beyond ``far``, ``+inf`` at ``+inf``. ``log(depth) - log(near)`` keeps a tiny ``near``
    (1e-6) as accurate as any other.

    Errors: ``near``, ``far`` and ``slices`` as in :func:`slice_depths`; TypeError naming
    ``depth`` unless it is a float32/float64 tensor.
    """
    raise NotImplementedError("not implemented yet: depth_to_slice (task 1)")


def froxel_to_world(grid, coords):
    """World points of froxel coordinates ``coords`` (..., 3) ``(x, y, z)``: the point at
    the view depth of slice coordinate ``z`` on the ray through pixel
    ``(column, row) = (x, y) * tile``. Returns (..., 3) of ``coords``' dtype.

    Errors: TypeError naming ``grid`` unless it is a FroxelGrid; TypeError or ValueError
    naming ``coords`` unless it is a float32/float64 tensor of shape (..., 3).
    """
    raise NotImplementedError("not implemented yet: froxel_to_world (task 1)")


def world_to_froxel(grid, points):
    """Froxel coordinates (..., 3) of world ``points`` (..., 3): the inverse of
    :func:`froxel_to_world`. Points at or behind the eye's plane (view depth <= 0) get NaN.

    Errors: TypeError naming ``grid`` unless it is a FroxelGrid; TypeError or ValueError
    naming ``points`` unless it is a float32/float64 tensor of shape (..., 3).
    """
    raise NotImplementedError("not implemented yet: world_to_froxel (task 1)")
