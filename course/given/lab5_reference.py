"""The brute-force single-scattering renderer that Lab 5's froxel pipeline is checked against.

Course code, not an exercise: no froxels, no shadow maps, no temporal reuse. Every pixel's
ray (through the pixel centre) is marched in float64 from ``near`` to its opaque depth (or
``far``) with many steps, each integrated exactly for the medium at its midpoint; at every
step the light of every light source is evaluated there with the exact shadow test: a ray
toward the sun against the occluder boxes, and a march of the extinction toward the light.

It models the same scene as the pipeline (so a difference is the pipeline's approximation,
not another model): media up to ``far``; every light's path is attenuated by the media
inside ``volume_bounds(scene, grid)`` (the region the pipeline's volumetric shadows cover:
the media's bounds within the frustum's), each shadow ray marched with ``shadow_steps``
midpoint steps over only its part inside that box; point and spot lights stop at
``range`` and are evaluated no closer than ``MIN_LIGHT_DISTANCE``.
``point_light_shadows=False`` leaves point lights unattenuated, to measure what that
model leaves out. The media and lights are evaluated by code written here, independently
of the lab's.
"""

from __future__ import annotations

import math

import torch

from course.given.lab5_checks import SCHLICK_K_MAX
from course.given.lab5_grid import FroxelGrid, ray_boxes, sample_texture
from course.given.lab5_scene import ConstantFog, DirectionalLight, HeightFog, SpotLight
from course.given.lab5_volumes import MIN_LIGHT_DISTANCE, volume_bounds

F64 = torch.float64


def phase_value(cos_theta: torch.Tensor, g: torch.Tensor, phase: str = "hg") -> torch.Tensor:
    """Henyey–Greenstein (or Schlick's approximation) per steradian, float64."""
    if phase == "schlick":
        k = (1.55 * g - 0.55 * g**3).clamp(-SCHLICK_K_MAX, SCHLICK_K_MAX)
        return (1 - k * k) / (4 * math.pi * (1 - k * cos_theta) ** 2)
    return (1 - g * g) / (4 * math.pi * (1 + g * g - 2 * g * cos_theta) ** 1.5)


def media(scene, p: torch.Tensor):
    """``(sigma_s (N, 3), sigma_t (N,), emissive (N, 3), g (N,))`` at points (N, 3), float64."""
    n = len(p)
    s, t, e, gw = (
        torch.zeros(n, 3, dtype=F64),
        torch.zeros(n, dtype=F64),
        torch.zeros(n, 3, dtype=F64),
        torch.zeros(n, dtype=F64),
    )
    for m in scene.media:
        if isinstance(m, ConstantFog):
            w = torch.ones(n, dtype=F64)
        elif isinstance(m, HeightFog):
            w = torch.exp(-m.falloff * (p[:, 1] - m.base))
        else:
            rot = torch.tensor(m.rotation, dtype=F64)
            q = (
                (p - torch.tensor(m.center, dtype=F64))
                @ rot.T
                / torch.tensor(m.half_size, dtype=F64)
            )
            w = ((q.abs().amax(-1) <= 1) if m.shape == "box" else (q.norm(dim=-1) <= 1)).to(F64)
            if m.density is not None:
                tex = m.density.detach().to("cpu", F64)
                w = w * sample_texture(tex, (q + 1) / 2 * torch.tensor(tex.shape, dtype=F64))
        ss = torch.tensor(m.scattering, dtype=F64)
        s = s + w[:, None] * ss
        t = t + w * m.extinction
        e = e + w[:, None] * torch.tensor(m.emissive, dtype=F64)
        gw = gw + w * ss.mean() * m.g
    ws = s.mean(-1)
    g = torch.where(ws > 0, gw / torch.where(ws > 0, ws, 1.0), 0.0)
    return s, t, e, g


def _clip_to_box(o, d, lo, hi, t_max):
    """The part ``[t0, t1]`` of rays o + t d, 0 <= t <= t_max, inside the box (t1 <= t0: none)."""
    lo, hi = torch.tensor(lo, dtype=F64), torch.tensor(hi, dtype=F64)
    inv = torch.reciprocal(d)
    a, b = (lo - o) * inv, (hi - o) * inv
    t0 = torch.minimum(a, b).nan_to_num(nan=-math.inf).amax(-1).clamp(min=0)
    t1 = torch.minimum(torch.maximum(a, b).nan_to_num(nan=math.inf).amin(-1), t_max)
    return t0, t1


def _optical_depth(scene, p, to_light, t_max, bounds, steps):
    """Optical depth from points p (N, 3) along unit to_light (N, 3) over the part of
    ``[0, t_max]`` inside the box ``bounds``, midpoint rule with ``steps`` steps."""
    t0, t1 = _clip_to_box(p, to_light, *bounds, t_max)
    length = torch.nan_to_num(t1 - t0, nan=0.0).clamp(min=0)
    t0 = torch.where(length > 0, t0, 0)
    tau = torch.zeros(len(p), dtype=F64)
    for i in range(steps):
        t = t0 + (i + 0.5) / steps * length
        tau = tau + media(scene, p + t[:, None] * to_light)[1] * length / steps
    return tau


def _in_light(scene, light, p, view, g, phase, bounds, shadow_steps, point_light_shadows):
    """Light scattered per unit sigma_s toward the camera at p (N, 3): (N, 3)."""
    if isinstance(light, DirectionalLight):
        to_light = torch.tensor(light.direction, dtype=F64).expand_as(p)
        e = torch.tensor(light.irradiance, dtype=F64).expand(len(p), 3)
        if light.shadows and scene.occluders:
            e = e * torch.isinf(ray_boxes(p, to_light, scene.occluders)).to(F64)[:, None]
        t_max = torch.full((len(p),), math.inf, dtype=F64)
        march = bounds is not None
    else:
        rel = torch.tensor(light.position, dtype=F64) - p
        dist = rel.norm(dim=-1)
        to_light = rel / dist.clamp(min=MIN_LIGHT_DISTANCE)[:, None]
        fall = torch.where(dist < light.range, dist.clamp(min=MIN_LIGHT_DISTANCE) ** -2, 0.0)
        if isinstance(light, SpotLight):
            c = -(to_light @ torch.tensor(light.direction, dtype=F64))
            lo, hi = (math.cos(math.radians(x)) for x in (light.outer_deg, light.inner_deg))
            s = ((c - lo) / (hi - lo)).clamp(0, 1)
            fall = fall * s * s * (3 - 2 * s)
        e = fall[:, None] * torch.tensor(light.intensity, dtype=F64)
        t_max = dist
        march = bounds is not None and (isinstance(light, SpotLight) or point_light_shadows)
    e = e * phase_value((view * to_light).sum(-1), g, phase)[:, None]
    if march:
        e = e * torch.exp(-_optical_depth(scene, p, to_light, t_max, bounds, shadow_steps))[:, None]
    return e


def reference_render(
    scene,
    camera,
    depth_image,
    opaque_image,
    *,
    near=0.1,
    far=100.0,
    tile=8,
    slices=64,
    samples=256,
    shadow_steps=64,
    pixels=None,
    phase="hg",
    volumetric_shadows=True,
    point_light_shadows=True,
    chunk=2048,
):
    """Single scattering per pixel, by brute force, in float64 on the CPU.

    depth_image (H, W) view depths (+inf: sky), opaque_image (H, W, 3); pixels: None (all,
    row-major) or a (P,) int64 tensor of flat pixel indices ``row * W + col``. ``tile`` and
    ``slices`` only name the grid whose ``volume_bounds`` limit the volumetric shadows (they
    do not depend on them); ``chunk`` pixels are marched at once. Returns a dict of ``image``
    (P, 3) = ``opaque T + L``, ``inscatter`` (P, 3) and ``transmittance`` (P,), float64.
    """
    grid = FroxelGrid(camera, tile, slices, near, far)
    eye, right, up, fwd, (hw, hh) = grid.axes()
    h, w = camera.height, camera.width
    if pixels is None:
        pixels = torch.arange(h * w)
    pixels = pixels.to("cpu", torch.int64)
    depth = depth_image.detach().to("cpu", F64).reshape(-1)[pixels]
    opaque = opaque_image.detach().to("cpu", F64).reshape(-1, 3)[pixels]
    bounds = volume_bounds(scene, grid) if volumetric_shadows else None
    ambient = torch.tensor(scene.ambient, dtype=F64)
    out_l, out_t = [], []
    for start in range(0, len(pixels), chunk):
        idx = pixels[start : start + chunk]
        row, col = (idx // w).to(F64), (idx % w).to(F64)
        d = (
            fwd
            + ((2 * (col + 0.5) / w - 1) * hw)[:, None] * right
            + ((1 - 2 * (row + 0.5) / h) * hh)[:, None] * up
        )  # unit view depth
        stretch = d.norm(dim=-1)
        view = d / stretch[:, None]
        z_end = depth[start : start + len(idx)].clamp(min=near, max=far)
        dz = (z_end - near) / samples
        radiance = torch.zeros(len(idx), 3, dtype=F64)
        transmittance = torch.ones(len(idx), dtype=F64)
        for i in range(samples):
            p = eye + (near + (i + 0.5) * dz)[:, None] * d
            s, t, e, g = media(scene, p)
            src = e + s * ambient
            if scene.lights and bool((s > 0).any()):
                light_sum = torch.zeros_like(src)
                for light in scene.lights:
                    light_sum = light_sum + _in_light(
                        scene, light, p, view, g, phase, bounds, shadow_steps, point_light_shadows
                    )
                src = src + s * light_sum
            ds = dz * stretch
            tau = t * ds
            phi = torch.where(tau > 1e-8, -torch.expm1(-tau) / tau.clamp(min=1e-300), 1 - tau / 2)
            radiance = radiance + transmittance[:, None] * src * (ds * phi)[:, None]
            transmittance = transmittance * torch.exp(-tau)
        out_l.append(radiance)
        out_t.append(transmittance)
    inscatter, transmittance = torch.cat(out_l), torch.cat(out_t)
    return {
        "image": opaque * transmittance[:, None] + inscatter,
        "inscatter": inscatter,
        "transmittance": transmittance,
    }
