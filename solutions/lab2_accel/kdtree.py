"""Task 4: the kd-tree: ``build_kdtree`` (SAH over triangle bound planes), ``kd_pack`` /
``kd_unpack`` (the 8-byte node), ``kd_closest_hit`` (early exit).
"""

from __future__ import annotations

import math

import torch

from course.core.types import Mesh, Rays
from course.given.lab2 import (
    OFFSET_BITS,
    add_count,
    as_hits,
    check_kd_fields,
    check_kd_knobs,
    check_leaf_size,
    check_mesh,
    check_packed,
    check_structure,
    check_trace_inputs,
    new_closest,
    new_counters,
    slab_test,
    surface_area,
    test_ranges,
    triangle_bounds,
)
from course.given.lab2_robust import reach


def build_kdtree(
    mesh: Mesh,
    max_depth: int | None = None,
    leaf_size: int = 2,
    traversal_cost: float = 1.0,
    intersect_cost: float = 2.0,
    empty_bonus: float = 0.5,
) -> dict:
    """A kd-tree by the surface area heuristic over triangle bound planes, level by level.

    mesh: F triangles; max_depth: default ``round(8 + 1.3 log2 F)`` (pbrt); leaf_size: a
    node with at most this many triangles is a leaf; the SAH costs: ``traversal_cost``
    per node, ``intersect_cost`` per triangle test, and ``empty_bonus`` (0..1) off the
    cost of a split with an empty side. Returns a dict on the mesh's device:

    =============  ==============  ==========================================================
    ``kind``       ``"kd"``
    ``lo, hi``     (3,) float      the root's box (the scene bounds)
    ``split``      (M,) float      split plane position (inner nodes; 0 for leaves)
    ``axis``       (M,) int64      split axis 0/1/2, ``-1`` for a leaf
    ``left``       (M,) int64      the lower child (``x[axis] <= split``); the upper child
                                   is ``left + 1``; ``-1`` for a leaf
    ``first``      (M,) int64      a leaf holds ``triangles[first : first + count]``
                                   (an inner node's is never read: any value)
    ``count``      (M,) int64
    ``triangles``  (K,) int64      leaf lists; a triangle straddling a split is in both
                                   children, so ``K >= F``
    =============  ==============  ==========================================================

    For every node of a level at once, on each axis: the candidate planes are the bounds
    of the node's triangles clipped to the node's box, as *events* (start = lower bound,
    end = upper bound) sorted by (node, position, start before end). At event ``j`` of a
    node with ``n`` triangles, ``N_below`` = starts before ``j`` and ``N_above`` = ends
    after ``j`` (prefix sums over the sorted events), and

        cost = traversal + intersect * (1 - bonus if a side is empty) *
               (A_below N_below + A_above N_above) / A_node

    for planes strictly inside the node's box. The node splits at its cheapest event if
    that beats a leaf (``intersect * n``) and the node is not at ``max_depth``; a
    triangle goes below iff its start event comes before the split event and above iff
    its end event comes after it (so one lying in the plane goes to one side, and every
    triangle to at least one). Coincident triangles offer no plane inside the box: a leaf.

    Errors (the provided checks): TypeError or ValueError naming ``mesh`` (not a ``Mesh``,
    or a vertex with a NaN or inf coordinate); ValueError naming ``leaf_size`` unless it is
    an int >= 1, ``max_depth`` unless it is None or an int in 0..60, ``traversal_cost`` or
    ``intersect_cost`` unless it is a positive number, or ``empty_bonus`` unless it is a
    number in [0, 1].

    Hints: Keep (node, triangle) pairs. Number each axis's planes once (``torch.sort`` of
    all bounds, ``torch.searchsorted`` for each bound's number): clipping to a node's box is
    then a clamp of integers, and one integer key ``(node * planes + plane) * 2 + is_end``
    sorts a level's events. The inverse permutation (``slot[perm] = arange``) finds each
    pair's events again when you partition; ``scatter_reduce(..., 'amin')`` finds each
    node's best cost. Create children in pairs (below, above) so that ``above = left + 1``.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    check_mesh(mesh, finite=True)
    check_leaf_size(leaf_size)
    max_depth = check_kd_knobs(mesh, max_depth, traversal_cost, intersect_cost, empty_bonus)
    # BEGIN SOLUTION (task 4)
    f, device = mesh.num_faces, mesh.device
    tri_lo, tri_hi = triangle_bounds(mesh)
    dtype = tri_lo.dtype
    # Every candidate plane is a triangle bound: number each axis's bounds once (sorted,
    # equal values share a number). Node faces are such planes too, so clipping a bound to
    # a node's box is a clamp of plane numbers (exact), and one integer sort per axis and
    # level orders the events.
    planes = [torch.sort(torch.cat((tri_lo[:, a], tri_hi[:, a]))).values for a in range(3)]
    start_plane = torch.stack(
        [torch.searchsorted(planes[a], tri_lo[:, a].contiguous()) for a in range(3)], dim=1
    )
    end_plane = torch.stack(
        [torch.searchsorted(planes[a], tri_hi[:, a].contiguous()) for a in range(3)], dim=1
    )
    # Per level: the nodes' boxes (as plane numbers); per created node: split, axis, left.
    box_lo, box_hi = start_plane.amin(0, keepdim=True), end_plane.amax(0, keepdim=True)
    root = [torch.stack([planes[a][box[0, a]] for a in range(3)]) for box in (box_lo, box_hi)]
    split = [torch.zeros(1, dtype=dtype, device=device)]
    axis = [torch.full((1,), -1, dtype=torch.int64, device=device)]
    left = [torch.full((1,), -1, dtype=torch.int64, device=device)]
    leaf_node, leaf_tri = [], []
    base = 0  # id of the first node of the current level
    pair_node = torch.zeros(f, dtype=torch.int64, device=device)  # (node, triangle) pairs
    pair_tri = torch.arange(f, device=device)
    for depth in range(max_depth + 1):
        k = len(box_lo)
        seg = pair_node - base
        n = torch.bincount(seg, minlength=k)
        best_cost = torch.full((k,), math.inf, dtype=dtype, device=device)
        best_axis = torch.zeros(k, dtype=torch.int64, device=device)
        best_plane = torch.zeros(k, dtype=torch.int64, device=device)
        best_event = torch.zeros(k, dtype=torch.int64, device=device)
        slot_start, slot_end = [], []
        p = len(seg)
        if depth < max_depth and p > 0:
            for a in range(3):
                cost, plane, owner, slot = _kd_sweep(
                    a,
                    seg,
                    n,
                    box_lo,
                    box_hi,
                    start_plane[pair_tri, a],
                    end_plane[pair_tri, a],
                    planes,
                    traversal_cost,
                    intersect_cost,
                    empty_bonus,
                )
                slot_start.append(slot[:p])
                slot_end.append(slot[p:])
                axis_best = torch.full((k,), math.inf, dtype=dtype, device=device)
                axis_best = axis_best.scatter_reduce(0, owner, cost, "amin")
                events = torch.arange(2 * p, device=device)
                at_best = (cost == axis_best[owner]) & torch.isfinite(cost)
                event = torch.full((k,), 2 * p - 1, dtype=torch.int64, device=device)
                event = event.scatter_reduce(0, owner[at_best], events[at_best], "amin")
                better = axis_best < best_cost
                best_cost = torch.where(better, axis_best, best_cost)
                best_axis = torch.where(better, a, best_axis)
                best_event = torch.where(better, event, best_event)
                best_plane = torch.where(better, plane[event], best_plane)
        do_split = (n > leaf_size) & (best_cost < intersect_cost * n)
        # Leaves of this level keep their pairs.
        is_leaf_pair = ~do_split[seg]
        leaf_node.append(pair_node[is_leaf_pair])
        leaf_tri.append(pair_tri[is_leaf_pair])
        splitting = do_split.nonzero()[:, 0]
        child = torch.full((k,), -1, dtype=torch.int64, device=device)
        next_base = base + k
        child[splitting] = next_base + 2 * torch.arange(len(splitting), device=device)
        value = torch.stack([planes[a][best_plane] for a in range(3)]).gather(0, best_axis[None])[0]
        split[-1] = torch.where(do_split, value, split[-1])
        axis[-1] = torch.where(do_split, best_axis, axis[-1])
        left[-1] = child
        if len(splitting) == 0:
            break
        # Pairs of splitting nodes go below, above or both, by their events' slots.
        sel = do_split[seg]
        s, t = seg[sel], pair_tri[sel]
        ax = best_axis[s]
        r_start = torch.stack(slot_start)[:, sel].gather(0, ax[None])[0]
        r_end = torch.stack(slot_end)[:, sel].gather(0, ax[None])[0]
        below, above = r_start < best_event[s], r_end > best_event[s]
        pair_node = torch.cat((child[s[below]], child[s[above]] + 1))
        pair_tri = torch.cat((t[below], t[above]))
        # Children's boxes: the parent's, cut at the plane.
        plo, phi = box_lo[splitting], box_hi[splitting]
        rows = torch.arange(len(splitting), device=device)
        below_hi, above_lo = phi.clone(), plo.clone()
        below_hi[rows, best_axis[splitting]] = best_plane[splitting]
        above_lo[rows, best_axis[splitting]] = best_plane[splitting]
        box_lo = torch.stack((plo, above_lo), 1).reshape(-1, 3)
        box_hi = torch.stack((below_hi, phi), 1).reshape(-1, 3)
        m = 2 * len(splitting)
        split.append(torch.zeros(m, dtype=dtype, device=device))
        axis.append(torch.full((m,), -1, dtype=torch.int64, device=device))
        left.append(torch.full((m,), -1, dtype=torch.int64, device=device))
        base = next_base
    leaf_node, leaf_tri = torch.cat(leaf_node), torch.cat(leaf_tri)
    order = torch.sort(leaf_node, stable=True).indices
    num_nodes = sum(len(x) for x in axis)
    count = torch.bincount(leaf_node, minlength=num_nodes)
    return {
        "kind": "kd",
        "lo": root[0],
        "hi": root[1],
        "split": torch.cat(split),
        "axis": torch.cat(axis),
        "left": torch.cat(left),
        "first": torch.cumsum(count, 0) - count,
        "count": count,
        "triangles": leaf_tri[order],
    }
    # END SOLUTION


# BEGIN SOLUTION
def _kd_sweep(
    a, seg, n, box_lo, box_hi, starts, ends, planes, traversal_cost, intersect_cost, empty_bonus
):
    """The SAH sweep of one level on axis ``a``: the cost of splitting at every event.

    seg: (P,) the node (of this level) of each (node, triangle) pair; n: (k,) pairs per
    node; box_lo, box_hi: (k, 3) node boxes and starts, ends: (P,) the triangles' bounds on
    axis a, all as plane numbers: indices into ``planes[a]``, the sorted bound positions.
    Returns ``(cost, plane, owner, slot)``: per sorted event (2P,) its cost (inf where the
    plane is not strictly inside the box), plane number and node; and the slot (2P,) of
    each pair's start (``slot[:P]``) and end (``slot[P:]``) event in the sorted order.
    """
    p, device = len(seg), seg.device
    lo_a, hi_a = box_lo[:, a], box_hi[:, a]
    plane = torch.cat(
        (
            torch.minimum(torch.maximum(starts, lo_a[seg]), hi_a[seg]),
            torch.minimum(torch.maximum(ends, lo_a[seg]), hi_a[seg]),
        )
    )
    is_end = (torch.arange(2 * p, device=device) >= p).long()
    owner = torch.cat((seg, seg))
    # One key orders by (node, plane, start before end).
    perm = torch.sort((owner * len(planes[a]) + plane) * 2 + is_end).indices
    plane, owner, is_end = plane[perm], owner[perm], is_end[perm]
    slot = torch.empty_like(perm)
    slot[perm] = torch.arange(2 * p, device=device)
    first = (torch.cumsum(2 * n, 0) - 2 * n).clamp(max=2 * p - 1)  # each node's first event
    starts_before = torch.cumsum(1 - is_end, 0) - (1 - is_end)
    ends_before = torch.cumsum(is_end, 0) - is_end
    n_below = starts_before - starts_before[first][owner]
    n_above = n[owner] - (ends_before + is_end - ends_before[first][owner])
    # Areas: only the extent along `a` changes, 2 (e1 e2 + x (e1 + e2)).
    nlo = torch.stack([planes[b][box_lo[:, b]] for b in range(3)], dim=1)
    nhi = torch.stack([planes[b][box_hi[:, b]] for b in range(3)], dim=1)
    ext = nhi - nlo
    e1, e2 = ext[:, (a + 1) % 3], ext[:, (a + 2) % 3]
    cap, rim = (e1 * e2)[owner], (e1 + e2)[owner]
    value = planes[a][plane]
    area_below = 2 * (cap + (value - nlo[owner, a]) * rim)
    area_above = 2 * (cap + (nhi[owner, a] - value) * rim)
    empty = (n_below == 0) | (n_above == 0)
    cost = (
        traversal_cost
        + intersect_cost
        * (1 - empty_bonus * empty)
        * (area_below * n_below + area_above * n_above)
        / surface_area(nlo, nhi)[owner]
    )
    inside = (plane > lo_a[owner]) & (plane < hi_a[owner])
    return torch.where(inside, cost, math.inf), plane, owner, slot


# END SOLUTION


def kd_pack(tree: dict) -> torch.Tensor:
    """The lecture's 8-byte kd node: ``split float + leftOffset:29 + splitAxis:2 + leaf:1``.

    tree: a kd dict (:func:`build_kdtree`). Returns (M, 2) int32, two 32-bit words a node:

    * word 0: inner node: the bits of ``split`` as float32 (``Tensor.view(torch.int32)``);
      leaf: its triangle ``count``.
    * word 1, as C bit-fields are laid out on a little-endian GPU (first field lowest):
      bits 0-28 ``leftOffset``, bits 29-30 ``splitAxis``, bit 31 ``leaf``. Inner node:
      ``leftOffset = left - i`` (the lower child is that far ahead, the upper one right
      after it), ``splitAxis = axis``. Leaf: ``leftOffset = first`` (where its triangle
      list starts), ``splitAxis = 0``, ``leaf = 1``: the sign bit, so ``word1 < 0`` is the
      leaf test.

    Compute in int64 and wrap to int32 (``leaf << 31`` is ``2^31``, one more than int32
    holds).

    Errors: TypeError naming ``tree`` unless it is a dict holding the tensors read here
    (the provided check); ValueError naming ``tree`` if an offset needs more than 29 bits or
    a count more than 31 (yours to raise: the node has no room for it).

    Hints: ``tree['split'].to(torch.float32).contiguous().view(torch.int32)``; build word 1 in
    int64 and wrap values ``>= 2**31`` by subtracting ``2**32`` before ``.to(torch.int32)``.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    check_kd_fields(tree)
    # BEGIN SOLUTION (task 4)
    m = len(tree["axis"])
    leaf = tree["axis"] < 0
    index = torch.arange(m, device=tree["axis"].device)
    offset = torch.where(leaf, tree["first"], tree["left"] - index)
    if m and (int(offset.min()) < 0 or int(offset.max()) >= 2**OFFSET_BITS):
        raise ValueError(
            f"tree: a leftOffset of {int(offset.max())} does not fit in "
            f"{OFFSET_BITS} bits (or is negative)"
        )
    if m and int(tree["count"].max()) >= 2**31:
        raise ValueError("tree: a leaf count does not fit in 31 bits")
    split_bits = tree["split"].to(torch.float32).contiguous().view(torch.int32).long()
    word0 = torch.where(leaf, tree["count"], split_bits)
    word1 = offset | (tree["axis"].clamp(min=0) << OFFSET_BITS) | (leaf.long() << 31)
    packed = torch.stack((word0, word1), dim=1)
    return torch.where(packed >= 2**31, packed - 2**32, packed).to(torch.int32)
    # END SOLUTION


def kd_unpack(packed: torch.Tensor) -> dict:
    """The fields of packed kd nodes (the inverse of :func:`kd_pack`).

    packed: (M, 2) int32. Returns a dict of (M,) tensors: ``split`` float32 (0 for
    leaves), ``axis`` int64 (-1 for leaves), ``left`` int64 (absolute index, -1 for
    leaves), ``first`` and ``count`` int64 (0 for inner nodes). Mask before shifting:
    ``>>`` on a negative int32 (a leaf's word) copies the sign bit.

    Hints: Work on ``packed[:, 1].long() & 0xFFFFFFFF``; ``packed[:, 0].contiguous()
    .view(torch.float32)`` reinterprets the split's bits.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    check_packed(packed)
    # BEGIN SOLUTION (task 4)
    word0, word1 = packed[:, 0], packed[:, 1].long() & 0xFFFFFFFF
    leaf = (word1 >> 31) == 1
    offset = word1 & (2**OFFSET_BITS - 1)
    axis = (word1 >> OFFSET_BITS) & 3
    index = torch.arange(len(packed), device=packed.device)
    zero = torch.zeros_like(offset)
    return {
        "split": torch.where(leaf, 0.0, word0.contiguous().view(torch.float32)),
        "axis": torch.where(leaf, -1, axis),
        "left": torch.where(leaf, -1, index + offset),
        "first": torch.where(leaf, offset, zero),
        "count": torch.where(leaf, word0.long(), zero),
    }
    # END SOLUTION


def kd_closest_hit(rays: Rays, mesh: Mesh, tree: dict, intersect):
    """Closest hits through a kd-tree: stack traversal with the early exit.

    rays: N rays; mesh: the tree's mesh; tree: from :func:`build_kdtree`; intersect: the
    triangle kernel. Returns ``(Hits, counters)``: ``"steps"`` = nodes visited,
    ``"tests"`` = triangle tests.

    Per ray: the current node with the ray's interval ``[t_near, t_far]`` inside it
    (initially the root box clipped to ``[t_min, t_max]``), and a stack of (node, t_near,
    t_far). Each iteration, every active ray handles its node:

    * inner node: ``t_split = (split - o[axis]) / d[axis]``; the near child is the lower
      one if ``o[axis] < split`` (or ``== split`` with ``d[axis] <= 0``). If ``t_split >
      reach(t_far)`` or ``t_split <= 0``: only the near child; if ``reach(t_split) <
      t_near``: only the far one; else push (far, t_split, t_far) and go to (near, t_near,
      t_split). ``reach`` (``course.given.lab2_robust``) keeps a child the ray crosses at a
      vertex in the plane, where the two ``t`` agree only up to rounding. For
      ``d[axis] = +-0``, ``t_split = +-inf`` selects the near child by these same rules; a
      ray lying *in* the plane (``0 * inf = NaN``) visits both children, whole interval,
      and exits early no more: its near child's interval is then the whole interval, so a
      hit found there says nothing of a nearer triangle that only the far child lists.
    * leaf: test its triangles. **Early exit** only if the closest hit so far lies inside
      this leaf's interval, rounding included: ``reach(best_t) < t_far``. A vertex in the
      split plane is hit from both leaves at the same ``t`` give or take rounding, and
      brute force picks the lowest index among equal ``t``. A triangle straddling the
      split sits in several leaves and can be hit beyond this leaf, where a nearer
      triangle of a later leaf may still be waiting. Otherwise pop the next (node,
      interval); an empty stack ends the ray.

    Hints: ``rays.origins[r].gather(1, axis[:, None])`` picks each ray's component on
    its node's axis. Handle the leaves first (test, then exit or pop), then the inner nodes
    (descend, maybe push); ``2 M + 1`` iterations bound the loop.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    check_trace_inputs(rays, mesh, intersect)
    check_structure(tree, "kd", "tree", mesh)
    # BEGIN SOLUTION (task 4)
    n, device, dtype = len(rays), rays.device, rays.dtype
    closest = new_closest(n, rays.t_min)
    counters = new_counters(n, device)
    corners = mesh.triangles()
    inv = 1 / rays.directions
    t_enter, t_exit, hit = slab_test(
        rays.origins, inv, tree["lo"], tree["hi"], rays.t_min, rays.t_max
    )
    ray = hit.nonzero()[:, 0]
    node = torch.zeros(len(ray), dtype=torch.int64, device=device)
    t_near, t_far = t_enter[ray], t_exit[ray]
    depth = 32
    stack = torch.zeros((len(ray), depth), dtype=torch.int64, device=device)
    stack_near = torch.zeros((len(ray), depth), dtype=dtype, device=device)
    stack_far = torch.zeros((len(ray), depth), dtype=dtype, device=device)
    sp = torch.zeros(len(ray), dtype=torch.int64, device=device)
    no_exit = torch.zeros(len(ray), dtype=torch.bool, device=device)  # went along a plane
    axis_of, left_of, split_of = tree["axis"], tree["left"], tree["split"]
    for _ in range(2 * len(axis_of) + 1):
        if len(ray) == 0:
            break
        if int(sp.max()) + 1 > depth:
            stack, stack_near, stack_far = (
                torch.cat((x, torch.zeros_like(x)), dim=1) for x in (stack, stack_near, stack_far)
            )
            depth *= 2
        add_count(counters["steps"], ray)
        axis = axis_of[node]
        leaf = axis < 0
        done = torch.zeros_like(leaf)
        # Leaves: test, then exit early or pop.
        test_ranges(
            intersect,
            rays,
            corners,
            ray[leaf],
            tree["first"][node[leaf]],
            tree["count"][node[leaf]],
            tree["triangles"],
            closest,
            counters,
        )
        exit_early = leaf & ~no_exit & (reach(closest["t"][ray]) < t_far)
        pop = leaf & ~exit_early & (sp > 0)
        done |= leaf & ~pop
        rows = pop.nonzero()[:, 0]
        sp = sp - pop.long()
        node = node.index_put((rows,), stack[rows, sp[rows]])
        t_near = t_near.index_put((rows,), stack_near[rows, sp[rows]])
        t_far = t_far.index_put((rows,), stack_far[rows, sp[rows]])
        # Inner nodes: descend to the near child, maybe push the far one.
        inner = (~leaf).nonzero()[:, 0]
        a = axis[inner]
        r = ray[inner]
        o_a = rays.origins[r].gather(1, a[:, None])[:, 0]
        d_a = rays.directions[r].gather(1, a[:, None])[:, 0]
        inv_a = inv[r].gather(1, a[:, None])[:, 0]
        plane = split_of[node[inner]]
        t_split = (plane - o_a) * inv_a
        lower = left_of[node[inner]]
        below_first = (o_a < plane) | ((o_a == plane) & (d_a <= 0))
        near = torch.where(below_first, lower, lower + 1)
        far = torch.where(below_first, lower + 1, lower)
        tn, tf = t_near[inner], t_far[inner]
        in_plane = torch.isnan(t_split)
        near_only = ~in_plane & ((t_split > reach(tf)) | (t_split <= 0))
        far_only = ~in_plane & ~near_only & (reach(t_split) < tn)
        both = ~near_only & ~far_only
        push = inner[both]
        stack[push, sp[push]] = far[both]
        stack_near[push, sp[push]] = torch.where(in_plane, tn, t_split)[both]
        stack_far[push, sp[push]] = tf[both]
        sp = sp.index_add(0, push, torch.ones_like(push))
        no_exit[inner] |= in_plane
        node[inner] = torch.where(far_only, far, near)
        t_far[inner] = torch.where(both & ~in_plane, t_split, tf)
        keep = ~done
        ray, node, t_near, t_far, sp = ray[keep], node[keep], t_near[keep], t_far[keep], sp[keep]
        no_exit = no_exit[keep]
        stack, stack_near, stack_far = stack[keep], stack_near[keep], stack_far[keep]
    return as_hits(closest), counters
    # END SOLUTION
