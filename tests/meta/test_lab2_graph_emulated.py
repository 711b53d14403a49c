"""Lab 2's sync-free walk on its CUDA-graph path (``compile="reduce-overhead"``), emulated
on the CPU: the graph class is swapped for one that keeps the same buffers and, when
"replayed", runs the eager steps in place on them. So the path's buffer handling (rays
gathered into a graph's buffers with padding, copied in at each look, compactions,
write-backs) and its graph cache run here, and must find exactly what the eager walk
finds, with the same counters.

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
from solutions.lab2_accel import build_sah_bvh
from solutions.lab2_accel import fast as lab  # the walk and its private graph cache


class _Replay:
    def __init__(self, replay):
        self.replay = replay


class EagerGraph(lab._StepGraph):
    """``_StepGraph`` with its buffers and its ``run``, the capture replaced by eager steps
    in place on the buffers."""

    made = 0

    def __init__(self, steps, fixed, state, args, calls: int):
        EagerGraph.made += 1
        self.fixed, self.state = lab._own(fixed, state)
        self.args = args
        self.count = torch.zeros((), dtype=torch.int64)

        def replay():
            for _ in range(calls):
                lab._fast_steps_in_place(self.fixed, self.state, *args)
            self.count.copy_((self.state[0] < args[1]).sum())

        self.graph = _Replay(replay)


class EagerStartGraph(lab._StartGraph):
    """``_StartGraph`` with its buffers and its ``run``, the capture replaced by an eager
    ``_start`` writing into the same output tensors at each "replay"."""

    made = 0

    def __init__(self, inputs, tables):
        EagerStartGraph.made += 1
        self.inputs = [x.clone() for x in inputs]
        self.outputs = lab._start(*self.inputs, *tables)

        def replay():
            for mine, new in zip(self.outputs, lab._start(*self.inputs, *tables)):
                mine.copy_(new)

        self.graph = _Replay(replay)


@pytest.fixture
def emulated(monkeypatch):
    monkeypatch.setattr(lab, "_StepGraph", EagerGraph)
    monkeypatch.setattr(lab, "_StartGraph", EagerStartGraph)
    monkeypatch.setattr(lab, "_GRAPH_DEVICES", ("cuda", "cpu"))
    monkeypatch.setattr(lab, "_GRAPHS", collections.OrderedDict())
    # Compactions at these few rays too (on a GPU they start from 65,536 rays).
    monkeypatch.setattr(lab, "_GRAPH_COMPACT_FROM", 0)
    # No compile here: the path's buffers are what is tested, not inductor.
    monkeypatch.setattr(lab, "_compiled_fast_steps", lambda mode: lab._fast_steps_in_place)


def _suzanne(size: int):
    scene = load_scene("suzanne")
    mesh = scene.mesh
    bvh = build_sah_bvh(mesh)
    return mesh, bvh, dataclasses.replace(scene.camera, width=size, height=size)


def test_graph_path_matches_eager(emulated):
    mesh, bvh, camera = _suzanne(40)
    walk = pack_bvh(bvh, mesh)
    moved = dataclasses.replace(
        camera, eye=tuple(t + 1.3 * (e - t) for e, t in zip(camera.eye, camera.target))
    )
    for cam, any_hit, k in ((camera, False, 4), (moved, False, 3), (camera, True, 4)):
        rays = primary_rays(cam)
        # Rays that hit first, so that a padding column written to a real ray's output
        # would show.
        first, _ = lab.bvh_closest_hit_fast(rays, mesh, bvh, walk=walk)
        rays = rays[torch.argsort((first.triangle < 0).int(), stable=True)]
        ref_hits, ref = lab.bvh_closest_hit_fast(
            rays, mesh, bvh, walk=walk, check_every=k, any_hit=any_hit
        )
        assert int((ref_hits.triangle >= 0).sum()) > 150, "the rays should hit Suzanne"
        for packed in (walk, None):
            made = EagerGraph.made
            hits, count = lab.bvh_closest_hit_fast(
                rays,
                mesh,
                bvh,
                walk=packed,
                check_every=k,
                any_hit=any_hit,
                compile="reduce-overhead",
            )
            what = f"emulated graphs (any_hit={any_hit}, k={k}, walk={packed is not None})"
            for key in ("steps", "tests"):
                assert_equal(
                    count[key],
                    ref[key],
                    where="ray",
                    name=f"{what}: counters[{key!r}] against eager",
                )
            assert_equal(
                hits.triangle,
                ref_hits.triangle,
                where="ray",
                name=f"{what}: triangles against eager",
            )
            for name in ("t", "u", "v"):
                assert_equal(
                    getattr(hits, name),
                    getattr(ref_hits, name),
                    where="ray",
                    name=f"{what}: {name} against eager",
                )
            assert EagerGraph.made - made >= 2, f"{what}: never compacted into a new graph"
    assert len(lab._GRAPHS) > 1, "the cached path should have compacted into other sizes"


def test_cached_graphs_are_reused(emulated):
    mesh, bvh, camera = _suzanne(48)
    walk = pack_bvh(bvh, mesh)
    rays = primary_rays(camera)
    first = lab.bvh_closest_hit_fast(rays, mesh, bvh, walk=walk, compile="reduce-overhead")
    made, started, cached = EagerGraph.made, EagerStartGraph.made, len(lab._GRAPHS)
    again = lab.bvh_closest_hit_fast(rays, mesh, bvh, walk=walk, compile="reduce-overhead")
    assert (EagerGraph.made, EagerStartGraph.made, len(lab._GRAPHS)) == (made, started, cached), (
        "a second traversal of the same rays made new graphs"
    )
    for a, b in ((first[0].triangle, again[0].triangle), (first[1]["steps"], again[1]["steps"])):
        assert_equal(b, a, where="ray", name="second traversal against the first")
    # Other rays in buffers a traversal left behind: nothing stale may leak into them.
    half = rays[torch.arange(0, len(rays), 2)]
    want, _ = lab.bvh_closest_hit_fast(half, mesh, bvh, walk=walk)
    got, _ = lab.bvh_closest_hit_fast(half, mesh, bvh, walk=walk, compile="reduce-overhead")
    assert_equal(got.triangle, want.triangle, where="ray", name="half the rays, graph path")
    assert_equal(got.t, want.t, where="ray", name="half the rays' t, graph path")
    # The start graph's buffers are the same for every traversal of as many rays: results
    # handed out before must not change when the next traversal replays it.
    moved = dataclasses.replace(
        camera, eye=tuple(t + 1.5 * (e - t) for e, t in zip(camera.eye, camera.target))
    )
    other = primary_rays(moved)
    started = EagerStartGraph.made
    later, _ = lab.bvh_closest_hit_fast(other, mesh, bvh, walk=walk, compile="reduce-overhead")
    assert EagerStartGraph.made == started, "as many rays again: the start graph is kept"
    assert not torch.equal(later.t, again[0].t), "the other camera should see other hits"
    assert_equal(
        again[0].triangle,
        first[0].triangle,
        where="ray",
        name="earlier results after another traversal replayed the start graph",
    )
    assert_equal(
        again[0].t,
        first[0].t,
        where="ray",
        name="earlier t after another traversal replayed the start graph",
    )


def test_graphs_compact_only_from_the_floor(emulated, monkeypatch):
    mesh, bvh, camera = _suzanne(40)
    walk = pack_bvh(bvh, mesh)
    rays = primary_rays(camera)
    want, count = lab.bvh_closest_hit_fast(rays, mesh, bvh, walk=walk, check_every=4)
    started = int(((count["steps"] + count["tests"]) > 0).sum())  # rays entering the root box
    for floor, compacts in ((started, True), (started + 1, False)):
        monkeypatch.setattr(lab, "_GRAPH_COMPACT_FROM", floor)
        monkeypatch.setattr(lab, "_GRAPHS", collections.OrderedDict())
        made = EagerGraph.made
        got, _ = lab.bvh_closest_hit_fast(
            rays, mesh, bvh, walk=walk, check_every=4, compile="reduce-overhead"
        )
        assert (EagerGraph.made - made >= 2) == compacts, (
            f"{started} rays started, compactions from {floor} rays: expected "
            f"{'a compaction' if compacts else 'none'}, made {EagerGraph.made - made} graphs"
        )
        assert_equal(
            got.triangle,
            want.triangle,
            where="ray",
            name=f"compactions from {floor} rays: triangles against eager",
        )
