"""Device functions of the fused froxel pipeline (:mod:`course.kernels.triton_froxel`): the
layout of its packed scene tables, the media at a point, the light-space lookups (shadow
maps, transmittance volumes), a segment's transmittance through the extinction volume and
the slice integral's ``phi``.

Given code, not an exercise; its accuracy contract is the pipeline's.
"""

from __future__ import annotations

import math

from course.given.lab5_checks import SCHLICK_K_MAX
from course.given.lab5_volumes import MIN_LIGHT_DISTANCE
from course.kernels.triton_intersect import _jit, tl

# Packed scene tables, one row per medium / light / light-space volume (see _plan):
# * media, float32 (MED_F): scattering 0-2, extinction 3, emissive 4-6, g weight 7, base 8,
#   falloff 9, centre 10-12, rotation rows 13-21, half size 22-24; int32 (MED_I): kind 0
#   (0 constant, 1 height, 2 box, 3 ellipsoid), texture offset 1, shape 2-4, has texture 5;
# * lights, float32 (LIGHT_F): colour 0-2, direction 3-5, position 6-8, range 9, cos(outer)
#   10, cos(inner) - cos(outer) 11; int32 (LIGHT_I): kind 0 (0 sun, 1 point, 2 spot), shadow
#   map 1, transmittance volume 2 (volume rows, -1 for none), 3: 1 where a point light's
#   path is marched through the extinction volume; float64 (LIGHT_D, culling):
#   listed everywhere 0, within the depth range 1, view-space position 2-4, range 5;
# * light-space volumes, float32 (VOL_F): origin 0-2, axes u 3-5, v 6-8, w 9-11, extent 12,
#   near 13, far - near 14, step (transmittance volume) or bias (shadow map) 15; int32
#   (VOL_I): perspective 0, data offset 1, resolution 2, depth samples 3;
# * the camera, float32 (CAM_F) and float64 (CAM_D): eye 0-2, right 3-5, up 6-8, forward
#   9-11, half width 12, half height 13 of the image plane at unit depth.
SIZES = {
    "MED_F": 32,
    "MED_I": 8,
    "LIGHT_F": 16,
    "LIGHT_I": 4,
    "LIGHT_D": 8,
    "VOL_F": 20,
    "VOL_I": 4,
    "CAM_F": 16,
    "CAM_D": 16,
}
# Kernels read module-level numbers only as constexpr.
_const = tl.constexpr if tl is not None else float
MED_F, MED_I, LIGHT_F, LIGHT_I, LIGHT_D, VOL_F, VOL_I = (
    _const(SIZES[k]) for k in ("MED_F", "MED_I", "LIGHT_F", "LIGHT_I", "LIGHT_D", "VOL_F", "VOL_I")
)
FOUR_PI = _const(4 * math.pi)
MIN_DISTANCE = _const(MIN_LIGHT_DISTANCE)
K_MAX = _const(SCHLICK_K_MAX)


# ---------------------------------------------------------------------------------------
# Device functions


@_jit
def _texture(tex_ptr, off, sx, sy, sz, cx, cy, cz, live):
    """``sample_texture`` of an (X, Y, Z) scalar texture at ``tex_ptr + off``: trilinear,
    voxel centres at index + 0.5, clamped to the border, NaN coordinates read voxel 0."""
    # ``* 1.0``, not ``.to``: Triton passes an int argument equal to 1 as a constant (a
    # Python int, which has no ``.to``); a texture or volume of one voxel per axis is valid.
    fx = sx * 1.0
    fy = sy * 1.0
    fz = sz * 1.0
    # NaN first: min/max treat NaN differently compiled and interpreted.
    ux = tl.where(cx == cx, cx, 0.0) - 0.5  # noqa: PLR0124 (NaN test)
    uy = tl.where(cy == cy, cy, 0.0) - 0.5  # noqa: PLR0124
    uz = tl.where(cz == cz, cz, 0.0) - 0.5  # noqa: PLR0124
    ux = tl.minimum(tl.maximum(ux, 0.0), fx - 1.0)
    uy = tl.minimum(tl.maximum(uy, 0.0), fy - 1.0)
    uz = tl.minimum(tl.maximum(uz, 0.0), fz - 1.0)
    x0 = tl.minimum(tl.floor(ux), tl.maximum(fx - 2.0, 0.0))
    y0 = tl.minimum(tl.floor(uy), tl.maximum(fy - 2.0, 0.0))
    z0 = tl.minimum(tl.floor(uz), tl.maximum(fz - 2.0, 0.0))
    ax = ux - x0
    ay = uy - y0
    az = uz - z0
    ix = x0.to(tl.int32)
    iy = y0.to(tl.int32)
    iz = z0.to(tl.int32)
    # Row starts of the four (x, y) corner pairs, then the eight corners in the torch
    # version's order (first axis outermost, weights (wa wb) wc) so the sums round alike.
    ptr = tex_ptr + off
    jx = tl.minimum(ix + 1, sx - 1)
    jy = tl.minimum(iy + 1, sy - 1)
    jz = tl.minimum(iz + 1, sz - 1)
    r00 = (ix * sy + iy) * sz
    r01 = (ix * sy + jy) * sz
    r10 = (jx * sy + iy) * sz
    r11 = (jx * sy + jy) * sz
    bx = 1.0 - ax
    by = 1.0 - ay
    bz = 1.0 - az
    w00 = bx * by
    w01 = bx * ay
    w10 = ax * by
    w11 = ax * ay
    total = tl.load(ptr + r00 + iz, mask=live, other=0.0) * (w00 * bz)
    total += tl.load(ptr + r00 + jz, mask=live, other=0.0) * (w00 * az)
    total += tl.load(ptr + r01 + iz, mask=live, other=0.0) * (w01 * bz)
    total += tl.load(ptr + r01 + jz, mask=live, other=0.0) * (w01 * az)
    total += tl.load(ptr + r10 + iz, mask=live, other=0.0) * (w10 * bz)
    total += tl.load(ptr + r10 + jz, mask=live, other=0.0) * (w10 * az)
    total += tl.load(ptr + r11 + iz, mask=live, other=0.0) * (w11 * bz)
    total += tl.load(ptr + r11 + jz, mask=live, other=0.0) * (w11 * az)
    return total


@_jit
def _media(px, py, pz, medf_ptr, medi_ptr, tex_ptr, n_media, live):
    """``media_at`` at points (px, py, pz): scattering RGB, extinction, emissive RGB, g."""
    s0 = tl.zeros_like(px)
    s1 = tl.zeros_like(px)
    s2 = tl.zeros_like(px)
    ext = tl.zeros_like(px)
    e0 = tl.zeros_like(px)
    e1 = tl.zeros_like(px)
    e2 = tl.zeros_like(px)
    gw = tl.zeros_like(px)
    for m in range(n_media):
        row = medf_ptr + m * MED_F
        irow = medi_ptr + m * MED_I
        kind = tl.load(irow)
        w = tl.full(px.shape, 1.0, tl.float32)
        if kind == 1:
            base = tl.load(row + 8)
            falloff = tl.load(row + 9)
            w = tl.exp(-falloff * (py - base))
        elif kind >= 2:
            rx = px - tl.load(row + 10)
            ry = py - tl.load(row + 11)
            rz = pz - tl.load(row + 12)
            lx = (
                rx * tl.load(row + 13) + ry * tl.load(row + 14) + rz * tl.load(row + 15)
            ) / tl.load(row + 22)
            ly = (
                rx * tl.load(row + 16) + ry * tl.load(row + 17) + rz * tl.load(row + 18)
            ) / tl.load(row + 23)
            lz = (
                rx * tl.load(row + 19) + ry * tl.load(row + 20) + rz * tl.load(row + 21)
            ) / tl.load(row + 24)
            if kind == 2:
                inside = (tl.abs(lx) <= 1.0) & (tl.abs(ly) <= 1.0) & (tl.abs(lz) <= 1.0)
            else:
                inside = lx * lx + ly * ly + lz * lz <= 1.0
            inside = inside & live
            w = inside.to(tl.float32)
            # Most tiles miss a local volume: its texture is read only where a lane is in.
            if (tl.load(irow + 5) != 0) & (tl.max(inside.to(tl.int32), axis=0) > 0):
                tx = tl.load(irow + 2)
                ty = tl.load(irow + 3)
                tz = tl.load(irow + 4)
                density = _texture(
                    tex_ptr,
                    tl.load(irow + 1),
                    tx,
                    ty,
                    tz,
                    (lx + 1.0) / 2.0 * tx.to(tl.float32),
                    (ly + 1.0) / 2.0 * ty.to(tl.float32),
                    (lz + 1.0) / 2.0 * tz.to(tl.float32),
                    inside,
                )
                w = w * density
        s0 += w * tl.load(row + 0)
        s1 += w * tl.load(row + 1)
        s2 += w * tl.load(row + 2)
        ext += w * tl.load(row + 3)
        e0 += w * tl.load(row + 4)
        e1 += w * tl.load(row + 5)
        e2 += w * tl.load(row + 6)
        gw += w * tl.load(row + 7)
    mean = (s0 + s1 + s2) / 3.0
    g = tl.where(mean > 0.0, gw / tl.where(mean > 0.0, mean, 1.0), 0.0)
    return s0, s1, s2, ext, e0, e1, e2, g


@_jit
def _light_frame(volf_ptr, v, px, py, pz):
    """A point's coordinates along a light volume's axes u, v, w, relative to its origin,
    and its offset from the origin (rx, ry, rz)."""
    row = volf_ptr + v * VOL_F
    rx = px - tl.load(row + 0)
    ry = py - tl.load(row + 1)
    rz = pz - tl.load(row + 2)
    cu = rx * tl.load(row + 3) + ry * tl.load(row + 4) + rz * tl.load(row + 5)
    cv = rx * tl.load(row + 6) + ry * tl.load(row + 7) + rz * tl.load(row + 8)
    cw = rx * tl.load(row + 9) + ry * tl.load(row + 10) + rz * tl.load(row + 11)
    return cu, cv, cw, rx, ry, rz


@_jit
def _shadow_lookup(volf_ptr, voli_ptr, vdata_ptr, v, px, py, pz, live):
    """``shadow_lookup``: 1 where lit (or outside the map), 0 where an occluder's depth in
    the nearest texel lies in front of the point by more than the bias."""
    cu, cv, cw, _, _, _ = _light_frame(volf_ptr, v, px, py, pz)
    row = volf_ptr + v * VOL_F
    extent = tl.load(row + 12)
    res = tl.load(voli_ptr + v * VOL_I + 2)
    off = tl.load(voli_ptr + v * VOL_I + 1)
    fres = res * 1.0
    fi = tl.floor((cu / extent + 1.0) / 2.0 * fres)
    fj = tl.floor((cv / extent + 1.0) / 2.0 * fres)
    inside = (fi >= 0.0) & (fi < fres) & (fj >= 0.0) & (fj < fres)  # False for NaN
    ii = tl.where(inside, fi, 0.0).to(tl.int32)
    jj = tl.where(inside, fj, 0.0).to(tl.int32)
    occluder = tl.load(vdata_ptr + off + ii * res + jj, mask=live & inside, other=0.0)
    lit = (inside == 0) | (cw <= occluder + tl.load(row + 15))
    return lit.to(tl.float32)


@_jit
def _transmittance_lookup(volf_ptr, voli_ptr, vdata_ptr, v, px, py, pz, live):
    """``sample_light_volume``: trilinear in the (R, R, K) volume, 1 outside it laterally
    and behind a spot light."""
    cu, cv, cw, rx, ry, rz = _light_frame(volf_ptr, v, px, py, pz)
    row = volf_ptr + v * VOL_F
    irow = voli_ptr + v * VOL_I
    extent = tl.load(row + 12)
    persp = tl.load(irow) != 0
    ahead = cw > 0.0
    scale = tl.where(ahead, cw, 1.0) * extent
    inf = float("inf")
    a = tl.where(persp, tl.where(ahead, cu / scale, inf), cu / extent)
    b = tl.where(persp, tl.where(ahead, cv / scale, inf), cv / extent)
    depth = tl.where(persp, tl.sqrt(rx * rx + ry * ry + rz * rz), cw)
    res = tl.load(irow + 2)
    k = tl.load(irow + 3)
    fres = res * 1.0
    inside = (tl.abs(a) <= 1.0) & (tl.abs(b) <= 1.0)
    ca = tl.where(inside, (a + 1.0) / 2.0 * fres, 0.0)
    cb = tl.where(inside, (b + 1.0) / 2.0 * fres, 0.0)
    cd = tl.where(
        inside, (depth - tl.load(row + 13)) / tl.load(row + 14) * (k - 1).to(tl.float32) + 0.5, 0.0
    )
    t = _texture(vdata_ptr, tl.load(irow + 1), res, res, k, ca, cb, cd, live)
    return tl.where(inside, t, 1.0)


@_jit
def _segment_transmittance(
    ext_ptr, ext_res, lo_x, lo_y, lo_z, size_x, size_y, size_z, px, py, pz, qx, qy, qz, steps, live
):
    """``light_transmittance``: exp(-optical depth) from points p to q through the
    extinction volume over the box ``lo .. lo + size`` (0 outside), midpoint rule with
    ``steps`` steps over the part of the segment inside the box (slab test)."""
    rx = qx - px
    ry = qy - py
    rz = qz - pz
    inf = float("inf")
    t0 = tl.zeros_like(px)
    t1 = tl.full(px.shape, 1.0, tl.float32)
    # Per axis the slab [lo, lo + size]: 1 / 0 gives +-inf, 0 * inf a NaN that says nothing.
    ix = 1.0 / rx
    a = (lo_x - px) * ix
    b = (lo_x + size_x - px) * ix
    nan = (a != a) | (b != b)  # noqa: PLR0124
    t0 = tl.maximum(t0, tl.where(nan, -inf, tl.minimum(a, b)))
    t1 = tl.minimum(t1, tl.where(nan, inf, tl.maximum(a, b)))
    iy = 1.0 / ry
    a = (lo_y - py) * iy
    b = (lo_y + size_y - py) * iy
    nan = (a != a) | (b != b)  # noqa: PLR0124
    t0 = tl.maximum(t0, tl.where(nan, -inf, tl.minimum(a, b)))
    t1 = tl.minimum(t1, tl.where(nan, inf, tl.maximum(a, b)))
    iz = 1.0 / rz
    a = (lo_z - pz) * iz
    b = (lo_z + size_z - pz) * iz
    nan = (a != a) | (b != b)  # noqa: PLR0124
    t0 = tl.maximum(t0, tl.where(nan, -inf, tl.minimum(a, b)))
    t1 = tl.minimum(t1, tl.where(nan, inf, tl.maximum(a, b)))
    span = t1 - t0
    span = tl.where(span > 0.0, span, 0.0)  # also NaN -> 0
    t0 = tl.where(span > 0.0, t0, 0.0)
    run = live & (span > 0.0)
    fres = ext_res * 1.0
    depth = tl.zeros_like(px)
    for m in range(steps):
        t = t0 + (m + 0.5) / steps * span
        lx = tl.div_rn(px + t * rx - lo_x, size_x)
        ly = tl.div_rn(py + t * ry - lo_y, size_y)
        lz = tl.div_rn(pz + t * rz - lo_z, size_z)
        inside = (lx >= 0.0) & (lx <= 1.0) & (ly >= 0.0) & (ly <= 1.0) & (lz >= 0.0) & (lz <= 1.0)
        sigma = _texture(
            ext_ptr, 0, ext_res, ext_res, ext_res, lx * fres, ly * fres, lz * fres, run & inside
        )
        depth += tl.where(inside, sigma, 0.0)
    length = tl.sqrt(rx * rx + ry * ry + rz * rz)
    return tl.exp(-depth * (span * length / steps))


@_jit
def _phi(tau):
    """(1 - e^-x) / x: its Taylor series below x = 0.25 (no 0 / 0, no cancellation in
    thin media; the first dropped term is below 1e-10), the ratio above."""
    series = 1.0 - tau / 2.0 * (
        1.0
        - tau
        / 3.0
        * (
            1.0
            - tau
            / 4.0
            * (1.0 - tau / 5.0 * (1.0 - tau / 6.0 * (1.0 - tau / 7.0 * (1.0 - tau / 8.0))))
        )
    )
    safe = tl.where(tau < 0.25, 1.0, tau)
    return tl.where(tau < 0.25, series, (1.0 - tl.exp(-safe)) / safe)
