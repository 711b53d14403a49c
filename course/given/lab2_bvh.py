"""Lab 2's BVH plumbing: node arrays from a build's levels (``assemble_bvh``,
``TreeLevels``), ray octants, and the packed walk layout (``pack_bvh``, ``check_walk``).

Given code, not exercises (imported through :mod:`course.given.lab2`).
"""

from __future__ import annotations

import math

import torch

from course.core.types import Mesh
from course.given.lab2_blocks import expand_ranges
from course.given.lab2_checks import check_structure


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
        return assemble_bvh(order, start, end, left, right, torch.cat(self.depths), tri_lo, tri_hi)


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
    down = torch.tensor(
        [[(o >> a) & 1 for a in range(3)] for o in octants], dtype=torch.bool, device=device
    )  # (R, 3)
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
    return {
        "kind": "bvh_walk",
        "boxes": torch.cat((lo[order], hi[order]), 2).reshape(-1, 6),
        "links": torch.stack((skip, first, count), 2).reshape(-1, 3).int(),
        "base": base,
        "slots": torch.cat(
            (corners[:, 0], corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), 1
        ),
        "tri": bvh["triangles"].int(),
        "lo": lo[0],
        "hi": hi[0],
        "nodes": m,
    }


def check_walk(walk, mesh: Mesh, rays) -> None:
    """Provided: ``walk`` must be :func:`pack_bvh`'s layout of a BVH of ``mesh``, packed
    for every octant the ``rays`` go in (ValueError/TypeError naming ``walk``)."""
    if not isinstance(walk, dict) or walk.get("kind") != "bvh_walk":
        got = walk.get("kind") if isinstance(walk, dict) else type(walk).__name__
        raise ValueError(
            f"walk: expected pack_bvh(bvh, mesh)'s dict (kind 'bvh_walk'), got {got!r}"
        )
    for key in ("boxes", "links", "base", "slots", "tri"):
        x = walk.get(key)
        if not isinstance(x, torch.Tensor) or x.device != mesh.device:
            raise ValueError(f"walk: expected a tensor on {mesh.device} under {key!r}")
    if walk["slots"].dtype != mesh.dtype or len(walk["tri"]) != mesh.num_faces:
        raise ValueError(
            f"walk: packed for {len(walk['tri'])} {walk['slots'].dtype} "
            f"triangles, the mesh has {mesh.num_faces} {mesh.dtype}"
        )
    # The octants in use marked in 8 flags (no sort, one host sync), the missing ones
    # listed only for the error.
    need = torch.zeros(8, dtype=torch.bool, device=rays.device)
    need.index_fill_(0, ray_octants(rays.directions), True)
    missing = need & (walk["base"] < 0)
    if bool(missing.any()):
        raise ValueError(
            f"walk: not packed for octant(s) {missing.nonzero()[:, 0].tolist()} "
            f"of these rays: pack_bvh(bvh, mesh, octants=...) with them, or all 8"
        )
