"""Input checks and tree plumbing shared by Lab 2's skeleton and reference.

Given code, not exercises: the lab's skeleton and its reference import these, so
there is one copy of them.
"""

from __future__ import annotations

import math

import torch

from course.core.raymath import gamma
from course.core.types import Hits, Mesh, Rays

STRUCTURES = ("grid", "grid2", "bvh", "kd")
"""The structures this lab builds, by their ``"kind"``."""
COUNTERS = ("steps", "tests")
"""The per-ray work counters every traversal returns (the grid adds ``"skipped"``)."""
STRUCTURE_KEYS = {
    "grid": ("lo", "hi", "resolution", "cell_start", "cell_count", "triangles",
             "tri_cell_lo", "tri_cell_hi"),
    "grid2": ("lo", "hi", "resolution", "cell_start", "cell_count", "triangles",
              "tri_cell_lo", "tri_cell_hi", "big", "sub_of", "sub_lo", "sub_hi",
              "sub_resolution", "sub_cell_base", "sub_cell_start", "sub_cell_count",
              "sub_triangles", "sub_tri_cell_lo", "sub_tri_cell_hi"),
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
        raise TypeError(f"mesh: expected vertices of dtype {rays.dtype} like rays, got {mesh.dtype}")
    if mesh.device != rays.device:
        raise ValueError(f"mesh: expected a mesh on {rays.device} like rays, got {mesh.device}")
    if not callable(intersect):
        raise TypeError("intersect: expected a callable intersect(origins, directions, v0, v1, "
                        f"v2, t_min, t_max) -> (t, u, v), got {type(intersect).__name__}")


def check_mesh(mesh, finite: bool = False) -> None:
    """Provided: ``mesh`` must be a valid ``course.core.types.Mesh`` (TypeError/ValueError).

    finite: also require finite vertices (every builder does: a NaN or inf corner has no
    bounds to sort by). Raises ValueError naming ``mesh``, the count and the first vertex.
    """
    if not isinstance(mesh, Mesh):
        raise TypeError(f"mesh: expected course.core.types.Mesh, got {type(mesh).__name__}")
    mesh.validate()
    if finite:
        bad = ~torch.isfinite(mesh.vertices).all(-1)
        if bool(bad.any()):
            first = int(bad.nonzero()[0, 0])
            raise ValueError(
                f"mesh: expected finite vertices to build a structure over, got "
                f"{int(bad.sum())} of {len(bad)} with NaN or inf coordinates (first: vertex "
                f"{first} = {mesh.vertices[first].tolist()}); repair or drop those triangles")


def check_structure(structure, kind: str, name: str, mesh: Mesh) -> None:
    """Provided: ``structure`` must be a ``kind`` dict built for a mesh like ``mesh``.

    Raises ValueError/TypeError naming ``name`` (the argument) and what is missing.
    """
    if not isinstance(structure, dict) or structure.get("kind") != kind:
        got = structure.get("kind") if isinstance(structure, dict) else type(structure).__name__
        raise ValueError(f"{name}: expected a dict with kind={kind!r} (from build_...), "
                         f"got {got!r}")
    for key in STRUCTURE_KEYS[kind]:
        x = structure.get(key)
        if not isinstance(x, torch.Tensor):
            raise TypeError(f"{name}: expected a tensor under {key!r}, got {type(x).__name__}")
        if x.device != mesh.device:
            raise ValueError(f"{name}: {key!r} is on {x.device}, the mesh on {mesh.device}")
    if structure["triangles"].numel() and int(structure["triangles"].max()) >= mesh.num_faces:
        raise ValueError(f"{name}: refers to triangle {int(structure['triangles'].max())}, "
                         f"but the mesh has {mesh.num_faces}: built for another mesh?")


def _positive_int(value, name: str, lo: int = 1, hi: int | None = None) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or value < lo or (
            hi is not None and value > hi):
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
        if isinstance(value, bool) or not (isinstance(value, (int, float))
                                           and math.isfinite(value) and value > 0):
            raise ValueError(f"{name}: expected a positive number, got {value!r}")
    _positive_int(min_triangles, "min_triangles", 0)


def check_resolution(resolution) -> None:
    """Provided: ``resolution`` must be None or 3 positive ints."""
    if resolution is not None and (
            not isinstance(resolution, (tuple, list)) or len(resolution) != 3
            or not all(isinstance(r, int) and not isinstance(r, bool) and r >= 1
                       for r in resolution)):
        raise ValueError(f"resolution: expected 3 positive ints (rx, ry, rz), got {resolution!r}")


def check_morton_inputs(points, lo, hi, bits) -> None:
    """Provided: validate :func:`morton_codes`'s arguments."""
    if not isinstance(points, torch.Tensor) or not points.is_floating_point():
        raise TypeError(f"points: expected a float tensor of shape (N, 3), got "
                        f"{getattr(points, 'dtype', type(points).__name__)}")
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"points: expected shape (N, 3), got {tuple(points.shape)}")
    for name, x in (("lo", lo), ("hi", hi)):
        if not isinstance(x, torch.Tensor) or x.shape != (3,):
            raise ValueError(f"{name}: expected a (3,) tensor, got "
                             f"{getattr(x, 'shape', type(x).__name__)}")
    _positive_int(bits, "bits", 1, 21)  # 3 * 21 = 63 bits fit an int64


def check_leaf_size(leaf_size) -> None:
    """Provided: ``leaf_size`` must be a positive int."""
    _positive_int(leaf_size, "leaf_size")


def check_bins(bins) -> None:
    """Provided: ``bins`` must be an int in 2..1024."""
    _positive_int(bins, "bins", 2, 1024)


def check_links(bvh) -> None:
    """Provided: ``bvh`` must hold ``left`` and ``right`` (M,) int64 tensors."""
    if not isinstance(bvh, dict) or not all(isinstance(bvh.get(k), torch.Tensor)
                                            for k in ("left", "right")):
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
        raise TypeError(f"packed: expected an int32 tensor of shape (M, 2), got "
                        f"{getattr(packed, 'dtype', type(packed).__name__)}")
    if packed.ndim != 2 or packed.shape[1] != 2:
        raise ValueError(f"packed: expected shape (M, 2), got {tuple(packed.shape)}")


def check_memory_budget(memory_budget_bytes) -> None:
    """Provided: ``memory_budget_bytes`` must be a positive int."""
    _positive_int(memory_budget_bytes, "memory_budget_bytes")


def triangle_bounds(mesh: Mesh) -> tuple[torch.Tensor, torch.Tensor]:
    """Provided: ``(lo, hi)``, each (F, 3): the axis-aligned bounds of every triangle."""
    corners = mesh.triangles()
    return corners.amin(dim=1), corners.amax(dim=1)


def surface_area(lo: torch.Tensor, hi: torch.Tensor) -> torch.Tensor:
    """Provided: ``2 (dx dy + dy dz + dz dx)`` of boxes ``(..., 3)``; 0 for empty boxes
    (``lo > hi``, e.g. the ``+inf``/``-inf`` bounds of an empty bin)."""
    ext = (hi - lo).clamp(min=0).nan_to_num(0.0, posinf=0.0)
    return 2 * (ext[..., 0] * ext[..., 1] + ext[..., 1] * ext[..., 2] + ext[..., 2] * ext[..., 0])


def slab_test(origins, inv_directions, lo, hi, t_lo, t_hi):
    """Provided: rays against axis-aligned boxes (Lab 1's conservative slab test).

    origins, inv_directions: (n, 3) with ``inv_directions = 1 / directions`` (``1/+-0 =
    +-inf``); lo, hi: (n, 3) or (3,) boxes; t_lo, t_hi: (n,). Returns ``(t_near, t_far,
    hit)``, each (n,): the ray's interval inside the box clipped to ``[t_lo, t_hi]``.

    NaN from ``0 * inf`` (a ray in a slab plane with a zero direction component) is
    dropped by ``fmax``/``fmin``; ``t_far`` is scaled by ``1 + 2 gamma(3)`` (Ize 2013) so
    rounding never turns a hit into a miss; NaN/inf rays and empty boxes never hit.
    """
    t0 = (lo - origins) * inv_directions
    t1 = (hi - origins) * inv_directions
    near = torch.minimum(t0, t1)
    far = torch.maximum(t0, t1) * (1 + 2 * gamma(3, t0.dtype))
    t_near = torch.fmax(t_lo, torch.fmax(torch.fmax(near[..., 0], near[..., 1]), near[..., 2]))
    t_far = torch.fmin(t_hi, torch.fmin(torch.fmin(far[..., 0], far[..., 1]), far[..., 2]))
    valid = (torch.isfinite(origins).all(-1) & (inv_directions.abs() > 0).all(-1)
             & (lo <= hi).all(-1))
    return t_near, t_far, (t_near <= t_far) & (t_near < math.inf) & valid


def expand_ranges(first: torch.Tensor, count: torch.Tensor):
    """Provided: every element of the ranges ``[first[i], first[i] + count[i])``.

    first, count: (k,) int64. Returns ``(owner, index)``, each (sum(count),) int64: range
    ``owner[j]`` contains element ``index[j]``; owners ascending, indices ascending within
    each range. The batched form of ``for i: for j in range(first[i], first[i] + count[i])``
    (a cell's triangle list, a leaf's triangles, a node's primitives).
    """
    owner = torch.repeat_interleave(torch.arange(len(count), device=count.device), count)
    offset = torch.cumsum(count, 0) - count
    index = first[owner] + torch.arange(len(owner), device=count.device) - offset[owner]
    return owner, index


def grid_resolutions(extent: torch.Tensor, num_triangles: torch.Tensor, density: float = 2.0,
                     max_cells: int = 2**22) -> torch.Tensor:
    """Provided: Lab 2's ``grid_resolution`` heuristic for many boxes at once (sub-grids).

    extent: (S, 3) float, non-negative box sizes; num_triangles: (S,) int64 >= 1.
    Returns (S, 3) int64 resolutions >= 1: about ``density * n`` cells per box (at most
    ``max_cells``), as close to cubes as possible, one cell on a thin axis.

    The thin-axis rule of ``grid_resolution`` without a loop over boxes: solve for
    ``k`` over the free axes in logs, drop the axes with ``k * extent < 1``, and repeat;
    three rounds suffice (each round drops an axis or changes nothing).
    """
    target = (density * num_triangles.double()).clamp(max=max_cells)
    ext = extent.double()
    free = ext > 0
    k = torch.zeros_like(target)
    for _ in range(3):
        n_free = free.sum(dim=1)
        log_volume = torch.where(free, ext.clamp(min=1e-300).log(), 0.0).sum(dim=1)
        k = torch.where(n_free > 0, ((target.log() - log_volume) / n_free.clamp(min=1)).exp(), 0.0)
        free = free & (ext * k[:, None] >= 1)
    return torch.where(free, torch.round(ext * k[:, None]), 1.0).long().clamp(min=1)


def pair_chunks(first: torch.Tensor, count: torch.Tensor, max_pairs: int = MAX_PAIRS):
    """Provided: :func:`expand_ranges` in chunks of at most ``max_pairs`` elements.

    Yields ``(owner, index)`` like ``expand_ranges(first, count)``, a chunk at a time (a range
    may be split between two chunks), so only one chunk is ever in memory.
    """
    end = torch.cumsum(count, 0)
    total = int(end[-1]) if len(end) else 0
    for p0 in range(0, total, max_pairs):
        j = torch.arange(p0, min(total, p0 + max_pairs), device=count.device)
        owner = torch.searchsorted(end, j, right=True)  # the first range ending after j
        yield owner, first[owner] + j - (end - count)[owner]


def test_ranges(intersect, rays: Rays, corners: torch.Tensor, ray: torch.Tensor,
                first: torch.Tensor, count: torch.Tensor, triangles: torch.Tensor,
                closest: dict, counters: dict) -> None:
    """Provided: test ray ``ray[i]`` against ``triangles[first[i] : first[i] + count[i]]``
    for every ``i`` (its leaf's list), in chunks, with :func:`intersect_pairs`."""
    for owner, k in pair_chunks(first, count):
        intersect_pairs(intersect, rays, corners, ray[owner], triangles[k], closest, counters)


def new_closest(n: int, like: torch.Tensor) -> dict:
    """Provided: the closest-hit state of ``n`` rays, all missed (dtype/device of ``like``)."""
    miss = Hits.miss(n, dtype=like.dtype, device=like.device)
    return {"t": miss.t, "triangle": miss.triangle, "u": miss.u, "v": miss.v}


def intersect_pairs(intersect, rays: Rays, corners: torch.Tensor, ray: torch.Tensor,
               tri: torch.Tensor, closest: dict, counters: dict) -> None:
    """Provided: run ``intersect`` on the (ray, triangle) pairs and keep each ray's closest.

    ray, tri: (P,) int64 indices into ``rays`` and ``corners`` (F, 3, 3). Updates
    ``closest`` (from :func:`new_closest`) in place: a pair replaces a ray's hit when its
    ``t`` is smaller, or equal with a lower triangle index (the brute-force order), and
    adds each ray's number of pairs to ``counters["tests"]``.
    """
    if len(ray) == 0:
        return
    tri_corners = corners[tri]
    t, u, v = intersect(rays.origins[ray], rays.directions[ray], tri_corners[:, 0],
                        tri_corners[:, 1], tri_corners[:, 2], rays.t_min[ray], rays.t_max[ray])
    counters["tests"].index_add_(0, ray, torch.ones_like(ray))
    best_t, best_tri = closest["t"], closest["triangle"]
    hit = t < math.inf
    # The nearest t per ray over the old hit and all pairs ...
    nearest = best_t.scatter_reduce(0, ray, t, "amin")
    # ... and among those at that t, the lowest triangle index.
    candidate = hit & (t == nearest[ray])
    big = torch.iinfo(torch.int64).max
    lowest = torch.where((best_t == nearest) & (best_tri >= 0), best_tri, big)
    lowest = lowest.scatter_reduce(0, ray[candidate], tri[candidate], "amin")
    win = candidate & (tri == lowest[ray])
    winners = ray[win]
    closest["t"][winners] = t[win]
    closest["triangle"][winners] = tri[win]
    closest["u"][winners] = u[win]
    closest["v"][winners] = v[win]


def new_counters(n: int, device, names=COUNTERS) -> dict:
    """Provided: zeroed per-ray counters ``{name: (n,) int64}``."""
    return {name: torch.zeros(n, dtype=torch.int64, device=device) for name in names}


def as_hits(closest: dict) -> Hits:
    """Provided: the closest-hit state as ``course.core.types.Hits``."""
    return Hits(t=closest["t"], triangle=closest["triangle"], u=closest["u"], v=closest["v"])


def add_count(counter: torch.Tensor, ray: torch.Tensor) -> None:
    """Provided: ``counter[r] += 1`` for every entry ``r`` of ``ray`` (repeats count)."""
    counter.index_add_(0, ray, torch.ones_like(ray))


def assemble_bvh(order, start, end, left, right, depth, tri_lo, tri_hi) -> dict:
    """Provided: the flat, depth-first BVH of a tree built level by level.

    order: (F,) int64, the triangles in leaf order; start, end: (M,) int64, node ``i``
    holds ``order[start[i]:end[i]]``; left, right: (M,) int64 child ids (-1 for leaves);
    depth: (M,) int64 (root 0). Node ids are in creation order, parents before children.
    tri_lo, tri_hi: (F, 3) triangle bounds.

    Returns the BVH dict (see :func:`build_lbvh`) with the nodes renumbered depth first
    (pre-order: a node, its left subtree, its right subtree), the order a stackless walk
    reads them in. Bounds come bottom-up: leaves from their triangles, parents from their
    two children, one tree level at a time; so every box contains its children exactly.
    """
    m, device = len(start), start.device
    leaf = left < 0
    max_depth = int(depth.max())
    levels = [(depth == k).nonzero()[:, 0] for k in range(max_depth + 1)]
    node_lo = torch.full((m, 3), math.inf, dtype=tri_lo.dtype, device=device)
    node_hi = torch.full((m, 3), -math.inf, dtype=tri_lo.dtype, device=device)
    leaves = leaf.nonzero()[:, 0]
    owner, k = expand_ranges(start[leaves], end[leaves] - start[leaves])
    index = leaves[owner, None].expand(-1, 3)
    node_lo.scatter_reduce_(0, index, tri_lo[order[k]], "amin")
    node_hi.scatter_reduce_(0, index, tri_hi[order[k]], "amax")
    size = torch.ones(m, dtype=torch.int64, device=device)
    for nodes in reversed(levels):
        nodes = nodes[~leaf[nodes]]
        a, b = left[nodes], right[nodes]
        node_lo[nodes] = torch.minimum(node_lo[a], node_lo[b])
        node_hi[nodes] = torch.maximum(node_hi[a], node_hi[b])
        size[nodes] = 1 + size[a] + size[b]
    # Pre-order positions: the left child right after its parent, the right child after
    # the whole left subtree.
    pos = torch.zeros(m, dtype=torch.int64, device=device)
    for nodes in levels:
        nodes = nodes[~leaf[nodes]]
        pos[left[nodes]] = pos[nodes] + 1
        pos[right[nodes]] = pos[nodes] + 1 + size[left[nodes]]
    out = {"kind": "bvh"}
    out["lo"] = torch.empty_like(node_lo).index_copy_(0, pos, node_lo)
    out["hi"] = torch.empty_like(node_hi).index_copy_(0, pos, node_hi)
    minus = torch.full_like(left, -1)
    out["left"] = minus.index_copy(0, pos, torch.where(leaf, -1, pos[left.clamp(min=0)]))
    out["right"] = minus.index_copy(0, pos, torch.where(leaf, -1, pos[right.clamp(min=0)]))
    out["first"] = torch.zeros_like(start).index_copy_(0, pos, torch.where(leaf, start, 0))
    out["count"] = torch.zeros_like(start).index_copy_(0, pos, torch.where(leaf, end - start, 0))
    out["triangles"] = order
    return out


class TreeLevels:
    """Provided: the nodes of a BVH built level by level, for :func:`assemble_bvh`.

    Node ``i`` holds the triangles ``order[start[i] : end[i]]`` of the build's triangle
    order; the root (id 0) holds all ``f``. :meth:`split` gives nodes of the current level
    their two children, :meth:`finish` assembles the flat BVH once no node splits.
    """

    def __init__(self, f: int, device):
        zero = torch.zeros(1, dtype=torch.int64, device=device)
        self.starts, self.ends, self.depths = [zero], [zero + f], [zero]
        self.children = []  # per level: (parents, left ids, right ids)
        self.count = 1

    def ranges(self, nodes: torch.Tensor):
        """``(start, end)`` of ``nodes`` (k,) int64 ids, each (k,) int64."""
        return torch.cat(self.starts)[nodes], torch.cat(self.ends)[nodes]

    def split(self, nodes: torch.Tensor, mid: torch.Tensor, depth: int) -> torch.Tensor:
        """Split each of ``nodes`` (k,), at tree depth ``depth``, into ``[start, mid)`` and
        ``[mid, end)``; returns the (2k,) children ids, left and right interleaved."""
        start, end = self.ranges(nodes)
        k = len(nodes)
        ids = self.count + torch.arange(2 * k, device=nodes.device)
        self.children.append((nodes, ids[0::2], ids[1::2]))
        self.starts.append(torch.stack((start, mid), 1).reshape(-1))
        self.ends.append(torch.stack((mid, end), 1).reshape(-1))
        self.depths.append(torch.full((2 * k,), depth + 1, dtype=torch.int64, device=nodes.device))
        self.count += 2 * k
        return ids

    def finish(self, order: torch.Tensor, tri_lo: torch.Tensor, tri_hi: torch.Tensor) -> dict:
        """The BVH dict of the tree; ``order`` (F,): the triangles in their final order."""
        start, end = torch.cat(self.starts), torch.cat(self.ends)
        left, right = torch.full_like(start, -1), torch.full_like(start, -1)
        for parents, a, b in self.children:
            left[parents], right[parents] = a, b
        return assemble_bvh(order, start, end, left, right, torch.cat(self.depths), tri_lo,
                            tri_hi)


def ray_octants(directions: torch.Tensor) -> torch.Tensor:
    """Provided: each ray's direction octant, ``x_neg + 2 y_neg + 4 z_neg`` ((n,) int64).

    directions: (n, 3). A component is negative by its sign bit, so ``-0.0`` counts as
    negative like ``-1``: either order of a node's children is right for a zero component.
    """
    neg = torch.signbit(directions).long()
    return neg[:, 0] + 2 * neg[:, 1] + 4 * neg[:, 2]


def pack_bvh(bvh: dict, mesh: Mesh, octants=None) -> dict:
    """Provided: a BVH laid out for the sync-free walk (``bvh_closest_hit_fast``).

    bvh: any valid BVH dict (``build_lbvh``/``build_sah_bvh``); mesh: its mesh; octants:
    the ray octants (:func:`ray_octants`) to lay out, default all 8. Returns:

    ===============  ================  ==================================================
    ``boxes``        (R * M, 6) float  ``lo, hi`` of every node, one depth-first array of
                                       the M nodes per packed octant (R of them)
    ``links``        (R * M, 3) int32  ``skip, first, count`` of the same rows: ``skip``
                                       the row after the node's subtree (``M`` past the
                                       end), a leaf's slots ``first .. first + count - 1``,
                                       ``count`` 0 for inner nodes
    ``base``         (8,) int64        octant -> its array's first row (-1: not packed)
    ``slots``        (F, 9) float      ``v0, e1, e2`` per leaf slot (``e1 = v1 - v0``,
                                       ``e2 = v2 - v0``; a leaf's triangles contiguous)
    ``tri``          (F,) int32        each slot's triangle index in the mesh
    ``lo, hi``       (3,) float        the root's box
    ``nodes``        int               M
    ===============  ================  ==================================================

    In the array of an octant every inner node is followed by its **near** child's subtree,
    then its far child's: near is the child whose box centre is lower along the node's
    split axis (the axis along which the children's centres differ most) for rays going up
    that axis, the other for rays going down. A walk that goes to ``i + 1`` after a hit
    inner node and to ``skip`` otherwise then visits exactly the nodes a stack traversal
    ordered by direction sign (pbrt's) pops, with no stack: the array *is* the traversal
    order. ``kind`` is ``"bvh_walk"``; host syncs happen here only (one per tree level),
    once per tree.
    """
    check_structure(bvh, "bvh", "bvh", mesh)
    octants = list(range(8)) if octants is None else sorted({int(o) for o in octants})
    if not octants or not all(0 <= o < 8 for o in octants):
        raise ValueError(f"octants: expected octants in 0..7, got {octants!r}")
    left, right, lo, hi = bvh["left"], bvh["right"], bvh["lo"], bvh["hi"]
    m, device = len(left), left.device
    leaf = left < 0
    inner = (~leaf).nonzero()[:, 0]
    parent = torch.full((m,), -1, dtype=torch.int64, device=device)
    parent[left[inner]] = inner
    parent[right[inner]] = inner
    levels = [torch.zeros(1, dtype=torch.int64, device=device)]  # breadth first, root down
    while True:
        below = levels[-1][~leaf[levels[-1]]]
        if not len(below):
            break
        levels.append(torch.cat((left[below], right[below])))
    size = torch.ones(m, dtype=torch.int64, device=device)  # nodes in each subtree
    for level in reversed(levels[1:]):
        size.index_add_(0, parent[level], size[level])
    # Near child first, per octant: (R, M) bool "left child first".
    safe_l, safe_r = left.clamp(min=0), right.clamp(min=0)
    gap = (lo[safe_r] + hi[safe_r]) - (lo[safe_l] + hi[safe_l])
    axis = gap.abs().argmax(1)
    left_low = gap.gather(1, axis[:, None])[:, 0] >= 0
    down = torch.tensor([[(o >> a) & 1 for a in range(3)] for o in octants], dtype=torch.bool,
                        device=device)                                        # (R, 3)
    left_first = left_low[None] ^ down[:, axis]
    near = torch.where(left_first, left[None], right[None])
    far = torch.where(left_first, right[None], left[None])
    pos = torch.zeros((len(octants), m), dtype=torch.int64, device=device)
    for level in levels[:-1]:  # children placed after their parent: top down
        up = level[~leaf[level]]
        a, b = near[:, up], far[:, up]
        pos.scatter_(1, a, pos[:, up] + 1)
        pos.scatter_(1, b, pos[:, up] + 1 + size[a])
    order = torch.empty_like(pos).scatter_(1, pos, torch.arange(m, device=device).expand_as(pos))
    skip = (pos + size).gather(1, order)
    count = torch.where(leaf, bvh["count"], 0)[order]
    first = torch.where(leaf, bvh["first"], 0)[order]
    base = torch.full((8,), -1, dtype=torch.int64, device=device)
    base[torch.tensor(octants, device=device)] = torch.arange(len(octants), device=device) * m
    corners = mesh.triangles()[bvh["triangles"]]
    return {"kind": "bvh_walk",
            "boxes": torch.cat((lo[order], hi[order]), 2).reshape(-1, 6),
            "links": torch.stack((skip, first, count), 2).reshape(-1, 3).int(),
            "base": base,
            "slots": torch.cat((corners[:, 0], corners[:, 1] - corners[:, 0],
                                corners[:, 2] - corners[:, 0]), 1),
            "tri": bvh["triangles"].int(), "lo": lo[0], "hi": hi[0], "nodes": m}


def check_walk(walk, mesh: Mesh, rays) -> None:
    """Provided: ``walk`` must be :func:`pack_bvh`'s layout of a BVH of ``mesh``, packed
    for every octant the ``rays`` go in (ValueError/TypeError naming ``walk``)."""
    if not isinstance(walk, dict) or walk.get("kind") != "bvh_walk":
        got = walk.get("kind") if isinstance(walk, dict) else type(walk).__name__
        raise ValueError(f"walk: expected pack_bvh(bvh, mesh)'s dict (kind 'bvh_walk'), "
                         f"got {got!r}")
    for key in ("boxes", "links", "base", "slots", "tri"):
        x = walk.get(key)
        if not isinstance(x, torch.Tensor) or x.device != mesh.device:
            raise ValueError(f"walk: expected a tensor on {mesh.device} under {key!r}")
    if walk["slots"].dtype != mesh.dtype or len(walk["tri"]) != mesh.num_faces:
        raise ValueError(f"walk: packed for {len(walk['tri'])} {walk['slots'].dtype} "
                         f"triangles, the mesh has {mesh.num_faces} {mesh.dtype}")
    # The octants in use marked in 8 flags (no sort, one host sync), the missing ones
    # listed only for the error.
    need = torch.zeros(8, dtype=torch.bool, device=rays.device)
    need.index_fill_(0, ray_octants(rays.directions), True)
    missing = need & (walk["base"] < 0)
    if bool(missing.any()):
        raise ValueError(f"walk: not packed for octant(s) {missing.nonzero()[:, 0].tolist()} "
                         f"of these rays: pack_bvh(bvh, mesh, octants=...) with them, or all 8")


def moller_trumbore_rows(o, d, v0, e1, e2, t_min, t_max):
    """Provided: Lab 1's Möller–Trumbore on precomputed edges, one ray per row.

    o, d, v0, e1, e2: (n, 3) float (``e1 = v1 - v0``, ``e2 = v2 - v0``), or each a tuple of
    its three (n,) columns; t_min, t_max: (n,).
    Returns ``(t, u, v, hit)``, each (n,): unmasked ``t, u, v`` and whether they are a hit
    (inside, not parallel, ``t`` in ``[t_min, t_max]``). The parallel test is relative:
    ``|det| <= eps |d| |e1| |e2|`` (max-norms). Every product is written out on (n,)
    columns: elementwise ops that ``torch.compile`` fuses into the kernel of its caller.
    """
    o, d, v0, e1, e2 = (_columns(x) for x in (o, d, v0, e1, e2))
    p = _cross(d, e2)
    det = _dot(e1, p)
    scale = _max_abs(d) * _max_abs(e1) * _max_abs(e2)
    not_parallel = det.abs() > torch.finfo(det.dtype).eps * scale
    inv_det = 1 / det
    s = tuple(a - b for a, b in zip(o, v0))
    u = _dot(s, p) * inv_det
    q = _cross(s, e1)
    v = _dot(d, q) * inv_det
    t = _dot(e2, q) * inv_det
    hit = not_parallel & (u >= 0) & (v >= 0) & (u + v <= 1) & (t >= t_min) & (t <= t_max)
    return t, u, v, hit


def _columns(x):
    """(n, 3) tensor or 3 columns -> a tuple of three (n,) columns."""
    return tuple(x.unbind(-1)) if isinstance(x, torch.Tensor) else tuple(x)


def _cross(a, b):
    """``a x b`` on column tuples."""
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def _dot(a, b):
    """``a . b`` on column tuples."""
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _max_abs(a):
    return torch.maximum(torch.maximum(a[0].abs(), a[1].abs()), a[2].abs())


def scene_statistics(mesh: Mesh) -> dict:
    """Provided: what the structure chooser looks at, in O(F) and without building anything.

    Returns plain Python numbers:

    * ``triangles``: F;
    * ``occupancy``: the fraction of the cells of a lambda = 2 grid over the scene's bounds
      that hold a triangle centre (a surface fills few, a soup many);
    * ``crowding``: the mean number of triangle centres in the cell of a triangle's centre,
      ``sum n_c^2 / sum n_c`` over that grid: about 1-4 when the triangles are spread as
      evenly as their surface allows, hundreds or more when most of them sit in a few
      cells (the teapot in a stadium: the grid's failure, measured before building it);
    * ``size_spread``: the 95th over the 5th percentile of the triangles' bounding-box
      diagonals (huge walls among tiny triangles: the mailbox's and the grid's worry).
    """
    check_mesh(mesh)
    tri_lo, tri_hi = triangle_bounds(mesh)
    lo, hi = tri_lo.amin(0), tri_hi.amax(0)
    extent = (hi - lo).double()
    f = mesh.num_faces
    res = grid_resolutions(extent[None], torch.tensor([f], device=extent.device), 2.0)[0]
    centres = ((tri_lo + tri_hi) / 2 - lo).double()
    cell = torch.where(extent > 0, centres / extent.clamp(min=1e-300) * res, 0.0).floor().long()
    cell = torch.minimum(cell.clamp(min=0), res - 1)
    cid = cell[:, 0] + res[0] * (cell[:, 1] + res[1] * cell[:, 2])
    counts = torch.bincount(cid, minlength=int(res.prod())).double()
    counts = counts[counts > 0]
    size = (tri_hi - tri_lo).double().norm(dim=1)
    q = torch.quantile(size[torch.randperm(f, device=size.device)[:100_000]]
                       if f > 100_000 else size, torch.tensor([0.05, 0.95], dtype=size.dtype,
                                                              device=size.device))
    return {"triangles": f, "occupancy": len(counts) / float(res.prod()),
            "crowding": float((counts * counts).sum() / counts.sum()),
            "size_spread": float(q[1] / q[0]) if q[0] > 0 else math.inf}


CHOOSER_LIMITS = {"grid_max_triangles": 50_000, "even_crowding": 32.0, "even_spread": 30.0,
                  "cheap_build_rays_per_triangle": 4.0}
"""The chooser's thresholds, from ``bench/lab2_accel.py``: a uniform grid only pays for
itself up to about 50K evenly spread triangles (the lecture's 1-50K); crowding above about 32
triangles per occupied cell (the bunny: 9, the teapot in a stadium: 960 and more) means the grid's cells do not fit the geometry; below about 4
rays per triangle the build time dominates the trace time, so the cheapest adequate build
wins."""


def choose_structure(mesh: Mesh, rays_hint: int | None = None):
    """Provided: the structure (and knobs) a scene requires, and why: ``(kind, knobs, reason)``.

    mesh: the scene; rays_hint: how many rays will be traced through it (None: many, e.g.
    frames of an image). ``kind`` is one of ``STRUCTURES`` and ``knobs`` go to
    ``build(mesh, kind, **knobs)``; ``reason`` explains the choice in words, with the
    numbers of :func:`scene_statistics`. Builds nothing: it only looks at the triangles.

    The rules, in order (thresholds in ``CHOOSER_LIMITS``, measured by the bench):

    1. Evenly spread (low crowding), similar sizes, at most ~50K triangles: a **uniform
       grid** (lambda = 2): the fastest build, and a short walk.
    2. Crowded (a teapot in a stadium): a uniform grid's cells miss the geometry. Few rays
       per triangle: the **two-level grid** (builds in a few sorts, adapts to the crowd);
       else the **binned-SAH BVH**, which adapts at every level (the LBVH does not: its
       Morton grid spans the whole scene).
    3. Otherwise (large or uneven sizes): a BVH; the **LBVH** when few rays per triangle
       will be traced (its build is a sort), the **SAH** build when many will.

    The **kd-tree** is considered and never chosen here: on this lab's batched traversal it
    builds 5-10x slower than the SAH BVH and traces no faster (bench), so it is the choice
    for none of these scenes.
    """
    stats = scene_statistics(mesh)
    f, crowd, spread = stats["triangles"], stats["crowding"], stats["size_spread"]
    if rays_hint is not None:
        _positive_int(rays_hint, "rays_hint")
    lim = CHOOSER_LIMITS
    few_rays = rays_hint is not None and rays_hint < lim["cheap_build_rays_per_triangle"] * f
    facts = (f"{f:,} triangles, crowding {crowd:.1f} triangles per occupied cell, "
             f"{stats['occupancy']:.1%} of the cells occupied, size spread {spread:.0f}x"
             + (f", {rays_hint:,} rays" if rays_hint is not None else ", many rays"))
    even = crowd <= lim["even_crowding"]
    if even and spread <= lim["even_spread"] and f <= lim["grid_max_triangles"]:
        return "grid", {"density": 2.0}, (
            f"{facts}: small and evenly spread, so a uniform grid (lambda = 2) fits it: the "
            f"fastest build and a short walk; the kd-tree never pays its build here")
    if not even:
        if few_rays:
            return "grid2", {}, (
                f"{facts}: most triangles crowd into a few cells of a uniform grid, and few "
                f"rays will be traced: a two-level grid gives the crowded cells their own "
                f"grids at the cost of a few sorts")
        return "bvh", {"method": "sah"}, (
            f"{facts}: most triangles crowd into a few cells, and many rays will be traced: "
            f"a binned-SAH BVH adapts at every level (the LBVH's Morton grid spans the whole "
            f"scene and would not)")
    if few_rays:
        return "bvh", {"method": "lbvh"}, (
            f"{facts}: too large or uneven for a uniform grid; with few rays per triangle the "
            f"build dominates, so the LBVH (one sort)")
    return "bvh", {"method": "sah"}, (
        f"{facts}: too large or uneven for a uniform grid; many rays repay the binned-SAH "
        f"build (fewer nodes per ray than the LBVH)")
