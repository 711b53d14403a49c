"""The five kernels of one fused froxel frame (:mod:`course.kernels.triton_froxel` states
what each does and launches them): shadow maps, the extinction volume, the transmittance
volumes, the froxels (media, culled lights, lighting and the column's integration) and the
application to the image.

Given code, not an exercise; its accuracy contract is the pipeline's.
"""

from __future__ import annotations

from course.kernels.triton_froxel_lookups import (
    FOUR_PI,
    K_MAX,
    LIGHT_D,
    LIGHT_F,
    LIGHT_I,
    MIN_DISTANCE,
    VOL_F,
    VOL_I,
    _media,
    _phi,
    _segment_transmittance,
    _shadow_lookup,
    _texture,
    _transmittance_lookup,
)
from course.kernels.triton_intersect import _jit, tl

# ---------------------------------------------------------------------------------------
# Kernels


@_jit
def _shadow_map_kernel(volf_ptr, voli_ptr, vdata_ptr, boxes_ptr, n_boxes, BLOCK: tl.constexpr):
    """``build_shadow_map``: texel (i, j) of volume row ``program_id(0)`` traces one ray
    from its centre along w against every occluder box; depth of the first hit or inf."""
    v = tl.program_id(0)
    row = volf_ptr + v * VOL_F
    res = tl.load(voli_ptr + v * VOL_I + 2)
    off = tl.load(voli_ptr + v * VOL_I + 1)
    t = tl.program_id(1) * BLOCK + tl.arange(0, BLOCK)
    live = t < res * res
    a = tl.div_rn((t // res).to(tl.float32) + 0.5, (res * 1.0)) * 2.0 - 1.0
    b = tl.div_rn((t % res).to(tl.float32) + 0.5, (res * 1.0)) * 2.0 - 1.0
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
def _extinction_kernel(
    ext_ptr,
    medf_ptr,
    medi_ptr,
    tex_ptr,
    n_media,
    res,
    lo_x,
    lo_y,
    lo_z,
    size_x,
    size_y,
    size_z,
    BLOCK: tl.constexpr,
):
    """``extinction_volume``: the media's extinction at the voxel centres of the (R, R, R)
    box ``lo .. lo + size`` (x the first axis)."""
    t = tl.program_id(0) * BLOCK + tl.arange(0, BLOCK)
    live = t < res * res * res
    fres = res * 1.0
    fx = tl.div_rn((t // (res * res)).to(tl.float32) + 0.5, fres)
    fy = tl.div_rn(((t // res) % res).to(tl.float32) + 0.5, fres)
    fz = tl.div_rn((t % res).to(tl.float32) + 0.5, fres)
    _, _, _, ext, _, _, _, _ = _media(
        lo_x + fx * size_x,
        lo_y + fy * size_y,
        lo_z + fz * size_z,
        medf_ptr,
        medi_ptr,
        tex_ptr,
        n_media,
        live,
    )
    tl.store(ext_ptr + t, ext, mask=live)


@_jit
def _transmittance_kernel(
    volf_ptr,
    voli_ptr,
    vdata_ptr,
    ext_ptr,
    ext_res,
    first,
    lo_x,
    lo_y,
    lo_z,
    size_x,
    size_y,
    size_z,
    BLOCK: tl.constexpr,
):
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
    a = tl.div_rn((t // res).to(tl.float32) + 0.5, (res * 1.0)) * 2.0 - 1.0
    b = tl.div_rn((t % res).to(tl.float32) + 0.5, (res * 1.0)) * 2.0 - 1.0
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
    fres = ext_res * 1.0
    depth = tl.zeros_like(sx)
    tl.store(vdata_ptr + off + t * k, tl.full(sx.shape, 1.0, tl.float32), mask=live)
    for m in range(k - 1):
        mid = near + (m + 0.5) * step
        lx = tl.div_rn(sx + mid * dx - lo_x, size_x)
        ly = tl.div_rn(sy + mid * dy - lo_y, size_y)
        lz = tl.div_rn(sz + mid * dz - lo_z, size_z)
        inside = (lx >= 0.0) & (lx <= 1.0) & (ly >= 0.0) & (ly <= 1.0) & (lz >= 0.0) & (lz <= 1.0)
        sigma = _texture(
            ext_ptr, 0, ext_res, ext_res, ext_res, lx * fres, ly * fres, lz * fres, live & inside
        )
        depth += tl.where(inside, sigma, 0.0) * step
        tl.store(vdata_ptr + off + t * k + m + 1, tl.exp(-depth), mask=live)


@_jit
def _froxel_kernel(
    nodes_ptr,
    lit_ptr,
    media_ptr,
    listed_ptr,
    camf_ptr,
    camd_ptr,
    dz_ptr,
    medf_ptr,
    medi_ptr,
    tex_ptr,
    n_media,
    lightf_ptr,
    lighti_ptr,
    lightd_ptr,
    n_lights,
    volf_ptr,
    voli_ptr,
    vdata_ptr,
    ext_ptr,
    ext_res,
    lo_x,
    lo_y,
    lo_z,
    size_x,
    size_y,
    size_z,
    light_steps,
    nx,
    ny,
    slices,
    tile,
    width,
    height,
    near,
    depth_scale,
    offset,
    amb_r,
    amb_g,
    amb_b,
    BLOCK_S: tl.constexpr,
    SCHLICK: tl.constexpr,
    NAIVE: tl.constexpr,
    COUNTS: tl.constexpr,
):
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

    s0, s1, s2, sigma_t, src0, src1, src2, g = _media(
        px, py, pz, medf_ptr, medi_ptr, tex_ptr, n_media, live
    )
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
                        ext_ptr,
                        ext_res,
                        lo_x,
                        lo_y,
                        lo_z,
                        size_x,
                        size_y,
                        size_z,
                        px,
                        py,
                        pz,
                        tl.load(frow + 6),
                        tl.load(frow + 7),
                        tl.load(frow + 8),
                        light_steps,
                        reach,
                    )
                if kind == 2:
                    cos_axis = -(
                        tx * tl.load(frow + 3) + ty * tl.load(frow + 4) + tz * tl.load(frow + 5)
                    )
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
                trans = _transmittance_lookup(volf_ptr, voli_ptr, vdata_ptr, tv, px, py, pz, lit)
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
    d64x = (
        tl.load(camd_ptr + 9)
        + (2.0 * (i64 + 0.5) * tile / width - 1.0) * hw * tl.load(camd_ptr + 3)
        + (1.0 - 2.0 * (j64 + 0.5) * tile / height) * hh * tl.load(camd_ptr + 6)
    )
    d64y = (
        tl.load(camd_ptr + 10)
        + (2.0 * (i64 + 0.5) * tile / width - 1.0) * hw * tl.load(camd_ptr + 4)
        + (1.0 - 2.0 * (j64 + 0.5) * tile / height) * hh * tl.load(camd_ptr + 7)
    )
    d64z = (
        tl.load(camd_ptr + 11)
        + (2.0 * (i64 + 0.5) * tile / width - 1.0) * hw * tl.load(camd_ptr + 5)
        + (1.0 - 2.0 * (j64 + 0.5) * tile / height) * hh * tl.load(camd_ptr + 8)
    )
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
def _apply_kernel(
    out_ptr,
    nodes_ptr,
    depth_ptr,
    opaque_ptr,
    n_pixels,
    width,
    tile,
    nx,
    ny,
    slices,
    fx,
    fy,
    fs,
    log_near,
    depth_to_z,
    BLOCK: tl.constexpr,
):
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
        w = (
            ((1 - ba) + (2 * ba - 1) * az)
            * ((1 - bb) + (2 * bb - 1) * ay)
            * ((1 - bc) + (2 * bc - 1) * ax)
        )
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
