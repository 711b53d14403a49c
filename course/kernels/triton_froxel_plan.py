"""The scene of the fused froxel pipeline packed into device tables (``_plan``), once per
scene, camera and settings: the layout is :mod:`course.kernels.triton_froxel_lookups`'s.

Given code, not an exercise.
"""

from __future__ import annotations

import math
import weakref

import torch

from course.given.lab5_scene import ConstantFog, DirectionalLight, HeightFog, PointLight, SpotLight
from course.given.lab5_volumes import (
    auto_volume_resolution,
    frustum_bounds,
    light_frame,
    volume_bounds,
)
from course.kernels.triton_froxel_lookups import SIZES

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
    camd = torch.zeros(SIZES["CAM_D"], dtype=f64)
    camd[0:12] = torch.cat([eye, right, up, fwd])
    camd[12], camd[13] = hw, hh
    camf = torch.zeros(SIZES["CAM_F"], dtype=f32)
    camf[0:12] = camd[0:12].to(f32)
    camf[12], camf[13] = hw, hh
    z = grid.near * torch.exp(
        torch.arange(grid.slices + 1, dtype=f64) / grid.slices * math.log(grid.far / grid.near)
    )
    z[0], z[-1] = grid.near, grid.far

    medf = torch.zeros(max(len(scene.media), 1), SIZES["MED_F"], dtype=f32)
    medi = torch.zeros(max(len(scene.media), 1), SIZES["MED_I"], dtype=torch.int32)
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
    shadow_lights = [
        n
        for n, light in enumerate(scene.lights)
        if isinstance(light, DirectionalLight) and light.shadows and scene.occluders
    ]
    # The extinction volume over the media in view (volume_bounds), as light_froxels.
    bounds = volume_bounds(scene, grid) if volumetric_shadows and scene.lights else None
    extinction = bounds is not None
    lo, hi = bounds if extinction else (view_lo, view_hi)
    if extinction and volume_resolution is None:
        volume_resolution = auto_volume_resolution(scene, lo, hi)
    volume_lights = [
        n
        for n, light in enumerate(scene.lights)
        if extinction and not isinstance(light, PointLight)
    ]
    n_vol = len(shadow_lights) + len(volume_lights)
    volf = torch.zeros(max(n_vol, 1), SIZES["VOL_F"], dtype=f32)
    voli = torch.zeros(max(n_vol, 1), SIZES["VOL_I"], dtype=torch.int32)
    lightf = torch.zeros(max(len(scene.lights), 1), SIZES["LIGHT_F"], dtype=f32)
    lighti = torch.full((max(len(scene.lights), 1), SIZES["LIGHT_I"]), -1, dtype=torch.int32)
    lightd = torch.zeros(max(len(scene.lights), 1), SIZES["LIGHT_D"], dtype=f64)
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
                        lift = max(
                            lift,
                            (cx - center[0]) * toward[0]
                            + (cy - center[1]) * toward[1]
                            + (cz - center[2]) * toward[2],
                        )
        origin = tuple(c + (lift + 1.0) * t for c, t in zip(center, toward))
        volume(
            v,
            origin,
            light_frame(tuple(-x for x in toward)),
            radius,
            0.0,
            math.inf,
            0,
            shadow_resolution,
            1,
            4 * radius / shadow_resolution,
        )
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
            volume(
                v,
                origin,
                light_frame(tuple(-x for x in light.direction)),
                box_radius,
                0.0,
                2 * box_radius,
                0,
                volume_resolution,
                k,
                2 * box_radius / (k - 1),
            )
        else:
            volume(
                v,
                light.position,
                light_frame(light.direction),
                math.tan(math.radians(light.outer_deg)),
                0.0,
                light.range,
                1,
                volume_resolution,
                k,
                light.range / (k - 1),
            )
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
        "camf": camf.to(device),
        "camd": camd.to(device),
        "dz": (z[1:] - z[:-1]).to(device),
        "medf": medf.to(device),
        "medi": medi.to(device),
        "textures": textures,
        "lightf": lightf.to(device),
        "lighti": lighti.to(device),
        "lightd": lightd.to(device),
        "volf": volf.to(device),
        "voli": voli.to(device),
        "boxes": boxes.to(device),
        "n_boxes": len(scene.occluders),
        "n_maps": len(shadow_lights),
        "n_volumes": len(volume_lights),
        "first_volume": first_volume,
        "data_size": max(data_offset, 1),
        "extinction": extinction,
        "bounds": bounds,
        "lo": lo32.tolist(),
        "size": size32.tolist(),
        "shadow_resolution": shadow_resolution,
        "volume_resolution": volume_resolution,
    }
    per_scene[key] = plan
    return plan
