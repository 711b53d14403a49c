"""Input checks and small helpers shared by Lab 1's skeleton and reference.

Given code, not exercises: the lab's skeleton and its reference import these, so
there is one copy of them. The vector helpers every kernel uses (``cross``, ``dot``,
``gamma``, ``check_inputs``, ``masked_result``) are in ``course.core.raymath``.
"""

from __future__ import annotations

import torch

from course.core.raymath import dot
from course.core.types import Mesh, Rays

VARIANTS = ("intersect_simple", "moller_trumbore", "woop_unit", "watertight")
"""The triangle kernels of Lab 1, by name (``closest_hit(..., variant=...)``)."""

BYTES_PER_PAIR = 64
"""Element sizes a triangle kernel keeps alive per (ray, triangle) pair, at most: the
chunk size is ``memory_budget_bytes // (BYTES_PER_PAIR * element size)`` pairs."""


def check_variant(variant) -> None:
    """ValueError naming ``variant`` unless it is a name in ``VARIANTS``."""
    if variant not in VARIANTS:
        raise ValueError(f"variant: expected one of {', '.join(VARIANTS)}, got {variant!r}")


def affine_row(row, origins, directions):
    """``(r . o + c, r . d)`` for one row ``[r | c]`` of a transform ``(..., 4)``."""
    return dot(row[..., :3], origins) + row[..., 3], dot(row[..., :3], directions)


def check_closest_hit_inputs(rays, mesh, variant, memory_budget_bytes) -> None:
    """Validate ``closest_hit``'s arguments (ValueError/TypeError naming the argument).
    Objects that crossed a process boundary are re-validated too."""
    if not isinstance(rays, Rays):
        raise TypeError(f"rays: expected course.core.types.Rays, got {type(rays).__name__}")
    if not isinstance(mesh, Mesh):
        raise TypeError(f"mesh: expected course.core.types.Mesh, got {type(mesh).__name__}")
    rays.validate()
    mesh.validate()
    if mesh.dtype != rays.dtype:
        raise TypeError(
            f"mesh: expected vertices of dtype {rays.dtype} like rays, got {mesh.dtype}"
        )
    if mesh.device != rays.device:
        raise ValueError(f"mesh: expected a mesh on {rays.device} like rays, got {mesh.device}")
    check_variant(variant)
    if not isinstance(memory_budget_bytes, int) or memory_budget_bytes <= 0:
        raise ValueError(
            f"memory_budget_bytes: expected a positive int, got {memory_budget_bytes!r}"
        )


def accounting_inputs(variant: str) -> tuple:
    """The one lane the accounting of Lab 1 measures, as arguments for ``variant``.

    One ray (origin (0.25, 0.2, -1), direction (0.1, 0.05, 1)) against one triangle
    ((0,0,0), (1,0,0), (0,1,0)), float32 on the CPU, each of shape (1, 3): a single lane
    that hits, so no early exit is taken. ``woop_unit`` gets the triangle's transform
    (1, 3, 4): the identity, as this triangle is the unit triangle (the lecture counts the
    per-triangle precomputation as free). A name not in ``VARIANTS`` raises ValueError
    naming ``variant``.
    """
    check_variant(variant)
    o, d = torch.tensor([[0.25, 0.2, -1.0]]), torch.tensor([[0.1, 0.05, 1.0]])
    if variant == "woop_unit":
        return o, d, torch.eye(3, 4)[None]  # rows [r_i | c_i]: x' = x
    v0, v1, v2 = (
        torch.tensor([[0.0, 0.0, 0.0]]),
        torch.tensor([[1.0, 0.0, 0.0]]),
        torch.tensor([[0.0, 1.0, 0.0]]),
    )
    return o, d, v0, v1, v2
