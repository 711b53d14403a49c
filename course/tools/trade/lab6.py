"""Lab 6's trade: rasterized against ray-traced primary visibility.

Knobs: the lab's visibility buffer (``to_clip_space``, ``clip_triangles``, ``to_screen``,
``rasterize``, ids through ``source``) with 32-bit (float view depth) and 24-bit (unorm
window depth) keys and with a small fragment budget (many small chunks), against the lab's
``traced_visibility`` through ``course.kernels.trace.trace_bvh`` (one primary ray per
pixel, a binned-SAH BVH built once), on the same camera and mesh. ``bytes`` is the
fragment budget. Error: the fraction of covered pixels whose triangle differs from the
exact one (float64 brute-force primary rays through the pixel centres, course code). On
CUDA the fused visibility kernels (``course.kernels.triton_raster.visibility_fused``) add
rows.
"""

from __future__ import annotations

import dataclasses
import functools

import torch

from course.core.camera import primary_rays
from course.core.scenes import load_scene
from course.kernels.trace import trace_bvh
from course.tools.trade.common import F64, exact_hits, timed

MODULE = "lab6_raster"
TITLE = "compute rasterizer: raster against trace"
ERROR_NAME = "pixels differing from exact"
ERROR = (
    "fraction of covered pixels whose triangle differs from float64 brute-force primary "
    "rays (course code)"
)
BUDGET = 2**28


def prepare(device, quick: bool) -> dict:
    size = 48 if quick else (1024 if device.type == "cuda" else 192)
    scene = load_scene("suzanne", device=device)
    camera = dataclasses.replace(scene.camera, width=size, height=size)
    _, exact = exact_hits(primary_rays(camera, device="cpu", dtype=F64), scene.mesh)
    return {
        "device": device,
        "quick": quick,
        "repeats": 2 if quick else 5,
        "mesh": scene.mesh,
        "camera": camera,
        "exact": exact.reshape(size, size),
    }


def knobs(ctx: dict) -> list[dict]:
    return [
        {"setting": "raster 32-bit depth", "method": "raster", "depth_bits": 32, "bytes": BUDGET},
        {"setting": "raster 24-bit depth", "method": "raster", "depth_bits": 24, "bytes": BUDGET},
        {
            "setting": "raster 32-bit, budget 256 KiB",
            "method": "raster",
            "depth_bits": 32,
            "bytes": 2**18,
        },
        {"setting": "trace (BVH)", "method": "trace"},
    ]


def raster_ids(lab, mesh, camera, depth_bits: int, memory_budget_bytes: int) -> torch.Tensor:
    """(H, W) source-face ids of the lab's visibility buffer (-1: empty)."""
    mvp = camera.view_projection(torch.float64).to(mesh.device)
    clip = lab.to_clip_space(mesh.vertices, mvp)
    clipped, source, _ = lab.clip_triangles(clip[mesh.faces])
    screen = lab.to_screen(clipped, camera.width, camera.height)
    keys = lab.rasterize(
        screen,
        camera.width,
        camera.height,
        depth_bits=depth_bits,
        memory_budget_bytes=memory_budget_bytes,
    )
    k = lab.triangle_ids(keys)
    ids = torch.where(k >= 0, source[k.clamp(min=0)], -1) if len(source) else k
    return ids.reshape(camera.height, camera.width)


def pixel_error(ids, ctx: dict) -> float:
    ids = ids.detach().cpu().reshape(ctx["exact"].shape)
    exact = ctx["exact"]
    covered = (ids >= 0) | (exact >= 0)
    return ((ids != exact) & covered).double().sum().item() / max(1, int(covered.sum()))


def measure(lab, ctx: dict, knob: dict) -> dict:
    mesh, camera = ctx["mesh"], ctx["camera"]
    if knob["method"] == "trace":
        trace = functools.partial(trace_bvh, mesh)  # its BVH: built in the untimed call
        ids, seconds = timed(ctx, lab.traced_visibility, trace, camera, ctx["device"])
    else:
        ids, seconds = timed(ctx, raster_ids, lab, mesh, camera, knob["depth_bits"], knob["bytes"])
    return {
        "seconds": seconds,
        "error": pixel_error(ids, ctx),
        "pixels": camera.width * camera.height,
        "triangles": mesh.num_faces,
    }


def fused(ctx: dict) -> list[dict]:
    """The fused visibility: MVP, clipping, viewport and raster in four Triton kernels."""
    try:
        from course.kernels.triton_launch import triton_available
        from course.kernels.triton_raster import visibility_fused
    except ImportError:
        return []
    if not triton_available():
        return []
    mesh, camera = ctx["mesh"], ctx["camera"]
    mvp = camera.view_projection(torch.float64)
    rows = []
    for bits in (32, 24):
        ids, seconds = timed(
            ctx,
            visibility_fused,
            mesh.vertices,
            mesh.faces,
            mvp,
            camera.width,
            camera.height,
            depth_bits=bits,
        )
        rows.append(
            {
                "setting": f"fused raster {bits}-bit depth",
                "method": "raster",
                "depth_bits": bits,
                "seconds": seconds,
                "error": pixel_error(ids, ctx),
                "pixels": camera.width * camera.height,
                "triangles": mesh.num_faces,
            }
        )
    return rows
