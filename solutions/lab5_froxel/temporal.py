"""Task 5: temporal integration: ``reproject`` (the previous frame's volume seen from the
current froxels) and ``temporal_blend`` (the exponential moving average).
"""

from __future__ import annotations

import torch

from course.given.lab5 import (
    BLEND,
    FroxelGrid,
    check_dtype,
    check_grid,
    check_volume,
    froxel_sample_coords,
    sample_texture,
    slice_offset,
)

from .grid import froxel_to_world, world_to_froxel


def reproject(history, prev_grid, grid):
    """The previous frame's volume seen from the current froxels: ``(values, valid)``.

    history: (S, ny, nx) or (S, ny, nx, C) on ``prev_grid``; ``grid``: the current frame's
    grid (same shape, another camera). Each current froxel's centre (jitter 0.5: the tile's
    centre, the slice's middle depth) is moved to world space and into ``prev_grid``'s
    froxel coordinates; ``values`` are the history sampled trilinearly there (shape of
    ``history``; its voxels sit at the froxel centres ``froxel_sample_coords(prev_grid,
    0.5)``, clamped at the border), ``valid`` (S, ny, nx) bool is True only where that
    point lies inside the previous froxel volume (``0 <= x <= nx``, ``0 <= y <= ny``,
    ``0 <= z <= slices``): history from outside the previous frustum is dropped (where
    ``valid`` is False, ``values`` are finite but unspecified: they are not used).

    Errors: TypeError naming ``grid`` or ``prev_grid`` unless it is a FroxelGrid; ValueError
    naming ``prev_grid`` unless its shape is the grid's; TypeError or ValueError naming
    ``history`` unless it is a float32/float64 tensor of shape (S, ny, nx) or (S, ny, nx, C).
    """
    # BEGIN SOLUTION (task 5)
    check_grid(grid)
    if not isinstance(prev_grid, FroxelGrid):
        raise TypeError(f"prev_grid: expected a FroxelGrid, got {type(prev_grid).__name__}")
    if prev_grid.shape != grid.shape:
        raise ValueError(
            f"prev_grid: expected the shape {grid.shape} of grid, got {prev_grid.shape}"
        )
    if (
        not isinstance(history, torch.Tensor)
        or history.ndim not in (3, 4)
        or tuple(history.shape[:3]) != grid.shape
    ):
        raise ValueError(
            f"history: expected shape {grid.shape} or {grid.shape} + (C,), got "
            f"{tuple(getattr(history, 'shape', ()))}"
        )
    check_dtype(history.dtype, "history")
    coords = froxel_sample_coords(grid, 0.5, history.dtype, history.device)
    prev = world_to_froxel(prev_grid, froxel_to_world(grid, coords))
    limits = torch.tensor(
        [grid.nx, grid.ny, grid.slices], dtype=history.dtype, device=history.device
    )
    valid = ((prev >= 0) & (prev <= limits)).all(-1)  # NaN compares False: dropped
    # History voxels sit at the froxel centres: x, y = i + 0.5, j + 0.5, z = k + offset.
    lookup = prev - torch.tensor(
        [0.0, 0.0, slice_offset(grid, 0.5) - 0.5], dtype=prev.dtype, device=prev.device
    )
    zyx = torch.where(valid[..., None], lookup.flip(-1), 0)
    return sample_texture(history, zyx), valid
    # END SOLUTION


def temporal_blend(current, history, valid, alpha=BLEND):
    """Exponential moving average: ``history + alpha (current - history)`` where ``valid``
    (broadcast over a trailing colour axis), ``current`` elsewhere. current, history:
    (S, ny, nx) or (S, ny, nx, C) of one dtype; valid: (S, ny, nx) bool; alpha in (0, 1].

    Errors: TypeError or ValueError naming ``current`` (not a float32/float64 tensor) or
    ``history`` (not of the current's shape, dtype and device); ValueError naming ``valid``
    unless it is a bool tensor of shape (S, ny, nx), or ``alpha`` unless it is a number in
    (0, 1].
    """
    # BEGIN SOLUTION (task 5)
    check_volume(current, "current", current.shape if isinstance(current, torch.Tensor) else ())
    check_volume(history, "history", current.shape, current.dtype, current.device)
    if (
        not isinstance(valid, torch.Tensor)
        or valid.dtype != torch.bool
        or tuple(valid.shape) != tuple(current.shape[:3])
    ):
        raise ValueError(f"valid: expected a bool tensor of shape {tuple(current.shape[:3])}")
    if isinstance(alpha, bool) or not isinstance(alpha, (int, float)) or not 0 < alpha <= 1:
        raise ValueError(f"alpha: expected a number in (0, 1], got {alpha!r}")
    mask = valid if current.ndim == 3 else valid[..., None]
    return torch.where(mask, history + alpha * (current - history), current)
    # END SOLUTION
