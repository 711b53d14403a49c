"""Lab 2's constants and input checks, shared by its skeleton and reference.

Given code, not exercises (imported through :mod:`course.given.lab2`). Each check raises
TypeError/ValueError naming the argument it rejects.
"""

from __future__ import annotations

import math

import torch

from course.core.raymath import check_mesh
from course.core.types import Mesh, Rays

STRUCTURES = ("grid", "grid2", "bvh", "kd")
"""The structures this lab builds, by their ``"kind"``."""
COUNTERS = ("steps", "tests")
"""The per-ray work counters every traversal returns (the grid adds ``"skipped"``)."""
STRUCTURE_KEYS = {
    "grid": (
        "lo",
        "hi",
        "resolution",
        "cell_start",
        "cell_count",
        "triangles",
        "tri_cell_lo",
        "tri_cell_hi",
    ),
    "grid2": (
        "lo",
        "hi",
        "resolution",
        "cell_start",
        "cell_count",
        "triangles",
        "tri_cell_lo",
        "tri_cell_hi",
        "big",
        "sub_of",
        "sub_lo",
        "sub_hi",
        "sub_resolution",
        "sub_cell_base",
        "sub_cell_start",
        "sub_cell_count",
        "sub_triangles",
        "sub_tri_cell_lo",
        "sub_tri_cell_hi",
    ),
    "bvh": ("lo", "hi", "left", "right", "first", "count", "triangles"),
    "kd": ("lo", "hi", "split", "axis", "left", "first", "count", "triangles"),
}
"""The tensors each kind of structure holds (see its ``build_*`` function)."""
MAX_PAIRS = 2**20
"""(ray, triangle) pairs tested at once, at most: about 256 bytes each (corners, indices and
the kernel's temporaries), so memory stays bounded however many triangles a cell or leaf
holds (a grid cell around a whole teapot, for every ray)."""
OFFSET_BITS = 29
"""The 8-byte kd node: word 0 = the split (float32 bits; a leaf: its triangle count);
word 1 = leftOffset (bits 0-28) | splitAxis << 29 (bits 29-30) | leaf << 31."""


def check_trace_inputs(rays, mesh, intersect) -> None:
    """Provided: validate the arguments every ``*_closest_hit`` takes.

    Raises TypeError/ValueError naming ``rays``, ``mesh`` or ``intersect``.
    """
    if not isinstance(rays, Rays):
        raise TypeError(f"rays: expected course.core.types.Rays, got {type(rays).__name__}")
    check_mesh(mesh)
    rays.validate()
    if mesh.dtype != rays.dtype:
        raise TypeError(
            f"mesh: expected vertices of dtype {rays.dtype} like rays, got {mesh.dtype}"
        )
    if mesh.device != rays.device:
        raise ValueError(f"mesh: expected a mesh on {rays.device} like rays, got {mesh.device}")
    if not callable(intersect):
        raise TypeError(
            "intersect: expected a callable intersect(origins, directions, v0, v1, "
            f"v2, t_min, t_max) -> (t, u, v), got {type(intersect).__name__}"
        )


def check_structure(structure, kind: str, name: str, mesh: Mesh) -> None:
    """Provided: ``structure`` must be a ``kind`` dict built for a mesh like ``mesh``.

    Raises ValueError/TypeError naming ``name`` (the argument) and what is missing.
    """
    if not isinstance(structure, dict) or structure.get("kind") != kind:
        got = structure.get("kind") if isinstance(structure, dict) else type(structure).__name__
        raise ValueError(
            f"{name}: expected a dict with kind={kind!r} (from build_...), got {got!r}"
        )
    for key in STRUCTURE_KEYS[kind]:
        x = structure.get(key)
        if not isinstance(x, torch.Tensor):
            raise TypeError(f"{name}: expected a tensor under {key!r}, got {type(x).__name__}")
        if x.device != mesh.device:
            raise ValueError(f"{name}: {key!r} is on {x.device}, the mesh on {mesh.device}")
    if structure["triangles"].numel() and int(structure["triangles"].max()) >= mesh.num_faces:
        raise ValueError(
            f"{name}: refers to triangle {int(structure['triangles'].max())}, "
            f"but the mesh has {mesh.num_faces}: built for another mesh?"
        )


def _positive_int(value, name: str, lo: int = 1, hi: int | None = None) -> None:
    if (
        isinstance(value, bool)
        or not isinstance(value, int)
        or value < lo
        or (hi is not None and value > hi)
    ):
        span = f"in {lo}..{hi}" if hi is not None else f">= {lo}"
        raise ValueError(f"{name}: expected an int {span}, got {value!r}")


def check_grid_inputs(extent, num_triangles, density) -> list[float]:
    """Provided: validate :func:`grid_resolution`'s arguments; returns ``extent`` as 3 floats."""
    values = extent.tolist() if isinstance(extent, torch.Tensor) else extent
    try:
        values = [float(x) for x in values]
    except (TypeError, ValueError):
        raise ValueError(f"extent: expected 3 finite non-negative sizes, got {extent!r}") from None
    if len(values) != 3 or not all(math.isfinite(x) and x >= 0 for x in values):
        raise ValueError(f"extent: expected 3 finite non-negative sizes, got {extent!r}")
    _positive_int(num_triangles, "num_triangles")
    if not (isinstance(density, (int, float)) and math.isfinite(density) and density > 0):
        raise ValueError(f"density: expected a positive number, got {density!r}")
    return values


def check_two_level_knobs(top_density, density, min_triangles) -> None:
    """Provided: validate ``build_two_level_grid``'s knobs (ValueError naming the knob)."""
    for name, value in (("top_density", top_density), ("density", density)):
        if isinstance(value, bool) or not (
            isinstance(value, (int, float)) and math.isfinite(value) and value > 0
        ):
            raise ValueError(f"{name}: expected a positive number, got {value!r}")
    _positive_int(min_triangles, "min_triangles", 0)


def check_resolution(resolution) -> None:
    """Provided: ``resolution`` must be None or 3 positive ints."""
    if resolution is not None and (
        not isinstance(resolution, (tuple, list))
        or len(resolution) != 3
        or not all(isinstance(r, int) and not isinstance(r, bool) and r >= 1 for r in resolution)
    ):
        raise ValueError(f"resolution: expected 3 positive ints (rx, ry, rz), got {resolution!r}")


def check_morton_inputs(points, lo, hi, bits) -> None:
    """Provided: validate :func:`morton_codes`'s arguments."""
    if not isinstance(points, torch.Tensor) or not points.is_floating_point():
        raise TypeError(
            f"points: expected a float tensor of shape (N, 3), got "
            f"{getattr(points, 'dtype', type(points).__name__)}"
        )
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"points: expected shape (N, 3), got {tuple(points.shape)}")
    for name, x in (("lo", lo), ("hi", hi)):
        if not isinstance(x, torch.Tensor) or x.shape != (3,):
            raise ValueError(
                f"{name}: expected a (3,) tensor, got {getattr(x, 'shape', type(x).__name__)}"
            )
    _positive_int(bits, "bits", 1, 21)  # 3 * 21 = 63 bits fit an int64


def check_leaf_size(leaf_size) -> None:
    """Provided: ``leaf_size`` must be a positive int."""
    _positive_int(leaf_size, "leaf_size")


def check_bins(bins) -> None:
    """Provided: ``bins`` must be an int in 2..1024."""
    _positive_int(bins, "bins", 2, 1024)


def check_links(bvh) -> None:
    """Provided: ``bvh`` must hold ``left`` and ``right`` (M,) int64 tensors."""
    if not isinstance(bvh, dict) or not all(
        isinstance(bvh.get(k), torch.Tensor) for k in ("left", "right")
    ):
        raise ValueError("bvh: expected a BVH dict with 'left' and 'right' tensors")


def check_kd_knobs(mesh, max_depth, traversal_cost, intersect_cost, empty_bonus) -> int:
    """Provided: validate :func:`build_kdtree`'s knobs; returns ``max_depth`` with its
    default ``round(8 + 1.3 log2 F)`` (pbrt's) filled in."""
    if max_depth is None:
        max_depth = round(8 + 1.3 * math.log2(mesh.num_faces))
    _positive_int(max_depth, "max_depth", 0, 60)
    for name, value in (("traversal_cost", traversal_cost), ("intersect_cost", intersect_cost)):
        if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
            raise ValueError(f"{name}: expected a positive number, got {value!r}")
    if not (isinstance(empty_bonus, (int, float)) and 0 <= empty_bonus <= 1):
        raise ValueError(f"empty_bonus: expected a number in [0, 1], got {empty_bonus!r}")
    return max_depth


def check_kd_fields(tree) -> None:
    """Provided: ``tree`` must hold the kd fields :func:`kd_pack` reads."""
    if not isinstance(tree, dict):
        raise TypeError(f"tree: expected a kd dict, got {type(tree).__name__}")
    for key in ("split", "axis", "left", "first", "count"):
        if not isinstance(tree.get(key), torch.Tensor):
            raise TypeError(f"tree: expected a tensor under {key!r}")


def check_packed(packed) -> None:
    """Provided: ``packed`` must be an (M, 2) int32 tensor."""
    if not isinstance(packed, torch.Tensor) or packed.dtype != torch.int32:
        raise TypeError(
            f"packed: expected an int32 tensor of shape (M, 2), got "
            f"{getattr(packed, 'dtype', type(packed).__name__)}"
        )
    if packed.ndim != 2 or packed.shape[1] != 2:
        raise ValueError(f"packed: expected shape (M, 2), got {tuple(packed.shape)}")


def check_memory_budget(memory_budget_bytes) -> None:
    """Provided: ``memory_budget_bytes`` must be a positive int."""
    _positive_int(memory_budget_bytes, "memory_budget_bytes")
