"""Lab 5 speed/accuracy benchmark: froxel resolution, temporal integration, volumetric shadows.

    python bench/lab5_froxel.py --device cpu|cuda [--small] [--out DIR]
    python bench/lab5_froxel.py --device cuda --gpu-target     # the talk's 1080p frame only
    python bench/lab5_froxel.py --device cpu --only volumes    # one series (its own files)
    python bench/lab5_froxel.py --device cpu --quick --impl labs  # your lab, toy sizes

The lab measured is ``--impl``'s (solutions/ in the course repository, labs/ in the handout);
a series that calls a function not written yet is skipped with the reason.

Every row renders one frame of a fog scene with ``render_froxels`` and compares it with
``course.given.lab5_reference.reference_render`` (brute-force single scattering, float64, exact
shadow rays) on a fixed subset of pixels; ``error`` is the mean absolute error divided by
the mean reference radiance, ``max_error`` the largest pixel error divided by the largest
reference radiance; ``seconds`` is the median time of one frame (after warm-up).

* ``resolution``: tile sizes 4, 8, 16 px x slice counts 32, 64, 128 (volumetric shadows on,
  no temporal integration).
* ``shadows``: volumetric shadows on and off at 8 px x 64 slices (the reference keeps them:
  turning them off is a modelling error, measured).
* ``volumes``: the sun through a homogeneous box of fog (sigma_s 0.5, sigma_a 0.1, g 0.5),
  seen from inside it and from outside (a 2 m box 5 m away), at the defaults (8 px x 64
  slices, 0.1 .. 100 m) for extinction/transmittance volume resolutions 16 .. 128 and the
  automatic one, over the media's bounds (the default) and over the whole frustum's (the
  old model, made here by adding an empty unbounded fog); ``mean_error`` is the signed
  error of the mean radiance. Plotted as ``pareto_volumes_<view>.png``.
* ``temporal``: error after 1, 8 and 32 frames of temporal integration with a static camera
  and with a camera sliding sideways (each frame against the reference from its own
  camera); 8 px x 32 slices, where the jitter has the most to add; with all the scene's
  lights and with the sun only. Point lights inside the fog put a 1/d^2 peak inside some
  froxels: jittered samples find it (the midpoint misses it) and the tile spreads it over
  8 x 8 pixels, so with point lights the error grows over frames; with the sun it shrinks.
* ``frame``: the talk's test scene at 1080p (240 x 135 x 64 froxels, sun + 14 point lights,
  6 local fog volumes with 16^3 density textures, height fog), time per frame; the target
  on an H100/H200 is 2 ms. ``--gpu-target`` times only this and prints ms/frame. On CUDA
  the same frame is also timed with ``course.kernels.triton_froxel.render_froxels_fused`` (the
  pipeline fused into five Triton kernels), without and with its counts, and its error
  against the torch pipeline's image is recorded (``error_vs_torch``, ``max_error_vs_torch``).

* ``trade``: the rows ``rtcourse bench --lab 5`` measures (``course.tools.trade.lab5``:
  tile x slices, without volumetric shadows, temporal reuse), written as ``trade.csv`` with
  their plot ``pareto_trade.png``, drawn as a student's is.

Writes ``lab5_froxel.json`` (a ResultTable with the command line), ``lab5_froxel.md`` and
Pareto plots (seconds against error) into ``--out``, by default
``bench/results/<device_name>/lab5/``. On the CPU only ratios between rows mean anything.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import shlex
import sys
from pathlib import Path

import torch

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))  # run from a checkout without installing

from course.core.camera import Camera
from course.core.device import default_device
from course.given.lab5 import (
    Box,
    ConstantFog,
    DirectionalLight,
    FogVolume,
    HeightFog,
    PointLight,
    Scene,
)
from course.given.lab5_reference import reference_render
from course.measure.bench import (
    ResultTable,
    add_impl_option,
    device_name,
    load_lab,
    pareto_plot,
    time_fn,
)
from course.tools.trade import bench_rows

lab = None  # the Lab 5 module measured: main() loads it from --impl

F64 = torch.float64
# Per mode: image size of the accuracy sweeps, reference samples and shadow steps, pixels
# compared (every n-th), timed runs per setting, far plane.
SIZES = {
    "quick": {
        "image": (48, 27),
        "samples": 16,
        "shadow_steps": 4,
        "stride": 7,
        "repeats": 1,
        "frames": (1, 2),
        "volume_resolutions": (16, None),
        "temporal_lights": ("sun",),
    },
    "small": {
        "image": (192, 108),
        "samples": 64,
        "shadow_steps": 12,
        "stride": 53,
        "repeats": 2,
        "frames": (1, 8, 32),
    },
    "full": {
        "image": (640, 360),
        "samples": 192,
        "shadow_steps": 32,
        "stride": 97,
        "repeats": 10,
        "frames": (1, 8, 32),
    },
}
NEAR, FAR = 0.1, 40.0


# --------------------------------------------------------------------------------------
# Scenes
# --------------------------------------------------------------------------------------


def density_texture(n: int, seed: int) -> torch.Tensor:
    """(n, n, n) float32 in [0, 1]: a few soft blobs, 0 on the border voxels."""
    g = torch.Generator().manual_seed(seed)
    x = (torch.arange(n, dtype=torch.float32) + 0.5) / n
    p = torch.stack(torch.meshgrid(x, x, x, indexing="ij"), -1)
    d = torch.zeros(n, n, n)
    for c, r in zip(
        0.3 + 0.4 * torch.rand(4, 3, generator=g), 0.15 + 0.15 * torch.rand(4, generator=g)
    ):
        d += torch.exp(-(p - c).square().sum(-1) / r**2)
    d = (d / d.max()).clamp(0, 1)
    d[[0, -1]] = 0
    d[:, [0, -1]] = 0
    d[:, :, [0, -1]] = 0
    return d


def talk_scene(device, volumes: int = 6, points: int = 14, texture: int = 16) -> Scene:
    """The talk's test scene: sun with a shadow-casting occluder, point lights, local fog
    volumes with density textures and a height fog, in a 40 m street."""
    g = torch.Generator().manual_seed(5)
    fogs = [
        HeightFog(scattering=(0.03, 0.035, 0.04), extinction=0.045, base=0.0, falloff=0.25, g=0.3)
    ]
    for v in range(volumes):
        c = (
            float(torch.rand(1, generator=g)) * 16 - 8,
            1.5 + float(torch.rand(1, generator=g)),
            -4.0 - 5.0 * v,
        )
        angle = float(torch.rand(1, generator=g)) * math.pi
        ca, sa = math.cos(angle), math.sin(angle)
        fogs.append(
            FogVolume(
                center=c,
                half_size=(2.5, 1.5, 2.0),
                scattering=(0.25,) * 3,
                extinction=0.3,
                g=0.5,
                shape="box" if v % 2 else "ellipsoid",
                rotation=((ca, 0, -sa), (0, 1, 0), (sa, 0, ca)),
                density=density_texture(texture, v).to(device),
            )
        )
    lights = [DirectionalLight(direction=(0.4, 0.8, -0.45), irradiance=(3.0, 2.8, 2.5))]
    for n in range(points):
        pos = (
            float(torch.rand(1, generator=g)) * 20 - 10,
            0.5 + 3 * float(torch.rand(1, generator=g)),
            -2.0 - 2.6 * n,
        )
        color = tuple(2.0 + 6.0 * float(x) for x in torch.rand(3, generator=g))
        lights.append(PointLight(position=pos, intensity=color, range=6.0))
    occluders = (
        Box((-6.0, 5.0, -20.0), (-1.0, 6.0, -12.0)),
        Box((2.0, 4.0, -30.0), (7.0, 5.0, -26.0)),
    )
    return Scene(
        media=tuple(fogs), lights=tuple(lights), ambient=(0.05, 0.06, 0.08), occluders=occluders
    )


def accuracy_scene() -> Scene:
    """A smaller scene for the sweeps against the reference: height fog, two textured fog
    volumes, the sun with a shadow-casting occluder and three point lights."""
    return talk_scene("cpu", volumes=2, points=3, texture=8)


def camera_at(width: int, height: int, shift: float = 0.0) -> Camera:
    return Camera(
        eye=(shift, 1.6, 2.0),
        target=(shift * 0.5, 1.8, -20.0),
        fov_y=55.0,
        width=width,
        height=height,
    )


def scene_images(camera: Camera, device, dtype=torch.float32):
    """Depth (H, W) and opaque (H, W, 3) images: a ground plane y = 0 and a wall at z = -36
    (sky above it), the wall's colour shaded by distance."""
    from course.core.camera import primary_rays

    rays = primary_rays(camera, device="cpu", dtype=F64)
    d = rays.directions
    fwd = torch.tensor(camera.target, dtype=F64) - torch.tensor(camera.eye, dtype=F64)
    fwd = fwd / fwd.norm()
    t_ground = torch.where(d[:, 1] < 0, -camera.eye[1] / d[:, 1].clamp(max=-1e-9), math.inf)
    t_wall = torch.where(d[:, 2] < 0, (-36.0 - camera.eye[2]) / d[:, 2].clamp(max=-1e-9), math.inf)
    p_wall = torch.tensor(camera.eye, dtype=F64) + t_wall.clamp(max=1e6)[:, None] * d
    t_wall = torch.where(p_wall[:, 1] < 8.0, t_wall, math.inf)
    t = torch.minimum(t_ground, t_wall)
    depth = (t * (d @ fwd)).reshape(camera.height, camera.width)
    colour = torch.where(
        (t_ground < t_wall)[:, None],
        torch.tensor([0.10, 0.09, 0.08], dtype=F64),
        torch.tensor([0.18, 0.16, 0.15], dtype=F64),
    )
    colour = torch.where(
        torch.isinf(t)[:, None], torch.tensor([0.0, 0.0, 0.0], dtype=F64), colour
    ).reshape(camera.height, camera.width, 3)
    return depth.to(device, dtype), colour.to(device, dtype)


# --------------------------------------------------------------------------------------
# Rows
# --------------------------------------------------------------------------------------


def errors(image, ref, pixels):
    got = image.detach().to("cpu", F64).reshape(-1, 3)[pixels]
    diff = (got - ref).abs()
    return (diff.mean() / ref.abs().mean()).item(), (diff.max() / ref.abs().max()).item()


def reference(scene, camera, cfg, device):
    depth, opaque = scene_images(camera, "cpu", F64)
    pixels = torch.arange(0, camera.width * camera.height, cfg["stride"])
    ref = reference_render(
        scene,
        camera,
        depth,
        opaque,
        near=NEAR,
        far=FAR,
        samples=cfg["samples"],
        shadow_steps=cfg["shadow_steps"],
        pixels=pixels,
    )
    return ref["image"], pixels


def bench_resolution(table, cfg, device):
    scene = accuracy_scene()
    camera = camera_at(*cfg["image"])
    ref, pixels = reference(scene, camera, cfg, device)
    depth, opaque = scene_images(camera, device)
    for tile in (4, 8, 16):
        for slices in (32, 64, 128):
            for shadows in (True, False) if (tile, slices) == (8, 64) else (True,):
                args = {
                    "tile": tile,
                    "slices": slices,
                    "near": NEAR,
                    "far": FAR,
                    "volumetric_shadows": shadows,
                }
                image, report = lab.render_froxels(scene, camera, depth, opaque, **args)
                t = time_fn(
                    lab.render_froxels,
                    scene,
                    camera,
                    depth,
                    opaque,
                    repeats=cfg["repeats"],
                    warmup=1,
                    device=device,
                    **args,
                )
                err, worst = errors(image, ref, pixels)
                series = "resolution" if shadows else "shadows"
                table.add(
                    series=series,
                    setting=f"{tile}px x {slices}" + ("" if shadows else " no vol. shadows"),
                    tile=tile,
                    slices=slices,
                    volumetric_shadows=shadows,
                    froxels=report["froxels"],
                    froxels_lit=report["froxels_lit"],
                    light_evaluations=report["light_evaluations"],
                    seconds=t.median,
                    ms_per_frame=1e3 * t.median,
                    error=err,
                    max_error=worst,
                )
                print(
                    f"  {series} {tile}px x {slices} shadows={shadows}: {1e3 * t.median:.1f} "
                    f"ms, error {err:.4f} (max {worst:.3f})",
                    flush=True,
                )
                if shadows and (tile, slices) == (8, 64):
                    table.add(
                        series="shadows",
                        setting="8px x 64",
                        tile=tile,
                        slices=slices,
                        volumetric_shadows=True,
                        froxels=report["froxels"],
                        froxels_lit=report["froxels_lit"],
                        light_evaluations=report["light_evaluations"],
                        seconds=t.median,
                        ms_per_frame=1e3 * t.median,
                        error=err,
                        max_error=worst,
                    )


def fog_box_scene(lo, hi, bounds: str) -> Scene:
    """The sun through a homogeneous box of fog lo .. hi; with ``bounds="frustum"`` an empty
    unbounded fog makes the volumes cover the whole frustum's bounds."""
    box = FogVolume(
        center=tuple((a + b) / 2 for a, b in zip(lo, hi)),
        half_size=tuple((b - a) / 2 for a, b in zip(lo, hi)),
        scattering=(0.5, 0.5, 0.5),
        extinction=0.6,
        g=0.5,
    )
    empty = (
        (ConstantFog(scattering=(0.0, 0.0, 0.0), extinction=0.0),) if bounds == "frustum" else ()
    )
    return Scene(
        media=(box, *empty),
        lights=(DirectionalLight(direction=(0.5, 0.7, -0.5), irradiance=(3.0, 3.0, 3.0)),),
    )


def bench_volumes(table, cfg, device):
    """Volume resolution and bounds on a sun-lit fog box, against the reference."""
    w, h = cfg["image"]
    views = {
        "inside a fog box": (
            (-3.0, 0.0, -10.0),
            (3.0, 3.0, 2.0),
            Camera(eye=(0.5, 1.5, 0.0), target=(0.5, 1.7, -5.0), fov_y=50.0, width=w, height=h),
        ),
        "a fog box in view": (
            (-1.0, 0.0, -1.0),
            (1.0, 2.0, 1.0),
            Camera(eye=(0.5, 1.5, 5.0), target=(0.0, 1.0, 0.0), fov_y=50.0, width=w, height=h),
        ),
        # Lab 5's graded scene: the same box spans two 8-pixel tiles.
        "a fog box in view at 64 px": (
            (-1.0, 0.0, -1.0),
            (1.0, 2.0, 1.0),
            Camera(eye=(0.5, 1.5, 5.0), target=(0.0, 1.0, 0.0), fov_y=50.0, width=64, height=36),
        ),
    }
    for view, (lo, hi, camera) in views.items():
        w, h = camera.width, camera.height
        depth = torch.full((h, w), math.inf, dtype=F64)
        black = torch.zeros(h, w, 3, dtype=F64)
        pixels = torch.arange(0, w * h, max(1, cfg["stride"] // 8))
        # No fog beyond 15 m: the reference's march ends there (shadow rays through a
        # constant medium are exact with few steps).
        ref = reference_render(
            fog_box_scene(lo, hi, "media"),
            camera,
            depth,
            black,
            far=15.0,
            samples=4 * cfg["samples"],
            shadow_steps=4,
            pixels=pixels,
        )["image"]
        depth, black = depth.to(device, torch.float32), black.to(device, torch.float32)
        for bounds in ("media", "frustum"):
            scene = fog_box_scene(lo, hi, bounds)
            for resolution in cfg.get("volume_resolutions", (16, 32, 64, 128, None)):
                args = {"volume_resolution": resolution}
                image, report = lab.render_froxels(scene, camera, depth, black, **args)
                t = time_fn(
                    lab.render_froxels,
                    scene,
                    camera,
                    depth,
                    black,
                    repeats=cfg["repeats"],
                    warmup=1,
                    device=device,
                    **args,
                )
                err, worst = errors(image, ref, pixels)
                got = image.detach().to("cpu", F64).reshape(-1, 3)[pixels]
                mean = (got.mean() / ref.mean()).item() - 1
                label = f"{report['volume_resolution']}" + (" (auto)" if resolution is None else "")
                grid = report["grid"]
                label += f", tile {grid.tile}, {grid.near:.3g}-{grid.far:.3g} m"
                table.add(
                    series="volumes",
                    setting=f"{view}, {bounds} bounds, R {label}",
                    view=view,
                    bounds=bounds,
                    volume_resolution=report["volume_resolution"],
                    auto=resolution is None,
                    seconds=t.median,
                    ms_per_frame=1e3 * t.median,
                    error=err,
                    max_error=worst,
                    mean_error=mean,
                    group=f"{view}, {bounds} bounds",
                )
                print(
                    f"  volumes ({view}, {bounds} bounds) R {label}: {1e3 * t.median:.1f} ms, "
                    f"mean radiance {mean:+.4f}, error {err:.4f} (max {worst:.3f})",
                    flush=True,
                )
        # The grid the scene needs (scene_grid, every row above) against the talk's fixed one.
        fixed = {"tile": 8, "near": NEAR, "far": FAR}
        scene = fog_box_scene(lo, hi, "media")
        image, report = lab.render_froxels(scene, camera, depth, black, **fixed)
        t = time_fn(
            lab.render_froxels,
            scene,
            camera,
            depth,
            black,
            repeats=cfg["repeats"],
            warmup=1,
            device=device,
            **fixed,
        )
        err, worst = errors(image, ref, pixels)
        got = image.detach().to("cpu", F64).reshape(-1, 3)[pixels]
        mean = (got.mean() / ref.mean()).item() - 1
        table.add(
            series="volumes",
            setting=f"{view}, media bounds, tile 8, {NEAR}-{FAR} m",
            view=view,
            bounds="media, tile 8, 0.1-100 m",
            volume_resolution=report["volume_resolution"],
            auto=True,
            seconds=t.median,
            ms_per_frame=1e3 * t.median,
            error=err,
            max_error=worst,
            mean_error=mean,
            group=f"{view}, fixed grid",
        )
        print(
            f"  volumes ({view}) on tile 8 over {NEAR}-{FAR} m: {1e3 * t.median:.1f} ms, "
            f"mean radiance {mean:+.4f}, error {err:.4f}",
            flush=True,
        )
        plain, _ = lab.render_froxels(
            fog_box_scene(lo, hi, "media"), camera, depth, black, volumetric_shadows=False
        )
        got = plain.detach().to("cpu", F64).reshape(-1, 3)[pixels]
        print(
            f"  volumes ({view}) without volumetric shadows: mean radiance "
            f"{(got.mean() / ref.mean()).item() - 1:+.4f}",
            flush=True,
        )


def plot_volumes(rows, out: Path):
    """One Pareto plot per view of the ``volumes`` series (``pareto_volumes_<view>.png``):
    time against error, a colour per bounds, each point labelled with its resolution."""
    for view in dict.fromkeys(r["view"] for r in rows):
        points = [
            {**r, "label": f"R {r['volume_resolution']}" + (" auto" if r["auto"] else "")}
            for r in rows
            if r["view"] == view
        ]
        name = view.replace(" ", "_")
        pareto_plot(
            points,
            x="seconds",
            y="error",
            label="label",
            group="bounds",
            path=out / f"pareto_volumes_{name}.png",
            title=f"Volumes, {view}",
        )


def bench_temporal(table, cfg, device, lights="all"):
    """Temporal integration on the accuracy scene with all its lights, or the sun only."""
    scene = accuracy_scene()
    if lights == "sun":
        scene = dataclasses.replace(scene, lights=scene.lights[:1])
    tile, slices, last = 8, 32, max(cfg["frames"])
    args = {"tile": tile, "slices": slices, "near": NEAR, "far": FAR}
    static_ref, pixels = reference(scene, camera_at(*cfg["image"]), cfg, device)
    for motion in ("static", "moving"):
        shift = 0.04 if motion == "moving" else 0.0
        history = None
        for frame in range(last):
            camera = camera_at(*cfg["image"], shift=shift * frame)
            depth, opaque = scene_images(camera, device)
            image, report = lab.render_froxels(
                scene, camera, depth, opaque, temporal=True, frame=frame, history=history, **args
            )
            if frame + 1 in cfg["frames"]:
                # Each frame against the reference seen from its own camera.
                ref = static_ref if shift == 0 else reference(scene, camera, cfg, device)[0]
                err, worst = errors(image, ref, pixels)
                t = time_fn(
                    lab.render_froxels,
                    scene,
                    camera,
                    depth,
                    opaque,
                    temporal=True,
                    frame=frame,
                    history=history,
                    repeats=cfg["repeats"],
                    warmup=1,
                    device=device,
                    **args,
                )
                table.add(
                    series="temporal",
                    setting=f"{lights} lights, {motion}, frame {frame + 1}",
                    lights=lights,
                    motion=motion,
                    frames=frame + 1,
                    tile=tile,
                    slices=slices,
                    history_valid=report["history_valid"],
                    seconds=t.median,
                    ms_per_frame=1e3 * t.median,
                    error=err,
                    max_error=worst,
                )
                print(
                    f"  temporal ({lights} lights) {motion} after {frame + 1} frames: error "
                    f"{err:.4f} "
                    f"(max {worst:.3f}), history kept {report['history_valid']:.2f}",
                    flush=True,
                )
            history = report["history"]
    # Without temporal integration, for comparison.
    camera = camera_at(*cfg["image"])
    depth, opaque = scene_images(camera, device)
    t = time_fn(
        lab.render_froxels,
        scene,
        camera,
        depth,
        opaque,
        repeats=cfg["repeats"],
        warmup=1,
        device=device,
        **args,
    )
    err, worst = errors(
        lab.render_froxels(scene, camera, depth, opaque, **args)[0], static_ref, pixels
    )
    table.add(
        series="temporal",
        setting=f"{lights} lights, off",
        lights=lights,
        motion="off",
        frames=1,
        tile=tile,
        slices=slices,
        seconds=t.median,
        ms_per_frame=1e3 * t.median,
        error=err,
        max_error=worst,
    )


def bench_frame(table, device, repeats: int, size=(1920, 1080)):
    """The talk's scene at 1080p: 240 x 135 x 64 froxels; milliseconds per frame."""
    scene = talk_scene(device)
    camera = camera_at(*size)
    depth, opaque = scene_images(camera, device)
    args = {"tile": 8, "slices": 64, "near": NEAR, "far": FAR}
    _, report = lab.render_froxels(scene, camera, depth, opaque, **args)
    t = time_fn(
        lab.render_froxels,
        scene,
        camera,
        depth,
        opaque,
        repeats=repeats,
        warmup=2,
        device=device,
        **args,
    )
    grid = report["grid"]
    table.add(
        series="frame",
        setting=f"{size[0]}x{size[1]}, 8px x 64, sun + "
        f"{len(scene.lights) - 1} points, {len(scene.media) - 1} volumes",
        tile=8,
        slices=64,
        froxels=report["froxels"],
        froxels_lit=report["froxels_lit"],
        light_evaluations=report["light_evaluations"],
        seconds=t.median,
        ms_per_frame=1e3 * t.median,
        grid=f"{grid.nx}x{grid.ny}x{grid.slices}",
    )
    print(
        f"  frame {size[0]}x{size[1]} ({grid.nx}x{grid.ny}x{grid.slices} froxels, "
        f"{report['froxels_lit']} lit, {report['light_evaluations']} light evaluations): "
        f"{1e3 * t.median:.2f} ms/frame (median of {repeats}; target 2 ms on an H100/H200)",
        flush=True,
    )
    if device.type == "cuda":
        bench_frame_fused(table, scene, camera, depth, opaque, args, report, repeats, size)
    return t.median


def bench_frame_fused(table, scene, camera, depth, opaque, args, report, repeats, size):
    """The same frame with ``course.kernels.triton_froxel.render_froxels_fused`` (five Triton
    launches, no host synchronisation unless the counts are asked for), its error against
    the torch pipeline's image: ``max_error`` the largest difference / the largest
    radiance, ``error`` the mean difference / the mean radiance."""
    from course.kernels.triton_froxel import render_froxels_fused

    want, _ = lab.render_froxels(scene, camera, depth, opaque, **args)
    got, counts = render_froxels_fused(scene, camera, depth, opaque, **args)
    diff = (got.double() - want.double()).abs()
    err = (diff.mean() / want.double().abs().mean()).item()
    worst = (diff.max() / want.double().abs().max()).item()
    same = all(
        counts[k] == report[k]
        for k in ("froxels_lit", "tiles_with_media", "light_tiles", "light_evaluations")
    )
    for label, knobs in (
        ("fused", {"counts": False}),
        ("fused, counts (one sync)", {"counts": True}),
    ):
        t = time_fn(
            render_froxels_fused,
            scene,
            camera,
            depth,
            opaque,
            repeats=repeats,
            warmup=2,
            device=depth.device,
            **args,
            **knobs,
        )
        table.add(
            series="frame",
            setting=f"{size[0]}x{size[1]}, 8px x 64, {label}",
            implementation=label,
            tile=8,
            slices=64,
            froxels=report["froxels"],
            froxels_lit=counts["froxels_lit"],
            light_evaluations=counts["light_evaluations"],
            seconds=t.median,
            ms_per_frame=1e3 * t.median,
            error_vs_torch=err,
            max_error_vs_torch=worst,
            counts_match=same,
        )
        print(
            f"  frame {size[0]}x{size[1]}, {label} (course.kernels.triton_froxel): "
            f"{1e3 * t.median:.3f} ms/frame (median of {repeats}, min {1e3 * t.min:.3f}); "
            f"against the torch pipeline: mean error {err:.2e}, max error {worst:.2e} of the "
            f"largest radiance; counts {'match' if same else 'differ'}",
            flush=True,
        )


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--device", default=None)
    parser.add_argument("--small", action="store_true", help="small sizes (CPU, CI)")
    parser.add_argument(
        "--quick",
        action="store_true",
        help="toy sizes (seconds on a CPU): it runs; its numbers mean little",
    )
    parser.add_argument(
        "--gpu-target",
        action="store_true",
        help="time only the talk's 1080p frame and print ms/frame",
    )
    parser.add_argument("--out", default=None)
    parser.add_argument(
        "--only",
        choices=("trade", "resolution", "volumes", "temporal", "frame"),
        default=None,
        help="run one series, into lab5_froxel_<series>.*",
    )
    add_impl_option(parser)
    args = parser.parse_args(argv)
    global lab
    lab = load_lab("lab5_froxel", args.impl, root=REPO)
    device = default_device(args.device)
    if args.gpu_target:
        table = ResultTable("Lab 5: the talk's 1080p frame", device)
        bench_frame(table, device, repeats=50 if device.type == "cuda" else 3)
        return table
    cfg = SIZES[
        "quick" if args.quick else "small" if args.small or device.type == "cpu" else "full"
    ]
    out = Path(args.out) if args.out else REPO / "bench" / "results" / device_name(device) / "lab5"
    table = ResultTable("Lab 5: the froxel pipeline, speed against accuracy", device)
    table.metadata["command"] = "python " + shlex.join(
        ["bench/lab5_froxel.py", *(sys.argv[1:] if argv is None else argv)]
    )
    table.metadata["lab_file"] = str(lab.__file__)
    mode = next(name for name, sizes in SIZES.items() if sizes is cfg)
    print(f"Lab 5 bench on {device} ({mode})", flush=True)
    run = {args.only} if args.only else {"trade", "resolution", "volumes", "temporal", "frame"}
    # The rows of rtcourse bench --lab 5 (course.tools.trade.lab5), measured on this lab and
    # plotted as a student's are: trade.csv and pareto_trade.png.
    series = {
        "trade": lambda: bench_rows(5, lab, device, cfg is not SIZES["full"], out),
        "resolution": lambda: bench_resolution(table, cfg, device),
        "volumes": lambda: bench_volumes(table, cfg, device),
        "temporal": lambda: [
            bench_temporal(table, cfg, device, lights=lights)
            for lights in cfg.get("temporal_lights", ("all", "sun"))
        ],
    }
    if args.quick:
        series["frame"] = lambda: bench_frame(table, device, repeats=1, size=(96, 54))
    elif device.type == "cuda" or not args.small:
        series["frame"] = lambda: bench_frame(table, device, repeats=cfg["repeats"])
    else:  # the 1080p frame on 2 CPU cores takes seconds: a quarter-size one
        series["frame"] = lambda: bench_frame(table, device, repeats=1, size=(480, 270))
    for name, run_series in series.items():
        if name not in run:
            continue
        try:
            run_series()
        except NotImplementedError as exc:  # the handout: a lab function not written yet
            print(f"{name}: skipped: {exc}", flush=True)
    out.mkdir(parents=True, exist_ok=True)
    stem = f"lab5_froxel_{args.only}" if args.only else "lab5_froxel"
    table.to_json(out / f"{stem}.json")
    notes = (
        "error: mean |pipeline - reference| / mean reference radiance over every "
        f"{cfg['stride']}th pixel; max_error: largest pixel error / largest reference "
        "radiance; seconds: median per frame; froxels_lit and light_evaluations from the "
        "pipeline's report (only froxels with medium are lit, culled lights not counted). "
        f"volumes: every {max(1, cfg['stride'] // 8)}th pixel, mean_error the signed error "
        "of the mean radiance."
    )
    (out / f"{stem}.md").write_text(
        "# Lab 5: the froxel pipeline, speed against accuracy\n\n"
        f"Device: {table.metadata['device']} ({torch.get_num_threads()} torch threads); "
        f"torch {table.metadata['torch']}; "
        f"{table.metadata['date']}.\n\nCommand: `{table.metadata['command']}`\n\n{notes}\n\n"
        + table.to_markdown()
        + "\n"
    )
    rows = [r for r in table.rows if r["series"] in ("resolution", "shadows")]
    if rows:
        pareto_plot(
            rows,
            x="seconds",
            y="error",
            label="setting",
            group="series",
            path=out / "pareto_resolution.png",
            title="Froxel resolution: time per frame against error",
        )
    plot_volumes([r for r in table.rows if r["series"] == "volumes"], out)
    temporal = [r for r in table.rows if r["series"] == "temporal" and r.get("seconds")]
    if temporal:
        pareto_plot(
            temporal,
            x="frames",
            y="error",
            label="setting",
            group="lights",
            maximize_x=False,
            path=out / "temporal.png",
            title="Temporal integration: error against frames accumulated",
        )
    print(f"wrote {out}", flush=True)
    return table


if __name__ == "__main__":
    main()
