"""Task 4: ``watertight``, the watertight test of Woop, Benthin & Wald 2013: the ray sheared
to the +z axis, 2D edge functions with a float64 fallback, no division before the hit.
"""

from __future__ import annotations

import math

import torch

from course.core.raymath import check_triangle_inputs, cross, masked_result


def watertight(origins, directions, v0, v1, v2, t_min=0.0, t_max=math.inf):
    """Woop, Benthin & Wald 2013, "Watertight Ray/Triangle Intersection" (JCGT 2(1)).

    Same arguments and results as :func:`intersect_simple`.

    1. Per ray: ``kz = argmax |d|``, ``kx = (kz + 1) % 3``, ``ky = (kx + 1) % 3`` (swapped
       when ``d[kz] < 0`` to keep the winding), shear ``Sx = d[kx] / d[kz]``,
       ``Sy = d[ky] / d[kz]``, ``Sz = 1 / d[kz]``: the ray becomes the +z axis.
    2. Per vertex ``V`` (A, B, C = v0, v1, v2, relative to the origin):
       ``Vx = V[kx] - Sx V[kz]``, ``Vy = V[ky] - Sy V[kz]``.
    3. 2D edge functions ``U = Cx By - Cy Bx``, ``V = Ax Cy - Ay Cx``, ``W = Bx Ay - By Ax``;
       where any of them rounds to exactly 0, all three are recomputed in float64 from
       the same sheared floats (products of two floats are exact there), so every sign is
       exact (the double fallback; nothing to do for float64 inputs).
    4. Miss on mixed signs, or ``det = U + V + W == 0``, or a zero-area triangle
       (``e1 x e2 == 0``: after the rounded shear it may have a sliver of noise area).
    5. ``T = U Az + V Bz + W Cz`` with ``Vz = Sz V[kz]``; compare ``T`` with ``t_min det``
       and ``t_max det`` (sign-corrected) without dividing. Only hits divide:
       ``t = T / det``, ``u = V / det``, ``v = W / det``.

    Contract: **watertight**. A shared edge gives the two triangles the same edge function
    with opposite signs, bit for bit, so a ray through a shared edge or vertex of a closed
    mesh hits at least one of the triangles sharing it. (Holds in eager PyTorch, where
    every product is rounded; a compiler that fuses ``a*b - c*d`` into an FMA breaks it.)

    Errors: as :func:`intersect_simple`, ValueError or TypeError naming ``origins``,
    ``directions``, ``v0``, ``v1``, ``v2``, ``t_min`` or ``t_max``.

    Hints: ``torch.argmax(d.abs(), dim=-1, keepdim=True)`` and
    ``torch.take_along_dim(x, k, dim=-1)`` pick per-ray components with broadcasting;
    for the fallback, index the lanes that need it with a boolean mask, compute in
    ``float64``, cast back and write them into (a full-shape copy of) U, V, W.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    t_min, t_max = check_triangle_inputs(origins, directions, v0, v1, v2, t_min, t_max)
    # BEGIN SOLUTION (task 4)
    dtype = directions.dtype
    # 1. Per-ray axes and shear.
    kz = directions.abs().argmax(dim=-1, keepdim=True)
    kx, ky = (kz + 1) % 3, (kz + 2) % 3
    dz = torch.take_along_dim(directions, kz, dim=-1)
    kx, ky = torch.where(dz < 0, ky, kx), torch.where(dz < 0, kx, ky)
    dx = torch.take_along_dim(directions, kx, dim=-1)
    dy = torch.take_along_dim(directions, ky, dim=-1)
    sx, sy, sz = (dx / dz)[..., 0], (dy / dz)[..., 0], (1 / dz)[..., 0]

    # 2. Vertices relative to the origin, sheared.
    def shear(vertex):
        rel = vertex - origins
        along = torch.take_along_dim(rel, kz, dim=-1)[..., 0]
        return (
            torch.take_along_dim(rel, kx, dim=-1)[..., 0] - sx * along,
            torch.take_along_dim(rel, ky, dim=-1)[..., 0] - sy * along,
            along,
        )

    ax, ay, az = shear(v0)
    bx, by, bz = shear(v1)
    cx, cy, cz = shear(v2)
    # 3. Edge functions, with the double fallback where one rounded to exactly zero.
    U, V, W = cx * by - cy * bx, ax * cy - ay * cx, bx * ay - by * ax
    shape = torch.broadcast_shapes(U.shape, V.shape, W.shape)
    U, V, W = U.expand(shape).clone(), V.expand(shape).clone(), W.expand(shape).clone()
    exact = (U == 0) | (V == 0) | (W == 0)
    if dtype != torch.float64 and bool(exact.any()):

        def at(x):
            return x.expand(shape)[exact].double()

        ax64, ay64, bx64, by64, cx64, cy64 = map(at, (ax, ay, bx, by, cx, cy))
        U[exact] = (cx64 * by64 - cy64 * bx64).to(dtype)
        V[exact] = (ax64 * cy64 - ay64 * cx64).to(dtype)
        W[exact] = (bx64 * ay64 - by64 * ax64).to(dtype)
    # 4. Inside test and determinant.
    negative = (U < 0) | (V < 0) | (W < 0)
    positive = (U > 0) | (V > 0) | (W > 0)
    det = U + V + W
    ray_ok = torch.isfinite(sz) & (sz != 0)
    # A zero-area triangle can get a sliver of noise area in the sheared frame.
    flat = (cross(v1 - v0, v2 - v0) == 0).all(-1)
    hit = ~(negative & positive) & (det != 0) & torch.isfinite(det) & ray_ok & ~flat
    # 5. Distance, compared without dividing: t_min <= T / det <= t_max.
    T = U * (sz * az) + V * (sz * bz) + W * (sz * cz)
    flip = det < 0
    T_abs = torch.where(flip, -T, T)
    det_abs = det.abs()
    hit &= (T_abs >= t_min * det_abs) & (T_abs <= t_max * det_abs)
    inv_det = 1 / torch.where(hit, det, torch.ones_like(det))
    return masked_result(hit, T * inv_det, V * inv_det, W * inv_det)
    # END SOLUTION
