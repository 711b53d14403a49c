"""Lab 3's brute-force tracer (the given ``trace`` callable) and its slow, obvious reference
renderer of the shading contract.

Given code, not exercises (imported through :mod:`course.given.lab3`, whose docstring
states the scene and shading contract).
"""

from __future__ import annotations

import math

import torch

from course.core.raymath import dot, normalize
from course.core.types import Hits
from course.given.lab3_checks import check_max_depth, check_scene
from course.given.lab3_scene import (
    BYTES_PER_PAIR,
    MAX_DEPTH,
    MEMORY_BUDGET_BYTES,
    WhittedScene,
    face_normals,
    offset_scale,
)


def pair_tiles(n: int, f: int):
    """Tiles of (ray, triangle) pairs within ``MEMORY_BUDGET_BYTES``: yields ``(rows,
    tiles)``, a slice of the N rays and a generator of slices of the F triangles; all
    triangles at once for many rays, or a few rays against chunks of the triangles."""
    pairs = max(1, MEMORY_BUDGET_BYTES // BYTES_PER_PAIR)
    ray_tile = max(1, min(n, pairs // max(f, 1)))
    tri_tile = max(1, min(f, pairs // ray_tile))
    for r0 in range(0, n, ray_tile):
        yield slice(r0, r0 + ray_tile), (slice(f0, f0 + tri_tile) for f0 in range(0, f, tri_tile))


def trace_brute_force(
    scene: WhittedScene,
    origins: torch.Tensor,
    directions: torch.Tensor,
    t_min: torch.Tensor,
    t_max: torch.Tensor,
    any_hit: bool = False,
) -> Hits:
    """Every ray against every triangle (Möller-Trumbore in the scene's dtype), in tiles.

    origins, directions: (N, 3); t_min, t_max: (N,); all of the scene's dtype and device.
    Returns Hits (N,): the nearest hit in the closed interval ``[t_min, t_max]`` (among
    equal ``t`` the lowest triangle index); with ``any_hit`` any hit in it (a tile of
    triangles that leaves every ray of the tile blocked ends the search early).

    Tiles of at most ``MEMORY_BUDGET_BYTES / BYTES_PER_PAIR`` (ray, triangle) pairs: never
    an N x F allocation. Rays with NaN/inf components or a zero direction miss. The edge
    tests are inclusive (``u >= 0, v >= 0, u + v <= 1``), so a ray through a shared edge
    hits at least one of its triangles up to the rounding of u and v ("watertight enough"
    for images; Lab 1's watertight test is exact).
    """
    n, f = origins.shape[0], scene.num_faces
    corners = scene.vertices[scene.faces]
    v0, e1, e2 = corners[:, 0], corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]
    hits = Hits.miss(n, dtype=origins.dtype, device=origins.device)
    valid = (
        torch.isfinite(origins).all(1)
        & torch.isfinite(directions).all(1)
        & (directions != 0).any(1)
        & ~(t_min > t_max)
    )
    t_out, i_out, u_out, v_out = hits.t, hits.triangle, hits.u, hits.v
    for rows, tiles in pair_tiles(n, f):
        o, d = origins[rows, None], directions[rows, None]
        lo, hi, ok = t_min[rows, None], t_max[rows, None], valid[rows, None]
        for cols in tiles:
            f0 = cols.start
            p = torch.linalg.cross(d, e2[None, cols], dim=-1)
            det = (e1[None, cols] * p).sum(-1)
            inv = 1 / det
            s = o - v0[None, cols]
            q = torch.linalg.cross(s, e1[None, cols], dim=-1)
            u = (s * p).sum(-1) * inv
            v = (d * q).sum(-1) * inv
            t = (e2[None, cols] * q).sum(-1) * inv
            hit = ok & (det != 0) & (u >= 0) & (v >= 0) & (u + v <= 1) & (t >= lo) & (t <= hi)
            t = torch.where(hit, t, math.inf)
            best = t.argmin(dim=1, keepdim=True)
            tb = t.gather(1, best)[:, 0]
            better = tb < t_out[rows]
            t_out[rows] = torch.where(better, tb, t_out[rows])
            i_out[rows] = torch.where(better, best[:, 0] + f0, i_out[rows])
            u_out[rows] = torch.where(better, u.gather(1, best)[:, 0], u_out[rows])
            v_out[rows] = torch.where(better, v.gather(1, best)[:, 0], v_out[rows])
            if any_hit and bool((t_out[rows] < math.inf).all()):
                break  # every ray of this tile is blocked: the shadow test is decided
    return hits


# ---------------------------------------------------------------------------------------
# The reference renderer


def render_reference(
    scene: WhittedScene, origins: torch.Tensor, directions: torch.Tensor, max_depth: int = MAX_DEPTH
) -> torch.Tensor:
    """The slow, obvious Whitted renderer every organisation is compared with.

    scene: float32 or float64; origins, directions: (N, 3), directions unit. Returns (N, 3)
    float64 radiance. Everything is computed in float64 with :func:`trace_brute_force`,
    but with the secondary-ray offset of the *scene's* dtype (:func:`offset_scale`): the
    same contract as a renderer working in that dtype, so what remains between the two is
    the renderer's rounding. The recursion is the contract written out plainly, one bounce
    level at a time, one light at a time, a shadow ray for every (hit, light) pair.
    """
    check_scene(scene)
    check_max_depth(max_depth)
    eps = offset_scale(scene.dtype)
    scene = scene.to(torch.float64)
    return _radiance(
        scene,
        origins.to(scene.device, torch.float64),
        directions.to(scene.device, torch.float64),
        0,
        max_depth,
        eps,
    )


def _radiance(scene: WhittedScene, o, d, depth: int, max_depth: int, eps: float):
    n_rays = o.shape[0]
    zeros = torch.zeros(n_rays, dtype=o.dtype, device=o.device)
    hits = trace_brute_force(scene, o, d, zeros, zeros + math.inf, any_hit=False)
    result = scene.background.expand(n_rays, 3).clone()
    h = hits.hit
    if not h.any():
        return result
    o, d, t, tri = o[h], d[h], hits.t[h], hits.triangle[h]
    m = scene.material[tri]
    p = o + t[:, None] * d
    n = face_normals(scene)[tri]
    n = torch.where(dot(n, d)[:, None] > 0, -n, n)
    p_off = p + n * eps * p.abs().amax(1, keepdim=True).clamp(min=1)
    v = -d
    kd, ks, s, kr = scene.kd[m], scene.ks[m], scene.shininess[m], scene.kr[m]
    radiance = scene.ambient * kd
    lights = [
        (
            scene.point_positions[i] - p_off,
            scene.point_intensities[i],
            eps * max(1.0, scene.point_positions[i].abs().max().item()),
        )
        for i in range(scene.num_point_lights)
    ]
    lights += [
        (scene.dir_directions[j].expand_as(p_off), scene.dir_irradiance[j], None)
        for j in range(scene.num_dir_lights)
    ]
    for to, power, light_offset in lights:
        if light_offset is None:  # directional: arrives everywhere with the same irradiance
            dist = torch.full_like(t, math.inf)
            l, irradiance = to, power.expand_as(p)
        else:  # point: inverse-square falloff, the shadow ray ends just short of the light
            dist = to.norm(dim=1)
            l, irradiance = to / dist[:, None], power / (dist**2)[:, None]
        t_max = dist - light_offset if light_offset is not None else dist
        blocked = trace_brute_force(scene, p_off, l, torch.zeros_like(t), t_max, any_hit=True).hit
        cos = dot(n, l)
        half = normalize(l + v)
        lobe = (s + 8) / (8 * math.pi) * dot(n, half).clamp(min=0) ** s
        brdf = kd / math.pi + ks * lobe[:, None]
        lit = (~blocked & (cos > 0))[:, None]
        radiance = radiance + torch.where(lit, irradiance * cos[:, None] * brdf, 0.0)
    mirror = (kr > 0).any(1)
    if depth < max_depth and mirror.any():
        r = normalize(d - 2 * dot(d, n)[:, None] * n)
        bounce = _radiance(scene, p_off[mirror], r[mirror], depth + 1, max_depth, eps)
        radiance[mirror] = radiance[mirror] + kr[mirror] * bounce
    result[h] = radiance
    return result
