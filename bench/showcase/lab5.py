"""Lab 5 showcase: light shafts in a hazy hall. The sun stands low outside the left wall and
shines in through its tall windows; the pillars between them and the roof throw volumetric
shadows into the haze, so each window sends a bright shaft down across the dark hall onto
the floor, where it ends in a lit patch. The camera stands by the right wall looking up
toward the windows (forward scattering, g = 0.72, makes the shafts bright on that side). A
warm lamp at the back of the hall, inside the haze, adds a local light whose glow the
haze dims with distance. The whole frame goes through ``render_froxels``: V-buffer,
lighting with the sun's shadow map and volumetric shadows, integration and application to
the opaque image (floor, walls and the sky seen through the windows).
"""

from __future__ import annotations

import math
import time

import torch

from course.core.camera import Camera, primary_rays
from course.given.lab5 import (
    Box,
    DirectionalLight,
    HeightFog,
    PointLight,
    Scene,
    ray_boxes,
)

SUN = (-0.75, 0.55, -0.25)  # toward the sun: outside the left wall, above the windows
SUN_IRRADIANCE = (30.0, 25.5, 19.0)
HALL = ((-8.0, 0.0, -30.0), (8.0, 9.0, 3.0))  # the room's inside
WINDOWS = [(-26.0 + 4.5 * i, -24.3 + 4.5 * i) for i in range(6)]  # z spans of the openings
SILL, LINTEL = 2.0, 7.0


def hall_walls() -> tuple:
    """The occluders: roof, the left wall with its window openings, the other walls."""
    (x0, y0, z0), (x1, y1, z1) = HALL
    t = 0.5
    boxes = [
        Box((x0 - t - 1, y1, z0 - t - 1), (x1 + t + 1, y1 + t, z1 + t + 1)),  # roof
        Box((x0 - t, y0, z0 - t), (x0, SILL, z1 + t)),  # left wall below the windows
        Box((x0 - t, LINTEL, z0 - t), (x0, y1, z1 + t)),  # ... above them
        Box((x1, y0, z0 - t), (x1 + t, y1, z1 + t)),  # right wall
        Box((x0 - t, y0, z0 - t), (x1 + t, y1, z0)),  # back wall
        Box((x0 - t, y0, z1), (x1 + t, y1, z1 + t)),
    ]  # front wall, behind the camera
    edges = [z0 - t, *[z for w in WINDOWS for z in w], z1 + t]
    for a, b in zip(edges[::2], edges[1::2]):  # the pillars between the openings
        boxes.append(Box((x0 - t, SILL, a), (x0, LINTEL, b)))
    return tuple(boxes)


def hall_scene() -> Scene:
    media = (
        HeightFog(
            scattering=(0.06, 0.061, 0.065), extinction=0.068, g=0.72, base=0.0, falloff=0.08
        ),
    )
    lights = (
        DirectionalLight(direction=SUN, irradiance=SUN_IRRADIANCE),
        PointLight(position=(4.5, 2.2, -25.0), intensity=(9.0, 4.5, 1.5), range=14.0),
    )
    return Scene(media=media, lights=lights, ambient=(0.004, 0.005, 0.007), occluders=hall_walls())


def opaque_layer(camera: Camera, scene: Scene, device):
    """View depths (H, W) and colours (H, W, 3): the hall's floor and walls, lit by the sun
    through the windows and by the lamp, and the sky through the openings."""
    rays = primary_rays(camera, device="cpu", dtype=torch.float64)
    o, d = rays.origins.expand_as(rays.directions), rays.directions
    fwd = torch.tensor(camera.target, dtype=torch.float64) - o[0]
    fwd = fwd / fwd.norm()
    t_floor = torch.where(d[:, 1] < 0, -o[:, 1] / d[:, 1].clamp(max=-1e-9), math.inf)
    t_wall = ray_boxes(o, d, scene.occluders)
    t = torch.minimum(t_floor, t_wall)
    hit = torch.isfinite(t)
    p = o + torch.where(hit, t, 0)[:, None] * d
    sun = torch.tensor(SUN, dtype=torch.float64)
    sun = sun / sun.norm()
    floor = t_floor <= t_wall
    # Lambert on the floor (normal +y) and on the walls (the face the ray hit).
    eps = 1e-6 * (1 + t.clamp(max=1e3))
    inside = (p > torch.tensor(HALL[0], dtype=torch.float64) - 1e-3) & (
        p < torch.tensor(HALL[1], dtype=torch.float64) + 1e-3
    )
    normal = torch.zeros_like(p)
    normal[:, 1] = 1.0
    for axis in (0, 2):
        lo_face = (p[:, axis] - HALL[0][axis]).abs() < 1e-3
        hi_face = (p[:, axis] - HALL[1][axis]).abs() < 1e-3
        normal[:, axis] = torch.where(
            lo_face & ~floor, 1.0, torch.where(hi_face & ~floor, -1.0, normal[:, axis])
        )
        normal[:, 1] = torch.where((lo_face | hi_face) & ~floor, 0.0, normal[:, 1])
    cos = (normal @ sun).clamp(min=0)
    lit = torch.isinf(ray_boxes(p + (eps[:, None] + 1e-3) * sun, sun.expand_as(p), scene.occluders))
    lamp = scene.lights[1]
    to_lamp = torch.tensor(lamp.position, dtype=torch.float64) - p
    dist = to_lamp.norm(dim=-1).clamp(min=0.3)
    lamp_e = (to_lamp / dist[:, None] * normal).sum(-1).clamp(min=0) / dist.square()
    checker = ((p[:, 0].floor() + p[:, 2].floor()) % 2) * 0.04
    albedo = torch.where(floor, 0.22 + checker, 0.35)[:, None] * torch.tensor(
        [1.0, 0.93, 0.84], dtype=torch.float64
    )
    irradiance = (
        torch.tensor(SUN_IRRADIANCE, dtype=torch.float64) * (cos * lit)[:, None]
        + lamp_e[:, None] * torch.tensor(lamp.intensity, dtype=torch.float64)
        + 0.05
    )
    colour = albedo / math.pi * irradiance
    through = ~inside.all(-1) | ~hit  # seen through a window: the sky
    colour = torch.where(
        through[:, None], torch.tensor([1.4, 1.6, 2.0], dtype=torch.float64), colour
    )
    depth = torch.where(hit & ~through, t * (d @ fwd), math.inf)
    h, w = camera.height, camera.width
    return (
        depth.reshape(h, w).to(device, torch.float32),
        colour.reshape(h, w, 3).to(device, torch.float32),
    )


def render(lab, device, size: int = 256):
    """``(image (size, size, 3) float linear RGB, info)`` for the gallery."""
    device = torch.device(device)
    start = time.perf_counter()
    scene = hall_scene()
    camera = Camera(
        eye=(6.0, 1.6, 1.5), target=(-3.0, 4.2, -13.0), fov_y=62.0, width=size, height=size
    )
    depth, opaque = opaque_layer(camera, scene, device)
    image, report = lab.render_froxels(
        scene,
        camera,
        depth,
        opaque,
        tile=4,
        slices=64,
        near=0.1,
        far=45.0,
        shadow_resolution=1024,
        volume_resolution=48,
    )
    seconds = time.perf_counter() - start
    grid = report["grid"]
    return image, {
        "seconds_total": seconds,
        "froxels": f"{grid.nx}x{grid.ny}x{grid.slices}",
        "froxels_lit": report["froxels_lit"],
        "light_evaluations": report["light_evaluations"],
        "lights": len(scene.lights),
        "occluders": len(scene.occluders),
    }
