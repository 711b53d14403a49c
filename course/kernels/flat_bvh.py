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
"""

from __future__ import annotations

import contextlib
import math
import time
import weakref
from dataclasses import dataclass

import torch

from course.core.raymath import check_mesh, gamma
from course.core.types import Hits, Mesh
from course.given.lab2_blocks import expand_ranges, surface_area
from course.given.lab2_bvh import TreeLevels

__all__ = [
    "BINS",
    "STACK_DEPTH",
    "FlatBVH",
    "build_flat_bvh",
    "flat_bvh_for",
    "trace_flat_torch",
]

BINS = 16
"""SAH bins per axis: 16 is within a few % of the full sweep's tree quality (Wald 2007)."""
STACK_DEPTH = 64
"""Traversal stack entries. Near-child-first traversal pushes at most one node per level,
so the tree depth bounds the stack; the build forces median splits below MEDIAN_DEPTH."""
MEDIAN_DEPTH = 40
"""Below this depth a node is split at its object median (halving it), whatever the SAH
says, so that even pathological inputs stay within STACK_DEPTH levels for up to 2^23
triangles."""
EXIT_SCALE = 1.0 + 2.0 * gamma(3, torch.float32)
"""Ize's factor on the slab exit distance: conservative box tests in float32 (pbrt-v4's
``1 + 2 gamma(3)``); an exit behind the origin (< 0) is scaled by ``2 - EXIT_SCALE``."""
HIT_SLACK = 2.0**-12
"""Relative slack of the box test for the triangle test's rounding: a box is culled only when
its entry lies beyond ``min(t_hi, exit) (1 + HIT_SLACK)`` (``t_hi`` the best hit so far, or
``t_max``). Möller–Trumbore in float32 accepts hits a little outside its triangle (u, v
rounded to >= 0) and rounds their ``t`` by a few ulps (more on grazing rays), so at a
vertex or an edge on a box's face its hit may lie just outside the box or just before its
entry: without the slack, 7 of 196 rays aimed at a mesh's vertices lost the nearest
triangle (the box culled once a neighbour's hit a few ulps farther was found, or missed
outright). The triangle test keeps the exact ``t_max`` and best hit, so the slack only
costs a few box visits."""


@dataclass(frozen=True, eq=False)
class FlatBVH:
    """The flat BVH of one mesh (see the module docstring for the layouts).

    nodes: (M, 8) float32; triangles: (F, 12) float32 in leaf order; order: (F,) int64, the
    original index of each row of ``triangles``; depth: the number of levels (root = 1);
    leaf_size: the build's largest leaf; build_seconds: wall time of the build; pairs:
    (K, 16) float32, the interior nodes with both children's boxes (module docstring).
    """

    nodes: torch.Tensor
    triangles: torch.Tensor
    order: torch.Tensor
    depth: int
    leaf_size: int
    build_seconds: float = 0.0
    pairs: torch.Tensor | None = None

    @property
    def root_ref(self) -> int:
        """Where a walk of ``pairs`` starts: 0 (the root's row) when the root is interior,
        ``~0 = -1`` (a leaf at row 0 of ``triangles``) when the tree is a single leaf."""
        return 0 if self.nodes.shape[0] > 1 else -1

    @property
    def pair_ints(self) -> torch.Tensor:
        """(K, 16) int32 view of ``pairs``: columns 12..15 are ``ref_a, ref_b, count_a,
        count_b``."""
        return self.pairs.view(torch.int32)

    @property
    def num_nodes(self) -> int:
        return self.nodes.shape[0]

    @property
    def nbytes(self) -> int:
        """Bytes the kernels read from: pairs (and the root's row of nodes) and triangles
        (``order`` stays on the host side of the API, the kernels find the index in ``w``)."""
        return self.pairs.numel() * 4 + 32 + self.triangles.numel() * 4

    @property
    def node_ints(self) -> torch.Tensor:
        """(M, 8) int32 view of ``nodes``: columns 6, 7 are (right, 0) or (first, count)."""
        return self.nodes.view(torch.int32)

    @property
    def triangle_ints(self) -> torch.Tensor:
        """(F, 12) int32 view of ``triangles``: column 3 is the original triangle index."""
        return self.triangles.view(torch.int32)

    def to(self, device) -> FlatBVH:
        return FlatBVH(
            self.nodes.to(device),
            self.triangles.to(device),
            self.order.to(device),
            self.depth,
            self.leaf_size,
            self.build_seconds,
            self.pairs.to(device),
        )


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


# --------------------------------------------------------------------------------------
# Tracing
# --------------------------------------------------------------------------------------


def check_rays(origins, directions, t_min, t_max):
    """Validate a tracer's ray arguments; returns float32 ``(o, d, t_lo, t_hi)``, each
    contiguous, (N, 3), (N, 3), (N,), (N,), on the origins' device.

    origins, directions: (N, 3) float tensors; t_min, t_max: numbers or (N,) tensors.
    Raises TypeError/ValueError naming the argument.
    """
    o, d, (lo, lo_value), (hi, hi_value) = check_ray_bounds(origins, directions, t_min, t_max)
    n, device = o.shape[0], o.device
    full = {"dtype": torch.float32, "device": device}
    return (
        o,
        d,
        torch.full((n,), lo_value, **full) if lo is None else lo,
        torch.full((n,), hi_value, **full) if hi is None else hi,
    )


def check_ray_bounds(origins, directions, t_min, t_max):
    """:func:`check_rays` for kernels that take numbers as numbers: returns ``(o, d,
    (t_lo, t_lo_value), (t_hi, t_hi_value))`` where a bound given as a number comes back
    as ``(None, value)`` and one given as a tensor as ``((N,) float32 tensor, 0.0)``.
    """
    for name, x in (("origins", origins), ("directions", directions)):
        if not isinstance(x, torch.Tensor):
            raise TypeError(f"{name}: expected a (N, 3) float tensor, got {type(x).__name__}")
        if not x.is_floating_point():
            raise TypeError(f"{name}: expected a floating-point tensor, got {x.dtype}")
        if x.ndim != 2 or x.shape[1] != 3:
            raise ValueError(f"{name}: expected shape (N, 3), got {tuple(x.shape)}")
    if directions.shape != origins.shape:
        raise ValueError(
            f"directions: expected shape {tuple(origins.shape)} like origins, "
            f"got {tuple(directions.shape)}"
        )
    if directions.device != origins.device:
        raise ValueError(
            f"directions: expected device {origins.device} like origins, got {directions.device}"
        )
    n, device = origins.shape[0], origins.device
    bounds = []
    for name, x in (("t_min", t_min), ("t_max", t_max)):
        if isinstance(x, torch.Tensor):
            if x.device != device:
                raise ValueError(f"{name}: expected device {device} like origins, got {x.device}")
            if x.shape not in (torch.Size([n]), torch.Size([])):
                raise ValueError(f"{name}: expected shape ({n},) or a scalar, got {tuple(x.shape)}")
            if not x.is_floating_point():
                raise TypeError(f"{name}: expected a floating-point tensor, got {x.dtype}")
            bounds.append((x.to(torch.float32).expand(n).contiguous(), 0.0))
        elif isinstance(x, (int, float)) and not isinstance(x, bool):
            bounds.append((None, float(x)))
        else:
            raise TypeError(f"{name}: expected a number or a ({n},) tensor, got {type(x).__name__}")
    return (
        origins.to(torch.float32).contiguous(),
        directions.to(torch.float32).contiguous(),
        *bounds,
    )


def valid_rays(
    o: torch.Tensor, d: torch.Tensor, t_lo: torch.Tensor, t_hi: torch.Tensor
) -> torch.Tensor:
    """(N,) bool: rays that can hit anything (finite, nonzero direction, t_min <= t_max)."""
    return (
        torch.isfinite(o).all(1)
        & torch.isfinite(d).all(1)
        & (d != 0).any(1)
        & ~torch.isnan(t_lo)
        & ~torch.isnan(t_hi)
        & (t_lo <= t_hi)
    )


def _slab(o, inv, lo, hi, t_lo, t_hi):
    """Rays (n, 3) against boxes (n, 3): the box-test contract of the module docstring."""
    t0 = (lo - o) * inv
    t1 = (hi - o) * inv
    near = torch.minimum(t0, t1).nan_to_num(nan=-math.inf, posinf=math.inf, neginf=-math.inf)
    far = torch.maximum(t0, t1).nan_to_num(nan=math.inf, posinf=math.inf, neginf=-math.inf)
    enter = torch.maximum(t_lo, near.amax(1))
    far = far.amin(1)
    # Widened away from zero (a negative distance is scaled toward it), by multiplications:
    # the exit by its own rounding, then the interval's end by the triangle test's.
    leave = torch.minimum(t_hi, far * torch.where(far >= 0, EXIT_SCALE, 2.0 - EXIT_SCALE))
    leave = leave * torch.where(leave >= 0, 1.0 + HIT_SLACK, 1.0 - HIT_SLACK)
    return enter, enter <= leave


def _mt(o, d, rows):
    """Möller–Trumbore of rays (n, 3) against rows (n, 12) of the triangle layout, float32.

    Returns (t, u, v); NaN/inf where det = 0 (comparisons with them fail: a miss)."""
    v0, e1, e2 = rows[:, 0:3], rows[:, 4:7], rows[:, 8:11]
    p = torch.linalg.cross(d, e2)
    det = (e1 * p).sum(1)
    inv = 1.0 / det
    s = o - v0
    q = torch.linalg.cross(s, e1)
    return (e2 * q).sum(1) * inv, (s * p).sum(1) * inv, (d * q).sum(1) * inv


def trace_flat_torch(
    bvh: FlatBVH, origins, directions, t_min=0.0, t_max=math.inf, any_hit: bool = False
) -> Hits:
    """The traversal contract (module docstring) in vectorised torch: the CPU fallback.

    Every ray takes one step per iteration (visit a node, or test its current leaf's
    triangles, all of them at once), working only on the rays still alive; the Python loop
    runs over traversal steps, never over rays. Same arguments as ``trace_bvh``, with
    the BVH given; returns float32 Hits on the rays' device.
    """
    o, d, t_lo, t_hi = check_rays(origins, directions, t_min, t_max)
    with _one_cpu_thread(o.device):
        return _walk(bvh.to(o.device), o, d, t_lo, t_hi, any_hit)


def _walk(bvh: FlatBVH, o, d, t_lo, t_hi, any_hit: bool) -> Hits:
    device, n = o.device, o.shape[0]
    nodes, ints, rows = bvh.nodes, bvh.node_ints, bvh.triangles
    tri_index = bvh.order
    inv = 1.0 / d
    best_t = t_hi.clone()
    best_row = torch.full((n,), -1, dtype=torch.int64, device=device)
    best_u = torch.zeros(n, device=device)
    best_v = torch.zeros(n, device=device)
    stack = torch.zeros(n, STACK_DEPTH, dtype=torch.int64, device=device)
    sp = torch.zeros(n, dtype=torch.int64, device=device)
    node = torch.zeros(n, dtype=torch.int64, device=device)
    alive = valid_rays(o, d, t_lo, t_hi)
    _, root_hit = _slab(o, inv, nodes[0, :3].expand(n, 3), nodes[0, 3:6].expand(n, 3), t_lo, t_hi)
    alive &= root_hit
    big = torch.iinfo(torch.int64).max
    lane = alive.nonzero()[:, 0]
    while len(lane):
        nd = node[lane]
        count = ints[nd, 7].long()
        leaf = count > 0
        # Leaves: all their triangles at once (count <= leaf_size), then pop.
        lf = lane[leaf]
        if len(lf):
            first = ints[nd[leaf], 6].long()
            owner, row = expand_ranges(first, count[leaf])
            ray = lf[owner]
            t, u, v = _mt(o[ray], d[ray], rows[row])
            tri = tri_index[row]
            ok = (u >= 0) & (v >= 0) & (u + v <= 1) & (t >= t_lo[ray]) & (t <= best_t[ray])
            if any_hit:
                # One hit per ray (its first pair), so t, row, u, v come from one triangle.
                pair = torch.arange(len(ray), device=device)
                first_pair = torch.full((n,), len(ray), dtype=torch.int64, device=device)
                first_pair.scatter_reduce_(0, ray[ok], pair[ok], "amin")
                win = pair[ok & (first_pair[ray] == pair)]
                wr = ray[win]
                best_t[wr], best_row[wr] = t[win], row[win]
                best_u[wr], best_v[wr] = u[win], v[win]
                alive[wr] = False
            else:
                # Per ray: the smallest t, then the lowest original index at that t, against
                # the best so far (current best_row's index competes only at equal t).
                t_ok = torch.where(ok, t, math.inf)
                nearest = best_t.clone().scatter_reduce_(0, ray, t_ok, "amin")
                cur_tri = torch.where(best_row >= 0, tri_index[best_row.clamp(min=0)], big)
                cand = ok & (t == nearest[ray])
                low = torch.where(best_t == nearest, cur_tri, big)
                low = low.scatter_reduce(0, ray[cand], tri[cand], "amin")
                win = cand & (tri == low[ray])
                wr = ray[win]
                best_t[wr], best_row[wr] = t[win], row[win]
                best_u[wr], best_v[wr] = u[win], v[win]
        # Interior nodes: test both children, go to the nearer hit, push the farther.
        inner = lane[~leaf]
        if len(inner):
            a = nd[~leaf] + 1
            b = ints[nd[~leaf], 6].long()
            oi, ii, lo_i, hi_i = o[inner], inv[inner], t_lo[inner], best_t[inner]
            ta, ha = _slab(oi, ii, nodes[a, :3], nodes[a, 3:6], lo_i, hi_i)
            tb, hb = _slab(oi, ii, nodes[b, :3], nodes[b, 3:6], lo_i, hi_i)
            b_first = hb & (~ha | (tb < ta))
            near = torch.where(b_first, b, a)
            far = torch.where(b_first, a, b)
            both = ha & hb
            push = inner[both]
            stack[push, sp[push]] = far[both]
            sp[push] += 1
            node[inner] = near
            # Neither child hit: pop, like after a leaf.
            popping = torch.cat([lf, inner[~(ha | hb)]])
        else:
            popping = lf
        popping = popping[alive[popping]]
        empty = sp[popping] == 0
        alive[popping[empty]] = False
        pop = popping[~empty]
        sp[pop] -= 1
        node[pop] = stack[pop, sp[pop]]
        lane = lane[alive[lane]]
    hit = best_row >= 0
    tri = torch.where(hit, tri_index[best_row.clamp(min=0)], -1)
    return Hits(
        t=torch.where(hit, best_t, math.inf),
        triangle=tri,
        u=torch.where(hit, best_u, 0.0),
        v=torch.where(hit, best_v, 0.0),
    )
