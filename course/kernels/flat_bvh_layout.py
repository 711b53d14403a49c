"""The flat BVH's layout and its constants: ``FlatBVH`` (the arrays a walk reads) and the
build's and the walk's bounds (``BINS``, ``STACK_DEPTH``, ``MEDIAN_DEPTH``, ``EXIT_SCALE``,
``HIT_SLACK``). Part of :mod:`course.kernels.flat_bvh`, whose docstring states the contract.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from course.core.raymath import gamma

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
