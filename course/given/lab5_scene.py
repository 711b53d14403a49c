"""Lab 5's scene: media (constant and height fog, fog volumes), lights (sun, point,
spot), occluder boxes and the :class:`Scene` that holds them, each validated when made.

Given code, not exercises (imported through :mod:`course.given.lab5`). Units are physical
(see there).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import torch

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


def _num(
    value,
    name: str,
    lo: float = -math.inf,
    hi: float = math.inf,
    open_lo: bool = False,
    open_hi: bool = False,
) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise TypeError(f"{name}: expected a number, got {type(value).__name__}")
    ok = (lo < value if open_lo else lo <= value) and (value < hi if open_hi else value <= hi)
    if not ok or math.isnan(value):
        raise ValueError(
            f"{name}: expected a number in {'(' if open_lo else '['}{lo}, {hi}"
            f"{')' if open_hi else ']'}, got {value!r}"
        )
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
        raise ValueError(
            f"scattering: expected every channel <= extinction={obj.extinction} "
            f"(albedo <= 1), got {obj.scattering}"
        )
    object.__setattr__(obj, "g", _num(obj.g, "g", -1.0, 1.0, open_lo=True, open_hi=True))


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
        if m.shape != (3, 3) or not torch.allclose(
            m @ m.T, torch.eye(3, dtype=torch.float64), atol=1e-6
        ):
            raise ValueError("rotation: expected a 3x3 orthonormal matrix (rows: local axes)")
        object.__setattr__(self, "rotation", rows)
        d = self.density
        if d is not None:
            if not isinstance(d, torch.Tensor) or not d.is_floating_point():
                raise TypeError(
                    f"density: expected None or a float tensor (X, Y, Z), got "
                    f"{getattr(d, 'dtype', type(d).__name__)}"
                )
            if d.ndim != 3 or min(d.shape) < 1:
                raise ValueError(f"density: expected a grid (X, Y, Z), got {tuple(d.shape)}")
            if not bool(torch.isfinite(d).all()) or bool((d < 0).any()):
                raise ValueError("density: expected finite values >= 0")


MEDIA = (ConstantFog, HeightFog, FogVolume)


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
                    raise TypeError(
                        f"{name}[{i}]: expected one of "
                        f"{', '.join(k.__name__ for k in kinds)}, got "
                        f"{type(item).__name__}"
                    )
            object.__setattr__(self, name, items)
        object.__setattr__(self, "ambient", _vec(self.ambient, "ambient", nonneg=True))
