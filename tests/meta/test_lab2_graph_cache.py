"""Lab 2's sync-free walk replayed from cached CUDA graphs (``compile="reduce-overhead"``):
a graph captured for one size is reused by later traversals of that size, with other rays
too, and every traversal finds what the eager walk finds, with the same counters; a walk
packed inside the call gets graphs of one call that are not kept.

CUDA only (skipped elsewhere); not shipped to students (it runs ``solutions/``).
"""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import pytest
import torch

REPO = Path(__file__).resolve().parents[2]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

from course.core.camera import primary_rays
from course.core.scenes import load_scene
from course.given.lab2 import pack_bvh
from course.grading.testing import assert_equal
from solutions.lab2_accel import build_sah_bvh
from solutions.lab2_accel import fast as lab  # the walk and its private graph cache

pytestmark = pytest.mark.skipif(not torch.cuda.is_available(), reason="CUDA graphs need CUDA")


def test_cached_graphs_match_eager():
    scene = load_scene("bunny", device="cuda")
    mesh = scene.mesh
    bvh = build_sah_bvh(mesh)
    walk = pack_bvh(bvh, mesh)
    camera = dataclasses.replace(scene.camera, width=96, height=96)
    moved = dataclasses.replace(
        camera, eye=tuple(t + 1.05 * (e - t) for e, t in zip(camera.eye, camera.target))
    )
    lab._GRAPHS.clear()
    sizes = []
    for cam, any_hit in ((camera, False), (camera, False), (moved, False), (camera, True)):
        rays = primary_rays(cam, device="cuda")
        ref_hits, ref = lab.bvh_closest_hit_fast(
            rays, mesh, bvh, walk=walk, check_every=8, any_hit=any_hit
        )
        hits, count = lab.bvh_closest_hit_fast(
            rays, mesh, bvh, walk=walk, check_every=8, any_hit=any_hit, compile="reduce-overhead"
        )
        what = f"graphs (any_hit={any_hit}, call {len(sizes) + 1})"
        assert int((ref_hits.triangle >= 0).sum()) > 1000, "the rays should hit the bunny"
        # The compiled step fuses its arithmetic, so a ray grazing an edge may pick the
        # neighbour (5 in 1M on the bench's rays): allow 1 in 1000, judge the rest exactly.
        if any_hit:
            same = (hits.triangle >= 0) == (ref_hits.triangle >= 0)
        else:
            same = hits.triangle == ref_hits.triangle
        assert int((~same).sum()) <= len(rays) // 1000, (
            f"{what}: {int((~same).sum())} of {len(rays)} rays differ from the eager walk"
        )
        for key in ("steps", "tests"):
            assert_equal(
                count[key][same].cpu(),
                ref[key][same].cpu(),
                where="ray",
                name=f"{what}: counters[{key!r}] against eager",
            )
        if not any_hit:
            torch.testing.assert_close(hits.t[same], ref_hits.t[same], rtol=1e-5, atol=0.0)
        sizes.append(len(lab._GRAPHS))
        if len(sizes) == 1:  # packed inside the call: graphs of one call, none kept
            fresh, _ = lab.bvh_closest_hit_fast(
                rays, mesh, bvh, check_every=8, compile="reduce-overhead"
            )
            differ = int((fresh.triangle != ref_hits.triangle).sum())
            assert differ <= len(rays) // 1000, f"graphs, packed per call: {differ} rays differ"
            assert len(lab._GRAPHS) == sizes[0], "graphs of a walk packed per call were kept"
    assert sizes[1] == sizes[0], (
        f"the second traversal of the same rays captured new graphs (cached graphs per call: "
        f"{sizes}): a warm traversal must reuse the sizes of the first"
    )
