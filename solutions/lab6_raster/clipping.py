"""Task 1: the MVP transform (``to_clip_space``), trivial reject and near-plane clipping
(``clip_triangles``), the perspective divide and the viewport (``to_screen``).
"""

from __future__ import annotations

import torch

from course.given.lab6 import check_size, check_tensor, crossing


def to_clip_space(vertices, mvp):
    """Homogeneous clip coordinates ``mvp @ [x, y, z, 1]`` of every vertex.

    vertices: (V, 3) float32/float64; mvp: (4, 4) float on the same device (e.g.
    ``camera.view_projection()``). Returns (V, 4) ``(x, y, z, w)`` in the vertices' dtype.

    Computed in float64, then rounded once: a mesh 1e5 from the origin with the camera next
    to it cancels about five digits in ``m . [x, y, z, 1]``, which float32 does not have
    (one transform per vertex, so the cost is negligible). Written out element-wise
    (``m[r, 0] * x + m[r, 1] * y + m[r, 2] * z + m[r, 3]``) rather than as a matmul, whose
    summation order differs between BLAS libraries: the CPU and CUDA agree bit for bit.

    Errors: ValueError or TypeError naming ``vertices`` (not an (N, 3) float tensor) or
    ``mvp`` (not a (4, 4) float tensor on the vertices' device).

    Hints: ``m[r, 0] * x`` with a 0-d tensor ``m[r, 0]`` broadcasts over all vertices;
    ``torch.stack(rows, dim=-1)`` assembles the four coordinates.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    check_tensor(vertices, "vertices", (None, 3))
    check_tensor(mvp, "mvp", (4, 4), like=vertices)
    # BEGIN SOLUTION (task 1)
    v = vertices.to(torch.float64)
    m = mvp.to(torch.float64)
    x, y, z = v.unbind(-1)
    rows = [m[r, 0] * x + m[r, 1] * y + m[r, 2] * z + m[r, 3] for r in range(4)]
    return torch.stack(rows, dim=-1).to(vertices.dtype)
    # END SOLUTION


def clip_triangles(clip):
    """Trivially reject triangles outside the view, clip the rest against the near plane.

    clip: (F, 3, 4) float, the clip coordinates of each triangle's corners
    (``to_clip_space(vertices)[faces]``). Returns ``(clipped, source, weights)``:
    clipped (K, 3, 4) the triangles to rasterize, same dtype; source (K,) int64 the input
    triangle each came from, in increasing order; weights (K, 3, 3): ``clipped[k, j] =
    sum_i weights[k, j, i] * clip[source[k], i]`` (the object-space barycentrics of each
    output corner in its source triangle: attributes follow with the same weights).

    1. Reject a triangle with a NaN/inf coordinate, or whose three corners all lie outside
       one of the seven half-spaces ``x < -w``, ``x > w``, ``y < -w``, ``y > w``,
       ``z < -w``, ``z > w`` and ``w <= 0`` (it cannot be visible: the half-spaces are
       those of homogeneous space, so this is exact even for corners behind the eye; the
       view volume has ``w >= |x|, |y|, |z|``, so none of it lies at ``w <= 0`` but its
       apex, the origin).
    2. With ``d = z + w`` (>= 0 on the visible side of the near plane), count the inside
       corners: 3 -> keep the triangle; 1 -> one smaller triangle; 2 -> a quad, two
       triangles. Rotate the corners (a rotation keeps the winding) so that the corner
       alone on its side comes first, call them A, B, C:
       one inside (A): ``(A, AB, AC)``; two inside (B, C): ``(BA, B, C)`` and
       ``(BA, C, CA)``, where ``XY = X + t (Y - X)``, ``t = d_X / (d_X - d_Y)``, is
       computed from the inside corner X (see ``crossing``).
    3. Drop a triangle whose clipped part has a corner at ``w <= 0`` (all its outputs). On
       the visible side of the near plane such a corner has ``z >= |w|``: it lies at or
       beyond the far plane, so no perspective camera makes one (there ``z + w >= 0``
       means ``w >= near > 0``), but degenerate clip coordinates can (a zero matrix,
       every ``w = 0``); dividing by its ``w`` would put inf/NaN or a flipped corner on
       screen. Every output corner has ``w > 0``.
    The near plane must be clipped: a corner behind the eye has ``w < 0`` and its
    perspective divide flips it to the other side of the screen. The other five planes
    need no clipping: the bounding box is clamped to the screen (a "guard band").

    Errors: ValueError or TypeError naming ``clip`` unless it is an (F, 3, 4) float tensor.

    Hints: work on all F triangles at once and select at the end. ``d.gather(1, order)``
    and ``clip.gather(1, order[..., None].expand(F, 3, 4))`` rotate the corners;
    ``torch.nn.functional.one_hot(order, 3)`` gives each rotated corner's weight row; the
    provided ``crossing`` makes the cut points. Build two candidate triangles per input,
    ``(F, 2, 3, 4)``, and a validity mask ``(F, 2)`` (the first is valid when kept, the second
    only for the quad case; neither when one of them has a corner at ``w <= 0``); indexing
    with the mask keeps the input order. ``torch.where`` picks per case; NaNs computed for
    the cases that do not use them are harmless.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    check_tensor(clip, "clip", (None, 3, 4))
    # BEGIN SOLUTION (task 1)
    F = clip.shape[0]
    x, y, z, w = clip.unbind(-1)  # (F, 3) each
    finite = torch.isfinite(clip).all(-1).all(-1)
    outside = (
        (x < -w).all(-1)
        | (x > w).all(-1)
        | (y < -w).all(-1)
        | (y > w).all(-1)
        | (z < -w).all(-1)
        | (z > w).all(-1)
        | (w <= 0).all(-1)
    )
    keep = finite & ~outside
    d = z + w
    inside = d >= 0
    n_in = inside.sum(-1)
    # The corner alone on its side: the inside one of 1, the outside one of 2 (0 when 3 in).
    odd = torch.where((n_in == 1)[:, None], inside, ~inside)
    first = odd.to(torch.int64).argmax(-1)
    order = (first[:, None] + torch.arange(3, device=clip.device)) % 3  # (F, 3)
    rot = clip.gather(1, order[..., None].expand(F, 3, 4))
    dr = d.gather(1, order)
    slots = torch.nn.functional.one_hot(order, 3).to(clip.dtype)  # row j: slot of corner j
    A, B, C = rot.unbind(1)
    dA, dB, dC = dr.unbind(1)
    wA, wB, wC = slots.unbind(1)
    AB, w_AB = crossing(A, dA, wA, B, dB, wB)
    AC, w_AC = crossing(A, dA, wA, C, dC, wC)
    BA, w_BA = crossing(B, dB, wB, A, dA, wA)
    CA, w_CA = crossing(C, dC, wC, A, dA, wA)
    one, two = (n_in == 1)[:, None, None], (n_in == 2)[:, None, None]
    first_tri = torch.where(
        one, torch.stack([A, AB, AC], 1), torch.where(two, torch.stack([BA, B, C], 1), rot)
    )
    first_w = torch.where(
        one,
        torch.stack([wA, w_AB, w_AC], 1),
        torch.where(two, torch.stack([w_BA, wB, wC], 1), slots),
    )
    tris = torch.stack([first_tri, torch.stack([BA, C, CA], 1)], 1)  # (F, 2, 3, 4)
    weights = torch.stack([first_w, torch.stack([w_BA, wC, w_CA], 1)], 1)
    valid = torch.stack([keep, keep & (n_in == 2)], 1)  # (F, 2): row-major keeps F's order
    behind = valid & ~(tris[..., 3] > 0).all(-1)  # step 3: a corner at w <= 0 (or NaN)
    valid &= ~behind.any(1, keepdim=True)
    source = torch.arange(F, device=clip.device)[:, None].expand(F, 2)
    return tris[valid], source[valid], weights[valid]
    # END SOLUTION


def to_screen(clipped, width: int, height: int):
    """Perspective divide and viewport transform.

    clipped: (K, 3, 4) clip coordinates with ``w > 0`` (the output of ``clip_triangles``;
    a corner with ``w <= 0`` or NaN ``w`` has no screen position, and raises ValueError
    naming ``clipped``: clip at the near plane first); width, height: the viewport in
    pixels. Returns (K, 3, 4) ``(x, y, z_ndc, 1/w)``, same dtype:
    ``x = (x_c / w + 1) * width / 2``, ``y = (1 - y_c / w) * height / 2`` (row 0 at the
    top, pixel centres at ``+0.5``), ``z_ndc = z_c / w`` in [-1, 1] from the near to the
    far plane, and ``1/w``, which varies linearly across the screen (task 4 needs it).

    Errors: ValueError or TypeError naming ``clipped`` (not a (K, 3, 4) float tensor, or a
    corner with w <= 0); ValueError naming ``width`` / ``height`` unless they are positive
    ints <= 32768.

    Hints: ``clipped.unbind(-1)`` gives x, y, z, w of shape (K, 3).
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    check_tensor(clipped, "clipped", (None, 3, 4))
    check_size(width, height)
    behind = ~(clipped[..., 3] > 0)
    if bool(behind.any()):
        k, corner = (int(i) for i in behind.nonzero()[0])
        raise ValueError(
            f"clipped: expected w > 0 at every corner (clip_triangles' output), "
            f"got w = {clipped[k, corner, 3].item()} at triangle {k}, corner "
            f"{corner}: the perspective divide x / w has no answer there"
        )
    # BEGIN SOLUTION (task 1)
    x, y, z, w = clipped.unbind(-1)
    sx = (x / w + 1) * (width / 2)
    sy = (1 - y / w) * (height / 2)
    return torch.stack([sx, sy, z / w, 1 / w], dim=-1)
    # END SOLUTION
