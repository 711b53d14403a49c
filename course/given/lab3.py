"""Lab 3's given code: the Whitted scene, its shading contract, a brute-force tracer and a
slow, obvious reference renderer, and the input checks shared by skeleton and reference.

Given code, not exercises: the lab's skeleton and its reference import these, and so do the
GPU tracers of ``course.kernels.flat_bvh``/``course.kernels.triton_tracer``/``course.kernels.cuda_tracer``, so that
every organisation of the tracer renders *the same* image.

The scene (:class:`WhittedScene`, tensors, one float dtype and one device)
--------------------------------------------------------------------------
* ``vertices (V, 3)`` float, ``faces (F, 3)`` int64, ``material (F,)`` int64 into the
  material table;
* materials ``kd (M, 3)`` diffuse albedo, ``ks (M, 3)`` specular colour, ``shininess (M,)``,
  ``kr (M, 3)`` mirror reflectance;
* point lights ``point_positions (P, 3)``, ``point_intensities (P, 3)`` [W/sr];
* directional lights ``dir_directions (D, 3)`` unit, pointing *toward* the light,
  ``dir_irradiance (D, 3)`` [W/m^2];
* ``ambient (3,)``, ``background (3,)``.

P or D may be 0, not both (a scene without lights is a ValueError naming ``lights``); a
material index outside ``[0, M)`` is a ValueError naming ``material``.

The shading contract (every renderer of Lab 3 and every GPU tracer)
-------------------------------------------------------------------
At the closest hit ``p`` of a ray ``(o, d)``, ``d`` unit, on triangle ``f`` of material ``m``:

* ``n``: the unit geometric normal ``cross(v1 - v0, v2 - v0)``, flipped to face the ray
  (``n = -n`` where ``n . d > 0``).
* Robust secondary origin: ``p_off = p + n * offset * max(1, |p|_inf)``, with
  ``offset = OFFSET = 1e-4`` in float32 (see :func:`offset_scale` for float64).
* ``v = -d``; ``L = ambient * kd[m]``.
* Point light ``i``: ``to = P_i - p_off``, ``dist = |to|``, ``l = to / dist``,
  ``E = I_i / dist^2``; shadow ray ``(p_off, l)``, any hit in ``[0, dist - offset *
  max(1, |P_i|_inf)]`` (it stops just short of the light, so a light on a surface is not
  hidden by that surface). Directional light ``j``: ``l = D_j``, ``E = irradiance_j``, the
  shadow ray's ``t_max = inf``.
* Unoccluded and ``n . l > 0``: ``L += E (n . l) (kd / pi + ks (s + 8) / (8 pi)
  max(0, n . h)^s)``, ``h = normalize(l + v)``, ``s = shininess[m]`` (normalised
  Blinn-Phong). A shadow ray is traced only toward lights with ``n . l > 0``: the others
  cannot contribute ("model only what the scene requires").
* Mirror: if ``any(kr[m] > 0)`` and ``depth < max_depth``: ``r = d - 2 (d . n) n``
  (renormalised), ``L += kr[m] * radiance(p_off, r, depth + 1)``. Primary rays have depth 0;
  ``max_depth = 2`` is a primary ray and up to two reflected ones. Shadow rays are cast at
  every hit, primary or reflected.
* A ray that hits nothing returns ``background``. A ray with a NaN/inf origin or direction,
  or a zero direction, hits nothing (it returns ``background``, never NaN).

The tracer callable (how Lab 3 meets Lab 2 without depending on it)
-------------------------------------------------------------------
``trace(scene, origins (N, 3), directions (N, 3), t_min (N,), t_max (N,), any_hit: bool)
-> course.core.types.Hits`` (``t = inf`` and ``triangle = -1`` where missed). With ``any_hit``
it may return any hit in the interval (a shadow ray needs only "blocked or not").
:func:`trace_brute_force` is the given one; ``course.kernels.trace.trace_bvh`` the fast one.

Precision: float32 and float64. Half precision cannot hold a 1e-4 offset next to a
coordinate of 1 (its spacing there is 1e-3), so float16/bfloat16 are rejected with a
TypeError rather than rendered with acne.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import time
from dataclasses import dataclass
from typing import ClassVar

import torch

from course.core.camera import Camera
from course.core.types import Hits, Mesh, _validate

OFFSET = 1e-4
"""The secondary-ray offset in float32, relative to ``max(1, |p|_inf)``: about 800 float32
ulps of the hit's largest coordinate, well above the rounding of ``p = o + t d``."""
MAX_DEPTH = 2
"""The default reflection depth: a primary ray and up to two reflected rays."""
MEMORY_BUDGET_BYTES = 2**27
"""Brute force tests at most this many bytes' worth of (ray, triangle) pairs at once."""
BYTES_PER_PAIR = 256
"""What one (ray, triangle) pair of brute force costs in temporaries (float32, generous)."""
DTYPES = (torch.float32, torch.float64)
"""The precisions Lab 3 renders in."""
SCENES = ("cornell_mirror", "bunny_mirror", "mirror_corridor")
"""The names :func:`whitted_scene` builds."""


def offset_scale(dtype: torch.dtype) -> float:
    """The relative offset for ``dtype``: ``OFFSET`` in float32, the same number of ulps in
    float64 (``OFFSET * eps64 / eps32``, about 1.9e-13).

    A fixed 1e-4 would be 10 units at a hit 1e5 from the origin: far outside a room 2 units
    wide. Float64 has the precision to keep the offset tiny there; float32 has not (its
    spacing at 1e5 is 0.008), so far-away scenes are a float64 job.
    """
    if dtype not in DTYPES:
        raise TypeError(f"dtype: expected one of {DTYPES}, got {dtype}")
    return OFFSET * torch.finfo(dtype).eps / torch.finfo(torch.float32).eps


# ---------------------------------------------------------------------------------------
# The scene


@dataclass(frozen=True, eq=False)
class WhittedScene:
    """Triangles with a material each, point and directional lights, ambient and background.

    See the module docstring for the fields and the shading contract. Built scenes are
    validated: shapes, dtypes (one float dtype, int64 indices), one device, at least one
    light, material indices in range.
    """

    vertices: torch.Tensor
    faces: torch.Tensor
    material: torch.Tensor
    kd: torch.Tensor
    ks: torch.Tensor
    shininess: torch.Tensor
    kr: torch.Tensor
    point_positions: torch.Tensor
    point_intensities: torch.Tensor
    dir_directions: torch.Tensor
    dir_irradiance: torch.Tensor
    ambient: torch.Tensor
    background: torch.Tensor

    _SPEC: ClassVar = (
        ("vertices", ("V", 3), "float"), ("faces", ("F", 3), "int64"),
        ("material", ("F",), "int64"), ("kd", ("M", 3), "float"), ("ks", ("M", 3), "float"),
        ("shininess", ("M",), "float"), ("kr", ("M", 3), "float"),
        ("point_positions", ("P", 3), "float"), ("point_intensities", ("P", 3), "float"),
        ("dir_directions", ("D", 3), "float"), ("dir_irradiance", ("D", 3), "float"),
        ("ambient", (3,), "float"), ("background", (3,), "float"))

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> WhittedScene:
        """Check the scene; raise ValueError/TypeError naming the field (or ``lights``)."""
        _validate(self, self._SPEC)
        Mesh(self.vertices, self.faces)  # faces: at least one, indices in range
        if self.num_point_lights == 0 and self.num_dir_lights == 0:
            raise ValueError("lights: the scene has no point light (point_positions is (0, 3)) "
                             "and no directional light (dir_directions is (0, 3)); "
                             "a Whitted scene needs at least one light")
        m = self.kd.shape[0]
        lo, hi = int(self.material.min()), int(self.material.max())
        if lo < 0 or hi >= m:
            raise ValueError(f"material: expected indices in [0, {m}) (M={m} materials), got "
                             f"values in [{lo}, {hi}]")
        return self

    @property
    def dtype(self) -> torch.dtype:
        return self.vertices.dtype

    @property
    def device(self) -> torch.device:
        return self.vertices.device

    @property
    def num_faces(self) -> int:
        return self.faces.shape[0]

    @property
    def num_point_lights(self) -> int:
        return self.point_positions.shape[0]

    @property
    def num_dir_lights(self) -> int:
        return self.dir_directions.shape[0]

    @property
    def mesh(self) -> Mesh:
        return Mesh(self.vertices, self.faces)

    def mirror_faces(self) -> torch.Tensor:
        """(F,) bool: the triangles whose material reflects (``any(kr > 0)``)."""
        return (self.kr > 0).any(dim=1)[self.material]

    def to(self, device=None, dtype: torch.dtype | None = None) -> WhittedScene:
        """A copy on ``device`` with the float fields cast to ``dtype`` (like ``Tensor.to``)."""
        if isinstance(device, torch.dtype):
            device, dtype = None, device
        return dataclasses.replace(self, **{
            name: getattr(self, name).to(device=device, dtype=dtype if kind == "float" else None)
            for name, _, kind in self._SPEC})


def make_scene(mesh: Mesh, material, materials: dict, point_lights=(), dir_lights=(),
               ambient=(0.0, 0.0, 0.0), background=(0.0, 0.0, 0.0)) -> WhittedScene:
    """A WhittedScene from plain numbers, on the mesh's device and dtype.

    material: (F,) indices; materials: ``{"kd": [[r, g, b], ...], "ks": ..., "shininess":
    [...], "kr": ...}``; point_lights: ``[(position, intensity), ...]``; dir_lights:
    ``[(direction toward the light, irradiance), ...]`` (directions are normalised here).
    Numbers pass through float64 before the final cast.
    """
    device, dtype = mesh.device, mesh.dtype

    def rows(values, width=3):
        x = torch.as_tensor(values, dtype=torch.float64).reshape(-1, width)
        return x.to(device, dtype)

    directions = rows([d for d, _ in dir_lights])
    directions_64 = torch.as_tensor([d for d, _ in dir_lights], dtype=torch.float64).reshape(-1, 3)
    if len(directions_64):
        directions = (directions_64 / directions_64.norm(dim=1, keepdim=True)).to(device, dtype)
    return WhittedScene(
        vertices=mesh.vertices, faces=mesh.faces,
        material=torch.as_tensor(material, dtype=torch.int64).to(device),
        kd=rows(materials["kd"]), ks=rows(materials["ks"]),
        shininess=rows(materials["shininess"], 1).reshape(-1), kr=rows(materials["kr"]),
        point_positions=rows([p for p, _ in point_lights]),
        point_intensities=rows([i for _, i in point_lights]),
        dir_directions=directions, dir_irradiance=rows([e for _, e in dir_lights]),
        ambient=rows(ambient).reshape(3), background=rows(background).reshape(3))


def whitted_scene(name: str, device=None, dtype: torch.dtype = torch.float32) -> WhittedScene:
    """A built-in Whitted scene:

    * ``"cornell_mirror"``: the course's Cornell box (36 triangles), red left and green
      right wall, a glossy short box and a **mirror** tall box; one point light just below
      the ceiling and a weak ambient term. Closed: every ray hits something.
    * ``"bunny_mirror"``: the Stanford bunny (69K triangles, glossy clay) on a square
      mirror floor, under a sun (directional light) and a point light; a sky background.
    * ``"mirror_corridor"``: two parallel mirrors 2 units apart (z = -1 and z = 1, 20
      units wide), dark grey, lit only by ambient light (one directional light grazes them
      at n . l = 0 exactly): a ray between them bounces until the depth limit.
    """
    from course.core.scenes import load_mesh, load_scene  # scenes import trimesh: only on demand

    if name == "cornell_mirror":
        mesh = load_scene("cornell_box", device=device, dtype=dtype).mesh
        x = mesh.vertices[mesh.faces][..., 0].to("cpu", torch.float64)  # (F, 3)
        material = torch.zeros(mesh.num_faces, dtype=torch.int64)
        material[:12][(x[:12] == -1).all(1)] = 1   # the room's left wall: red
        material[:12][(x[:12] == 1).all(1)] = 2    # the right wall: green
        material[12:24] = 3                        # the short box: glossy white
        material[24:36] = 4                        # the tall box: a mirror
        materials = {"kd": [[0.73, 0.73, 0.73], [0.65, 0.05, 0.05], [0.12, 0.45, 0.15],
                            [0.6, 0.6, 0.6], [0.05, 0.05, 0.05]],
                     "ks": [[0, 0, 0], [0, 0, 0], [0, 0, 0], [0.3, 0.3, 0.3], [0, 0, 0]],
                     "shininess": [1.0, 1.0, 1.0, 40.0, 1.0],
                     "kr": [[0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0], [0.85, 0.85, 0.85]]}
        return make_scene(mesh, material, materials,
                          point_lights=[((0.0, 1.8, 1.0), (6.0, 5.4, 4.6))],
                          ambient=(0.03, 0.03, 0.03))
    if name == "bunny_mirror":
        bunny = load_mesh("bunny", device="cpu", dtype=torch.float64)
        v, f = bunny.vertices, bunny.faces
        lo, hi = v.amin(0), v.amax(0)
        c, r = (lo + hi) / 2, float((hi - lo).max())
        floor_y = float(lo[1])
        quad = torch.tensor([[-1.5, floor_y, -1.5], [1.5, floor_y, -1.5], [1.5, floor_y, 1.5],
                             [-1.5, floor_y, 1.5]], dtype=torch.float64)
        quad[:, [0, 2]] = quad[:, [0, 2]] * r + c[[0, 2]]
        vertices = torch.cat((v, quad))
        n = len(v)
        faces = torch.cat((f, torch.tensor([[n, n + 3, n + 2], [n, n + 2, n + 1]])))
        material = torch.cat((torch.zeros(len(f), dtype=torch.int64), torch.ones(2, dtype=torch.int64)))
        materials = {"kd": [[0.75, 0.55, 0.42], [0.08, 0.08, 0.1]],
                     "ks": [[0.25, 0.25, 0.25], [0.0, 0.0, 0.0]], "shininess": [24.0, 1.0],
                     "kr": [[0, 0, 0], [0.6, 0.6, 0.65]]}
        light = (c + torch.tensor([-0.9, 1.2, 1.0], dtype=torch.float64) * r).tolist()
        return make_scene(Mesh(vertices.to(device, dtype), faces.to(device)), material, materials,
                          point_lights=[(light, (0.03, 0.028, 0.025))],
                          dir_lights=[((0.5, 0.8, 0.35), (1.6, 1.5, 1.3))],
                          ambient=(0.06, 0.07, 0.09), background=(0.45, 0.6, 0.85))
    if name == "mirror_corridor":
        w = 10.0
        vertices = torch.tensor([[-w, -w, -1.0], [w, -w, -1.0], [w, w, -1.0], [-w, w, -1.0],
                                 [-w, -w, 1.0], [w, -w, 1.0], [w, w, 1.0], [-w, w, 1.0]],
                                dtype=torch.float64)
        faces = torch.tensor([[0, 1, 2], [0, 2, 3], [4, 6, 5], [4, 7, 6]])
        materials = {"kd": [[0.2, 0.2, 0.2]], "ks": [[0.0, 0.0, 0.0]], "shininess": [1.0],
                     "kr": [[0.9, 0.7, 0.5]]}
        return make_scene(Mesh(vertices.to(device, dtype), faces.to(device)), [0, 0, 0, 0],
                          materials, dir_lights=[((1.0, 0.0, 0.0), (1.0, 1.0, 1.0))],
                          ambient=(0.5, 0.5, 0.5), background=(0.0, 0.0, 1.0))
    raise ValueError(f"name: unknown Whitted scene {name!r}; built-in: {', '.join(SCENES)}")


def whitted_camera(name: str, width: int = 256, height: int = 256) -> Camera:
    """The default view of a built-in Whitted scene at ``width x height`` pixels."""
    if name == "cornell_mirror":
        return Camera(eye=(0.0, 1.0, 2.9), target=(0.0, 1.0, 0.0), fov_y=40.0, width=width,
                      height=height, near=0.01, far=10.0)
    if name == "bunny_mirror":
        return Camera(eye=(-0.04, 0.2, 0.4), target=(-0.015, 0.06, 0.0), fov_y=40.0,
                      width=width, height=height, near=0.01, far=10.0)
    if name == "mirror_corridor":
        return Camera(eye=(0.0, 0.0, 0.5), target=(0.3, 0.1, -1.0), fov_y=60.0, width=width,
                      height=height, near=0.01, far=100.0)
    raise ValueError(f"name: unknown Whitted scene {name!r}; built-in: {', '.join(SCENES)}")


def translated(scene: WhittedScene, offset) -> WhittedScene:
    """The scene moved by ``offset`` (a number or 3 numbers): vertices and point lights.

    Computed in float64 and rounded once, so a float64 scene moves exactly (up to one
    rounding) and a float32 one as well as float32 can hold it.
    """
    shift = torch.as_tensor(offset, dtype=torch.float64).expand(3).to(scene.device)
    return dataclasses.replace(
        scene, vertices=(scene.vertices.double() + shift).to(scene.dtype),
        point_positions=(scene.point_positions.double() + shift).to(scene.dtype))


# ---------------------------------------------------------------------------------------
# Small vector helpers


def dot(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """``(..., 3), (..., 3) -> (...)``."""
    return (a * b).sum(-1)


def normalize(v: torch.Tensor) -> torch.Tensor:
    """``v / |v|`` over the last axis; a zero vector stays zero (never NaN)."""
    length = v.norm(dim=-1, keepdim=True)
    return v / torch.where(length > 0, length, torch.ones_like(length))


def face_normals(scene: WhittedScene) -> torch.Tensor:
    """(F, 3): unit geometric normals ``cross(v1 - v0, v2 - v0)`` (zero for degenerate
    triangles, which no ray hits)."""
    c = scene.vertices[scene.faces]
    return normalize(torch.linalg.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0], dim=-1))


# ---------------------------------------------------------------------------------------
# The brute-force tracer


def pair_tiles(n: int, f: int):
    """Tiles of (ray, triangle) pairs within ``MEMORY_BUDGET_BYTES``: yields ``(rows,
    tiles)``, a slice of the N rays and a generator of slices of the F triangles; all
    triangles at once for many rays, or a few rays against chunks of the triangles."""
    pairs = max(1, MEMORY_BUDGET_BYTES // BYTES_PER_PAIR)
    ray_tile = max(1, min(n, pairs // max(f, 1)))
    tri_tile = max(1, min(f, pairs // ray_tile))
    for r0 in range(0, n, ray_tile):
        yield slice(r0, r0 + ray_tile), (slice(f0, f0 + tri_tile) for f0 in range(0, f, tri_tile))


def trace_brute_force(scene: WhittedScene, origins: torch.Tensor, directions: torch.Tensor,
                      t_min: torch.Tensor, t_max: torch.Tensor, any_hit: bool = False) -> Hits:
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
    valid = (torch.isfinite(origins).all(1) & torch.isfinite(directions).all(1)
             & (directions != 0).any(1) & ~(t_min > t_max))
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


def render_reference(scene: WhittedScene, origins: torch.Tensor, directions: torch.Tensor,
                     max_depth: int = MAX_DEPTH) -> torch.Tensor:
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
    return _radiance(scene, origins.to(scene.device, torch.float64),
                     directions.to(scene.device, torch.float64), 0, max_depth, eps)


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
    lights = [(scene.point_positions[i] - p_off, scene.point_intensities[i],
               eps * max(1.0, scene.point_positions[i].abs().max().item()))
              for i in range(scene.num_point_lights)]
    lights += [(scene.dir_directions[j].expand_as(p_off), scene.dir_irradiance[j], None)
               for j in range(scene.num_dir_lights)]
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
        brdf = kd / math.pi + ks * ((s + 8) / (8 * math.pi) * dot(n, half).clamp(min=0) ** s)[:, None]
        lit = (~blocked & (cos > 0))[:, None]
        radiance = radiance + torch.where(lit, irradiance * cos[:, None] * brdf, 0.0)
    mirror = (kr > 0).any(1)
    if depth < max_depth and mirror.any():
        r = normalize(d - 2 * dot(d, n)[:, None] * n)
        bounce = _radiance(scene, p_off[mirror], r[mirror], depth + 1, max_depth, eps)
        radiance[mirror] = radiance[mirror] + kr[mirror] * bounce
    result[h] = radiance
    return result


# ---------------------------------------------------------------------------------------
# Input checks (given: the skeleton and the reference call them first)


def check_scene(scene) -> None:
    """``scene`` must be a valid WhittedScene (TypeError/ValueError naming the problem:
    ``scene``, a field, ``lights`` or ``material``)."""
    if not isinstance(scene, WhittedScene):
        raise TypeError(f"scene: expected course.given.lab3.WhittedScene, got "
                        f"{type(scene).__name__}")
    scene.validate()
    if scene.dtype not in DTYPES:
        raise TypeError(f"scene: expected float32 or float64 geometry, got {scene.dtype} "
                        f"(half precision cannot hold the {OFFSET:g} secondary-ray offset)")


def check_vectors(like: torch.Tensor | None, **vectors) -> int:
    """Each of ``vectors`` (name=tensor) must be an (N, 3) float32/float64 tensor, all with
    one N, dtype and device (those of ``like`` when given). Returns N."""
    n = None
    for name, x in vectors.items():
        if not isinstance(x, torch.Tensor):
            raise TypeError(f"{name}: expected a torch.Tensor of shape (N, 3), "
                            f"got {type(x).__name__}")
        if x.dtype not in DTYPES:
            raise TypeError(f"{name}: expected float32 or float64, got {x.dtype} (half "
                            f"precision cannot hold the {OFFSET:g} secondary-ray offset: "
                            f"its spacing near 1 is 1e-3)")
        if x.ndim != 2 or x.shape[1] != 3 or (n is not None and x.shape[0] != n):
            want = "(N, 3)" if n is None else f"({n}, 3)"
            raise ValueError(f"{name}: expected shape {want}, got {tuple(x.shape)}")
        n = x.shape[0]
        if like is not None and x.dtype != like.dtype:
            raise TypeError(f"{name}: expected dtype {like.dtype} like the scene, got {x.dtype}")
        if like is not None and x.device != like.device:
            raise ValueError(f"{name}: expected device {like.device} like the scene, "
                             f"got {x.device}")
        like = x
    return n or 0


def check_trace(trace) -> None:
    """``trace`` must be callable as ``trace(scene, origins, directions, t_min, t_max,
    any_hit) -> Hits``."""
    if not callable(trace):
        raise TypeError("trace: expected a callable trace(scene, origins, directions, t_min, "
                        f"t_max, any_hit) -> Hits, got {type(trace).__name__}")


def _int_at_least(value, name: str, lo: int) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or value < lo:
        raise ValueError(f"{name}: expected an int >= {lo}, got {value!r}")


def check_max_depth(max_depth) -> None:
    """``max_depth`` must be an int >= 0 (0: primary rays only, no reflections)."""
    _int_at_least(max_depth, "max_depth", 0)


def check_pool_size(pool_size) -> None:
    """``pool_size`` must be an int >= 1."""
    _int_at_least(pool_size, "pool_size", 1)


def check_render_inputs(scene, origins, directions, trace, max_depth) -> int:
    """Provided: validate a renderer's arguments; returns N (the number of rays)."""
    check_scene(scene)
    n = check_vectors(scene.vertices, origins=origins, directions=directions)
    check_trace(trace)
    check_max_depth(max_depth)
    return n


def check_surface_inputs(scene, points, normals, directions, material, trace) -> int:
    """Provided: validate :func:`shade_direct`'s arguments; returns N."""
    check_scene(scene)
    n = check_vectors(scene.vertices, points=points, normals=normals, directions=directions)
    if not isinstance(material, torch.Tensor) or material.dtype != torch.int64:
        raise TypeError(f"material: expected an int64 tensor of shape ({n},), got "
                        f"{getattr(material, 'dtype', type(material).__name__)}")
    if material.shape != (n,):
        raise ValueError(f"material: expected shape ({n},), got {tuple(material.shape)}")
    if n and (int(material.min()) < 0 or int(material.max()) >= scene.kd.shape[0]):
        raise ValueError(f"material: expected indices in [0, {scene.kd.shape[0]}), got values "
                         f"in [{int(material.min())}, {int(material.max())}]")
    check_trace(trace)
    return n


LAYOUTS = {"indexed": "vertices", "float4": "triangles", "woop": "transforms"}
"""The geometry layouts of Lab 3's task 5, each with the tensor that carries its dtype."""


def check_order(order, mesh: Mesh) -> torch.Tensor:
    """Provided: ``order`` must be None or an int64 permutation of the F triangles; returns
    it (``arange(F)`` for None) on the mesh's device."""
    f = mesh.num_faces
    if order is None:
        return torch.arange(f, device=mesh.device)
    if not isinstance(order, torch.Tensor) or order.dtype != torch.int64 or order.shape != (f,):
        raise ValueError(f"order: expected an int64 permutation of shape ({f},), got "
                         f"{getattr(order, 'dtype', type(order).__name__)} of shape "
                         f"{tuple(getattr(order, 'shape', ()))}")
    if not torch.equal(torch.sort(order).values.cpu(), torch.arange(f)):
        raise ValueError(f"order: expected a permutation of 0..{f - 1}")
    return order.to(mesh.device)


def check_layout_inputs(layout, origins, directions, t_min, t_max) -> tuple[str, int]:
    """Provided: validate :func:`intersect_layout`'s arguments; returns ``(kind, F)``."""
    if not isinstance(layout, dict) or layout.get("kind") not in LAYOUTS:
        got = layout.get("kind") if isinstance(layout, dict) else type(layout).__name__
        raise ValueError(f"layout: expected a dict from layout_indexed/layout_float4/"
                         f"layout_woop (kind {'/'.join(LAYOUTS)}), got {got!r}")
    kind = layout["kind"]
    like = layout.get(LAYOUTS[kind])
    if not isinstance(like, torch.Tensor):
        raise TypeError(f"layout: a {kind!r} layout needs a tensor under {LAYOUTS[kind]!r}")
    n = check_vectors(like, origins=origins, directions=directions)
    for name, x in (("t_min", t_min), ("t_max", t_max)):
        if not isinstance(x, torch.Tensor) or x.shape != (n,) or x.dtype != like.dtype:
            raise ValueError(f"{name}: expected a ({n},) {like.dtype} tensor, got "
                             f"{getattr(x, 'dtype', type(x).__name__)} of shape "
                             f"{tuple(getattr(x, 'shape', ()))}")
    f = len(layout["faces"]) if kind == "indexed" else len(like)
    return kind, f


def check_mesh(mesh) -> None:
    """Provided: ``mesh`` must be a valid course.core.types.Mesh of float32/float64."""
    if not isinstance(mesh, Mesh):
        raise TypeError(f"mesh: expected course.core.types.Mesh, got {type(mesh).__name__}")
    mesh.validate()
    if mesh.dtype not in DTYPES:
        raise TypeError(f"mesh: expected float32 or float64 vertices, got {mesh.dtype}")


# ---------------------------------------------------------------------------------------
# Stage timing and the float4 layout's index word


class StageClock:
    """Seconds spent per named stage: ``with clock("trace"): ...`` adds to
    ``clock.seconds["trace"]``. On CUDA it synchronises around each stage, so the time is
    the stage's work and not its launch (the price: no overlap between stages)."""

    def __init__(self, device) -> None:
        self.device = torch.device(device)
        self.seconds: dict[str, float] = {}

    @contextlib.contextmanager
    def __call__(self, name: str):
        if self.device.type == "cuda":
            torch.cuda.synchronize(self.device)
        start = time.perf_counter()
        try:
            yield
        finally:
            if self.device.type == "cuda":
                torch.cuda.synchronize(self.device)
            self.seconds[name] = self.seconds.get(name, 0.0) + time.perf_counter() - start


_INDEX_BITS = {torch.float32: torch.int32, torch.float64: torch.int64}


def index_as_float(index: torch.Tensor, dtype: torch.dtype) -> torch.Tensor:
    """Integer indices stored bit for bit in floats of ``dtype`` (CUDA's ``__int_as_float``):
    int32 bits in float32, int64 bits in float64. Exact for every index, unlike a value
    conversion (float32 holds integers exactly only up to 2^24)."""
    return index.to(_INDEX_BITS[dtype]).contiguous().view(dtype)


def float_as_index(word: torch.Tensor) -> torch.Tensor:
    """The inverse of :func:`index_as_float`: int64 indices from their float bits."""
    return word.contiguous().view(_INDEX_BITS[word.dtype]).to(torch.int64)
