"""Lab 2's sync-free walk on its CUDA-graph path (``compile="reduce-overhead"``), emulated
on the CPU: the graph class is swapped for one that runs the eager steps in place on its
own buffers when "replayed", and counts are read one look late as on a GPU. So the path's
buffer handling (rays written into a graph's buffers, compactions gathered into the next
graph's, padding columns, write-backs), its lagged looks and its graph cache run here,
and must find what the eager walk finds, with the same counters.

Not shipped to students (it runs ``solutions/``). ``test_lab2_graph_cache.py`` runs the
real graphs on CUDA.
"""

from __future__ import annotations

import collections
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
from solutions import lab2_accel as lab


class EagerGraph:
    """A stand-in for ``_StepGraph``: the same buffers and count, stepped eagerly."""

    made = 0

    def __init__(self, steps, size, dtype, device, args, calls, replays=1):
        EagerGraph.made += 1
        self.size, self.args, self.runs = size, args, calls * replays
        self.floats, self.ints = lab._new_buffers(size, dtype, device, args[1])
        self.count = torch.zeros((), dtype=torch.int64, device=device)

    def run(self):
        for _ in range(self.runs):  # eager, not the compiled steps: no compile here
            lab._fast_steps(self.floats, self.ints, *self.args)
        self.count.copy_((self.ints[lab._NODE] < self.args[1]).sum())
        return self.count


@pytest.fixture
def emulated(monkeypatch):
    monkeypatch.setattr(lab, "_StepGraph", EagerGraph)
    monkeypatch.setattr(lab, "_GRAPH_DEVICES", ("cuda", "cpu"))
    monkeypatch.setattr(lab, "_GRAPHS", collections.OrderedDict())
    monkeypatch.setitem(lab._LAG, "cpu", 1)
    looks = []
    put = lab._Looks.put
    monkeypatch.setattr(lab._Looks, "put", lambda self, count: (looks.append(int(count)),
                                                                put(self, count))[1])
    return looks


def test_graph_path_matches_eager(emulated):
    scene = load_scene("suzanne")
    mesh = scene.mesh
    bvh = lab.build_sah_bvh(mesh)
    walk = pack_bvh(bvh, mesh)
    camera = dataclasses.replace(scene.camera, width=40, height=40)
    moved = dataclasses.replace(camera, eye=tuple(t + 1.3 * (e - t) for e, t in
                                                  zip(camera.eye, camera.target)))
    for cam, any_hit, k in ((camera, False, 4), (camera, False, 4), (moved, False, 3),
                            (camera, True, 4)):
        rays = primary_rays(cam)
        # Rays that hit first, so that a padding column written to a real ray's output
        # shows; the reference on the camera's order (its first ray misses), then sorted.
        first, _ = lab.bvh_closest_hit_fast(rays, mesh, bvh, walk=walk)
        order = torch.argsort((first.triangle < 0).int(), stable=True)
        ref_hits, ref = lab.bvh_closest_hit_fast(rays, mesh, bvh, walk=walk, check_every=k,
                                                 any_hit=any_hit, compact=False)
        rays, ref_hits = rays[order], ref_hits[order]
        ref = {key: value[order] for key, value in ref.items()}
        assert int((ref_hits.triangle >= 0).sum()) > 150, "the rays should hit Suzanne"
        for packed in (walk, None):
            made, emulated[:] = EagerGraph.made, []
            hits, count = lab.bvh_closest_hit_fast(rays, mesh, bvh, walk=packed,
                                                   check_every=k, any_hit=any_hit,
                                                   compile="reduce-overhead")
            what = f"emulated graphs (any_hit={any_hit}, k={k}, walk={packed is not None})"
            for key in ("steps", "tests"):
                assert_equal(count[key], ref[key], where="ray",
                             name=f"{what}: counters[{key!r}] against eager")
            assert_equal(hits.triangle, ref_hits.triangle, where="ray",
                         name=f"{what}: triangles against eager")
            for name in ("t", "u", "v"):
                assert_equal(getattr(hits, name), getattr(ref_hits, name), where="ray",
                             name=f"{what}: {name} against eager")
            # Lagged: the look after the one whose count read 0 ran too (and changed nothing).
            assert emulated[-1] == 0 and emulated[-2] == 0, f"{what}: looks {emulated}"
            assert emulated.count(0) == 2, f"{what}: stopped late: {emulated}"
            compactions = EagerGraph.made - made - 1
            assert compactions >= 1 or packed is not None, f"{what}: never compacted"
    assert len(lab._GRAPHS) > 1, "the cached path should have compacted into other sizes"


def test_cached_graphs_are_reused(emulated):
    scene = load_scene("suzanne")
    mesh = scene.mesh
    bvh = lab.build_sah_bvh(mesh)
    walk = pack_bvh(bvh, mesh)
    rays = primary_rays(dataclasses.replace(scene.camera, width=48, height=48))
    first = lab.bvh_closest_hit_fast(rays, mesh, bvh, walk=walk, compile="reduce-overhead")
    made, cached = EagerGraph.made, len(lab._GRAPHS)
    # Other rays of the same sizes reuse the buffers: stale rays there must not leak.
    again = lab.bvh_closest_hit_fast(rays, mesh, bvh, walk=walk, compile="reduce-overhead")
    assert EagerGraph.made == made and len(lab._GRAPHS) == cached, (
        "a second traversal of the same rays made new graphs")
    for a, b in ((first[0].triangle, again[0].triangle), (first[1]["steps"], again[1]["steps"])):
        assert_equal(b, a, where="ray", name="second traversal against the first")
    half = rays[torch.arange(0, len(rays), 2)]
    hits, count = lab.bvh_closest_hit_fast(half, mesh, bvh, walk=walk, compile="reduce-overhead")
    ref_hits, ref = lab.bvh_closest_hit_fast(half, mesh, bvh, walk=walk)
    assert_equal(hits.triangle, ref_hits.triangle, where="ray", name="half the rays, cached")
    assert_equal(count["tests"], ref["tests"], where="ray", name="half the rays, cached")
