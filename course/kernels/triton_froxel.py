"""Lab 5's froxel pipeline as fused Triton kernels: one frame without a Python loop over lights.

Lab 5 writes the Frostbite pipeline as batched torch code, stage by stage: the V-buffer,
then one pass over the lit froxels per light (a dozen tensor operations each), the
prefix sums of the integration, the trilinear application. Every stage is a round trip
of a 2-million-froxel volume through DRAM, and the reference reads tensor sizes back to
the host several times per frame. The talk's GPU version does the opposite: one thread
per froxel evaluates the media and all the lights of its tile in registers, and the
integration walks each froxel column in the same program. This module is that design,
given (not an exercise) so the lab can measure the gap on the same numbers.

Kernels of one frame (no host synchronisation between them):

1. ``_shadow_map_kernel``: the sun's shadow map (a ray per texel against the occluder
   boxes), for every sun with ``shadows`` when the scene has occluders;
2. ``_extinction_kernel``: the extinction volume over ``volume_bounds(scene, grid)`` (the
   media's bounds in view, reaching the point and spot lights that light it; the media at
   its voxel centres), at ``volume_resolution`` or the one chosen from the media's size;
3. ``_transmittance_kernel``: every sun's and spot light's transmittance volume, a texel
   per lane marching its ray through the extinction volume (4 depth samples per texel
   of resolution, as the lab's ``light_froxels``);
4. ``_froxel_kernel``: a program per tile column (all its slices in one block of lanes):
   the media at each froxel's sample point (constant fog, height fog, fog volumes with
   their density textures), the light culling of the tile (float64, as the lab's
   ``cull_lights``), the lighting (phase function, shadow map, transmittance volume),
   with each point light's path to the froxel marched through the extinction volume
   (``light_steps`` midpoint steps over its part inside the volume's box, as the lab's
   ``light_transmittance``; lanes beyond the light's range skip it),
   and the front-to-back integration of the column as prefix sums over the block
   (``tl.cumsum``), written as the volume of nodes ``(L, T)`` that the application reads;
5. ``_apply_kernel``: a lane per pixel, the trilinear lookup at its view depth.

What it computes is Lab 5's ``render_froxels`` for the non-temporal path (jitter 0.5),
with every numerical convention of the lab (``solutions/lab5_froxel.py`` states them):
exponential slices, samples at the tile centre and the middle depth of the slice,
``MIN_LIGHT_DISTANCE`` and the ``range`` cut-off of point and spot lights, the spot's
smoothstep, the shadow map's nearest-texel test with its bias, trilinear transmittance
volumes (1 outside them), the energy-conserving slice integral ``S D phi(sigma_t D)``
with ``phi(x) = (1 - e^-x) / x`` by its series for small ``x`` (finite at 0, no NaN for
huge ``x``), and the application's clamping (depths beyond ``far`` and the sky read the
last slice, depths before ``near`` get no fog). Only tiles with media are lit, only
froxels that scatter, each light only in the tiles of its list.

Accuracy: float32 throughout (float64 images are computed in float32 and returned as
float64); the compiled kernels use the GPU's fast ``exp``/``log``/division, so values
agree with the torch pipeline in float32 to a few 1e-6 relative. A sample point within
rounding of a discontinuity (the edge of a fog volume, a shadow-map texel, a light's
range) may fall on the other side of it; ``tests/meta/test_triton_froxel.py`` bounds how
often.

Speed (``bench/lab5_froxel.py --device cuda --gpu-target``, the talk's 1080p frame: 240 x 135
x 64 froxels, sun with shadow map, 14 point lights, 6 textured fog volumes, height fog):
0.57 ms per frame on an H100 against 71 ms for the torch pipeline, max difference 8e-6 of
the largest radiance; the froxel kernel takes 0.41 ms of it, the application and the
transmittance volume 0.03 ms each (``bench/results/nvidia-h100-80gb-hbm3/lab5/``). Those
figures predate the point lights' transmittance (8 steps through the extinction volume
per froxel and light within range) and the volume chosen from the media's size (64^3
here, with 256 depth samples for the sun): the frame's budget is 2 ms; the bench's CUDA
run measures it.

Runs compiled on CUDA, or in Triton's CPU interpreter when ``TRITON_INTERPRET=1`` is set
before ``triton`` is first imported (small frames only). Importing this module without
Triton works; calling it then raises ImportError.
"""

from __future__ import annotations

import math
import weakref

import torch

from course.given.lab5 import (
    INTEGRATIONS,
    LIGHT_STEPS,
    MIN_LIGHT_DISTANCE,
    PHASES,
    SCHLICK_K_MAX,
    SLICES,
    ConstantFog,
    DirectionalLight,
    HeightFog,
    PointLight,
    SpotLight,
    auto_volume_resolution,
    check_choice,
    check_scene,
    check_volume,
    check_volume_resolution,
    frustum_bounds,
    light_frame,
    scene_grid,
    slice_offset,
    volume_bounds,
)
from course.kernels.triton_intersect import (
    _ieee_quiet,
    _jit,
    _require_triton,
    interpreting,
    tl,
    triton,
)

__all__ = ["render_froxels_fused"]

BLOCK_PIXELS = 256  # lanes per program of the application
BLOCK_TEXELS = 128  # lanes per program of the light-space textures and the extinction volume
# Interpreted, every program costs milliseconds of Python: far fewer, larger blocks.
BLOCK_TEXELS_INTERPRETED = 8192

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
SIZES = {"MED_F": 32, "MED_I": 8, "LIGHT_F": 16, "LIGHT_I": 4, "LIGHT_D": 8, "VOL_F": 20,
         "VOL_I": 4, "CAM_F": 16, "CAM_D": 16}
# Kernels read module-level numbers only as constexpr.
_const = tl.constexpr if tl is not None else float
MED_F, MED_I, LIGHT_F, LIGHT_I, LIGHT_D, VOL_F, VOL_I = (
    _const(SIZES[k]) for k in ("MED_F", "MED_I", "LIGHT_F", "LIGHT_I", "LIGHT_D", "VOL_F",
                               "VOL_I"))
FOUR_PI = _const(4 * math.pi)
MIN_DISTANCE = _const(MIN_LIGHT_DISTANCE)
K_MAX = _const(SCHLICK_K_MAX)


# ---------------------------------------------------------------------------------------
# Device functions


@_jit
def _texture(tex_ptr, off, sx, sy, sz, cx, cy, cz, live):
    """``sample_texture`` of an (X, Y, Z) scalar texture at ``tex_ptr + off``: trilinear,
    voxel centres at index + 0.5, clamped to the border, NaN coordinates read voxel 0."""
    fx = sx.to(tl.float32)
    fy = sy.to(tl.float32)
    fz = sz.to(tl.float32)
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
            lx = (rx * tl.load(row + 13) + ry * tl.load(row + 14) + rz * tl.load(row + 15)) \
                / tl.load(row + 22)
            ly = (rx * tl.load(row + 16) + ry * tl.load(row + 17) + rz * tl.load(row + 18)) \
                / tl.load(row + 23)
            lz = (rx * tl.load(row + 19) + ry * tl.load(row + 20) + rz * tl.load(row + 21)) \
                / tl.load(row + 24)
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
                density = _texture(tex_ptr, tl.load(irow + 1), tx, ty, tz,
                                   (lx + 1.0) / 2.0 * tx.to(tl.float32),
                                   (ly + 1.0) / 2.0 * ty.to(tl.float32),
                                   (lz + 1.0) / 2.0 * tz.to(tl.float32), inside)
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
    fres = res.to(tl.float32)
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
    fres = res.to(tl.float32)
    inside = (tl.abs(a) <= 1.0) & (tl.abs(b) <= 1.0)
    ca = tl.where(inside, (a + 1.0) / 2.0 * fres, 0.0)
    cb = tl.where(inside, (b + 1.0) / 2.0 * fres, 0.0)
    cd = tl.where(inside, (depth - tl.load(row + 13)) / tl.load(row + 14)
                  * (k - 1).to(tl.float32) + 0.5, 0.0)
    t = _texture(vdata_ptr, tl.load(irow + 1), res, res, k, ca, cb, cd, live)
    return tl.where(inside, t, 1.0)


@_jit
def _segment_transmittance(ext_ptr, ext_res, lo_x, lo_y, lo_z, size_x, size_y, size_z,
                           px, py, pz, qx, qy, qz, steps, live):
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
    fres = ext_res.to(tl.float32)
    depth = tl.zeros_like(px)
    for m in range(steps):
        t = t0 + (m + 0.5) / steps * span
        lx = tl.div_rn(px + t * rx - lo_x, size_x)
        ly = tl.div_rn(py + t * ry - lo_y, size_y)
        lz = tl.div_rn(pz + t * rz - lo_z, size_z)
        inside = (lx >= 0.0) & (lx <= 1.0) & (ly >= 0.0) & (ly <= 1.0) & (lz >= 0.0) \
            & (lz <= 1.0)
        sigma = _texture(ext_ptr, 0, ext_res, ext_res, ext_res, lx * fres, ly * fres,
                         lz * fres, run & inside)
        depth += tl.where(inside, sigma, 0.0)
    length = tl.sqrt(rx * rx + ry * ry + rz * rz)
    return tl.exp(-depth * (span * length / steps))


@_jit
def _phi(tau):
    """(1 - e^-x) / x: its Taylor series below x = 0.25 (no 0 / 0, no cancellation in
    thin media; the first dropped term is below 1e-10), the ratio above."""
    series = 1.0 - tau / 2.0 * (1.0 - tau / 3.0 * (1.0 - tau / 4.0 * (1.0 - tau / 5.0 * (
        1.0 - tau / 6.0 * (1.0 - tau / 7.0 * (1.0 - tau / 8.0))))))
    safe = tl.where(tau < 0.25, 1.0, tau)
    return tl.where(tau < 0.25, series, (1.0 - tl.exp(-safe)) / safe)


# ---------------------------------------------------------------------------------------
# Kernels


@_jit
def _shadow_map_kernel(volf_ptr, voli_ptr, vdata_ptr, boxes_ptr, n_boxes,
                       BLOCK: tl.constexpr):
    """``build_shadow_map``: texel (i, j) of volume row ``program_id(0)`` traces one ray
    from its centre along w against every occluder box; depth of the first hit or inf."""
    v = tl.program_id(0)
    row = volf_ptr + v * VOL_F
    res = tl.load(voli_ptr + v * VOL_I + 2)
    off = tl.load(voli_ptr + v * VOL_I + 1)
    t = tl.program_id(1) * BLOCK + tl.arange(0, BLOCK)
    live = t < res * res
    a = tl.div_rn((t // res).to(tl.float32) + 0.5, res.to(tl.float32)) * 2.0 - 1.0
    b = tl.div_rn((t % res).to(tl.float32) + 0.5, res.to(tl.float32)) * 2.0 - 1.0
    extent = tl.load(row + 12)
    sx = tl.load(row + 0) + extent * (a * tl.load(row + 3) + b * tl.load(row + 6))
    sy = tl.load(row + 1) + extent * (a * tl.load(row + 4) + b * tl.load(row + 7))
    sz = tl.load(row + 2) + extent * (a * tl.load(row + 5) + b * tl.load(row + 8))
    ix = tl.div_rn(1.0, tl.load(row + 9))
    iy = tl.div_rn(1.0, tl.load(row + 10))
    iz = tl.div_rn(1.0, tl.load(row + 11))
    inf = float("inf")
    t_hit = tl.full(sx.shape, inf, tl.float32)
    for n in range(n_boxes):
        box = boxes_ptr + 6 * n
        t0 = (tl.load(box + 0) - sx) * ix
        t1 = (tl.load(box + 3) - sx) * ix
        nan = (t0 != t0) | (t1 != t1)  # noqa: PLR0124 (0 * inf on a slab plane)
        near = tl.where(nan, -inf, tl.minimum(t0, t1))
        far = tl.where(nan, inf, tl.maximum(t0, t1))
        t0 = (tl.load(box + 1) - sy) * iy
        t1 = (tl.load(box + 4) - sy) * iy
        nan = (t0 != t0) | (t1 != t1)  # noqa: PLR0124
        near = tl.maximum(near, tl.where(nan, -inf, tl.minimum(t0, t1)))
        far = tl.minimum(far, tl.where(nan, inf, tl.maximum(t0, t1)))
        t0 = (tl.load(box + 2) - sz) * iz
        t1 = (tl.load(box + 5) - sz) * iz
        nan = (t0 != t0) | (t1 != t1)  # noqa: PLR0124
        near = tl.maximum(tl.maximum(near, tl.where(nan, -inf, tl.minimum(t0, t1))), 0.0)
        far = tl.minimum(far, tl.where(nan, inf, tl.maximum(t0, t1)))
        hit = (near <= far) & (far > 0.0)
        t_hit = tl.where(hit, tl.minimum(t_hit, near), t_hit)
    tl.store(vdata_ptr + off + t, t_hit, mask=live)


@_jit
def _extinction_kernel(ext_ptr, medf_ptr, medi_ptr, tex_ptr, n_media, res,
                       lo_x, lo_y, lo_z, size_x, size_y, size_z, BLOCK: tl.constexpr):
    """``extinction_volume``: the media's extinction at the voxel centres of the (R, R, R)
    box ``lo .. lo + size`` (x the first axis)."""
    t = tl.program_id(0) * BLOCK + tl.arange(0, BLOCK)
    live = t < res * res * res
    fres = res.to(tl.float32)
    fx = tl.div_rn((t // (res * res)).to(tl.float32) + 0.5, fres)
    fy = tl.div_rn(((t // res) % res).to(tl.float32) + 0.5, fres)
    fz = tl.div_rn((t % res).to(tl.float32) + 0.5, fres)
    _, _, _, ext, _, _, _, _ = _media(lo_x + fx * size_x, lo_y + fy * size_y,
                                      lo_z + fz * size_z, medf_ptr, medi_ptr, tex_ptr,
                                      n_media, live)
    tl.store(ext_ptr + t, ext, mask=live)


@_jit
def _transmittance_kernel(volf_ptr, voli_ptr, vdata_ptr, ext_ptr, ext_res, first,
                          lo_x, lo_y, lo_z, size_x, size_y, size_z, BLOCK: tl.constexpr):
    """``transmittance_volume`` of volume row ``first + program_id(0)``: a lane per texel
    marches its ray in K - 1 equal steps from the light side, midpoint rule, through the
    extinction volume (0 outside its box); data[i, j, k] = exp(-optical depth to k)."""
    v = first + tl.program_id(0)
    row = volf_ptr + v * VOL_F
    irow = voli_ptr + v * VOL_I
    res = tl.load(irow + 2)
    k = tl.load(irow + 3)
    off = tl.load(irow + 1)
    t = tl.program_id(1) * BLOCK + tl.arange(0, BLOCK)
    live = t < res * res
    a = tl.div_rn((t // res).to(tl.float32) + 0.5, res.to(tl.float32)) * 2.0 - 1.0
    b = tl.div_rn((t % res).to(tl.float32) + 0.5, res.to(tl.float32)) * 2.0 - 1.0
    extent = tl.load(row + 12)
    ox = tl.load(row + 0)
    oy = tl.load(row + 1)
    oz = tl.load(row + 2)
    ux = a * tl.load(row + 3) + b * tl.load(row + 6)
    uy = a * tl.load(row + 4) + b * tl.load(row + 7)
    uz = a * tl.load(row + 5) + b * tl.load(row + 8)
    wx = tl.load(row + 9)
    wy = tl.load(row + 10)
    wz = tl.load(row + 11)
    persp = tl.load(irow) != 0
    # Sun: parallel rays from the texels of the plane facing it; spot: rays fanning out
    # of the light through the texels of its cone.
    sx = tl.where(persp, ox, ox + extent * ux)
    sy = tl.where(persp, oy, oy + extent * uy)
    sz = tl.where(persp, oz, oz + extent * uz)
    dx = tl.where(persp, wx + extent * ux, wx)
    dy = tl.where(persp, wy + extent * uy, wy)
    dz = tl.where(persp, wz + extent * uz, wz)
    norm = tl.where(persp, tl.sqrt(dx * dx + dy * dy + dz * dz), 1.0)
    dx = dx / norm
    dy = dy / norm
    dz = dz / norm
    near = tl.load(row + 13)
    step = tl.load(row + 15)
    fres = ext_res.to(tl.float32)
    depth = tl.zeros_like(sx)
    tl.store(vdata_ptr + off + t * k, tl.full(sx.shape, 1.0, tl.float32), mask=live)
    for m in range(k - 1):
        mid = near + (m + 0.5) * step
        lx = tl.div_rn(sx + mid * dx - lo_x, size_x)
        ly = tl.div_rn(sy + mid * dy - lo_y, size_y)
        lz = tl.div_rn(sz + mid * dz - lo_z, size_z)
        inside = (lx >= 0.0) & (lx <= 1.0) & (ly >= 0.0) & (ly <= 1.0) & (lz >= 0.0) \
            & (lz <= 1.0)
        sigma = _texture(ext_ptr, 0, ext_res, ext_res, ext_res, lx * fres, ly * fres,
                         lz * fres, live & inside)
        depth += tl.where(inside, sigma, 0.0) * step
        tl.store(vdata_ptr + off + t * k + m + 1, tl.exp(-depth), mask=live)


@_jit
def _froxel_kernel(nodes_ptr, lit_ptr, media_ptr, listed_ptr, camf_ptr, camd_ptr, dz_ptr,
                   medf_ptr, medi_ptr, tex_ptr, n_media,
                   lightf_ptr, lighti_ptr, lightd_ptr, n_lights,
                   volf_ptr, voli_ptr, vdata_ptr,
                   ext_ptr, ext_res, lo_x, lo_y, lo_z, size_x, size_y, size_z, light_steps,
                   nx, ny, slices, tile, width, height,
                   near, depth_scale, offset, amb_r, amb_g, amb_b,
                   BLOCK_S: tl.constexpr, SCHLICK: tl.constexpr, NAIVE: tl.constexpr,
                   COUNTS: tl.constexpr):
    """One tile column (i, j): V-buffer, lighting and integration of all its slices."""
    tile_id = tl.program_id(0)
    i = tile_id % nx
    j = tile_id // nx
    n_tiles = nx * ny
    k = tl.arange(0, BLOCK_S)
    live = k < slices

    # The sample points: the tile's centre, the middle depth of each slice (float32, as
    # froxel_to_world of froxel_sample_coords).
    x = i.to(tl.float32) + 0.5
    y = j.to(tl.float32) + 0.5
    ndc_x = 2.0 * x * tile / width - 1.0
    ndc_y = 1.0 - 2.0 * y * tile / height
    ax = ndc_x * tl.load(camf_ptr + 12)
    ay = ndc_y * tl.load(camf_ptr + 13)
    eye_x = tl.load(camf_ptr + 0)
    eye_y = tl.load(camf_ptr + 1)
    eye_z = tl.load(camf_ptr + 2)
    dir_x = tl.load(camf_ptr + 9) + ax * tl.load(camf_ptr + 3) + ay * tl.load(camf_ptr + 6)
    dir_y = tl.load(camf_ptr + 10) + ax * tl.load(camf_ptr + 4) + ay * tl.load(camf_ptr + 7)
    dir_z = tl.load(camf_ptr + 11) + ax * tl.load(camf_ptr + 5) + ay * tl.load(camf_ptr + 8)
    depth = near * tl.exp((k.to(tl.float32) + offset) * depth_scale)
    px = eye_x + depth * dir_x
    py = eye_y + depth * dir_y
    pz = eye_z + depth * dir_z

    s0, s1, s2, sigma_t, src0, src1, src2, g = _media(px, py, pz, medf_ptr, medi_ptr, tex_ptr,
                                                      n_media, live)
    has_media = live & ((sigma_t > 0.0) | (tl.maximum(tl.maximum(src0, src1), src2) > 0.0))
    media_lanes = tl.sum(has_media.to(tl.int32), axis=0)
    tile_media = media_lanes > 0
    # (A block-wide condition enters the mask as a block: the interpreter cannot broadcast
    # a reduced boolean.)
    lit = live & (tl.maximum(tl.maximum(s0, s1), s2) > 0.0) & (k * 0 + media_lanes > 0)
    n_lit = tl.sum(lit.to(tl.int32), axis=0)
    any_lit = n_lit > 0

    vx = px - eye_x
    vy = py - eye_y
    vz = pz - eye_z
    vn = tl.sqrt(vx * vx + vy * vy + vz * vz)
    vx = vx / vn
    vy = vy / vn
    vz = vz / vn
    r0 = tl.zeros_like(px) + amb_r
    r1 = tl.zeros_like(px) + amb_g
    r2 = tl.zeros_like(px) + amb_b

    # The tile's side planes for the light lists, in float64 as cull_lights.
    hw = tl.load(camd_ptr + 12)
    hh = tl.load(camd_ptr + 13)
    i64 = i.to(tl.float64)
    j64 = j.to(tl.float64)
    x0 = 2.0 * i64 * tile / width - 1.0
    x1 = 2.0 * (i64 + 1.0) * tile / width - 1.0
    y0 = 1.0 - 2.0 * j64 * tile / height
    y1 = 1.0 - 2.0 * (j64 + 1.0) * tile / height
    n_left = tl.sqrt(1.0 + (x0 * hw) * (x0 * hw))
    n_right = tl.sqrt(1.0 + (x1 * hw) * (x1 * hw))
    n_top = tl.sqrt(1.0 + (y0 * hh) * (y0 * hh))
    n_bottom = tl.sqrt(1.0 + (y1 * hh) * (y1 * hh))

    for light in range(n_lights):
        drow = lightd_ptr + light * LIGHT_D
        lpx = tl.load(drow + 2)
        lpy = tl.load(drow + 3)
        lpz = tl.load(drow + 4)
        r = tl.load(drow + 5)
        cols = ((lpx - x0 * hw * lpz) / n_left >= -r) & ((x1 * hw * lpz - lpx) / n_right >= -r)
        rows = ((y0 * hh * lpz - lpy) / n_top >= -r) & ((lpy - y1 * hh * lpz) / n_bottom >= -r)
        listed = (tl.load(drow) != 0.0) | ((tl.load(drow + 1) != 0.0) & cols & rows)
        if COUNTS:
            tl.store(listed_ptr + light * n_tiles + tile_id, listed.to(tl.int8))
        if listed & any_lit:
            frow = lightf_ptr + light * LIGHT_F
            irow = lighti_ptr + light * LIGHT_I
            kind = tl.load(irow)
            if kind == 0:  # the sun: parallel light, no falloff
                tx = tl.zeros_like(px) + tl.load(frow + 3)
                ty = tl.zeros_like(px) + tl.load(frow + 4)
                tz = tl.zeros_like(px) + tl.load(frow + 5)
                e0 = tl.zeros_like(px) + tl.load(frow + 0)
                e1 = tl.zeros_like(px) + tl.load(frow + 1)
                e2 = tl.zeros_like(px) + tl.load(frow + 2)
            else:
                rx = tl.load(frow + 6) - px
                ry = tl.load(frow + 7) - py
                rz = tl.load(frow + 8) - pz
                dist = tl.sqrt(rx * rx + ry * ry + rz * rz)
                # A bulb's radius: 1 / d^2 stays finite on top of the light.
                dm = tl.maximum(dist, MIN_DISTANCE)
                tx = rx / dm
                ty = ry / dm
                tz = rz / dm
                falloff = tl.where(dist < tl.load(frow + 9), 1.0 / (dm * dm), 0.0)
                # A point light's path through the media, marched only where some lane of
                # the column is within its range (a listed tile's froxels mostly are not).
                reach = lit & (falloff > 0.0)
                if (tl.load(irow + 3) != 0) & (tl.max(reach.to(tl.int32), axis=0) > 0):
                    falloff = falloff * _segment_transmittance(
                        ext_ptr, ext_res, lo_x, lo_y, lo_z, size_x, size_y, size_z, px, py,
                        pz, tl.load(frow + 6), tl.load(frow + 7), tl.load(frow + 8),
                        light_steps, reach)
                if kind == 2:
                    cos_axis = -(tx * tl.load(frow + 3) + ty * tl.load(frow + 4)
                                 + tz * tl.load(frow + 5))
                    s = (cos_axis - tl.load(frow + 10)) / tl.load(frow + 11)
                    s = tl.minimum(tl.maximum(s, 0.0), 1.0)
                    falloff = falloff * s * s * (3.0 - 2.0 * s)
                e0 = falloff * tl.load(frow + 0)
                e1 = falloff * tl.load(frow + 1)
                e2 = falloff * tl.load(frow + 2)
            cos_theta = vx * tx + vy * ty + vz * tz
            if SCHLICK:
                kk = tl.minimum(tl.maximum(1.55 * g - 0.55 * (g * g * g), -K_MAX), K_MAX)
                q = 1.0 - kk * cos_theta
                phase = (1.0 - kk * kk) / (FOUR_PI * (q * q))
            else:
                denom = tl.maximum(1.0 + g * g - 2.0 * g * cos_theta, 0.0)
                phase = (1.0 - g * g) / (FOUR_PI * denom * tl.sqrt(denom))
            e0 = e0 * phase
            e1 = e1 * phase
            e2 = e2 * phase
            smap = tl.load(irow + 1)
            if smap >= 0:
                vis = _shadow_lookup(volf_ptr, voli_ptr, vdata_ptr, smap, px, py, pz, lit)
                e0 = e0 * vis
                e1 = e1 * vis
                e2 = e2 * vis
            tv = tl.load(irow + 2)
            if tv >= 0:
                trans = _transmittance_lookup(volf_ptr, voli_ptr, vdata_ptr, tv, px, py, pz,
                                              lit)
                e0 = e0 * trans
                e1 = e1 * trans
                e2 = e2 * trans
            r0 += e0
            r1 += e1
            r2 += e2
    src0 = tl.where(lit, src0 + s0 * r0, src0)
    src1 = tl.where(lit, src1 + s1 * r1, src1)
    src2 = tl.where(lit, src2 + s2 * r2, src2)

    # Front to back along the column: the transmittance in front of slice k is
    # exp(-(inclusive prefix sum - own optical depth)), as integrate_froxels computes it.
    # Slice lengths along the ray through the tile's centre, in float64 like the lab.
    d64x = tl.load(camd_ptr + 9) + (2.0 * (i64 + 0.5) * tile / width - 1.0) \
        * hw * tl.load(camd_ptr + 3) + (1.0 - 2.0 * (j64 + 0.5) * tile / height) * hh \
        * tl.load(camd_ptr + 6)
    d64y = tl.load(camd_ptr + 10) + (2.0 * (i64 + 0.5) * tile / width - 1.0) * hw \
        * tl.load(camd_ptr + 4) + (1.0 - 2.0 * (j64 + 0.5) * tile / height) * hh \
        * tl.load(camd_ptr + 7)
    d64z = tl.load(camd_ptr + 11) + (2.0 * (i64 + 0.5) * tile / width - 1.0) * hw \
        * tl.load(camd_ptr + 5) + (1.0 - 2.0 * (j64 + 0.5) * tile / height) * hh \
        * tl.load(camd_ptr + 8)
    stretch = tl.sqrt(d64x * d64x + d64y * d64y + d64z * d64z)
    length = (tl.load(dz_ptr + k, mask=live, other=0.0) * stretch).to(tl.float32)
    sigma_t = tl.where(live, sigma_t, 0.0)
    tau = sigma_t * length
    behind = tl.cumsum(tau, axis=0)
    in_front = tl.exp(-(behind - tau))
    if NAIVE:
        factor = length
    else:
        factor = length * _phi(tau)
    l0 = tl.cumsum(tl.where(live, in_front * (src0 * factor), 0.0), axis=0)
    l1 = tl.cumsum(tl.where(live, in_front * (src1 * factor), 0.0), axis=0)
    l2 = tl.cumsum(tl.where(live, in_front * (src2 * factor), 0.0), axis=0)
    trans = tl.exp(-behind)
    # Nodes (slices + 1, ny, nx, 4): (0, 0, 0, 1) at near, then each slice's far boundary.
    node = ((k + 1) * ny + j) * nx + i
    tl.store(nodes_ptr + 4 * node + 0, l0, mask=live)
    tl.store(nodes_ptr + 4 * node + 1, l1, mask=live)
    tl.store(nodes_ptr + 4 * node + 2, l2, mask=live)
    tl.store(nodes_ptr + 4 * node + 3, trans, mask=live)
    tl.store(nodes_ptr + 4 * tile_id + k, tl.where(k == 3, 1.0, 0.0), mask=k < 4)
    if COUNTS:
        tl.store(lit_ptr + tile_id, n_lit)
        tl.store(media_ptr + tile_id, tile_media.to(tl.int8))


@_jit
def _apply_kernel(out_ptr, nodes_ptr, depth_ptr, opaque_ptr, n_pixels, width, tile, nx, ny,
                  slices, fx, fy, fs, log_near, depth_to_z, BLOCK: tl.constexpr):
    """``apply_froxels``: opaque * T + L, (L, T) trilinear in the nodes at the pixel's
    view depth (clamped to near .. far) and its position across the tiles."""
    p = tl.program_id(0) * BLOCK + tl.arange(0, BLOCK)
    live = p < n_pixels
    row = p // width
    col = p % width
    d = tl.load(depth_ptr + p, mask=live, other=1.0)
    z = (tl.log(d) - log_near) * depth_to_z
    # fx, fy, fs: nx, ny, slices as floats (an int argument of 1 arrives as a constant).
    z = tl.where(z == z, z, 0.0)  # noqa: PLR0124 (NaN test): nan_to_num
    z = tl.minimum(tl.maximum(z, 0.0), fs)  # -inf (depth 0) -> 0, +inf (sky) -> slices
    # Continuous node indices (minus the voxel-centre 0.5) along slices, rows, columns.
    uz = (z + 0.5) - 0.5
    uy = (row.to(tl.float32) + 0.5) / tile - 0.5
    ux = (col.to(tl.float32) + 0.5) / tile - 0.5
    uz = tl.minimum(tl.maximum(uz, 0.0), fs)
    uy = tl.minimum(tl.maximum(uy, 0.0), fy - 1.0)
    ux = tl.minimum(tl.maximum(ux, 0.0), fx - 1.0)
    z0 = tl.minimum(tl.floor(uz), tl.maximum(fs - 1.0, 0.0))
    y0 = tl.minimum(tl.floor(uy), tl.maximum(fy - 2.0, 0.0))
    x0 = tl.minimum(tl.floor(ux), tl.maximum(fx - 2.0, 0.0))
    az = uz - z0
    ay = uy - y0
    ax = ux - x0
    iz = z0.to(tl.int32)
    iy = y0.to(tl.int32)
    ix = x0.to(tl.int32)
    jz = tl.minimum(iz + 1, slices)
    jy = tl.minimum(iy + 1, ny - 1)
    jx = tl.minimum(ix + 1, nx - 1)
    l0 = tl.zeros_like(uz)
    l1 = tl.zeros_like(uz)
    l2 = tl.zeros_like(uz)
    t = tl.zeros_like(uz)
    for corner in tl.static_range(8):
        ba = (corner >> 2) & 1
        bb = (corner >> 1) & 1
        bc = corner & 1
        gz = iz + (jz - iz) * ba
        gy = iy + (jy - iy) * bb
        gx = ix + (jx - ix) * bc
        w = ((1 - ba) + (2 * ba - 1) * az) * ((1 - bb) + (2 * bb - 1) * ay) \
            * ((1 - bc) + (2 * bc - 1) * ax)
        base = nodes_ptr + 4 * ((gz * ny + gy) * nx + gx)
        l0 += tl.load(base + 0, mask=live, other=0.0) * w
        l1 += tl.load(base + 1, mask=live, other=0.0) * w
        l2 += tl.load(base + 2, mask=live, other=0.0) * w
        t += tl.load(base + 3, mask=live, other=0.0) * w
    red = tl.load(opaque_ptr + 3 * p, mask=live, other=0.0)
    green = tl.load(opaque_ptr + 3 * p + 1, mask=live, other=0.0)
    blue = tl.load(opaque_ptr + 3 * p + 2, mask=live, other=0.0)
    tl.store(out_ptr + 3 * p, red * t + l0, mask=live)
    tl.store(out_ptr + 3 * p + 1, green * t + l1, mask=live)
    tl.store(out_ptr + 3 * p + 2, blue * t + l2, mask=live)


# ---------------------------------------------------------------------------------------
# Host side: the scene packed into tables (once per scene and camera), the launches


_PLANS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _plan(scene, grid, shadow_resolution, volume_resolution, volumetric_shadows, device):
    """The scene's tables on ``device`` for this grid and these settings, cached per scene.

    Everything here follows from the frozen scene and camera description (numbers, not
    tensors), like a renderer's scene buffers; the density textures (tensors, which may
    change) and everything computed from them are rebuilt every frame."""
    key = (grid, shadow_resolution, volume_resolution, volumetric_shadows, str(device))
    per_scene = _PLANS.setdefault(scene, {})
    if key in per_scene:
        return per_scene[key]
    f32, f64 = torch.float32, torch.float64
    eye, right, up, fwd, (hw, hh) = grid.axes(f64)
    camd = torch.zeros(SIZES['CAM_D'], dtype=f64)
    camd[0:12] = torch.cat([eye, right, up, fwd])
    camd[12], camd[13] = hw, hh
    camf = torch.zeros(SIZES['CAM_F'], dtype=f32)
    camf[0:12] = camd[0:12].to(f32)
    camf[12], camf[13] = hw, hh
    z = grid.near * torch.exp(torch.arange(grid.slices + 1, dtype=f64) / grid.slices
                              * math.log(grid.far / grid.near))
    z[0], z[-1] = grid.near, grid.far

    medf = torch.zeros(max(len(scene.media), 1), SIZES['MED_F'], dtype=f32)
    medi = torch.zeros(max(len(scene.media), 1), SIZES['MED_I'], dtype=torch.int32)
    textures, tex_offset = [], 0
    for m, medium in enumerate(scene.media):
        sigma_s = torch.tensor(medium.scattering, dtype=f32)
        medf[m, 0:3] = sigma_s
        medf[m, 3] = medium.extinction
        medf[m, 4:7] = torch.tensor(medium.emissive, dtype=f32)
        medf[m, 7] = sigma_s.mean() * medium.g  # the g weight, rounded as media_at does
        if isinstance(medium, ConstantFog):
            medi[m, 0] = 0
        elif isinstance(medium, HeightFog):
            medi[m, 0] = 1
            medf[m, 8], medf[m, 9] = medium.base, medium.falloff
        else:
            medi[m, 0] = 2 if medium.shape == "box" else 3
            medf[m, 10:13] = torch.tensor(medium.center, dtype=f32)
            medf[m, 13:22] = torch.tensor(medium.rotation, dtype=f32).reshape(-1)
            medf[m, 22:25] = torch.tensor(medium.half_size, dtype=f32)
            if medium.density is not None:
                medi[m, 1] = tex_offset
                medi[m, 2:5] = torch.tensor(medium.density.shape)
                medi[m, 5] = 1
                textures.append(m)
                tex_offset += medium.density.numel()

    view_lo, view_hi = frustum_bounds(grid)
    center = tuple((a + b) / 2 for a, b in zip(view_lo, view_hi))
    radius = 0.5 * math.dist(view_lo, view_hi)
    shadow_lights = [n for n, light in enumerate(scene.lights)
                     if isinstance(light, DirectionalLight) and light.shadows
                     and scene.occluders]
    # The extinction volume over the media in view (volume_bounds), as light_froxels.
    bounds = volume_bounds(scene, grid) if volumetric_shadows and scene.lights else None
    extinction = bounds is not None
    lo, hi = bounds if extinction else (view_lo, view_hi)
    if extinction and volume_resolution is None:
        volume_resolution = auto_volume_resolution(scene, lo, hi)
    volume_lights = [n for n, light in enumerate(scene.lights)
                     if extinction and not isinstance(light, PointLight)]
    n_vol = len(shadow_lights) + len(volume_lights)
    volf = torch.zeros(max(n_vol, 1), SIZES['VOL_F'], dtype=f32)
    voli = torch.zeros(max(n_vol, 1), SIZES['VOL_I'], dtype=torch.int32)
    lightf = torch.zeros(max(len(scene.lights), 1), SIZES['LIGHT_F'], dtype=f32)
    lighti = torch.full((max(len(scene.lights), 1), SIZES['LIGHT_I']), -1, dtype=torch.int32)
    lightd = torch.zeros(max(len(scene.lights), 1), SIZES['LIGHT_D'], dtype=f64)
    data_offset = 0

    def volume(v, origin, axes, extent, near, far, persp, res, k, last):
        nonlocal data_offset
        volf[v, 0:3] = torch.tensor(origin, dtype=f64).to(f32)
        volf[v, 3:12] = torch.tensor(axes, dtype=f64).reshape(-1).to(f32)
        volf[v, 12], volf[v, 13], volf[v, 14], volf[v, 15] = extent, near, far - near, last
        voli[v] = torch.tensor([persp, data_offset, res, k], dtype=torch.int32)
        data_offset += res * res * k

    v = 0
    for n in shadow_lights:  # build_shadow_map's frame: beyond every occluder, facing the sun
        light = scene.lights[n]
        toward = light.direction
        lift = radius
        for box in scene.occluders:
            for cx in (box.lo[0], box.hi[0]):
                for cy in (box.lo[1], box.hi[1]):
                    for cz in (box.lo[2], box.hi[2]):
                        lift = max(lift, (cx - center[0]) * toward[0] + (cy - center[1])
                                   * toward[1] + (cz - center[2]) * toward[2])
        origin = tuple(c + (lift + 1.0) * t for c, t in zip(center, toward))
        volume(v, origin, light_frame(tuple(-x for x in toward)), radius, 0.0, math.inf, 0,
               shadow_resolution, 1, 4 * radius / shadow_resolution)
        lighti[n, 1] = v
        v += 1
    first_volume = v
    k = 4 * volume_resolution if extinction else 0  # light_froxels' depth samples
    box_center = tuple((a + b) / 2 for a, b in zip(lo, hi))
    box_radius = 0.5 * math.dist(lo, hi)
    for n in volume_lights:  # transmittance_volume's frames, over the extinction's box
        light = scene.lights[n]
        if isinstance(light, DirectionalLight):
            origin = tuple(c + box_radius * t for c, t in zip(box_center, light.direction))
            volume(v, origin, light_frame(tuple(-x for x in light.direction)), box_radius,
                   0.0, 2 * box_radius, 0, volume_resolution, k, 2 * box_radius / (k - 1))
        else:
            volume(v, light.position, light_frame(light.direction),
                   math.tan(math.radians(light.outer_deg)), 0.0, light.range, 1,
                   volume_resolution, k, light.range / (k - 1))
        lighti[n, 2] = v
        v += 1

    for n, light in enumerate(scene.lights):
        if isinstance(light, DirectionalLight):
            lighti[n, 0] = 0
            lightf[n, 0:3] = torch.tensor(light.irradiance, dtype=f32)
            lightf[n, 3:6] = torch.tensor(light.direction, dtype=f32)
            lightd[n, 0] = 1.0
            continue
        lighti[n, 0] = 1 if isinstance(light, PointLight) else 2
        lighti[n, 3] = int(extinction and isinstance(light, PointLight))
        lightf[n, 0:3] = torch.tensor(light.intensity, dtype=f32)
        lightf[n, 6:9] = torch.tensor(light.position, dtype=f32)
        lightf[n, 9] = light.range
        if isinstance(light, SpotLight):
            lightf[n, 3:6] = torch.tensor(light.direction, dtype=f32)
            lo_cos = math.cos(math.radians(light.outer_deg))
            hi_cos = math.cos(math.radians(light.inner_deg))
            lightf[n, 10], lightf[n, 11] = lo_cos, hi_cos - lo_cos
        p = torch.tensor(light.position, dtype=f64) - eye
        pz = float(p @ fwd)
        lightd[n, 1] = float(grid.near - light.range <= pz <= grid.far + light.range)
        lightd[n, 2:5] = torch.stack([p @ right, p @ up, p @ fwd])
        lightd[n, 5] = light.range

    lo32 = torch.tensor(lo, dtype=f32)
    size32 = torch.tensor(hi, dtype=f32) - lo32
    boxes = torch.tensor([[*b.lo, *b.hi] for b in scene.occluders] or [[0.0] * 6], dtype=f32)
    plan = {
        "camf": camf.to(device), "camd": camd.to(device), "dz": (z[1:] - z[:-1]).to(device),
        "medf": medf.to(device), "medi": medi.to(device), "textures": textures,
        "lightf": lightf.to(device), "lighti": lighti.to(device),
        "lightd": lightd.to(device), "volf": volf.to(device), "voli": voli.to(device),
        "boxes": boxes.to(device), "n_boxes": len(scene.occluders),
        "n_maps": len(shadow_lights), "n_volumes": len(volume_lights),
        "first_volume": first_volume, "data_size": max(data_offset, 1),
        "extinction": extinction, "bounds": bounds, "lo": lo32.tolist(),
        "size": size32.tolist(),
        "shadow_resolution": shadow_resolution, "volume_resolution": volume_resolution,
    }
    per_scene[key] = plan
    return plan


def render_froxels_fused(scene, camera, depth_image, opaque_image, *, tile=None,
                         slices=SLICES, near=None, far=None, phase="hg", integration="energy",
                         volumetric_shadows=True, shadow_resolution=128, volume_resolution=None,
                         light_steps=LIGHT_STEPS, counts=True, num_warps=None):
    """Lab 5's ``render_froxels`` (non-temporal) in five Triton launches: ``(image, report)``.

    scene: a ``course.given.lab5.Scene``; camera: its ``Camera``; depth_image (H, W)
    view depths >= 0 (+inf: sky), opaque_image (H, W, 3), float32 or float64 on one CUDA
    device (or the CPU under ``TRITON_INTERPRET=1``); the keywords as ``render_froxels``.
    Returns the image (H, W, 3) in the images' dtype and a report with the keys of
    ``render_froxels``' (``grid``, ``froxels``, ``froxels_lit``, ``tiles_with_media``,
    ``light_tiles``, ``light_evaluations``, ``jitter`` 0.5, ``history_valid`` 0.0,
    ``history`` None) and ``kernel``, the froxel kernel's compiled handle (``n_regs``,
    ``n_spills``; absent without media), ``volume_bounds`` and ``volume_resolution`` (as the
    lab's). The counts cost one synchronisation at the end of the frame: with
    ``counts=False`` they are None, the kernels skip that bookkeeping and nothing waits
    for the GPU (the frame is only queued).

    ``num_warps``: of the froxel kernel, a power of two up to 32 (default: one warp per 32
    slices, a lane per froxel of the column; one warp for 64 slices timed faster on an
    H100, 0.40 against 0.50 ms per frame, but the GPU accuracy tests ran with the default).

    A scene without media returns a copy of ``opaque_image``, as the lab does. The scene's
    description (not its density textures) is packed into device tables once per scene,
    camera and settings; the shadow maps, the extinction and transmittance volumes, the
    froxels and the image are computed every call.
    """
    _require_triton()
    check_scene(scene)
    grid = scene_grid(scene, camera, tile, slices, near, far)
    # The lab's check_images also scans the depths for NaN and negative values, which
    # waits for the GPU: here only shapes, dtypes and devices are checked (a NaN depth
    # reads as no fog, a negative one as before near).
    h, w = camera.height, camera.width
    check_volume(depth_image, "depth_image", (h, w))
    check_volume(opaque_image, "opaque_image", (h, w, 3), depth_image.dtype, depth_image.device)
    dtype = depth_image.dtype
    check_choice(phase, "phase", PHASES)
    check_choice(integration, "integration", INTEGRATIONS)
    for name, value in (("shadow_resolution", shadow_resolution), ("light_steps", light_steps)):
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise ValueError(f"{name}: expected an int >= 1, got {value!r}")
    check_volume_resolution(volume_resolution)
    # Compiled, Triton rejects a warp count that is not a power of two deep in its compiler
    # (an assertion naming none of these arguments) and cannot launch over 32 warps; the
    # interpreter ignores num_warps, so a bad value would pass every CPU test.
    if num_warps is not None and (isinstance(num_warps, bool) or not isinstance(num_warps, int)
                                  or not 1 <= num_warps <= 32 or num_warps & (num_warps - 1)):
        raise ValueError(f"num_warps: expected None or a power of two <= 32, got {num_warps!r}")
    report = {"grid": grid, "froxels": math.prod(grid.shape), "froxels_lit": 0,
              "tiles_with_media": 0, "light_tiles": [0] * len(scene.lights),
              "light_evaluations": 0, "volume_bounds": None, "volume_resolution": 0,
              "jitter": 0.5, "history_valid": 0.0, "history": None}
    if not scene.media:
        return opaque_image.clone(), report
    device = depth_image.device
    if not interpreting() and device.type != "cuda":
        raise ValueError(f"depth_image: the compiled Triton kernels need CUDA tensors, got "
                         f"{device} (for the CPU, set TRITON_INTERPRET=1 before importing "
                         "triton)")

    plan = _plan(scene, grid, shadow_resolution, volume_resolution, bool(volumetric_shadows),
                 device)
    f32 = torch.float32
    if plan["textures"]:
        tex = torch.cat([scene.media[m].density.to(device, f32).reshape(-1)
                         for m in plan["textures"]])
    else:
        tex = torch.zeros(1, dtype=f32, device=device)
    vdata = torch.empty(plan["data_size"], dtype=f32, device=device)
    n_tiles = grid.nx * grid.ny
    n_lights = len(scene.lights)
    nodes = torch.empty(grid.slices + 1, grid.ny, grid.nx, 4, dtype=f32, device=device)
    lit = torch.empty(n_tiles if counts else 1, dtype=torch.int32, device=device)
    media = torch.empty(n_tiles if counts else 1, dtype=torch.int8, device=device)
    listed = torch.empty(max(n_lights, 1) * n_tiles if counts else 1, dtype=torch.int8,
                         device=device)
    depth = depth_image.to(f32).contiguous()
    opaque = opaque_image.to(f32).contiguous()
    out = torch.empty(opaque.shape, dtype=f32, device=device)
    block_s = max(triton.next_power_of_2(grid.slices), 4)  # >= 4: lanes 0-3 write node 0
    warps = num_warps or max(1, min(8, block_s // 32))
    block = BLOCK_TEXELS_INTERPRETED if interpreting() else BLOCK_TEXELS
    with _ieee_quiet():
        if plan["n_maps"]:
            res = plan["shadow_resolution"]
            _shadow_map_kernel[(plan["n_maps"], triton.cdiv(res * res, block))](
                plan["volf"], plan["voli"], vdata, plan["boxes"], plan["n_boxes"],
                BLOCK=block)
        res = plan["volume_resolution"] if plan["extinction"] else 1
        ext = torch.empty(res ** 3, dtype=f32, device=device)
        if plan["extinction"]:
            _extinction_kernel[(triton.cdiv(res ** 3, block),)](
                ext, plan["medf"], plan["medi"], tex, len(scene.media), res, *plan["lo"],
                *plan["size"], BLOCK=block)
            if plan["n_volumes"]:
                _transmittance_kernel[(plan["n_volumes"],
                                       triton.cdiv(res * res, block))](
                    plan["volf"], plan["voli"], vdata, ext, res, plan["first_volume"],
                    *plan["lo"], *plan["size"], BLOCK=block)
        log_ratio = math.log(grid.far / grid.near)
        report["kernel"] = _froxel_kernel[(n_tiles,)](
            nodes, lit, media, listed, plan["camf"], plan["camd"], plan["dz"],
            plan["medf"], plan["medi"], tex, len(scene.media),
            plan["lightf"], plan["lighti"], plan["lightd"], n_lights,
            plan["volf"], plan["voli"], vdata,
            ext, res, *plan["lo"], *plan["size"], light_steps,
            grid.nx, grid.ny, grid.slices, grid.tile, camera.width, camera.height,
            grid.near, log_ratio / grid.slices, slice_offset(grid, 0.5), *scene.ambient,
            BLOCK_S=block_s, SCHLICK=phase == "schlick", NAIVE=integration == "naive",
            COUNTS=bool(counts), num_warps=warps)
        n_pixels = camera.width * camera.height
        _apply_kernel[(triton.cdiv(n_pixels, BLOCK_PIXELS),)](
            out, nodes, depth, opaque, n_pixels, camera.width, grid.tile, grid.nx, grid.ny,
            grid.slices, float(grid.nx), float(grid.ny), float(grid.slices),
            math.log(grid.near), grid.slices / log_ratio, BLOCK=BLOCK_PIXELS)
    if plan["extinction"]:
        report["volume_bounds"] = plan["bounds"]
        report["volume_resolution"] = plan["volume_resolution"]
    if counts:
        _count(report, lit, media, listed, n_lights, n_tiles)
    else:
        for name in ("froxels_lit", "tiles_with_media", "light_tiles", "light_evaluations"):
            report[name] = None
    return out.to(dtype), report


def _count(report, lit, media, listed, n_lights, n_tiles):
    """The lab's counts from the per-tile numbers the kernel wrote, in one transfer."""
    listed = listed[:n_lights * n_tiles].reshape(n_lights, n_tiles).to(torch.int64)
    lit = lit.to(torch.int64)
    media = media.to(torch.int64)
    totals = torch.cat([lit.sum()[None], media.sum()[None], (listed * lit).sum()[None],
                        (listed * media).sum(1)]).tolist()
    report["froxels_lit"], report["tiles_with_media"] = totals[0], totals[1]
    report["light_evaluations"] = totals[2]
    # Nothing lit: the lab evaluates no light anywhere.
    report["light_tiles"] = totals[3:] if totals[0] else [0] * n_lights
