"""Lab 3 benchmark: what each organisation of the Whitted tracer costs, and what it returns.

    python bench/lab3_wavefront.py --device cpu|cuda [--size S] [--reference-pixels R]
                                   [--scenes cornell_mirror,bunny_mirror] [--no-compile]
                                   [--threads T] [--out DIR] [--impl labs|solutions|DIR]
    python bench/lab3_wavefront.py --device cpu --quick   # the Cornell box at 16 x 16, seconds

For the Cornell box with a mirror box (36 triangles) and the bunny on a mirror floor (69K
triangles), ``S x S`` primary rays (1024 on a GPU, 32 on the CPU), shadow rays to every
light and up to two mirror reflections, it renders the image with every organisation of
``--impl``'s Lab 3 (the reference solution in the course repository, the student's labs/ in
the handout; an organisation not written yet is skipped with the reason):

* ``whitted``: one loop over full-size buffers, every lane traced every bounce;
* ``wavefront`` (and ``wavefront sorted``): separate stages over compacted queues;
* ``uber`` (eager, and under ``torch.compile`` unless ``--no-compile``): fixed-size lanes,
  every shadow lane traced;
* ``persistent``: a pool of ray slots fed from one queue (pools of N/4 and N slots);
* on CUDA, the Triton uber kernel ``course.kernels.triton_tracer.render_whitted_triton`` (traversal
  and shading in one launch), where it exists;

and records images/s, rays/s, the **lanes traced** (closest-hit and shadow lanes, live or
idle), the time per stage of the wavefront renderer, the persistent pool's steps and idle
fraction, and the error of the image against ``render_reference`` (float64) on ``R``
sampled pixels: ``max_rel_error`` (the largest relative error where the shading decisions
agree) and ``flipped`` (the fraction of pixels whose shadow/edge decision differs).

The tracer is ``course.kernels.trace.trace_bvh`` (a flattened binned-SAH BVH) where it exists,
else brute force. Also measured: the three geometry layouts of task 5 (bytes per triangle,
the time of a brute-force pass over each, agreement with the reference tracer).

The rows ``rtcourse bench --lab 3`` measures (``course.tools.trade.lab3``) are measured on
the same lab too and written as ``trade.csv`` with their plot ``pareto_trade.png``, drawn
as a student's is.

Writes ``lab3_wavefront.json`` (a ResultTable with the command line), ``lab3_wavefront.md``,
two Pareto plots per scene (error against images/s; lanes traced against images/s) and the
persistent pool's active lanes per step into ``--out``, by default
``bench/results/<device_name>/lab3/``.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import torch

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))  # run from a checkout without installing

from course.core.camera import primary_rays
from course.core.device import default_device
from course.given.lab3 import (
    render_reference,
    trace_brute_force,
    whitted_camera,
    whitted_scene,
)
from course.measure.bench import (
    ResultTable,
    add_impl_option,
    device_name,
    load_lab,
    pareto_plot,
    time_fn,
)
from course.tools.trade import bench_rows

lab = None  # the Lab 3 module measured: main() loads it from --impl

try:  # the fast tracer of the GPU track (a flattened BVH), where it exists
    from course.kernels.trace import trace_bvh
except ImportError:  # pragma: no cover - older checkouts
    trace_bvh = None

SIZES = {
    "cpu": {"size": 32, "reference_pixels": 256, "repeats": 2, "warmup": 1, "layout_rays": 64},
    "cuda": {
        "size": 1024,
        "reference_pixels": 4096,
        "repeats": 5,
        "warmup": 2,
        "layout_rays": 4096,
    },
    "quick": {"size": 16, "reference_pixels": 64, "repeats": 1, "warmup": 1, "layout_rays": 16},
}
MAX_DEPTH = 2
FLIP = 1e-3  # a pixel off by more than this (relative) took another shading decision


def sync(device):
    if device.type == "cuda":
        torch.cuda.synchronize(device)


def organisations(n: int, compile_uber: bool, device) -> list[tuple[str, str, object, dict]]:
    """(label, kind, renderer, keywords) of every organisation measured."""
    rows = [
        ("whitted (full-size loop)", "loop", lab.render_whitted, {}),
        ("wavefront", "wavefront", lab.render_wavefront, {}),
        (
            "wavefront sorted by material",
            "wavefront",
            lab.render_wavefront,
            {"sort_by_material": True},
        ),
        ("uber (eager)", "uber", lab.render_uber, {}),
    ]
    if compile_uber:
        rows.append(("uber (torch.compile)", "uber", lab.render_uber, {"compile": True}))
    for pool in sorted({max(1, n // 4), n}):
        rows.append(
            (f"persistent, pool {pool}", "persistent", lab.render_persistent, {"pool_size": pool})
        )
    return rows


def triton_renderer(device):
    """The Triton uber kernel (traversal + shading in one launch) on CUDA, else None."""
    if device.type != "cuda":
        return None
    try:
        from course.kernels.triton_tracer import render_whitted_triton, triton_available
    except ImportError:
        return None
    return render_whitted_triton if triton_available() else None


def errors(image: torch.Tensor, sample: torch.Tensor, reference: torch.Tensor) -> dict:
    """max_rel_error over the pixels that agree in their decisions, and the flipped fraction."""
    got = image[sample].double().cpu()
    reference = reference.double().cpu()
    rel = ((got - reference).abs() / reference.abs().clamp(min=1e-3)).amax(1)
    flipped = rel > FLIP
    agree = rel[~flipped]
    return {
        "max_rel_error": float(agree.max()) if len(agree) else math.nan,
        "flipped": float(flipped.double().mean()),
    }


def lanes(kind: str, n: int, lights: int, wave: dict, extra: dict) -> tuple[int, int]:
    """(closest-hit lanes, shadow lanes) an organisation traces, live or idle (NaN where
    they depend on the live rays and the lab's wavefront renderer is not written yet)."""
    live_closest, live_shadow = sum(wave["closest_rays"]), sum(wave["shadow_rays"])
    bounces = len(wave["closest_rays"])
    if kind == "loop":  # every lane traced every bounce; shadow rays only for hits
        return n * bounces, live_shadow
    if kind == "uber":  # every lane and every shadow lane, every bounce
        return n * (MAX_DEPTH + 1), n * lights * (MAX_DEPTH + 1)
    if kind == "persistent":
        return extra["work_processed"], extra["shadow_rays"]
    return live_closest, live_shadow


def lanes_or_nan(kind: str, n: int, lights: int, wave: dict | None, extra: dict):
    if wave is None and kind in ("loop", "wavefront"):
        return math.nan, math.nan
    return lanes(kind, n, lights, wave, extra)


def run_scene(name, sizes, device, table, compile_uber, log):
    scene = whitted_scene(name, device=device)
    size = sizes["size"]
    camera = whitted_camera(name, size, size)
    rays = primary_rays(camera, device=device)
    o, d, n = rays.origins, rays.directions, len(rays)
    trace = trace_bvh or trace_brute_force
    start = time.perf_counter()
    trace(
        scene,
        o[:1],
        d[:1],
        torch.zeros(1, device=device),
        torch.full((1,), math.inf, device=device),
        False,
    )
    sync(device)
    log(
        f"{name}: {scene.num_faces} triangles, {n} primary rays, tracer {trace.__name__} "
        f"(first call, with its build: {time.perf_counter() - start:.2f} s)"
    )
    g = torch.Generator().manual_seed(0)
    sample = torch.randperm(n, generator=g)[: min(n, sizes["reference_pixels"])].to(device)
    start = time.perf_counter()
    reference = render_reference(scene, o[sample], d[sample], MAX_DEPTH)
    log(
        f"  reference (float64 brute force) on {len(sample)} pixels: "
        f"{time.perf_counter() - start:.1f} s"
    )
    lights = scene.num_point_lights + scene.num_dir_lights
    try:
        _, wave = lab.render_wavefront(scene, o, d, trace, MAX_DEPTH)
        log(f"  live rays per bounce: closest {wave['closest_rays']}, shadow {wave['shadow_rays']}")
    except NotImplementedError as exc:  # the handout: the live-ray counts are unknown
        wave = None
        log(f"  live rays per bounce unknown: {exc}")
    results = {}
    for label, kind, render, kw in organisations(n, compile_uber, device):
        try:
            timing = time_fn(
                render,
                scene,
                o,
                d,
                trace,
                MAX_DEPTH,
                repeats=sizes["repeats"],
                warmup=sizes["warmup"],
                device=device,
                **kw,
            )
        except Exception as exc:  # noqa: BLE001  (e.g. torch.compile without a C++ compiler)
            log(f"  {label:<32} failed: {type(exc).__name__}: {str(exc).splitlines()[0][:80]}")
            continue
        out = render(scene, o, d, trace, MAX_DEPTH, **kw)
        image, extra = out if isinstance(out, tuple) else (out, {})
        closest, shadow = lanes_or_nan(kind, n, lights, wave, extra)
        row = table.add(
            scene=name,
            organisation=label,
            kind=kind,
            triangles=scene.num_faces,
            pixels=n,
            seconds=timing.median,
            images_per_s=1 / timing.median,
            rays_per_s=(closest + shadow) / timing.median,
            closest_lanes=closest,
            shadow_lanes=shadow,
            lanes=closest + shadow,
            **errors(image, sample, reference),
            **stage_columns(extra if kind == "wavefront" else {}),
            **pool_columns(extra if kind == "persistent" else {}),
        )
        results[label] = extra
        log(
            f"  {label:<32} {row['images_per_s']:9.3f} images/s  {row['rays_per_s']:>13,.0f} "
            f"lanes/s  lanes {closest:>9,.0f} + {shadow:>9,.0f} shadow  max rel err "
            f"{row['max_rel_error']:.2e}, flipped {row['flipped']:.2%}"
        )
    render = triton_renderer(device)
    if render is not None:
        timing = time_fn(
            render,
            scene,
            o,
            d,
            MAX_DEPTH,
            repeats=sizes["repeats"],
            warmup=sizes["warmup"],
            device=device,
        )
        image = render(scene, o, d, MAX_DEPTH)
        row = table.add(
            scene=name,
            organisation="uber (Triton kernel)",
            kind="uber",
            triangles=scene.num_faces,
            pixels=n,
            seconds=timing.median,
            images_per_s=1 / timing.median,
            **errors(image, sample, reference),
        )
        log(
            f"  {'uber (Triton kernel)':<32} {row['images_per_s']:9.3f} images/s  max rel err "
            f"{row['max_rel_error']:.2e}, flipped {row['flipped']:.2%}"
        )
    return results


def stage_columns(stats: dict) -> dict:
    seconds = stats.get("seconds", {})
    return {
        f"{stage}_s": seconds[stage]
        for stage in ("generate", "trace", "shade", "spawn")
        if stage in seconds
    }


def pool_columns(stats: dict) -> dict:
    if not stats:
        return {}
    return {
        "steps": stats["steps"],
        "idle_fraction": stats["idle_fraction"],
        "mean_active_lanes": sum(stats["active_lanes"]) / max(1, stats["steps"]),
    }


def run_layouts(name, sizes, device, table, log):
    """Bytes per triangle and a brute-force pass over each layout (task 5)."""
    scene = whitted_scene(name, device=device)
    mesh = scene.mesh
    camera = whitted_camera(name, 64, 64)
    rays = primary_rays(camera, device=device)
    pick = torch.linspace(0, len(rays) - 1, sizes["layout_rays"], device=device).long()
    o, d = rays.origins[pick], rays.directions[pick]
    t_min, t_max = (
        torch.zeros(len(o), device=device),
        torch.full((len(o),), math.inf, device=device),
    )
    expected = trace_brute_force(scene, o, d, t_min, t_max)
    for label, build in (
        ("indexed", lab.layout_indexed),
        ("float4", lab.layout_float4),
        ("woop", lab.layout_woop),
    ):
        try:
            layout = build(mesh)
            timing = time_fn(
                lab.intersect_layout,
                layout,
                o,
                d,
                t_min,
                t_max,
                repeats=sizes["repeats"],
                warmup=1,
                device=device,
            )
        except NotImplementedError as exc:
            log(f"  layout {label:<8} skipped: {exc}")
            continue
        hits = lab.intersect_layout(layout, o, d, t_min, t_max)
        agree = float((hits.triangle == expected.triangle).double().mean())
        tests = len(o) * mesh.num_faces
        row = table.add(
            scene=name,
            organisation=f"layout {label}",
            kind="layout",
            triangles=mesh.num_faces,
            bytes_per_triangle=layout["bytes_per_triangle"],
            seconds=timing.median,
            tests_per_s=tests / timing.median,
            same_hit=agree,
        )
        log(
            f"  layout {label:<8} {row['bytes_per_triangle']:6.1f} bytes/triangle  "
            f"{row['tests_per_s']:>14,.0f} tests/s  same hit as brute force {agree:.2%}"
        )


def lanes_plot(results: dict, path: Path, title: str) -> None:
    from matplotlib.figure import Figure
    from matplotlib.ticker import MaxNLocator

    fig = Figure(figsize=(6.4, 3.6), layout="constrained")
    ax = fig.add_subplot()
    for label, stats in results.items():
        if "active_lanes" in stats:
            ax.step(
                range(1, stats["steps"] + 1),
                stats["active_lanes"],
                where="mid",
                label=f"{label} (idle {stats['idle_fraction']:.0%})",
            )
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_xlabel("step")
    ax.set_ylabel("active lanes")
    ax.set_title(title)
    ax.legend()
    fig.savefig(path)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--device", default=None, help="cpu or cuda (default: cuda if present)")
    parser.add_argument("--size", type=int, default=None, help="image size S (S x S pixels)")
    parser.add_argument(
        "--reference-pixels",
        type=int,
        default=None,
        help="pixels compared with the float64 reference renderer",
    )
    parser.add_argument("--scenes", default="cornell_mirror,bunny_mirror")
    parser.add_argument(
        "--no-compile",
        action="store_true",
        help="skip the torch.compile'd uber kernel (slow to compile on a CPU)",
    )
    parser.add_argument("--out", default=None, help="output folder")
    parser.add_argument(
        "--threads",
        type=int,
        default=None,
        help="CPU threads for torch (1 gives steadier ratios on a shared CPU)",
    )
    parser.add_argument(
        "--quick",
        action="store_true",
        help="seconds on a CPU: the Cornell box only, 16 x 16 pixels, 64 "
        "compared, no torch.compile, one timed run",
    )
    add_impl_option(parser)
    args = parser.parse_args(argv)
    global lab
    lab = load_lab("lab3_wavefront", args.impl, root=REPO)
    if args.threads:
        torch.set_num_threads(args.threads)
    device = default_device(args.device)
    sizes = dict(SIZES["quick" if args.quick else "cuda" if device.type == "cuda" else "cpu"])
    if args.quick:
        args.no_compile = True
        args.scenes = "cornell_mirror"
    if args.size:
        sizes["size"] = args.size
    if args.reference_pixels:
        sizes["reference_pixels"] = args.reference_pixels
    out = Path(args.out) if args.out else REPO / "bench" / "results" / device_name(device) / "lab3"
    out.mkdir(parents=True, exist_ok=True)
    table = ResultTable("lab3 organising the tracer", device=device)
    table.metadata.update(
        sizes=sizes,
        max_depth=MAX_DEPTH,
        cpu_threads=torch.get_num_threads(),
        tracer=(trace_bvh or trace_brute_force).__name__,
        lab_file=str(lab.__file__),
    )
    start = time.perf_counter()
    names = args.scenes.split(",")
    for name in names:
        results = run_scene(
            name, sizes, device, table, not args.no_compile, lambda text: print(text, flush=True)
        )
        run_layouts(name, sizes, device, table, lambda text: print(text, flush=True))
        if any("active_lanes" in stats for stats in results.values()):
            lanes_plot(
                results,
                out / f"lanes_{name}.png",
                f"{name}: active lanes per step of the persistent pool",
            )
    # The rows of rtcourse bench --lab 3 (course.tools.trade.lab3: the organisations on the
    # Cornell box, error against render_reference), measured on this lab and plotted as a
    # student's are: trade.csv and pareto_trade.png.
    bench_rows(3, lab, device, args.quick, out, lambda text: print(text, flush=True))
    table.to_json(out / "lab3_wavefront.json")
    renders = ResultTable(rows=[r for r in table.rows if r["kind"] != "layout"])
    layouts = ResultTable(rows=[r for r in table.rows if r["kind"] == "layout"])
    (out / "lab3_wavefront.md").write_text(
        f"# Lab 3: organising the tracer on {table.metadata['device']}\n\n"
        f"`{table.metadata['command']}` (torch {table.metadata['torch']}, "
        f"{table.metadata['date']}; tracer {table.metadata['tracer']}, "
        f"{sizes['size']}x{sizes['size']} pixels, max_depth {MAX_DEPTH})\n\n"
        f"Organisations (lanes: closest-hit and shadow rays traced, live or idle; "
        f"max_rel_error where the shading decisions agree, flipped: pixels where a "
        f"shadow/edge decision differs from the float64 reference):\n\n"
        f"{renders.to_markdown()}\n\nGeometry layouts (a brute-force pass over "
        f"{sizes['layout_rays']} rays):\n\n{layouts.to_markdown()}\n"
    )
    for name in names:
        rows = [r for r in table.rows if r["scene"] == name and r["kind"] != "layout"]
        if not rows:  # the handout before any organisation is written: nothing to plot
            continue
        pareto_plot(
            [dict(r, error=r["max_rel_error"] + r["flipped"]) for r in rows],
            x="images_per_s",
            y="error",
            label="organisation",
            group="kind",
            path=out / f"pareto_{name}.png",
            title=f"{name}: error (max rel. + flipped fraction) vs images/s",
        )
        pareto_plot(
            rows,
            x="images_per_s",
            y="lanes",
            label="organisation",
            group="kind",
            path=out / f"pareto_{name}_lanes.png",
            title=f"{name}: lanes traced (closest + shadow) vs images/s",
        )
    print(f"wrote {out} in {time.perf_counter() - start:.0f} s")
    return table


if __name__ == "__main__":
    main()
