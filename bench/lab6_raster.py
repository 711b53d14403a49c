"""Lab 6 speed/accuracy benchmark: the compute rasterizer against ray-traced primary visibility.

    python bench/lab6_raster.py --device cpu|cuda [--sizes 64 128 256] [--scene suzanne]
                                [--repeats N] [--threads N] [--out DIR]
                                [--only sizes knobs zfight frames] [--quick]

For each square resolution it times, on the same camera and mesh,

* ``raster``: the visibility buffer of the lab's pipeline (``to_clip_space``,
  ``clip_triangles``, ``to_screen``, ``rasterize``, ids through ``source``), with 32-bit
  (float view depth) and 24-bit (unorm window depth) keys;
* ``raytrace``: one primary ray per pixel through Lab 1's brute-force ``closest_hit``
  (Möller–Trumbore, float32), the course's reference tracer;

reporting triangles/s and pixels/s and the **disagreement**: the fraction of pixels whose
triangle id differs between the raster and the ray tracer (edges and silhouettes only).
At the largest size it sweeps the knobs of the rasterizer:

* ``chunk``: the memory budget of ``rasterize`` (fragments alive at once = budget / 256 B):
  the bounding-box enumeration in a few large chunks or many small ones;
* ``tile``: screen tiles of t x t pixels rasterized one after the other (every triangle's
  box clamped to the tile), against the whole screen at once; the result must not change;
* ``zfight``: two parallel quads 1 cm apart at increasing distance (near plane 0.01): the
  fraction of the front quad's pixels where the back quad wins (it has the lower ids, so
  it wins every tie), with 24-bit window depth against 32-bit float view depth.

Then, for every scene of ``--scenes`` (suzanne, bunny, bunny_x4, bunny_x16 on a GPU) and
frame of ``--frames`` (512x512, 1920x1080, 3840x2160 on a GPU), the ``frame`` series:

* ``raster``: ``rasterize_mesh`` (visibility + perspective-correct barycentrics), and the
  visibility buffer alone (triangle ids) from the lab's ``rasterize`` and, on CUDA, from
  the fused kernels of ``course.kernels.triton_raster``: after the lab's torch setup stages
  (``fused Triton``), and end to end with the fused vertex kernel (``fused, vertex
  kernel``: camera matrix to ids in four kernels, no host synchronisation; ``CUDA graph``:
  the same four replayed as one graph, ``FusedVisibility``; ``kernels' GPU time``: the
  profiler's time of each kernel, the host's launch time left out), whose
  ``raster_speedup`` is the BVH-traced time over its own (same keys). The camera matrix
  is computed once per camera (``camera_matrix``), as the BVH is built once per mesh;
* ``raytrace``: ``traced_visibility`` through ``course.kernels.trace.trace_bvh`` (a binned-SAH
  BVH, Triton traversal on CUDA; its build time is reported apart, ``build_s``), the
  fair competitor at scale where brute force is hopeless;
* ``hybrid``: raster visibility + Lambert shading + ``hybrid_shadows`` (one BVH shadow ray
  per lit pixel), against ``traced``: ``traced_shadows`` (primary and shadow rays traced).

``--quick`` keeps, in the frame series, only the BVH-traced visibility and the end-to-end
fused raster (e.g. ``--only frames --quick --scenes suzanne bunny bunny_x4 --frames
1920x1080`` on a GPU: a few minutes, most of it building bunny_x4 and compiling).

``trade``: the rows ``rtcourse bench --lab 6`` measures (``course.tools.trade.lab6``: raster
with 32- and 24-bit depth and a small fragment budget against BVH-traced visibility, error
against float64 brute-force primary rays), written as ``trade.csv`` with their plot
``pareto_trade.png``, drawn as a student's is.

Writes ``lab6_raster.json`` (a ResultTable with the command line), ``lab6_raster.md``,
``throughput.png`` (pixels/s by resolution, both methods) and ``zfighting.png`` into
``--out``, by default ``bench/results/<device_name>/lab6/``. On the CPU only ratios between
rows of one run mean anything; absolute numbers count on a GPU.
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import shlex
import sys
import time
from pathlib import Path

import torch

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))  # run from a checkout without installing

from course.core.camera import Camera, primary_rays
from course.core.device import default_device
from course.core.scenes import load_scene
from course.core.types import Mesh, Rays
from course.measure.bench import ResultTable, add_impl_option, device_name, load_lab, time_fn
from course.tools.trade import bench_rows

# The references in the course repository, the student's labs/ in the handout (RTCOURSE_IMPL,
# or --impl, picks another): main() loads them.
lab = closest_hit = None

SIZES = {
    "cpu": {
        "sizes": (64, 128, 256),
        "repeats": 7,
        "rt_max": 128,
        "scenes": ("suzanne", "bunny"),
        "frames": ((128, 128), (192, 108)),
    },
    "cuda": {
        "sizes": (256, 512, 1024, 2048),
        "repeats": 10,
        "rt_max": 1024,
        "scenes": ("suzanne", "bunny", "bunny_x4", "bunny_x16"),
        "frames": ((512, 512), (1920, 1080), (3840, 2160)),
    },
}
SUN = (0.4, 0.8, 0.45)
BUDGETS = (2**18, 2**20, 2**24, 2**28)
TILES = (32, 64, 128)
ZFIGHT_DISTANCES = (3.0, 10.0, 30.0, 100.0, 300.0)


# --------------------------------------------------------------------------------------
# The two ways to find what each pixel sees
# --------------------------------------------------------------------------------------


def raster_ids(
    mesh: Mesh,
    camera: Camera,
    depth_bits: int = 32,
    memory_budget_bytes: int = 2**28,
    tile: int | None = None,
) -> torch.Tensor:
    """(H, W) source-face ids of the rasterizer's visibility buffer (-1: empty)."""
    mvp = camera.view_projection(torch.float64).to(mesh.device)
    clip = lab.to_clip_space(mesh.vertices, mvp)
    clipped, source, _ = lab.clip_triangles(clip[mesh.faces])
    screen = lab.to_screen(clipped, camera.width, camera.height)
    kwargs = {"depth_bits": depth_bits, "memory_budget_bytes": memory_budget_bytes}
    if tile is None:
        keys = lab.rasterize(screen, camera.width, camera.height, **kwargs)
    else:
        keys = tiled_keys(screen, camera.width, camera.height, tile, **kwargs)
    k = lab.triangle_ids(keys)
    ids = torch.where(k >= 0, source[k.clamp(min=0)], -1) if len(source) else k
    return ids.reshape(camera.height, camera.width)


def fused_ids(mesh: Mesh, camera: Camera, depth_bits: int = 32) -> torch.Tensor:
    """``raster_ids`` with ``rasterize`` replaced by the fused Triton kernels (CUDA), and
    the near-plane clipper applied only to the triangles that cross the near plane."""
    from course.kernels.triton_raster import rasterize_triton, screen_triangles_fast

    mvp = camera.view_projection(torch.float64).to(mesh.device)
    clip = lab.to_clip_space(mesh.vertices, mvp)
    screen, source = screen_triangles_fast(
        clip, mesh.faces, camera.width, camera.height, lab.clip_triangles, lab.to_screen
    )
    k = lab.triangle_ids(
        rasterize_triton(screen, camera.width, camera.height, depth_bits=depth_bits)
    )
    ids = torch.where(k >= 0, source[k.clamp(min=0)], -1) if len(source) else k
    return ids.reshape(camera.height, camera.width)


@functools.lru_cache(maxsize=64)
def camera_matrix(camera: Camera) -> torch.Tensor:
    """The (4, 4) float64 MVP of a camera, computed once per camera (a host tensor).

    ``Camera.view_projection`` builds it from a dozen small torch operations, 0.1-0.3 ms of
    host time: longer than the fused raster's kernels at 1080p, and not part of
    rasterizing (an engine computes its 4x4 matrix once per frame, in nanoseconds). The
    fused rows time the rasterizer from this matrix, the copy to the GPU included; the
    traced rows build their rays from the camera, on the GPU."""
    return camera.view_projection(torch.float64)


def fused_vertex_ids(mesh: Mesh, camera: Camera, depth_bits: int = 32) -> torch.Tensor:
    """``raster_ids`` as one fused pipeline, ``course.kernels.triton_raster.visibility_fused``: the
    MVP, near-plane clipping and viewport in one Triton kernel (no host synchronisation),
    then the raster kernels and the id map. The same pieces and keys as the lab's; only an
    exact depth tie between the second piece of a clipped face and another face can go
    the other way (slot order)."""
    from course.kernels.triton_raster import visibility_fused

    return visibility_fused(
        mesh.vertices,
        mesh.faces,
        camera_matrix(camera),
        camera.width,
        camera.height,
        depth_bits=depth_bits,
    )


@functools.lru_cache(maxsize=8)
def _recorded(mesh: Mesh, width: int, height: int):
    from course.kernels.triton_raster import FusedVisibility

    return FusedVisibility(mesh.vertices, mesh.faces, width, height)


def graphed_ids(mesh: Mesh, camera: Camera) -> torch.Tensor:
    """``fused_vertex_ids`` replayed from a CUDA graph (``FusedVisibility``, recorded on
    the first call for this mesh and viewport): one launch per frame instead of four."""
    return _recorded(mesh, camera.width, camera.height)(camera_matrix(camera))


def kernel_times(fn, repeats: int = 20) -> dict[str, float]:
    """Seconds of GPU time per call of each CUDA kernel and copy ``fn`` launches
    (``torch.profiler``), by name; empty where the profiler reports no device times."""
    from torch.profiler import ProfilerActivity, profile

    fn()
    torch.cuda.synchronize()
    with profile(activities=[ProfilerActivity.CUDA]) as prof:
        for _ in range(repeats):
            fn()
        torch.cuda.synchronize()
    return {
        e.key: e.self_device_time_total / 1e6 / repeats
        for e in prof.key_averages()
        if getattr(e, "self_device_time_total", 0) > 0
    }


def tiled_keys(screen, width: int, height: int, tile: int, **kwargs) -> torch.Tensor:
    """The visibility buffer rasterized tile by tile: each tile is a small viewport, the
    triangles shifted by its corner (integer shifts are exact), so every box is clamped to
    the tile and the ids stay those of ``screen``."""
    out = torch.empty(height, width, dtype=torch.int64, device=screen.device)
    for y0 in range(0, height, tile):
        for x0 in range(0, width, tile):
            tw, th = min(tile, width - x0), min(tile, height - y0)
            shifted = screen.clone()
            shifted[..., 0] -= x0
            shifted[..., 1] -= y0
            out[y0 : y0 + th, x0 : x0 + tw] = lab.rasterize(shifted, tw, th, **kwargs).reshape(
                th, tw
            )
    return out.reshape(-1)


def traced_ids(mesh: Mesh, camera: Camera) -> torch.Tensor:
    """(H, W) triangle ids of one primary ray per pixel, Lab 1's brute force in float32."""
    rays = primary_rays(camera, device=mesh.device, dtype=mesh.dtype)
    hits = closest_hit(
        Rays.create(rays.origins, rays.directions, rays.t_min, rays.t_max),
        mesh,
        "moller_trumbore",
        memory_budget_bytes=2**30,
    )
    return hits.triangle.reshape(camera.height, camera.width)


# --------------------------------------------------------------------------------------
# Rows
# --------------------------------------------------------------------------------------


def bench_resolutions(table: ResultTable, mesh: Mesh, camera: Camera, cfg: dict) -> None:
    for size in cfg["sizes"]:
        cam = dataclasses.replace(camera, width=size, height=size)
        pixels, tris = size * size, mesh.num_faces
        traced = traced_ids(mesh, cam) if size <= cfg["rt_max"] else None
        for depth_bits in (32, 24):
            ids = raster_ids(mesh, cam, depth_bits)
            t = time_fn(raster_ids, mesh, cam, depth_bits, repeats=cfg["repeats"], warmup=1)
            _add(
                table,
                method="raster",
                setting=f"{depth_bits}-bit",
                size=size,
                seconds=t.median,
                triangles_per_s=tris / t.median,
                pixels_per_s=pixels / t.median,
                coverage=(ids >= 0).double().mean(),
                disagreement=None if traced is None else (ids != traced).double().mean(),
            )
        if traced is not None:
            # Slow and steady: one timed run, the id pass above was its warm-up.
            t = time_fn(traced_ids, mesh, cam, repeats=1, warmup=0)
            _add(
                table,
                method="raytrace",
                setting="MT fp32 brute force",
                size=size,
                seconds=t.median,
                triangles_per_s=tris / t.median,
                pixels_per_s=pixels / t.median,
                coverage=(traced >= 0).double().mean(),
                disagreement=0.0,
            )


def bench_knobs(table: ResultTable, mesh: Mesh, camera: Camera, cfg: dict) -> None:
    size = max(cfg["sizes"])
    cam = dataclasses.replace(camera, width=size, height=size)
    pixels, tris = size * size, mesh.num_faces
    whole = raster_ids(mesh, cam)
    for budget in BUDGETS:
        t = time_fn(raster_ids, mesh, cam, 32, budget, repeats=cfg["repeats"], warmup=1)
        ids = raster_ids(mesh, cam, 32, budget)
        _add(
            table,
            method="chunk",
            setting=f"{budget >> 20} MiB" if budget >= 2**20 else f"{budget >> 10} KiB",
            size=size,
            seconds=t.median,
            triangles_per_s=tris / t.median,
            pixels_per_s=pixels / t.median,
            changed=(ids != whole).double().mean(),
        )
    for tile in TILES:
        if tile >= size:
            continue
        t = time_fn(raster_ids, mesh, cam, 32, 2**28, tile, repeats=cfg["repeats"], warmup=1)
        ids = raster_ids(mesh, cam, 32, 2**28, tile)
        _add(
            table,
            method="tile",
            setting=f"{tile}x{tile}",
            size=size,
            seconds=t.median,
            triangles_per_s=tris / t.median,
            pixels_per_s=pixels / t.median,
            changed=(ids != whole).double().mean(),
        )


def zfight_scene(distance: float, gap: float, device) -> tuple[Mesh, Camera]:
    """Two parallel quads ``gap`` apart, ``distance`` away, tilted by 30 degrees; the front
    one (faces 2, 3) hides the back one (faces 0, 1) wherever both are drawn. The back quad
    comes first: equal keys go to the lower id, so every depth tie shows as z-fighting."""
    half = 0.4 * distance  # both fill a similar part of the view at every distance
    quad = torch.tensor(
        [[-half, -half], [half, -half], [half, half], [-half, half]], dtype=torch.float64
    )
    # Tilted by 30 degrees about y: depth varies across the quads, as on real surfaces.
    c, s = 0.8660254037844386, 0.5

    def place(z):
        x, y = quad[:, 0], quad[:, 1]
        return torch.stack([c * x, y, -distance + s * x + z], -1)

    vertices = torch.cat([place(-gap), place(0.0)])
    faces = torch.tensor([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])
    camera = Camera(
        eye=(0.0, 0.0, 0.0),
        target=(0.0, 0.0, -1.0),
        fov_y=60.0,
        width=128,
        height=128,
        near=0.01,
        far=10 * distance + 10,
    )
    return Mesh(vertices.float().to(device), faces.to(device)), camera


def bench_zfighting(table: ResultTable, device) -> None:
    gap = 0.01
    for distance in ZFIGHT_DISTANCES:
        mesh, camera = zfight_scene(distance, gap, device)
        for depth_bits in (32, 24):
            ids = raster_ids(mesh, camera, depth_bits)
            front = ids >= 0
            back = (ids < 2) & front
            _add(
                table,
                method="zfight",
                setting=f"{depth_bits}-bit",
                size=camera.width,
                distance=distance,
                gap=gap,
                zfight_rate=back.double().sum() / front.double().sum().clamp(min=1),
            )


def bench_frames(table: ResultTable, device, cfg: dict) -> None:
    """Raster vs BVH-traced visibility and the hybrid frame, per scene and frame size."""

    from course.kernels.flat_bvh import flat_bvh_for
    from course.kernels.trace import trace_bvh

    sun = torch.tensor(SUN, device=device)
    for name in cfg["scenes"]:
        scene = load_scene(name, device=device)
        mesh = scene.mesh
        started = time.perf_counter()
        flat_bvh_for(mesh)
        build_s = time.perf_counter() - started
        trace = functools.partial(trace_bvh, mesh)
        for width, height in cfg["frames"]:
            cam = dataclasses.replace(scene.camera, width=width, height=height)
            common = {
                "scene": name,
                "triangles": mesh.num_faces,
                "frame": f"{width}x{height}",
                "size": width,
                "pixels": width * height,
            }
            traced = lab.traced_visibility(trace, cam, device=device)
            # traced_visibility's own ``device`` goes positionally; time_fn's by keyword.
            t_rt = time_fn(
                lab.traced_visibility,
                trace,
                cam,
                device,
                repeats=cfg["repeats"],
                warmup=1,
                device=device,
            )
            torch_ids = raster_ids(mesh, cam)
            if device.type == "cuda":
                # The whole pipeline in the fused kernels (vertex stage included), from the
                # camera to the ids like traced_visibility; timed next to it, same process.
                fused = fused_vertex_ids(mesh, cam)
                t_v = time_fn(
                    fused_vertex_ids, mesh, cam, repeats=cfg["repeats"], warmup=2, device=device
                )
                covered = (fused >= 0) | (traced >= 0)
                _add(
                    table,
                    method="frame",
                    setting="raster ids (fused, vertex kernel)",
                    seconds=t_v.median,
                    ms_per_frame=1e3 * t_v.median,
                    pixels_per_s=width * height / t_v.median,
                    disagreement=((fused != traced) & covered).double().sum()
                    / covered.double().sum(),
                    differs_from_torch=(fused != torch_ids).double().mean().item(),
                    raster_speedup=t_rt.median / t_v.median,
                    **common,
                )
                graphed = graphed_ids(mesh, cam)
                t_g = time_fn(
                    graphed_ids, mesh, cam, repeats=cfg["repeats"], warmup=2, device=device
                )
                _add(
                    table,
                    method="frame",
                    setting="raster ids (fused, vertex kernel, CUDA graph)",
                    seconds=t_g.median,
                    ms_per_frame=1e3 * t_g.median,
                    pixels_per_s=width * height / t_g.median,
                    differs_from_torch=(graphed != torch_ids).double().mean().item(),
                    raster_speedup=t_rt.median / t_g.median,
                    **common,
                )
                # Where the time goes: each kernel's GPU time (the rest is host time).
                gpu = kernel_times(functools.partial(fused_vertex_ids, mesh, cam))
                if gpu:
                    total = sum(gpu.values())
                    _add(
                        table,
                        method="frame",
                        setting="fused, vertex kernel: kernels' GPU time",
                        seconds=total,
                        ms_per_frame=1e3 * total,
                        pixels_per_s=width * height / total,
                        raster_speedup=t_rt.median / total,
                        **{
                            f"{k.strip('_').removesuffix('_kernel')}_us": 1e6 * v
                            for k, v in gpu.items()
                            if k.startswith("_")
                        },
                        **common,
                    )
            if cfg.get("quick"):
                _add(
                    table,
                    method="frame",
                    setting="BVH-traced visibility",
                    seconds=t_rt.median,
                    ms_per_frame=1e3 * t_rt.median,
                    pixels_per_s=width * height / t_rt.median,
                    build_s=build_s,
                    **common,
                )
                continue
            face, _ = lab.rasterize_mesh(mesh, cam)
            t = time_fn(lab.rasterize_mesh, mesh, cam, repeats=cfg["repeats"], warmup=1)
            covered = (face >= 0) | (traced >= 0)
            differ = ((face != traced) & covered).double().sum() / covered.double().sum()
            _add(
                table,
                method="frame",
                setting="raster visibility",
                seconds=t.median,
                ms_per_frame=1e3 * t.median,
                pixels_per_s=width * height / t.median,
                disagreement=differ,
                **common,
            )
            t_ids = time_fn(raster_ids, mesh, cam, repeats=cfg["repeats"], warmup=1, device=device)
            _add(
                table,
                method="frame",
                setting="raster ids (torch)",
                seconds=t_ids.median,
                ms_per_frame=1e3 * t_ids.median,
                pixels_per_s=width * height / t_ids.median,
                **common,
            )
            if device.type == "cuda":
                fused = fused_ids(mesh, cam)
                t_f = time_fn(fused_ids, mesh, cam, repeats=cfg["repeats"], warmup=1, device=device)
                same = ((fused != torch_ids).double().mean()).item()
                _add(
                    table,
                    method="frame",
                    setting="raster ids (fused Triton)",
                    seconds=t_f.median,
                    ms_per_frame=1e3 * t_f.median,
                    pixels_per_s=width * height / t_f.median,
                    differs_from_torch=same,
                    raster_speedup=t_rt.median / t_f.median,
                    **common,
                )
                # Where the time goes: the torch setup (MVP, near-plane clipping, viewport)
                # against the fused kernels alone on its output.
                from course.kernels.triton_raster import rasterize_triton

                mvp = cam.view_projection(torch.float64).to(device)
                clipped, _, _ = lab.clip_triangles(
                    lab.to_clip_space(mesh.vertices, mvp)[mesh.faces]
                )
                screen = lab.to_screen(clipped, width, height)
                t_k = time_fn(
                    rasterize_triton,
                    screen,
                    width,
                    height,
                    repeats=cfg["repeats"],
                    warmup=1,
                    device=device,
                )
                _add(
                    table,
                    method="frame",
                    setting="fused raster kernels alone",
                    seconds=t_k.median,
                    ms_per_frame=1e3 * t_k.median,
                    pixels_per_s=width * height / t_k.median,
                    raster_speedup=t_rt.median / t_k.median,
                    **common,
                )
            _add(
                table,
                method="frame",
                setting="BVH-traced visibility",
                seconds=t_rt.median,
                ms_per_frame=1e3 * t_rt.median,
                pixels_per_s=width * height / t_rt.median,
                build_s=build_s,
                raster_speedup=t_rt.median / t.median,
                **common,
            )

            def hybrid(mesh=mesh, cam=cam, trace=trace):
                face, bary = lab.rasterize_mesh(mesh, cam)
                lambert = lab.shade(mesh, face, bary, sun, True)
                lit = torch.where(lambert > 0, face, -1)  # no shadow rays where it is dark
                return lab.hybrid_shadows(trace, mesh, lit, bary, sun)

            t_h = time_fn(hybrid, repeats=cfg["repeats"], warmup=1, device=device)
            t_t = time_fn(
                lab.traced_shadows, trace, mesh, cam, sun, repeats=cfg["repeats"], warmup=1
            )
            _add(
                table,
                method="frame",
                setting="hybrid: raster + traced shadows",
                seconds=t_h.median,
                ms_per_frame=1e3 * t_h.median,
                pixels_per_s=width * height / t_h.median,
                **common,
            )
            _add(
                table,
                method="frame",
                setting="traced: primary + shadow rays",
                seconds=t_t.median,
                ms_per_frame=1e3 * t_t.median,
                pixels_per_s=width * height / t_t.median,
                **common,
            )


def _add(table: ResultTable, **row) -> None:
    row = table.add(**row)
    shown = {k: (f"{v:.4g}" if isinstance(v, float) else v) for k, v in row.items()}
    print(" ".join(f"{k}={v}" for k, v in shown.items()), flush=True)


# --------------------------------------------------------------------------------------
# Output
# --------------------------------------------------------------------------------------


def write_outputs(table: ResultTable, out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    table.to_json(out / "lab6_raster.json")
    meta = table.metadata
    legend = (
        "raster: the lab's visibility buffer (to_clip_space .. rasterize, ids through "
        "source); raytrace: Lab 1's brute-force closest_hit, one primary ray per pixel; "
        "disagreement: fraction of pixels whose triangle differs between the two; "
        "chunk: rasterize's memory budget; tile: screen tiles rasterized in turn; "
        "changed: pixels differing from the untiled, default-budget raster (must be 0); "
        "zfight_rate: fraction of the front quad's pixels where the back quad (1 cm "
        "behind, lower ids: it wins exact ties) shows."
    )
    device = (
        f"Device: {meta['device']}, {meta.get('threads')} torch threads; torch "
        f"{meta['torch']}; {meta['date']}."
    )
    header = [
        f"# {table.name}",
        "",
        device,
        "",
        f"Command: `{meta['command']}`",
        "",
        f"Scene: {meta['scene']} ({meta['triangles']} triangles).",
        "",
        legend,
        "",
    ]
    (out / "lab6_raster.md").write_text("\n".join(header) + table.to_markdown() + "\n")
    from matplotlib.figure import Figure

    frames = [r for r in table.rows if r["method"] == "frame"]
    if frames:
        fig = Figure(figsize=(7.2, 4.8), layout="constrained")
        ax = fig.add_subplot()
        for key in dict.fromkeys((r["setting"], r["frame"]) for r in frames):
            sel = [r for r in frames if (r["setting"], r["frame"]) == key]
            ax.plot(
                [r["triangles"] for r in sel],
                [r["ms_per_frame"] for r in sel],
                marker="o",
                label=f"{key[0]}, {key[1]}",
            )
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("triangles (suzanne, bunny, bunny_x4, bunny_x16)")
        ax.set_ylabel("ms per frame")
        ax.set_title("raster vs ray-traced visibility and the hybrid frame")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=6)
        fig.savefig(out / "frames.png", dpi=150)
    series = [r for r in table.rows if r["method"] in ("raster", "raytrace")]
    if series:
        fig = Figure(figsize=(6.4, 4.8), layout="constrained")
        ax = fig.add_subplot()
        for key in dict.fromkeys((r["method"], r["setting"]) for r in series):
            sel = [r for r in series if (r["method"], r["setting"]) == key]
            ax.plot(
                [r["size"] for r in sel],
                [r["pixels_per_s"] for r in sel],
                marker="o",
                label=" ".join(key),
            )
        worst = max(
            (r["disagreement"] for r in series if r.get("disagreement") is not None), default=None
        )
        ax.set_xscale("log", base=2)
        ax.set_yscale("log")
        ax.set_xlabel("image size (pixels per side)")
        ax.set_ylabel("pixels / s (primary visibility)")
        ax.set_title(
            "raster vs ray-traced primary visibility"
            + ("" if worst is None else f" (ids differ on <= {worst:.2%} of pixels)")
        )
        ax.grid(True, which="both", alpha=0.3)
        ax.legend()
        fig.savefig(out / "throughput.png", dpi=150)
    zrows = [r for r in table.rows if r["method"] == "zfight"]
    if zrows:
        fig = Figure(figsize=(6.4, 4.8), layout="constrained")
        ax = fig.add_subplot()
        for setting in dict.fromkeys(r["setting"] for r in zrows):
            sel = [r for r in zrows if r["setting"] == setting]
            ax.plot(
                [r["distance"] for r in sel],
                [r["zfight_rate"] for r in sel],
                marker="o",
                label=setting,
            )
        ax.set_xscale("log")
        ax.set_xlabel("distance of two quads 1 cm apart (near plane 0.01)")
        ax.set_ylabel("fraction of pixels where the back quad wins")
        ax.set_title("z-fighting: 24-bit window depth vs 32-bit float view depth")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend()
        fig.savefig(out / "zfighting.png", dpi=150)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--device", default=None, help="cpu or cuda (default: cuda if present)")
    parser.add_argument("--sizes", type=int, nargs="+", help="square image sizes in pixels")
    parser.add_argument(
        "--scene", default="suzanne", help="the scene of the resolution and knob sweeps"
    )
    parser.add_argument("--scenes", nargs="+", help="scenes of the frame series")
    parser.add_argument("--frames", nargs="+", help="frame sizes WxH of the frame series")
    parser.add_argument(
        "--only",
        nargs="+",
        choices=("trade", "sizes", "knobs", "zfight", "frames"),
        help="run only these parts",
    )
    parser.add_argument(
        "--quick",
        action="store_true",
        help="frame series: only the BVH-traced visibility and the end-to-end fused raster",
    )
    parser.add_argument("--repeats", type=int, help="timed runs per setting (median reported)")
    parser.add_argument("--threads", type=int, help="CPU threads of torch (default: torch's)")
    parser.add_argument(
        "--out", type=Path, help="output folder (default: bench/results/<device_name>/lab6)"
    )
    add_impl_option(parser)
    args = parser.parse_args(argv)
    global lab, closest_hit
    lab = load_lab("lab6_raster", args.impl, root=REPO)
    closest_hit = load_lab("lab1_intersect", args.impl, root=REPO).closest_hit

    device = default_device(args.device)
    cfg = dict(SIZES["cuda" if device.type == "cuda" else "cpu"])
    if args.sizes:
        cfg["sizes"] = tuple(args.sizes)
    if args.repeats:
        cfg["repeats"] = args.repeats
    cfg["quick"] = args.quick
    if args.scenes:
        cfg["scenes"] = tuple(args.scenes)
    if args.frames:
        cfg["frames"] = tuple(tuple(int(x) for x in f.lower().split("x")) for f in args.frames)
    out = args.out or REPO / "bench" / "results" / device_name(device) / "lab6"
    if args.threads:
        torch.set_num_threads(args.threads)

    scene = load_scene(args.scene, device=device)
    table = ResultTable("Lab 6: compute rasterizer vs ray-traced primary visibility", device)
    table.metadata.update(
        command=shlex.join(
            ["python", "bench/lab6_raster.py", *(sys.argv[1:] if argv is None else argv)]
        ),
        scene=args.scene,
        triangles=scene.mesh.num_faces,
        sizes=list(cfg["sizes"]),
        scenes=list(cfg["scenes"]),
        frames=[f"{w}x{h}" for w, h in cfg["frames"]],
        repeats=cfg["repeats"],
        threads=torch.get_num_threads(),
        quick=args.quick,
        lab_file=str(lab.__file__),
    )
    print(
        f"{table.metadata['device']}: {args.scene} ({scene.mesh.num_faces} triangles), "
        f"sizes {cfg['sizes']}",
        flush=True,
    )
    started = time.perf_counter()
    # "trade": the rows of rtcourse bench --lab 6 (course.tools.trade.lab6), measured on this
    # lab and plotted as a student's are (trade.csv, pareto_trade.png).
    parts = {
        "trade": lambda: bench_rows(6, lab, device, device.type == "cpu", out),
        "sizes": lambda: bench_resolutions(table, scene.mesh, scene.camera, cfg),
        "knobs": lambda: bench_knobs(table, scene.mesh, scene.camera, cfg),
        "zfight": lambda: bench_zfighting(table, device),
        "frames": lambda: bench_frames(table, device, cfg),
    }
    for part in args.only or parts:
        try:
            parts[part]()
        except NotImplementedError as exc:  # the handout: a lab function not written yet
            print(f"{part}: skipped: {exc}", flush=True)
            continue
        write_outputs(table, out)  # after every part: a run cut short keeps what it measured
    print(f"done in {time.perf_counter() - started:.1f} s: {out}")


if __name__ == "__main__":
    main()
