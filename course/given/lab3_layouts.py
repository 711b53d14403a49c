"""Lab 3's triangle layouts (indexed, float4, woop): their input checks, and the float4
layout's index word (an integer stored in a float's bits).

Given code, not exercises (imported through :mod:`course.given.lab3`, whose docstring
states the scene and shading contract).
"""

from __future__ import annotations

import torch

from course.core.types import Mesh
from course.given.lab3_checks import check_vectors

LAYOUTS = {"indexed": "vertices", "float4": "triangles", "woop": "transforms"}
"""The geometry layouts of Lab 3's task 5, each with the tensor that carries its dtype."""


def check_order(order, mesh: Mesh) -> torch.Tensor:
    """Provided: ``order`` must be None or an int64 permutation of the F triangles; returns
    it (``arange(F)`` for None) on the mesh's device."""
    f = mesh.num_faces
    if order is None:
        return torch.arange(f, device=mesh.device)
    if not isinstance(order, torch.Tensor) or order.dtype != torch.int64 or order.shape != (f,):
        raise ValueError(
            f"order: expected an int64 permutation of shape ({f},), got "
            f"{getattr(order, 'dtype', type(order).__name__)} of shape "
            f"{tuple(getattr(order, 'shape', ()))}"
        )
    if not torch.equal(torch.sort(order).values.cpu(), torch.arange(f)):
        raise ValueError(f"order: expected a permutation of 0..{f - 1}")
    return order.to(mesh.device)


def check_layout_inputs(layout, origins, directions, t_min, t_max) -> tuple[str, int]:
    """Provided: validate :func:`intersect_layout`'s arguments; returns ``(kind, F)``."""
    if not isinstance(layout, dict) or layout.get("kind") not in LAYOUTS:
        got = layout.get("kind") if isinstance(layout, dict) else type(layout).__name__
        raise ValueError(
            f"layout: expected a dict from layout_indexed/layout_float4/"
            f"layout_woop (kind {'/'.join(LAYOUTS)}), got {got!r}"
        )
    kind = layout["kind"]
    like = layout.get(LAYOUTS[kind])
    if not isinstance(like, torch.Tensor):
        raise TypeError(f"layout: a {kind!r} layout needs a tensor under {LAYOUTS[kind]!r}")
    n = check_vectors(like, origins=origins, directions=directions)
    for name, x in (("t_min", t_min), ("t_max", t_max)):
        if not isinstance(x, torch.Tensor) or x.shape != (n,) or x.dtype != like.dtype:
            raise ValueError(
                f"{name}: expected a ({n},) {like.dtype} tensor, got "
                f"{getattr(x, 'dtype', type(x).__name__)} of shape "
                f"{tuple(getattr(x, 'shape', ()))}"
            )
    f = len(layout["faces"]) if kind == "indexed" else len(like)
    return kind, f


_INDEX_BITS = {torch.float32: torch.int32, torch.float64: torch.int64}


def index_as_float(index: torch.Tensor, dtype: torch.dtype) -> torch.Tensor:
    """Integer indices stored bit for bit in floats of ``dtype`` (CUDA's ``__int_as_float``):
    int32 bits in float32, int64 bits in float64. Exact for every index, unlike a value
    conversion (float32 holds integers exactly only up to 2^24)."""
    return index.to(_INDEX_BITS[dtype]).contiguous().view(dtype)


def float_as_index(word: torch.Tensor) -> torch.Tensor:
    """The inverse of :func:`index_as_float`: int64 indices from their float bits."""
    return word.contiguous().view(_INDEX_BITS[word.dtype]).to(torch.int64)
