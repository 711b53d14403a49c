"""Lab 2's trade: acceleration structures and their parameters.

Knobs: brute force, the uniform grid at densities 1, 2 and 4 (cells per triangle), the
two-level grid, LBVH, the binned-SAH BVH at leaf sizes 2, 4 and 8, and the SAH kd-tree,
each built once and traced with the lab's ``closest_hit`` on primary rays of a scene (the
triangle test is the given float32 Möller–Trumbore, so no Lab 1 is needed). ``seconds`` is
the trace (the build's time is ``build_s``); ``steps``, ``tests`` (per ray) and ``bytes``
are the structure's work and memory. Error: the fraction of rays whose hit differs from
the exact one (float64 brute force, course code). On CUDA the fused BVH tracer
(``course.kernels.trace.trace_bvh``) adds a row.
"""

from __future__ import annotations

import dataclasses
import time

import torch

from course.core.camera import primary_rays
from course.core.raymath import masked_result
from course.core.scenes import load_scene
from course.given.lab2 import moller_trumbore_rows
from course.tools.trade.common import F64, exact_hits, hit_disagreement, timed

MODULE = "lab2_accel"
TITLE = "acceleration structures: kind and parameters"
ERROR_NAME = "hits differing from exact"
ERROR = "fraction of rays whose closest hit differs from float64 brute force (course code)"
STRUCTURES = [  # (label, kind, build knobs); kind None: brute force
    ("brute force", None, {}),
    ("grid density 1", "grid", {"density": 1.0}),
    ("grid density 2", "grid", {"density": 2.0}),
    ("grid density 4", "grid", {"density": 4.0}),
    ("two-level grid", "grid2", {}),
    ("LBVH", "bvh", {"method": "lbvh"}),
    ("SAH BVH leaf 2", "bvh", {"method": "sah", "leaf_size": 2}),
    ("SAH BVH leaf 4", "bvh", {"method": "sah", "leaf_size": 4}),
    ("SAH BVH leaf 8", "bvh", {"method": "sah", "leaf_size": 8}),
    ("kd-tree (SAH)", "kd", {}),
]


def intersect(origins, directions, v0, v1, v2, t_min, t_max):
    """The triangle kernel the structures call: Lab 1's Möller–Trumbore (given code)."""
    t, u, v, hit = moller_trumbore_rows(origins, directions, v0, v1 - v0, v2 - v0, t_min, t_max)
    return masked_result(hit, t, u, v)


def prepare(device, quick: bool) -> dict:
    size = 20 if quick else (256 if device.type == "cuda" else 64)
    scene = load_scene("suzanne", device=device)
    camera = dataclasses.replace(scene.camera, width=size, height=size)
    rays = primary_rays(camera, device=device)
    exact = exact_hits(primary_rays(camera, device="cpu", dtype=F64), scene.mesh)
    return {
        "device": device,
        "quick": quick,
        "repeats": 1 if quick else 3,
        "mesh": scene.mesh,
        "rays": rays,
        "exact": exact,
    }


def knobs(ctx: dict) -> list[dict]:
    return [
        {"setting": label, "structure": kind or "none", **params}
        for label, kind, params in STRUCTURES
    ]


def _nbytes(structure) -> int:
    return sum(
        x.numel() * x.element_size() for x in structure.values() if isinstance(x, torch.Tensor)
    )


def measure(lab, ctx: dict, knob: dict) -> dict:
    label, kind, params = next(s for s in STRUCTURES if s[0] == knob["setting"])
    mesh, rays = ctx["mesh"], ctx["rays"]
    if kind is None:
        (hits, counters), seconds = timed(ctx, lab.brute_force_closest_hit, rays, mesh, intersect)
        build_s, nbytes = 0.0, 0
    else:
        start = time.perf_counter()
        structure = lab.build(mesh, kind, **params)
        build_s = time.perf_counter() - start
        (hits, counters), seconds = timed(ctx, lab.closest_hit, rays, mesh, structure, intersect)
        nbytes = _nbytes(structure)
    return {
        "seconds": seconds,
        "error": hit_disagreement(hits.t, hits.triangle, *ctx["exact"]),
        "build_s": build_s,
        "steps": counters["steps"].double().mean().item(),
        "tests": counters["tests"].double().mean().item(),
        "bytes": nbytes,
        "rays": len(rays),
    }


def fused(ctx: dict) -> list[dict]:
    """``course.kernels.trace.trace_bvh``: a flattened binned-SAH BVH, Triton traversal."""
    from course.kernels.trace import trace_bvh

    rays, mesh = ctx["rays"], ctx["mesh"]
    hits, seconds = timed(
        ctx, trace_bvh, mesh, rays.origins, rays.directions, rays.t_min, rays.t_max
    )
    t, triangle = (hits.t, hits.triangle) if hasattr(hits, "t") else hits[:2]
    return [
        {
            "setting": "fused BVH (trace_bvh)",
            "structure": "flat bvh",
            "seconds": seconds,
            "error": hit_disagreement(t, triangle, *ctx["exact"]),
            "rays": len(rays),
        }
    ]
