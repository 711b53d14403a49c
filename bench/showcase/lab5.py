"""Lab 5 showcase: light shafts in fog. The sun shines through the gaps of a slatted roof
into a hazy hall; the camera looks toward the sun, where forward scattering (g = 0.6) makes
the shafts bright. Two warm point lights and a textured fog bank by the floor add local
light. The whole frame goes through ``render_froxels``: V-buffer, lighting with the sun's
shadow map and volumetric shadows, integration and application to the opaque image.
"""

from __future__ import annotations

import math
import time

import torch

from course.camera import Camera, primary_rays
from course.froxel_support import (
    Box,
    DirectionalLight,
    FogVolume,
    HeightFog,
    PointLight,
    Scene,
    ray_boxes,
)

SUN = (0.25, 0.55, -0.8)  # toward the sun: ahead of the camera, above the roof
ROOF_Y = 7.0


def hall_scene(device) -> Scene:
    """Height fog, a fog bank with a density texture, the sun through a slatted roof."""
    slats = tuple(Box((-14.0, ROOF_Y, z), (14.0, ROOF_Y + 0.4, z + 3.5))
                  for z in torch.arange(-38.0, 6.0, 5.5).tolist())
    g = torch.Generator().manual_seed(3)
    n = 16
    x = (torch.arange(n, dtype=torch.float32) + 0.5) / n
    p = torch.stack(torch.meshgrid(x, x, x, indexing="ij"), -1)
    bank = sum(torch.exp(-(p - c).square().sum(-1) / 0.05)
               for c in 0.25 + 0.5 * torch.rand(5, 3, generator=g))
    bank = (bank / bank.max() * (1 - p[..., 1])).clamp(0, 1)
    media = (HeightFog(scattering=(0.035, 0.037, 0.04), extinction=0.042, g=0.7, base=0.0,
                       falloff=0.05),
             FogVolume(center=(-2.0, 0.8, -12.0), half_size=(5.0, 0.8, 3.0),
                       scattering=(0.5, 0.5, 0.5), extinction=0.55, g=0.3,
                       density=bank.to(device)))
    lights = (DirectionalLight(direction=SUN, irradiance=(14.0, 12.5, 10.0)),
              PointLight(position=(3.0, 1.2, -8.0), intensity=(6.0, 3.0, 1.0), range=8.0),
              PointLight(position=(-4.0, 2.0, -18.0), intensity=(5.0, 2.5, 0.8), range=8.0))
    return Scene(media=media, lights=lights, ambient=(0.02, 0.025, 0.03), occluders=slats)


def opaque_layer(camera: Camera, scene: Scene, device):
    """View depths (H, W) and colours (H, W, 3): a floor lit through the roof, a back wall."""
    rays = primary_rays(camera, device="cpu", dtype=torch.float64)
    o, d = rays.origins.expand_as(rays.directions), rays.directions
    fwd = torch.tensor(camera.target, dtype=torch.float64) - o[0]
    fwd = fwd / fwd.norm()
    t_floor = torch.where(d[:, 1] < 0, -o[:, 1] / d[:, 1].clamp(max=-1e-9), math.inf)
    t_wall = torch.where(d[:, 2] < 0, (-36.0 - o[:, 2]) / d[:, 2].clamp(max=-1e-9), math.inf)
    t_roof = ray_boxes(o, d, scene.occluders)
    t = torch.minimum(torch.minimum(t_floor, t_wall), t_roof)
    t = torch.where(o[:, 1] + t * d[:, 1] <= ROOF_Y + 0.5, t, math.inf)  # above: the sky
    hit = torch.isfinite(t)
    p = o + torch.where(hit, t, 0)[:, None] * d
    sun = torch.tensor(SUN, dtype=torch.float64)
    sun = sun / sun.norm()
    lit = torch.isinf(ray_boxes(p + 1e-3 * sun, sun.expand_as(p), scene.occluders))
    floor = t_floor <= torch.minimum(t_wall, t_roof)
    cos = torch.where(floor, sun[1], -sun[2]).expand_as(t)
    lit = lit & (t_roof > t)  # the slats' undersides face away from the sun
    checker = ((p[:, 0].floor() + p[:, 2].floor()) % 2) * 0.05
    albedo = (0.25 + checker)[:, None] * torch.tensor([1.0, 0.95, 0.85], dtype=torch.float64)
    colour = albedo / math.pi * (14.0 * cos * lit + 0.3)[:, None]
    colour = torch.where(hit[:, None], colour, torch.tensor([1.5, 1.6, 1.8],
                                                            dtype=torch.float64))
    depth = torch.where(hit, t * (d @ fwd), math.inf)
    h, w = camera.height, camera.width
    return (depth.reshape(h, w).to(device, torch.float32),
            colour.reshape(h, w, 3).to(device, torch.float32))


def render(lab, device, size: int = 256):
    """``(image (size, size, 3) float linear RGB, info)`` for the gallery."""
    device = torch.device(device)
    start = time.perf_counter()
    scene = hall_scene(device)
    camera = Camera(eye=(0.0, 1.7, 3.0), target=(1.5, 5.5, -20.0), fov_y=60.0, width=size,
                    height=size)
    depth, opaque = opaque_layer(camera, scene, device)
    image, report = lab.render_froxels(scene, camera, depth, opaque, tile=8, slices=64,
                                       near=0.1, far=45.0, shadow_resolution=512,
                                       volume_resolution=48)
    seconds = time.perf_counter() - start
    grid = report["grid"]
    return image, {"seconds_total": seconds, "froxels": f"{grid.nx}x{grid.ny}x{grid.slices}",
                   "froxels_lit": report["froxels_lit"],
                   "light_evaluations": report["light_evaluations"],
                   "lights": len(scene.lights), "occluders": len(scene.occluders)}
