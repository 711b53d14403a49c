"""Lab 2's sync-free walk compiled: the reference's ``torch.compile`` paths find what its
eager path finds, with the same counters.

Not shipped to students (it runs ``solutions/``): the graders call the eager path, since a
compile takes tens of seconds. Here, on the CPU: one step per compiled call (closest hits)
and two fused per call (any hit, a look every 5 steps, so the last call of a look runs
past it); with CUDA also the CUDA-graph path (``compile="reduce-overhead"``), compacting.
"""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import torch

REPO = Path(__file__).resolve().parents[2]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

from course.core.camera import primary_rays
from course.core.scenes import load_scene
from course.core.types import Rays
from course.given.lab2 import pack_bvh
from course.grading.testing import assert_equal
from solutions import lab2_accel as lab


def suzanne_rays(device):
    """24 x 24 camera rays at Suzanne, and axis-parallel rays (+-0.0 components) through it."""
    scene = load_scene("suzanne", device=device)
    rays = primary_rays(dataclasses.replace(scene.camera, width=24, height=24), device=device)
    lo, hi = scene.mesh.vertices.amin(0), scene.mesh.vertices.amax(0)
    t = torch.linspace(0.05, 0.95, 8, device=device)
    origins, directions = [], []
    for axis in range(3):
        o = lo + (hi - lo) * torch.stack((t, t.flip(0), t.roll(3)), 1)
        o[:, axis] = lo[axis] - 1
        d = torch.tensor([0.0, -0.0, 0.0], device=device).expand(8, 3).clone()
        d[:, axis] = 1.0
        origins.append(o)
        directions.append(d)
    axis_rays = Rays.create(torch.cat(origins), torch.cat(directions))
    return scene.mesh, Rays.create(
        torch.cat((rays.origins, axis_rays.origins)),
        torch.cat((rays.directions, axis_rays.directions)),
    )


def test_compiled_walk_matches_eager(device):  # device: cpu, and cuda where present
    mesh, rays = suzanne_rays(device)
    bvh = lab.build_sah_bvh(mesh)
    walk = pack_bvh(bvh, mesh)
    settings = [
        {"compile": True, "check_every": 3},
        {"compile": True, "check_every": 5, "fuse_steps": 2, "any_hit": True},
    ]
    if torch.device(device).type == "cuda":
        settings.append({"compile": "reduce-overhead", "check_every": 4})
    for knobs in settings:
        eager = {k: v for k, v in knobs.items() if k in ("check_every", "any_hit")}
        ref_hits, ref = lab.bvh_closest_hit_fast(rays, mesh, bvh, walk=walk, **eager)
        hits, count = lab.bvh_closest_hit_fast(rays, mesh, bvh, walk=walk, **knobs)
        assert int((ref_hits.triangle >= 0).sum()) > 50, "the rays should hit Suzanne"
        for key in ("steps", "tests"):
            assert_equal(
                count[key].cpu(),
                ref[key].cpu(),
                where="ray",
                name=f"bvh_closest_hit_fast({knobs}): counters[{key!r}] against eager",
            )
        assert_equal(
            hits.triangle.cpu(),
            ref_hits.triangle.cpu(),
            where="ray",
            name=f"bvh_closest_hit_fast({knobs}): triangles against eager",
        )
        torch.testing.assert_close(hits.t, ref_hits.t, rtol=1e-5, atol=0.0)
