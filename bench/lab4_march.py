"""Lab 4 speed/accuracy benchmark: step counts, integrators, skipping and tolerances.

    python bench/lab4_march.py --device cpu|cuda [--rays N] [--out DIR] [--impl labs]
    python bench/lab4_march.py --device cpu --quick     # every series at toy sizes

The lab measured is ``--impl``'s (solutions/ in the course repository, labs/ in the handout);
a series that calls a function not written yet is skipped with the reason.

Every row is one knob setting, timed (median of several runs) and compared with an
analytic or exact reference computed in float64 on the same rays:

* ``march``: the rows of ``rtcourse bench --lab 4`` (``course.tools.trade.lab4``, at this
  script's sizes; their plot as a student's is drawn: ``pareto_trade.png``):
  ``march_box`` with ``integrator`` "riemann" / "exact" and 1 .. 256 steps, on a
  homogeneous box (closed form ``q (1 - e^{-s D}) / s``) and on a linear density ramp with
  constant emission (closed form with ``erfcx``); ``order`` is the observed convergence
  order ``log2(error(n/2) / error(n))``.
* ``early_exit``: a dense box with ``min_transmittance`` 0 .. 0.1: samples saved and the
  radiance lost.
* ``scatter``: ``march_single_scatter`` on a homogeneous box lit along +y (closed form) over
  the view steps, and on a quadratic density with an oblique light over the shadow steps
  (reference: 2001-point Simpson quadrature with the light's optical depth exact; the
  shadow sweep runs at half the largest view step count, whose own error is its floor).
* ``voxels``: a piecewise-constant grid of blobs: ``voxel_walk`` (exact, error = float32
  rounding against the float64 walk) without skipping and with macro cells of 1, 4 and 8
  voxels (steps and samples per ray), against ``march_box`` sampling the same voxels
  (nearest) with 8 .. 256 steps.
* ``trace``: ``sphere_trace`` of a sphere, a box and a ground plane over ``epsilon``,
  ``max_steps`` and ``relaxation``: error of t on clear hits, UNSURE rays, steps per ray.
* ``frame``: the issue's target, a single-scattering volume filling a 1080p frame
  (``--frame``; 1920 x 1080 rays on a GPU, a smaller frame on the CPU) with 128 view
  steps, sun light, a 128^3 density grid (64^3 on the CPU): the lab's
  ``march_single_scatter`` (a shadow march per sample), the same light baked once into a
  transmittance grid then ``march_box`` over the baked source, and the fused
  ``course.kernels.triton_march`` kernel over the baked source (CUDA only), each against a
  high-step reference on every 61st pixel. The bake's own time is a separate row, eager
  (the lab's ``shadow_transmittance`` at the voxel centres) and fused
  (``course.kernels.triton_march.bake_light_triton``, one launch that also writes the source); the
  whole-frame row (fused bake, fused march, phase: target <= 5 ms) carries its error
  against the 4x-steps float64 reference, and ``bake_vs_eager`` the fused bake's largest
  difference from the eager one, relative to the source's maximum.

Writes ``lab4_march.json`` (a ResultTable with the command line), ``lab4_march.md``, the
convergence plot (error against steps) and Pareto plots (seconds against error) into
``--out``, by default ``bench/results/<device_name>/lab4/``. On the CPU only ratios between
rows of one run mean anything; absolute times count on a GPU.
"""

from __future__ import annotations

import argparse
import math
import shlex
import sys
import time
from pathlib import Path

import torch

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))  # run from a checkout without installing

from course.core.device import default_device
from course.measure.bench import (
    ResultTable,
    add_impl_option,
    device_name,
    load_lab,
    pareto_plot,
    time_fn,
    trade_plot,
)
from course.tools.trade import lab4 as trade

lab = None  # the Lab 4 module measured: main() loads it from --impl

F64 = torch.float64
# Per device: rays of the marching sweeps, of the sphere-tracing sweep, the voxel grid's
# resolution, the largest step count, timed runs per setting (after one untimed call).
# The frame's size and grid resolution. The CUDA sweeps use 2^18 rays and at most 256
# steps: at 2^20 rays and 1024 steps the eager sweeps alone took longer than four minutes.
SIZES = {
    "cpu": {
        "rays": 1024,
        "trace_rays": 1024,
        "grid": 24,
        "max_steps": 128,
        "repeats": 2,
        "frame": (96, 54),
        "frame_grid": 32,
    },
    "cuda": {
        "rays": 1 << 18,
        "trace_rays": 1 << 20,
        "grid": 128,
        "max_steps": 256,
        "repeats": 5,
        "frame": (1920, 1080),
        "frame_grid": 128,
    },
    "quick": {
        "rays": 64,
        "trace_rays": 64,
        "grid": 8,
        "max_steps": 16,
        "repeats": 1,
        "frame": (32, 18),
        "frame_grid": 8,
        "frame_steps": 16,
    },
}


# --------------------------------------------------------------------------------------
# Rays and references (float64)
# --------------------------------------------------------------------------------------

# The rays, the closed forms and the ramp of rtcourse bench --lab 4, shared with it.
x_face_rays, phi, chord = trade.x_face_rays, trade.phi, trade.chord
ramp_density, ramp_reference = trade.ramp_density, trade.ramp_reference


BOWL = (0.5, 0.4, 0.6)


def bowl_density(p):
    return 0.3 + 3.0 * (p - torch.tensor(BOWL, dtype=p.dtype, device=p.device)).square().sum(-1)


def hg(cos, g):
    return (1 - g * g) / (4 * math.pi * (1 + g * g - 2 * g * cos) ** 1.5)


def bowl_scatter_reference(o, d, light, lo, hi, g, m=2001):
    """Single scattering in bowl_density, light toward ``light`` (unit), by Simpson's rule
    along each view ray with the light's optical depth in closed form."""
    near, far = chord(o, d, lo, hi)
    length = far - near
    s = torch.linspace(0, 1, m, dtype=F64)[None, :] * length[:, None]
    pts = (o + near[:, None] * d)[:, None, :] + s[..., None] * d[:, None, :]
    flat = pts.reshape(-1, 3)
    sigma = bowl_density(flat).reshape(s.shape)
    lnear, lfar = chord(flat, light.expand_as(flat), lo, hi)
    ll = (lfar - lnear).reshape(s.shape)
    beta = 6.0 * ((pts - torch.tensor(BOWL, dtype=F64)) * light).sum(-1)
    shadow = sigma * ll + beta * ll**2 / 2 + ll**3
    step = length[:, None] / (m - 1)
    depth = torch.cat(
        [
            torch.zeros(len(o), 1, dtype=F64),
            torch.cumsum((sigma[:, 1:] + sigma[:, :-1]) / 2 * step, 1),
        ],
        1,
    )
    w = torch.ones(m, dtype=F64)
    w[1:-1:2], w[2:-1:2] = 4.0, 2.0
    integrand = sigma * torch.exp(-depth - shadow)
    return (integrand * w).sum(-1) * length / (3 * (m - 1)) * hg(d @ light, g)


def blob_grid(n: int) -> torch.Tensor:
    """Two dense blobs and a lone voxel in an otherwise empty n^3 grid (float64)."""
    x = (torch.arange(n, dtype=F64) + 0.5) / n
    p = torch.stack(torch.meshgrid(x, x, x, indexing="ij"), -1)
    grid = torch.zeros(n, n, n, dtype=F64)
    for c, r in (((0.3, 0.3, 0.6), 0.12), ((0.7, 0.6, 0.3), 0.09)):
        dist = (p - torch.tensor(c, dtype=F64)).norm(dim=-1)
        grid = grid + torch.where(dist < r, 3.0 * (1 - dist / r), 0.0)
    grid[n - 3, 1, n - 2] = 5.0
    return grid


# --------------------------------------------------------------------------------------
# The sweeps
# --------------------------------------------------------------------------------------


def timed(cfg, fn, *args, **kwargs):
    """(result, median seconds) of ``fn(*args, **kwargs)``; the first call is the warm-up."""
    result = fn(*args, **kwargs)
    timing = time_fn(fn, *args, repeats=cfg["repeats"], warmup=0, **kwargs)
    return result, timing.median


def step_counts(cfg, first=1):
    """Powers of two from ``first`` to the device's largest step count."""
    return [2**k for k in range(int(math.log2(first)), int(math.log2(cfg["max_steps"])) + 1)]


def rel_error(got, want):
    got = got.detach().to("cpu", F64)
    return ((got - want).abs() / want.abs().clamp(min=1e-12)).max().item()


def bench_march(table, device, cfg):
    """The rows of ``rtcourse bench --lab 4`` (``course.tools.trade.lab4``: medium x integrator
    x steps, error against the closed forms) at this script's sizes, with the observed
    convergence order."""
    ctx = trade.prepare(
        device, False, rays=cfg["rays"], max_steps=cfg["max_steps"], repeats=cfg["repeats"]
    )
    n, previous = ctx["rays"], {}
    for knob in trade.knobs(ctx):
        row = trade.measure(lab, ctx, knob)
        error, key = row["error"], (knob["medium"], knob["integrator"])
        # No order where the error is float32 rounding (the exact integrator on a
        # homogeneous box): rounding does not converge.
        order = math.log2(previous[key] / error) if key in previous and error > 1e-5 else None
        table.add(
            series="march",
            setting=knob["setting"],
            medium=knob["medium"],
            integrator=knob["integrator"],
            steps=knob["steps"],
            dtype="fp32",
            rays=n,
            seconds=row["seconds"],
            rays_per_s=n / row["seconds"],
            error=error,
            order=order,
        )
        previous[key] = error
    print("  march: done", flush=True)


def bench_early_exit(table, device, cfg):
    n = cfg["rays"]
    o, d = x_face_rays(n, seed=1)
    sigma, q = 40.0, 1.0
    near, far = chord(o, d, [0.0] * 3, [1.0] * 3)
    want = q * (far - near) * phi(sigma * (far - near))
    dens = torch.full((1, 1, 1), sigma, dtype=torch.float32, device=device)
    emis = torch.full((1, 1, 1), q, dtype=torch.float32, device=device)
    steps = cfg["max_steps"]
    for threshold in (0.0, 1e-4, 1e-3, 1e-2, 1e-1):
        result, seconds = timed(
            cfg,
            lab.march_box,
            o.float().to(device),
            d.float().to(device),
            [0.0] * 3,
            [1.0] * 3,
            dens,
            emis,
            steps,
            min_transmittance=threshold,
        )
        table.add(
            series="early_exit",
            setting=f"T<{threshold:g}",
            min_transmittance=threshold,
            steps=steps,
            dtype="fp32",
            rays=n,
            seconds=seconds,
            rays_per_s=n / seconds,
            error=rel_error(result["radiance"], want),
            samples_per_ray=result["samples"].double().mean().item(),
        )


def bench_scatter(table, device, cfg):
    n = max(64, cfg["rays"] // 4)
    g = torch.Generator().manual_seed(2)
    lo, hi = (0.0, 0.0, 0.0), (1.0, 2.0, 1.0)
    target = torch.tensor(lo, dtype=F64) + torch.tensor(hi, dtype=F64) * (
        0.05 + 0.9 * torch.rand(n, 3, generator=g, dtype=F64)
    )
    o = torch.tensor([0.5, 1.0, -2.5], dtype=F64) + 0.3 * torch.randn(n, 3, generator=g, dtype=F64)
    d = (target - o) / (target - o).norm(dim=1, keepdim=True)
    sigma, albedo, irradiance, gg = 1.3, 0.8, 2.0, 0.4
    # Homogeneous, lit along +y: closed form; sweep the view steps.
    near, far = chord(o, d, lo, hi)
    length = far - near
    y_entry = o[:, 1] + near * d[:, 1]
    want = (
        albedo
        * sigma
        * hg(d[:, 1], gg)
        * irradiance
        * torch.exp(-sigma * (hi[1] - y_entry))
        * length
        * phi(sigma * (1 - d[:, 1]) * length)
    )
    dens = torch.full((1, 1, 1), sigma, dtype=torch.float32, device=device)
    oo, dd = o.float().to(device), d.float().to(device)
    for integrator in lab.INTEGRATORS:
        for steps in step_counts(cfg, first=4)[:-1]:
            result, seconds = timed(
                cfg,
                lab.march_single_scatter,
                oo,
                dd,
                lo,
                hi,
                dens,
                albedo,
                [0.0, 1.0, 0.0],
                irradiance,
                gg,
                steps,
                1,
                integrator=integrator,
            )
            table.add(
                series="scatter",
                setting=f"view {integrator} {steps}",
                medium="homogeneous",
                integrator=integrator,
                steps=steps,
                shadow_steps=1,
                dtype="fp32",
                rays=n,
                seconds=seconds,
                rays_per_s=n / seconds,
                error=rel_error(result["radiance"], want),
            )
    # Quadratic density, oblique light: sweep the shadow steps at fixed view steps.
    light = torch.tensor([0.4, 1.0, -0.5], dtype=F64)
    light = light / light.norm()
    want = bowl_scatter_reference(o, d, light, lo, hi, gg) * albedo * irradiance
    view = cfg["max_steps"] // 2
    for shadow_steps in (1, 2, 4, 8, 16):
        result, seconds = timed(
            cfg,
            lab.march_single_scatter,
            oo,
            dd,
            lo,
            hi,
            bowl_density,
            albedo,
            light.float().to(device),
            irradiance,
            gg,
            view,
            shadow_steps,
        )
        table.add(
            series="scatter",
            setting=f"shadow {shadow_steps}",
            medium="quadratic",
            integrator="exact",
            steps=view,
            shadow_steps=shadow_steps,
            dtype="fp32",
            rays=n,
            seconds=seconds,
            rays_per_s=n / seconds,
            error=rel_error(result["radiance"], want),
        )
    print("  scatter: done", flush=True)


def bench_voxels(table, device, cfg):
    n, res = cfg["rays"], cfg["grid"]
    g = torch.Generator().manual_seed(3)
    target = torch.rand(n, 3, generator=g, dtype=F64)
    out = torch.randn(n, 3, generator=g, dtype=F64)
    o = 0.5 + 2.0 * out / out.norm(dim=1, keepdim=True)
    d = (target - o) / (target - o).norm(dim=1, keepdim=True)
    grid = blob_grid(res)
    lo, hi = [0.0] * 3, [1.0] * 3
    exact = lab.voxel_walk(o.to(device), d.to(device), lo, hi, grid.to(device))
    want = exact["optical_depth"].cpu()
    oo, dd, gg = o.float().to(device), d.float().to(device), grid.float().to(device)
    settings = [("no skipping", None, 1)] + [(f"macro {m}", m, m) for m in (1, 4, 8)]
    for name, m, cell in settings:
        occ = None if m is None else lab.build_occupancy(gg, cell)
        result, seconds = timed(cfg, lab.voxel_walk, oo, dd, lo, hi, gg, None, occ, cell)
        error = (result["optical_depth"].cpu().double() - want).abs().max().item()
        table.add(
            series="voxels",
            setting=f"walk {name}",
            method="voxel_walk",
            skipping=name,
            grid=res,
            dtype="fp32",
            rays=n,
            seconds=seconds,
            rays_per_s=n / seconds,
            error=error,
            steps_per_ray=result["steps"].double().mean().item(),
            samples_per_ray=result["samples"].double().mean().item(),
        )

    def nearest(points):  # the same piecewise-constant medium, for march_box
        cell = torch.floor(points * res).long().clamp(0, res - 1)
        return gg[cell[:, 0], cell[:, 1], cell[:, 2]]

    for steps in step_counts(cfg, first=8)[::2]:
        result, seconds = timed(cfg, lab.march_box, oo, dd, lo, hi, nearest, None, steps)
        depth = -torch.log(result["transmittance"].cpu().double())
        table.add(
            series="voxels",
            setting=f"march {steps}",
            method="march_box",
            steps=steps,
            grid=res,
            dtype="fp32",
            rays=n,
            seconds=seconds,
            rays_per_s=n / seconds,
            error=(depth - want).abs().max().item(),
            samples_per_ray=steps,
        )
    print("  voxels: done", flush=True)


SPHERE, BOX = ((0.0, 0.0, 4.0), 1.0), ((1.5, 0.3, 6.0), (0.6, 0.8, 0.5))


def scene(p):
    return lab.sdf_union(lab.sdf_sphere(p, *SPHERE), lab.sdf_box(p, *BOX), p[:, 1] + 1.0)


def scene_reference(o, d):
    """First hit t of unit rays from ``o`` with the sphere, the box and the plane y = -1,
    and the cosine of the angle of incidence there."""
    inf = torch.full((len(o),), math.inf, dtype=F64)
    c = torch.tensor(SPHERE[0], dtype=F64)
    f = o - c
    b = (f * d).sum(-1)
    perp = f - b[:, None] * d
    disc = SPHERE[1] ** 2 - (perp * perp).sum(-1)
    t_s = torch.where(disc >= 0, -b - disc.clamp(min=0).sqrt(), inf)
    cos_s = ((o + t_s.nan_to_num(0, 0, 0)[:, None] * d - c) * d).sum(-1).abs() / SPHERE[1]
    bc, bh = torch.tensor(BOX[0], dtype=F64), torch.tensor(BOX[1], dtype=F64)
    near, far = chord(o, d, (bc - bh).tolist(), (bc + bh).tolist())
    t_b = torch.where(near <= far, near, inf)
    face = ((o + t_b.nan_to_num(0, 0, 0)[:, None] * d - bc).abs() / bh).argmax(-1)
    cos_b = d.gather(1, face[:, None])[:, 0].abs()
    t_p = torch.where(d[:, 1] < 0, (-1.0 - o[:, 1]) / d[:, 1], inf)
    t = torch.stack([t_s, t_b, t_p], -1)
    first = t.argmin(-1)
    cos = torch.stack([cos_s, cos_b, d[:, 1].abs()], -1).gather(1, first[:, None])[:, 0]
    return t.amin(-1), cos


def bench_trace(table, device, cfg):
    n = cfg["trace_rays"]
    side = math.isqrt(n)
    x = (torch.arange(side, dtype=F64) + 0.5) / side * 2 - 1
    yy, xx = torch.meshgrid(-x, x, indexing="ij")
    d = torch.stack(
        [0.45 * xx.reshape(-1) + 0.2, 0.45 * yy.reshape(-1), torch.ones(side * side, dtype=F64)], -1
    )
    d = d / d.norm(dim=1, keepdim=True)
    o = torch.zeros_like(d)
    t_ref, cos = scene_reference(o, d)
    hit = torch.isfinite(t_ref)
    clear = hit & (cos > 0.2)  # the error of t grows like epsilon t / cos
    oo, dd = o.float().to(device), d.float().to(device)
    for relaxation in (1.0, 1.5):
        for max_steps in (64, 256):
            for epsilon in (1e-2, 1e-3, 1e-4):
                result, seconds = timed(
                    cfg, lab.sphere_trace, oo, dd, scene, 100.0, max_steps, epsilon, relaxation
                )
                t = result["t"].cpu().double()
                found = hit & (result["status"].cpu() == lab.HIT)
                judged = found & clear
                errors = ((t - t_ref).abs() / t_ref)[judged]
                error = errors.max().item() if judged.any() else None
                median = errors.median().item() if judged.any() else None
                table.add(
                    series="trace",
                    setting=f"w{relaxation} s{max_steps} e{epsilon:g}",
                    relaxation=relaxation,
                    max_steps=max_steps,
                    epsilon=epsilon,
                    dtype="fp32",
                    rays=len(o),
                    seconds=seconds,
                    rays_per_s=len(o) / seconds,
                    error=error,
                    error_median=median,
                    unsure=(result["status"] == lab.UNSURE).double().mean().item(),
                    missed_hits=(hit & ~found).double().mean().item(),
                    steps_per_ray=result["steps"].double().mean().item(),
                )
    print("  trace: done", flush=True)


# --------------------------------------------------------------------------------------
# Output
# --------------------------------------------------------------------------------------


def frame_scene(res: int, device):
    """The target frame's medium: a (res, res, res) cloud of Gaussian blobs in a box."""
    g = torch.Generator().manual_seed(5)
    x = (torch.arange(res, dtype=torch.float32) + 0.5) / res
    p = torch.stack(torch.meshgrid(x, x, x, indexing="ij"), -1)
    density = torch.zeros(res, res, res)
    for c, r in zip(
        0.25 + 0.5 * torch.rand(12, 3, generator=g), 0.08 + 0.12 * torch.rand(12, generator=g)
    ):
        density += 6.0 * torch.exp(-(p - c).square().sum(-1) / r**2)
    return density.to(device)


def bench_frame(table, device, cfg):
    """The 1080p single-scattering target: per-sample shadow marches against a baked light."""
    from course.core.camera import Camera, primary_rays

    width, height = cfg["frame"]
    steps = cfg.get("frame_steps", 128)  # view steps; the shadow marches take a quarter
    shadow_steps = steps // 4
    lo, hi = (-1.0, -1.0, -1.0), (1.0, 1.0, 1.0)
    albedo, irradiance, gg = 0.9, 3.0, 0.5
    light = torch.tensor([0.5, 0.8, -0.3])
    light = (light / light.norm()).to(device)
    density = frame_scene(cfg["frame_grid"], device)
    camera = Camera(
        eye=(0.0, 0.3, 3.2), target=(0.0, 0.0, 0.0), fov_y=48.0, width=width, height=height
    )
    rays = primary_rays(camera, device=device)
    o, d = rays.origins.float(), rays.directions.float()
    n = len(o)
    phase = lab.henyey_greenstein((d / d.norm(dim=1, keepdim=True)) @ light, gg)

    def bake():  # transmittance to the sun at every voxel centre: the volumetric shadow map
        res = density.shape[0]
        centres = (torch.arange(res, device=device, dtype=torch.float32) + 0.5) / res * 2 - 1
        grid = torch.stack(torch.meshgrid(centres, centres, centres, indexing="ij"), -1)
        lit = lab.shadow_transmittance(
            grid.reshape(-1, 3), light, lo, hi, density, shadow_steps
        ).reshape(density.shape)
        return albedo * irradiance * density * lit

    # High-accuracy reference on a subset of pixels: 4x the view and shadow steps, float64.
    pick = torch.arange(0, n, 61, device=device)
    ref = lab.march_single_scatter(
        o[pick].double(),
        d[pick].double(),
        lo,
        hi,
        density.double(),
        albedo,
        light.double(),
        irradiance,
        gg,
        4 * steps,
        4 * shadow_steps,
    )["radiance"]

    def err(radiance):
        return ((radiance[pick].double() - ref).abs().max() / ref.abs().max()).item()

    def row(setting, seconds, radiance, **extra):
        table.add(
            series="frame",
            setting=setting,
            steps=steps,
            shadow_steps=shadow_steps,
            dtype="fp32",
            rays=n,
            seconds=seconds,
            rays_per_s=n / seconds,
            ms_per_frame=1e3 * seconds,
            error=None if radiance is None else err(radiance),
            **extra,
        )
        print(f"  frame {setting}: {1e3 * seconds:.2f} ms", flush=True)

    source, seconds = timed(cfg, bake)
    row("bake the sun's transmittance grid (eager torch)", seconds, None, grid=cfg["frame_grid"])
    result, seconds = timed(
        cfg, lambda: lab.march_box(o, d, lo, hi, density, source, steps)["radiance"] * phase
    )
    row("baked light, march_box (eager torch)", seconds, result, grid=cfg["frame_grid"])
    if device.type == "cuda":
        from course.kernels.triton_march import march_grid_triton

        def fused():
            return march_grid_triton(o, d, lo, hi, density, source, steps)

        out = fused()
        kernel = out["kernel"]
        _, seconds = timed(cfg, fused)
        row(
            "baked light, fused Triton kernel",
            seconds,
            out["radiance"] * phase,
            grid=cfg["frame_grid"],
            n_regs=kernel.n_regs,
            n_spills=kernel.n_spills,
        )
        _, seconds = timed(
            cfg, lambda: march_grid_triton(o, d, lo, hi, density, bake(), steps)["radiance"] * phase
        )
        row(
            "eager bake + fused march (whole frame)",
            seconds,
            out["radiance"] * phase,
            grid=cfg["frame_grid"],
        )
        from course.kernels.triton_march import bake_light_triton

        sun = light.tolist()  # numbers: no device-to-host copy per frame

        def fused_bake():
            return bake_light_triton(density, lo, hi, sun, shadow_steps, scale=albedo * irradiance)

        baked, seconds = timed(cfg, fused_bake)
        bake_err = (
            (baked.double() - source.double()).abs().max() / source.double().abs().max()
        ).item()
        row(
            "bake, fused Triton kernel",
            seconds,
            None,
            grid=cfg["frame_grid"],
            bake_vs_eager=bake_err,
        )

        def frame():  # everything a frame computes: bake, march, phase
            cos = (d / d.norm(dim=1, keepdim=True)) @ light
            return march_grid_triton(o, d, lo, hi, density, fused_bake(), steps)[
                "radiance"
            ] * lab.henyey_greenstein(cos, gg)

        radiance, seconds = timed(cfg, frame)
        row(
            "fused bake + fused march + phase (whole frame)",
            seconds,
            radiance,
            grid=cfg["frame_grid"],
            bake_vs_eager=bake_err,
            target_ms=5.0,
            target_met=1e3 * seconds <= 5.0,
        )
    # The per-sample shadow march: steps * (shadow_steps + 2) density reads per ray. A
    # quarter of the frame on the GPU is plenty to time it.
    part = slice(0, n if device.type == "cpu" else n // 4)
    _, seconds = timed(
        dict(cfg, repeats=1),
        lab.march_single_scatter,
        o[part],
        d[part],
        lo,
        hi,
        density,
        albedo,
        light,
        irradiance,
        gg,
        steps,
        shadow_steps,
    )
    seconds *= n / len(range(n)[part])
    full = lab.march_single_scatter(
        o[pick], d[pick], lo, hi, density, albedo, light, irradiance, gg, steps, shadow_steps
    )["radiance"]
    table.add(
        series="frame",
        setting="per-sample shadow march (eager torch)",
        steps=steps,
        shadow_steps=shadow_steps,
        dtype="fp32",
        rays=n,
        seconds=seconds,
        rays_per_s=n / seconds,
        ms_per_frame=1e3 * seconds,
        error=((full.double() - ref).abs().max() / ref.abs().max()).item(),
        grid=cfg["frame_grid"],
    )
    print(f"  frame per-sample shadow march: {1e3 * seconds:.1f} ms", flush=True)


def convergence_plot(table: ResultTable, path: Path) -> None:
    """Error against steps, log-log, with reference slopes 1 and 2."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(6.4, 4.8), layout="constrained")
    ax = fig.add_subplot()
    for medium in ("homogeneous", "ramp"):
        for integrator, marker in (("riemann", "o"), ("exact", "s")):
            rows = [
                r
                for r in table.rows
                if r["series"] == "march"
                and r["medium"] == medium
                and r["integrator"] == integrator
            ]
            steps = [r["steps"] for r in rows]
            errors = [max(r["error"], 1e-9) for r in rows]
            ax.loglog(steps, errors, marker=marker, label=f"{integrator}, {medium}")
    most = max(r["steps"] for r in table.rows if r["series"] == "march")
    s = torch.tensor([4.0, float(most)])
    ax.loglog(s, 0.3 / s, "k:", label="slope -1")
    ax.loglog(s, 0.3 / s**2, "k--", label="slope -2")
    ax.set_xlabel("steps per ray")
    ax.set_ylabel("max relative error of the radiance")
    ax.set_title(
        "march_box: Riemann order 1, exact per-step integral order 2\n"
        "(exact on the homogeneous box: float32 rounding only)",
        fontsize=10,
    )
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.savefig(path, dpi=150)


def write_outputs(table: ResultTable, out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    table.to_json(out / "lab4_march.json")
    meta = table.metadata
    legend = (
        "error: max relative error of the radiance against the closed form (march, "
        "early_exit, scatter), max absolute error of the optical depth against the "
        "float64 voxel walk (voxels), max relative error of the hit t (trace); order: "
        "log2 of the error ratio per doubling of the steps; samples/steps_per_ray: "
        "density reads and cells (voxels) or sdf evaluations (trace) per ray; trace "
        "errors over hits with incidence cos > 0.2 (the error grows like eps t / cos; the "
        "max is set by silhouettes, which a coarse epsilon fattens by eps t); "
        "unsure, missed_hits: fractions of the rays."
    )
    device = f"Device: {meta['device']}; torch {meta['torch']}; {meta['date']}."
    header = [f"# {table.name}", "", device, "", f"Command: `{meta['command']}`", "", legend, ""]
    (out / "lab4_march.md").write_text("\n".join(header) + table.to_markdown() + "\n")
    if any(r["series"] == "march" for r in table.rows):
        convergence_plot(table, out / "convergence.png")
        # The plot rtcourse bench --lab 4 draws a student's points over, from the same rows.
        trade_plot(
            [r for r in table.rows if r["series"] == "march"],
            [],
            path=out / "pareto_trade.png",
            title=f"{trade.TITLE}\nerror: {trade.ERROR_NAME}",
        )
    for series, title in (
        ("frame", "single scattering frame: seconds against error"),
        ("march", "march_box: seconds against error"),
        ("scatter", "march_single_scatter: seconds against error"),
        ("voxels", "voxel_walk (exact) against march_box on voxels"),
        ("trace", "sphere_trace: seconds against error of t"),
    ):
        rows = [r for r in table.rows if r["series"] == series and r.get("error") is not None]
        if not rows:  # not run (--only, or a run cut short)
            continue
        group = {
            "frame": "grid",
            "march": "integrator",
            "scatter": "medium",
            "voxels": "method",
            "trace": "relaxation",
        }[series]
        pareto_plot(
            rows,
            x="seconds",
            y="error",
            label="setting",
            group=group,
            title=title,
            path=out / f"pareto_{series}.png",
        )


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--device", default=None, help="cpu or cuda (default: cuda if present)")
    parser.add_argument("--rays", type=int, help="rays of the marching sweeps")
    parser.add_argument("--trace-rays", type=int, help="rays of the sphere-tracing sweep")
    parser.add_argument("--grid", type=int, help="voxel grid resolution")
    parser.add_argument("--max-steps", type=int, help="largest step count of the sweeps")
    parser.add_argument("--only", nargs="+", choices=SERIES, help="run only these series")
    parser.add_argument(
        "--threads",
        type=int,
        default=1,
        help="CPU threads for torch (default 1: batches this small gain nothing "
        "from intra-op threads, and on a shared machine waking the thread "
        "pool costs more than the work)",
    )
    parser.add_argument("--repeats", type=int, help="timed runs per setting (median reported)")
    parser.add_argument(
        "--out", type=Path, help="output folder (default: bench/results/<device_name>/lab4)"
    )
    parser.add_argument(
        "--quick",
        action="store_true",
        help="toy sizes (seconds on a CPU): it runs; its numbers mean little",
    )
    add_impl_option(parser)
    args = parser.parse_args(argv)
    global lab
    lab = load_lab("lab4_march", args.impl, root=REPO)

    device = default_device(args.device)
    if device.type == "cpu":
        torch.set_num_threads(args.threads)
    cfg = dict(SIZES["quick" if args.quick else "cuda" if device.type == "cuda" else "cpu"])
    for key in ("rays", "trace_rays", "grid", "max_steps", "repeats"):
        if getattr(args, key) is not None:
            cfg[key] = getattr(args, key)
    out = args.out or REPO / "bench" / "results" / device_name(device) / "lab4"
    table = ResultTable("Lab 4: ray marching, speed against accuracy", device)
    table.metadata.update(
        command=shlex.join(
            ["python", "bench/lab4_march.py", *(sys.argv[1:] if argv is None else argv)]
        ),
        sizes=cfg,
        lab=lab.__name__,
        lab_file=str(lab.__file__),
        threads=torch.get_num_threads(),
    )
    print(f"{table.metadata['device']}: {cfg}", flush=True)
    started = time.perf_counter()
    for series in args.only or SERIES:
        try:
            SERIES[series](table, device, cfg)
        except NotImplementedError as exc:  # the handout: a lab function not written yet
            print(f"{series}: skipped: {exc}", flush=True)
            continue
        write_outputs(table, out)  # after every series: a run cut short keeps what it measured
    print(f"wrote {out} ({time.perf_counter() - started:.1f} s)")


SERIES = {
    "frame": bench_frame,
    "march": bench_march,
    "early_exit": bench_early_exit,
    "scatter": bench_scatter,
    "voxels": bench_voxels,
    "trace": bench_trace,
}

if __name__ == "__main__":
    main()
