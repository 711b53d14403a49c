"""Lab 2 showcase: the work behind every pixel, through a uniform grid and through a BVH.

The Stanford bunny (69K triangles), one primary ray per pixel, four heat maps (log scale,
inferno) in a 2 x 2 mosaic:

    cells visited (grid)       nodes visited (BVH)      1 .. 64 steps
    triangle tests (grid)      triangle tests (BVH)     1 .. 256 tests

The grid walks every ray through every cell on its way, so the rays that miss the bunny
are the expensive ones (the bright frame); the SAH BVH dismisses them at a few boxes and
spends its work at the silhouette. Traced by the lab module passed in (its
``build_grid``/``grid_closest_hit`` and ``build_sah_bvh``/``bvh_closest_hit``), with a
Möller–Trumbore kernel defined here, so a student's labs/ renders too.
"""

from __future__ import annotations

import dataclasses
import math
import time

import torch

from course.core.camera import primary_rays
from course.core.image import srgb_decode
from course.core.scenes import load_scene

TOP = {"steps": 64, "tests": 256}  # the top of each row's colour scale


def moller_trumbore(origins, directions, v0, v1, v2, t_min, t_max):
    """The triangle kernel handed to the lab: ``(t, u, v)``, ``t = inf`` on a miss."""
    e1, e2 = v1 - v0, v2 - v0
    p = torch.linalg.cross(directions, e2, dim=-1)
    det = (e1 * p).sum(-1)
    inv = 1 / det
    s = origins - v0
    q = torch.linalg.cross(s, e1, dim=-1)
    u = (s * p).sum(-1) * inv
    v = (directions * q).sum(-1) * inv
    t = (e2 * q).sum(-1) * inv
    hit = (det != 0) & (u >= 0) & (v >= 0) & (u + v <= 1) & (t >= t_min) & (t <= t_max)
    return (torch.where(hit, t, math.inf), torch.where(hit, u, 0.0), torch.where(hit, v, 0.0))


def heat(count: torch.Tensor, size: int, top: int) -> torch.Tensor:
    """(size, size, 3) linear RGB: log(count) on [0, log top] through inferno (0 is black)."""
    from matplotlib import colormaps

    level = (count.double().clamp(min=1).log() / math.log(top)).clamp(0, 1)
    srgb = torch.as_tensor(colormaps["inferno"](level.cpu().numpy())[..., :3], dtype=torch.float32)
    srgb = torch.where((count.cpu() == 0)[:, None], 0.0, srgb)
    return srgb_decode(srgb).reshape(size, size, 3)


def render(lab, device, size: int = 256):
    """``(image (2 size + 2, 2 size + 2, 3) float linear RGB, info)`` for the gallery."""
    device = torch.device(device)
    scene = load_scene("bunny", device=device)
    mesh = scene.mesh
    rays = primary_rays(dataclasses.replace(scene.camera, width=size, height=size), device=device)
    info = {"triangles": mesh.num_faces, "rays": len(rays)}
    columns = []
    for kind, build, traverse in (
        ("grid", lab.build_grid, lab.grid_closest_hit),
        ("bvh", lab.build_sah_bvh, lab.bvh_closest_hit),
    ):
        start = time.perf_counter()
        structure = build(mesh)
        built = time.perf_counter()
        _, counters = traverse(rays, mesh, structure, moller_trumbore)
        if device.type == "cuda":
            torch.cuda.synchronize(device)
        traced = time.perf_counter()
        info[f"{kind}_build_s"] = built - start
        info[f"{kind}_rays_per_s"] = len(rays) / (traced - built)
        for key in TOP:
            info[f"{kind}_mean_{key}"] = counters[key].double().mean().item()
        gap = torch.ones(2, size, 3)
        columns.append(
            torch.cat(
                (
                    heat(counters["steps"], size, TOP["steps"]),
                    gap,
                    heat(counters["tests"], size, TOP["tests"]),
                ),
                dim=0,
            )
        )
    return torch.cat((columns[0], torch.ones(2 * size + 2, 2, 3), columns[1]), dim=1), info
