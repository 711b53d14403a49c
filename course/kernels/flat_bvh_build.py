"""Building a flat BVH: binned SAH splits level by level (median splits below
``MEDIAN_DEPTH``), then the node pairs packed as the walks read them. Part of
:mod:`course.kernels.flat_bvh`.
"""

from __future__ import annotations

import contextlib
import math
import time

import torch

from course.core.raymath import check_mesh
from course.core.types import Mesh
from course.given.lab2_blocks import expand_ranges, surface_area
from course.given.lab2_bvh import TreeLevels
from course.kernels.flat_bvh_layout import BINS, MEDIAN_DEPTH, STACK_DEPTH, FlatBVH

# --------------------------------------------------------------------------------------
# Build
# --------------------------------------------------------------------------------------


@contextlib.contextmanager
def _one_cpu_thread(device: torch.device):
    """Run torch's CPU ops on one thread inside (restored after; a no-op off the CPU).

    The build and the torch walk run many small ops (10^3 to 10^5 elements) one after
    another: splitting each over threads costs more in start-up and waiting than it saves,
    and on a busy machine much more (the bunny's build took 1.9 s on one thread and 12-27 s
    on two, on a shared two-core machine). The setting is process-wide while inside: torch
    ops of other Python threads run on one thread meanwhile.
    """
    if device.type != "cpu":
        yield
        return
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(threads)


def _binned_splits(lo, hi, cen, tri, owner, k):
    """SAH over BINS bins per axis for k nodes at once.

    tri: (P,) triangle ids of the nodes' triangles; owner: (P,) their node (0..k-1).
    Returns (axis, split bin, cost, widest centroid axis) per node, each (k,), and the
    (P, 3) bin of each triangle:
    a triangle goes left when its bin on the chosen axis is <= the split bin.
    """
    device, c = cen.device, cen[tri]
    idx3 = owner[:, None].expand(-1, 3)
    cmin = torch.full((k, 3), math.inf, device=device).scatter_reduce(0, idx3, c, "amin")
    cmax = torch.full((k, 3), -math.inf, device=device).scatter_reduce(0, idx3, c, "amax")
    extent = (cmax - cmin)[owner]
    scale = torch.where(extent > 0, BINS / extent, torch.zeros_like(extent))
    b = ((c - cmin[owner]) * scale).long().clamp_(0, BINS - 1)  # (P, 3)
    key = (owner[:, None] * 3 + torch.arange(3, device=device)) * BINS + b  # (P, 3)
    key = key.reshape(-1)
    n = torch.zeros(k * 3 * BINS, device=device).index_add_(
        0, key, torch.ones(len(key), device=device)
    )
    idx = key[:, None].expand(-1, 3)
    box_lo = lo[tri][:, None, :].expand(-1, 3, -1).reshape(-1, 3)
    box_hi = hi[tri][:, None, :].expand(-1, 3, -1).reshape(-1, 3)
    blo = (
        torch.full((k * 3 * BINS, 3), math.inf, device=device)
        .scatter_reduce(0, idx, box_lo, "amin")
        .view(k, 3, BINS, 3)
    )
    bhi = (
        torch.full((k * 3 * BINS, 3), -math.inf, device=device)
        .scatter_reduce(0, idx, box_hi, "amax")
        .view(k, 3, BINS, 3)
    )
    n = n.view(k, 3, BINS)
    # Left of split s: bins 0..s; right: bins s+1..BINS-1 (prefix and suffix scans).
    left_n = n.cumsum(2)[..., :-1]
    left_a = surface_area(blo.cummin(2).values, bhi.cummax(2).values)[..., :-1]
    right_n = n.flip(2).cumsum(2).flip(2)[..., 1:]
    right_a = surface_area(
        blo.flip(2).cummin(2).values.flip(2), bhi.flip(2).cummax(2).values.flip(2)
    )[..., 1:]
    cost = left_a * left_n + right_a * right_n
    cost = torch.where((left_n > 0) & (right_n > 0), cost, math.inf).reshape(k, -1)
    best_cost, best = cost.min(1)
    widest = (cmax - cmin).argmax(1)
    return best // (BINS - 1), best % (BINS - 1), best_cost, widest, b


def build_flat_bvh(vertices: torch.Tensor, faces: torch.Tensor, leaf_size: int = 4) -> FlatBVH:
    """Binned-SAH BVH of a triangle mesh, flattened for the GPU kernels.

    vertices: (V, 3) float (finite); faces: (F, 3) int64 (or int32), F >= 1; leaf_size: the
    largest leaf (every node with more triangles is split; 4 is a good GPU default: 1-2 leaf
    visits fill a warp's triangle tests). Built on ``vertices.device``; the result lives there too.

    Splits minimise the SAH ``A_left n_left + A_right n_right`` over 16 centroid bins per
    axis; a node whose centroids all fall into one bin (or one below MEDIAN_DEPTH) is split
    at its object median instead. Node boxes are the exact float32 bounds of their triangles.
    """
    start_time = time.perf_counter()
    if isinstance(faces, torch.Tensor) and faces.dtype == torch.int32:
        faces = faces.long()
    check_mesh(Mesh(vertices, faces), finite=True, name="vertices")
    if isinstance(leaf_size, bool) or not isinstance(leaf_size, int) or leaf_size < 1:
        raise ValueError(f"leaf_size: expected an int >= 1, got {leaf_size!r}")
    with _one_cpu_thread(vertices.device):
        return _build(vertices, faces, leaf_size, start_time)


def _build(
    vertices: torch.Tensor, faces: torch.Tensor, leaf_size: int, start_time: float
) -> FlatBVH:
    device = vertices.device
    faces = faces.long()
    corners = vertices[faces]  # (F, 3, 3) in the input dtype
    f32 = corners.to(torch.float32)
    lo, hi = f32.amin(1), f32.amax(1)
    cen = (lo + hi) * 0.5
    n_tri = faces.shape[0]
    tree = TreeLevels(n_tri, device)
    order = torch.arange(n_tri, device=device)
    level = torch.zeros(1, dtype=torch.int64, device=device)
    depth = 0
    while len(level):
        start, end = tree.ranges(level)
        split = (end - start) > leaf_size
        level, start, end = level[split], start[split], end[split]
        if not len(level):
            break
        k, count = len(level), end - start
        owner, pos = expand_ranges(start, count)
        tri = order[pos]
        axis, split_bin, cost, widest, b = _binned_splits(lo, hi, cen, tri, owner, k)
        use_median = ~torch.isfinite(cost) | (depth >= MEDIAN_DEPTH)
        rank = torch.arange(len(pos), device=device) - (torch.cumsum(count, 0) - count)[owner]
        if bool(use_median.any()):
            # Object median along the widest centroid axis: sort each such node's triangles
            # by centroid (the others keep their order) and cut in the middle.
            c_axis = cen[tri].gather(1, widest[owner, None])[:, 0]
            key = torch.argsort(torch.where(use_median[owner], c_axis, rank.float()), stable=True)
            key = key[torch.argsort(owner[key], stable=True)]  # by node, then by value
            tri, b = tri[key], b[key]
        go_right = torch.where(
            use_median[owner],
            rank >= (count // 2)[owner],
            b.gather(1, axis[owner, None])[:, 0] > split_bin[owner],
        )
        perm = torch.argsort(owner * 2 + go_right.long(), stable=True)
        order[pos] = tri[perm]
        n_left = torch.zeros(k, dtype=torch.int64, device=device).index_add_(
            0, owner, (~go_right).long()
        )
        level = tree.split(level, start + n_left, depth)
        depth += 1
    if depth + 1 > STACK_DEPTH:
        raise ValueError(
            f"faces: the BVH has {depth + 1} levels, more than the traversal "
            f"stack's {STACK_DEPTH} (over 2^23 triangles?)"
        )
    bvh = tree.finish(order, lo, hi)
    leaf = bvh["left"] < 0
    ints = torch.stack(
        [torch.where(leaf, bvh["first"], bvh["right"]), torch.where(leaf, bvh["count"], 0)], 1
    ).to(torch.int32)
    nodes = torch.cat([bvh["lo"], bvh["hi"], ints.view(torch.float32)], 1).contiguous()
    tris = corners[bvh["triangles"]].to(torch.float64)
    v0, e1, e2 = tris[:, 0], tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]
    index = bvh["triangles"].to(torch.int32).view(torch.float32)[:, None]
    zero = torch.zeros_like(index)
    last = torch.zeros(n_tri, dtype=torch.int32, device=device)
    last[(bvh["first"] + bvh["count"] - 1)[leaf]] = 1  # each leaf's last row
    rows = torch.cat(
        [v0.float(), index, e1.float(), zero, e2.float(), last.view(torch.float32)[:, None]], 1
    ).contiguous()
    return FlatBVH(
        nodes=nodes,
        triangles=rows,
        order=bvh["triangles"],
        depth=depth + 1,
        leaf_size=leaf_size,
        build_seconds=time.perf_counter() - start_time,
        pairs=_pairs(nodes, ints, leaf),
    )


def _pairs(nodes: torch.Tensor, ints: torch.Tensor, leaf: torch.Tensor) -> torch.Tensor:
    """The (K, 16) ``pairs`` layout (module docstring) of the (M, 8) nodes: row r holds the
    children of the r-th interior node in depth-first order."""
    inner = (~leaf).nonzero()[:, 0]
    rank = torch.cumsum((~leaf).long(), 0) - 1
    first, count = ints[:, 0].long(), ints[:, 1].long()
    ref = torch.where(leaf, ~first, rank).to(torch.int32)  # each node as a child
    a, b = inner + 1, first[inner]  # an interior node's word 6 is its right child
    lo, hi = nodes[:, 0:3], nodes[:, 3:6]
    planes = torch.stack([lo[a], hi[a], lo[b], hi[b]], 2).reshape(-1, 12)  # axis-major
    links = torch.stack(
        [
            ref[a],
            ref[b],
            torch.where(leaf[a], count[a], 0).to(torch.int32),
            torch.where(leaf[b], count[b], 0).to(torch.int32),
        ],
        1,
    )
    return torch.cat([planes, links.view(torch.float32)], 1).contiguous()
