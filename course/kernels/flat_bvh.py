"""A flat, GPU-ready BVH and a closest/any-hit tracer on top of it (given, not an exercise).

Lab 3 organises a tracer; it does not ask students to build another acceleration structure
(that was Lab 2). This module gives the kernels of ``course.kernels.triton_tracer`` and
``course.kernels.cuda_tracer`` the structure they walk, and ``course.kernels.trace`` the
walk behind every lab's fast tracer callable, ``trace_bvh``.

The build (``build_flat_bvh``) is a binned-SAH BVH made level by level in torch: every node
of one tree level is split at once (a scatter of triangle boxes into 16 bins per axis, prefix
scans for the SAH cost, one stable sort to partition), so there is no Python loop over
triangles or nodes, only over the ~20-40 levels. Lab 2's ``TreeLevels``/``assemble_bvh``
number the nodes depth first, so a node's left child is always the next node.

The flat layouts (what the GPU reads; 32 + 48 bytes per node / triangle):

* ``nodes``: (M, 8) float32, one 32-byte row per node: ``lo.xyz, hi.xyz`` then two int32
  words stored bit for bit (read them through ``nodes.view(torch.int32)``): an interior
  node has ``(right child, 0)`` (its left child is ``i + 1``), a leaf ``(first row,
  count >= 1)``. Node 0 is the root.
* ``triangles``: (F, 12) float32, three float4 rows per triangle in leaf order: ``v0.xyz``
  with the original triangle index in ``w`` (int32 bits: the lecture's "float4 triangles
  with the index in w"), ``e1 = v1 - v0`` (w = 0) and ``e2 = v2 - v0`` with ``w`` = 1 (int32
  bits) on the last row of each leaf, else 0: Möller–Trumbore's precomputed edges, formed
  in float64 and rounded once; the flag ends a leaf that is entered by its first row alone.
* ``pairs``: (K, 16) float32, one 64-byte row per *interior* node (K = M // 2, numbered in
  depth-first order, the root's row 0), holding both children's boxes (the packed node of
  the lecture: a walk reads the two boxes it tests with four float4 loads of one row, and
  never the children themselves)::

      lo_a.x hi_a.x lo_b.x hi_b.x | lo_a.y hi_a.y lo_b.y hi_b.y |
      lo_a.z hi_a.z lo_b.z hi_b.z | ref_a  ref_b  count_a count_b    (last four: int32)

  ``a`` is the left child, ``b`` the right one. A child's ``ref`` is its own row of
  ``pairs`` (>= 0) for an interior child, ``~first`` (< 0, ``first`` its first row of
  ``triangles``) for a leaf, whose ``count`` is > 0 (0 for interior children). Each axis's
  four planes share one float4, so a ray picks its near and far plane per axis by the sign
  of its direction. :attr:`FlatBVH.root_ref` says where a walk starts (after testing the
  root's box, row 0 of ``nodes``).

Traversal contract (the torch fallback here and both GPU kernels implement the same one):

* one ray at a time walks the tree with a stack, near child first: at an interior node both
  children's boxes are tested, the nearer hit child is visited next and the farther one
  pushed; the stack holds at most the tree depth (``STACK_DEPTH`` entries, checked at build);
* box test: the slab test on ``(box - o) * (1/d)``. A zero direction component gives
  ``1/d = +-inf``; a ray lying exactly in a slab plane then makes ``0 * inf = NaN``, which
  counts as "inside this slab" (near -inf, far +inf), so axis-parallel rays along a face
  are not lost. Conservative: the exit distance is widened by ``1 + 2 gamma(3)`` (Ize 2013,
  pbrt-v4), so rounding never culls a box the ray touches, and then the interval's end
  ``min(best hit so far or t_max, exit)`` by ``1 + HIT_SLACK``, so a triangle whose float32
  hit falls a little outside its box or before its entry (at a vertex or an edge on the
  box's face) is still tested;
* triangle test: Möller–Trumbore in float32 with one division, the closed interval
  ``t_min <= t <= t_max``, ``u >= 0, v >= 0, u + v <= 1``. ``det`` that rounds to 0 misses
  (degenerate, zero-area triangles and rays in a triangle's plane never hit);
* what that promises at shared edges and vertices: the walk finds what a brute-force loop
  of the same float32 Möller–Trumbore over every triangle finds (the same closest triangle
  and ``t``; a miss where it misses), the box tests never lose a hit. It is **not
  watertight**: ``u, v`` are rounded per triangle, so a ray through a shared edge or vertex
  may miss every triangle around it (rays aimed at the vertices of a rotated height-field
  mesh: 11.7% miss, at its edges' midpoints 10.9%; ``tests/test_flat_bvh.py``), and a ray
  may hit two neighbours, the nearer (then lower-index) one reported. A watertight test
  (Woop et al. 2013, pbrt-v4) is Lab 2's subject, not this tracer's;
* closest hit: the smallest t; exact ties go to the lower original triangle index, so the
  result does not depend on the traversal order;
* any hit: stops at the first triangle hit in ``[t_min, t_max]`` (which one is unspecified;
  ``triangle`` reports it, ``t`` its distance);
* rays with a NaN/inf component in the origin or direction, or a zero direction, miss
  (t = inf, triangle = -1, u = v = 0), as do rays with ``t_max < t_min``; NaN never travels
  into the outputs.

Its parts: :mod:`~course.kernels.flat_bvh_layout` (``FlatBVH`` and the constants),
:mod:`~course.kernels.flat_bvh_build` (the build) and :mod:`~course.kernels.flat_bvh_walk` (the
ray checks and the torch walk); this module keeps one BVH per scene and re-exports them.
"""

from __future__ import annotations

import weakref

import torch

from course.kernels.flat_bvh_build import _binned_splits as _binned_splits
from course.kernels.flat_bvh_build import _build as _build
from course.kernels.flat_bvh_build import _one_cpu_thread as _one_cpu_thread
from course.kernels.flat_bvh_build import _pairs as _pairs
from course.kernels.flat_bvh_build import build_flat_bvh
from course.kernels.flat_bvh_layout import BINS as BINS
from course.kernels.flat_bvh_layout import EXIT_SCALE as EXIT_SCALE
from course.kernels.flat_bvh_layout import HIT_SLACK as HIT_SLACK
from course.kernels.flat_bvh_layout import MEDIAN_DEPTH as MEDIAN_DEPTH
from course.kernels.flat_bvh_layout import STACK_DEPTH as STACK_DEPTH
from course.kernels.flat_bvh_layout import FlatBVH
from course.kernels.flat_bvh_walk import _mt as _mt
from course.kernels.flat_bvh_walk import _slab as _slab
from course.kernels.flat_bvh_walk import _walk as _walk
from course.kernels.flat_bvh_walk import check_ray_bounds as check_ray_bounds
from course.kernels.flat_bvh_walk import check_rays as check_rays
from course.kernels.flat_bvh_walk import trace_flat_torch as trace_flat_torch
from course.kernels.flat_bvh_walk import valid_rays as valid_rays

__all__ = [
    "BINS",
    "STACK_DEPTH",
    "FlatBVH",
    "build_flat_bvh",
    "flat_bvh_for",
    "trace_flat_torch",
]


# --------------------------------------------------------------------------------------
# One BVH per scene object
# --------------------------------------------------------------------------------------

_CACHE: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
_ID_CACHE: dict = {}


def flat_bvh_for(scene, leaf_size: int = 4) -> FlatBVH:
    """The FlatBVH of ``scene`` (anything with ``vertices`` (V, 3) and ``faces`` (F, 3)),
    built on first use and cached per scene object and leaf size.

    Frozen dataclasses cannot hold the BVH, so it lives in a weak dictionary keyed by the
    scene (dropped with it); objects that cannot be weakly referenced are keyed by ``id``
    and remembered alongside the object itself (so the id is never reused while cached).
    The cache trusts that a scene's tensors are not modified in place.
    """
    for name in ("vertices", "faces"):
        if not isinstance(getattr(scene, name, None), torch.Tensor):
            raise TypeError(
                f"scene: expected an object with a {name!r} tensor (a WhittedScene "
                f"or a Mesh), got {type(scene).__name__}"
            )
    try:
        per_scene = _CACHE.setdefault(scene, {})
    except TypeError:
        per_scene = _ID_CACHE.setdefault(id(scene), (scene, {}))[1]
    if leaf_size not in per_scene:
        per_scene[leaf_size] = build_flat_bvh(scene.vertices, scene.faces, leaf_size)
    return per_scene[leaf_size]
