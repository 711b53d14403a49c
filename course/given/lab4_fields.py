"""Lab 4's media given as callables: their values at world points, checked.

Given code, not an exercise: ``evaluate`` in Lab 4's skeleton and reference calls
:func:`field_values` for a callable field and the lab's own ``sample_grid`` for a grid.
"""

from __future__ import annotations

import torch


def field_values(field, name: str, points: torch.Tensor, channels: bool = False) -> torch.Tensor:
    """``field(points)`` for a callable medium ``field`` at world ``points`` (N, 3).

    Returns (N,), or also (N, C) when ``channels``, in the points' dtype. A result of
    another shape raises ValueError naming ``name``, and so do negative values of the
    ``"density"`` (an extinction coefficient is >= 0: the transmittance would exceed 1).
    """
    values = field(points)
    if (
        not isinstance(values, torch.Tensor)
        or values.shape[:1] != points.shape[:1]
        or values.ndim > (2 if channels else 1)
    ):
        got = tuple(values.shape) if isinstance(values, torch.Tensor) else type(values).__name__
        want = "(N,) or (N, C)" if channels else "(N,)"
        raise ValueError(
            f"{name}: the callable must return a tensor of shape {want} for "
            f"points of shape {tuple(points.shape)}, got {got}"
        )
    if name == "density" and bool((values < 0).any()):
        raise ValueError(
            f"density: the callable returned {int((values < 0).sum())} negative "
            f"values (an extinction coefficient is >= 0; the transmittance would "
            f"exceed 1)"
        )
    return values.to(points.dtype)
