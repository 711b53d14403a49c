"""Lab 1 showcase: Suzanne on a floor next to a sphere and a box, traced with the lab's kernels.

Every surface is one of the lab's tests: Suzanne (968 triangles) and the floor (two) go
through ``lab.closest_hit`` (Möller–Trumbore, brute force), the sphere through
``lab.ray_sphere``, the box through ``lab.ray_box``; the nearest wins. Only rays that
enter Suzanne's bounding box (``lab.ray_box`` again) are tested against her triangles: a
box test costs a third of a triangle test, and this one spares most rays 968 of them, the
first acceleration structure. Shading is Lambert by the geometric normal under one
directional light, with shadow rays traced the same way.

The inset is the crack test: a closed icosphere moved to 1e6, traced with Woop's
unit-triangle test in float32. Red pixels are rays through the ball inscribed in the mesh,
which must hit it, that hit nothing.
"""

from __future__ import annotations

import math

import torch

from course.core.camera import Camera, primary_rays
from course.core.raymath import cross, dot
from course.core.scenes import load_scene
from course.core.types import Hits, Mesh, Rays
from course.measure.bench import time_fn

VARIANT = "moller_trumbore"
LIGHT = (-0.6, 0.65, 0.3)  # towards the light
AMBIENT = 0.12
FLOOR_Y = -0.86  # just below Suzanne's chin
SPHERE = ((2.35, FLOOR_Y + 0.7, -0.4), 0.7)  # centre, radius
BOX = ((-3.05, FLOOR_Y, -0.9), (-1.85, FLOOR_Y + 1.0, 0.3))  # min, max corner
ALBEDO = ((0.80, 0.42, 0.16), (0.16, 0.32, 0.80), (0.22, 0.62, 0.26))  # Suzanne, sphere, box
CRACK_RED = (1.0, 0.0, 0.0)


def render(lab, device, size: int = 256):
    """``(image (size, size, 3) float linear RGB, info)`` for the gallery."""
    device = torch.device(device)
    scene = _scene(device)
    camera = Camera(
        eye=(0.0, 1.5, 6.6), target=(0.0, -0.05, 0.0), fov_y=46.0, width=size, height=size
    )
    rays = primary_rays(camera, device, torch.float32)
    # closest_hit's tiles of rays x triangles: a few hundred MiB of temporaries on the CPU
    # (the fastest of the budgets tried there); a GPU takes larger tiles, fewer launches.
    budget = 2**30 if device.type == "cuda" else 2**28

    result = {}

    def trace_primary():
        result["surface"] = _nearest_surface(lab, scene, rays, budget)

    cpu = device.type != "cuda"
    timing = time_fn(trace_primary, repeats=1 if cpu else 5, warmup=0 if cpu else 1, device=device)
    t, normal, albedo, triangle_tests = result["surface"]
    hit = torch.isfinite(t)

    # Shadow rays towards the light from every visible point that faces it, started a
    # little off the surface (along the normal) so they do not hit the surface they leave.
    light = torch.tensor(LIGHT, device=device)
    light = light / light.norm()
    cosine = (normal * light).sum(-1).clamp(min=0)
    facing = cosine > 0
    points = rays.at(torch.where(facing, t, torch.zeros_like(t)))[facing]
    shadow = Rays.create(points + 1e-3 * normal[facing], light.repeat(len(points), 1))
    blocked = torch.isfinite(_nearest_surface(lab, scene, shadow, budget)[0])
    lit = torch.zeros_like(t)
    lit[facing] = (~blocked).to(t.dtype)

    shade = albedo * (AMBIENT + (1 - AMBIENT) * cosine * lit)[:, None]
    image = torch.where(hit[:, None], shade, _sky(rays.directions)).reshape(size, size, 3)

    inset, cracks = crack_view(lab, "woop_unit", max(24, size // 3), device)
    info = {
        "variant": VARIANT,
        "triangles": scene["suzanne"].num_faces + 2,
        "rays": len(rays),
        "rays_per_s": len(rays) / timing.median,
        "triangle_tests": triangle_tests,
        "shadow_rays": len(shadow),
        "inset": f"woop_unit, float32, icosphere at 1e6: {cracks['crack_pixels']} crack "
        f"pixels (red) of {cracks['must_hit_pixels']} that must hit",
    }
    return _paste_inset(image, inset), info


def crack_view(
    lab,
    variant: str,
    size: int,
    device,
    offset: float = 1e6,
    level: int = 2,
    dtype: torch.dtype = torch.float32,
):
    """A closed icosphere moved by ``offset`` on every axis, traced with ``variant``.

    Returns ``(image (size, size, 3) float linear RGB, info)``: Lambert-shaded hits, crack
    pixels in red, a dark background. A crack pixel is a ray that passes through the ball
    inscribed in the mesh (centre at ``offset``, radius the smallest distance from it to a
    triangle's plane, from the vertices as rounded to ``dtype``), so it must cross the
    closed surface, but hits no triangle. The camera moves along with the sphere; its eye
    lies on the ``dtype`` grid, so the rays are the same at every offset.
    info: ``crack_pixels``, ``must_hit_pixels``, ``hit_pixels``.
    """
    device = torch.device(device)
    sphere = load_scene("icosphere", level=level, device="cpu", dtype=torch.float64).mesh
    mesh = Mesh((sphere.vertices + offset).to(dtype), sphere.faces).to(device)
    camera = Camera(
        eye=(offset + 0.5, offset + 0.75, offset + 3.0),
        target=(offset, offset, offset),
        fov_y=40.0,
        width=size,
        height=size,
    )
    rays = primary_rays(camera, device, dtype)
    hits = lab.closest_hit(rays, mesh, variant)

    # The inscribed ball, in float64 from the rounded vertices: no triangle is nearer to the
    # centre than its plane, so the ball touches no triangle and lies inside the mesh.
    corners = mesh.triangles().double()
    centre = torch.full((3,), offset, dtype=torch.float64, device=device)
    normal = cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    normal = normal / normal.norm(dim=-1, keepdim=True)
    radius = dot(corners[:, 0] - centre, normal).abs().min() * (1 - 1e-9)
    to_centre = centre - rays.origins.double()
    direction = rays.directions.double()
    direction = direction / direction.norm(dim=-1, keepdim=True)
    along = dot(to_centre, direction)
    must_hit = (along > 0) & (dot(to_centre, to_centre) - along**2 < radius**2)
    cracks = must_hit & ~hits.hit

    light = torch.tensor(LIGHT, device=device)
    cosine = (_face_normals(mesh, hits, rays) * (light / light.norm())).sum(-1).clamp(min=0)
    grey = (0.08 + 0.7 * cosine)[:, None].expand(-1, 3)
    image = torch.where(hits.hit[:, None], grey, torch.tensor((0.02, 0.02, 0.03), device=device))
    image = torch.where(cracks[:, None], torch.tensor(CRACK_RED, device=device), image)
    info = {
        "crack_pixels": int(cracks.sum()),
        "must_hit_pixels": int(must_hit.sum()),
        "hit_pixels": int(hits.hit.sum()),
    }
    return image.reshape(size, size, 3), info


def _scene(device) -> dict:
    """Suzanne (turned to face the camera at +z) with her bounding box, and the floor: a
    square of two triangles under her. float32 on ``device``."""
    suzanne = load_scene("suzanne", device=device, dtype=torch.float32).mesh
    half_turn = torch.tensor([-1.0, 1.0, -1.0], device=device)  # 180 degrees about y
    suzanne = Mesh(suzanne.vertices * half_turn, suzanne.faces)
    s = 6.0
    floor = Mesh(
        torch.tensor(
            [[-s, FLOOR_Y, -s], [-s, FLOOR_Y, s], [s, FLOOR_Y, s], [s, FLOOR_Y, -s]], device=device
        ),
        torch.tensor([[0, 1, 2], [0, 2, 3]], device=device),
    )
    return {
        "suzanne": suzanne,
        "bounds": (suzanne.vertices.amin(0), suzanne.vertices.amax(0)),
        "floor": floor,
    }


def _trace_culled(lab, mesh: Mesh, bounds, rays: Rays, budget: int) -> tuple[Hits, int]:
    """``closest_hit`` on the rays that enter ``mesh``'s bounding box; the rest miss.
    Returns the hits of all rays and the number of ray-triangle tests made."""
    _, _, inside = lab.ray_box(
        rays.origins, lab.safe_reciprocal(rays.directions), *bounds, rays.t_min, rays.t_max
    )
    index = inside.nonzero()[:, 0]
    found = lab.closest_hit(rays[index], mesh, VARIANT, budget)
    hits = Hits.miss(len(rays), dtype=rays.dtype, device=rays.origins.device)
    for name in ("t", "triangle", "u", "v"):
        getattr(hits, name)[index] = getattr(found, name)
    return hits, len(index) * mesh.num_faces


def _face_normals(mesh: Mesh, hits: Hits, rays: Rays) -> torch.Tensor:
    """Unit geometric normals (N, 3) of the hit triangles, facing the ray (0 on a miss),
    computed in float64 (the triangles may lie far from the origin) and returned in the
    rays' dtype."""
    corners = mesh.triangles()[hits.triangle.clamp(min=0)].double()
    n = cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    n = n / n.norm(dim=-1, keepdim=True).clamp(min=1e-300)
    n = torch.where(dot(n, rays.directions.double())[:, None] > 0, -n, n)
    return torch.where(hits.hit[:, None], n, torch.zeros_like(n)).to(rays.dtype)


def _nearest_surface(lab, scene: dict, rays: Rays, budget: int):
    """``(t, normal, albedo, triangle_tests)`` of the nearest of Suzanne, the floor, the
    sphere and the box: t (N,) inf on a miss; normal (N, 3) unit, facing the ray;
    albedo (N, 3); triangle_tests: ray-triangle tests made."""
    device = rays.origins.device
    o, d = rays.origins, rays.directions
    suzanne, tests = _trace_culled(lab, scene["suzanne"], scene["bounds"], rays, budget)
    floor = lab.closest_hit(rays, scene["floor"], VARIANT, budget)
    centre, radius = torch.tensor(SPHERE[0], device=device), SPHERE[1]
    t_sphere = lab.ray_sphere(o, d, centre, radius, rays.t_min, rays.t_max)
    box_min, box_max = (torch.tensor(c, device=device) for c in BOX)
    t_near, _, box_hit = lab.ray_box(
        o, lab.safe_reciprocal(d), box_min, box_max, rays.t_min, rays.t_max
    )
    t_box = torch.where(box_hit, t_near, torch.full_like(t_near, math.inf))

    t, which = torch.stack([suzanne.t, t_sphere, t_box, floor.t]).min(dim=0)
    p = rays.at(torch.where(torch.isfinite(t), t, torch.zeros_like(t)))
    # Box normal: the axis on which the point lies farthest out, relative to the half size.
    rel = (p - (box_min + box_max) / 2) / ((box_max - box_min) / 2)
    axis = rel.abs().argmax(dim=-1, keepdim=True)
    box_normal = torch.zeros_like(p).scatter(-1, axis, rel.gather(-1, axis).sign())
    up = torch.tensor([0.0, 1.0, 0.0], device=device).expand_as(p)
    normals = torch.stack(
        [_face_normals(scene["suzanne"], suzanne, rays), (p - centre) / radius, box_normal, up]
    )
    normal = normals.gather(0, which[None, :, None].expand(1, -1, 3))[0]
    checker = 0.35 + 0.35 * ((p[:, 0].floor() + p[:, 2].floor()) % 2 == 0).to(p.dtype)
    albedo = torch.tensor(ALBEDO, device=device)[which.clamp(max=2)]
    albedo = torch.where((which == 3)[:, None], checker[:, None].expand(-1, 3), albedo)
    return t, normal, albedo, tests + 2 * len(rays)


def _sky(directions: torch.Tensor) -> torch.Tensor:
    """A blue gradient by the ray's elevation: (N, 3) linear RGB."""
    up = (directions[:, 1] / directions.norm(dim=-1)).clamp(0, 1)[:, None]
    horizon = torch.tensor((0.60, 0.70, 0.85), device=directions.device)
    zenith = torch.tensor((0.18, 0.32, 0.62), device=directions.device)
    return horizon + (zenith - horizon) * up


def _paste_inset(image: torch.Tensor, inset: torch.Tensor, border: int = 2) -> torch.Tensor:
    """``inset`` in the top-left corner of ``image``, framed in white."""
    h, w = inset.shape[:2]
    out = image.clone()
    out[: h + 2 * border, : w + 2 * border] = 1.0
    out[border : border + h, border : border + w] = inset
    return out
