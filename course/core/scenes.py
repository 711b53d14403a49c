"""Meshes from files (through trimesh) and the course's built-in scenes.

``load_mesh`` reads OBJ, PLY and glTF/GLB files; ``load_scene`` builds a named scene:

  triangle           one triangle: the smallest test
  icosphere          a closed, watertight sphere (``level`` subdivisions)
  random_soup        ``n`` random triangles of very different sizes in the unit cube
  cornell_box        a closed room with two boxes and a ceiling light
  suzanne            Blender's monkey head (glTF, 968 triangles)
  bunny              the Stanford bunny (69K triangles)
  bunny_x4/x16       the bunny Loop-subdivided once/twice (278K/1.1M triangles), cached on disk
  teapot_in_stadium  a dense small mesh inside a room 1000 times larger

A scene holds only what it has: a mesh, a camera, lights and participating media are each
``None`` when absent. Nothing is loaded or built until asked for.
"""

from __future__ import annotations

import dataclasses
import math
import os
import tempfile
import zipfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
import trimesh

from course.core.camera import Camera
from course.core.device import default_device
from course.core.types import Mesh

ASSETS = Path(__file__).resolve().parents[1] / "assets"
_ASSET_FILES = {"suzanne": "suzanne.glb", "bunny": "bunny.obj"}


# ---------------------------------------------------------------------------------------
# Meshes from files


def load_mesh(
    path_or_name: str | Path,
    device: str | torch.device | None = None,
    dtype: torch.dtype = torch.float32,
) -> Mesh:
    """A triangle mesh from a file (OBJ, PLY, glTF/GLB, ...) or a bundled asset name.

    path_or_name: a file path, or ``"suzanne"`` / ``"bunny"`` for the bundled assets.
    A glTF scene is flattened: every mesh node is transformed to world space and all are
    concatenated. Vertices are merged by position, because files split them at UV and
    normal seams and a ray tracer needs the shared edges (e.g. for watertightness).
    Face order and winding are kept as stored.
    """
    path = _resolve(path_or_name)
    kind = path.suffix.lstrip(".").upper() or "no extension"
    try:
        loaded = trimesh.load(path, process=False)
    except Exception as exc:  # trimesh's loaders raise anything on bad bytes
        supported = trimesh.available_formats()
        if path.suffix.lstrip(".").lower() not in supported:
            raise ValueError(
                f"path_or_name: {path}: the {kind} format is not supported "
                f"(trimesh reads {', '.join(sorted(supported)[:12])}, ...)"
            ) from exc
        raise ValueError(
            f"path_or_name: {path} is not a readable {kind} file: {type(exc).__name__}: {exc}"
        ) from exc
    parts = loaded.dump() if isinstance(loaded, trimesh.Scene) else [loaded]
    parts = [p for p in parts if isinstance(p, trimesh.Trimesh) and len(p.faces) > 0]
    if not parts:
        raise ValueError(f"path_or_name: {path} ({kind} file) contains no triangles")
    mesh = trimesh.util.concatenate(parts)
    mesh.merge_vertices(merge_tex=True, merge_norm=True)
    return _mesh(mesh.vertices, mesh.faces, device, dtype)


def _resolve(path_or_name: str | Path) -> Path:
    if str(path_or_name) in _ASSET_FILES:
        return ASSETS / _ASSET_FILES[str(path_or_name)]
    path = Path(path_or_name)
    if not path.is_file():
        raise FileNotFoundError(
            f"path_or_name: no file {str(path)!r}; bundled meshes: {', '.join(_ASSET_FILES)}"
        )
    return path


def _mesh(vertices, faces, device, dtype: torch.dtype) -> Mesh:
    """A Mesh from array-likes; positions pass through float64 before the final cast."""
    device = default_device(device)
    return Mesh(
        vertices=torch.as_tensor(np.asarray(vertices, dtype=np.float64)).to(device, dtype),
        faces=torch.as_tensor(np.asarray(faces, dtype=np.int64)).to(device),
    )


# ---------------------------------------------------------------------------------------
# Scenes


@dataclass(frozen=True)
class PointLight:
    """An isotropic point light. intensity: RGB radiant intensity (W/sr)."""

    position: tuple[float, float, float]
    intensity: tuple[float, float, float]


@dataclass(frozen=True)
class QuadLight:
    """A one-sided rectangular area light ``corner + s * edge_u + t * edge_v``, s, t in [0, 1].

    It emits ``radiance`` (RGB, W/sr/m^2) to the side of ``normal = edge_u x edge_v``.
    """

    corner: tuple[float, float, float]
    edge_u: tuple[float, float, float]
    edge_v: tuple[float, float, float]
    radiance: tuple[float, float, float]

    @property
    def center(self) -> tuple[float, float, float]:
        return tuple((np.array(self.corner) + (np.array(self.edge_u) + self.edge_v) / 2).tolist())

    @property
    def normal(self) -> tuple[float, float, float]:
        n = np.cross(self.edge_u, self.edge_v)
        return tuple((n / np.linalg.norm(n)).tolist())

    @property
    def area(self) -> float:
        return float(np.linalg.norm(np.cross(self.edge_u, self.edge_v)))


@dataclass(frozen=True, eq=False)
class Scene:
    """What a scene has, ``None`` for what it lacks.

    mesh: the triangles; camera: a sensible default view; lights: PointLight/QuadLight list;
    media: participating media (volumes) for the ray-marching labs; name: for titles and files.
    """

    mesh: Mesh | None = None
    camera: Camera | None = None
    lights: list | None = None
    media: object | None = None
    name: str = ""


_BUILTINS: dict[str, Callable[..., Scene]] = {}


def _builtin(name: str):
    def register(build: Callable[..., Scene]) -> Callable[..., Scene]:
        _BUILTINS[name] = build
        return build

    return register


def list_scenes() -> list[str]:
    """The names ``load_scene`` accepts (besides a mesh file path)."""
    return sorted(_BUILTINS)


def load_scene(
    name: str,
    device: str | torch.device | None = None,
    dtype: torch.dtype = torch.float32,
    **params,
) -> Scene:
    """Build the built-in scene ``name`` (see ``list_scenes()``), or frame a mesh file.

    params: the scene's own knobs, e.g. ``load_scene("icosphere", level=4)``,
    ``load_scene("random_soup", n=10_000, seed=1)``.
    """
    if name not in _BUILTINS:
        if Path(name).is_file():
            mesh = load_mesh(name, device, dtype)
            return Scene(mesh=mesh, camera=_framing_camera(mesh.vertices), name=Path(name).stem)
        raise ValueError(
            f"name: unknown scene {name!r}; built-in scenes are "
            f"{', '.join(list_scenes())} (or pass a mesh file path)"
        )
    return _BUILTINS[name](device=default_device(device), dtype=dtype, **params)


def _framing_camera(
    vertices,
    view_from=(0.0, 0.0, 1.0),
    up=(0.0, 1.0, 0.0),
    fov_y: float = 40.0,
    width: int = 256,
    height: int = 256,
) -> Camera:
    """A camera looking at ``vertices`` from direction ``view_from``, just far enough that
    their bounding sphere (centred on the bounding box) fits the view with a small margin."""
    points = torch.as_tensor(vertices).detach().to("cpu", torch.float64)
    center = (points.min(dim=0).values + points.max(dim=0).values) / 2
    radius = max(float((points - center).norm(dim=1).max()), 1e-6)
    distance = 1.1 * radius / math.sin(math.radians(fov_y) / 2)
    direction = torch.tensor(view_from, dtype=torch.float64)
    eye = center + distance * direction / direction.norm()
    return Camera(
        eye=tuple(eye.tolist()),
        target=tuple(center.tolist()),
        up=up,
        fov_y=fov_y,
        width=width,
        height=height,
        near=0.01 * distance,
        far=10 * (distance + radius),
    )


@_builtin("triangle")
def _triangle(device, dtype) -> Scene:
    mesh = _mesh([[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [0.0, 1.0, 0.0]], [[0, 1, 2]], device, dtype)
    return Scene(mesh=mesh, camera=_framing_camera(mesh.vertices), name="triangle")


@_builtin("icosphere")
def _icosphere(device, dtype, level: int = 3) -> Scene:
    """A unit sphere of ``20 * 4**level`` triangles: closed, watertight, consistently wound."""
    if not 0 <= level <= 8:
        raise ValueError(f"level: expected 0..8 subdivisions (8 is 1.3M triangles), got {level}")
    sphere = trimesh.creation.icosphere(subdivisions=level, radius=1.0)
    mesh = _mesh(sphere.vertices, sphere.faces, device, dtype)
    return Scene(mesh=mesh, camera=_framing_camera(mesh.vertices), name=f"icosphere{level}")


@_builtin("random_soup")
def _random_soup(device, dtype, n: int = 1000, seed: int = 0) -> Scene:
    """``n`` unconnected triangles inside the unit cube [0, 1]^3, sizes log-uniform from
    0.001 to 0.25 (mixing tiny and large ones), the same for a seed on every device."""
    if n < 1:
        raise ValueError(f"n: expected at least one triangle, got {n}")
    g = torch.Generator().manual_seed(seed)
    size = torch.exp(
        torch.empty(n, dtype=torch.float64).uniform_(math.log(1e-3), math.log(0.25), generator=g)
    )
    # Centres at least `size` from the cube's faces keep every corner inside the cube.
    centre = size[:, None] + (1 - 2 * size[:, None]) * torch.rand(
        n, 3, dtype=torch.float64, generator=g
    )
    offsets = (2 * torch.rand(n, 3, 3, dtype=torch.float64, generator=g) - 1) * size[:, None, None]
    vertices = (centre[:, None, :] + offsets).reshape(-1, 3)
    mesh = _mesh(vertices, torch.arange(3 * n).reshape(n, 3), device, dtype)
    return Scene(mesh=mesh, camera=_framing_camera(vertices), name=f"random_soup{n}")


def _box(extents, center, angle_y_deg: float = 0.0, inward: bool = False) -> trimesh.Trimesh:
    """An axis-aligned box turned by ``angle_y_deg`` about +y; ``inward`` for a room's walls."""
    transform = trimesh.transformations.rotation_matrix(math.radians(angle_y_deg), [0, 1, 0])
    transform[:3, 3] = center
    box = trimesh.creation.box(extents=extents, transform=transform)
    if inward:
        box.invert()
    return box


@_builtin("cornell_box")
def _cornell_box(device, dtype) -> Scene:
    """The classic box [-1, 1] x [0, 2] x [-1, 1] with a short and a tall box and a quad light
    just below the ceiling, extended to z = 3 and closed there (every ray hits something), so
    the camera stands inside the room with the classic view."""
    parts = [
        _box((2.0, 2.0, 4.0), (0.0, 1.0, 1.0), inward=True),
        _box((0.6, 0.6, 0.6), (0.35, 0.3, 0.3), angle_y_deg=-18.0),
        _box((0.6, 1.2, 0.6), (-0.35, 0.6, -0.3), angle_y_deg=17.0),
    ]
    room = trimesh.util.concatenate(parts)
    # 1 mm below the ceiling, facing down: a shadow ray ending on the light is not blocked
    # by the ceiling it is mounted on.
    light = QuadLight(
        corner=(-0.25, 1.999, -0.2),
        edge_u=(0.5, 0.0, 0.0),
        edge_v=(0.0, 0.0, 0.4),
        radiance=(17.0, 12.0, 4.0),
    )
    camera = Camera(eye=(0.0, 1.0, 2.9), target=(0.0, 1.0, 0.0), fov_y=40.0, near=0.01, far=10.0)
    return Scene(
        mesh=_mesh(room.vertices, room.faces, device, dtype),
        camera=camera,
        lights=[light],
        name="cornell_box",
    )


@_builtin("suzanne")
def _suzanne(device, dtype) -> Scene:
    """Suzanne as stored in the file: z up, looking toward -y (Blender's axes)."""
    mesh = load_mesh("suzanne", device, dtype)
    camera = _framing_camera(mesh.vertices, view_from=(0.3, -1.0, 0.2), up=(0.0, 0.0, 1.0))
    return Scene(mesh=mesh, camera=camera, name="suzanne")


@_builtin("bunny")
def _bunny(device, dtype) -> Scene:
    return _bunny_scene(0, device, dtype)


@_builtin("bunny_x4")
def _bunny_x4(device, dtype) -> Scene:
    return _bunny_scene(1, device, dtype)


@_builtin("bunny_x16")
def _bunny_x16(device, dtype) -> Scene:
    return _bunny_scene(2, device, dtype)


def _bunny_scene(iterations: int, device, dtype) -> Scene:
    """The bunny after ``iterations`` Loop subdivisions (each multiplies the faces by 4)."""
    if iterations == 0:
        mesh = load_mesh("bunny", device, dtype)
    else:
        mesh = _mesh(*_subdivided_bunny(iterations), device, dtype)
    name = "bunny" if iterations == 0 else f"bunny_x{4**iterations}"
    return Scene(mesh=mesh, camera=_framing_camera(mesh.vertices), name=name)


def _subdivided_bunny(iterations: int) -> tuple[np.ndarray, np.ndarray]:
    def build():
        bunny = load_mesh("bunny", device="cpu", dtype=torch.float64)
        return trimesh.remesh.subdivide_loop(
            bunny.vertices.numpy(), bunny.faces.numpy(), iterations=iterations
        )

    return _cached(f"bunny_loop{iterations}", build)


@_builtin("teapot_in_stadium")
def _teapot_in_stadium(device, dtype, subdivisions: int = 2) -> Scene:
    """Suzanne Loop-subdivided (``968 * 4**subdivisions`` triangles) and scaled to 0.2 across,
    sitting on the floor of a closed room 200 across: nearly all triangles fill a tiny part of
    the scene's bounds, the case that defeats a uniform grid."""
    suzanne = load_mesh("suzanne", device="cpu", dtype=torch.float64)
    vertices, faces = trimesh.remesh.subdivide_loop(
        suzanne.vertices.numpy(), suzanne.faces.numpy(), iterations=subdivisions
    )
    vertices = vertices @ np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])  # z-up to y-up, face +z
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    vertices = (vertices - (lo + hi) / 2) * (0.2 / (hi - lo).max())
    floor = vertices[:, 1].min()
    stadium = _box((200.0, 200.0, 200.0), (0.0, floor + 100.0, 0.0), inward=True)
    teapot = trimesh.Trimesh(vertices, faces, process=False)
    world = trimesh.util.concatenate([teapot, stadium])
    camera = dataclasses.replace(_framing_camera(vertices, view_from=(0.3, 0.2, 1.0)), far=1000.0)
    return Scene(
        mesh=_mesh(world.vertices, world.faces, device, dtype),
        camera=camera,
        name="teapot_in_stadium",
    )


# ---------------------------------------------------------------------------------------
# The on-disk cache for meshes that are slow to build


def cache_dir() -> Path:
    """``$RTCOURSE_CACHE``, else ``~/.cache/rtcourse``."""
    return Path(os.environ.get("RTCOURSE_CACHE") or Path.home() / ".cache" / "rtcourse")


def _cached(key: str, build: Callable[[], tuple[np.ndarray, np.ndarray]]):
    """``(vertices, faces)`` from ``<cache_dir>/<key>.npz``, built and stored on a miss.

    Written to a temporary file and renamed: a reader never sees half a file, even with
    several processes (pytest workers) building the same key at once.
    """
    path = cache_dir() / f"{key}.npz"
    try:
        with np.load(path) as data:
            return data["vertices"], data["faces"]
    except (OSError, KeyError, ValueError, zipfile.BadZipFile):
        pass  # missing or unreadable: rebuild
    vertices, faces = build()
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{key}.", suffix=".npz")
    try:
        with os.fdopen(fd, "wb") as file:
            np.savez(file, vertices=vertices, faces=faces.astype(np.int32))
        os.replace(tmp, path)
    except BaseException:
        os.unlink(tmp)
        raise
    return vertices, faces
