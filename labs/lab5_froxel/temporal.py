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
    raise NotImplementedError("not implemented yet: reproject (task 5)")


def temporal_blend(current, history, valid, alpha=BLEND):
    """Exponential moving average: ``history + alpha (current - history)`` where ``valid``
    (broadcast over a trailing colour axis), ``current`` elsewhere. current, history:
    (S, ny, nx) or (S, ny, nx, C) of one dtype; valid: (S, ny, nx) bool; alpha in (0, 1].

    Errors: TypeError or ValueError naming ``current`` (not a float32/float64 tensor) or
    ``history`` (not of the current's shape, dtype and device); ValueError naming ``valid``
    unless it is a bool tensor of shape (S, ny, nx), or ``alpha`` unless it is a number in
    (0, 1].
    """
    raise NotImplementedError("not implemented yet: temporal_blend (task 5)")
