"""Lab 1's trade: the triangle tests and their precision.

Knobs: every intersection variant of ``closest_hit`` (simple, Möller–Trumbore, Woop's unit
test, the watertight test) in fp16, bf16, fp32 and fp64, brute force over a random soup.
Error: the fraction of rays whose hit is not the exact one (float64 brute force, course
code: hit/miss, or another triangle at another distance). On CUDA the fused Triton
Möller–Trumbore (``course.kernels.triton_intersect``) adds a row.
"""

from __future__ import annotations

import torch

from course.core.scenes import load_scene
from course.core.types import Rays
from course.given.lab1 import VARIANTS
from course.tools.trade.common import F64, exact_hits, hit_disagreement, timed

MODULE = "lab1_intersect"
TITLE = "ray/triangle intersection: variant and precision"
ERROR_NAME = "hits differing from exact"
ERROR = "fraction of rays whose closest hit differs from float64 brute force (course code)"
DTYPES = {
    "fp16": torch.float16,
    "bf16": torch.bfloat16,
    "fp32": torch.float32,
    "fp64": torch.float64,
}


def soup_rays(n: int, seed: int = 1) -> Rays:
    """Rays from a sphere of radius 2 around the unit cube, aimed at random points in it."""
    g = torch.Generator().manual_seed(seed)
    target = torch.rand(n, 3, dtype=F64, generator=g)
    out = torch.randn(n, 3, dtype=F64, generator=g)
    origins = 0.5 + 2.0 * out / out.norm(dim=1, keepdim=True)
    return Rays.create(origins, target - origins)


def prepare(device, quick: bool) -> dict:
    cuda = device.type == "cuda"
    rays, tris = (256, 64) if quick else ((65536, 2048) if cuda else (2048, 512))
    soup = load_scene("random_soup", n=tris, seed=0, device="cpu", dtype=F64).mesh
    ray_batch = soup_rays(rays)
    t, triangle = exact_hits(ray_batch, soup)
    return {
        "device": device,
        "quick": quick,
        "repeats": 2 if quick else 5,
        "soup": soup,
        "rays": ray_batch,
        "exact": (t, triangle),
        "pairs": rays * tris,
    }


def knobs(ctx: dict) -> list[dict]:
    return [
        {"setting": f"{variant} {name}", "variant": variant, "dtype": name}
        for variant in VARIANTS
        for name in DTYPES
    ]


def measure(lab, ctx: dict, knob: dict) -> dict:
    dtype = DTYPES[knob["dtype"]]
    rays, mesh = ctx["rays"].to(ctx["device"], dtype), ctx["soup"].to(ctx["device"], dtype)
    budget = {"memory_budget_bytes": ctx["memory"]} if ctx.get("memory") else {}
    hits, seconds = timed(ctx, lab.closest_hit, rays, mesh, variant=knob["variant"], **budget)
    return {
        "seconds": seconds,
        "error": hit_disagreement(hits.t, hits.triangle, *ctx["exact"]),
        "tests": ctx["pairs"],
        "hits": hits,
    }


def fused(ctx: dict) -> list[dict]:
    """The Triton Möller–Trumbore brute force (fp32, one launch)."""
    try:
        from course.kernels import triton_intersect as ti
        from course.kernels.triton_launch import triton_available
    except ImportError:
        return []
    if not triton_available():
        return []
    rays = ctx["rays"].to(ctx["device"], torch.float32)
    layout = ti.mt_layout(ctx["soup"].to(ctx["device"], torch.float32).triangles())
    (t, index, _, _), seconds = timed(
        ctx, ti.mt_closest_hit_triton, rays.origins, rays.directions, layout, rays.t_min, rays.t_max
    )
    return [
        {
            "setting": "fused moller_trumbore fp32",
            "variant": "triton_mt",
            "dtype": "fp32",
            "seconds": seconds,
            "error": hit_disagreement(t, index, *ctx["exact"]),
            "tests": ctx["pairs"],
        }
    ]
