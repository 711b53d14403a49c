"""Lab 0 bench: what it costs to bring a frame from the device to the display.

Measures (1) device-to-host copy bandwidth into pageable and pinned memory over block
sizes from 64 KiB to 128 MiB, and (2) frames/s of the render -> download -> display loop
with and without overlapping the download of frame i-1 with the rendering of frame i.

    python bench/lab0_interop.py --device cuda
    python bench/lab0_interop.py --device cpu --out bench/results/cpu/lab0_interop.json

On the CPU there is no device: the "copy" rows time a host-to-host copy (pinned memory
needs CUDA, so there is one row per size) and overlap cannot help; read those numbers as
the baseline the GPU rows are compared with, not as interop costs.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from course.core.device import default_device
from course.measure.bench import ResultTable, device_name, load_lab

KIB, MIB = 1 << 10, 1 << 20
COPY_SIZES = [64 * KIB, 256 * KIB, MIB, 4 * MIB, 16 * MIB, 64 * MIB, 128 * MIB]
FRAME_SIZES = [(512, 512), (1080, 1920), (2160, 3840)]  # (H, W)


def measure(lab, device, quick: bool) -> ResultTable:
    table = ResultTable("lab0 interop: device-to-host copies and the frame loop", device)
    cuda = device.type == "cuda"
    sizes = COPY_SIZES[:4] if quick else COPY_SIZES
    for nbytes in sizes:
        for pinned in ([False, True] if cuda else [False]):
            gbps = lab.measure_copy_bandwidth(nbytes, pinned, device, repeats=10)
            kind = ("d2h " + ("pinned" if pinned else "pageable")) if cuda else "host copy"
            table.add(kind="copy", setting=kind, nbytes=nbytes, pinned=pinned,
                      seconds=nbytes / gbps / 1e9, GB_per_s=gbps)
            print(f"  {kind:<13} {nbytes / MIB:9.3f} MiB  {gbps:8.2f} GB/s")
    frames = FRAME_SIZES[:1] if quick else FRAME_SIZES if cuda else FRAME_SIZES[:2]
    for height, width in frames:
        n_frames = 60 if cuda else 5
        # warm-up: the first frames pay for allocator growth and kernel loading
        lab.run_frame_loop(lab.render_rotating_triangle, 3, (height, width), device)
        for overlap in (False, True):
            result = lab.run_frame_loop(lab.render_rotating_triangle, n_frames,
                                        (height, width), device, overlap=overlap)
            table.add(kind="frame_loop", setting=f"{width}x{height} overlap={overlap}",
                      width=width, height=height, overlap=overlap, frames=n_frames,
                      seconds=result["seconds"] / n_frames,
                      frames_per_second=result["frames_per_second"])
            print(f"  frame loop {width}x{height} overlap={overlap!s:<5} "
                  f"{result['frames_per_second']:8.1f} frames/s")
    return table


def plot(table: ResultTable, path: Path):
    from matplotlib.figure import Figure

    fig = Figure(figsize=(11, 4.2), layout="constrained")
    left, right = fig.subplots(1, 2)
    copies = [r for r in table.rows if r["kind"] == "copy"]
    for setting in dict.fromkeys(r["setting"] for r in copies):
        rows = [r for r in copies if r["setting"] == setting]
        left.plot([r["nbytes"] / MIB for r in rows], [r["GB_per_s"] for r in rows], "o-",
                  label=setting)
    left.set_xscale("log")
    left.set_xlabel("block size (MiB)")
    left.set_ylabel("GB/s (higher is better)")
    left.set_title("copy bandwidth")
    left.grid(True, which="both", alpha=0.3)
    left.legend()
    loops = [r for r in table.rows if r["kind"] == "frame_loop"]
    labels = [f"{r['width']}x{r['height']}\n{'overlap' if r['overlap'] else 'serial'}"
              for r in loops]
    right.bar(range(len(loops)), [r["frames_per_second"] for r in loops],
              color=["tab:blue" if r["overlap"] else "tab:gray" for r in loops])
    right.set_xticks(range(len(loops)), labels, fontsize=8)
    right.set_ylabel("frames/s (higher is better)")
    right.set_title("render -> download -> display")
    fig.suptitle(f"Lab 0 on {table.metadata['device']}")
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=150)
    return path


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--device", default=None, help="cpu or cuda (default: cuda if present)")
    parser.add_argument("--out", default=None, help="result JSON (default: "
                        "bench/results/<device>/lab0_interop.json); the plot goes next to it")
    parser.add_argument("--impl", default=None, help="solutions (the default where it "
                        "exists), labs, or a folder holding lab0_interop.py")
    parser.add_argument("--quick", action="store_true", help="small sizes only")
    args = parser.parse_args(argv)
    device = default_device(args.device)
    out = Path(args.out) if args.out else ROOT / "bench" / "results" / device_name(device)
    if out.suffix != ".json":  # a folder
        out = out / "lab0_interop.json"
    print(f"lab 0 interop bench on {device}")
    table = measure(load_lab("lab0_interop", args.impl), device, args.quick)
    print(f"wrote {table.to_json(out)}")
    print(f"wrote {plot(table, out.with_suffix('.png'))}")
    print(table.to_markdown())


if __name__ == "__main__":
    main()
