"""Lab 3: organising the tracer (reference solution).

Whitted-style backward ray tracing, organised four ways, and three layouts of the triangles
in memory. See ``labs/lab3_wavefront.py`` for the tasks; the shading contract, the scene
type, the brute-force tracer and the input checks are given in ``course.given.lab3``.
"""

from __future__ import annotations

import functools
import math

import torch

from course.core.types import Hits, Mesh
from course.given.lab3 import (  # noqa: F401  (given helpers)
    LAYOUTS,
    MAX_DEPTH,
    OFFSET,
    StageClock,
    WhittedScene,
    check_layout_inputs,
    check_mesh,
    check_order,
    check_pool_size,
    check_render_inputs,
    check_scene,
    check_surface_inputs,
    check_vectors,
    dot,
    face_normals,
    float_as_index,
    index_as_float,
    normalize,
    offset_scale,
    pair_tiles,
)

# =======================================================================================
# Task 1: Whitted building blocks and backward tracing


def offset_origins(points: torch.Tensor, normals: torch.Tensor) -> torch.Tensor:
    """Secondary-ray origins lifted off the surface: ``p + n * offset * max(1, |p|_inf)``."""
    check_vectors(None, points=points, normals=normals)
    scale = points.abs().amax(dim=1, keepdim=True).clamp(min=1)
    return points + normals * (offset_scale(points.dtype) * scale)


def reflect(directions: torch.Tensor, normals: torch.Tensor) -> torch.Tensor:
    """Mirror directions ``d - 2 (d . n) n``, renormalised."""
    check_vectors(None, directions=directions, normals=normals)
    return normalize(directions - 2 * dot(directions, normals)[:, None] * normals)


def surface_at(scene: WhittedScene, origins: torch.Tensor, directions: torch.Tensor,
               hits: Hits):
    """``(points, normals, material)`` at each ray's hit; zeros and -1 where it missed.

    ``hits`` is taken as given: the ``Hits`` of these N rays from ``trace``. Any other value
    is outside the contract (it need not be checked, nor raise any particular error).
    """
    check_scene(scene)
    n = check_vectors(scene.vertices, origins=origins, directions=directions)
    if not isinstance(hits, Hits) or len(hits) != n:
        raise TypeError(f"hits: expected course.core.types.Hits for {n} rays, got "
                        f"{type(hits).__name__}")
    hit = hits.hit
    tri = hits.triangle.clamp(min=0)
    t = torch.where(hit, hits.t, 0.0)
    points = torch.where(hit[:, None], origins + t[:, None] * directions, 0.0)
    normals = face_normals(scene)[tri]
    # Face the ray: shading and offsets happen on the side the ray arrives from.
    normals = torch.where((dot(normals, directions) > 0)[:, None], -normals, normals)
    normals = torch.where(hit[:, None], normals, 0.0)
    material = torch.where(hit, scene.material[tri], -1)
    return points, normals, material


def _light_rays(scene: WhittedScene, p_off: torch.Tensor):
    """Per (hit, light): unit direction to the light (n, L, 3), irradiance (n, L, 3) and the
    shadow ray's t_max (n, L); point lights first, then directional lights."""
    eps = offset_scale(scene.dtype)
    to = scene.point_positions[None] - p_off[:, None]                 # (n, P, 3)
    dist = to.norm(dim=-1)
    light_offset = eps * scene.point_positions.abs().amax(dim=1).clamp(min=1)
    n, d = p_off.shape[0], scene.num_dir_lights
    directions = torch.cat((to / dist[..., None], scene.dir_directions.expand(n, d, 3)), 1)
    irradiance = torch.cat((scene.point_intensities / (dist**2)[..., None],
                            scene.dir_irradiance.expand(n, d, 3)), 1)
    t_max = torch.cat((dist - light_offset, torch.full((n, d), math.inf, dtype=dist.dtype,
                                                        device=dist.device)), 1)
    return directions, irradiance, t_max


def shade_direct(scene: WhittedScene, points: torch.Tensor, normals: torch.Tensor,
                 directions: torch.Tensor, material: torch.Tensor, trace):
    """Ambient plus every light with its shadow ray; returns ``(radiance (N, 3), shadow
    rays traced)``."""
    n = check_surface_inputs(scene, points, normals, directions, material, trace)
    kd, ks, s = scene.kd[material], scene.ks[material], scene.shininess[material]
    radiance = scene.ambient * kd
    if n == 0:
        return radiance, 0
    p_off = offset_origins(points, normals)
    l, irradiance, t_max = _light_rays(scene, p_off)
    cos = dot(normals[:, None], l)                                     # (n, L)
    # Only lights above the surface can contribute: only they get a shadow ray.
    row, light = (cos > 0).nonzero(as_tuple=True)
    blocked = trace(scene, p_off[row], l[row, light], torch.zeros_like(t_max[row, light]),
                    t_max[row, light], True).hit
    lit = torch.zeros_like(cos, dtype=torch.bool)
    lit[row, light] = ~blocked
    half = normalize(l - directions[:, None])                          # h = normalize(l + v)
    lobe = ((s + 8) / (8 * math.pi))[:, None] * dot(normals[:, None], half).clamp(min=0) ** s[:, None]
    brdf = kd[:, None] / math.pi + ks[:, None] * lobe[..., None]
    light_sum = torch.where(lit[..., None], irradiance * cos[..., None] * brdf, 0.0).sum(1)
    return radiance + light_sum, int(row.numel())


def _is_mirror(scene: WhittedScene, material: torch.Tensor) -> torch.Tensor:
    return (scene.kr[material] > 0).any(dim=1)


def render_whitted(scene: WhittedScene, origins: torch.Tensor, directions: torch.Tensor,
                   trace, max_depth: int = MAX_DEPTH) -> torch.Tensor:
    """Backward tracing with full-size ray state and masks: (N, 3) radiance."""
    n = check_render_inputs(scene, origins, directions, trace, max_depth)
    image = torch.zeros(n, 3, dtype=scene.dtype, device=scene.device)
    throughput = torch.ones_like(image)
    alive = torch.ones(n, dtype=torch.bool, device=scene.device)
    o, d = origins, directions
    zeros = torch.zeros(n, dtype=scene.dtype, device=scene.device)
    for depth in range(max_depth + 1):
        # Every lane is traced every bounce; dead lanes get an empty interval.
        hits = trace(scene, o, d, zeros, torch.where(alive, math.inf, -math.inf), False)
        hit = hits.hit & alive
        image = image + torch.where((alive & ~hit)[:, None], throughput * scene.background, 0.0)
        points, normals, material = surface_at(scene, o, d, hits)
        direct, _ = shade_direct(scene, points[hit], normals[hit], d[hit], material[hit], trace)
        image[hit] += throughput[hit] * direct
        alive = hit & _is_mirror(scene, material.clamp(min=0)) & (depth < max_depth)
        throughput = torch.where(alive[:, None], throughput * scene.kr[material.clamp(min=0)], 0.0)
        o = torch.where(alive[:, None], offset_origins(points, normals), o)
        d = torch.where(alive[:, None], reflect(d, normals), d)
        if not bool(alive.any()):
            break
    return image


# =======================================================================================
# Task 2: separate kernels with compaction ("wavefront")


def render_wavefront(scene: WhittedScene, origins: torch.Tensor, directions: torch.Tensor,
                     trace, max_depth: int = MAX_DEPTH, sort_by_material: bool = False):
    """Generate -> trace -> shade -> spawn, compacting the active rays between stages."""
    n = check_render_inputs(scene, origins, directions, trace, max_depth)
    if not isinstance(sort_by_material, bool):
        raise TypeError(f"sort_by_material: expected a bool, got {sort_by_material!r}")
    clock = StageClock(scene.device)
    stats = {"closest_rays": [], "hits": [], "shadow_rays": [], "reflected_rays": [],
             "material_runs": [], "seconds": clock.seconds}
    with clock("generate"):
        image = torch.zeros(n, 3, dtype=scene.dtype, device=scene.device)
        pixel = torch.arange(n, device=scene.device)
        o, d = origins, directions
        throughput = torch.ones(n, 3, dtype=scene.dtype, device=scene.device)
    for depth in range(max_depth + 1):
        if len(pixel) == 0:
            break
        with clock("trace"):
            zeros = torch.zeros(len(pixel), dtype=scene.dtype, device=scene.device)
            hits = trace(scene, o, d, zeros, zeros + math.inf, False)
        with clock("shade"):
            hit = hits.hit
            image.index_add_(0, pixel[~hit], throughput[~hit] * scene.background)
            pixel, o, d, throughput, hits = pixel[hit], o[hit], d[hit], throughput[hit], hits[hit]
            points, normals, material = surface_at(scene, o, d, hits)
            if sort_by_material:
                # Rays of one material next to each other: coherent shading (and on a GPU,
                # warps that take one branch).
                order = torch.argsort(material, stable=True)
                pixel, d, throughput = pixel[order], d[order], throughput[order]
                points, normals, material = points[order], normals[order], material[order]
            direct, shadow_rays = shade_direct(scene, points, normals, d, material, trace)
            image.index_add_(0, pixel, throughput * direct)
        with clock("spawn"):
            mirror = _is_mirror(scene, material) & (depth < max_depth)
            pixel, throughput = pixel[mirror], throughput[mirror] * scene.kr[material[mirror]]
            o = offset_origins(points[mirror], normals[mirror])
            d = reflect(d[mirror], normals[mirror])
        runs = 1 + int((material[1:] != material[:-1]).sum()) if len(material) else 0
        stats["closest_rays"].append(len(hit))
        stats["hits"].append(len(material))
        stats["shadow_rays"].append(shadow_rays)
        stats["reflected_rays"].append(len(pixel))
        stats["material_runs"].append(runs)
    stats["seconds"] = dict(clock.seconds)
    return image, stats


# =======================================================================================
# Task 3: the uber kernel (fixed-size buffers, no data-dependent shapes)


def _uber_shadow_rays(vertices, faces, mat_table, point_positions, point_intensities,
                      dir_directions, dir_irradiance, eps: float, o, d, t, triangle, alive):
    """Surface and shadow rays of all N lanes x L lights (static shapes, no branches)."""
    hit = alive & (triangle >= 0)
    tri = triangle.clamp(min=0)
    c = vertices[faces[tri]]
    normal = normalize(torch.linalg.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0], dim=-1))
    normal = torch.where((dot(normal, d) > 0)[:, None], -normal, normal)
    p = o + torch.where(hit, t, 0.0)[:, None] * d
    p_off = p + normal * (eps * p.abs().amax(dim=1, keepdim=True).clamp(min=1))
    to = point_positions[None] - p_off[:, None]
    dist = to.norm(dim=-1)
    n, nd = o.shape[0], dir_directions.shape[0]
    l = torch.cat((to / dist[..., None], dir_directions.expand(n, nd, 3)), 1)
    irradiance = torch.cat((point_intensities / (dist**2)[..., None],
                            dir_irradiance.expand(n, nd, 3)), 1)
    light_offset = eps * point_positions.abs().amax(dim=1).clamp(min=1)
    t_max = torch.cat((dist - light_offset,
                       torch.full((n, nd), math.inf, dtype=dist.dtype, device=dist.device)), 1)
    cos = dot(normal[:, None], l)
    needed = hit[:, None] & (cos > 0)
    t_max = torch.where(needed, t_max, -math.inf)  # an empty interval: an idle lane
    return hit, tri, normal, p_off, l, irradiance, cos, needed, t_max


def _uber_shade(material, kd, ks, shininess, kr, ambient, background, d, throughput, alive,
                hit, tri, normal, p_off, l, irradiance, cos, needed, blocked, image,
                more: bool):
    """Shading and spawning of all N lanes (static shapes, no branches)."""
    m = material[tri]
    s = shininess[m]
    half = normalize(l - d[:, None])
    lobe = ((s + 8) / (8 * math.pi))[:, None] * dot(normal[:, None], half).clamp(min=0) ** s[:, None]
    brdf = kd[m][:, None] / math.pi + ks[m][:, None] * lobe[..., None]
    lit = needed & ~blocked
    direct = ambient * kd[m] + torch.where(lit[..., None], irradiance * cos[..., None] * brdf,
                                           0.0).sum(1)
    image = image + throughput * torch.where(hit[:, None], direct,
                                             torch.where(alive[:, None], background, 0.0))
    alive = hit & (kr[m] > 0).any(dim=1) & more
    throughput = torch.where(alive[:, None], throughput * kr[m], 0.0)
    r = normalize(d - 2 * dot(d, normal)[:, None] * normal)
    return image, throughput, alive, p_off, r


@functools.cache
def _compiled(backend):
    return (torch.compile(_uber_shadow_rays, backend=backend, fullgraph=True, dynamic=True),
            torch.compile(_uber_shade, backend=backend, fullgraph=True, dynamic=True))


def render_uber(scene: WhittedScene, origins: torch.Tensor, directions: torch.Tensor, trace,
                max_depth: int = MAX_DEPTH, compile=False) -> torch.Tensor:
    """The bounce loop over fixed-size lane buffers; ``compile`` (True, or a torch.compile
    backend: a name or a callable) fuses each step."""
    n = check_render_inputs(scene, origins, directions, trace, max_depth)
    if not (isinstance(compile, (bool, str)) or callable(compile)):
        raise TypeError(f"compile: expected a bool or a torch.compile backend (a name or a "
                        f"callable), got {compile!r}")
    if compile:
        shadow_step, shade_step = _compiled("inductor" if compile is True else compile)
    else:
        shadow_step, shade_step = _uber_shadow_rays, _uber_shade
    lights = scene.num_point_lights + scene.num_dir_lights
    image = torch.zeros(n, 3, dtype=scene.dtype, device=scene.device)
    throughput = torch.ones_like(image)
    alive = torch.ones(n, dtype=torch.bool, device=scene.device)
    o, d = origins, directions
    zeros = torch.zeros(n, dtype=scene.dtype, device=scene.device)
    eps = offset_scale(scene.dtype)
    for depth in range(max_depth + 1):
        hits = trace(scene, o, d, zeros, torch.where(alive, math.inf, -math.inf), False)
        hit, tri, normal, p_off, l, irradiance, cos, needed, t_max = shadow_step(
            scene.vertices, scene.faces, scene.material, scene.point_positions,
            scene.point_intensities, scene.dir_directions, scene.dir_irradiance, eps, o, d,
            hits.t, hits.triangle, alive)
        # All N x L shadow lanes are traced; the unneeded ones have an empty interval.
        blocked = trace(scene, p_off[:, None].expand(n, lights, 3).reshape(-1, 3),
                        l.reshape(-1, 3), torch.zeros_like(t_max).reshape(-1),
                        t_max.reshape(-1), True).hit.reshape(n, lights)
        image, throughput, alive, o, d = shade_step(
            scene.material, scene.kd, scene.ks, scene.shininess, scene.kr, scene.ambient,
            scene.background, d, throughput, alive, hit, tri, normal, p_off, l, irradiance,
            cos, needed, blocked, image, depth < max_depth)
    return image


# =======================================================================================
# Task 4: persistent workers


def render_persistent(scene: WhittedScene, origins: torch.Tensor, directions: torch.Tensor,
                      trace, max_depth: int = MAX_DEPTH, pool_size: int = 4096):
    """A fixed pool of ray slots fed from one global queue of work items until it is empty."""
    n = check_render_inputs(scene, origins, directions, trace, max_depth)
    check_pool_size(pool_size)
    device, dtype = scene.device, scene.dtype
    image = torch.zeros(n, 3, dtype=dtype, device=device)
    # The queue: one work item (pixel, origin, direction, depth, throughput) per row.
    queue = {"pixel": torch.arange(n, device=device), "o": origins, "d": directions,
             "depth": torch.zeros(n, dtype=torch.int64, device=device),
             "throughput": torch.ones(n, 3, dtype=dtype, device=device)}
    head = 0
    # The pool: pool_size slots; pixel -1 marks an empty slot.
    pool = {key: torch.zeros((pool_size, *x.shape[1:]), dtype=x.dtype, device=device)
            for key, x in queue.items()}
    pool["pixel"].fill_(-1)
    stats = {"pool_size": pool_size, "steps": 0, "active_lanes": [], "work_generated": n,
             "work_processed": 0, "shadow_rays": 0}
    while True:
        free = (pool["pixel"] < 0).nonzero()[:, 0]
        take = min(len(free), len(queue["pixel"]) - head)
        if take > 0:  # refill the empty slots from the head of the queue
            for key, slots in pool.items():
                slots[free[:take]] = queue[key][head:head + take]
            head += take
        lane = (pool["pixel"] >= 0).nonzero()[:, 0]
        if len(lane) == 0:
            break
        stats["steps"] += 1
        stats["active_lanes"].append(len(lane))
        stats["work_processed"] += len(lane)
        pixel, o, d = pool["pixel"][lane], pool["o"][lane], pool["d"][lane]
        depth, throughput = pool["depth"][lane], pool["throughput"][lane]
        zeros = torch.zeros(len(lane), dtype=dtype, device=device)
        hits = trace(scene, o, d, zeros, zeros + math.inf, False)
        hit = hits.hit
        image.index_add_(0, pixel[~hit], throughput[~hit] * scene.background)
        points, normals, material = surface_at(scene, o[hit], d[hit], hits[hit])
        direct, shadow_rays = shade_direct(scene, points, normals, d[hit], material, trace)
        stats["shadow_rays"] += shadow_rays
        image.index_add_(0, pixel[hit], throughput[hit] * direct)
        # Spawn: a mirror hit appends its reflected ray to the tail of the queue.
        mirror = _is_mirror(scene, material) & (depth[hit] < max_depth)
        spawned = {"pixel": pixel[hit][mirror],
                   "o": offset_origins(points[mirror], normals[mirror]),
                   "d": reflect(d[hit][mirror], normals[mirror]),
                   "depth": depth[hit][mirror] + 1,
                   "throughput": throughput[hit][mirror] * scene.kr[material[mirror]]}
        stats["work_generated"] += len(spawned["pixel"])
        queue = {key: torch.cat((queue[key][head:], spawned[key])) for key in queue}
        head = 0
        pool["pixel"][lane] = -1  # every slot finished its item this step
    active = stats["active_lanes"]
    stats["idle_fraction"] = 1 - sum(active) / (pool_size * len(active)) if active else 0.0
    return image, stats


# =======================================================================================
# Task 5: geometry layouts


def _bytes(*tensors) -> int:
    return sum(x.numel() * x.element_size() for x in tensors)


def layout_indexed(mesh: Mesh) -> dict:
    """Shared vertices (V, 3) and an int32 index triple per triangle."""
    check_mesh(mesh)
    faces = mesh.faces.to(torch.int32)
    return {"kind": "indexed", "vertices": mesh.vertices, "faces": faces,
            "bytes_per_triangle": _bytes(mesh.vertices, faces) / mesh.num_faces}


def layout_float4(mesh: Mesh, order: torch.Tensor | None = None) -> dict:
    """Three float4 per triangle, the triangle's index in every w (bit for bit)."""
    check_mesh(mesh)
    index = check_order(order, mesh)
    corners = mesh.triangles()[index]                                   # (F, 3, 3)
    w = index_as_float(index, mesh.dtype)[:, None, None].expand(-1, 3, 1)
    triangles = torch.cat((corners, w), dim=2).contiguous()
    return {"kind": "float4", "triangles": triangles,
            "bytes_per_triangle": _bytes(triangles) / mesh.num_faces}


def layout_woop(mesh: Mesh) -> dict:
    """Per triangle the 3 x 4 affine map (3 float4 rows) to Woop's unit triangle."""
    check_mesh(mesh)
    c = mesh.triangles().to(torch.float64)
    e1, e2 = c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]
    # Columns e1, e2 and the unit normal: z' is then the signed distance from the plane in
    # world units, which keeps the third row as well conditioned as the ray's coordinates.
    frame = torch.stack((e1, e2, normalize(torch.linalg.cross(e1, e2, dim=-1))), dim=2)
    inverse, info = torch.linalg.inv_ex(frame)
    # A degenerate triangle has no unit-triangle map: NaN rows, which no ray hits.
    inverse = torch.where((info == 0)[:, None, None], inverse, math.nan)
    translation = -(inverse @ c[:, 0, :, None])
    transforms = torch.cat((inverse, translation), dim=2).to(mesh.dtype).contiguous()
    return {"kind": "woop", "transforms": transforms,
            "bytes_per_triangle": _bytes(transforms) / mesh.num_faces}


def _moller_trumbore(o, d, v0, v1, v2):
    e1, e2 = v1 - v0, v2 - v0
    p = torch.linalg.cross(d, e2, dim=-1)
    det = dot(e1, p)
    s = o - v0
    q = torch.linalg.cross(s, e1, dim=-1)
    u, v, t = dot(s, p) / det, dot(d, q) / det, dot(e2, q) / det
    return t, u, v, det != 0


def _woop(o, d, m):
    ox = dot(m[..., 0, :3], o) + m[..., 0, 3]
    oy = dot(m[..., 1, :3], o) + m[..., 1, 3]
    oz = dot(m[..., 2, :3], o) + m[..., 2, 3]
    dx, dy, dz = dot(m[..., 0, :3], d), dot(m[..., 1, :3], d), dot(m[..., 2, :3], d)
    t = -oz / dz
    return t, ox + t * dx, oy + t * dy, dz != 0


def intersect_layout(layout: dict, origins: torch.Tensor, directions: torch.Tensor,
                     t_min: torch.Tensor, t_max: torch.Tensor) -> Hits:
    """Closest hits of N rays against every triangle of a layout, in tiles."""
    kind, f = check_layout_inputs(layout, origins, directions, t_min, t_max)
    like = layout[LAYOUTS[kind]]
    n = origins.shape[0]
    best = Hits.miss(n, dtype=like.dtype, device=like.device)
    valid = torch.isfinite(origins).all(1) & torch.isfinite(directions).all(1)
    pairs = ((rows, cols) for rows, tiles in pair_tiles(n, f) for cols in tiles)
    for rows, cols in pairs:
        o, d = origins[rows, None], directions[rows, None]
        if kind == "woop":
            t, u, v, ok = _woop(o, d, layout["transforms"][None, cols])
            index = torch.arange(f, device=like.device)[cols]
        elif kind == "float4":
            tri = layout["triangles"][None, cols]
            t, u, v, ok = _moller_trumbore(o, d, tri[..., 0, :3], tri[..., 1, :3], tri[..., 2, :3])
            index = float_as_index(layout["triangles"][cols, 0, 3])   # the w word
        else:
            c = layout["vertices"][layout["faces"][cols].long()][None]
            t, u, v, ok = _moller_trumbore(o, d, c[..., 0, :], c[..., 1, :], c[..., 2, :])
            index = torch.arange(f, device=like.device)[cols]
        hit = (ok & valid[rows, None] & (u >= 0) & (v >= 0) & (u + v <= 1)
               & (t >= t_min[rows, None]) & (t <= t_max[rows, None]))
        t = torch.where(hit, t, math.inf)
        # Nearest per ray; among equal t the lowest triangle index (as brute force).
        key = torch.where(hit, index[None].expand_as(t), torch.iinfo(torch.int64).max)
        nearest = t.amin(dim=1, keepdim=True)
        j = torch.where(t == nearest, key, torch.iinfo(torch.int64).max).argmin(dim=1,
                                                                              keepdim=True)
        tb, ib = t.gather(1, j)[:, 0], index[j[:, 0]]
        better = (tb < best.t[rows]) | ((tb == best.t[rows]) & (tb < math.inf)
                                        & (ib < best.triangle[rows]))
        best.t[rows] = torch.where(better, tb, best.t[rows])
        best.triangle[rows] = torch.where(better, ib, best.triangle[rows])
        best.u[rows] = torch.where(better, u.gather(1, j)[:, 0], best.u[rows])
        best.v[rows] = torch.where(better, v.gather(1, j)[:, 0], best.v[rows])
    return best
