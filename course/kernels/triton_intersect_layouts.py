"""The triangle layouts of the brute-force kernels, built once per mesh: structure-of-arrays
rows padded to ``PAD`` (Möller–Trumbore's ``v0, e1, e2``, or Woop's unit-triangle
transform). Part of :mod:`course.kernels.triton_intersect`.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

# Layouts pad the triangle count to a multiple of this, so an unrolled loop of any
# power-of-two factor up to PAD needs no bounds mask; padding triangles never hit.
PAD = 16


# --------------------------------------------------------------------------------------
# Triangle layouts (built once per mesh, like an acceleration structure)
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class TriangleLayout:
    """Per-triangle data in structure-of-arrays form, padded for the kernels.

    data: (R, M_pad) float32 contiguous, one row per coordinate (R = 9 for ``"mt"``:
        v0, e1, e2; R = 12 for ``"unit"``: the 3x4 transform row by row);
    count: M, the number of real triangles (columns ``M..M_pad-1`` are padding);
    kind: ``"mt"`` or ``"unit"``.
    """

    data: torch.Tensor
    count: int
    kind: str

    @property
    def padded_count(self) -> int:
        return self.data.shape[1]


def _check_triangles(triangles: torch.Tensor) -> torch.Tensor:
    if not isinstance(triangles, torch.Tensor):
        raise TypeError(
            f"triangles: expected a (M, 3, 3) float tensor or a TriangleLayout, "
            f"got {type(triangles).__name__}"
        )
    if triangles.ndim != 3 or triangles.shape[1:] != (3, 3):
        raise ValueError(
            f"triangles: expected shape (M, 3, 3) (corners x xyz), got {tuple(triangles.shape)}"
        )
    if not triangles.is_floating_point():
        raise TypeError(f"triangles: expected a floating-point tensor, got {triangles.dtype}")
    return triangles


def _soa(rows: torch.Tensor, count: int, kind: str, pad_row: torch.Tensor) -> TriangleLayout:
    """(M, R) per-triangle rows -> (R, M_pad) float32, padding columns set to ``pad_row``."""
    padded = max(1, -(-count // PAD)) * PAD  # never empty: the epilogue reads column 0
    data = pad_row.to(rows.device, torch.float32)[:, None].repeat(1, padded)
    data[:, :count] = rows.T.to(torch.float32)
    return TriangleLayout(data.contiguous(), count, kind)


def mt_layout(triangles: torch.Tensor) -> TriangleLayout:
    """Möller–Trumbore's precomputed layout: rows ``v0x v0y v0z e1x e1y e1z e2x e2y e2z``.

    triangles: (M, 3, 3) float, corners ``v0, v1, v2`` of each triangle. The edges are
    formed in the input dtype (so a float64 mesh gives correctly rounded fp32 edges).
    Padding triangles have zero edges: ``det = 0``, never a hit.
    """
    tri = _check_triangles(triangles)
    v0, v1, v2 = tri.unbind(1)
    rows = torch.cat([v0, v1 - v0, v2 - v0], dim=1)  # (M, 9)
    return _soa(rows, tri.shape[0], "mt", torch.zeros(9))


def unit_layout(triangles: torch.Tensor) -> TriangleLayout:
    """Woop's unit-triangle layout: the 3x4 affine map ``M`` from world to triangle space.

    triangles: (M, 3, 3) float. ``M`` sends ``v0 -> (0,0,0)``, ``v1 -> (1,0,0)``,
    ``v2 -> (0,1,0)`` and ``n = e1 x e2`` to ``(0,0,1)``, so a ray hits where its
    transformed ``z`` is 0, at barycentrics ``(u, v) = (x, y)``. It is the inverse of
    ``[e1 e2 n | v0]``, in closed form: rows ``(e2 x n, n x e1, n) / |n|^2`` (computed in
    float64, then rounded to fp32). Degenerate triangles (``|n| = 0`` or non-finite) get
    the padding transform, whose ``z`` never reaches 0 and whose ``u`` is -1: never a hit.
    """
    tri = _check_triangles(triangles).to(torch.float64)
    v0, v1, v2 = tri.unbind(1)
    e1, e2 = v1 - v0, v2 - v0
    n = torch.linalg.cross(e1, e2)
    n2 = (n * n).sum(-1, keepdim=True)
    rot = (
        torch.stack([torch.linalg.cross(e2, n), torch.linalg.cross(n, e1), n], dim=1)
        / n2[..., None]
    )
    shift = -(rot @ v0[..., None])  # (M, 3, 1): maps v0 to the origin
    rows = torch.cat([rot, shift], dim=2).reshape(-1, 12)
    never = torch.tensor([0.0, 0, 0, -1, 0, 0, 0, -1, 0, 0, 0, 1], dtype=torch.float64)
    good = (n2[:, 0] > 0) & torch.isfinite(rows).all(dim=1)
    rows = torch.where(good[:, None], rows, never.to(rows.device))
    return _soa(rows, tri.shape[0], "unit", never)
