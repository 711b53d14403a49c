"""Task 6: final integration: ``slice_integral`` (one slice of constant medium, stable for
any optical depth) and ``integrate_froxels`` (front to back along every froxel column).
"""

from __future__ import annotations

import torch

from course.given.lab5 import INTEGRATIONS, check_choice, check_grid, check_volume

from .grid import slice_depths

# BEGIN SOLUTION
# A function of the reference's own, not in the skeleton: so is its import (a block
# of its own).
# isort: split
from .grid import _view_dirs

# END SOLUTION


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
    # BEGIN SOLUTION (task 6)
    for name, x in (("source", source), ("extinction", extinction), ("length", length)):
        if not isinstance(x, torch.Tensor) or not x.is_floating_point():
            raise TypeError(
                f"{name}: expected a float tensor, got {getattr(x, 'dtype', type(x).__name__)}"
            )
    for name, x in (("extinction", extinction), ("length", length)):
        if bool((x < 0).any()):
            raise ValueError(
                f"{name}: expected values >= 0, got {int((x < 0).sum())} "
                f"negative (minimum {x.min().item():.3g})"
            )
    # inf * 0 is no optical depth (written so autograd keeps d tau / d sigma = length).
    finite = torch.where(torch.isinf(length) & (extinction == 0), 0, length)
    tau = torch.where(length == 0, 0, extinction * finite)
    small = tau < 1e-4
    safe = torch.where(small, 1.0, tau)
    # Below 1e-4 the series 1 - x/2 + x^2/6 is within x^3/24 (4e-14 relative) of phi.
    phi = torch.where(small, 1 - tau / 2 + tau * tau / 6, -torch.expm1(-safe) / safe)
    # tau = inf: D phi(sigma_t D) -> 1 / sigma_t (D = inf would give inf * 0 = NaN).
    endless = torch.isinf(tau)
    factor = torch.where(
        endless, 1 / torch.where(endless, extinction, 1), torch.where(endless, 0, length) * phi
    )
    if source.ndim == factor.ndim + 1:
        factor = factor[..., None]
    return source * factor, torch.exp(-tau)
    # END SOLUTION


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
    # BEGIN SOLUTION (task 6)
    check_grid(grid)
    check_choice(method, "method", INTEGRATIONS)
    check_volume(source, "source", (*grid.shape, 3))
    dtype, device = source.dtype, source.device
    check_volume(extinction, "extinction", grid.shape, dtype, device)
    if bool((extinction < 0).any()):
        raise ValueError(
            f"extinction: expected values >= 0, got minimum {extinction.min().item():.3g}"
        )
    z = slice_depths(grid.near, grid.far, grid.slices, torch.float64, device)
    j = torch.arange(grid.ny, dtype=torch.float64, device=device) + 0.5
    i = torch.arange(grid.nx, dtype=torch.float64, device=device) + 0.5
    jj, ii = torch.meshgrid(j, i, indexing="ij")
    stretch = _view_dirs(grid, ii, jj, torch.float64, device).norm(dim=-1)  # (ny, nx)
    lengths = ((z[1:] - z[:-1])[:, None, None] * stretch).to(dtype)  # (S, ny, nx)
    # Front to back without a loop over slices: the transmittance in front of slice k is
    # exp(-(sum of the optical depths before it)), an exclusive prefix sum.
    tau = extinction * lengths
    behind = torch.cumsum(tau, 0)
    in_front = torch.exp(-(behind - tau))
    if method == "energy":
        piece, _ = slice_integral(source, extinction, lengths)
    else:
        piece = source * lengths[..., None]
    radiance = torch.cumsum(in_front[..., None] * piece, 0)
    return radiance, torch.exp(-behind)
    # END SOLUTION
