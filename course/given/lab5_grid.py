"""Lab 5's froxel grid: :class:`FroxelGrid`, the grid a scene requires (``scene_grid``),
the froxels' sample positions and jitter, texture sampling and ray-box tests.

Given code, not exercises (imported through :mod:`course.given.lab5`). Units are physical
(see there).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from course.core.camera import Camera, _camera_axes
from course.given.lab5_scene import DirectionalLight, FogVolume, Scene, _num


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
            raise TypeError(
                f"camera: expected a course.core.camera.Camera, got {type(self.camera).__name__}"
            )
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
        right, up, back = (
            a.to(device, dtype)
            for a in _camera_axes(self.camera.eye, self.camera.target, self.camera.up)
        )
        eye = torch.tensor(self.camera.eye, dtype=dtype, device=device)
        half_h = math.tan(math.radians(self.camera.fov_y) / 2)
        return eye, right, up, -back, (half_h * self.camera.aspect, half_h)


# ---------------------------------------------------------------------------------------
# Given numerical functions


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
    t_hit = torch.full(origins.shape[:-1], math.inf, dtype=origins.dtype, device=origins.device)
    inv = torch.reciprocal(directions)
    for box in boxes:
        lo = torch.tensor(box.lo, dtype=origins.dtype, device=origins.device)
        hi = torch.tensor(box.hi, dtype=origins.dtype, device=origins.device)
        t0, t1 = (lo - origins) * inv, (hi - origins) * inv
        near = torch.fmax(
            torch.minimum(t0, t1).nan_to_num(nan=-math.inf).amax(-1), torch.zeros_like(t_hit)
        )
        far = torch.maximum(t0, t1).nan_to_num(nan=math.inf).amin(-1)
        hit = (near <= far) & (far > 0)
        t_hit = torch.where(hit, torch.minimum(t_hit, near), t_hit)
    return t_hit


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


# The froxel grid a scene requires. Froxels sample the media at their centres and the image
# reads them bilinearly between tile centres: a fog volume spanning few tiles on screen
# loses or gains light along its silhouette (a 4 m box 8 tiles across: -6% in mean
# radiance), and slices spread over 0.1 .. 100 m put few of them where a small volume is.
TILE, SLICES, NEAR, FAR = 8, 64, 0.1, 100.0
TILES_PER_VOLUME = 12
# Smaller tiles never make more screen tiles than 8-pixel tiles at 1920 x 1080: a small
# volume far away in a large image keeps the talk's grid rather than 130M froxels.
MAX_TILES = 240 * 135


def lights_in_media(scene: Scene, camera: Camera) -> bool:
    """Whether a point or spot light sits inside a scattering medium (inside a fog volume's
    shape, its density texture aside, or anywhere in an unbounded constant or height fog)
    and in view: in front of the camera, its image on the screen or within ``TILE`` pixels
    of its border.

    Such a light's ``1 / d^2`` makes the in-scattered light peak around its image, over
    distances as small as the light is close to a pixel's ray: froxel samples at tile
    centres, read bilinearly, miss or smear that peak (a lamp inside a box of fog seen
    through 2-pixel tiles: -2% to -27% in mean radiance, depending on where the tile centres
    fall). A light behind the camera or far off screen lights the view smoothly: any tile
    resolves it (a lamp just behind the camera in fog: -0.4% with 8-pixel tiles)."""
    eye, right, up, fwd, (half_w, half_h) = FroxelGrid(camera).axes()
    for light in scene.lights:
        if isinstance(light, DirectionalLight):
            continue
        rel = torch.tensor(light.position, dtype=torch.float64) - eye
        z = float(rel @ fwd)
        if z <= 0:
            continue
        col = (float(rel @ right) / (z * half_w) + 1) / 2 * camera.width
        row = (1 - float(rel @ up) / (z * half_h)) / 2 * camera.height
        if not (-TILE <= col <= camera.width + TILE and -TILE <= row <= camera.height + TILE):
            continue
        for m in scene.media:
            if max(m.scattering) <= 0:
                continue
            if not isinstance(m, FogVolume):
                return True
            local = [
                sum(r * (x - c) for r, x, c in zip(axis, light.position, m.center))
                for axis in m.rotation
            ]
            q = [abs(a / h) for a, h in zip(local, m.half_size)]
            if (max(q) if m.shape == "box" else math.sqrt(sum(x * x for x in q))) <= 1:
                return True
    return False


def scene_grid(
    scene: Scene, camera: Camera, tile=None, slices=SLICES, near=None, far=None
) -> FroxelGrid:
    """The ``FroxelGrid`` for ``scene`` seen by ``camera``; None picks what the scene needs.

    ``near``/``far`` None: the view-depth range of the media (the corners of every fog
    volume's box) within ``NEAR .. FAR``, so the slices lie where the media are and no
    light is lost before ``near`` or after ``far``; ``NEAR .. FAR`` when a medium is unbounded
    (height or constant fog) or the media lie behind the camera. ``tile`` None: the largest
    of ``TILE``, ``TILE / 2``, ... 1 at which every fog volume in front of the camera (and not
    around it) spans ``TILES_PER_VOLUME`` tiles across its thinnest side at its centre's
    depth, and down to 1 when a point or spot light sits inside a medium in view
    (:func:`lights_in_media`: its ``1 / d^2`` peak is narrower than any tile, and tiles of
    one pixel sample every pixel's own ray), as long as the screen holds at most
    ``MAX_TILES`` tiles (so a large image keeps coarser tiles, and the accuracy of tile 1
    only up to 240 x 135 pixels). A scene of unbounded media lit by the sun, or volumes
    filling the view, keeps ``TILE``; a 2 m box 5 m away in a 64 x 36 image gets tile 1
    (36 x 64 x 64 froxels, few of them lit).
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
            signs = torch.tensor(
                [[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=torch.float64
            )
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
            lamps = lights_in_media(scene, camera)
            while (
                tile > 1
                and (lamps or any(s < TILES_PER_VOLUME * tile for s in sizes))
                and (
                    -(-camera.width // (tile // 2)) * -(-camera.height // (tile // 2)) <= MAX_TILES
                )
            ):
                tile //= 2
    return FroxelGrid(camera, tile, slices, near, far)
