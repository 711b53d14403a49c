"""Task 1: the lecture's box ray marcher: ``ray_box_interval`` (the slab test),
``sample_grid`` (trilinear interpolation) and ``march_box`` (front-to-back compositing,
early termination, jittered offsets); and the provided ``evaluate``.
"""

from __future__ import annotations

import torch

from course.given.lab4 import check_grid_inputs, check_march_inputs, check_ray_box_inputs
from course.given.lab4_fields import field_values

from .integrals import segment_integral

# Provided (not a task): a field's values at points, for every task that samples a medium.


def check_density_defined(values: torch.Tensor, name: str = "density") -> None:
    """An extinction coefficient is a number or +inf (opaque), never NaN: a NaN density
    would turn every transmittance behind it into NaN. ValueError naming ``name``."""
    if bool(torch.isnan(values).any()):
        raise ValueError(
            f"{name}: expected extinction coefficients >= 0 (or +inf), got "
            f"{int(torch.isnan(values).sum())} NaN values: a NaN density makes "
            f"the transmittance NaN for every ray that crosses it"
        )


def evaluate(
    field, name: str, points: torch.Tensor, local: torch.Tensor, channels: bool = False
) -> torch.Tensor:
    """A field's values at N points: ``field(points)`` for a callable (world points, checked
    by ``field_values``), ``sample_grid(field, local)`` for a grid (box coordinates in
    [0, 1]^3). Returns (N,), or also (N, C) when ``channels``, in the points' dtype.
    NaN values of a callable ``"density"`` raise ValueError naming it."""
    if isinstance(field, torch.Tensor):
        return sample_grid(field, local)
    values = field_values(field, name, points, channels)
    if name == "density":
        check_density_defined(values)
    return values


def ray_box_interval(origins, directions, box_min, box_max):
    """Where each ray is inside the box: the slab test (Kay & Kajiya).

    origins, directions: (N, 3) float; box_min, box_max: (3,).
    Returns ``(t_near, t_far, hit)``, (N,) each: the parametric interval of the ray inside
    the closed box, clipped to ``t >= 0`` (a ray starting inside has ``t_near = 0``), and
    ``hit = t_near <= t_far`` (bool). Where ``hit`` is False, ``t_near = t_far = 0``.

    Per axis the slab gives ``t = (box_min - o) / d`` and ``(box_max - o) / d``;
    ``1 / ±0 = ±inf`` puts an axis-parallel ray's slab at ``[-inf, inf]`` (inside it) or at
    infinity (outside it: a miss). A ray starting exactly on a slab plane with ``d = 0``
    there gives ``0 * inf = NaN``: that slab says nothing, so the reduction over slabs
    drops NaN (``torch.fmax``/``fmin``). Rays with NaN/inf components or ``d = 0`` miss.
    The differences ``box - o`` come first, so a box far from the world origin keeps the
    relative accuracy of its size.

    Errors: TypeError or ValueError naming ``origins`` or ``directions`` (not float tensors
    of shape (N, 3) or (3,) of one dtype and device); TypeError naming ``box_min`` /
    ``box_max`` unless each is a (3,) tensor of the rays' dtype or 3 numbers; ValueError
    naming them for another shape or device, a non-finite value, or ``box_min > box_max`` on
    an axis.

    Hints: ``torch.reciprocal`` keeps the sign of zero; reduce over the three slabs
    with ``torch.fmax``/``torch.fmin`` (they ignore NaN) and clip ``t_near`` at 0; build the
    validity mask with ``torch.isfinite``; return ``torch.where(hit, t, 0)``.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    origins, directions, box_min, box_max = check_ray_box_inputs(
        origins, directions, box_min, box_max
    )
    raise NotImplementedError("not implemented yet: ray_box_interval (task 1)")


def sample_grid(grid, uvw):
    """Trilinear interpolation of a cell-centred grid at box coordinates.

    grid: (X, Y, Z) or (X, Y, Z, C) float; uvw: (..., 3) float of the grid's dtype, the
    points' coordinates in the box scaled to [0, 1]^3 (``(p - box_min) / (box_max - box_min)``).
    Returns (...) or (..., C).

    ``grid[i, j, k]`` sits at the centre of its voxel, ``uvw = ((i, j, k) + 0.5) / (X, Y, Z)``
    (``align_corners=False`` in ``torch.nn.functional.grid_sample`` terms). Between centres
    the value is trilinear; within half a voxel of a face, and outside the box, the
    coordinates are clamped to the nearest centre (``padding_mode="border"``), so a constant
    grid is constant all the way to the faces. NaN coordinates give 0. A voxel of +inf
    (opaque) gives +inf wherever it weighs, and nothing (not NaN) where its weight is 0.

    Watch the axis order: x indexes the grid's *first* axis. ``grid_sample`` would want
    the grid as ``(1, C, Z, Y, X)`` (depth first) and coordinates ``2 uvw - 1`` in (x, y, z)
    order.

    Errors: TypeError or ValueError naming ``uvw`` (not a float tensor of shape (..., 3)) or
    ``grid`` (not an (X, Y, Z) or (X, Y, Z, C) tensor of the uvw's dtype and device).

    Hints: ``u = uvw * (X, Y, Z) - 0.5`` is the continuous index (voxel centres at the
    integers); clamp it to ``[0, n - 1]``; ``i0 = floor(u)`` clamped to ``[0, n - 2]`` (mind
    ``n = 1``), ``f = u - i0``, ``i1 = min(i0 + 1, n - 1)``. Gather the 8 corners from
    ``grid.reshape(-1, ...)`` at ``(ix * Y + iy) * Z + iz`` and weight each by ``f`` or
    ``1 - f`` per axis. Compare with ``grid_sample`` yourself as the docstring describes.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    check_grid_inputs(grid, uvw)
    raise NotImplementedError("not implemented yet: sample_grid (task 1)")


def march_box(
    origins,
    directions,
    box_min,
    box_max,
    density,
    emission=None,
    steps=64,
    *,
    integrator="exact",
    min_transmittance=0.0,
    jitter=False,
    seed=0,
):
    """The lecture's ray marcher: a fixed number of steps through a volume in a box.

    origins, directions: (N, 3) float; box_min, box_max: (3,); density: callable or grid
    (X, Y, Z); emission: None (a purely absorbing medium), callable, or grid (X, Y, Z) or
    (X, Y, Z, C); steps: int >= 0, the same for every ray.
    Returns a dict of tensors on the rays' device:
      ``radiance`` (N,) or (N, C): the emitted light reaching the origin,
      ``transmittance`` (N,): ``T`` at the end of the march (what the background keeps),
      ``samples`` (N,) int64: the steps the ray took (density evaluations).

    1. ``[t_near, t_far]`` from :func:`ray_box_interval`; ``steps`` equal steps of
       ``dt = (t_far - t_near) / steps`` (world length ``ds = |d| dt``).
    2. Step i samples the medium at ``t_near + (i + xi) dt``: ``xi = 1/2`` (midpoint), or
       with ``jitter`` one offset ``xi`` in [0, 1] per ray, the same for all its steps,
       drawn on the CPU from a generator seeded with ``seed`` (the same offsets on every
       device).
    3. Front to back: ``(w, T_step) = segment_integral(sigma_i, ds, integrator)``, then
       ``L += T * q_i * w`` and only then ``T *= T_step``: the sample is seen through
       everything in front of it (``w`` already accounts for the step itself).
    4. Early termination: a ray whose ``T`` has dropped below ``min_transmittance`` stops
       (no more samples); the loop ends when no ray is left. The light it ignores is at
       most ``min_transmittance * max(q / sigma)`` (exact integrator).

    Grids are sampled at box coordinates computed as ``((o - box_min) + t d) / size``,
    never from the absolute point, so a box far from the origin keeps its accuracy; on a
    flat axis (``box_min = box_max`` there) at its middle, 0.5. Callables get world points.
    The density is an extinction coefficient, >= 0 or +inf: a grid or a callable with
    negative or NaN values raises ValueError naming ``density`` (the provided checks and
    ``evaluate`` do it). Rays that miss (and NaN/inf rays) sample nothing: radiance 0,
    transmittance 1, samples 0. ``steps = 0`` is an empty march.

    Errors: ValueError or TypeError naming ``origins``, ``directions``, ``box_min`` or
    ``box_max`` as in ``ray_box_interval``; ``density`` (neither a callable nor an (X, Y, Z)
    grid of the rays' dtype and device; ValueError for negative or NaN values, also from a
    callable) or ``emission`` (neither None, a callable nor an (X, Y, Z) / (X, Y, Z, C) grid
    like that); TypeError or ValueError naming ``steps`` unless it is an int >= 0;
    ValueError naming ``integrator`` (not ``"exact"`` or ``"riemann"``) or
    ``min_transmittance`` (not a number in [0, 1]).

    Hints: ``ray_box_interval`` gives the span. Keep ``rel = o - box_min`` (0 for
    missed rays) and sample at ``offset = rel + t d``: ``local = offset / size`` for grids,
    ``box_min + offset`` for callables; the provided ``evaluate(field, name, points, local,
    channels)`` does the rest (it calls your ``sample_grid``). Mask inactive rays with
    ``torch.where`` *before* ``segment_integral``. The radiance is (N,) or (N, C) as the
    emission's values are; with no emission (or no step) return zeros of that shape.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    origins, directions, box_min, box_max = check_march_inputs(
        origins,
        directions,
        box_min,
        box_max,
        density,
        emission,
        steps,
        integrator,
        min_transmittance,
    )
    if isinstance(density, torch.Tensor):
        check_density_defined(density)
    raise NotImplementedError("not implemented yet: march_box (task 1)")
