"""Profile one sync-free BVH traversal (Lab 2) on CUDA: where its device time goes.

    python bench/lab2_profile.py --size 1024 --compile reduce-overhead --out DIR [--impl labs]

Traces the bunny's primary rays once to compile and warm up, then once under
``torch.profiler``: writes the kernel table (``profile.txt``), where the device waits for the
host (its idle gaps, by the host operation running then; the trace itself in
``trace.json``), and the rays that still run after every look at them (how much of the
work compaction can save). Then where the host
time goes (``host.txt``): the wall time of warm traversals without any profiler, before
the profilers ran in the process and after, and one under ``cProfile`` (Python's own
profiler: every Python function with the host time spent in it, a sync counted where the
host waits), the functions sorted by cumulative time.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

import torch

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))  # run from a checkout without installing

from course.core.camera import primary_rays
from course.core.scenes import load_scene
from course.given.lab2 import pack_bvh
from course.measure.bench import add_impl_option, load_lab


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=1024)
    parser.add_argument("--compile", default="reduce-overhead")
    parser.add_argument("--check-every", type=int, default=16)
    parser.add_argument("--no-compact", action="store_true")
    parser.add_argument("--out", default=".")
    add_impl_option(parser)
    args = parser.parse_args(argv)
    if not torch.cuda.is_available():
        raise SystemExit(
            "lab2_profile: it profiles the traversal on CUDA, and this machine "
            "has no CUDA device (bench/lab2_accel.py measures it on the CPU)"
        )
    lab = load_lab("lab2_accel", args.impl, root=REPO)
    scene = load_scene("bunny", device="cuda")
    mesh = scene.mesh
    bvh = lab.build_sah_bvh(mesh)
    walk = pack_bvh(bvh, mesh)
    rays = primary_rays(
        dataclasses.replace(scene.camera, width=args.size, height=args.size), device="cuda"
    )
    knobs = {
        "check_every": args.check_every,
        "compile": args.compile,
        "walk": walk,
        "compact": not args.no_compact,
    }
    _, counters = lab.bvh_closest_hit_fast(rays, mesh, bvh, **knobs)  # compile, warm up
    lab.bvh_closest_hit_fast(rays, mesh, bvh, **knobs)
    torch.cuda.synchronize()
    # Warm traversals before any profiler runs in this process (the device's activity
    # tracing, once started, can stay attached and slow every later launch).
    before = wall_time(lambda: lab.bvh_closest_hit_fast(rays, mesh, bvh, **knobs), len(rays))
    with torch.profiler.profile(
        activities=[torch.profiler.ProfilerActivity.CPU, torch.profiler.ProfilerActivity.CUDA]
    ) as prof:
        lab.bvh_closest_hit_fast(rays, mesh, bvh, **knobs)
        torch.cuda.synchronize()
    table = prof.key_averages().table(sort_by="cuda_time_total", row_limit=25)
    trace_path = Path(args.out) / "trace.json"
    Path(args.out).mkdir(parents=True, exist_ok=True)
    prof.export_chrome_trace(str(trace_path))
    idle = idle_report(trace_path)
    steps = counters["steps"] + counters["tests"]
    started = int((steps > 0).sum())
    lines = [
        (
            f"{len(rays):,} rays, {started:,} start (hit the root box); steps per ray: "
            f"mean {steps.double().mean():.1f}, max {int(steps.max())}"
        ),
        (
            "still running after s steps: "
            + ", ".join(f"{s}: {int((steps > s).sum()):,}" for s in (16, 32, 48, 64, 96, 128, 192))
        ),
    ]
    text = "\n".join(lines) + "\n\n" + idle + "\n\n" + table
    print(text)
    (Path(args.out) / "profile.txt").write_text(f"{' '.join(sys.argv)}\n\n{text}\n")
    host = host_time(lambda: lab.bvh_closest_hit_fast(rays, mesh, bvh, **knobs), len(rays))
    host = f"before the profilers ran: {before}\nafter them: {host}"
    print(host)
    (Path(args.out) / "host.txt").write_text(f"{' '.join(sys.argv)}\n\n{host}\n")


def idle_report(trace_path: Path, gap_us: float = 5.0, shown: int = 12) -> str:
    """Where the device waits, from a chrome trace of one traversal: the wall time from the
    first to the last device event, the time the device is busy (kernels and copies, their
    union), and the gaps longer than ``gap_us`` with the host operation that was running
    when each began (the one the device waits for)."""
    import json

    events = json.loads(trace_path.read_text())["traceEvents"]
    device = sorted(
        (e["ts"], e["ts"] + e.get("dur", 0))
        for e in events
        if e.get("ph") == "X" and e.get("cat") in ("kernel", "gpu_memcpy", "gpu_memset")
    )
    host = [e for e in events if e.get("ph") == "X" and e.get("cat") == "cpu_op"]
    if not device:
        return "no device events in the trace"
    busy, gaps, end = 0.0, [], device[0][0]
    for start, stop in device:
        if start > end:
            gaps.append((start - end, end))
        busy += max(0.0, stop - max(start, end))
        end = max(end, stop)
    wall = end - device[0][0]

    def running(t):  # the innermost host op around time t
        around = [e for e in host if e["ts"] <= t <= e["ts"] + e.get("dur", 0)]
        return min(around, key=lambda e: e.get("dur", 0))["name"] if around else "(Python)"

    long = sorted((g for g in gaps if g[0] > gap_us), reverse=True)
    by_op: dict = {}
    for length, at in long:
        op = running(at)
        by_op[op] = by_op.get(op, 0.0) + length
    lines = [
        (
            f"device busy {busy / 1e3:.2f} ms of {wall / 1e3:.2f} ms from its first event "
            f"to its last; {len(long)} gaps over {gap_us:g} us, "
            f"{sum(g for g, _ in long) / 1e3:.2f} ms in all; the host was in (total gap ms):"
        )
    ]
    lines += [
        f"  {ms / 1e3:7.3f}  {name}"
        for name, ms in sorted(by_op.items(), key=lambda kv: -kv[1])[:shown]
    ]
    return "\n".join(lines)


def host_time(trace, n_rays: int, repeats: int = 10) -> str:
    """Wall time of ``repeats`` warm traversals (each synced), then one under cProfile: the
    report's text."""
    import cProfile
    import io
    import pstats

    walls = _walls(trace, repeats)
    profiler = cProfile.Profile()
    torch.cuda.synchronize()
    profiler.enable()
    trace()
    torch.cuda.synchronize()
    profiler.disable()
    listing = io.StringIO()
    pstats.Stats(profiler, stream=listing).sort_stats("cumulative").print_stats(40)
    # Paths relative to the repository and to torch's folder: the report reads the same on
    # any machine.
    text = (
        listing.getvalue()
        .replace(f"{REPO}/", "")
        .replace(f"{Path(torch.__file__).parent.parent}/", "<site-packages>/")
    )
    return (
        f"{_wall_text(walls, n_rays)}\n\n"
        f"one traversal under cProfile (host time per Python function; a sync is "
        f"time spent waiting in the call that reads the device):\n{text}"
    )


def _walls(trace, repeats: int) -> list:
    """Seconds of ``repeats`` warm traversals, each synced."""
    import time

    walls = []
    for _ in range(repeats):
        torch.cuda.synchronize()
        start = time.perf_counter()
        trace()
        torch.cuda.synchronize()
        walls.append(time.perf_counter() - start)
    return walls


def _wall_text(walls: list, n_rays: int) -> str:
    import statistics

    wall = statistics.median(walls)
    return (
        f"warm traversal, no profiler: median {wall * 1e3:.2f} ms of {len(walls)} "
        f"({n_rays / wall / 1e6:.0f} M rays/s); min {min(walls) * 1e3:.2f} ms"
    )


def wall_time(trace, n_rays: int, repeats: int = 10) -> str:
    """Wall time of ``repeats`` warm traversals (each synced), as text."""
    return _wall_text(_walls(trace, repeats), n_rays)


if __name__ == "__main__":
    main()
