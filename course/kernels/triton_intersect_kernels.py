"""The brute-force closest-hit kernels' device side: Triton itself (``_jit`` and ``tl``, or
stand-ins where Triton is missing), triangle and ray loads, the Möller–Trumbore and
unit-triangle tests and the two kernels. Part of :mod:`course.kernels.triton_intersect`,
whose docstring states the design and the contract.
"""

from __future__ import annotations

try:
    import triton
    import triton.language as tl
except ImportError as _err:  # the rest of the course works without Triton
    triton = tl = None
    _TRITON_IMPORT_ERROR: ImportError | None = _err

    def _jit(fn):
        return fn
else:
    _TRITON_IMPORT_ERROR = None
    _jit = triton.jit


# --------------------------------------------------------------------------------------
# Kernels
# --------------------------------------------------------------------------------------


@_jit
def _load_mt(ptr, stride, idx):
    """Column ``idx`` of the (9, stride) Möller–Trumbore layout: v0, e1, e2.

    ``idx`` is a scalar (one triangle, broadcast to the ray block) in the loop and a
    per-ray vector (each ray's winner: a gather) in the epilogue."""
    return (
        tl.load(ptr + 0 * stride + idx),
        tl.load(ptr + 1 * stride + idx),
        tl.load(ptr + 2 * stride + idx),
        tl.load(ptr + 3 * stride + idx),
        tl.load(ptr + 4 * stride + idx),
        tl.load(ptr + 5 * stride + idx),
        tl.load(ptr + 6 * stride + idx),
        tl.load(ptr + 7 * stride + idx),
        tl.load(ptr + 8 * stride + idx),
    )


@_jit
def _load_unit(ptr, stride, idx):
    """Column ``idx`` of the (12, stride) unit-triangle layout: the 3x4 transform by rows."""
    return (
        tl.load(ptr + 0 * stride + idx),
        tl.load(ptr + 1 * stride + idx),
        tl.load(ptr + 2 * stride + idx),
        tl.load(ptr + 3 * stride + idx),
        tl.load(ptr + 4 * stride + idx),
        tl.load(ptr + 5 * stride + idx),
        tl.load(ptr + 6 * stride + idx),
        tl.load(ptr + 7 * stride + idx),
        tl.load(ptr + 8 * stride + idx),
        tl.load(ptr + 9 * stride + idx),
        tl.load(ptr + 10 * stride + idx),
        tl.load(ptr + 11 * stride + idx),
    )


@_jit
def _mt_terms(ox, oy, oz, dx, dy, dz, v0x, v0y, v0z, e1x, e1y, e1z, e2x, e2y, e2z):
    """Möller–Trumbore by Cramer's rule: ``det`` and the numerators of ``u, v, t``.

    With ``s = o - v0``, ``p = d x e2``, ``q = s x e1``: ``det = e1 . p``,
    ``u = (s . p) / det``, ``v = (d . q) / det``, ``t = (e2 . q) / det``.
    """
    sx = ox - v0x
    sy = oy - v0y
    sz = oz - v0z
    px = dy * e2z - dz * e2y
    py = dz * e2x - dx * e2z
    pz = dx * e2y - dy * e2x
    det = e1x * px + e1y * py + e1z * pz
    u_num = sx * px + sy * py + sz * pz
    qx = sy * e1z - sz * e1y
    qy = sz * e1x - sx * e1z
    qz = sx * e1y - sy * e1x
    v_num = dx * qx + dy * qy + dz * qz
    t_num = e2x * qx + e2y * qy + e2z * qz
    return det, u_num, v_num, t_num


@_jit
def _load_rays(o_ptr, d_ptr, tmin_ptr, tmax_ptr, ray, live):
    """Rays ``ray`` (a block of indices); dead lanes get a zero direction, which misses."""
    ox = tl.load(o_ptr + ray * 3 + 0, mask=live, other=0.0)
    oy = tl.load(o_ptr + ray * 3 + 1, mask=live, other=0.0)
    oz = tl.load(o_ptr + ray * 3 + 2, mask=live, other=0.0)
    dx = tl.load(d_ptr + ray * 3 + 0, mask=live, other=0.0)
    dy = tl.load(d_ptr + ray * 3 + 1, mask=live, other=0.0)
    dz = tl.load(d_ptr + ray * 3 + 2, mask=live, other=0.0)
    t_lo = tl.load(tmin_ptr + ray, mask=live, other=0.0)
    t_hi = tl.load(tmax_ptr + ray, mask=live, other=0.0)
    return ox, oy, oz, dx, dy, dz, t_lo, t_hi


@_jit
def _store_hits(t_ptr, id_ptr, u_ptr, v_ptr, ray, live, best_t, best_id, u, v):
    """Write one block of hits; misses get t = inf, id = -1, u = v = 0 (the Hits contract)."""
    found = best_id >= 0
    tl.store(t_ptr + ray, tl.where(found, best_t, float("inf")), mask=live)
    tl.store(id_ptr + ray, best_id.to(tl.int64), mask=live)
    tl.store(u_ptr + ray, tl.where(found, u, 0.0), mask=live)
    tl.store(v_ptr + ray, tl.where(found, v, 0.0), mask=live)


@_jit
def _mt_closest_kernel(
    o_ptr,
    d_ptr,
    tmin_ptr,
    tmax_ptr,
    tri_ptr,
    t_ptr,
    id_ptr,
    u_ptr,
    v_ptr,
    n_rays,
    m_pad,
    BLOCK_RAYS: tl.constexpr,
    UNROLL: tl.constexpr,
    DIVISION_FREE: tl.constexpr,
):
    ray = tl.program_id(0) * BLOCK_RAYS + tl.arange(0, BLOCK_RAYS)
    live = ray < n_rays
    ox, oy, oz, dx, dy, dz, t_lo, t_hi = _load_rays(o_ptr, d_ptr, tmin_ptr, tmax_ptr, ray, live)

    # The best hit is the fraction best_num / best_den. The reciprocal variant divides
    # every pair and keeps best_den = 1; the division-free one keeps (t' * sign, |det|).
    best_num = t_hi
    best_den = tl.full([BLOCK_RAYS], 1.0, tl.float32)
    best_id = tl.full([BLOCK_RAYS], -1, tl.int32)
    # A while loop rather than `for base in range(0, m_pad, UNROLL)`: the same code
    # compiled (measured), and older Triton interpreters cannot range over a runtime int.
    base = 0
    while base < m_pad:
        # Unrolled so the next triangle's loads are in flight during this one's math.
        for k in tl.static_range(UNROLL):
            j = base + k
            v0x, v0y, v0z, e1x, e1y, e1z, e2x, e2y, e2z = _load_mt(tri_ptr, m_pad, j)
            det, u_num, v_num, t_num = _mt_terms(
                ox, oy, oz, dx, dy, dz, v0x, v0y, v0z, e1x, e1y, e1z, e2x, e2y, e2z
            )
            if DIVISION_FREE:
                # Fold det's sign into the numerators, then test u, v, t scaled by |det|:
                # u >= 0, v >= 0, u + v <= 1, t_min <= t < best become comparisons of
                # products. det = 0 (parallel ray, padding) fails "t_lo*0 <= t < best*0"
                # (or gives NaN = false), so it needs no test of its own.
                flip = det < 0.0
                adet = tl.abs(det)
                su = tl.where(flip, -u_num, u_num)
                sv = tl.where(flip, -v_num, v_num)
                st = tl.where(flip, -t_num, t_num)
                hit = (
                    (su >= 0.0)
                    & (sv >= 0.0)
                    & (su + sv <= adet)
                    & (st >= t_lo * adet)
                    & (st * best_den < best_num * adet)
                )
                best_num = tl.where(hit, st, best_num)
                best_den = tl.where(hit, adet, best_den)
            else:
                # det = 0 makes inv_det infinite and u or v inf or NaN, which fails
                # the interval tests: parallel rays and padding need no branch.
                inv_det = 1.0 / det
                u = u_num * inv_det
                v = v_num * inv_det
                t = t_num * inv_det
                hit = (u >= 0.0) & (v >= 0.0) & (u + v <= 1.0) & (t >= t_lo) & (t < best_num)
                best_num = tl.where(hit, t, best_num)
            best_id = tl.where(hit, j, best_id)
        base += UNROLL

    # Epilogue, once per ray: barycentrics of the winner (a gather by best_id).
    # Misses read column 0 (a layout always has one) and are overwritten by the store.
    winner = tl.maximum(best_id, 0)
    v0x, v0y, v0z, e1x, e1y, e1z, e2x, e2y, e2z = _load_mt(tri_ptr, m_pad, winner)
    det, u_num, v_num, t_num = _mt_terms(
        ox, oy, oz, dx, dy, dz, v0x, v0y, v0z, e1x, e1y, e1z, e2x, e2y, e2z
    )
    inv_det = 1.0 / det
    _store_hits(
        t_ptr,
        id_ptr,
        u_ptr,
        v_ptr,
        ray,
        live,
        best_num / best_den,
        best_id,
        u_num * inv_det,
        v_num * inv_det,
    )


@_jit
def _unit_terms(ox, oy, oz, dx, dy, dz, m00, m01, m02, m03, m10, m11, m12, m13, m20, m21, m22, m23):
    """Woop's unit-triangle test: transform the ray, intersect the plane z = 0.

    ``t = -o'z / d'z``; the hit point's ``(x, y)`` in triangle space are ``(u, v)``.
    """
    oz_ = m20 * ox + m21 * oy + m22 * oz + m23
    dz_ = m20 * dx + m21 * dy + m22 * dz
    t = -oz_ / dz_
    u = (m00 * ox + m01 * oy + m02 * oz + m03) + t * (m00 * dx + m01 * dy + m02 * dz)
    v = (m10 * ox + m11 * oy + m12 * oz + m13) + t * (m10 * dx + m11 * dy + m12 * dz)
    return t, u, v


@_jit
def _unit_closest_kernel(
    o_ptr,
    d_ptr,
    tmin_ptr,
    tmax_ptr,
    tri_ptr,
    t_ptr,
    id_ptr,
    u_ptr,
    v_ptr,
    n_rays,
    m_pad,
    BLOCK_RAYS: tl.constexpr,
    UNROLL: tl.constexpr,
):
    ray = tl.program_id(0) * BLOCK_RAYS + tl.arange(0, BLOCK_RAYS)
    live = ray < n_rays
    ox, oy, oz, dx, dy, dz, t_lo, t_hi = _load_rays(o_ptr, d_ptr, tmin_ptr, tmax_ptr, ray, live)

    best_t = t_hi
    best_id = tl.full([BLOCK_RAYS], -1, tl.int32)
    base = 0
    while base < m_pad:
        for k in tl.static_range(UNROLL):
            j = base + k
            (m00, m01, m02, m03, m10, m11, m12, m13, m20, m21, m22, m23) = _load_unit(
                tri_ptr, m_pad, j
            )
            t, u, v = _unit_terms(
                ox, oy, oz, dx, dy, dz, m00, m01, m02, m03, m10, m11, m12, m13, m20, m21, m22, m23
            )
            # A ray parallel to the plane gives t = +-inf or NaN and u, v = NaN: no hit.
            hit = (u >= 0.0) & (v >= 0.0) & (u + v <= 1.0) & (t >= t_lo) & (t < best_t)
            best_t = tl.where(hit, t, best_t)
            best_id = tl.where(hit, j, best_id)
        base += UNROLL

    winner = tl.maximum(best_id, 0)
    (m00, m01, m02, m03, m10, m11, m12, m13, m20, m21, m22, m23) = _load_unit(
        tri_ptr, m_pad, winner
    )
    t, u, v = _unit_terms(
        ox, oy, oz, dx, dy, dz, m00, m01, m02, m03, m10, m11, m12, m13, m20, m21, m22, m23
    )
    _store_hits(t_ptr, id_ptr, u_ptr, v_ptr, ray, live, best_t, best_id, u, v)
