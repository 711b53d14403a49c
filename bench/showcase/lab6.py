"""Lab 6 showcase: Suzanne rasterized, smooth-shaded, with ray-traced shadows on a floor.

The inset shows the rasterizer's visibility buffer: the id of the triangle that won each
pixel's depth test, one colour per triangle.

Primary visibility comes from the lab's compute rasterizer (``rasterize_mesh``), shading
from its ``shade`` (interpolated vertex normals, one directional sun), and shadows from its
``hybrid_shadows``: one shadow ray per visible pixel that faces the sun, traced by the small
brute-force tracer below (Suzanne split into 16 groups of triangles, each behind its
bounding box: a one-level BVH, so most shadow rays test a few dozen triangles, not 968).
"""

from __future__ import annotations

import functools
import math
import time

import torch

from course.core.camera import Camera
from course.core.scenes import load_mesh
from course.core.types import Hits, Mesh

SUN = (0.55, -0.35, 1.0)  # toward the sun (Suzanne's file is z-up)
SUN_RGB = (1.0, 0.93, 0.8)
SKY_RGB = (0.16, 0.2, 0.28)  # ambient light
BACKGROUND = (0.05, 0.06, 0.08)
ALBEDO = {"suzanne": (0.85, 0.42, 0.16), "floor": (0.6, 0.6, 0.62)}


def build_scene(device, size: int) -> tuple[Mesh, list[tuple[int, int]], Camera]:
    """Suzanne on a floor quad: (mesh, face ranges per object, camera)."""
    monkey = load_mesh("suzanne", device="cpu", dtype=torch.float64)
    v = monkey.vertices
    lo, hi = v.amin(0), v.amax(0)
    z = float(lo[2]) - 0.02
    floor = torch.tensor(
        [[-6.0, -6.0, z], [6.0, -6.0, z], [6.0, 6.0, z], [-6.0, 6.0, z]], dtype=torch.float64
    )
    n = v.shape[0]
    faces = torch.cat([monkey.faces, torch.tensor([[n, n + 1, n + 2], [n, n + 2, n + 3]])])
    mesh = Mesh(torch.cat([v, floor]).float().to(device), faces.to(device))
    centre = ((lo + hi) / 2).tolist()
    eye = (centre[0] + 1.6, centre[1] - 4.2, centre[2] + 1.7)
    camera = Camera(
        eye=eye,
        target=tuple(centre),
        up=(0.0, 0.0, 1.0),
        fov_y=38.0,
        width=size,
        height=size,
        near=0.05,
        far=100.0,
    )
    return mesh, [(0, monkey.num_faces), (monkey.num_faces, mesh.num_faces)], camera


def _slab(o, d, lo, hi):
    """(N,) bool: rays that enter the box [lo, hi] for some t >= 0."""
    inv = 1 / d
    t0, t1 = (lo - o) * inv, (hi - o) * inv
    near = torch.minimum(t0, t1).nan_to_num(-math.inf).amax(-1)
    far = torch.maximum(t0, t1).nan_to_num(math.inf).amin(-1)
    return far >= near.clamp(min=0)


def _moller_trumbore(tris, o, d, t_min, t_max, pairs=2**20):
    """Nearest hits of rays (N, 3) against triangles (M, 3, 3), in chunks of rays; written
    per component (no (N, M, 3) temporaries)."""
    n = o.shape[0]
    t_best = torch.full((n,), math.inf, dtype=o.dtype, device=o.device)
    tri_best = torch.full((n,), -1, dtype=torch.int64, device=o.device)
    v0 = tris[:, 0]
    e1 = (tris[:, 1] - v0).T[:, None, :]  # (3, 1, M): broadcast against (R, 1) ray components
    e2 = (tris[:, 2] - v0).T[:, None, :]
    step = max(1, pairs // max(1, tris.shape[0]))
    for s in range(0, n, step):
        dx, dy, dz = d[s : s + step, :, None].unbind(1)
        sx, sy, sz = (o[s : s + step, :, None] - v0.T[None]).unbind(1)
        px, py, pz = dy * e2[2] - dz * e2[1], dz * e2[0] - dx * e2[2], dx * e2[1] - dy * e2[0]
        det = e1[0] * px + e1[1] * py + e1[2] * pz
        qx, qy, qz = sy * e1[2] - sz * e1[1], sz * e1[0] - sx * e1[2], sx * e1[1] - sy * e1[0]
        u = (sx * px + sy * py + sz * pz) / det
        v = (dx * qx + dy * qy + dz * qz) / det
        t = (e2[0] * qx + e2[1] * qy + e2[2] * qz) / det
        ok = (
            (det != 0)
            & (u >= 0)
            & (v >= 0)
            & (u + v <= 1)
            & (t >= t_min[s : s + step, None])
            & (t <= t_max[s : s + step, None])
        )
        t = torch.where(ok, t, math.inf)
        t_near, idx = t.min(1)
        t_best[s : s + step] = t_near
        tri_best[s : s + step] = torch.where(t_near < math.inf, idx, -1)
    return t_best, tri_best


def clusters(mesh: Mesh, first: int, last: int, depth: int = 4) -> list[torch.Tensor]:
    """Faces ``first..last-1`` split ``depth`` times at the median centroid along the longest
    axis: ``2**depth`` index tensors with tight boxes (a one-level BVH)."""
    centroids = mesh.triangles()[first:last].mean(1)
    groups = [torch.arange(first, last, device=centroids.device)]
    for _ in range(depth):
        split = []
        for g in groups:
            c = centroids[g - first]
            axis = int((c.amax(0) - c.amin(0)).argmax())
            order = g[c[:, axis].argsort()]
            split += [order[: len(order) // 2], order[len(order) // 2 :]]
        groups = split
    return groups


def trace(mesh: Mesh, groups, origins, directions, t_min, t_max) -> Hits:
    """Closest hits by brute force, group by group behind each group's bounding box."""
    n = origins.shape[0]
    t_best = torch.full((n,), math.inf, dtype=origins.dtype, device=origins.device)
    tri_best = torch.full((n,), -1, dtype=torch.int64, device=origins.device)
    corners = mesh.triangles()
    for faces in groups:
        tris = corners[faces]
        flat = tris.reshape(-1, 3)
        pad = 1e-4 * (flat.amax(0) - flat.amin(0)).norm()
        rays = _slab(origins, directions, flat.amin(0) - pad, flat.amax(0) + pad).nonzero()[:, 0]
        if len(rays) == 0:
            continue
        t, tri = _moller_trumbore(
            tris,
            origins[rays],
            directions[rays],
            t_min[rays],
            torch.minimum(t_max[rays], t_best[rays]),
        )
        nearer = t < t_best[rays]
        t_best[rays] = torch.where(nearer, t, t_best[rays])
        tri_best[rays] = torch.where(nearer, faces[tri.clamp(min=0)], tri_best[rays])
    zeros = torch.zeros_like(t_best)
    return Hits(t=t_best, triangle=tri_best, u=zeros, v=zeros)


def render(lab, device, size: int = 256):
    """``(image (size, size, 3) float linear RGB, info)`` for the gallery."""
    device = torch.device(device)
    mesh, objects, camera = build_scene(device, size)
    sun = torch.tensor(SUN, device=device)

    def timed(fn, *args, **kwargs):
        if device.type == "cuda":
            torch.cuda.synchronize(device)
        start = time.perf_counter()
        result = fn(*args, **kwargs)
        if device.type == "cuda":
            torch.cuda.synchronize(device)
        return result, time.perf_counter() - start

    (face, bary), raster_s = timed(lab.rasterize_mesh, mesh, camera)
    lambert, shade_s = timed(lab.shade, mesh, face, bary, sun, True)
    # Surfaces facing away from the sun are dark anyway: no shadow rays for them.
    lit = torch.where(lambert > 0, face, -1)
    groups = clusters(mesh, *objects[0]) + [torch.arange(*objects[1], device=device)]
    shadowed, shadow_s = timed(
        lab.hybrid_shadows, functools.partial(trace, mesh, groups), mesh, lit, bary, sun
    )

    albedo = torch.tensor(
        [ALBEDO["suzanne"]] * objects[0][1] + [ALBEDO["floor"]] * (objects[1][1] - objects[1][0]),
        device=device,
    )[face.clamp(min=0)]
    light = (
        torch.tensor(SKY_RGB, device=device)
        + torch.tensor(SUN_RGB, device=device) * (lambert * ~shadowed)[..., None]
    )
    image = torch.where(
        (face >= 0)[..., None], albedo * light, torch.tensor(BACKGROUND, device=device)
    )
    # Inset: the visibility buffer itself, one colour per triangle id (the id half of the
    # packed depth|id word each pixel's atomic minimum kept): the rasterizer's output.
    k = max(size // 3, 1)
    rows = torch.arange(k, device=device) * face.shape[0] // k
    cols = torch.arange(k, device=device) * face.shape[1] // k
    ids = face[rows[:, None], cols[None, :]]
    hashed = (ids[..., None] * torch.tensor([2654435761, 40503, 97], device=device)) % 251
    inset = torch.where(
        (ids >= 0)[..., None],
        0.1 + 0.9 * (hashed.float() / 250) ** 2,
        torch.tensor(BACKGROUND, device=device),
    )
    image = image.clone()
    image[: k + 2, : k + 2] = 0.8  # a light frame around the inset
    image[1 : k + 1, 1 : k + 1] = inset
    covered = face >= 0
    info = {
        "triangles": mesh.num_faces,
        "raster_ms": raster_s * 1e3,
        "shade_ms": shade_s * 1e3,
        "shadow_rays": int((lit >= 0).sum()),
        "shadow_ms": shadow_s * 1e3,
        "shadowed_fraction": float((shadowed | (lambert <= 0))[covered].float().mean()),
        "pixels_per_s_raster": size * size / raster_s,
    }
    return image.float(), info
