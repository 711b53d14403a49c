"""Lab 3's scene: its constants (``OFFSET``, ``MAX_DEPTH``, ...), :class:`WhittedScene`,
the built-in scenes and cameras, and the scene's face normals.

Given code, not exercises (imported through :mod:`course.given.lab3`, whose docstring
states the scene and shading contract).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import ClassVar

import torch

from course.core.camera import Camera
from course.core.raymath import normalize
from course.core.types import Mesh, _validate

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
        ("vertices", ("V", 3), "float"),
        ("faces", ("F", 3), "int64"),
        ("material", ("F",), "int64"),
        ("kd", ("M", 3), "float"),
        ("ks", ("M", 3), "float"),
        ("shininess", ("M",), "float"),
        ("kr", ("M", 3), "float"),
        ("point_positions", ("P", 3), "float"),
        ("point_intensities", ("P", 3), "float"),
        ("dir_directions", ("D", 3), "float"),
        ("dir_irradiance", ("D", 3), "float"),
        ("ambient", (3,), "float"),
        ("background", (3,), "float"),
    )

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> WhittedScene:
        """Check the scene; raise ValueError/TypeError naming the field (or ``lights``)."""
        _validate(self, self._SPEC)
        Mesh(self.vertices, self.faces)  # faces: at least one, indices in range
        if self.num_point_lights == 0 and self.num_dir_lights == 0:
            raise ValueError(
                "lights: the scene has no point light (point_positions is (0, 3)) "
                "and no directional light (dir_directions is (0, 3)); "
                "a Whitted scene needs at least one light"
            )
        m = self.kd.shape[0]
        lo, hi = int(self.material.min()), int(self.material.max())
        if lo < 0 or hi >= m:
            raise ValueError(
                f"material: expected indices in [0, {m}) (M={m} materials), got "
                f"values in [{lo}, {hi}]"
            )
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
        return dataclasses.replace(
            self,
            **{
                name: getattr(self, name).to(
                    device=device, dtype=dtype if kind == "float" else None
                )
                for name, _, kind in self._SPEC
            },
        )


def make_scene(
    mesh: Mesh,
    material,
    materials: dict,
    point_lights=(),
    dir_lights=(),
    ambient=(0.0, 0.0, 0.0),
    background=(0.0, 0.0, 0.0),
) -> WhittedScene:
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
        vertices=mesh.vertices,
        faces=mesh.faces,
        material=torch.as_tensor(material, dtype=torch.int64).to(device),
        kd=rows(materials["kd"]),
        ks=rows(materials["ks"]),
        shininess=rows(materials["shininess"], 1).reshape(-1),
        kr=rows(materials["kr"]),
        point_positions=rows([p for p, _ in point_lights]),
        point_intensities=rows([i for _, i in point_lights]),
        dir_directions=directions,
        dir_irradiance=rows([e for _, e in dir_lights]),
        ambient=rows(ambient).reshape(3),
        background=rows(background).reshape(3),
    )


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
        material[:12][(x[:12] == -1).all(1)] = 1  # the room's left wall: red
        material[:12][(x[:12] == 1).all(1)] = 2  # the right wall: green
        material[12:24] = 3  # the short box: glossy white
        material[24:36] = 4  # the tall box: a mirror
        materials = {
            "kd": [
                [0.73, 0.73, 0.73],
                [0.65, 0.05, 0.05],
                [0.12, 0.45, 0.15],
                [0.6, 0.6, 0.6],
                [0.05, 0.05, 0.05],
            ],
            "ks": [[0, 0, 0], [0, 0, 0], [0, 0, 0], [0.3, 0.3, 0.3], [0, 0, 0]],
            "shininess": [1.0, 1.0, 1.0, 40.0, 1.0],
            "kr": [[0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0], [0.85, 0.85, 0.85]],
        }
        return make_scene(
            mesh,
            material,
            materials,
            point_lights=[((0.0, 1.8, 1.0), (6.0, 5.4, 4.6))],
            ambient=(0.03, 0.03, 0.03),
        )
    if name == "bunny_mirror":
        bunny = load_mesh("bunny", device="cpu", dtype=torch.float64)
        v, f = bunny.vertices, bunny.faces
        lo, hi = v.amin(0), v.amax(0)
        c, r = (lo + hi) / 2, float((hi - lo).max())
        floor_y = float(lo[1])
        quad = torch.tensor(
            [
                [-1.5, floor_y, -1.5],
                [1.5, floor_y, -1.5],
                [1.5, floor_y, 1.5],
                [-1.5, floor_y, 1.5],
            ],
            dtype=torch.float64,
        )
        quad[:, [0, 2]] = quad[:, [0, 2]] * r + c[[0, 2]]
        vertices = torch.cat((v, quad))
        n = len(v)
        faces = torch.cat((f, torch.tensor([[n, n + 3, n + 2], [n, n + 2, n + 1]])))
        material = torch.cat(
            (torch.zeros(len(f), dtype=torch.int64), torch.ones(2, dtype=torch.int64))
        )
        materials = {
            "kd": [[0.75, 0.55, 0.42], [0.08, 0.08, 0.1]],
            "ks": [[0.25, 0.25, 0.25], [0.0, 0.0, 0.0]],
            "shininess": [24.0, 1.0],
            "kr": [[0, 0, 0], [0.6, 0.6, 0.65]],
        }
        light = (c + torch.tensor([-0.9, 1.2, 1.0], dtype=torch.float64) * r).tolist()
        return make_scene(
            Mesh(vertices.to(device, dtype), faces.to(device)),
            material,
            materials,
            point_lights=[(light, (0.03, 0.028, 0.025))],
            dir_lights=[((0.5, 0.8, 0.35), (1.6, 1.5, 1.3))],
            ambient=(0.06, 0.07, 0.09),
            background=(0.45, 0.6, 0.85),
        )
    if name == "mirror_corridor":
        w = 10.0
        vertices = torch.tensor(
            [
                [-w, -w, -1.0],
                [w, -w, -1.0],
                [w, w, -1.0],
                [-w, w, -1.0],
                [-w, -w, 1.0],
                [w, -w, 1.0],
                [w, w, 1.0],
                [-w, w, 1.0],
            ],
            dtype=torch.float64,
        )
        faces = torch.tensor([[0, 1, 2], [0, 2, 3], [4, 6, 5], [4, 7, 6]])
        materials = {
            "kd": [[0.2, 0.2, 0.2]],
            "ks": [[0.0, 0.0, 0.0]],
            "shininess": [1.0],
            "kr": [[0.9, 0.7, 0.5]],
        }
        return make_scene(
            Mesh(vertices.to(device, dtype), faces.to(device)),
            [0, 0, 0, 0],
            materials,
            dir_lights=[((1.0, 0.0, 0.0), (1.0, 1.0, 1.0))],
            ambient=(0.5, 0.5, 0.5),
            background=(0.0, 0.0, 1.0),
        )
    raise ValueError(f"name: unknown Whitted scene {name!r}; built-in: {', '.join(SCENES)}")


def whitted_camera(name: str, width: int = 256, height: int = 256) -> Camera:
    """The default view of a built-in Whitted scene at ``width x height`` pixels."""
    if name == "cornell_mirror":
        return Camera(
            eye=(0.0, 1.0, 2.9),
            target=(0.0, 1.0, 0.0),
            fov_y=40.0,
            width=width,
            height=height,
            near=0.01,
            far=10.0,
        )
    if name == "bunny_mirror":
        return Camera(
            eye=(-0.04, 0.2, 0.4),
            target=(-0.015, 0.06, 0.0),
            fov_y=40.0,
            width=width,
            height=height,
            near=0.01,
            far=10.0,
        )
    if name == "mirror_corridor":
        return Camera(
            eye=(0.0, 0.0, 0.5),
            target=(0.3, 0.1, -1.0),
            fov_y=60.0,
            width=width,
            height=height,
            near=0.01,
            far=100.0,
        )
    raise ValueError(f"name: unknown Whitted scene {name!r}; built-in: {', '.join(SCENES)}")


def translated(scene: WhittedScene, offset) -> WhittedScene:
    """The scene moved by ``offset`` (a number or 3 numbers): vertices and point lights.

    Computed in float64 and rounded once, so a float64 scene moves exactly (up to one
    rounding) and a float32 one as well as float32 can hold it.
    """
    shift = torch.as_tensor(offset, dtype=torch.float64).expand(3).to(scene.device)
    return dataclasses.replace(
        scene,
        vertices=(scene.vertices.double() + shift).to(scene.dtype),
        point_positions=(scene.point_positions.double() + shift).to(scene.dtype),
    )


def face_normals(scene: WhittedScene) -> torch.Tensor:
    """(F, 3): unit geometric normals ``cross(v1 - v0, v2 - v0)`` (zero for degenerate
    triangles, which no ray hits)."""
    c = scene.vertices[scene.faces]
    return normalize(torch.linalg.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0], dim=-1))
