"""Task 2: ``segment_integral``, the energy-conserving per-step integral ("exact", exact
for a medium constant over the step) against the Riemann sum.
"""

from __future__ import annotations

import torch

from course.given.lab4 import check_segment_inputs


def segment_integral(sigma, length, integrator="exact"):
    """One step of emission–absorption through a medium constant over the step.

    sigma: extinction >= 0 (may be +inf); length: the step's world length >= 0 (may be
    +inf, an endless step: everything behind the last sample); numbers or float tensors
    that broadcast (NaN is neither: it propagates) (a negative value raises ValueError naming it:
    the transmittance would exceed 1; the provided check does it). Returns ``(weight,
    transmittance)`` of the broadcast shape: a source ``q`` constant over the step adds
    ``T_before * q * weight`` to the radiance, and then ``T`` is multiplied by
    ``transmittance = exp(-sigma length)``.

    ``"exact"``: ``weight = int_0^D e^{-sigma x} dx = (1 - e^{-sigma D}) / sigma``, the
    energy-conserving integral (Hillaire 2015), exact for a medium constant over the step.
    Written as ``D f(sigma D)`` with ``f(x) = -expm1(-x) / x``: no cancellation for small
    ``x``, ``f(0) = 1`` (vacuum: emission times length; ``0 / 0`` is not an answer) and
    ``f(inf) = 0`` (an opaque step gives ``1 / sigma -> 0``, not ``inf - inf``).
    ``sigma = inf`` over ``length = 0`` is no step at all: weight 0, transmittance 1.
    An endless step (``length = inf``) is the limit: ``weight = 1 / sigma`` and
    transmittance 0 for ``sigma > 0`` (0 for ``sigma = inf``); ``sigma = 0`` over it is
    vacuum forever: weight +inf (a constant source adds endless light), transmittance 1
    (``0 * inf`` is no medium, not NaN).

    ``"riemann"``: ``weight = D``, the naive sum, which ignores the absorption inside the
    step: it overestimates by ``sigma D / (1 - e^{-sigma D})`` (first order in the step)
    and emits more than a black body could (``q = c sigma`` gives ``L > c``); over an
    endless step it is +inf.

    Errors: ValueError naming ``integrator`` unless it is ``"exact"`` or ``"riemann"``;
    TypeError naming ``sigma`` or ``length`` unless each is a number or a float tensor
    (tensors of one dtype and device); ValueError naming either for a negative value.

    Hints: ``x = sigma * length`` (but 0 where ``length == 0``); ``torch.expm1``;
    ``torch.where(x > 0, ..., 1)`` keeps the 0 / 0 of the unused branch out of the result.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    sigma, length = check_segment_inputs(sigma, length, integrator)
    # BEGIN SOLUTION (task 2)
    # inf * 0 is no step (length 0) or no medium (sigma 0), not NaN.
    x = torch.where((length == 0) | (sigma == 0), 0, sigma * length)
    transmittance = torch.exp(-x)
    if integrator == "riemann":
        return length.expand_as(x), transmittance
    ratio = torch.where(x > 0, -torch.expm1(-x) / x, 1)
    # An endless step: D f(sigma D) is inf * 0 there; its limit is 1 / sigma. The inner
    # where keeps 1 / 0 (and its infinite gradient) out of the finite steps.
    endless = torch.isinf(length)
    return torch.where(endless, 1 / torch.where(endless, sigma, 1), length * ratio), transmittance
    # END SOLUTION
