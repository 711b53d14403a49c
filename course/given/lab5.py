"""Scenes, lights, the froxel grid and input checks shared by Lab 5's skeleton and reference.

Given code, not exercises: the lab's skeleton, its reference, the brute-force reference
renderer (:mod:`course.given.lab5_reference`), the grader and the benchmarks all describe a
scene with these dataclasses, so there is one copy of them. They are frozen dataclasses of
the ``course`` package: they travel to a sandboxed worker by value.

Units are physical: lengths in metres, extinction and scattering coefficients per metre,
sun irradiance in W/m^2 per colour channel, point/spot intensity in W/sr, radiance in
W/(m^2 sr). Media are summed linearly; extinction is one number per medium (independent of
wavelength, as in Hillaire's talk), scattering is RGB and must not exceed it (albedo <= 1).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import torch

from course.core.camera import Camera, _camera_axes

PHASES = ("hg", "schlick")
"""Phase functions of the lighting stage: Henyey–Greenstein or Schlick's approximation."""
INTEGRATIONS = ("energy", "naive")
"""Per-slice integrals of the final integration: energy-conserving, or the talk's naive one."""
BLEND = 0.05
"""Weight of the new frame in the temporal exponential blend (the talk's 5%)."""
SCHLICK_K_MAX = 0.999
"""Schlick's ``k = 1.55 g - 0.55 g^3`` reaches 1 (a delta) before ``g`` does (at g = 0.9986):
``|k|`` is clamped here so the phase function stays finite and normalised."""
FLOATS = (torch.float32, torch.float64)
"""Working dtypes of the pipeline: float16/bfloat16 are rejected (exponential depth slicing
and transmittance products need more than 11 bits of mantissa)."""


# ---------------------------------------------------------------------------------------
# Small validators


def _vec(value, name: str, size: int = 3, nonneg: bool = False) -> tuple:
    try:
        values = tuple(float(v) for v in value)
    except (TypeError, ValueError):
        raise TypeError(f"{name}: expected {size} numbers, got {value!r}") from None
    if len(values) != size:
        raise ValueError(f"{name}: expected {size} numbers, got {len(values)}")
    if not all(math.isfinite(v) for v in values):
        raise ValueError(f"{name}: expected finite numbers, got {values}")
    if nonneg and min(values) < 0:
        raise ValueError(f"{name}: expected numbers >= 0, got {values}")
    return values


def _num(value, name: str, lo: float = -math.inf, hi: float = math.inf,
         open_lo: bool = False, open_hi: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise TypeError(f"{name}: expected a number, got {type(value).__name__}")
    ok = (lo < value if open_lo else lo <= value) and (value < hi if open_hi else value <= hi)
    if not ok or math.isnan(value):
        raise ValueError(f"{name}: expected a number in {'(' if open_lo else '['}{lo}, {hi}"
                         f"{')' if open_hi else ']'}, got {value!r}")
    return float(value)


def _unit(value, name: str) -> tuple:
    v = _vec(value, name)
    n = math.sqrt(sum(x * x for x in v))
    if n == 0:
        raise ValueError(f"{name}: expected a non-zero direction, got {v}")
    return tuple(x / n for x in v)


def _optics(obj) -> None:
    object.__setattr__(obj, "scattering", _vec(obj.scattering, "scattering", nonneg=True))
    object.__setattr__(obj, "emissive", _vec(obj.emissive, "emissive", nonneg=True))
    object.__setattr__(obj, "extinction", _num(obj.extinction, "extinction", 0.0))
    if max(obj.scattering) > obj.extinction * (1 + 1e-12):
        raise ValueError(f"scattering: expected every channel <= extinction={obj.extinction} "
                         f"(albedo <= 1), got {obj.scattering}")
    object.__setattr__(obj, "g", _num(obj.g, "g", -1.0, 1.0, open_lo=True, open_hi=True))


# ---------------------------------------------------------------------------------------
# Media


@dataclass(frozen=True)
class ConstantFog:
    """Depth fog: the same medium everywhere. ``scattering`` RGB and ``extinction`` per metre
    (``max(scattering) <= extinction``), ``emissive`` RGB radiance per metre, phase ``g``."""

    scattering: tuple = (0.02, 0.02, 0.02)
    extinction: float = 0.025
    emissive: tuple = (0.0, 0.0, 0.0)
    g: float = 0.0

    def __post_init__(self):
        _optics(self)


@dataclass(frozen=True)
class HeightFog:
    """Height fog: coefficients scaled by ``exp(-falloff (y - base))`` (full strength at
    ``y = base``, thinning upward; ``falloff`` per metre, >= 0)."""

    scattering: tuple = (0.05, 0.05, 0.05)
    extinction: float = 0.06
    emissive: tuple = (0.0, 0.0, 0.0)
    g: float = 0.0
    base: float = 0.0
    falloff: float = 0.3

    def __post_init__(self):
        _optics(self)
        object.__setattr__(self, "base", _num(self.base, "base"))
        object.__setattr__(self, "falloff", _num(self.falloff, "falloff", 0.0, 50.0))


@dataclass(frozen=True, eq=False)
class FogVolume:
    """A local fog volume: an oriented box or ellipsoid.

    center (3,), half_size (3,) > 0 in metres along the volume's own axes; ``rotation`` a 3x3
    orthonormal matrix (rows: the local x, y, z axes in world space; identity by default);
    ``shape`` "box" or "ellipsoid". Inside, the coefficients are scaled by ``density``: None
    (1 everywhere) or an (X, Y, Z) float tensor >= 0 spanning the volume's box in local
    coordinates ``(local + half_size) / (2 half_size)`` in [0, 1]^3, sampled trilinearly with
    voxel centres at ``(i + 0.5) / X`` and clamped to the border (:func:`sample_texture`).
    Outside the shape the volume contributes nothing.
    """

    center: tuple = (0.0, 0.0, 0.0)
    half_size: tuple = (1.0, 1.0, 1.0)
    scattering: tuple = (0.3, 0.3, 0.3)
    extinction: float = 0.4
    emissive: tuple = (0.0, 0.0, 0.0)
    g: float = 0.0
    shape: str = "box"
    rotation: tuple = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
    density: torch.Tensor | None = None

    def __post_init__(self):
        _optics(self)
        object.__setattr__(self, "center", _vec(self.center, "center"))
        half = _vec(self.half_size, "half_size")
        if min(half) <= 0:
            raise ValueError(f"half_size: expected three numbers > 0, got {half}")
        object.__setattr__(self, "half_size", half)
        if self.shape not in ("box", "ellipsoid"):
            raise ValueError(f"shape: expected 'box' or 'ellipsoid', got {self.shape!r}")
        rows = tuple(_vec(r, "rotation") for r in self.rotation)
        m = torch.tensor(rows, dtype=torch.float64)
        if m.shape != (3, 3) or not torch.allclose(m @ m.T, torch.eye(3, dtype=torch.float64),
                                                   atol=1e-6):
            raise ValueError("rotation: expected a 3x3 orthonormal matrix (rows: local axes)")
        object.__setattr__(self, "rotation", rows)
        d = self.density
        if d is not None:
            if not isinstance(d, torch.Tensor) or not d.is_floating_point():
                raise TypeError(f"density: expected None or a float tensor (X, Y, Z), got "
                                f"{getattr(d, 'dtype', type(d).__name__)}")
            if d.ndim != 3 or min(d.shape) < 1:
                raise ValueError(f"density: expected a grid (X, Y, Z), got {tuple(d.shape)}")
            if not bool(torch.isfinite(d).all()) or bool((d < 0).any()):
                raise ValueError("density: expected finite values >= 0")


MEDIA = (ConstantFog, HeightFog, FogVolume)


# ---------------------------------------------------------------------------------------
# Lights and occluders


@dataclass(frozen=True)
class DirectionalLight:
    """The sun: ``direction`` points toward the light (normalised here); ``irradiance`` RGB in
    W/m^2 on a surface facing it. Casts opaque shadows from the scene's occluders (through a
    shadow map in the pipeline) when ``shadows``, and volumetric shadows."""

    direction: tuple = (0.3, 1.0, 0.2)
    irradiance: tuple = (3.0, 3.0, 3.0)
    shadows: bool = True

    def __post_init__(self):
        object.__setattr__(self, "direction", _unit(self.direction, "direction"))
        object.__setattr__(self, "irradiance", _vec(self.irradiance, "irradiance", nonneg=True))


@dataclass(frozen=True)
class PointLight:
    """A point light at ``position``: ``intensity`` RGB in W/sr, irradiance ``I / d^2``, and
    nothing beyond ``range`` metres (the culling radius). No shadows."""

    position: tuple = (0.0, 2.0, 0.0)
    intensity: tuple = (10.0, 10.0, 10.0)
    range: float = 10.0

    def __post_init__(self):
        object.__setattr__(self, "position", _vec(self.position, "position"))
        object.__setattr__(self, "intensity", _vec(self.intensity, "intensity", nonneg=True))
        object.__setattr__(self, "range", _num(self.range, "range", 0.0, open_lo=True))


@dataclass(frozen=True)
class SpotLight:
    """A spot light: a point light whose intensity is scaled by ``smoothstep(cos outer,
    cos inner, cos angle to the axis)``; ``direction`` is the cone's axis (from the light).
    Casts volumetric shadows through a perspective transmittance volume."""

    position: tuple = (0.0, 3.0, 0.0)
    direction: tuple = (0.0, -1.0, 0.0)
    intensity: tuple = (30.0, 30.0, 30.0)
    range: float = 12.0
    inner_deg: float = 15.0
    outer_deg: float = 25.0

    def __post_init__(self):
        object.__setattr__(self, "position", _vec(self.position, "position"))
        object.__setattr__(self, "direction", _unit(self.direction, "direction"))
        object.__setattr__(self, "intensity", _vec(self.intensity, "intensity", nonneg=True))
        object.__setattr__(self, "range", _num(self.range, "range", 0.0, open_lo=True))
        _num(self.outer_deg, "outer_deg", 0.0, 80.0, open_lo=True)
        _num(self.inner_deg, "inner_deg", 0.0, self.outer_deg, open_hi=True)


LIGHTS = (DirectionalLight, PointLight, SpotLight)


@dataclass(frozen=True)
class Box:
    """An opaque axis-aligned box ``lo .. hi`` that casts sun shadows."""

    lo: tuple
    hi: tuple

    def __post_init__(self):
        lo, hi = _vec(self.lo, "lo"), _vec(self.hi, "hi")
        if not all(a < b for a, b in zip(lo, hi)):
            raise ValueError(f"hi: expected lo < hi on every axis, got {lo} .. {hi}")
        object.__setattr__(self, "lo", lo)
        object.__setattr__(self, "hi", hi)


@dataclass(frozen=True, eq=False)
class Scene:
    """What the froxel pipeline renders: media (summed), lights, an isotropic ``ambient``
    radiance RGB (sky light scattered with a phase integral of 1) and opaque ``occluders``
    that shadow the sun. The opaque surfaces themselves come as an image with view depths."""

    media: tuple = ()
    lights: tuple = ()
    ambient: tuple = (0.0, 0.0, 0.0)
    occluders: tuple = field(default=())

    def __post_init__(self):
        for name, kinds in (("media", MEDIA), ("lights", LIGHTS), ("occluders", (Box,))):
            items = tuple(getattr(self, name))
            for i, item in enumerate(items):
                if not isinstance(item, kinds):
                    raise TypeError(f"{name}[{i}]: expected one of "
                                    f"{', '.join(k.__name__ for k in kinds)}, got "
                                    f"{type(item).__name__}")
            object.__setattr__(self, name, items)
        object.__setattr__(self, "ambient", _vec(self.ambient, "ambient", nonneg=True))


# ---------------------------------------------------------------------------------------
# The froxel grid


@dataclass(frozen=True)
class FroxelGrid:
    """The froxel volume of a camera: screen tiles of ``tile`` x ``tile`` pixels times
    ``slices`` depth slices spaced exponentially in view depth between ``near`` and ``far``.

    Shape ``(slices, ny, nx)`` with ``nx = ceil(width / tile)``, ``ny = ceil(height / tile)``:
    volumes are indexed ``[k, j, i]`` (slice, tile row from the top, tile column), colour last.
    Continuous froxel coordinates ``(x, y, z)``: ``x = pixel column / tile``, ``y = pixel row /
    tile`` (pixel centres at +0.5, tile ``i`` spans ``[i, i + 1)``) and ``z`` the slice
    coordinate (slice ``k`` spans ``[k, k + 1)``, ``z = 0`` at ``near``, ``slices`` at ``far``).
    """

    camera: Camera
    tile: int = 8
    slices: int = 64
    near: float = 0.1
    far: float = 100.0

    def __post_init__(self):
        if not isinstance(self.camera, Camera):
            raise TypeError(f"camera: expected a course.core.camera.Camera, got "
                            f"{type(self.camera).__name__}")
        for name in ("tile", "slices"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ValueError(f"{name}: expected an int >= 1, got {v!r}")
        _num(self.near, "near", 0.0, math.inf, open_lo=True, open_hi=True)
        _num(self.far, "far", self.near, math.inf, open_lo=True, open_hi=True)

    @property
    def nx(self) -> int:
        return -(-self.camera.width // self.tile)

    @property
    def ny(self) -> int:
        return -(-self.camera.height // self.tile)

    @property
    def shape(self) -> tuple:
        """(slices, ny, nx)."""
        return (self.slices, self.ny, self.nx)

    def axes(self, dtype=torch.float64, device="cpu"):
        """The camera's ``(eye, right, up, forward)`` (3,) each, and ``(half_w, half_h)``:
        the image plane's half extents at unit view depth."""
        right, up, back = (a.to(device, dtype) for a in _camera_axes(
            self.camera.eye, self.camera.target, self.camera.up))
        eye = torch.tensor(self.camera.eye, dtype=dtype, device=device)
        half_h = math.tan(math.radians(self.camera.fov_y) / 2)
        return eye, right, up, -back, (half_h * self.camera.aspect, half_h)


# ---------------------------------------------------------------------------------------
# Given numerical helpers


def halton(index: int, base: int = 2) -> float:
    """The radical inverse of ``index`` (>= 1) in ``base``: 1/2, 1/4, 3/4, 1/8, ... for 2."""
    if isinstance(index, bool) or not isinstance(index, int) or index < 1:
        raise ValueError(f"index: expected an int >= 1, got {index!r}")
    result, f = 0.0, 1.0
    while index:
        f /= base
        result += f * (index % base)
        index //= base
    return result


def frame_jitter(frame: int) -> float:
    """The sample depth offset within a froxel for temporal frame ``frame`` (0, 1, ...):
    ``halton(frame + 1, 2)``, so frame 0 samples the slice's middle depth."""
    return halton(frame + 1, 2)


def sample_texture(volume: torch.Tensor, coords: torch.Tensor) -> torch.Tensor:
    """Trilinear lookup with voxel centres at ``index + 0.5``, clamped to the border.

    volume: (A, B, C) or (A, B, C, K); coords: (..., 3) continuous indices along (A, B, C)
    (voxel ``a`` spans ``[a, a + 1)``). Returns (...) or (..., K). NaN coordinates read
    voxel 0. Used for density textures (coords = local [0, 1]^3 times the shape).
    """
    scalar = volume.ndim == 3
    v = volume[..., None] if scalar else volume
    sizes = torch.tensor(v.shape[:3], dtype=coords.dtype, device=coords.device)
    u = torch.nan_to_num(coords, nan=0.0) - 0.5
    u = torch.minimum(u.clamp(min=0), sizes - 1)
    i0 = torch.minimum(u.floor(), (sizes - 2).clamp(min=0)).long()
    f = u - i0
    i1 = torch.minimum(i0 + 1, (sizes - 1).long())
    flat = v.reshape(-1, v.shape[-1])
    _, b, c = v.shape[:3]
    out = 0
    for ia, fa in ((i0[..., 0], 1 - f[..., 0]), (i1[..., 0], f[..., 0])):
        for ib, fb in ((i0[..., 1], 1 - f[..., 1]), (i1[..., 1], f[..., 1])):
            for ic, fc in ((i0[..., 2], 1 - f[..., 2]), (i1[..., 2], f[..., 2])):
                out = out + flat[(ia * b + ib) * c + ic] * (fa * fb * fc)[..., None]
    return out[..., 0] if scalar else out


def ray_boxes(origins: torch.Tensor, directions: torch.Tensor, boxes) -> torch.Tensor:
    """Distance along unit ``directions`` (N, 3) from ``origins`` (N, 3) to the first of the
    axis-aligned ``boxes`` (a sequence of :class:`Box`) hit at t > 0; inf where none is."""
    t_hit = torch.full(origins.shape[:-1], math.inf, dtype=origins.dtype,
                       device=origins.device)
    inv = torch.reciprocal(directions)
    for box in boxes:
        lo = torch.tensor(box.lo, dtype=origins.dtype, device=origins.device)
        hi = torch.tensor(box.hi, dtype=origins.dtype, device=origins.device)
        t0, t1 = (lo - origins) * inv, (hi - origins) * inv
        near = torch.fmax(torch.minimum(t0, t1).nan_to_num(nan=-math.inf).amax(-1),
                          torch.zeros_like(t_hit))
        far = torch.maximum(t0, t1).nan_to_num(nan=math.inf).amin(-1)
        hit = (near <= far) & (far > 0)
        t_hit = torch.where(hit, torch.minimum(t_hit, near), t_hit)
    return t_hit


# ---------------------------------------------------------------------------------------
# Input checks (each raises ValueError/TypeError naming the argument)


def check_dtype(dtype, name: str = "dtype") -> torch.dtype:
    if dtype not in FLOATS:
        raise TypeError(f"{name}: expected torch.float32 or torch.float64, got {dtype} "
                        f"(float16/bfloat16 lose the exponential slicing and transmittance)")
    return dtype


def check_grid(grid) -> FroxelGrid:
    if not isinstance(grid, FroxelGrid):
        raise TypeError(f"grid: expected a FroxelGrid, got {type(grid).__name__}")
    return grid


def check_scene(scene) -> Scene:
    if not isinstance(scene, Scene):
        raise TypeError(f"scene: expected a course.given.lab5.Scene, got "
                        f"{type(scene).__name__}")
    return scene


def check_volume(x, name: str, shape, dtype=None, device=None) -> torch.Tensor:
    """A float tensor of exactly ``shape`` (and ``dtype``/``device`` when given)."""
    if not isinstance(x, torch.Tensor) or not x.is_floating_point():
        raise TypeError(f"{name}: expected a float tensor of shape {tuple(shape)}, got "
                        f"{getattr(x, 'dtype', type(x).__name__)}")
    check_dtype(x.dtype, name)
    if tuple(x.shape) != tuple(shape):
        raise ValueError(f"{name}: expected shape {tuple(shape)}, got {tuple(x.shape)}")
    if dtype is not None and x.dtype != dtype:
        raise TypeError(f"{name}: expected dtype {dtype}, got {x.dtype}")
    if device is not None and x.device != torch.device(device):
        raise ValueError(f"{name}: expected a tensor on {device}, got one on {x.device}")
    return x


def check_depths(near, far, slices) -> None:
    if isinstance(slices, bool) or not isinstance(slices, int) or slices < 1:
        raise ValueError(f"slices: expected an int >= 1, got {slices!r}")
    _num(near, "near", 0.0, math.inf, open_lo=True, open_hi=True)
    _num(far, "far", near, math.inf, open_lo=True, open_hi=True)


def check_choice(value, name: str, choices) -> str:
    if value not in choices:
        raise ValueError(f"{name}: expected one of {', '.join(map(repr, choices))}, "
                         f"got {value!r}")
    return value


def check_jitter(jitter) -> float:
    return _num(jitter, "jitter", 0.0, 1.0, open_hi=True)


def check_images(camera: Camera, depth_image, opaque_image):
    """``depth_image`` (H, W) view depths >= 0 (+inf: sky) and ``opaque_image`` (H, W, 3),
    float32/float64 of one dtype and device; returns their dtype."""
    h, w = camera.height, camera.width
    check_volume(depth_image, "depth_image", (h, w))
    check_volume(opaque_image, "opaque_image", (h, w, 3), dtype=depth_image.dtype,
                 device=depth_image.device)
    if bool((torch.isnan(depth_image) | (depth_image < 0)).any()):
        raise ValueError("depth_image: expected view depths >= 0 (+inf for the sky), got "
                         "NaN or negative values")
    return depth_image.dtype


# ---------------------------------------------------------------------------------------
# Light-space textures: sun shadow maps and transmittance volumes

LIGHT_STEPS = 8
"""Midpoint steps of a point light's transmittance march (``light_transmittance``): exact
for a medium that is constant along the segment, whatever the count."""
MIN_LIGHT_DISTANCE = 0.01
"""Point and spot lights are evaluated no closer than 1 cm (a bulb's radius): ``1 / d^2``
stays finite for a froxel sample on top of a light inside fog."""


@dataclass(frozen=True, eq=False)
class LightVolume:
    """A texture in a light's frame: a sun shadow map or a transmittance volume.

    kind "ortho" (the sun): ``origin`` lies on a plane facing the light, ``axes`` rows
    ``(u, v, w)`` with ``w`` pointing away from the light; a point maps to
    ``a = (p - origin).u / extent``, ``b = (p - origin).v / extent`` and depth
    ``(p - origin).w`` in metres. kind "persp" (a spot light): ``origin`` is the light,
    ``w`` its axis, ``a = (p - origin).u / ((p - origin).w * extent)`` (``extent``: tan of
    the half angle), likewise ``b``, and depth ``|p - origin|``.
    ``data``: (R, R) depth in metres of the first occluder per texel (a shadow map), or
    (R, R, K) transmittance at depths ``near + k (far - near) / (K - 1)`` (a transmittance
    volume). Texel ``(i, j)`` covers ``a`` in ``[-1 + 2 i / R, -1 + 2 (i + 1) / R)``, same for
    ``b`` with ``j``.
    """

    kind: str
    origin: tuple
    axes: tuple
    extent: float
    near: float
    far: float
    data: torch.Tensor


def light_frame(direction) -> tuple:
    """Rows ``(u, v, w)``: an orthonormal frame with ``w = direction`` (unit, 3 numbers)."""
    w = torch.tensor(direction, dtype=torch.float64)
    w = w / w.norm()
    helper = torch.tensor([0.0, 1.0, 0.0] if abs(float(w[1])) < 0.9 else [1.0, 0.0, 0.0],
                          dtype=torch.float64)
    u = torch.linalg.cross(helper, w)
    u = u / u.norm()
    v = torch.linalg.cross(w, u)
    return tuple(tuple(x.tolist()) for x in (u, v, w))


def light_coords(volume: LightVolume, points: torch.Tensor):
    """``(a, b, depth)``, (N,) each, of ``points`` (N, 3) in ``volume``'s frame (see
    :class:`LightVolume`). Points behind a spot light get ``a = b = inf``."""
    o = torch.tensor(volume.origin, dtype=points.dtype, device=points.device)
    axes = torch.tensor(volume.axes, dtype=points.dtype, device=points.device)
    rel = (points - o) @ axes.T  # (N, 3): along u, v, w
    if volume.kind == "ortho":
        return rel[:, 0] / volume.extent, rel[:, 1] / volume.extent, rel[:, 2]
    ahead = rel[:, 2] > 0
    scale = torch.where(ahead, rel[:, 2], 1.0) * volume.extent
    a = torch.where(ahead, rel[:, 0] / scale, math.inf)
    b = torch.where(ahead, rel[:, 1] / scale, math.inf)
    return a, b, (points - o).norm(dim=-1)


def frustum_bounds(grid: FroxelGrid):
    """World-space axis-aligned bounds ``(lo, hi)`` (3-tuples) of the froxel volume: the
    region around the camera that the volumetric shadows cover."""
    eye, right, up, fwd, (hw, hh) = grid.axes()
    corners = []
    for z in (grid.near, grid.far):
        for sx in (-1, 1):
            for sy in (-1, 1):
                corners.append(eye + z * (fwd + sx * hw * right + sy * hh * up))
    c = torch.stack(corners)
    return tuple(c.amin(0).tolist()), tuple(c.amax(0).tolist())


def media_bounds(scene: Scene):
    """World-space axis-aligned bounds ``(lo, hi)`` (3-tuples) of the scene's media, or None
    when a medium is unbounded (constant fog, height fog) or there are no media. A fog
    volume's bounds are those of its rotated box (an ellipsoid's are tight: per world axis
    ``sqrt(sum_i (rotation[i][axis] half_size[i])^2)``)."""
    if not scene.media or any(not isinstance(m, FogVolume) for m in scene.media):
        return None
    lo, hi = [math.inf] * 3, [-math.inf] * 3
    for m in scene.media:
        for axis in range(3):
            terms = [m.rotation[i][axis] * m.half_size[i] for i in range(3)]
            reach = (math.sqrt(sum(t * t for t in terms)) if m.shape == "ellipsoid"
                     else sum(abs(t) for t in terms))
            lo[axis] = min(lo[axis], m.center[axis] - reach)
            hi[axis] = max(hi[axis], m.center[axis] + reach)
    return tuple(lo), tuple(hi)


def volume_bounds(scene: Scene, grid: FroxelGrid):
    """The region the extinction and transmittance volumes cover: the smallest box holding
    ``frustum_bounds(grid)`` and the position of every point or spot light whose range
    reaches that box (so each path from a froxel to such a light lies inside it),
    intersected with :func:`media_bounds` (no intersection when a medium is unbounded).
    ``(lo, hi)``, or None when no medium lies inside: then nothing in view is shadowed by
    the media and no volume is built. Media outside this region cast no volumetric shadows
    (the pipeline's model, and the reference's): toward the sun, the part of its path that
    leaves the frustum's bounds."""
    if not scene.media:
        return None
    view_lo, view_hi = frustum_bounds(grid)
    lo, hi = list(view_lo), list(view_hi)
    for light in scene.lights:
        if isinstance(light, DirectionalLight):
            continue
        p, r = light.position, light.range
        if all(a - r <= x <= b + r for a, b, x in zip(view_lo, view_hi, p)):
            lo = [min(a, x) for a, x in zip(lo, p)]
            hi = [max(b, x) for b, x in zip(hi, p)]
    lo, hi = tuple(lo), tuple(hi)
    media = media_bounds(scene)
    if media is not None:
        lo = tuple(max(a, b) for a, b in zip(lo, media[0]))
        hi = tuple(min(a, b) for a, b in zip(hi, media[1]))
        if not all(a < b for a, b in zip(lo, hi)):
            return None
    return lo, hi


# The froxel grid a scene requires. Froxels sample the media at their centres and the image
# reads them bilinearly between tile centres: a fog volume spanning few tiles on screen
# loses or gains light along its silhouette (a 4 m box 8 tiles across: -6% in mean
# radiance), and slices spread over 0.1 .. 100 m put few of them where a small volume is.
TILE, SLICES, NEAR, FAR = 8, 64, 0.1, 100.0
TILES_PER_VOLUME = 12
# Smaller tiles never make more screen tiles than 8-pixel tiles at 1920 x 1080: a small
# volume far away in a large image keeps the talk's grid rather than 130M froxels.
MAX_TILES = 240 * 135


def scene_grid(scene: Scene, camera: Camera, tile=None, slices=SLICES, near=None,
               far=None) -> FroxelGrid:
    """The ``FroxelGrid`` for ``scene`` seen by ``camera``; None picks what the scene needs.

    ``near``/``far`` None: the view-depth range of the media (the corners of every fog
    volume's box) within ``NEAR .. FAR``, so the slices lie where the media are and no
    light is lost before ``near`` or after ``far``; ``NEAR .. FAR`` when a medium is unbounded
    (height or constant fog) or the media lie behind the camera. ``tile`` None: the largest
    of ``TILE``, ``TILE / 2``, ... 1 at which every fog volume in front of the camera (and not
    around it) spans ``TILES_PER_VOLUME`` tiles across its thinnest side at its centre's
    depth, as long as the screen holds at most ``MAX_TILES`` tiles. A scene of unbounded
    media, or volumes filling the view, keeps ``TILE``; a 2 m box 5 m away in a 64 x 36
    image gets tile 1 (36 x 64 x 64 froxels, few of them lit).
    Given numbers are kept (and checked by ``FroxelGrid``).
    """
    if tile is None or near is None or far is None:
        eye, _, _, fwd, (_, half_h) = FroxelGrid(camera).axes()
        depths, sizes = [], []
        for m in scene.media:
            if not isinstance(m, FogVolume):
                depths = None
                continue
            center = torch.tensor(m.center, dtype=torch.float64)
            rotation = torch.tensor(m.rotation, dtype=torch.float64)
            half = torch.tensor(m.half_size, dtype=torch.float64)
            signs = torch.tensor([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)],
                                 dtype=torch.float64)
            if depths is not None:
                depths += (((signs * half) @ rotation + center - eye) @ fwd).tolist()
            inside = bool((((eye - center) @ rotation.T).abs() <= half).all())
            z = float((center - eye) @ fwd)
            if z > 0 and not inside:
                sizes.append(2 * min(m.half_size) * camera.height / (2 * half_h * z))
        if near is None or far is None:
            fitted = depths and max(depths) > NEAR
            lo = min(max(min(depths), NEAR), FAR) if fitted else NEAR
            hi = min(max(max(depths), lo * 1.01), FAR) if fitted else FAR
            given = isinstance(near, (int, float)) and not isinstance(near, bool)
            near = lo if near is None else near  # a bad given one is named by FroxelGrid
            far = (max(hi, near * 1.01) if given else hi) if far is None else far
        if tile is None:
            tile = TILE
            while tile > 1 and any(s < TILES_PER_VOLUME * tile for s in sizes) and (
                    -(-camera.width // (tile // 2)) * -(-camera.height // (tile // 2))
                    <= MAX_TILES):
                tile //= 2
    return FroxelGrid(camera, tile, slices, near, far)


VOLUME_RESOLUTION = 32
"""Extinction and transmittance volume resolution for scenes without local fog volumes."""
MAX_VOLUME_RESOLUTION = 64
"""The automatic resolution's cap: 64^3 voxels, 64^2 x 128 samples per light."""
VOXELS_PER_VOLUME = 16
"""The automatic resolution puts this many voxels across the thinnest fog volume."""


def auto_volume_resolution(scene: Scene, lo, hi) -> int:
    """The volume resolution a scene requires over the region ``lo .. hi``: enough voxels
    that the thinnest fog volume overlapping it spans ``VOXELS_PER_VOLUME`` of them
    (``ceil(VOXELS_PER_VOLUME * largest extent / thinnest size)``), between
    ``VOLUME_RESOLUTION`` and ``MAX_VOLUME_RESOLUTION``; ``VOLUME_RESOLUTION`` without fog
    volumes. The region is :func:`volume_bounds`, so a fog volume alone in view is covered
    by its own box and the default resolution resolves it."""
    extent = max(b - a for a, b in zip(lo, hi))
    sizes = []
    for m in scene.media:
        if not isinstance(m, FogVolume):
            continue
        box = media_bounds(Scene(media=(m,)))
        if all(a < d and c < b for a, b, c, d in zip(lo, hi, *box)):
            sizes.append(2 * min(m.half_size))
    if not sizes:
        return VOLUME_RESOLUTION
    want = math.ceil(VOXELS_PER_VOLUME * extent / min(sizes))
    return max(VOLUME_RESOLUTION, min(MAX_VOLUME_RESOLUTION, want))


def check_volume_resolution(value):
    """``volume_resolution``: None (:func:`auto_volume_resolution`) or an int >= 2."""
    if value is not None and (isinstance(value, bool) or not isinstance(value, int)
                              or value < 2):
        raise ValueError(f"volume_resolution: expected None (chosen from the media's size) "
                         f"or an int >= 2, got {value!r}")
    return value


def slice_offset(grid: FroxelGrid, jitter: float) -> float:
    """Slice coordinate offset of the view depth ``z_k + jitter (z_(k+1) - z_k)`` within any
    slice: ``log(1 + jitter (r - 1)) / log(r)`` with ``r = (far / near)^(1 / slices)``.
    Uniform in depth, so averaging frames over jitters averages the slice over its depth
    (uniform in the slice coordinate would favour the slice's near end)."""
    log_r = math.log(grid.far / grid.near) / grid.slices
    return math.log1p(jitter * math.expm1(log_r)) / log_r


def froxel_sample_coords(grid, jitter, dtype, device):
    """Froxel coordinates (slices, ny, nx, 3) of every froxel's sample point
    ``(i + 0.5, j + 0.5, k + slice_offset(grid, jitter))``: its tile's centre, the fraction
    ``jitter`` of the way through its slice in view depth."""
    k = torch.arange(grid.slices, dtype=dtype, device=device) + slice_offset(grid, jitter)
    j = torch.arange(grid.ny, dtype=dtype, device=device) + 0.5
    i = torch.arange(grid.nx, dtype=dtype, device=device) + 0.5
    kk, jj, ii = torch.meshgrid(k, j, i, indexing="ij")
    return torch.stack([ii, jj, kk], -1)


def check_phase_inputs(cos_theta, g):
    """``g`` as a tensor of ``cos_theta``'s dtype and device, all values in (-1, 1)."""
    check_volume(cos_theta, "cos_theta", cos_theta.shape if isinstance(cos_theta, torch.Tensor)
                 else ())
    if isinstance(g, torch.Tensor):
        if g.dtype != cos_theta.dtype or g.device != cos_theta.device:
            raise TypeError(f"g: expected dtype {cos_theta.dtype} on {cos_theta.device} like "
                            f"cos_theta, got {g.dtype} on {g.device}")
    elif isinstance(g, (int, float)) and not isinstance(g, bool):
        g = torch.tensor(float(g), dtype=cos_theta.dtype, device=cos_theta.device)
    else:
        raise TypeError(f"g: expected a number or a float tensor, got {type(g).__name__}")
    if not bool((g.abs() < 1).all()):
        raise ValueError("g: expected values in (-1, 1) (|g| = 1 is a delta, not a phase "
                         "function)")
    return g


def check_lights(lights):
    lights = tuple(lights)
    for i, light in enumerate(lights):
        if not isinstance(light, LIGHTS):
            raise TypeError(f"lights[{i}]: expected a DirectionalLight, PointLight or "
                            f"SpotLight, got {type(light).__name__}")
    return lights
