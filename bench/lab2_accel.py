"""Lab 2 benchmark: what each acceleration structure, and each knob of the fast traversal,
costs and buys, against brute force (and, on the CPU, trimesh) in the same run.

    python bench/lab2_accel.py --small                  # CPU, a few minutes
    python bench/lab2_accel.py --device cuda            # GPU, a few minutes on an H100
    python bench/lab2_accel.py --device cpu --threads 2 --scenes bunny --fast-size 256
    python bench/lab2_accel.py --device cuda --headline  # LBVH build + traversal rows, ~2 min
    python bench/lab2_accel.py --device cpu --parts embree  # Embree against the walks, CPU
    python bench/lab2_accel.py --small --impl labs      # your labs/ (the handout's default)

Parts, each a table of the same ResultTable (column ``part``):

* ``trade``: the rows of ``rtcourse bench --lab 2`` (``course.tools.trade.lab2``: brute
  force, grid densities, the two-level grid, LBVH, SAH leaf sizes, the kd-tree on suzanne's
  primary rays; error against float64 brute force), measured on this lab and plotted as a
  student's plot is (``pareto_trade.png``);
* ``structures``: per scene (suzanne 1K, bunny 69K, bunny_x4 278K, bunny_x16 1.1M,
  teapot_in_stadium, a random soup) and structure (uniform grid, two-level grid, LBVH,
  binned-SAH BVH with the stack traversal and with the sync-free one, kd-tree): build time,
  bytes, primary-ray and shadow-ray throughput (shadow rays: from the primary hits to a
  light; the sync-free BVH runs them in any-hit mode, the others as closest-hit rays
  clipped at the light), mean steps (cells or nodes) and triangle tests per primary ray,
  and the fraction of sampled rays whose hit differs from brute force (``error``). Every
  scene also gets a brute-force row and, on the CPU, a row for trimesh's own ray query
  (``RayMeshIntersector.intersects_first``: numpy, or Embree where installed) on the same
  rays. Structures whose build would take minutes on a scene are skipped there (the kd
  tree above 300K triangles, the slow traversals above ``--max-slow``).
* ``fast``: the sync-free BVH traversal on the bunny, one knob at a time: ``check_every``
  (k, steps between host syncs), ``compile`` (off, ``torch.compile``, CUDA graphs), leaf
  size; primary rays at ``--fast-size`` squared.
* ``lbvh``: the LBVH build of bunny_x16 (1.1M triangles), median of several builds.
* ``embree`` (CPU): Embree (``embreex``, optional: ``pip install embreex``; the part is
  skipped with the reason when it is missing) and the lab's walks on the same bunny primary
  rays (``--fast-size`` squared), warm (each traced once first), at one thread and at all
  cores this process may use (and at the free ones, ``course.core.device.free_cpus``, where
  that differs): the stack and stackless BVH traversals, the
  sync-free walk eager and compiled, and ``course.kernels.flat_bvh``'s tracer. Each thread count
  runs in its own process pinned to that many cores (Embree's thread pool sizes itself
  from the affinity at its first use); the timings of one count are interleaved round by
  round, so a load that comes and goes slows every row alike, and each row records its
  ratio to Embree at the same thread count. ``--parts embree`` alone writes its
  ``lab2_accel.json`` / ``.md`` into ``bench/results/<device>/lab2_embree/`` by default.

The lab measured is ``--impl``'s (solutions/ in the course repository, labs/ in the
handout); a function it has not written yet costs its rows, with the reason printed. The
triangle kernel of the structures is Lab 1's Möller–Trumbore (float32) as the given code has
it (``course.given.lab2.moller_trumbore_rows``), so no Lab 1 is needed; the sync-free
traversal inlines the same test. Brute force is the lab's, or where it is not written the
given ``intersect_pairs`` over every triangle. Writes ``lab2_accel.json``,
``lab2_accel.md`` and plots (trace throughput against build time per scene; the fast
path's knobs) into ``--out`` (default ``bench/results/<device>/lab2/``).
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import os
import sys
import time
from pathlib import Path

import torch
from torch._inductor import metrics as inductor_metrics

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))  # run from a checkout without installing

from course.core.camera import primary_rays
from course.core.device import allowed_cpus, default_device, free_cpus, set_cpu_threads
from course.core.scenes import load_scene
from course.core.types import Hits, Rays
from course.given.lab2 import intersect_pairs, new_closest, pack_bvh
from course.measure.bench import (
    ResultTable,
    add_impl_option,
    device_name,
    load_lab,
    pareto_plot,
    time_fn,
    trade_plot,
)
from course.tools.trade import lab2 as trade

lab = None  # the Lab 2 module measured: main() loads it from --impl

ALL_SCENES = "suzanne,bunny,bunny_x4,bunny_x16,teapot_in_stadium,random_soup"
# size: primary rays size^2 for the per-step-compacting traversals; fast_size: for the
# sync-free one; brute_rays: rays checked against (and timed with) brute force.
MODES = {
    "small": {
        "scenes": "suzanne,bunny,bunny_x4,teapot_in_stadium,random_soup",
        "size": 32,
        "fast_size": 256,
        "brute_rays": 32,
        "trimesh_rays": 48,
        "repeats": 1,
        "warmup": 1,
        "teapot": 1,
        "soup": 10_000,
        "max_slow": 100_000,
        "lbvh_builds": 3,
        "compile": (),
        "knob_compile": True,
    },
    "cpu": {
        "scenes": ALL_SCENES,
        "size": 64,
        "fast_size": 256,
        "brute_rays": 64,
        "trimesh_rays": 64,
        "repeats": 2,
        "warmup": 1,
        "teapot": 2,
        "soup": 100_000,
        "max_slow": 300_000,
        "lbvh_builds": 3,
        "compile": ("default",),
        "knob_compile": True,
    },
    "cuda": {
        "scenes": ALL_SCENES,
        "size": 256,
        "fast_size": 1024,
        "brute_rays": 4096,
        "trimesh_rays": 0,
        "repeats": 3,
        "warmup": 1,
        "teapot": 2,
        "soup": 100_000,
        "max_slow": 300_000,
        "lbvh_builds": 10,
        "compile": ("default",),
        "knob_compile": True,
    },
}

# (label, kind, build knobs, traversal): traversal "slow" = lab.closest_hit, "fast" = the
# sync-free BVH traversal (k = 8, eager), "fast+<mode>" = the same under torch.compile.
STRUCTURES = [
    ("grid lambda=2", "grid", {"density": 2.0}, "slow"),
    ("two-level grid", "grid2", {}, "slow"),
    ("LBVH leaf 4", "bvh", {"method": "lbvh"}, "slow"),
    ("SAH leaf 4, stack", "bvh", {"method": "sah"}, "slow"),
    ("SAH leaf 4, sync-free", "bvh", {"method": "sah"}, "fast"),
    ("kd-tree (SAH)", "kd", {}, "slow"),
]


# The triangle kernel the structures call: Lab 1's Möller–Trumbore (given code), the one
# rtcourse bench --lab 2 gives them.
intersect = trade.intersect


def run_trade(mode, device, table, log):
    """The rows of ``rtcourse bench --lab 2`` (``course.tools.trade.lab2``: its scene, its
    structures and parameters, error against float64 brute force), measured on this
    script's lab, and their plot (``pareto_trade.png``), made as the student's is."""
    from course.tools.trade import measure_rows

    ctx = trade.prepare(device, quick=mode["size"] <= MODES["small"]["size"])
    rows, skipped = measure_rows(trade, lab, ctx, "reference", log)
    for reason in skipped:
        log(f"  trade {reason}")
    for row in rows:
        table.add(part="trade", scene="suzanne", **{k: v for k, v in row.items() if k != "impl"})
        log(
            f"  trade {row['setting']:<24} {row['seconds'] * 1e3:9.2f} ms  error {row['error']:.3g}"
        )


def given_brute_force(rays: Rays, mesh):
    """Brute force from the given code (every triangle tested by ``intersect_pairs``):
    the reference hits where the lab's ``brute_force_closest_hit`` is not written yet."""
    corners = mesh.vertices[mesh.faces]
    closest = new_closest(len(rays), rays.origins)
    counters = {"tests": torch.zeros(len(rays), dtype=torch.int64, device=rays.origins.device)}
    tris = torch.arange(mesh.num_faces, device=rays.origins.device)
    tile = max(1, 2**20 // mesh.num_faces)  # rays per call: about a million pairs
    for start in range(0, len(rays), tile):
        ray = torch.arange(start, min(len(rays), start + tile), device=rays.origins.device)
        intersect_pairs(
            intersect,
            rays,
            corners,
            ray.repeat_interleave(len(tris)),
            tris.repeat(len(ray)),
            closest,
            counters,
        )
    return Hits(**closest), counters


def sync(device):
    if device.type == "cuda":
        torch.cuda.synchronize(device)


def seconds(fn, *args, device, **kwargs):
    """(result, seconds) of one call, synchronised."""
    sync(device)
    start = time.perf_counter()
    out = fn(*args, **kwargs)
    sync(device)
    return out, time.perf_counter() - start


def load(name: str, mode: dict, device):
    params = {}
    if name == "teapot_in_stadium":
        params = {"subdivisions": mode["teapot"]}
    elif name == "random_soup":
        params = {"n": mode["soup"], "seed": 1}
    return load_scene(name, device=device, **params)


def camera_rays(scene, size: int, device) -> Rays:
    return primary_rays(dataclasses.replace(scene.camera, width=size, height=size), device=device)


def shadow_rays(rays: Rays, hits, mesh) -> Rays:
    """From the primary hits towards a light above the scene (t_max just short of it)."""
    hit = hits.triangle >= 0
    points = rays.origins[hit] + hits.t[hit, None] * rays.directions[hit]
    v = mesh.vertices
    lo, hi = v.amin(0), v.amax(0)
    light = (lo + hi) / 2 + torch.tensor([0.3, 1.0, 0.2], device=v.device, dtype=v.dtype) * (
        hi - lo
    ).norm()
    scale = float((hi - lo).norm())
    return Rays.create(
        points,
        light - points,
        1e-5 * scale / float((light - points).norm(dim=1).amax().clamp(min=1e-30)),
        1 - 1e-4,
    )


def nbytes(structure) -> int:
    return sum(
        x.numel() * x.element_size() for x in structure.values() if isinstance(x, torch.Tensor)
    )


def trace(label_kind, structure, rays, mesh, traversal, any_hit=False):
    if traversal == "slow":
        return lab.closest_hit(rays, mesh, structure, intersect)
    mode = traversal.split("+")[1] if "+" in traversal else False
    return lab.bvh_closest_hit_fast(
        rays, mesh, structure, any_hit=any_hit, check_every=8, compile=mode
    )


def run_scene(name, mode, device, table, log):
    scene = load(name, mode, device)
    mesh, f = scene.mesh, scene.mesh.num_faces
    slow_rays = camera_rays(scene, mode["size"], device)
    fast_rays = camera_rays(scene, mode["fast_size"], device)
    check = (
        torch.linspace(
            0, len(fast_rays) - 1, min(len(fast_rays), mode["brute_rays"]), device=device
        )
        .long()
        .unique()
    )
    sample = fast_rays[check]
    brute = "brute force"
    try:
        (reference, _), brute_s = seconds(
            lab.brute_force_closest_hit, sample, mesh, intersect, device=device
        )
    except NotImplementedError as error:  # the handout before task 5: the given code's
        log(f"  brute force of the lab: {error}; the given intersect_pairs instead")
        brute = "brute force (given intersect_pairs)"
        (reference, _), brute_s = seconds(given_brute_force, sample, mesh, device=device)
    log(
        f"{name}: {f:,} triangles; {brute} {len(sample) / brute_s:,.0f} rays/s ({len(sample)} rays)"
    )
    common = {"part": "structures", "scene": name, "triangles": f}
    table.add(
        **common,
        setting=brute,
        rays=len(sample),
        build_s=0.0,
        rays_per_s=len(sample) / brute_s,
        shadow_rays_per_s=math.nan,
        steps=0.0,
        tests=float(f),
        bytes=0,
        error=0.0,
    )
    if mode["trimesh_rays"] and device.type == "cpu":
        trimesh_row(mesh, fast_rays, mode, table, common, log)
    for label, kind, knobs, traversal in STRUCTURES:
        if (kind == "kd" and f > 300_000) or (
            traversal == "slow" and f > mode["max_slow"] and kind != "bvh"
        ):
            log(f"  {label:<26} skipped: its build or walk takes minutes at {f:,} triangles")
            continue
        if kind == "kd" and f > mode["max_slow"]:
            continue
        # Compiled rows on the bunny only: every scene (and any-hit) recompiles the step,
        # tens of seconds each; the knob part measures compile on the bunny in full.
        variants = [traversal] + (
            [f"fast+{m}" for m in mode["compile"]]
            if traversal == "fast" and name == "bunny"
            else []
        )
        try:
            structure, build_s = seconds(lab.build, mesh, kind, device=device, **dict(knobs))
        except NotImplementedError as error:  # the handout: a structure not written yet
            log(f"  {label:<26} skipped: {error}")
            continue
        for variant in variants:
            rays = fast_rays if variant.startswith("fast") else slow_rays
            if variant == "slow" and f > mode["max_slow"]:
                continue
            try:
                trace(kind, structure, rays[:64], mesh, variant)  # warm up (and compile)
                (hits, counters), trace_s = seconds(
                    trace, kind, structure, rays, mesh, variant, device=device
                )
                if mode["repeats"] > 1:
                    timing = time_fn(
                        trace,
                        kind,
                        structure,
                        rays,
                        mesh,
                        variant,
                        repeats=mode["repeats"],
                        warmup=0,
                        device=device,
                    )
                    trace_s = timing.median
                shadow = shadow_rays(rays, hits, mesh)
                trace(kind, structure, shadow[:64], mesh, variant, any_hit=True)
                _, shadow_s = seconds(
                    trace,
                    kind,
                    structure,
                    shadow,
                    mesh,
                    variant,
                    any_hit=variant.startswith("fast"),
                    device=device,
                )
            except RuntimeError as error:  # a failed variant (no compiler, out of memory): a row
                log(f"  {label} [{variant}]: failed: {type(error).__name__}: {error}")
                table.add(
                    **common,
                    setting=f"{label} [{variant}]",
                    rays=len(rays),
                    build_s=build_s,
                    rays_per_s=math.nan,
                    shadow_rays_per_s=math.nan,
                    steps=math.nan,
                    tests=math.nan,
                    bytes=nbytes(structure),
                    error=math.nan,
                    failed=f"{type(error).__name__}",
                )
                continue
            if variant.startswith("fast"):
                got = hits[check]
            else:
                got, _ = trace(kind, structure, sample, mesh, variant)
            wrong = (got.triangle != reference.triangle) & ~(
                (got.t - reference.t).abs() <= 1e-5 * reference.t.abs()
            )
            setting = label if variant in ("slow", "fast") else f"{label}, compile={variant[5:]}"
            row = table.add(
                **common,
                setting=setting,
                rays=len(rays),
                build_s=build_s,
                rays_per_s=len(rays) / trace_s,
                shadow_rays_per_s=len(shadow) / shadow_s,
                steps=counters["steps"].double().mean().item(),
                tests=counters["tests"].double().mean().item(),
                bytes=nbytes(structure),
                error=wrong.double().mean().item(),
            )
            log(
                f"  {setting:<40} build {build_s:7.3f} s  primary {row['rays_per_s']:>13,.0f} "
                f"rays/s  shadow {row['shadow_rays_per_s']:>13,.0f} rays/s  steps "
                f"{row['steps']:6.1f}  tests {row['tests']:7.1f}  "
                f"{row['bytes'] / 2**20:6.1f} MiB  error {row['error']:.3g}"
            )


def trimesh_row(mesh, rays, mode, table, common, log):
    """trimesh's own ray queries on the same rays (CPU): its numpy intersector (with an
    rtree of boxes) on a subsample, and Embree (through ``embreex``, where installed) on
    all of them."""
    import trimesh

    tm = trimesh.Trimesh(
        mesh.vertices.cpu().double().numpy(), mesh.faces.cpu().numpy(), process=False
    )
    n = min(len(rays), mode["trimesh_rays"])
    pick = torch.linspace(0, len(rays) - 1, n).long().unique()
    queries = [
        ("RayMeshIntersector", "trimesh.ray.ray_triangle", pick),
        ("Embree", "trimesh.ray.ray_pyembree", torch.arange(len(rays))),
    ]
    for kind, module, rows in queries:
        o = rays.origins[rows].cpu().double().numpy()
        d = rays.directions[rows].cpu().double().numpy()
        try:
            import importlib

            query = importlib.import_module(module).RayMeshIntersector(tm)
            start = time.perf_counter()
            query.intersects_first(o, d)
        except (ImportError, AttributeError) as error:  # rtree / embreex not installed
            log(f"  trimesh ({kind}): unavailable ({error})")
            continue
        elapsed = time.perf_counter() - start
        log(f"  trimesh ({kind}) {len(rows) / elapsed:,.0f} rays/s ({len(rows)} rays)")
        table.add(
            **common,
            setting=f"trimesh {kind}",
            rays=len(rows),
            build_s=math.nan,
            rays_per_s=len(rows) / elapsed,
            shadow_rays_per_s=math.nan,
            steps=math.nan,
            tests=math.nan,
            bytes=0,
            error=math.nan,
        )


def run_fast_knobs(mode, device, table, log, headline=False):
    """The sync-free traversal on the bunny, one knob at a time (``headline``: only the
    rows of the targets: eager, compiled, compiled with CUDA graphs, and the pack).

    Every row but the ``packed per call`` one traces a tree packed once (``walk=``), as a
    renderer keeps its structure between frames; the pack's own time is a row."""
    scene = load("bunny", mode, device)
    mesh = scene.mesh
    rays = camera_rays(scene, mode["fast_size"], device)
    log(f"fast path knobs: bunny, {len(rays):,} primary rays")
    if mode["trimesh_rays"] and device.type == "cpu":  # the same rays, in the same run
        trimesh_row(
            mesh,
            rays,
            mode,
            table,
            {"part": "fast", "scene": "bunny", "triangles": mesh.num_faces},
            log,
        )
    # (k, compile, leaf size, compact, packed per call, steps fused per compiled call)
    settings = [
        (8, False, 4, True, False, 1),
        (1, False, 4, True, False, 1),
        (32, False, 4, True, False, 1),
        (8, False, 4, False, False, 1),
    ]
    first = (mode["compile"] or ("default",))[0]
    compiled = [(k, first, 4, True, False, 1) for k in (8, 16, 32)]
    if device.type == "cuda":  # the same compiled step replayed from CUDA graphs
        compiled += [(k, "reduce-overhead", 4, True, False, 1) for k in (16, 32, 64)]
        compiled += [
            (16, "reduce-overhead", 4, True, True, 1),
            (16, "reduce-overhead", 4, False, False, 1),
        ]
    graphs = "reduce-overhead" if device.type == "cuda" else first
    compiled += [(16, graphs, leaf, True, False, 1) for leaf in (2, 8)]
    compiled += [(16, graphs, 4, True, False, 8)]  # last: the longest compile
    if headline:  # leaf 4; on a GPU one step per compiled call (8 compile for minutes)
        settings = settings[:1] + [
            c for c in compiled if c[2] == 4 and (c[5] == 1 or device.type == "cpu")
        ]
    elif mode["knob_compile"]:
        settings += compiled
    bvhs, walks, reference = {}, {}, {}
    for k, compile_mode, leaf, compact, per_call, fuse in settings:
        if leaf not in bvhs:
            try:
                bvhs[leaf] = lab.build_sah_bvh(mesh, leaf_size=leaf)
            except NotImplementedError as error:
                log(f"  fast path knobs skipped: {error}")
                return
            timing = time_fn(
                pack_bvh, bvhs[leaf], mesh, repeats=mode["repeats"], warmup=1, device=device
            )
            walks[leaf] = pack_bvh(bvhs[leaf], mesh)
            table.add(
                part="fast",
                scene="bunny",
                setting=f"pack_bvh, leaf {leaf}",
                triangles=mesh.num_faces,
                build_s=timing.median,
                leaf_size=leaf,
            )
            log(f"  pack_bvh (8 octants), leaf {leaf}: {timing.median * 1e3:.1f} ms")
        bvh = bvhs[leaf]
        walk = None if per_call else walks[leaf]
        label = (
            f"k={k}, compile={compile_mode or 'off'}, leaf {leaf}"
            + (f", {fuse} steps per kernel" if fuse > 1 else "")
            + ("" if compact else ", no compaction")
            + (", packed per call" if per_call else "")
        )
        knobs = {
            "check_every": k,
            "compile": compile_mode,
            "compact": compact,
            "walk": walk,
            "fuse_steps": fuse,
        }
        try:
            kernels = inductor_metrics.generated_kernel_count
            (hits, counters), warm_s = seconds(
                lab.bvh_closest_hit_fast, rays, mesh, bvh, device=device, **knobs
            )  # warm up (and compile)
            kernels = inductor_metrics.generated_kernel_count - kernels
            repeats = mode["repeats"]
            if compile_mode == "reduce-overhead":  # milliseconds a call: a median of 20,
                repeats = max(repeats, 20)  # where 3 moved by a fifth between runs
            timing = time_fn(
                lab.bvh_closest_hit_fast,
                rays,
                mesh,
                bvh,
                repeats=repeats,
                warmup=1,
                device=device,
                **knobs,
            )
        except RuntimeError as error:
            log(f"  {label}: failed: {type(error).__name__}: {error}")
            continue
        # The same leaf size must find the same triangles whatever the other knobs.
        first_hits = reference.setdefault(leaf, hits.triangle)
        differ = (hits.triangle != first_hits).double().mean().item()
        row = table.add(
            part="fast",
            scene="bunny",
            setting=label,
            triangles=mesh.num_faces,
            rays=len(rays),
            build_s=math.nan,
            rays_per_s=len(rays) / timing.median,
            differ_from_first_row=differ,
            check_every=k,
            compile=str(compile_mode),
            leaf_size=leaf,
            compact=compact,
            packed_per_call=per_call,
            fuse_steps=fuse,
            first_call_s=warm_s,
            kernels_generated=kernels,
            steps=counters["steps"].double().mean().item(),
            tests=counters["tests"].double().mean().item(),
        )
        log(
            f"  {label:<60} {row['rays_per_s']:>14,.0f} rays/s  (first call {warm_s:6.1f} s, "
            f"{kernels} kernels generated, {differ:.2g} differ)"
        )


def run_lbvh_build(mode, device, table, log):
    mesh = load("bunny_x16", mode, device).mesh
    try:
        lab.build_lbvh(mesh)  # warm up
    except NotImplementedError as error:
        log(f"LBVH build skipped: {error}")
        return
    timing = time_fn(lab.build_lbvh, mesh, repeats=mode["lbvh_builds"], warmup=0, device=device)
    log(
        f"LBVH build, bunny_x16 ({mesh.num_faces:,} triangles): {timing.median * 1e3:.1f} ms "
        f"(median of {mode['lbvh_builds']})"
    )
    table.add(
        part="lbvh",
        scene="bunny_x16",
        setting="LBVH leaf 4 build",
        triangles=mesh.num_faces,
        build_s=timing.median,
    )


EMBREE_WALKS = (
    "Embree",
    "sync-free walk, compiled",
    "sync-free walk, eager",
    "SAH stack traversal",
    "SAH stackless traversal",
    "flat_bvh.trace_bvh",
)


def embree_tracer(mesh):
    """A warm-able Embree query on ``mesh``: ``trace(origins, directions) -> triangle ids``
    (numpy float32 in, int32 out, -1 for a miss), or ``(None, reason)`` without embreex."""
    try:
        from embreex import rtcore_scene
        from embreex.mesh_construction import TriangleMesh
    except ImportError as error:
        return None, f"embreex is not installed ({error}); pip install embreex"
    import numpy as np

    scene = rtcore_scene.EmbreeScene()
    TriangleMesh(
        scene=scene,
        vertices=mesh.vertices.cpu().float().numpy(),
        indices=mesh.faces.cpu().numpy().astype(np.int32),
    )

    def trace(origins, directions):
        return scene.run(origins, directions)

    return trace, ""


def run_embree_one(mode, table, log, threads: int, rounds: int, budget: float):
    """One thread count of the ``embree`` part (this process is pinned to ``threads``
    cores): every walk warm, then ``rounds`` rounds timing each walk once in turn (a walk
    whose timed calls add up to more than ``budget`` seconds sits out the later rounds)."""
    from course.kernels import trace

    device = torch.device("cpu")
    scene = load("bunny", mode, device)
    mesh = scene.mesh
    rays = camera_rays(scene, mode["fast_size"], device)
    embree, reason = embree_tracer(mesh)
    if embree is None:
        log(f"embree part skipped: {reason}")
        table.metadata["embree_skipped"] = reason
        return
    o32 = rays.origins.float().numpy().copy()
    d32 = rays.directions.float().numpy().copy()
    try:
        bvh = lab.build_sah_bvh(mesh)
    except NotImplementedError as error:
        log(f"embree part skipped: {error}")
        return
    walk = pack_bvh(bvh, mesh)
    calls = {
        "Embree": lambda: torch.from_numpy(embree(o32, d32).astype("int64")),
        "sync-free walk, compiled": lambda: (
            lab.bvh_closest_hit_fast(rays, mesh, bvh, check_every=8, compile=True, walk=walk)[
                0
            ].triangle
        ),
        "sync-free walk, eager": lambda: (
            lab.bvh_closest_hit_fast(rays, mesh, bvh, check_every=8, walk=walk)[0].triangle
        ),
        "SAH stack traversal": lambda: lab.bvh_closest_hit(rays, mesh, bvh, intersect)[0].triangle,
        "SAH stackless traversal": lambda: (
            lab.bvh_closest_hit_stackless(rays, mesh, bvh, intersect)[0].triangle
        ),
        "flat_bvh.trace_bvh": lambda: (
            trace.trace_bvh(mesh, rays.origins, rays.directions, rays.t_min, rays.t_max).triangle
        ),
    }
    first, warm = {}, {}
    for name, call in list(calls.items()):  # warm: Embree's build, torch.compile, flat BVH
        started = time.perf_counter()
        try:
            first[name] = call()
        except NotImplementedError as error:
            log(f"  {threads} thread(s): {name} skipped: {error}")
            del calls[name]
            continue
        warm[name] = time.perf_counter() - started
        log(f"  {threads} thread(s): {name} warm-up call {warm[name]:.2f} s")
    times = {name: [] for name in calls}
    for _ in range(rounds):
        for name, call in calls.items():
            if times[name] and sum(times[name]) > budget:  # enough of a slow walk
                continue
            started = time.perf_counter()
            call()
            times[name].append(time.perf_counter() - started)
    embree_s = sorted(times["Embree"])[len(times["Embree"]) // 2]
    for name in calls:
        median = sorted(times[name])[len(times[name]) // 2]
        agree = (first[name] == first["Embree"]).double().mean().item()
        row = table.add(
            part="embree",
            scene="bunny",
            setting=name,
            threads=threads,
            triangles=mesh.num_faces,
            rays=len(rays),
            rays_per_s=len(rays) / median,
            seconds_median=median,
            seconds_min=min(times[name]),
            seconds_max=max(times[name]),
            rounds=len(times[name]),
            first_call_s=warm[name],
            ratio_to_embree=embree_s / median,
            same_triangle_as_embree=agree,
        )
        log(
            f"  {threads} thread(s): {name:<26} {row['rays_per_s']:>13,.0f} rays/s  "
            f"x{row['ratio_to_embree']:.3f} Embree  (min {len(rays) / max(times[name]):,.0f}, "
            f"max {len(rays) / min(times[name]):,.0f}; same triangle as Embree "
            f"{agree:.2%})"
        )


def run_embree(args, mode, table, log):
    """The ``embree`` part: one process per thread count (1, the free cores, all), each
    pinned to that many of this process's cores; their rows join ``table``."""
    import json
    import subprocess
    import tempfile

    counts = sorted({1, free_cpus(), allowed_cpus()})
    table.metadata.update(
        embree_threads=counts,
        allowed_cpus=allowed_cpus(),
        free_cpus=free_cpus(),
        load_average=list(os.getloadavg()),
    )
    for threads in counts:
        with tempfile.TemporaryDirectory() as folder:
            command = [
                sys.executable,
                str(Path(__file__).resolve()),
                "--device",
                "cpu",
                "--parts",
                "embree-one",
                "--threads",
                str(threads),
                "--out",
                folder,
                "--fast-size",
                str(mode["fast_size"]),
                "--rounds",
                str(args.rounds),
                "--walk-budget",
                str(args.walk_budget),
            ]
            command += ["--impl", args.impl] if args.impl else []
            log(f"embree part, {threads} thread(s): {' '.join(command[1:])}")
            done = subprocess.run(command, check=False, capture_output=True, text=True)
            for line in done.stdout.splitlines():
                log(f"  | {line}")
            if done.returncode:
                log(f"  failed (exit {done.returncode}): {done.stderr.strip()[-2000:]}")
                continue
            part = json.loads((Path(folder) / "lab2_accel.json").read_text())
            if part["metadata"].get("embree_skipped"):
                table.metadata["embree_skipped"] = part["metadata"]["embree_skipped"]
            for row in part["rows"]:
                table.add(**row)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--device", default=None, help="cpu or cuda (default: cuda if present)")
    parser.add_argument("--small", action="store_true", help="the CPU run of a few minutes")
    parser.add_argument("--scenes", default=None, help=f"comma-separated (default: {ALL_SCENES})")
    parser.add_argument("--parts", default="trade,structures,fast,lbvh")
    parser.add_argument("--size", type=int, default=None)
    parser.add_argument("--fast-size", type=int, default=None)
    parser.add_argument("--out", default=None, help="output folder")
    parser.add_argument(
        "--threads",
        type=int,
        default=None,
        help="CPU threads for torch (default: the free cores, "
        "course.core.device.free_cpus); with --parts embree-one the process "
        "is also pinned to that many cores",
    )
    parser.add_argument(
        "--rounds",
        type=int,
        default=7,
        help="embree part: timed rounds of every walk (median reported)",
    )
    parser.add_argument(
        "--walk-budget",
        type=float,
        default=20.0,
        help="embree part: seconds of timed calls after which a walk sits out the remaining rounds",
    )
    parser.add_argument("--no-compile", action="store_true", help="skip torch.compile rows")
    parser.add_argument(
        "--headline",
        action="store_true",
        help="only the LBVH build and the headline traversal rows (bunny, "
        "eager / compiled / CUDA graphs): ~2 minutes on a GPU",
    )
    add_impl_option(parser)
    args = parser.parse_args(argv)
    global lab
    lab = load_lab("lab2_accel", args.impl, root=REPO)
    if args.parts == "embree-one" and hasattr(os, "sched_setaffinity"):
        cores = sorted(os.sched_getaffinity(0))
        os.sched_setaffinity(0, cores[: args.threads or 1])  # before Embree sizes its pool
    threads = set_cpu_threads(args.threads)
    device = default_device(args.device)
    mode = dict(MODES["small" if args.small else device.type if device.type == "cuda" else "cpu"])
    if args.no_compile:
        mode.update(compile=(), knob_compile=False)
    for key in ("scenes", "size", "fast_size"):
        if getattr(args, key) is not None:
            mode[key] = getattr(args, key)
    folder = "lab2_embree" if args.parts == "embree" else "lab2"
    out = Path(args.out) if args.out else REPO / "bench" / "results" / device_name(device) / folder
    table = ResultTable("lab2 acceleration structures", device=device)
    table.metadata.update(
        mode={k: v for k, v in mode.items()},
        cpu_threads=threads,
        kernel="course.given.lab2.moller_trumbore_rows float32; sync-free path: inline, float32",
        lab_file=str(lab.__file__),
    )
    start = time.perf_counter()

    def log(text):
        print(f"[{time.perf_counter() - start:6.0f} s] {text}", flush=True)

    # The headline figures first, and the files rewritten after every part: a run stopped
    # at its time limit keeps what it measured.
    parts = ["lbvh", "fast"] if args.headline else args.parts.split(",")
    if "embree-one" in parts:  # one thread count of the embree part (run by run_embree)
        run_embree_one(mode, table, log, threads, args.rounds, args.walk_budget)
        write(table, out, mode)
        return table
    if "embree" in parts:
        if device.type != "cpu":
            log("embree part: CPU only, skipped")
        else:
            run_embree(args, mode, table, log)
            write(table, out, mode)
    if "lbvh" in parts:
        run_lbvh_build(mode, device, table, log)
    if "fast" in parts:
        run_fast_knobs(mode, device, table, log, headline=args.headline)
        write(table, out, mode)
    if "trade" in parts:
        run_trade(mode, device, table, log)
        write(table, out, mode)
    if "structures" in parts:
        for name in mode["scenes"].split(","):
            run_scene(name, mode, device, table, log)
            write(table, out, mode)
    write(table, out, mode)
    log(f"wrote {out}")
    return table


def write(table, out: Path, mode: dict):
    out.mkdir(parents=True, exist_ok=True)
    table.to_json(out / "lab2_accel.json")
    meta = table.metadata
    parts = []
    for part, title in (
        ("structures", "Structures: build, primary and shadow rays, work"),
        ("fast", "The sync-free BVH traversal: one knob at a time (bunny)"),
        ("lbvh", "LBVH build of bunny_x16"),
        ("embree", "Embree and the lab's walks, same rays, warm (bunny)"),
    ):
        rows = [r for r in table.rows if r.get("part") == part]
        if rows:
            sub = ResultTable(part)
            for r in rows:
                sub.add(**{k: v for k, v in r.items() if k != "part"})
            parts.append(f"## {title}\n\n{sub.to_markdown()}\n")
    (out / "lab2_accel.md").write_text(
        f"# Lab 2: acceleration structures on {meta['device']}\n\n"
        f"`{meta['command']}` (torch {meta['torch']}, {meta['date']}, "
        f"{meta['cpu_threads']} CPU threads)\n\n" + "\n".join(parts)
    )
    rows = [r for r in table.rows if r.get("part") == "trade"]
    if rows:
        trade_plot(
            rows,
            [],
            path=out / "pareto_trade.png",
            title="suzanne: trace seconds against hits differing from exact",
        )
    for name in ("bunny", "teapot_in_stadium"):  # two plots: the device returns few files
        rows = [
            r
            for r in table.rows
            if r.get("part") == "structures"
            and r["scene"] == name
            and r["build_s"] > 0
            and math.isfinite(r["rays_per_s"])
        ]
        if rows:
            pareto_plot(
                rows,
                x="rays_per_s",
                y="build_s",
                label="setting",
                path=out / f"pareto_{name}_trace_vs_build.png",
                title=f"{name}: primary rays/s against build time",
            )
    rows = [r for r in table.rows if r.get("part") == "fast" and "rays_per_s" in r]
    if rows:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(7, 0.35 * len(rows) + 1.2))
        ax.barh([r["setting"] for r in rows], [r["rays_per_s"] for r in rows])
        ax.set_xscale("log")
        ax.set_xlabel("primary rays/s (bunny)")
        ax.set_title(f"sync-free BVH traversal, one knob at a time ({meta['device']})")
        ax.invert_yaxis()
        fig.tight_layout()
        fig.savefig(out / "fast_path_knobs.png", dpi=110)
        plt.close(fig)


if __name__ == "__main__":
    main()
