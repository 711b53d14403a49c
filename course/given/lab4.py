"""Input checks and small helpers shared by Lab 4's skeleton and reference.

Given code, not exercises: the lab's skeleton and its reference import these, so
there is one copy of them.
"""

from __future__ import annotations

import math

import torch

from course.core.raymath import check_inputs

INTEGRATORS = ("exact", "riemann")
"""Per-step integrators of :func:`segment_integral` (the accuracy knob of the marchers)."""
MISS, HIT, UNSURE = 0, 1, 2
"""Status codes of :func:`sphere_trace`: the ray escaped (``t > t_max``), found a surface,
or ran out of steps before deciding (a grazing ray)."""


def check_rays(origins, directions, names=("origins", "directions")):
    """Validate rays; return ``(origins, directions)`` broadcast to ``(N, 3)``."""
    shape, _ = check_inputs({names[0]: (origins, (3,)), names[1]: (directions, (3,))})
    if len(shape) != 1:
        raise ValueError(
            f"{names[0]}: expected shape (N, 3) (or one (3,) shared by all), "
            f"got {tuple(origins.shape)} with {names[1]} {tuple(directions.shape)}"
        )
    return origins.expand(*shape, 3), directions.expand(*shape, 3)


def as_vector(value, name: str, like: torch.Tensor) -> torch.Tensor:
    """A (3,) tensor of ``like``'s dtype and device from a tensor or 3 numbers."""
    if isinstance(value, torch.Tensor):
        if not value.is_floating_point() or value.dtype != like.dtype:
            raise TypeError(
                f"{name}: expected a tensor of dtype {like.dtype} like the rays, got {value.dtype}"
            )
        if value.device != like.device:
            raise ValueError(
                f"{name}: expected a tensor on {like.device} like the rays, "
                f"got one on {value.device}"
            )
    elif isinstance(value, (list, tuple)) and all(
        isinstance(v, (int, float)) and not isinstance(v, bool) for v in value
    ):
        value = torch.tensor(value, dtype=like.dtype, device=like.device)
    else:
        raise TypeError(f"{name}: expected a (3,) tensor or 3 numbers, got {type(value).__name__}")
    if value.shape != (3,):
        raise ValueError(f"{name}: expected shape (3,), got {tuple(value.shape)}")
    if not bool(torch.isfinite(value).all()):
        raise ValueError(f"{name}: expected finite values, got {value.tolist()}")
    return value


def as_box(box_min, box_max, like: torch.Tensor):
    """``box_min, box_max`` as (3,) tensors of ``like``'s dtype and device, with
    ``box_min <= box_max`` on every axis."""
    lo, hi = as_vector(box_min, "box_min", like), as_vector(box_max, "box_max", like)
    if not bool((lo <= hi).all()):
        raise ValueError(
            f"box_max: expected box_min <= box_max on every axis, got "
            f"{lo.tolist()} .. {hi.tolist()}"
        )
    return lo, hi


def check_count(value, name: str, minimum: int) -> int:
    """A Python int >= ``minimum`` (a step count), else TypeError/ValueError naming it."""
    if isinstance(value, bool) or not isinstance(value, int):
        raise TypeError(f"{name}: expected an int, got {type(value).__name__}")
    if value < minimum:
        raise ValueError(f"{name}: expected an int >= {minimum}, got {value}")
    return value


def check_number(value, name: str, lo: float, hi: float, closed_hi: bool = True) -> float:
    """A Python number in ``[lo, hi]`` (``[lo, hi)`` unless ``closed_hi``)."""
    if (
        isinstance(value, bool)
        or not isinstance(value, (int, float))
        or not (lo <= value and (value <= hi if closed_hi else value < hi))
    ):
        raise ValueError(
            f"{name}: expected a number in [{lo}, {hi}{']' if closed_hi else ')'}, got {value!r}"
        )
    return float(value)


def check_field(
    field, name: str, like: torch.Tensor, channels: bool = False, grid_only: bool = False
):
    """A medium field: a callable, or a grid tensor (X, Y, Z) (also (X, Y, Z, C) when
    ``channels``) of ``like``'s dtype and device with at least one voxel per axis."""
    if callable(field) and not isinstance(field, torch.Tensor) and not grid_only:
        return field
    if not isinstance(field, torch.Tensor):
        what = "a grid tensor" if grid_only else "a callable of points or a grid tensor"
        raise TypeError(f"{name}: expected {what}, got {type(field).__name__}")
    shapes = "(X, Y, Z) or (X, Y, Z, C)" if channels else "(X, Y, Z)"
    if field.ndim not in ((3, 4) if channels else (3,)) or min(field.shape) < 1:
        raise ValueError(f"{name}: expected a grid of shape {shapes}, got {tuple(field.shape)}")
    if field.dtype != like.dtype:
        raise TypeError(
            f"{name}: expected a grid of dtype {like.dtype} like the rays, got {field.dtype}"
        )
    if field.device != like.device:
        raise ValueError(
            f"{name}: expected a grid on {like.device} like the rays, got one on {field.device}"
        )
    return field


def check_density_values(density, name: str = "density") -> None:
    """A density grid must hold extinction coefficients >= 0 (a negative one would make
    the transmittance exceed 1): ValueError naming it otherwise."""
    if isinstance(density, torch.Tensor) and bool((density < 0).any()):
        raise ValueError(
            f"{name}: expected values >= 0 (an extinction coefficient), got "
            f"{int((density < 0).sum())} negative (minimum "
            f"{density.min().item():.3g})"
        )


def check_integrator(integrator):
    if integrator not in INTEGRATORS:
        raise ValueError(
            f"integrator: expected one of {', '.join(map(repr, INTEGRATORS))}, got {integrator!r}"
        )


def check_ray_box_inputs(origins, directions, box_min, box_max):
    origins, directions = check_rays(origins, directions)
    return (origins, directions, *as_box(box_min, box_max, origins))


def check_grid_inputs(grid, uvw):
    check_inputs({"uvw": (uvw, (3,))})
    check_field(grid, "grid", uvw, channels=True, grid_only=True)


def check_march_inputs(
    origins, directions, box_min, box_max, density, emission, steps, integrator, min_transmittance
):
    """Validate :func:`march_box`'s arguments; returns ``(origins, directions, box_min,
    box_max)`` as tensors ((N, 3), (N, 3), (3,), (3,))."""
    origins, directions, box_min, box_max = check_ray_box_inputs(
        origins, directions, box_min, box_max
    )
    check_field(density, "density", origins)
    check_density_values(density)
    if emission is not None:
        check_field(emission, "emission", origins, channels=True)
    check_count(steps, "steps", 0)
    check_integrator(integrator)
    check_number(min_transmittance, "min_transmittance", 0.0, 1.0)
    return origins, directions, box_min, box_max


def check_segment_inputs(sigma, length, integrator):
    """``sigma, length`` as tensors of one dtype and device (numbers are converted)."""
    check_integrator(integrator)
    like = next((v for v in (sigma, length) if isinstance(v, torch.Tensor)), None)
    result = []
    for name, value in (("sigma", sigma), ("length", length)):
        if isinstance(value, torch.Tensor):
            if not value.is_floating_point():
                raise TypeError(f"{name}: expected a floating-point tensor, got {value.dtype}")
            if value.dtype != like.dtype or value.device != like.device:
                raise TypeError(
                    f"{name}: expected dtype {like.dtype} on {like.device} like "
                    f"sigma, got {value.dtype} on {value.device}"
                )
        elif isinstance(value, (int, float)) and not isinstance(value, bool):
            value = torch.tensor(
                float(value),
                dtype=like.dtype if like is not None else None,
                device=like.device if like is not None else None,
            )
        else:
            raise TypeError(
                f"{name}: expected a number or a float tensor, got {type(value).__name__}"
            )
        if bool((value < 0).any()):
            raise ValueError(
                f"{name}: expected values >= 0 (a negative {name} would make the "
                f"transmittance exceed 1), got minimum {value.min().item():.3g}"
            )
        result.append(value)
    return result


def check_phase_inputs(cos_theta, g):
    """``g`` as a tensor of ``cos_theta``'s dtype and device, all values in (-1, 1)."""
    if not isinstance(cos_theta, torch.Tensor) or not cos_theta.is_floating_point():
        raise TypeError(
            "cos_theta: expected a floating-point tensor, got "
            + (
                str(cos_theta.dtype)
                if isinstance(cos_theta, torch.Tensor)
                else type(cos_theta).__name__
            )
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
        raise ValueError(
            f"g: expected values in (-1, 1) (|g| = 1 is a delta, not a phase "
            f"function), got {g.tolist()}"
        )
    return g


def unit_light(light_direction, like: torch.Tensor) -> torch.Tensor:
    """The unit vector toward the light, (3,) of ``like``'s dtype (normalised in float64)."""
    light = as_vector(light_direction, "light_direction", like)
    norm = light.double().norm()
    if norm == 0:
        raise ValueError("light_direction: expected a non-zero vector, got (0, 0, 0)")
    return (light.double() / norm).to(like.dtype)


def check_shadow_inputs(points, light_direction, box_min, box_max, density, steps):
    """Returns ``(points (N, 3), unit light (3,), box_min, box_max)``."""
    shape, _ = check_inputs({"points": (points, (3,))})
    if len(shape) != 1:
        raise ValueError(f"points: expected shape (N, 3), got {tuple(points.shape)}")
    box_min, box_max = as_box(box_min, box_max, points)
    check_field(density, "density", points)
    check_density_values(density)
    check_count(steps, "steps", 0)
    return points, unit_light(light_direction, points), box_min, box_max


def check_scatter_inputs(
    origins,
    directions,
    box_min,
    box_max,
    density,
    albedo,
    light_direction,
    light_irradiance,
    g,
    steps,
    shadow_steps,
    integrator,
    min_transmittance,
):
    """Returns ``(origins, directions, box_min, box_max, unit light (3,), factor)`` with
    ``factor = albedo * light_irradiance`` (a number or a (C,) tensor)."""
    origins, directions, box_min, box_max = check_march_inputs(
        origins, directions, box_min, box_max, density, None, steps, integrator, min_transmittance
    )
    factor = 1.0
    for name, value in (("albedo", albedo), ("light_irradiance", light_irradiance)):
        if isinstance(value, torch.Tensor):
            if value.ndim != 1 or value.dtype != origins.dtype or value.device != origins.device:
                raise TypeError(
                    f"{name}: expected a number or a (C,) tensor of dtype "
                    f"{origins.dtype} on {origins.device}, got shape "
                    f"{tuple(value.shape)}, {value.dtype} on {value.device}"
                )
        elif isinstance(value, bool) or not isinstance(value, (int, float)) or not value >= 0:
            raise ValueError(f"{name}: expected a number >= 0 or a (C,) tensor, got {value!r}")
        factor = factor * value
    check_phase_inputs(torch.zeros((), dtype=origins.dtype, device=origins.device), g)
    check_count(shadow_steps, "shadow_steps", 0)
    return origins, directions, box_min, box_max, unit_light(light_direction, origins), factor


def check_occupancy_inputs(density, macro_cell, emission):
    check_field(density, "density", density, grid_only=True)
    check_count(macro_cell, "macro_cell", 1)
    if emission is not None:
        check_field(emission, "emission", density, channels=True, grid_only=True)
        if emission.shape[:3] != density.shape:
            raise ValueError(
                f"emission: expected a grid with the voxels of density "
                f"{tuple(density.shape)}, got {tuple(emission.shape)}"
            )


def check_voxel_inputs(
    origins, directions, box_min, box_max, density, emission, occupancy, macro_cell
):
    """Returns ``(origins, directions, box_min, box_max)``; density must be a grid >= 0."""
    origins, directions, box_min, box_max = check_ray_box_inputs(
        origins, directions, box_min, box_max
    )
    check_field(density, "density", origins, grid_only=True)
    check_occupancy_inputs(density, macro_cell, emission)
    if bool((density < 0).any()):
        raise ValueError("density: expected values >= 0 (an extinction coefficient)")
    if occupancy is not None:
        want = tuple(-(-s // macro_cell) for s in density.shape)
        if (
            not isinstance(occupancy, torch.Tensor)
            or occupancy.dtype != torch.bool
            or tuple(occupancy.shape) != want
            or occupancy.device != origins.device
        ):
            raise ValueError(
                f"occupancy: expected a bool grid of shape {want} on "
                f"{origins.device}, as build_occupancy(density, {macro_cell}) "
                f"returns"
            )
    return origins, directions, box_min, box_max


def check_trace_inputs(origins, directions, sdf, t_max, max_steps, epsilon, relaxation):
    origins, directions = check_rays(origins, directions)
    if not callable(sdf):
        raise TypeError(f"sdf: expected a callable of points, got {type(sdf).__name__}")
    check_count(max_steps, "max_steps", 1)
    if isinstance(t_max, bool) or not isinstance(t_max, (int, float)) or not 0 < t_max < math.inf:
        raise ValueError(
            f"t_max: expected a finite number > 0, got {t_max!r} (the hit test "
            f"|f| <= epsilon t |d| accepts any distance |f| once t >= |f| / "
            f"epsilon: without a bound every ray ends in a hit)"
        )
    check_number(epsilon, "epsilon", 0.0, 1.0, closed_hi=False)
    if epsilon == 0:
        raise ValueError("epsilon: expected a number > 0 (0 is never reached in floating point)")
    check_number(relaxation, "relaxation", 1.0, 2.0, closed_hi=False)
    return origins, directions


def sdf_sphere(points, center, radius):
    """Signed distance to a sphere, ``|p - c| - r`` (negative inside). points (..., 3)."""
    c = torch.as_tensor(center, dtype=points.dtype, device=points.device)
    return (points - c).norm(dim=-1) - radius


def sdf_box(points, center, half_size):
    """Signed distance to an axis-aligned box, exact inside and outside (Quilez)."""
    c = torch.as_tensor(center, dtype=points.dtype, device=points.device)
    h = torch.as_tensor(half_size, dtype=points.dtype, device=points.device)
    q = (points - c).abs() - h
    return q.clamp(min=0).norm(dim=-1) + q.amax(dim=-1).clamp(max=0)


def sdf_union(*distances):
    """Union of solids: the minimum of their signed distances (exact outside, a bound
    inside where the solids overlap)."""
    result = distances[0]
    for d in distances[1:]:
        result = torch.minimum(result, d)
    return result
