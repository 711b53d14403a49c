"""Lab 5's pipeline constants (phase functions, integrations, the blend, dtypes) and input
checks: each raises ValueError/TypeError naming the argument it rejects.

Given code, not exercises (imported through :mod:`course.given.lab5`). Units are physical
(see there).
"""

from __future__ import annotations

import math

import torch

from course.core.camera import Camera
from course.given.lab5_grid import FroxelGrid
from course.given.lab5_scene import LIGHTS, Scene, _num

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


def check_dtype(dtype, name: str = "dtype") -> torch.dtype:
    if dtype not in FLOATS:
        raise TypeError(
            f"{name}: expected torch.float32 or torch.float64, got {dtype} "
            f"(float16/bfloat16 lose the exponential slicing and transmittance)"
        )
    return dtype


def check_grid(grid) -> FroxelGrid:
    if not isinstance(grid, FroxelGrid):
        raise TypeError(f"grid: expected a FroxelGrid, got {type(grid).__name__}")
    return grid


def check_scene(scene) -> Scene:
    if not isinstance(scene, Scene):
        raise TypeError(f"scene: expected a course.given.lab5.Scene, got {type(scene).__name__}")
    return scene


def check_volume(x, name: str, shape, dtype=None, device=None) -> torch.Tensor:
    """A float tensor of exactly ``shape`` (and ``dtype``/``device`` when given)."""
    if not isinstance(x, torch.Tensor) or not x.is_floating_point():
        raise TypeError(
            f"{name}: expected a float tensor of shape {tuple(shape)}, got "
            f"{getattr(x, 'dtype', type(x).__name__)}"
        )
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
        raise ValueError(f"{name}: expected one of {', '.join(map(repr, choices))}, got {value!r}")
    return value


def check_jitter(jitter) -> float:
    return _num(jitter, "jitter", 0.0, 1.0, open_hi=True)


def check_images(camera: Camera, depth_image, opaque_image):
    """``depth_image`` (H, W) view depths >= 0 (+inf: sky) and ``opaque_image`` (H, W, 3),
    float32/float64 of one dtype and device; returns their dtype."""
    h, w = camera.height, camera.width
    check_volume(depth_image, "depth_image", (h, w))
    check_volume(
        opaque_image, "opaque_image", (h, w, 3), dtype=depth_image.dtype, device=depth_image.device
    )
    if bool((torch.isnan(depth_image) | (depth_image < 0)).any()):
        raise ValueError(
            "depth_image: expected view depths >= 0 (+inf for the sky), got NaN or negative values"
        )
    return depth_image.dtype


def check_volume_resolution(value):
    """``volume_resolution``: None (:func:`auto_volume_resolution`) or an int >= 2."""
    if value is not None and (isinstance(value, bool) or not isinstance(value, int) or value < 2):
        raise ValueError(
            f"volume_resolution: expected None (chosen from the media's size) "
            f"or an int >= 2, got {value!r}"
        )
    return value


def check_phase_inputs(cos_theta, g):
    """``g`` as a tensor of ``cos_theta``'s dtype and device, all values in (-1, 1)."""
    check_volume(
        cos_theta, "cos_theta", cos_theta.shape if isinstance(cos_theta, torch.Tensor) else ()
    )
    if isinstance(g, torch.Tensor):
        if g.dtype != cos_theta.dtype or g.device != cos_theta.device:
            raise TypeError(
                f"g: expected dtype {cos_theta.dtype} on {cos_theta.device} like "
                f"cos_theta, got {g.dtype} on {g.device}"
            )
    elif isinstance(g, (int, float)) and not isinstance(g, bool):
        g = torch.tensor(float(g), dtype=cos_theta.dtype, device=cos_theta.device)
    else:
        raise TypeError(f"g: expected a number or a float tensor, got {type(g).__name__}")
    if not bool((g.abs() < 1).all()):
        raise ValueError("g: expected values in (-1, 1) (|g| = 1 is a delta, not a phase function)")
    return g


def check_lights(lights):
    lights = tuple(lights)
    for i, light in enumerate(lights):
        if not isinstance(light, LIGHTS):
            raise TypeError(
                f"lights[{i}]: expected a DirectionalLight, PointLight or "
                f"SpotLight, got {type(light).__name__}"
            )
    return lights
