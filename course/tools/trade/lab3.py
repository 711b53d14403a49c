"""Lab 3's trade: how the Whitted tracer is organised.

Knobs: the full-size loop (``render_whitted``), the wavefront renderer (separate stages over
compacted queues; also sorted by material), the uber kernel (fixed lanes, every shadow lane
traced) and the persistent pool at N/4 and N slots, on the Cornell box with a mirror box,
primary rays, shadow rays to every light and up to two reflections; the tracer they are
given is ``course.kernels.trace.trace_bvh``. ``lanes`` counts the closest-hit and shadow
lanes the persistent pool traced, where the lab reports it. Error: the mean relative error
of the image against ``course.given.lab3.render_reference`` (float64 brute force) on
sampled pixels. On CUDA the Triton uber kernel (``render_whitted_triton``) adds a row.
"""

from __future__ import annotations

import torch

from course.core.camera import primary_rays
from course.given.lab3 import MAX_DEPTH, render_reference, whitted_camera, whitted_scene
from course.kernels.trace import trace_bvh
from course.tools.trade.common import F64, timed

MODULE = "lab3_wavefront"
TITLE = "organising the tracer: loop, wavefront, uber, persistent"
ERROR_NAME = "mean relative image error"
ERROR = (
    "mean relative error of the image against render_reference (float64 brute force) "
    "on sampled pixels"
)
SCENE = "cornell_mirror"


def prepare(device, quick: bool) -> dict:
    size = 12 if quick else (512 if device.type == "cuda" else 32)
    scene = whitted_scene(SCENE, device=device)
    rays = primary_rays(whitted_camera(SCENE, size, size), device=device)
    g = torch.Generator().manual_seed(0)
    sample = torch.randperm(len(rays), generator=g)[: min(len(rays), 64 if quick else 256)]
    sample = sample.to(device)
    reference = (
        render_reference(scene, rays.origins[sample], rays.directions[sample], MAX_DEPTH)
        .detach()
        .to("cpu", F64)
    )
    return {
        "device": device,
        "quick": quick,
        "repeats": 1 if quick else 3,
        "scene": scene,
        "origins": rays.origins,
        "directions": rays.directions,
        "sample": sample,
        "reference": reference,
    }


def knobs(ctx: dict) -> list[dict]:
    n = len(ctx["origins"])
    rows = [
        {"setting": "whitted (full-size loop)", "renderer": "render_whitted"},
        {"setting": "wavefront", "renderer": "render_wavefront"},
        {"setting": "wavefront sorted", "renderer": "render_wavefront", "sort_by_material": True},
        {"setting": "uber (eager)", "renderer": "render_uber"},
    ]
    rows += [
        {"setting": f"persistent pool {pool}", "renderer": "render_persistent", "pool_size": pool}
        for pool in sorted({max(1, n // 4), n})
    ]
    return rows


def image_error(image, ctx: dict) -> float:
    got = image[ctx["sample"]].detach().to("cpu", F64)
    want = ctx["reference"]
    return ((got - want).abs() / want.abs().clamp(min=1e-3)).mean().item()


def measure(lab, ctx: dict, knob: dict) -> dict:
    options = {k: v for k, v in knob.items() if k not in ("setting", "renderer")}
    render = getattr(lab, knob["renderer"])
    out, seconds = timed(
        ctx,
        render,
        ctx["scene"],
        ctx["origins"],
        ctx["directions"],
        trace_bvh,
        MAX_DEPTH,
        **options,
    )
    image, extra = out if isinstance(out, tuple) else (out, {})
    row = {"seconds": seconds, "error": image_error(image, ctx), "pixels": len(ctx["origins"])}
    if knob["renderer"] == "render_persistent" and isinstance(extra, dict):
        row["lanes"] = extra.get("work_processed", 0) + extra.get("shadow_rays", 0)
    return row


def fused(ctx: dict) -> list[dict]:
    """The Triton uber kernel: traversal and shading in one launch."""
    try:
        from course.kernels.triton_tracer import render_whitted_triton, triton_available
    except ImportError:
        return []
    if not triton_available():
        return []
    image, seconds = timed(
        ctx, render_whitted_triton, ctx["scene"], ctx["origins"], ctx["directions"], MAX_DEPTH
    )
    return [
        {
            "setting": "fused uber (Triton)",
            "renderer": "render_whitted_triton",
            "seconds": seconds,
            "error": image_error(image, ctx),
            "pixels": len(ctx["origins"]),
        }
    ]
