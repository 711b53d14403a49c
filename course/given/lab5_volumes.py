"""Lab 5's light-space textures: sun shadow maps and transmittance volumes (their frames,
coordinates and bounds) and the automatic volume resolution.

Given code, not exercises (imported through :mod:`course.given.lab5`). Units are physical
(see there).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from course.given.lab5_grid import FroxelGrid
from course.given.lab5_scene import DirectionalLight, FogVolume, Scene

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
    other = torch.tensor(
        [0.0, 1.0, 0.0] if abs(float(w[1])) < 0.9 else [1.0, 0.0, 0.0], dtype=torch.float64
    )
    u = torch.linalg.cross(other, w)
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
            reach = (
                math.sqrt(sum(t * t for t in terms))
                if m.shape == "ellipsoid"
                else sum(abs(t) for t in terms)
            )
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
