"""The box ray marcher as one Triton kernel: Lab 4's ``march_box`` for grids, fused.

Lab 4 writes the marcher as batched torch code: every step of every ray is a dozen tensor
operations over all rays, each a kernel launch that reads and writes its operands in
DRAM. The lecture's shader does the opposite: one thread per ray, a loop over the steps,
the running radiance and transmittance in registers, and only the volume texture read
from memory. This kernel is that design, given (not an exercise) so the lab can measure
the gap between the two organisations on the same numbers.

What it computes is exactly ``march_box(origins, directions, box_min, box_max, density,
source, steps, integrator="exact")`` for grid media (Lab 4's contract):

* ``[t_near, t_far]`` from the slab test, clipped to ``t >= 0``; NaN/inf rays and
  ``d = 0`` miss (radiance 0, transmittance 1);
* ``steps`` equal steps, sampled at their midpoints, both grids read by cell-centred
  trilinear interpolation with border clamping (``sample_grid``) at box coordinates
  ``((o - box_min) + t d) / size``;
* the energy-conserving step ``L += T q (1 - e^{-sigma ds}) / sigma``, then
  ``T *= e^{-sigma ds}``, with the ratio's series for small ``sigma ds`` (no ``0 / 0``);
* early termination: a ray whose ``T`` dropped below ``min_transmittance`` stops sampling
  (its loads are masked off; the loop count is the same for all rays of a block).

Single scattering of a directional light fits this form when the light's transmittance
is baked into a grid: ``source = albedo sigma E T_light`` per voxel, and the phase
function, constant along a ray, multiplies the result (``bench/lab4_march.py`` does this
for its 1080p target and reports the baked shadow's error against per-sample shadow rays).
The bake is a kernel too, :func:`bake_light_triton`: one lane per voxel marches toward the
light (Lab 4's ``shadow_transmittance`` of the voxel centres) and writes the source grid,
so a whole frame is two launches instead of a bake of a hundred eager torch operations
(each a pass over the whole grid in DRAM) and one launch.

Runs compiled on CUDA, or in Triton's CPU interpreter when ``TRITON_INTERPRET=1`` is set
before ``triton`` is first imported (small tests only). Accuracy: float32 throughout;
agrees with the torch marcher in float32 to rounding (a few ulp per step, accumulated).
"""

from __future__ import annotations

import math

import torch

from course.kernels.triton_intersect import _ieee_quiet, _is_pow2, _jit, _require_triton, tl, triton

__all__ = ["bake_light_triton", "march_grid_triton"]

DEFAULT_BLOCK_RAYS = 128
DEFAULT_NUM_WARPS = 4


@_jit
def _trilinear(grid_ptr, u, v, w, nx, ny, nz, fx, fy, fz, stride, channel, live):
    """Cell-centred trilinear sample with border clamping (Lab 4's ``sample_grid``)."""
    cx = tl.minimum(tl.maximum(u * fx - 0.5, 0.0), fx - 1.0)
    cy = tl.minimum(tl.maximum(v * fy - 0.5, 0.0), fy - 1.0)
    cz = tl.minimum(tl.maximum(w * fz - 0.5, 0.0), fz - 1.0)
    ix = tl.minimum(tl.floor(cx).to(tl.int32), tl.maximum(nx - 2, 0))
    iy = tl.minimum(tl.floor(cy).to(tl.int32), tl.maximum(ny - 2, 0))
    iz = tl.minimum(tl.floor(cz).to(tl.int32), tl.maximum(nz - 2, 0))
    ax, ay, az = cx - ix, cy - iy, cz - iz
    jx, jy, jz = tl.minimum(ix + 1, nx - 1), tl.minimum(iy + 1, ny - 1), tl.minimum(iz + 1, nz - 1)
    total = tl.zeros_like(u)
    for corner in tl.static_range(8):
        # Bit k of the corner picks the upper neighbour along axis k.
        bx = corner & 1
        by = (corner >> 1) & 1
        bz = (corner >> 2) & 1
        gx = ix + (jx - ix) * bx
        gy = iy + (jy - iy) * by
        gz = iz + (jz - iz) * bz
        wx = (1 - bx) + (2 * bx - 1) * ax
        wy = (1 - by) + (2 * by - 1) * ay
        wz = (1 - bz) + (2 * bz - 1) * az
        index = ((gx * ny + gy) * nz + gz) * stride + channel
        total += wx * wy * wz * tl.load(grid_ptr + index, mask=live, other=0.0)
    return total


@_jit
def _slab(r, d, size, t_near, t_far):
    """One axis of the slab test on box-relative coordinates: the interval, narrowed."""
    inv = 1.0 / d
    t0 = (0.0 - r) * inv
    t1 = (size - r) * inv
    # 0 * inf = NaN: a ray on a slab plane and parallel to it lies in the closed slab, so
    # that slab says nothing. Replace the NaN before min/max, whose NaN rule differs
    # between the compiled kernel and the interpreter.
    t0 = tl.where(t0 == t0, t0, -float("inf"))  # noqa: PLR0124 (NaN test)
    t1 = tl.where(t1 == t1, t1, float("inf"))  # noqa: PLR0124
    t_near = tl.maximum(t_near, tl.minimum(t0, t1))
    t_far = tl.minimum(t_far, tl.maximum(t0, t1))
    return t_near, t_far


@_jit
def _march_kernel(
    o_ptr,
    d_ptr,
    density_ptr,
    source_ptr,
    radiance_ptr,
    trans_ptr,
    samples_ptr,
    n_rays,
    divisions,
    min_t,
    lo_x,
    lo_y,
    lo_z,
    size_x,
    size_y,
    size_z,
    nx,
    ny,
    nz,
    STEPS: tl.constexpr,
    CHANNELS: tl.constexpr,
    BLOCK_RAYS: tl.constexpr,
):
    ray = tl.program_id(0) * BLOCK_RAYS + tl.arange(0, BLOCK_RAYS)
    live = ray < n_rays
    ox = tl.load(o_ptr + 3 * ray, mask=live, other=0.0)
    oy = tl.load(o_ptr + 3 * ray + 1, mask=live, other=0.0)
    oz = tl.load(o_ptr + 3 * ray + 2, mask=live, other=0.0)
    dx = tl.load(d_ptr + 3 * ray, mask=live, other=0.0)
    dy = tl.load(d_ptr + 3 * ray + 1, mask=live, other=0.0)
    dz = tl.load(d_ptr + 3 * ray + 2, mask=live, other=0.0)
    # Box-relative origin first: a far-away box keeps the accuracy of its size.
    rx, ry, rz = ox - lo_x, oy - lo_y, oz - lo_z
    inf = float("inf")
    t_near = tl.zeros_like(ox)
    t_far = tl.full(ox.shape, inf, tl.float32)
    t_near, t_far = _slab(rx, dx, size_x, t_near, t_far)
    t_near, t_far = _slab(ry, dy, size_y, t_near, t_far)
    t_near, t_far = _slab(rz, dz, size_z, t_near, t_far)
    finite = (
        (tl.abs(ox) < inf)
        & (tl.abs(oy) < inf)
        & (tl.abs(oz) < inf)
        & (tl.abs(dx) < inf)
        & (tl.abs(dy) < inf)
        & (tl.abs(dz) < inf)
    )
    moving = (dx != 0.0) | (dy != 0.0) | (dz != 0.0)
    hit = live & finite & moving & (t_near <= t_far) & (tl.abs(t_far) < inf)
    t_near = tl.where(hit, t_near, 0.0)
    dt = tl.where(hit, t_far - t_near, 0.0) / (divisions * 1.0)  # 1 may arrive as a constant
    ds = dt * tl.sqrt(dx * dx + dy * dy + dz * dz)
    fx, fy, fz = nx.to(tl.float32), ny.to(tl.float32), nz.to(tl.float32)
    transmittance = tl.full(ox.shape, 1.0, tl.float32)
    l0 = tl.zeros_like(ox)
    l1 = tl.zeros_like(ox)
    l2 = tl.zeros_like(ox)
    samples = tl.zeros(ox.shape, tl.int32)
    # The step count is a compile-time constant: one compiled kernel per count (a march
    # uses few), and older Triton interpreters loop only over plain integers.
    for i in range(STEPS):
        active = hit & (transmittance >= min_t)
        t = t_near + (i + 0.5) * dt
        u = (rx + t * dx) / size_x
        v = (ry + t * dy) / size_y
        w = (rz + t * dz) / size_z
        sigma = _trilinear(density_ptr, u, v, w, nx, ny, nz, fx, fy, fz, 1, 0, active)
        x = sigma * ds
        step_t = tl.exp(-x)
        # (1 - e^-x) / x by its series 1 - x/2 + x^2/6 below x = 1e-3: no 0 / 0 in vacuum,
        # no cancellation in thin media (the series' next term is below fp32 rounding).
        ratio = tl.where(x < 1e-3, 1.0 - x * (0.5 - x / 6.0), (1.0 - step_t) / x)
        weight = tl.where(active, ds * ratio, 0.0) * transmittance
        l0 += weight * _trilinear(source_ptr, u, v, w, nx, ny, nz, fx, fy, fz, CHANNELS, 0, active)
        if CHANNELS == 3:
            l1 += weight * _trilinear(source_ptr, u, v, w, nx, ny, nz, fx, fy, fz, 3, 1, active)
            l2 += weight * _trilinear(source_ptr, u, v, w, nx, ny, nz, fx, fy, fz, 3, 2, active)
        transmittance = tl.where(active, transmittance * step_t, transmittance)
        samples += active.to(tl.int32)
    tl.store(radiance_ptr + CHANNELS * ray, l0, mask=live)
    if CHANNELS == 3:
        tl.store(radiance_ptr + 3 * ray + 1, l1, mask=live)
        tl.store(radiance_ptr + 3 * ray + 2, l2, mask=live)
    tl.store(trans_ptr + ray, transmittance, mask=live)
    tl.store(samples_ptr + ray, samples.to(tl.int64), mask=live)


@_jit
def _bake_kernel(
    density_ptr,
    out_ptr,
    n_cells,
    nx,
    ny,
    nz,
    size_x,
    size_y,
    size_z,
    lx,
    ly,
    lz,
    scale,
    divisions,
    STEPS: tl.constexpr,
    SCALED: tl.constexpr,
    BLOCK: tl.constexpr,
):
    """Transmittance toward a directional light from every voxel centre: one lane per voxel,
    a midpoint march of STEPS steps to where the light ray leaves the box (Lab 4's
    ``shadow_transmittance`` of the voxel centres). SCALED: write ``scale * sigma * T``,
    the single-scattering source, instead of ``T``."""
    cell = tl.program_id(0) * BLOCK + tl.arange(0, BLOCK)
    live = cell < n_cells
    i = cell // (ny * nz)
    j = (cell // nz) % ny
    k = cell % nz
    fx, fy, fz = nx.to(tl.float32), ny.to(tl.float32), nz.to(tl.float32)
    # The centre relative to box_min: voxel (i, j, k) spans [i, i + 1] * size / n.
    rx = (i.to(tl.float32) + 0.5) * (size_x / fx)
    ry = (j.to(tl.float32) + 0.5) * (size_y / fy)
    rz = (k.to(tl.float32) + 0.5) * (size_z / fz)
    dir_x = tl.zeros_like(rx) + lx
    dir_y = tl.zeros_like(rx) + ly
    dir_z = tl.zeros_like(rx) + lz
    t_near = tl.zeros_like(rx)
    t_far = tl.full(rx.shape, float("inf"), tl.float32)
    t_near, t_far = _slab(rx, dir_x, size_x, t_near, t_far)
    t_near, t_far = _slab(ry, dir_y, size_y, t_near, t_far)
    t_near, t_far = _slab(rz, dir_z, size_z, t_near, t_far)
    inside = live & (t_near <= t_far) & (tl.abs(t_far) < float("inf"))
    t_near = tl.where(inside, t_near, 0.0)
    dt = tl.where(inside, t_far - t_near, 0.0) / (divisions * 1.0)  # max(steps, 1)
    depth = tl.zeros_like(rx)
    for step in range(STEPS):
        t = t_near + (step + 0.5) * dt
        u = (rx + t * dir_x) / size_x
        v = (ry + t * dir_y) / size_y
        w = (rz + t * dir_z) / size_z
        depth += _trilinear(density_ptr, u, v, w, nx, ny, nz, fx, fy, fz, 1, 0, inside) * dt
    lit = tl.exp(-depth)
    if SCALED:
        lit = scale * tl.load(density_ptr + cell, mask=live, other=0.0) * lit
    tl.store(out_ptr + cell, lit, mask=live)


def bake_light_triton(
    density: torch.Tensor,
    box_min,
    box_max,
    light_direction,
    steps: int = 16,
    *,
    scale: float | None = None,
    block: int = 128,
    num_warps: int = 4,
) -> torch.Tensor:
    """The sun's transmittance at every voxel centre of ``density``, as one Triton kernel.

    density: (X, Y, Z) extinction grid spanning the box ``box_min .. box_max`` (3 numbers
    each); light_direction: 3 numbers, toward the light (normalised here, in float64);
    steps: int >= 0, midpoint steps of each light ray to the box's exit. Returns (X, Y, Z)
    float32: ``exp(-sum_k sigma_k dt)`` per voxel, what Lab 4's ``shadow_transmittance``
    gives at the voxel centres (the volumetric shadow map the frame's source is baked
    from). With ``scale`` (e.g. ``albedo * irradiance``) it returns ``scale * density * T``
    instead: the single-scattering source grid that :func:`march_grid_triton` marches, in
    the same launch.
    """
    _require_triton()
    if not isinstance(density, torch.Tensor):
        raise TypeError(f"density: expected a float grid tensor, got {type(density).__name__}")
    dens = _grid(density, "density", density.device, channels=False)
    lo, hi = _box(box_min, box_max)
    light = (
        [float(c) for c in light_direction]
        if not isinstance(light_direction, torch.Tensor)
        else [float(c) for c in light_direction.detach().cpu().double().tolist()]
    )
    norm = math.sqrt(sum(c * c for c in light)) if len(light) == 3 else 0.0
    if len(light) != 3 or not math.isfinite(norm) or norm == 0:
        raise ValueError(f"light_direction: expected a finite non-zero 3-vector, got {light}")
    if not isinstance(steps, int) or isinstance(steps, bool) or steps < 0:
        raise ValueError(f"steps: expected an int >= 0, got {steps!r}")
    if scale is not None and (isinstance(scale, bool) or not isinstance(scale, (int, float))):
        raise TypeError(f"scale: expected a number or None, got {type(scale).__name__}")
    if not _is_pow2(block) or not _is_pow2(num_warps) or num_warps > 32:
        raise ValueError(
            f"block, num_warps: expected powers of two (num_warps <= 32), "
            f"got {block!r}, {num_warps!r}"
        )
    from course.kernels.triton_intersect import interpreting

    if not interpreting() and dens.device.type != "cuda":
        raise ValueError(
            f"density: the compiled Triton kernel needs a CUDA tensor, got "
            f"{dens.device} (for the CPU, set TRITON_INTERPRET=1 before "
            "importing triton)"
        )
    out = torch.empty_like(dens)
    cells = dens.numel()
    with _ieee_quiet():
        _bake_kernel[(triton.cdiv(cells, block),)](
            dens,
            out,
            cells,
            *dens.shape,
            *(b - a for a, b in zip(lo, hi)),
            *(c / norm for c in light),
            float(scale or 0.0),
            max(steps, 1),
            STEPS=steps,
            SCALED=scale is not None,
            BLOCK=block,
            num_warps=num_warps,
        )
    return out


def _box(box_min, box_max) -> tuple[list[float], list[float]]:
    lo = [float(c) for c in box_min]
    hi = [float(c) for c in box_max]
    if (
        len(lo) != 3
        or len(hi) != 3
        or not all(math.isfinite(c) for c in lo + hi)
        or not all(b > a for a, b in zip(lo, hi))
    ):
        raise ValueError(
            f"box_min, box_max: expected finite 3-vectors with box_max > box_min, got {lo} and {hi}"
        )
    return lo, hi


def _grid(x, name: str, device: torch.device, channels: bool) -> torch.Tensor:
    if not isinstance(x, torch.Tensor) or not x.is_floating_point():
        raise TypeError(f"{name}: expected a float grid tensor, got {type(x).__name__}")
    ok = x.ndim == 3 or (channels and x.ndim == 4 and x.shape[3] in (1, 3))
    want = "(X, Y, Z) or (X, Y, Z, 1 or 3)" if channels else "(X, Y, Z)"
    if not ok or min(x.shape[:3]) < 1:
        raise ValueError(f"{name}: expected a grid of shape {want}, got {tuple(x.shape)}")
    if x.device != device:
        raise ValueError(f"{name}: expected device {device} like origins, got {x.device}")
    return x.to(torch.float32).contiguous()


def march_grid_triton(
    origins: torch.Tensor,
    directions: torch.Tensor,
    box_min,
    box_max,
    density: torch.Tensor,
    source: torch.Tensor,
    steps: int = 64,
    *,
    min_transmittance: float = 0.0,
    block_rays: int = DEFAULT_BLOCK_RAYS,
    num_warps: int = DEFAULT_NUM_WARPS,
) -> dict:
    """Lab 4's exact-integrator ``march_box`` over grids, as one fused Triton kernel.

    origins, directions: (N, 3) float (computed in float32); box_min, box_max: 3 numbers;
    density: (X, Y, Z) extinction grid; source: (X, Y, Z) or (X, Y, Z, C), C in {1, 3},
    the emitted radiance per unit length, on the same cells as ``density``; steps: int >= 0.
    Returns ``{"radiance": (N,) or (N, C), "transmittance": (N,), "samples": (N,) int64}``
    (float32), like ``march_box``. Returns the compiled kernel handle under ``"kernel"``
    when it ran (None for N = 0) so callers can read ``n_regs``/``n_spills``.
    """
    _require_triton()
    for name, x in (("origins", origins), ("directions", directions)):
        if not isinstance(x, torch.Tensor):
            raise TypeError(f"{name}: expected a (N, 3) float tensor, got {type(x).__name__}")
        if x.ndim != 2 or x.shape[1] != 3 or not x.is_floating_point():
            raise ValueError(
                f"{name}: expected a (N, 3) float tensor, got shape {tuple(x.shape)} {x.dtype}"
            )
    if directions.shape != origins.shape or directions.device != origins.device:
        raise ValueError(
            f"directions: expected shape {tuple(origins.shape)} on "
            f"{origins.device} like origins, got {tuple(directions.shape)} on "
            f"{directions.device}"
        )
    device = origins.device
    lo, hi = _box(box_min, box_max)
    if not isinstance(steps, int) or isinstance(steps, bool) or steps < 0:
        raise ValueError(f"steps: expected an int >= 0, got {steps!r}")
    if not _is_pow2(block_rays) or not _is_pow2(num_warps) or num_warps > 32:
        raise ValueError(
            f"block_rays, num_warps: expected powers of two (num_warps <= 32), "
            f"got {block_rays!r}, {num_warps!r}"
        )
    dens = _grid(density, "density", device, channels=False)
    src = _grid(source, "source", device, channels=True)
    if src.shape[:3] != dens.shape:
        raise ValueError(
            f"source: expected the cells of density {tuple(dens.shape)}, got {tuple(src.shape)}"
        )
    channels = 1 if src.ndim == 3 else src.shape[3]
    from course.kernels.triton_intersect import interpreting

    if not interpreting() and device.type != "cuda":
        raise ValueError(
            f"origins: the compiled Triton kernel needs CUDA tensors, got {device} "
            "(for the CPU, set TRITON_INTERPRET=1 before importing triton)"
        )
    n = origins.shape[0]
    o = origins.to(torch.float32).contiguous()
    d = directions.to(torch.float32).contiguous()
    radiance = torch.empty(
        (n, channels) if src.ndim == 4 else (n,), dtype=torch.float32, device=device
    )
    transmittance = torch.empty(n, dtype=torch.float32, device=device)
    samples = torch.empty(n, dtype=torch.int64, device=device)
    handle = None
    if n > 0:
        grid = (triton.cdiv(n, block_rays),)
        with _ieee_quiet():
            handle = _march_kernel[grid](
                o,
                d,
                dens,
                src,
                radiance,
                transmittance,
                samples,
                n,
                max(steps, 1),
                float(min_transmittance),
                *lo,
                *(b - a for a, b in zip(lo, hi)),
                *dens.shape,
                STEPS=steps,
                CHANNELS=channels,
                BLOCK_RAYS=block_rays,
                num_warps=num_warps,
            )
    return {
        "radiance": radiance,
        "transmittance": transmittance,
        "samples": samples,
        "kernel": handle,
    }
