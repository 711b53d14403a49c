"""Lab 5's trade: froxel resolution, tile size and temporal reuse.

Knobs: ``render_froxels`` at tile sizes x slice counts, without volumetric shadows at one
of them (a modelling error, measured), and with temporal integration after several frames
of a static camera (the reprojected history blended in: each frame costs one frame, the
error is the accumulated frame's), on a fog scene (height fog, two textured fog volumes, the
sun with two shadow-casting occluders, two point lights) in front of a ground and a wall.
``froxels`` and ``light_evaluations`` are the pipeline's work. Error: the mean absolute
error over the mean reference radiance, against ``course.given.lab5_reference`` (brute-force
single scattering, float64, exact shadow rays) on every n-th pixel (``--quick``: light-space
volumes of 16^3). On CUDA the fused pipeline
(``course.kernels.triton_froxel.render_froxels_fused``) adds rows.
"""

from __future__ import annotations

import math

import torch

from course.core.camera import Camera, primary_rays
from course.given.lab5 import (
    Box,
    DirectionalLight,
    FogVolume,
    HeightFog,
    PointLight,
    Scene,
)
from course.given.lab5_reference import reference_render
from course.tools.trade.common import F64, timed

MODULE = "lab5_froxel"
TITLE = "froxels: resolution, tile and temporal reuse"
ERROR_NAME = "mean relative radiance error"
ERROR = (
    "mean absolute error / mean radiance against lab5_reference.reference_render "
    "(brute force, float64) on every n-th pixel"
)
NEAR, FAR = 0.1, 40.0


def density_texture(n: int, seed: int) -> torch.Tensor:
    """(n, n, n) float32 in [0, 1]: a few soft blobs, 0 on the border voxels."""
    g = torch.Generator().manual_seed(seed)
    x = (torch.arange(n, dtype=torch.float32) + 0.5) / n
    p = torch.stack(torch.meshgrid(x, x, x, indexing="ij"), -1)
    d = torch.zeros(n, n, n)
    for c, r in zip(
        0.3 + 0.4 * torch.rand(3, 3, generator=g), 0.15 + 0.15 * torch.rand(3, generator=g)
    ):
        d += torch.exp(-(p - c).square().sum(-1) / r**2)
    d = (d / d.max()).clamp(0, 1)
    d[[0, -1]] = 0
    d[:, [0, -1]] = 0
    d[:, :, [0, -1]] = 0
    return d


def fog_scene(device) -> Scene:
    fogs = (
        HeightFog(scattering=(0.03, 0.035, 0.04), extinction=0.045, base=0.0, falloff=0.25, g=0.3),
        FogVolume(
            center=(0.5, 1.8, -7.0),
            half_size=(2.5, 1.5, 2.0),
            scattering=(0.25,) * 3,
            extinction=0.3,
            g=0.5,
            shape="ellipsoid",
            density=density_texture(8, 0).to(device),
        ),
        FogVolume(
            center=(-3.0, 1.5, -13.0),
            half_size=(2.0, 1.5, 2.0),
            scattering=(0.2,) * 3,
            extinction=0.25,
            g=0.4,
            shape="box",
            density=density_texture(8, 1).to(device),
        ),
    )
    lights = (
        DirectionalLight(direction=(0.4, 0.8, -0.45), irradiance=(3.0, 2.8, 2.5)),
        PointLight(position=(-1.5, 1.5, -5.0), intensity=(6.0, 5.0, 4.0), range=6.0),
        PointLight(position=(2.0, 2.5, -9.0), intensity=(3.0, 4.0, 6.0), range=6.0),
    )
    return Scene(
        media=fogs,
        lights=lights,
        ambient=(0.05, 0.06, 0.08),
        occluders=(
            Box((-6.0, 5.0, -20.0), (-1.0, 6.0, -12.0)),
            Box((2.0, 4.0, -30.0), (7.0, 5.0, -26.0)),
        ),
    )


def camera_at(width: int, height: int) -> Camera:
    return Camera(
        eye=(0.0, 1.6, 2.0), target=(0.0, 1.8, -20.0), fov_y=55.0, width=width, height=height
    )


def scene_images(camera: Camera, device, dtype=torch.float32):
    """Depth (H, W) and opaque (H, W, 3): a ground plane y = 0 and a wall at z = -36 (sky
    above it)."""
    d = primary_rays(camera, device="cpu", dtype=F64).directions
    eye = torch.tensor(camera.eye, dtype=F64)
    fwd = torch.tensor(camera.target, dtype=F64) - eye
    fwd = fwd / fwd.norm()
    t_ground = torch.where(d[:, 1] < 0, -eye[1] / d[:, 1].clamp(max=-1e-9), math.inf)
    t_wall = torch.where(d[:, 2] < 0, (-36.0 - eye[2]) / d[:, 2].clamp(max=-1e-9), math.inf)
    p_wall = eye + t_wall.clamp(max=1e6)[:, None] * d
    t_wall = torch.where(p_wall[:, 1] < 8.0, t_wall, math.inf)
    t = torch.minimum(t_ground, t_wall)
    depth = (t * (d @ fwd)).reshape(camera.height, camera.width)
    colour = torch.where(
        (t_ground < t_wall)[:, None],
        torch.tensor([0.10, 0.09, 0.08], dtype=F64),
        torch.tensor([0.18, 0.16, 0.15], dtype=F64),
    )
    colour = torch.where(torch.isinf(t)[:, None], torch.zeros(3, dtype=F64), colour)
    return depth.to(device, dtype), colour.reshape(camera.height, camera.width, 3).to(device, dtype)


def prepare(device, quick: bool) -> dict:
    image = (48, 27) if quick else (192, 108)
    camera = camera_at(*image)
    depth, opaque = scene_images(camera, "cpu", F64)
    pixels = torch.arange(0, image[0] * image[1], 5 if quick else 23)
    scene_cpu = fog_scene("cpu")
    reference = reference_render(
        scene_cpu,
        camera,
        depth,
        opaque,
        near=NEAR,
        far=FAR,
        samples=48 if quick else 128,
        shadow_steps=8 if quick else 24,
        pixels=pixels,
    )["image"]
    depth, opaque = scene_images(camera, device)
    return {
        "device": device,
        "quick": quick,
        "repeats": 1 if quick else 3,
        "scene": fog_scene(device),
        "camera": camera,
        "depth": depth,
        "opaque": opaque,
        "pixels": pixels,
        "reference": reference.to(F64),
    }


def knobs(ctx: dict) -> list[dict]:
    quick = ctx["quick"]
    grid = [
        (t, s)
        for t in ((8, 16) if quick else (4, 8, 16))
        for s in ((16, 32) if quick else (32, 64, 128))
    ]
    rows = [{"setting": f"{t}px x {s}", "tile": t, "slices": s} for t, s in grid]
    rows.append(
        {
            "setting": "8px x 32 no vol. shadows",
            "tile": 8,
            "slices": 32,
            "volumetric_shadows": False,
        }
    )
    rows += [
        {"setting": f"8px x 32 temporal, frame {n}", "tile": 8, "slices": 32, "temporal_frames": n}
        for n in ((1, 4) if quick else (1, 8, 32))
    ]
    # The light-space volumes' resolution: the automatic one (None) costs most of a CPU
    # frame at the quick sizes, so --quick fixes it at 16 (a column of every row).
    for row in rows:
        row["volume_resolution"] = 16 if quick else None
    return rows


def image_error(image, ctx: dict) -> float:
    got = image.detach().to("cpu", F64).reshape(-1, 3)[ctx["pixels"]]
    want = ctx["reference"].reshape(-1, 3)
    return ((got - want).abs().mean() / want.abs().mean()).item()


def _options(knob: dict) -> dict:
    options = {
        "tile": knob["tile"],
        "slices": knob["slices"],
        "near": NEAR,
        "far": FAR,
        "volume_resolution": knob["volume_resolution"],
    }
    if "volumetric_shadows" in knob:
        options["volumetric_shadows"] = knob["volumetric_shadows"]
    return options


def measure(lab, ctx: dict, knob: dict) -> dict:
    args = (ctx["scene"], ctx["camera"], ctx["depth"], ctx["opaque"])
    options = _options(knob)
    if "temporal_frames" in knob:  # a static camera: the history accumulates jittered frames
        history = None
        for frame in range(knob["temporal_frames"] - 1):
            _, report = lab.render_froxels(
                *args, temporal=True, frame=frame, history=history, **options
            )
            history = report["history"]
        options.update(temporal=True, frame=knob["temporal_frames"] - 1, history=history)
    (image, report), seconds = timed(ctx, lab.render_froxels, *args, **options)
    return {
        "seconds": seconds,
        "error": image_error(image, ctx),
        "froxels": report.get("froxels"),
        "light_evaluations": report.get("light_evaluations"),
    }


def fused(ctx: dict) -> list[dict]:
    """The pipeline fused into five Triton kernels (not temporal)."""
    try:
        from course.kernels.triton_froxel import render_froxels_fused
        from course.kernels.triton_launch import triton_available
    except ImportError:
        return []
    if not triton_available():
        return []
    rows = []
    for knob in knobs(ctx):
        if "temporal_frames" in knob:
            continue
        (image, report), seconds = timed(
            ctx,
            render_froxels_fused,
            ctx["scene"],
            ctx["camera"],
            ctx["depth"],
            ctx["opaque"],
            **_options(knob),
        )
        rows.append(
            {
                **knob,
                "setting": f"fused {knob['setting']}",
                "seconds": seconds,
                "error": image_error(image, ctx),
                "froxels": report.get("froxels"),
            }
        )
    return rows
