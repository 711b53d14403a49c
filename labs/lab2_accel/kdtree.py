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
    raise NotImplementedError("not implemented yet: build_kdtree (task 4)")


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
    raise NotImplementedError("not implemented yet: kd_pack (task 4)")


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
    raise NotImplementedError("not implemented yet: kd_unpack (task 4)")


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
    raise NotImplementedError("not implemented yet: kd_closest_hit (task 4)")
