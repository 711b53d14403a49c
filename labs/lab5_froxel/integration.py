"""Task 6: final integration: ``slice_integral`` (one slice of constant medium, stable for
any optical depth) and ``integrate_froxels`` (front to back along every froxel column).
"""

from __future__ import annotations

import torch

from course.given.lab5 import INTEGRATIONS, check_choice, check_grid, check_volume

from .grid import slice_depths


def slice_integral(source, extinction, length):
    """One slice of constant medium: ``(integral, transmittance)``.

    ``integral = int_0^D e^(-sigma_t x) S dx = S D phi(sigma_t D)`` with
    ``phi(x) = (1 - e^(-x)) / x`` (= 1 at 0), the talk's ``(S - S e^(-sigma_t D)) / sigma_t``
    written so it stays exact as ``sigma_t -> 0`` (``S D``, with a finite gradient) and
    for huge ``sigma_t`` (``S / sigma_t``, transmittance 0, no NaN). source (..., C) or
    (...); extinction, length: broadcasting with it (without C), >= 0 (``inf`` allowed):
    a negative one raises ValueError naming it (it would give a transmittance above 1).
    A slice of zero length, or of no medium, is no optical depth even where the other
    factor is ``inf``: transmittance 1 (``sigma_t = inf`` over ``D = 0`` gives ``(0, 1)``;
    no medium over ``D = inf`` gives ``(S D, 1)``, infinite where ``S > 0``). An endless
    slice of medium (``sigma_t > 0``, ``D = inf``) gives ``(S / sigma_t, 0)``, the limit.
    Returns tensors of the broadcast shape (integral with C).

    Errors: TypeError naming ``source``, ``extinction`` or ``length`` unless it is a float
    tensor; ValueError naming ``extinction`` or ``length`` for a negative value.
    """
    raise NotImplementedError("not implemented yet: slice_integral (task 6)")


def integrate_froxels(source, extinction, grid, method="energy"):
    """Front-to-back accumulation along every froxel column: ``(inscatter (S, ny, nx, 3),
    transmittance (S, ny, nx))`` from ``near`` to the far boundary of each slice.

    source: (S, ny, nx, 3) light per unit length; extinction: (S, ny, nx). Slice ``k`` of
    column ``(j, i)`` is ``(z_{k+1} - z_k) |dir|`` long along the ray through the tile centre
    (``dir`` with unit view depth). method "energy": ``L += T * slice_integral``, then
    ``T *= e^(-sigma_t D)`` (after: the slice's own medium absorbs only via the integral).
    "naive": ``L += T * S D`` (the talk's leak: no absorption within a slice, so a dense
    slice emits more light than it can). A loop over slices or prefix sums (``cumsum``
    of the optical depths) are both fine; the result is the same to rounding. A negative
    extinction raises ValueError naming ``extinction`` with either method (it would give a
    transmittance above 1).

    Errors: TypeError naming ``grid`` unless it is a FroxelGrid; ValueError naming
    ``method`` unless it is ``"energy"`` or ``"naive"``; TypeError or ValueError naming
    ``source`` (not an (S, ny, nx, 3) float32/float64 tensor) or ``extinction`` (not (S, ny,
    nx) of the source's dtype and device); ValueError naming ``extinction`` for a negative
    value.
    """
    raise NotImplementedError("not implemented yet: integrate_froxels (task 6)")
