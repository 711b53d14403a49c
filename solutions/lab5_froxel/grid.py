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
    (1e-6) as accurate as any other.

    Errors: ``near``, ``far`` and ``slices`` as in :func:`slice_depths`; TypeError naming
    ``depth`` unless it is a float32/float64 tensor.
    """
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
    ``(column, row) = (x, y) * tile``. Returns (..., 3) of ``coords``' dtype.

    Errors: TypeError naming ``grid`` unless it is a FroxelGrid; TypeError or ValueError
    naming ``coords`` unless it is a float32/float64 tensor of shape (..., 3).
    """
    # BEGIN SOLUTION (task 1)
    check_grid(grid)
    check_inputs({"coords": (coords, (3,))})
    check_dtype(coords.dtype, "coords")
    eye = _camera(grid, coords.dtype, coords.device)[0]
    depth = grid.near * torch.exp(coords[..., 2] * (math.log(grid.far / grid.near) / grid.slices))
    dirs = _view_dirs(grid, coords[..., 0], coords[..., 1], coords.dtype, coords.device)
    return eye + depth[..., None] * dirs
    # END SOLUTION


def world_to_froxel(grid, points):
    """Froxel coordinates (..., 3) of world ``points`` (..., 3): the inverse of
    :func:`froxel_to_world`. Points at or behind the eye's plane (view depth <= 0) get NaN.

    Errors: TypeError naming ``grid`` unless it is a FroxelGrid; TypeError or ValueError
    naming ``points`` unless it is a float32/float64 tensor of shape (..., 3).
    """
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
