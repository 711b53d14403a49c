"""Lab 2 benchmark: what each acceleration structure and each of its knobs costs and buys.

    python bench/lab2_accel.py --device cpu|cuda [--size S] [--brute-rays B] [--threads T]
                               [--out DIR]

For two scenes, the Stanford bunny (69K triangles, rays from its framing camera) and the
teapot in a stadium (Suzanne Loop-subdivided twice on a GPU, 15.5K triangles, once on the
CPU, 3.9K triangles, in a room a thousand times larger), and for every structure and knob
setting of the reference solution:

* uniform grid: density lambda (cells per triangle), mailbox on/off;
* BVH: build method (LBVH / binned SAH), leaf size, SAH bins; stack vs stackless traversal;
* kd-tree: the default SAH build, and one cut at depth 12 (big leaves);

it measures the build time, the traversal time of ``S x S`` primary rays (rays/s), the
mean work per ray (steps = cells or nodes visited, triangle tests, mailbox skips), the
structure's size in bytes, and the **error**: the fraction of rays, among ``B`` checked
against brute force with the same triangle kernel, that get another hit (0 for a correct
structure: an acceleration structure trades build time and memory for speed, never
accuracy). Brute force is timed on the ``B`` rays, so every row also gets its speed-up
over brute force, measured in the same run: on the CPU only such ratios mean anything.

The triangle kernel is Lab 1's Möller–Trumbore (float32) from the solutions.

Writes ``lab2_accel.json`` (a ResultTable with the command line), ``lab2_accel.md`` and
Pareto plots (trace time against build time per scene; triangle tests against steps) into
``--out``, by default ``bench/results/<device_name>/lab2/``.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import torch

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))  # `solutions` is not an installed package

from course.bench import ResultTable, device_name, pareto_plot, time_fn
from course.camera import primary_rays
from course.device import default_device
from course.scenes import load_scene
from solutions import lab2_accel as lab
from solutions.lab1_intersect import moller_trumbore

# Image size (rays = size^2), rays checked against brute force, timing repeats, and the
# teapot's Loop subdivisions (the grid tests every teapot triangle for every ray at it: on
# the CPU, 968 * 4 = 3.9K triangles keep that row short).
SIZES = {"cpu": {"size": 48, "brute_rays": 64, "repeats": 2, "warmup": 1, "teapot": 1},
         "cuda": {"size": 512, "brute_rays": 8192, "repeats": 5, "warmup": 2, "teapot": 2}}

# (structure, build keywords, traversal keywords, label); "default" marks the lab's defaults.
SETTINGS = [
    ("grid", {"density": 0.5}, {}, "grid lambda=0.5"),
    ("grid", {"density": 2.0}, {}, "grid lambda=2 (default)"),
    ("grid", {"density": 2.0}, {"mailbox": False}, "grid lambda=2, no mailbox"),
    ("grid", {"density": 8.0}, {}, "grid lambda=8"),
    ("bvh", {"method": "lbvh", "leaf_size": 1}, {}, "LBVH leaf 1"),
    ("bvh", {"method": "lbvh", "leaf_size": 4}, {}, "LBVH leaf 4 (default)"),
    ("bvh", {"method": "lbvh", "leaf_size": 4, "bits": 4}, {}, "LBVH leaf 4, 4-bit Morton"),
    ("bvh", {"method": "sah", "leaf_size": 1, "bins": 16}, {}, "SAH leaf 1"),
    ("bvh", {"method": "sah", "leaf_size": 4, "bins": 16}, {}, "SAH leaf 4 (default)"),
    ("bvh", {"method": "sah", "leaf_size": 4, "bins": 16}, {"stackless": True},
     "SAH leaf 4, stackless"),
    ("bvh", {"method": "sah", "leaf_size": 16, "bins": 16}, {}, "SAH leaf 16"),
    ("bvh", {"method": "sah", "leaf_size": 4, "bins": 4}, {}, "SAH leaf 4, 4 bins"),
    ("bvh", {"method": "sah", "leaf_size": 4, "bins": 64}, {}, "SAH leaf 4, 64 bins"),
    ("kd", {}, {}, "kd leaf 2 (default)"),
    ("kd", {"max_depth": 12}, {}, "kd max depth 12"),
]


def intersect(origins, directions, v0, v1, v2, t_min, t_max):
    """The triangle kernel every structure calls: Lab 1's Möller–Trumbore."""
    return moller_trumbore(origins, directions, v0, v1, v2, t_min, t_max)


def scene_rays(name: str, sizes: dict, device):
    """(mesh, primary rays of the scene's camera at size x size) on ``device``."""
    params = {"subdivisions": sizes["teapot"]} if name == "teapot_in_stadium" else {}
    scene = load_scene(name, device=device, **params)
    size = sizes["size"]
    camera = dataclasses.replace(scene.camera, width=size, height=size)
    return scene.mesh, primary_rays(camera, device=device)


def speedup_text(x: float) -> str:
    return f"{x:,.0f}" if x >= 10 else f"{x:.2f}"


def nbytes(structure: dict) -> int:
    return sum(x.numel() * x.element_size() for x in structure.values()
               if isinstance(x, torch.Tensor))


def sync(device):
    if device.type == "cuda":
        torch.cuda.synchronize(device)


def run_scene(name, sizes, device, table, log):
    mesh, rays = scene_rays(name, sizes, device)
    n, f = len(rays), mesh.num_faces
    check = torch.linspace(0, n - 1, min(n, sizes["brute_rays"]), device=device).long().unique()
    sample = rays[check]
    timing = time_fn(lab.brute_force_closest_hit, sample, mesh, intersect, repeats=1, warmup=0,
                     device=device)
    reference, _ = lab.brute_force_closest_hit(sample, mesh, intersect)
    brute_per_ray = timing.median / len(sample)
    log(f"{name}: {f} triangles, {n} rays; brute force {len(sample) / timing.median:,.0f} "
        f"rays/s on {len(sample)} rays")
    table.add(scene=name, setting="brute force", structure="none", triangles=f, rays=len(sample),
              build_s=0.0, trace_s=timing.median, rays_per_s=len(sample) / timing.median,
              speedup=1.0, steps=0.0, tests=float(f), skipped=0.0, bytes=0, error=0.0)
    for kind, build_kw, trace_kw, label in SETTINGS:
        sync(device)
        start = time.perf_counter()
        structure = lab.build(mesh, kind, **dict(build_kw))
        sync(device)
        build_s = time.perf_counter() - start
        trace = time_fn(lab.closest_hit, rays, mesh, structure, intersect, repeats=sizes["repeats"],
                        warmup=sizes["warmup"], device=device, **trace_kw)
        hits, counters = lab.closest_hit(rays, mesh, structure, intersect, **trace_kw)
        got = hits[check]
        wrong = (got.triangle != reference.triangle) & ~((got.t - reference.t).abs()
                                                         <= 1e-6 * reference.t.abs())
        row = table.add(
            scene=name, setting=label, structure=kind, triangles=f, rays=n, build_s=build_s,
            trace_s=trace.median, rays_per_s=n / trace.median,
            speedup=brute_per_ray / (trace.median / n),
            steps=counters["steps"].double().mean().item(),
            tests=counters["tests"].double().mean().item(),
            skipped=counters.get("skipped", torch.zeros(1)).double().mean().item(),
            bytes=nbytes(structure), error=wrong.double().mean().item())
        log(f"  {label:<28} build {build_s:7.3f} s  trace {row['rays_per_s']:>12,.0f} rays/s "
            f"(x{speedup_text(row['speedup'])} brute)  steps {row['steps']:6.1f}  tests "
            f"{row['tests']:7.1f}  {row['bytes'] / 2**20:6.1f} MiB  error {row['error']:.3g}")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--device", default=None, help="cpu or cuda (default: cuda if present)")
    parser.add_argument("--size", type=int, default=None, help="image size S (S x S rays)")
    parser.add_argument("--brute-rays", type=int, default=None,
                        help="rays checked against (and timed with) brute force")
    parser.add_argument("--scenes", default="bunny,teapot_in_stadium")
    parser.add_argument("--out", default=None, help="output folder")
    parser.add_argument("--threads", type=int, default=None,
                        help="CPU threads for torch (default: torch's choice); 1 gives steadier "
                             "ratios on a machine shared with other work")
    args = parser.parse_args(argv)
    if args.threads:
        torch.set_num_threads(args.threads)
    device = default_device(args.device)
    sizes = dict(SIZES["cuda" if device.type == "cuda" else "cpu"])
    if args.size:
        sizes["size"] = args.size
    if args.brute_rays:
        sizes["brute_rays"] = args.brute_rays
    out = Path(args.out) if args.out else REPO / "bench" / "results" / device_name(device) / "lab2"
    table = ResultTable("lab2 acceleration structures", device=device)
    table.metadata.update(sizes=sizes, kernel="lab1 moller_trumbore float32",
                          cpu_threads=torch.get_num_threads())
    start = time.perf_counter()
    for name in args.scenes.split(","):
        run_scene(name, sizes, device, table, lambda text: print(text, flush=True))
    table.to_json(out / "lab2_accel.json")
    (out / "lab2_accel.md").write_text(
        f"# Lab 2: acceleration structures on {table.metadata['device']}\n\n"
        f"`{table.metadata['command']}` (torch {table.metadata['torch']}, "
        f"{table.metadata['date']})\n\n{table.to_markdown()}\n")
    for name in args.scenes.split(","):
        rows = [r for r in table.rows if r["scene"] == name and r["structure"] != "none"]
        pareto_plot(rows, x="trace_s", y="build_s", label="setting", group="structure",
                    path=out / f"pareto_{name}_trace_vs_build.png",
                    title=f"{name}: trace time of {rows[0]['rays']} rays vs build time")
        pareto_plot(rows, x="steps", y="tests", label="setting", group="structure",
                    maximize_x=False, path=out / f"pareto_{name}_tests_vs_steps.png",
                    title=f"{name}: mean triangle tests vs traversal steps per ray")
    print(f"wrote {out} in {time.perf_counter() - start:.0f} s")
    return table


if __name__ == "__main__":
    main()
