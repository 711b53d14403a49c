"""A whole Whitted frame in one Triton launch: the lecture's **uber kernel** (given, not an
exercise).

Each lane runs its pixel's whole Whitted recursion, the TRAVERSE -> INTERSECT -> SHADE state
machine, in one launch, with no rays written to memory between the stages: the BVH walk of
:mod:`course.kernels.triton_walk`, shading by the contract of :mod:`course.given.lab3` in
float32. The walk's knobs for it (``UBER_*``) are the ones timed for its frames
(bench/results/nvidia-h200/lab3_packed/).

Accuracy contract: that of course.kernels.flat_bvh for every ray of the recursion, then the
shading contract of Lab 3 in float32.
"""

from __future__ import annotations

import math
import weakref

import torch

from course.kernels.flat_bvh import EXIT_SCALE, FlatBVH, check_rays, flat_bvh_for
from course.kernels.triton_intersect import _ieee_quiet, _jit, _require_triton, interpreting, tl
from course.kernels.triton_launch import _bvh_args, _check_launch, _device_check, _info, _stack
from course.kernels.triton_walk import (
    DEFAULT_BLOCK,
    DEFAULT_NUM_WARPS,
    DEFAULT_UNIFORM,
    UBER_SPECULATE,
    UBER_STACK_REGS,
    UBER_TRIS_PER_STEP,
    _trace,
)


@_jit
def _pow(x, s):
    """``x ** s`` for x >= 0 as torch computes it (``0 ** 0 = 1``, ``0 ** s = 0``)."""
    safe = tl.where(x > 0.0, x, 1.0)
    return tl.where(x > 0.0, tl.exp2(s * tl.log2(safe)), tl.where(s == 0.0, 1.0, 0.0))


@_jit
def _whitted_kernel(
    o_ptr,
    d_ptr,
    out_ptr,
    n_rays,
    pairs,
    root,
    tris_f,
    tris_i,
    root_ref,
    stack_ptr,
    stride,
    mat_id_ptr,
    mat_ptr,
    light_ptr,
    amb_r,
    amb_g,
    amb_b,
    bg_r,
    bg_g,
    bg_b,
    offset,
    N_LIGHTS: tl.constexpr,
    MAX_DEPTH: tl.constexpr,
    BLOCK: tl.constexpr,
    EXIT: tl.constexpr,
    UNIFORM: tl.constexpr,
    VEC: tl.constexpr,
    SANITIZE: tl.constexpr,
    REGS: tl.constexpr,
    TRIS: tl.constexpr,
    SPECULATE: tl.constexpr,
):
    """The uber kernel: per lane, primary ray -> (closest hit -> shade with shadow rays ->
    mirror bounce) up to ``max_depth`` bounces; the radiance recursion unrolled into a
    loop with a throughput weight (``L += kr * radiance(...)`` becomes ``weight *= kr``).

    The light count and the depth are compile-time constants: the loops stay loops (not
    unrolled), but their trip counts are known, which also keeps the interpreter of older
    Tritons (whose scalar arguments are 1-element arrays) able to run them."""
    slot = tl.program_id(0) * BLOCK + tl.arange(0, BLOCK)
    live = slot < n_rays
    ox = tl.load(o_ptr + slot * 3 + 0, mask=live, other=0.0)
    oy = tl.load(o_ptr + slot * 3 + 1, mask=live, other=0.0)
    oz = tl.load(o_ptr + slot * 3 + 2, mask=live, other=0.0)
    dx = tl.load(d_ptr + slot * 3 + 0, mask=live, other=1.0)
    dy = tl.load(d_ptr + slot * 3 + 1, mask=live, other=1.0)
    dz = tl.load(d_ptr + slot * 3 + 2, mask=live, other=1.0)
    zero = tl.zeros([BLOCK], tl.float32)
    inf = zero + float("inf")
    # A primary ray with a NaN/inf component or a zero direction misses: background.
    finite = (
        (tl.abs(ox) < inf)
        & (tl.abs(oy) < inf)
        & (tl.abs(oz) < inf)
        & (tl.abs(dx) < inf)
        & (tl.abs(dy) < inf)
        & (tl.abs(dz) < inf)
        & ((dx != 0.0) | (dy != 0.0) | (dz != 0.0))
    )
    w_r = zero + 1.0
    w_g = zero + 1.0
    w_b = zero + 1.0
    c_r = tl.where(finite, zero, bg_r)
    c_g = tl.where(finite, zero, bg_g)
    c_b = tl.where(finite, zero, bg_b)
    active = live & finite
    inv_pi = 0.3183098861837907
    for _depth in range(MAX_DEPTH + 1):
        t, row, _u, _v = _trace(
            pairs,
            root,
            tris_i,
            root_ref,
            stack_ptr,
            slot,
            stride,
            ox,
            oy,
            oz,
            dx,
            dy,
            dz,
            zero,
            inf,
            active,
            False,
            EXIT,
            UNIFORM,
            VEC,
            SANITIZE,
            REGS,
            TRIS,
            SPECULATE,
            False,
        )
        hit = active & (row >= 0)
        miss = active & (row < 0)
        c_r += tl.where(miss, w_r * bg_r, 0.0)
        c_g += tl.where(miss, w_g * bg_g, 0.0)
        c_b += tl.where(miss, w_b * bg_b, 0.0)
        active = hit
        # SHADE: geometric normal from the stored edges, facing the ray.
        base = tris_f + row * 12
        e1x = tl.load(base + 4, mask=hit, other=0.0)
        e1y = tl.load(base + 5, mask=hit, other=0.0)
        e1z = tl.load(base + 6, mask=hit, other=1.0)
        e2x = tl.load(base + 8, mask=hit, other=0.0)
        e2y = tl.load(base + 9, mask=hit, other=1.0)
        e2z = tl.load(base + 10, mask=hit, other=0.0)
        tri = tl.load(tris_i + row * 12 + 3, mask=hit, other=0)
        nx = e1y * e2z - e1z * e2y
        ny = e1z * e2x - e1x * e2z
        nz = e1x * e2y - e1y * e2x
        n_len = tl.sqrt(nx * nx + ny * ny + nz * nz)
        flip = tl.where(nx * dx + ny * dy + nz * dz > 0.0, -1.0, 1.0) / n_len
        nx = nx * flip
        ny = ny * flip
        nz = nz * flip
        px = ox + t * dx
        py = oy + t * dy
        pz = oz + t * dz
        scale = offset * tl.maximum(tl.maximum(tl.abs(px), tl.abs(py)), tl.maximum(tl.abs(pz), 1.0))
        px = px + nx * scale
        py = py + ny * scale
        pz = pz + nz * scale
        m = tl.load(mat_id_ptr + tri, mask=hit, other=0)
        mb = mat_ptr + m * 12
        kd_r = tl.load(mb + 0, mask=hit, other=0.0)
        kd_g = tl.load(mb + 1, mask=hit, other=0.0)
        kd_b = tl.load(mb + 2, mask=hit, other=0.0)
        ks_r = tl.load(mb + 3, mask=hit, other=0.0)
        ks_g = tl.load(mb + 4, mask=hit, other=0.0)
        ks_b = tl.load(mb + 5, mask=hit, other=0.0)
        kr_r = tl.load(mb + 6, mask=hit, other=0.0)
        kr_g = tl.load(mb + 7, mask=hit, other=0.0)
        kr_b = tl.load(mb + 8, mask=hit, other=0.0)
        shin = tl.load(mb + 9, mask=hit, other=0.0)
        spec_norm = (shin + 8.0) * (0.125 * inv_pi)
        c_r += tl.where(hit, w_r * amb_r * kd_r, 0.0)
        c_g += tl.where(hit, w_g * amb_g * kd_g, 0.0)
        c_b += tl.where(hit, w_b * amb_b * kd_b, 0.0)
        for li in range(N_LIGHTS):
            lb = light_ptr + li * 8
            lpx = tl.load(lb + 0)
            lpy = tl.load(lb + 1)
            lpz = tl.load(lb + 2)
            is_point = tl.load(lb + 3) > 0.5
            e_r = tl.load(lb + 4)
            e_g = tl.load(lb + 5)
            e_b = tl.load(lb + 6)
            light_reach = tl.load(lb + 7)  # point: OFFSET max(1, |P|inf); directional: unused
            tox = lpx - px
            toy = lpy - py
            toz = lpz - pz
            dist = tl.sqrt(tox * tox + toy * toy + toz * toz)
            lx = tl.where(is_point, tox / dist, lpx)
            ly = tl.where(is_point, toy / dist, lpy)
            lz = tl.where(is_point, toz / dist, lpz)
            falloff = tl.where(is_point, 1.0 / (dist * dist), 1.0)
            s_max = tl.where(is_point, dist - light_reach, inf)
            ndl = nx * lx + ny * ly + nz * lz
            want = hit & (ndl > 0.0)
            _t, occluder, _u2, _v2 = _trace(
                pairs,
                root,
                tris_i,
                root_ref,
                stack_ptr,
                slot,
                stride,
                px,
                py,
                pz,
                lx,
                ly,
                lz,
                zero,
                s_max,
                want,
                True,
                EXIT,
                UNIFORM,
                VEC,
                SANITIZE,
                REGS,
                TRIS,
                SPECULATE,
                False,
            )
            lit = want & (occluder < 0)
            hx = lx - dx
            hy = ly - dy
            hz = lz - dz
            h_len = tl.sqrt(hx * hx + hy * hy + hz * hz)
            ndh = tl.maximum((nx * hx + ny * hy + nz * hz) / h_len, 0.0)
            spec = spec_norm * _pow(ndh, shin)
            g = falloff * ndl
            c_r += tl.where(lit, w_r * e_r * g * (kd_r * inv_pi + ks_r * spec), 0.0)
            c_g += tl.where(lit, w_g * e_g * g * (kd_g * inv_pi + ks_g * spec), 0.0)
            c_b += tl.where(lit, w_b * e_b * g * (kd_b * inv_pi + ks_b * spec), 0.0)
        # Mirror bounce: the next iteration traces r = normalize(d - 2 (d.n) n) from p_off.
        active = hit & ((kr_r > 0.0) | (kr_g > 0.0) | (kr_b > 0.0))
        dn2 = 2.0 * (dx * nx + dy * ny + dz * nz)
        dx = dx - dn2 * nx
        dy = dy - dn2 * ny
        dz = dz - dn2 * nz
        r_len = tl.sqrt(dx * dx + dy * dy + dz * dz)  # renormalised, as the contract says
        dx = dx / r_len
        dy = dy / r_len
        dz = dz / r_len
        ox = px
        oy = py
        oz = pz
        w_r = w_r * kr_r
        w_g = w_g * kr_g
        w_b = w_b * kr_b
    tl.store(out_ptr + slot * 3 + 0, c_r, mask=live)
    tl.store(out_ptr + slot * 3 + 1, c_g, mask=live)
    tl.store(out_ptr + slot * 3 + 2, c_b, mask=live)


_TABLES: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _scene_tables(scene, device, offset: float):
    """Per-face material ids (F,) int32, materials (M, 12) float32 ``kd ks kr shininess``,
    lights (L, 8) float32 ``xyz, is_point, rgb, offset max(1, |P|inf)``, the light count,
    and the ambient and background colours as 6 floats, of a WhittedScene: built once per
    scene, device and offset (cached like its BVH), so a frame launches without host syncs."""
    names = (
        "vertices",
        "faces",
        "material",
        "kd",
        "ks",
        "shininess",
        "kr",
        "point_positions",
        "point_intensities",
        "dir_directions",
        "dir_irradiance",
        "ambient",
        "background",
    )
    for name in names:
        if not isinstance(getattr(scene, name, None), torch.Tensor):
            raise TypeError(
                f"scene: expected a WhittedScene with a {name!r} tensor, got {type(scene).__name__}"
            )
    key = (str(device), offset)
    try:
        cached = _TABLES.setdefault(scene, {})
    except TypeError:  # not weakly referenceable: no cache
        cached = {}
    if key in cached:
        return cached[key]
    f32 = {"dtype": torch.float32, "device": device}
    mats = torch.zeros(scene.kd.shape[0], 12, **f32)
    mats[:, 0:3], mats[:, 3:6], mats[:, 6:9] = scene.kd, scene.ks, scene.kr
    mats[:, 9] = scene.shininess
    pp = scene.point_positions.to(**f32)
    reach = offset * pp.abs().amax(1).clamp(min=1.0) if len(pp) else pp[:, 0]
    point = torch.cat(
        [pp, torch.ones(len(pp), 1, **f32), scene.point_intensities.to(**f32), reach[:, None]], 1
    )
    dd = scene.dir_directions.to(**f32)
    direc = torch.cat(
        [
            dd,
            torch.zeros(len(dd), 1, **f32),
            scene.dir_irradiance.to(**f32),
            torch.zeros(len(dd), 1, **f32),
        ],
        1,
    )
    lights = torch.cat([point, direc], 0).contiguous()
    if not len(lights):
        lights = torch.zeros(1, 8, **f32)  # never read: n_lights = 0
    colours = [float(x) for x in torch.cat([scene.ambient, scene.background]).tolist()]
    cached[key] = (
        scene.material.to(device, torch.int32).contiguous(),
        mats.contiguous(),
        lights,
        len(pp) + len(dd),
        colours,
    )
    return cached[key]


def render_whitted_triton(
    scene,
    origins,
    directions,
    max_depth: int = 2,
    *,
    offset: float | None = None,
    block: int = DEFAULT_BLOCK,
    num_warps: int = DEFAULT_NUM_WARPS,
    bvh: FlatBVH | None = None,
    uniform_branches: bool = DEFAULT_UNIFORM,
    return_info: bool = False,
):
    """Radiance along each primary ray by the Whitted contract, in one kernel launch.

    scene: a ``course.given.lab3.WhittedScene`` (its BVH is cached per scene object
    unless ``bvh`` is given); origins, directions: (N, 3) float primary rays (unit
    directions, e.g. ``course.core.camera.primary_rays``); max_depth: mirror bounces (2: up to
    two reflected rays); offset: the contract's OFFSET (default: whitted_support's).
    Returns (N, 3) float32 linear RGB, or ``(rgb, TracerKernelInfo)`` with ``return_info``.
    """
    _require_triton()
    if isinstance(max_depth, bool) or not isinstance(max_depth, int) or max_depth < 0:
        raise ValueError(f"max_depth: expected an int >= 0, got {max_depth!r}")
    o, d, _, _ = check_rays(origins, directions, 0.0, math.inf)
    _check_launch(block, num_warps)
    n, device = o.shape[0], o.device
    _device_check(device)
    if offset is None:
        from course.given.lab3_scene import OFFSET as offset
    if bvh is None:
        bvh = flat_bvh_for(scene).to(device)
    pairs, root, tris_f, tris_i, root_ref = _bvh_args(bvh, device)
    mat_id, mats, lights, n_lights, colours = _scene_tables(scene, device, float(offset))
    out = torch.empty(n, 3, dtype=torch.float32, device=device)
    handle = None
    if n:
        stack, lanes = _stack(n, block, device, bvh)
        compiled = not interpreting()
        with _ieee_quiet():
            handle = _whitted_kernel[(lanes // block,)](
                o,
                d,
                out,
                n,
                pairs,
                root,
                tris_f,
                tris_i,
                root_ref,
                stack,
                lanes,
                mat_id,
                mats,
                lights,
                *colours,
                float(offset),
                N_LIGHTS=n_lights,
                MAX_DEPTH=max_depth,
                BLOCK=block,
                EXIT=EXIT_SCALE,
                UNIFORM=bool(uniform_branches),
                VEC=compiled,
                SANITIZE=not compiled,
                REGS=UBER_STACK_REGS,
                TRIS=UBER_TRIS_PER_STEP,
                SPECULATE=UBER_SPECULATE,
                num_warps=num_warps,
            )
    if return_info:
        return out, _info("whitted_uber", handle, num_warps, block)
    return out
