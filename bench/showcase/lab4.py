"""Lab 4 showcase: a cloud in a box, lit by the sun with single scattering, over a ground
that receives its shadow.

The cloud is a procedural density grid (Gaussian blobs eroded by two octaves of value
noise, flattened at the base). ``march_single_scatter`` integrates the sunlight scattered
once toward the camera (Henyey–Greenstein, g = 0.6: a bright silver lining toward the
sun), with a shadow march per sample and early termination; sky light is added as an
unshadowed isotropic source ``c sigma``, whose integral is exactly ``c (1 - T)`` with the
exact per-step integral (no second march). The ground's sunlight goes through
``shadow_transmittance``: the cloud's shadow. Finally ``L_cloud + T * background``.
"""

from __future__ import annotations

import math
import time

import torch

from course.core.camera import Camera, primary_rays

BOX_MIN, BOX_MAX = (-1.3, 0.25, -1.1), (1.3, 1.45, 1.1)
SUN = (0.75, 0.45, -0.55)  # toward the sun: behind the cloud, to the right
SUN_IRRADIANCE = (9.0, 8.2, 7.0)
SKY = (0.2, 0.26, 0.38)  # ambient sky radiance on the cloud and the ground
ALBEDO = (0.98, 0.98, 0.98)


def cloud_density(lab, n: int, device, generator: torch.Generator) -> torch.Tensor:
    """(n, n, n) float32 extinction grid spanning the box."""
    x = (torch.arange(n, dtype=torch.float32) + 0.5) / n
    p = torch.stack(torch.meshgrid(x, x, x, indexing="ij"), -1)  # box coordinates
    blobs = torch.zeros(n, n, n)
    centres = torch.tensor([0.5, 0.33, 0.5]) + (
        torch.rand(14, 3, generator=generator) - 0.5
    ) * torch.tensor([0.42, 0.16, 0.4])
    radii = 0.10 + 0.12 * torch.rand(14, generator=generator)
    for c, r in zip(centres, radii):
        blobs = blobs + torch.exp(
            -((p - c) / torch.tensor([1.0, 1.3, 1.0])).square().sum(-1) / r**2
        )
    # Value noise: random grids sampled trilinearly (the lab's own sample_grid).
    noise = sum(
        lab.sample_grid(torch.rand(k, k, k, generator=generator), p) / 2**i
        for i, k in enumerate((6, 13))
    )
    base = torch.clamp((p[..., 1] - 0.12) / 0.15, 0, 1)  # flat-bottomed cumulus
    edge = (torch.minimum(p, 1 - p) / 0.15).clamp(0, 1).prod(-1)  # fade out before the faces
    density = (blobs * edge - 0.5 + 0.7 * noise * edge).clamp(min=0) * base * 25.0
    return density.to(device)


def render(lab, device, size: int = 256):
    """``(image (size, size, 3) float linear RGB, info)`` for the gallery."""
    device = torch.device(device)
    start = time.perf_counter()
    generator = torch.Generator().manual_seed(4)
    grid_n = 48 if size >= 192 else 32
    density = cloud_density(lab, grid_n, device, generator)
    camera = Camera(
        eye=(0.0, 0.8, 4.6), target=(0.1, 0.7, 0.0), fov_y=48.0, width=size, height=size
    )
    rays = primary_rays(camera, device=device)
    o, d = rays.origins, rays.directions
    n = len(o)
    f32 = {"dtype": torch.float32, "device": device}
    sun = torch.tensor(SUN, **f32)
    sun = sun / sun.norm()
    sun_rgb, sky, albedo = (torch.tensor(v, **f32) for v in (SUN_IRRADIANCE, SKY, ALBEDO))

    # Background: sky gradient with a sun disc, or the ground plane y = 0.
    up = d[:, 1].clamp(min=0)[:, None]
    background = (1 - up) * torch.tensor([0.75, 0.82, 0.92], **f32) + up * torch.tensor(
        [0.25, 0.42, 0.78], **f32
    )
    background = background + (d @ sun > math.cos(math.radians(1.5)))[:, None] * 20.0 * sun_rgb
    ground = d[:, 1] < 0
    t_ground = torch.where(ground, -o[:, 1] / d[:, 1].clamp(max=-1e-6), 0)
    p_ground = o + t_ground[:, None] * d
    g_idx = ground.nonzero()[:, 0]
    shadow = lab.shadow_transmittance(p_ground[g_idx], sun, BOX_MIN, BOX_MAX, density, 16)
    checker = ((p_ground[g_idx, 0].floor() + p_ground[g_idx, 2].floor()) % 2)[:, None]
    ground_albedo = 0.30 + 0.08 * checker
    fog = torch.exp(-0.04 * t_ground[g_idx])[:, None]  # a little aerial perspective
    lit = ground_albedo * (sun_rgb * sun[1] * shadow[:, None] + sky) / math.pi
    background[g_idx] = fog * lit + (1 - fog) * background[g_idx]

    # The cloud: only rays that meet its box are marched.
    _, _, hit = lab.ray_box_interval(o, d, BOX_MIN, BOX_MAX)
    idx = hit.nonzero()[:, 0]
    steps, shadow_steps = 40, 6
    cloud = lab.march_single_scatter(
        o[idx],
        d[idx],
        BOX_MIN,
        BOX_MAX,
        density,
        albedo,
        sun,
        sun_rgb,
        0.6,
        steps,
        shadow_steps,
        min_transmittance=0.01,
    )
    transmittance = torch.ones(n, **f32)
    transmittance[idx] = cloud["transmittance"]
    radiance = torch.zeros(n, 3, **f32)
    # Sky light as the source sigma * albedo * sky / (4 pi) * 4 pi: exactly (1 - T) times it.
    radiance[idx] = cloud["radiance"] + (1 - cloud["transmittance"])[:, None] * albedo * sky
    image = (radiance + transmittance[:, None] * background).reshape(size, size, 3)
    seconds = time.perf_counter() - start
    return image, {
        "seconds_total": seconds,
        "grid": f"{grid_n}^3",
        "steps": steps,
        "shadow_steps": shadow_steps,
        "rays_marched": len(idx),
        "mean_samples": cloud["samples"].double().mean().item(),
        "phase_g": 0.6,
        "min_transmittance": 0.01,
    }
