"""Task 4: exact integration over a voxel grid: ``build_occupancy`` (the macro cells that
hold any medium) and ``voxel_walk`` (a 3D DDA, with empty-space skipping).
"""

from __future__ import annotations

import math

import torch

from course.given.lab4 import check_occupancy_inputs, check_voxel_inputs

from .integrals import segment_integral
from .march import check_density_defined, ray_box_interval


def build_occupancy(density, macro_cell=1, emission=None):
    """Which macro cells hold any medium: the acceleration grid of empty-space skipping.

    density: (X, Y, Z) float grid; macro_cell: int >= 1, the macro cell's edge in voxels;
    emission: optional (X, Y, Z) or (X, Y, Z, C) grid (emitting voxels are not empty).
    Returns (ceil(X/m), ceil(Y/m), ceil(Z/m)) bool: True where some voxel of the macro
    cell has ``density > 0`` or non-zero emission (a max over m^3 blocks; the last block
    of an axis may be partial).

    Hints: ``torch.nn.functional.max_pool3d`` on a float copy of the mask, shaped
    (1, 1, X, Y, Z), with ``kernel_size = stride = macro_cell`` and ``ceil_mode=True``.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    check_occupancy_inputs(density, macro_cell, emission)
    # BEGIN SOLUTION (task 4)
    busy = density > 0
    if emission is not None:
        nonzero = emission != 0
        busy = busy | (nonzero.any(-1) if emission.ndim == 4 else nonzero)
    pooled = torch.nn.functional.max_pool3d(
        busy[None, None].float(), macro_cell, stride=macro_cell, ceil_mode=True
    )
    return pooled[0, 0] > 0
    # END SOLUTION


def voxel_walk(
    origins, directions, box_min, box_max, density, emission=None, occupancy=None, macro_cell=1
):
    """Exact emission–absorption through a piecewise-constant voxel grid (3D DDA).

    origins, directions: (N, 3); box_min, box_max: (3,); density: (X, Y, Z) grid >= 0
    (NaN raises ValueError), constant over each voxel (nearest, not trilinear); emission:
    None or (X, Y, Z) / (X, Y, Z, C) grid, constant per voxel; occupancy: None (no
    skipping) or the bool grid of :func:`build_occupancy` for ``macro_cell``.
    Returns a dict: ``optical_depth`` (N,), ``transmittance`` (N,) ``= exp(-optical_depth)``,
    ``radiance`` (N,) or (N, C), ``steps`` (N,) int64 (cells stepped through: voxels or
    skipped macro cells) and ``samples`` (N,) int64 (voxels whose density was read).

    Amanatides & Woo: from the entry voxel, step to the neighbour across the nearest
    boundary plane ahead. Each boundary's ``t`` is computed afresh from the integer voxel
    index, ``(index * voxel - (o - box_min)) / d`` (no accumulated increments, no absolute
    coordinates), so the segments telescope to the chord and each is integrated exactly
    (:func:`segment_integral`, "exact"): no step count to choose.

    Skipping: a voxel whose macro cell is empty is crossed together with its whole macro
    cell in one step, to the macro cell's exit plane; the indices on the other axes are
    re-located from the exit point (clamped into the macro cell, never backwards). A fine
    step is the same move with a block of one voxel. Every iteration advances at least one
    index, so ``X + Y + Z + 1`` iterations finish every ray.

    Ties: a ray lying exactly in a voxel plane (a zero direction component) belongs to the
    voxel on the plane's positive side, ``floor((o - box_min) / voxel)``; where the ray
    crosses several planes at one ``t`` (an edge or a corner), it steps one axis at a time
    with zero-length segments in between. A flat box (``box_min = box_max`` on an axis) has
    voxels of no volume: every ray passes it untouched (optical depth 0, no steps).

    Errors: ValueError or TypeError naming ``origins``, ``directions``, ``box_min`` or
    ``box_max`` as in ``ray_box_interval``; TypeError naming ``density`` unless it is a grid
    tensor; ValueError or TypeError naming ``density`` for a grid not (X, Y, Z) of the rays'
    dtype and device, and ValueError for negative or NaN values; ValueError or TypeError
    naming ``emission`` (neither None nor an (X, Y, Z) / (X, Y, Z, C) grid with the
    density's voxels) or ``macro_cell`` (not an int >= 1); ValueError naming ``occupancy``
    unless it is None or the bool grid ``build_occupancy(density, macro_cell)`` returns, on
    the rays' device.

    Hints: per-ray state ``cell`` (N, 3) int64, ``t`` (N,) and ``active`` (N,) bool;
    ``step = torch.sign(d).long()``. In each iteration: the block ``[block_lo, block_hi]``
    (the voxel, or its macro cell when ``occupancy`` says it is empty), the plane ahead on
    each axis (``block_hi + 1`` or ``block_lo``), its ``t`` (inf where ``step == 0``), the
    exit ``t`` and axis (``amin``/``argmin``), the segment, then the move. Only
    ``torch.where`` updates: no Python loop over rays.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    origins, directions, box_min, box_max = check_voxel_inputs(
        origins, directions, box_min, box_max, density, emission, occupancy, macro_cell
    )
    check_density_defined(density)
    # BEGIN SOLUTION (task 4)
    n = origins.shape[0]
    like = {"dtype": origins.dtype, "device": origins.device}
    sizes = torch.tensor(density.shape, device=origins.device)
    voxel = (box_max - box_min) / sizes
    t, t_end, hit = ray_box_interval(origins, directions, box_min, box_max)
    hit = hit & (voxel > 0).all()
    # Missed rays get a harmless finite ray; they never become active.
    rel = torch.where(hit[:, None], origins - box_min, 0)
    d = torch.where(hit[:, None], directions, 1)
    length = d.norm(dim=-1)
    step = torch.sign(d).long()  # +0.0 and -0.0 both give 0: never cross a plane of that axis
    inv = torch.reciprocal(d)
    cell = torch.floor((rel + t[:, None] * d) / voxel).long()
    cell = torch.minimum(cell.clamp(min=0), sizes - 1)

    depth = torch.zeros(n, **like)
    transmittance = torch.ones(n, **like)
    channels = tuple(emission.shape[3:]) if emission is not None else ()
    radiance = torch.zeros(n, *channels, **like)
    steps_taken = torch.zeros(n, dtype=torch.int64, device=origins.device)
    samples = torch.zeros_like(steps_taken)
    flat = density.reshape(-1)
    ny, nz = density.shape[1], density.shape[2]
    inf = torch.full((), math.inf, **like)
    active = hit & (t < t_end)
    for _ in range(int(sizes.sum()) + 1):
        active = active & (cell >= 0).all(-1) & (cell < sizes).all(-1) & (t < t_end)
        if not bool(active.any()):
            break
        index = torch.minimum(cell.clamp(min=0), sizes - 1)
        if occupancy is None:
            skip = torch.zeros(n, dtype=torch.bool, device=origins.device)
        else:
            macro = index // macro_cell
            skip = ~occupancy[macro[:, 0], macro[:, 1], macro[:, 2]]
        # The block being crossed: one voxel, or the whole (empty) macro cell.
        block_lo = torch.where(skip[:, None], (index // macro_cell) * macro_cell, index)
        block_hi = torch.where(
            skip[:, None], torch.minimum((index // macro_cell + 1) * macro_cell, sizes) - 1, index
        )
        ahead = torch.where(step > 0, block_hi + 1, block_lo)  # index of the plane ahead
        t_axis = torch.where(step != 0, (ahead * voxel - rel) * inv, inf)
        t_exit = torch.minimum(t_axis.amin(-1), t_end)
        axis = t_axis.argmin(-1)
        seg = torch.where(active, (t_exit - t).clamp(min=0) * length, 0)
        sample = active & ~skip
        linear = (index[:, 0] * ny + index[:, 1]) * nz + index[:, 2]
        sigma = torch.where(sample, flat[linear], 0)
        depth = depth + sigma * seg
        if emission is not None:
            q = emission.reshape(-1, *channels)[linear]
            weight, t_seg = segment_integral(sigma, seg, "exact")
            seen = transmittance * weight
            if channels:
                radiance = radiance + seen[:, None] * torch.where(sample[:, None], q, 0)
            else:
                radiance = radiance + seen * torch.where(sample, q, 0)
            transmittance = transmittance * t_seg
        steps_taken += active
        samples += sample
        # Leave the block across the exit plane on `axis`; on the other axes go where the
        # exit point lies, kept inside the block and never backwards (rounding).
        located = torch.floor((rel + t_exit[:, None] * d) / voxel).long()
        located = torch.minimum(torch.maximum(located, block_lo), block_hi)
        located = torch.where(
            step > 0,
            torch.maximum(located, index),
            torch.where(step < 0, torch.minimum(located, index), index),
        )
        across = torch.where(step > 0, block_hi + 1, block_lo - 1)
        on_axis = torch.nn.functional.one_hot(axis, 3).bool()
        cell = torch.where(active[:, None], torch.where(on_axis, across, located), cell)
        t = torch.where(active, t_exit, t)
    return {
        "optical_depth": depth,
        "transmittance": torch.exp(-depth),
        "radiance": radiance,
        "steps": steps_taken,
        "samples": samples,
    }
    # END SOLUTION
