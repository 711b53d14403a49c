"""Task 2: the BVH builds: ``morton_codes``, ``build_lbvh``, ``build_sah_bvh`` (binned SAH)."""

from __future__ import annotations

import math

import torch

from course.core.types import Mesh
from course.given.lab2 import (
    TreeLevels,
    check_bins,
    check_leaf_size,
    check_mesh,
    check_morton_inputs,
    expand_ranges,
    surface_area,
    triangle_bounds,
)


def morton_codes(
    points: torch.Tensor, lo: torch.Tensor, hi: torch.Tensor, bits: int = 10
) -> torch.Tensor:
    """Morton (Z-order) codes of points in the box ``[lo, hi]``.

    points: (N, 3) float; lo, hi: (3,) float; bits: bits per axis, 1..21 (10 gives the
    classic 30-bit code). Returns (N,) int64.

    1. Quantise each coordinate to ``bits`` bits: ``q = floor((p - lo) / (hi - lo) * 2^bits)``
       clamped to ``[0, 2^bits - 1]`` (``q = 0`` on an axis where ``hi == lo``; NaN -> 0).
    2. Interleave, x highest: bit ``i`` of ``qx`` goes to bit ``3i + 2`` of the code, of
       ``qy`` to ``3i + 1``, of ``qz`` to ``3i`` (Karras 2012: ``expandBits(x) * 4 +
       expandBits(y) * 2 + expandBits(z)``).

    Sorting by the code puts points that are close in space close in the array, so a
    range of sorted triangles is a compact cluster: the whole idea of the LBVH.

    Errors (the provided check): TypeError naming ``points`` unless it is a float tensor,
    ValueError naming it unless its shape is (N, 3); ValueError naming ``lo`` or ``hi``
    unless it is a (3,) tensor, or ``bits`` unless it is an int in 1..21 (three times 21
    bits fill an int64).

    Hints: ``torch.floor``, ``.clamp``, ``.long()``; interleave with a loop over the bits:
    ``((q >> i) & 1) << (3 * i + shift)``.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    check_morton_inputs(points, lo, hi, bits)
    # BEGIN SOLUTION (task 2)
    extent = hi - lo
    scale = torch.where(extent > 0, 2.0**bits / extent, torch.zeros_like(extent))
    q = torch.floor(((points - lo) * scale).nan_to_num(0.0)).clamp(0, 2**bits - 1).long()
    code = torch.zeros(len(points), dtype=torch.int64, device=points.device)
    for axis, shift in ((0, 2), (1, 1), (2, 0)):
        code |= _spread_bits(q[:, axis]) << shift
    return code
    # END SOLUTION


# BEGIN SOLUTION
# x -> the bits of x (up to 21) two zeros apart: bit i moves to bit 3i. Five shift-and-mask
# rounds (each moves the upper half of every group), not one op per bit: 15 kernels on a
# GPU instead of 60 per axis.
_SPREAD = (
    (32, 0x1F00000000FFFF),
    (16, 0x1F0000FF0000FF),
    (8, 0x100F00F00F00F00F),
    (4, 0x10C30C30C30C30C3),
    (2, 0x1249249249249249),
)


def _spread_bits(x: torch.Tensor) -> torch.Tensor:
    """Bit ``i`` of ``x`` (int64, ``0 <= x < 2^21``) at bit ``3i`` of the result."""
    for shift, mask in _SPREAD:
        x = (x | (x << shift)) & mask
    return x


# END SOLUTION


def build_lbvh(mesh: Mesh, leaf_size: int = 4, bits: int = 10) -> dict:
    """A linear BVH (Lauterbach et al. 2009; Karras 2012): sort by Morton code, then split.

    mesh: F triangles; leaf_size: a node with at most this many triangles is a leaf;
    bits: Morton bits per axis. Returns the BVH dict (on the mesh's device):

    =============  ==============  =========================================================
    ``kind``       ``"bvh"``
    ``lo, hi``     (M, 3) float    node bounds (contain their children and triangles)
    ``left``       (M,) int64      left child, ``-1`` for a leaf; **depth-first layout**:
                                   the left child of node ``i`` is ``i + 1``
    ``right``      (M,) int64      right child (after the whole left subtree), -1 for a leaf
    ``first``      (M,) int64      a leaf holds ``triangles[first : first + count]``
                                   (an inner node's is never read: any value)
    ``count``      (M,) int64      0 for inner nodes
    ``triangles``  (F,) int64      triangle indices in leaf order: each exactly once
    =============  ==============  =========================================================

    1. Morton codes of the triangles' bounds centres (in the centres' bounding box), and a
       stable sort by code: ``order`` (ties keep triangle order).
    2. Level by level, for every node of the level at once: a node ``[s, e)`` of the
       sorted codes with more than ``leaf_size`` triangles splits where its highest
       differing bit flips: with ``b = highest set bit of codes[s] ^ codes[e - 1]``, the
       first index whose code has bit ``b`` set, i.e. ``searchsorted(codes,
       (codes[e - 1] >> b) << b)``. Equal codes (no differing bit): split in the middle.
    3. ``TreeLevels`` (provided) records the levels and, through ``assemble_bvh``, turns
       them into the flat depth-first layout with bounds computed bottom-up.

    The tree's quality depends on the code's resolution only: a bad split wastes node
    visits, never correctness.

    Errors (the provided checks): TypeError or ValueError naming ``mesh`` (not a ``Mesh``,
    or a vertex with a NaN or inf coordinate); ValueError naming ``leaf_size`` unless it is
    an int >= 1.

    Hints: ``TreeLevels`` (provided) records the levels: ``levels.ranges(nodes)`` gives their
    ranges, ``levels.split(nodes, mid, depth)`` the children's ids, and
    ``levels.finish(order, tri_lo, tri_hi)`` assembles the dict.
    ``torch.frexp(x.double()).exponent - 1`` is the highest set bit of ``x > 0``;
    ``torch.searchsorted`` finds the first code ``>=`` a value.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    check_mesh(mesh, finite=True)
    check_leaf_size(leaf_size)
    # BEGIN SOLUTION (task 2)
    # This builds exactly that tree without a loop over levels (a level loop waits for the
    # device at every level: 30 ms for 1.1M triangles on an H200, mostly syncs), as Karras
    # 2012 does: every one of the F - 1 gaps between neighbouring sorted codes is the split
    # of exactly one node of the full tree (_lbvh_gap_ranges), each node's box is a min/max
    # over its contiguous range of sorted triangles (a sparse table, _range_boxes), and one
    # sort by (first triangle, -size) is the depth-first order. It waits for the device
    # three times, at any size.
    tri_lo, tri_hi = triangle_bounds(mesh)
    centres = (tri_lo + tri_hi) / 2
    codes = morton_codes(centres, centres.amin(dim=0), centres.amax(dim=0), bits)
    codes, order = torch.sort(codes, stable=True)
    f, device = mesh.num_faces, mesh.device
    if f <= leaf_size:  # the root is a leaf
        zero = torch.zeros(1, dtype=torch.int64, device=device)
        start, size, split = zero, zero + f, zero - 1
    else:
        differ = codes[:-1] ^ codes[1:]  # gap g lies between sorted triangles g and g + 1
        same = differ == 0
        start, end = _lbvh_gap_ranges(differ, same)
        # The tree cut at leaf_size: a node of more triangles splits at its gap, its
        # children of at most leaf_size are leaves.
        split = ((end - start) > leaf_size).nonzero()[:, 0]  # host sync 1: the node count
        s, e = start[split], end[split]
        kids_start = torch.stack((s, split + 1), 1).reshape(-1)
        kids_size = torch.stack((split + 1 - s, e - split - 1), 1).reshape(-1)
        leaf_kid = kids_size <= leaf_size
        start = torch.cat((s, kids_start))
        size = torch.cat((e - s, kids_size))
        split = torch.cat((split, torch.full_like(kids_start, -1)))
        valid = torch.cat((torch.ones_like(s, dtype=torch.bool), leaf_kid))
        # Depth-first (pre-order) = by first triangle, then larger nodes first (a node
        # precedes the nodes inside it that start where it starts); invalid entries last.
        key = torch.where(valid, start * (f + 1) + (f - size), (f + 1) ** 2)
        pick = torch.sort(key).indices[: 2 * len(s) + 1]  # inner nodes + their leaves
        start, size, split = start[pick], size[pick], split[pick]
    leaf = split < 0
    m = len(start)
    # The right child follows the left subtree: 2 L - 1 nodes for L leaves in [s, g + 1).
    starts_leaf = torch.zeros(f + 1, dtype=torch.int64, device=device)
    starts_leaf.index_add_(0, torch.where(leaf, start, f), leaf.long())
    before = torch.cumsum(starts_leaf, 0) - starts_leaf  # leaves starting before i
    node = torch.arange(m, device=device)
    gap = split.clamp(min=0)
    left_size = 2 * (before[gap + 1] - before[start]) - 1
    lo, hi = _range_boxes(tri_lo[order], tri_hi[order], start, size)
    minus = torch.full_like(start, -1)
    return {
        "kind": "bvh",
        "lo": lo,
        "hi": hi,
        "left": torch.where(leaf, minus, node + 1),
        "right": torch.where(leaf, minus, node + 1 + left_size),
        "first": torch.where(leaf, start, 0),
        "count": torch.where(leaf, size, 0),
        "triangles": order,
    }
    # END SOLUTION


# BEGIN SOLUTION
def _lbvh_gap_ranges(differ: torch.Tensor, same: torch.Tensor):
    """The node of the full LBVH (down to one triangle) that splits at each gap.

    differ: (F - 1,) int64, ``codes[g] ^ codes[g + 1]`` of the sorted codes; same: (F - 1,)
    bool, ``differ == 0``. Returns ``(start, end)``, each (F - 1,) int64: the node that
    splits between sorted triangles ``g`` and ``g + 1`` holds ``[start[g], end[g])``.

    Splitting ``[s, e)`` at its highest differing bit is splitting at the gap of the
    highest ``differ`` bit inside it (the codes are sorted, so that bit flips once there);
    a run of equal codes splits in the middle. So every gap gets a priority (lower =
    nearer the root): ``63 - highest bit``, and below all of those, a run's gaps by the
    depth of their middle split inside the run. A gap's node then reaches out to the
    nearest gap of lower priority on each side: the tree is the Cartesian tree of the
    priorities. Those nearest gaps come from a sparse table of minima (``log2 F`` levels
    of elementwise ``minimum``) walked down by binary lifting: ``2 log2 F`` gathers and
    compares for all gaps at once, no host sync.
    """
    n, device = len(differ), differ.device
    # frexp: differ = m 2^e with m in [0.5, 1), the highest set bit is e - 1 (the double
    # may round up to the next power of two above 2^53: then one less).
    high = torch.frexp(differ.double()).exponent.long() - 1
    high = high - ((differ >> high.clamp(0, 63)) == 0).long()
    prio = torch.where(same, 64 * 32 + _middle_split_depth(same), (63 - high) * 32).int()
    # Sparse table: table[k][i] = min(prio[i : i + 2^k]).
    table = [prio]
    while 2 ** len(table) <= n:
        half = 2 ** (len(table) - 1)
        last = table[-1]
        table.append(torch.minimum(last[:-half], last[half:]))
    gap = torch.arange(n, device=device)
    start, end = gap.clone(), gap + 1  # in gaps: lower-priority neighbours at start - 1, end
    for k in reversed(range(len(table))):
        width, level = 2**k, table[k]
        top = len(level) - 1
        step = start - width  # the block [start - 2^k, start) holds no lower priority?
        ok = (step >= 0) & (level[step.clamp(0, top)] >= prio)
        start = torch.where(ok, step, start)
        ok = (end + width <= n) & (level[end.clamp(max=top)] >= prio)
        end = torch.where(ok, end + width, end)
    return start, end + 1  # in triangles: gap end lies between triangles end and end + 1


def _middle_split_depth(same: torch.Tensor) -> torch.Tensor:
    """For each gap inside a run of equal codes (``same``), at which depth the run's middle
    splits (``[s, e)`` at ``(s + e) // 2``) cut there; 0 elsewhere. (F - 1,) int64."""
    n, device = len(same), same.device
    depth = torch.zeros(n, dtype=torch.int64, device=device)
    gap = same.nonzero()[:, 0]  # host sync 2 (runs are few: a short loop on few gaps)
    if len(gap) == 0:
        return depth
    # Run ids of the triangles (nondecreasing): a run's triangles share one.
    run = torch.cat((depth[:1], torch.cumsum((~same).long(), 0)))
    s = torch.searchsorted(run, run[gap])  # the run's triangles [s, e)
    e = torch.searchsorted(run, run[gap], right=True)
    d = torch.zeros_like(gap)
    found = torch.zeros_like(gap, dtype=torch.bool)
    for _ in range(n.bit_length() + 1):  # halving: at most log2(run) + 1 rounds
        mid = (s + e) // 2
        here = gap == mid - 1
        d = d + (~found & ~here).long()
        found = found | here
        go_left = gap < mid - 1
        s, e = torch.where(go_left, s, mid), torch.where(go_left, mid, e)
    return depth.index_copy_(0, gap, d)


def _range_boxes(lo: torch.Tensor, hi: torch.Tensor, start: torch.Tensor, size: torch.Tensor):
    """Bounds of contiguous ranges of boxes: ``lo[start[i] : start[i] + size[i]].amin(0)``
    and the ``amax`` of ``hi`` for every range ``i`` at once (sizes >= 1).

    A sparse table level by level, without keeping the levels: level ``k`` holds the
    minimum of every ``2^k`` consecutive boxes, and a range whose size has its highest bit
    at ``k`` is the union of two (overlapping) such blocks: its first and its last. The
    ranges are grouped by that bit (one sort, one host sync for the group sizes), so each
    range is read at its own level only: ``log2 F`` elementwise minima over the boxes plus
    two gathers per range. The result is exactly the union (min and max do not round).
    """
    f, m = len(lo), len(start)
    high = torch.frexp(size.double()).exponent.long() - 1  # sizes < 2^53: exact
    group = torch.argsort(high)
    counts = torch.bincount(high, minlength=f.bit_length()).tolist()  # host sync
    first, last = start[group], (start + size)[group]
    level = torch.cat((lo, -hi), 1)  # one minimum for both
    out = torch.empty((m, 6), dtype=lo.dtype, device=lo.device)
    done = 0
    for k, count in enumerate(counts):
        if count:
            s, e = first[done : done + count], last[done : done + count] - 2**k
            out[done : done + count] = torch.minimum(level[s], level[e])
            done += count
        if done == m:
            break
        level = torch.minimum(level[: -(2**k)], level[2**k :])
    out = torch.empty_like(out).index_copy_(0, group, out)
    return out[:, :3].contiguous(), (-out[:, 3:]).contiguous()


# END SOLUTION


def build_sah_bvh(mesh: Mesh, leaf_size: int = 4, bins: int = 16) -> dict:
    """A BVH by the binned surface area heuristic (Wald 2007), built level by level.

    mesh: F triangles; leaf_size: nodes of at most this many triangles become leaves;
    bins: candidate split positions per axis (2..1024). Returns the BVH dict of
    :func:`build_lbvh`.

    Every node of a level at once:

    1. Bin each triangle by its centroid ``c`` (the centre of its bounds): on each axis,
       ``bin = floor(bins * (c - cmin) / (cmax - cmin))`` clamped to ``[0, bins - 1]``,
       with the node's centroid bounds ``cmin, cmax`` (bin 0 where ``cmax == cmin``).
    2. Per (node, axis, bin): the number of triangles and the union of their **triangle
       bounds** (``scatter_reduce`` amin/amax), then prefix (left) and suffix (right)
       unions and counts over the bins (``cummin``/``cummax``/``cumsum``).
    3. The cost of splitting after bin ``k``: ``A(left) N(left) + A(right) N(right)``
       (``A`` = surface area); invalid where a side is empty. Take the cheapest (axis, k)
       over the node; triangles with ``bin[axis] <= k`` go left (a stable partition of
       the node's range of ``order``: ``argsort`` by (node, side), stable).
    4. No valid split (all centroids in one bin on every axis: coincident triangles):
       split the range in the middle instead, so the build always ends.

    Errors (the provided checks): TypeError or ValueError naming ``mesh`` (not a ``Mesh``,
    or a vertex with a NaN or inf coordinate); ValueError naming ``leaf_size`` unless it is
    an int >= 1, or ``bins`` unless it is an int in 2..1024.

    Hints: ``expand_ranges(start, count)`` lists each node's primitives (node, slot);
    number the (node, axis, bin) slots ``(node * 3 + axis) * bins + bin`` for ``index_add_``
    and ``scatter_reduce``; ``cummin``/``cummax``/``cumsum`` along the bins (and ``.flip`` for
    the right side); ``surface_area`` is provided. ``TreeLevels`` as in :func:`build_lbvh`.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    check_mesh(mesh, finite=True)
    check_leaf_size(leaf_size)
    check_bins(bins)
    # BEGIN SOLUTION (task 2)
    tri_lo, tri_hi = triangle_bounds(mesh)
    centres = (tri_lo + tri_hi) / 2
    device, dtype = mesh.device, tri_lo.dtype
    order = torch.arange(mesh.num_faces, device=device)
    levels = TreeLevels(mesh.num_faces, device)
    nodes = torch.zeros(1, dtype=torch.int64, device=device)
    level = 0
    while len(nodes):
        start, end = levels.ranges(nodes)
        inner = end - start > leaf_size
        nodes, start, end = nodes[inner], start[inner], end[inner]
        k = len(nodes)
        if k == 0:
            break
        count = end - start
        seg, pos = expand_ranges(start, count)  # the node of each primitive, and its slot
        prim = order[pos]
        c = centres[prim]
        inf = torch.full((k, 3), math.inf, dtype=dtype, device=device)
        cmin = inf.scatter_reduce(0, seg[:, None].expand(-1, 3), c, "amin")
        cmax = (-inf).scatter_reduce(0, seg[:, None].expand(-1, 3), c, "amax")
        extent = cmax - cmin
        scale = torch.where(extent > 0, bins / extent, torch.zeros_like(extent))
        b = torch.floor((c - cmin[seg]) * scale[seg]).long().clamp(0, bins - 1)  # (P, 3)
        slot = (seg[:, None] * 3 + torch.arange(3, device=device)) * bins + b  # (P, 3)
        slot = slot.reshape(-1)
        n_slots = k * 3 * bins
        bin_count = torch.zeros(n_slots, dtype=torch.int64, device=device)
        bin_count.index_add_(0, slot, torch.ones_like(slot))
        big = torch.full((n_slots, 3), math.inf, dtype=dtype, device=device)
        slot3 = slot[:, None].expand(-1, 3)
        bin_lo = big.scatter_reduce(0, slot3, tri_lo[prim].repeat_interleave(3, 0), "amin")
        bin_hi = (-big).scatter_reduce(0, slot3, tri_hi[prim].repeat_interleave(3, 0), "amax")
        bin_count = bin_count.reshape(k, 3, bins)
        bin_lo, bin_hi = bin_lo.reshape(k, 3, bins, 3), bin_hi.reshape(k, 3, bins, 3)
        # Left side: bins 0..j; right side: bins j+1..bins-1.
        left_lo = bin_lo.cummin(dim=2).values
        left_hi = bin_hi.cummax(dim=2).values
        left_n = bin_count.cumsum(dim=2)
        right_lo = bin_lo.flip(2).cummin(dim=2).values.flip(2)
        right_hi = bin_hi.flip(2).cummax(dim=2).values.flip(2)
        right_n = bin_count.flip(2).cumsum(dim=2).flip(2)
        n_l, n_r = left_n[..., :-1], right_n[..., 1:]
        cost = (
            surface_area(left_lo[..., :-1, :], left_hi[..., :-1, :]) * n_l
            + surface_area(right_lo[..., 1:, :], right_hi[..., 1:, :]) * n_r
        )
        cost = torch.where((n_l > 0) & (n_r > 0), cost, math.inf).reshape(k, -1)
        best_cost, best = cost.min(dim=1)
        axis, after = best // (bins - 1), best % (bins - 1)
        goes_left = b.gather(1, axis[seg, None])[:, 0] <= after[seg]
        # The fallback: no valid split, so halve the range (always progress).
        halves = (pos - start[seg]) < count[seg] // 2
        goes_left = torch.where(torch.isfinite(best_cost)[seg], goes_left, halves)
        # Stable partition inside each node's range: left triangles first.
        perm = torch.sort(seg * 2 + (~goes_left).long(), stable=True).indices
        order = order.index_copy(0, pos, prim[perm])
        n_left = torch.zeros(k, dtype=torch.int64, device=device)
        n_left.index_add_(0, seg, goes_left.long())
        nodes = levels.split(nodes, start + n_left, level)
        level += 1
    return levels.finish(order, tri_lo, tri_hi)
    # END SOLUTION
