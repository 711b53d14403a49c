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
    raise NotImplementedError("not implemented yet: bvh_closest_hit (task 3)")


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
    raise NotImplementedError("not implemented yet: bvh_skip_indices (task 3)")


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
    raise NotImplementedError("not implemented yet: bvh_closest_hit_stackless (task 3)")
