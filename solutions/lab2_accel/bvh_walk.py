"""Task 3: BVH traversal: ``bvh_closest_hit`` (stack, near child first), ``bvh_skip_indices``
and ``bvh_closest_hit_stackless``.
"""

from __future__ import annotations

import torch

from course.core.types import Mesh, Rays
from course.given.lab2 import (
    add_count,
    as_hits,
    check_links,
    check_structure,
    check_trace_inputs,
    new_closest,
    new_counters,
    slab_test,
    test_ranges,
)
from course.given.lab2_robust import reach


def bvh_closest_hit(rays: Rays, mesh: Mesh, bvh: dict, intersect):
    """Closest hits through a BVH with a per-ray stack, near child first.

    rays: N rays; mesh: the BVH's mesh; bvh: from :func:`build_lbvh`/:func:`build_sah_bvh`
    (any valid BVH: inner nodes have two children, leaves a triangle range); intersect:
    the triangle kernel. Returns ``(Hits, counters)``: ``"steps"`` = nodes visited (popped
    and not culled), ``"tests"`` = triangle tests.

    The stack is a tensor ``(active rays, depth)`` of node ids and their entry ``t``, with
    a stack pointer per ray (a GPU thread keeps it in local memory: 64 entries). Start with
    the root on the stack where the ray hits the root's box. Each iteration, every active
    ray pops one entry:

    * culled: its entry ``t`` is beyond ``reach(best_t)``, the closest hit found since it
      was pushed, widened by its rounding (``course.given.lab2_robust``: at a vertex,
      triangles of several nodes are hit at the same ``t`` give or take rounding, and the
      lowest index must win as in brute force);
    * a leaf: test its triangles (``test_ranges``);
    * an inner node: slab-test both children against ``[t_min, min(t_max, reach(best_t))]``
      and push those hit, **far child first**, so the near one is popped next: the near
      side's hit then culls the far side.

    A ray with an empty stack is done. The stack grows (a new column) if a ray would
    overflow it; a tree of depth D never needs more than D + 1 entries.

    Errors (the provided checks): TypeError or ValueError naming ``rays`` (not ``Rays``),
    ``mesh`` (not a ``Mesh``, or another dtype or device than the rays), ``intersect`` (not
    callable) or ``bvh`` (not a BVH dict of this mesh's device and triangles: a grid passed
    as the BVH, say).

    Hints: ``slab_test``, ``expand_ranges``, ``intersect_pairs``, ``new_closest``,
    ``new_counters`` and ``as_hits`` are provided. Push with ``stack[rows, sp[rows]] = node``
    then ``sp[rows] += 1``; a node is pushed at most once per ray, so ``2 M + 1`` iterations
    bound the loop.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    check_trace_inputs(rays, mesh, intersect)
    check_structure(bvh, "bvh", "bvh", mesh)
    # BEGIN SOLUTION (task 3)
    n, device = len(rays), rays.device
    closest = new_closest(n, rays.t_min)
    counters = new_counters(n, device)
    corners = mesh.triangles()
    inv = 1 / rays.directions
    t_root, _, hit = slab_test(
        rays.origins, inv, bvh["lo"][0], bvh["hi"][0], rays.t_min, rays.t_max
    )
    ray = hit.nonzero()[:, 0]
    depth = 32
    stack = torch.zeros((len(ray), depth), dtype=torch.int64, device=device)
    stack_t = torch.zeros((len(ray), depth), dtype=rays.dtype, device=device)
    stack_t[:, 0] = t_root[ray]
    sp = torch.ones(len(ray), dtype=torch.int64, device=device)
    left, right, lo, hi = bvh["left"], bvh["right"], bvh["lo"], bvh["hi"]
    for _ in range(2 * len(left) + 1):  # each node is pushed at most once per ray
        if len(ray) == 0:
            break
        if int(sp.max()) + 2 > depth:  # room for two pushes
            stack = torch.cat((stack, torch.zeros_like(stack)), dim=1)
            stack_t = torch.cat((stack_t, torch.zeros_like(stack_t)), dim=1)
            depth *= 2
        rows = torch.arange(len(ray), device=device)
        sp = sp - 1
        node, t_node = stack[rows, sp], stack_t[rows, sp]
        live = t_node <= reach(closest["t"][ray])
        add_count(counters["steps"], ray[live])
        leaf = live & (left[node] < 0)
        test_ranges(
            intersect,
            rays,
            corners,
            ray[leaf],
            bvh["first"][node[leaf]],
            bvh["count"][node[leaf]],
            bvh["triangles"],
            closest,
            counters,
        )
        inner = (live & (left[node] >= 0)).nonzero()[:, 0]
        r = ray[inner]
        t_hi = torch.minimum(rays.t_max[r], reach(closest["t"][r]))
        a, b = left[node[inner]], right[node[inner]]
        o, iv, t_lo = rays.origins[r], inv[r], rays.t_min[r]
        ta, _, hit_a = slab_test(o, iv, lo[a], hi[a], t_lo, t_hi)
        tb, _, hit_b = slab_test(o, iv, lo[b], hi[b], t_lo, t_hi)
        a_first = ta <= tb
        near, far = torch.where(a_first, a, b), torch.where(a_first, b, a)
        t_near, t_far = torch.where(a_first, ta, tb), torch.where(a_first, tb, ta)
        hit_near, hit_far = torch.where(a_first, hit_a, hit_b), torch.where(a_first, hit_b, hit_a)
        for push, t_push, ok in ((far, t_far, hit_far), (near, t_near, hit_near)):
            rows_ok = inner[ok]
            stack[rows_ok, sp[rows_ok]] = push[ok]
            stack_t[rows_ok, sp[rows_ok]] = t_push[ok]
            sp = sp.index_add(0, rows_ok, torch.ones_like(rows_ok))
        keep = sp > 0
        ray, stack, stack_t, sp = ray[keep], stack[keep], stack_t[keep], sp[keep]
    return as_hits(closest), counters
    # END SOLUTION


def bvh_skip_indices(bvh: dict) -> torch.Tensor:
    """The stackless walk's links: where to go after node ``i``'s subtree.

    bvh: a BVH dict in the depth-first layout (left child of ``i`` is ``i + 1``).
    Returns (M,) int64: ``skip[i]`` = the first node after ``i``'s subtree in the array,
    ``M`` (past the end) for the subtrees that end the array.

    In the depth-first layout a subtree is the contiguous block ``i .. last(i)``, where
    ``last(i)`` is its rightmost leaf (follow ``right`` from ``i`` until a leaf), so
    ``skip[i] = last(i) + 1``. Compute ``last`` for all nodes at once by pointer jumping:
    start with ``last = right`` (``i`` for leaves) and repeat ``last = last[last]`` until
    nothing changes (about ``log2(depth)`` rounds): no loop over nodes.

    Hints: ``torch.where(left < 0, torch.arange(M), right)``; stop when ``torch.equal``
    says a round changed nothing.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    check_links(bvh)
    # BEGIN SOLUTION (task 3)
    left, right = bvh["left"], bvh["right"]
    last = torch.where(left < 0, torch.arange(len(left), device=left.device), right)
    for _ in range(64):  # the depth doubles per round; 2^64 is more than enough
        jumped = last[last]
        if torch.equal(jumped, last):
            break
        last = jumped
    return last + 1
    # END SOLUTION


def bvh_closest_hit_stackless(rays: Rays, mesh: Mesh, bvh: dict, intersect):
    """Closest hits through a BVH without a stack: walk the node array left to right.

    Same arguments and results as :func:`bvh_closest_hit`; ``"steps"`` counts the nodes
    whose box the ray tested. Needs the depth-first layout (``left[i] == i + 1``).

    Each ray holds one node index, starting at the root (0). Each iteration, every active
    ray slab-tests its node's box against ``[t_min, min(t_max, reach(best_t))]``:

    * hit and inner node: go to ``i + 1`` (the left child: descend);
    * hit and leaf: test its triangles, then go to ``skip[i]``;
    * miss: go to ``skip[i]`` (jump over the whole subtree).

    A ray whose next node is ``M`` is done. No stack at all (one register on a GPU), but no
    near-first order either: the walk always takes the left child first, so it visits
    more nodes than the stack traversal: the lecture's trade of memory against work.

    Hints: One ``slab_test`` per iteration on ``bvh['lo'][node]``; the next node
    is ``torch.where(hit & inner, node + 1, skip[node])``. Every step moves right, so ``M + 1``
    iterations bound the loop.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    check_trace_inputs(rays, mesh, intersect)
    check_structure(bvh, "bvh", "bvh", mesh)
    # BEGIN SOLUTION (task 3)
    n, device = len(rays), rays.device
    closest = new_closest(n, rays.t_min)
    counters = new_counters(n, device)
    corners = mesh.triangles()
    skip = bvh_skip_indices(bvh)
    m = len(skip)
    inv = 1 / rays.directions
    ray = torch.arange(n, device=device)
    node = torch.zeros(n, dtype=torch.int64, device=device)
    leaf_of = bvh["left"] < 0
    for _ in range(m + 1):  # every step moves right: at most M steps
        if len(ray) == 0:
            break
        t_hi = torch.minimum(rays.t_max[ray], reach(closest["t"][ray]))
        _, _, hit = slab_test(
            rays.origins[ray], inv[ray], bvh["lo"][node], bvh["hi"][node], rays.t_min[ray], t_hi
        )
        add_count(counters["steps"], ray)
        leaf = hit & leaf_of[node]
        test_ranges(
            intersect,
            rays,
            corners,
            ray[leaf],
            bvh["first"][node[leaf]],
            bvh["count"][node[leaf]],
            bvh["triangles"],
            closest,
            counters,
        )
        node = torch.where(hit & ~leaf_of[node], node + 1, skip[node])
        keep = node < m
        ray, node = ray[keep], node[keep]
    return as_hits(closest), counters
    # END SOLUTION
