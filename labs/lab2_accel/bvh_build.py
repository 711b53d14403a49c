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
    raise NotImplementedError("not implemented yet: morton_codes (task 2)")


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
    raise NotImplementedError("not implemented yet: build_lbvh (task 2)")


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
    raise NotImplementedError("not implemented yet: build_sah_bvh (task 2)")
