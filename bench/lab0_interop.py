"""Lab 0 bench: what it costs to bring a frame from the device to the display.

Measures (1) device-to-host copy bandwidth into pageable and pinned memory over block
sizes from 64 KiB to 128 MiB, and (2) frames/s of the render -> download -> display loop
with and without overlapping the download of frame i-1 with the rendering of frame i.

    python bench/lab0_interop.py --device cuda
    python bench/lab0_interop.py --device cpu --out bench/results/cpu/lab0_interop.json

On the CPU there is no device: the "copy" rows time a host-to-host copy (pinned memory
needs CUDA, so there is one row per size) and overlap cannot help; read those numbers as
the baseline the GPU rows are compared with, not as interop costs.

The rows are those of ``course.tools.trade.lab0`` (the staging paths of ``rtcourse bench
--lab 0``, which puts a student's points over the reference's), at this script's sizes: the
frame loop renders a known pattern, so each row also says which fraction of the frames
was displayed wrong (``error``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from course.core.device import default_device
from course.measure.bench import ResultTable, device_name, load_lab
from course.tools.trade import lab0 as trade

KIB, MIB = 1 << 10, 1 << 20
COPY_SIZES = [64 * KIB, 256 * KIB, MIB, 4 * MIB, 16 * MIB, 64 * MIB, 128 * MIB]
FRAME_SIZES = [(512, 512), (1080, 1920), (2160, 3840)]  # (H, W)


def measure(lab, device, quick: bool) -> ResultTable:
    """The rows of ``course.tools.trade.lab0`` (what ``rtcourse bench --lab 0`` measures, with
    the same error: frames displayed wrong) at this script's sizes."""
    table = ResultTable("lab0 interop: device-to-host copies and the frame loop", device)
    cuda = device.type == "cuda"
    ctx = trade.prepare(device, quick)
    ctx["sizes"] = COPY_SIZES[:4] if quick else COPY_SIZES
    ctx["repeats"] = 10
    frames = FRAME_SIZES[:1] if quick else FRAME_SIZES if cuda else FRAME_SIZES[:2]
    ctx["frames"] = 60 if cuda else 5
    knobs = [k for k in trade.knobs(ctx) if k["kind"] == "copy"]
    for height, width in frames:
        ctx["frame"] = (height, width)
        knobs += [
            dict(k, height=height, width=width)
            for k in trade.knobs(ctx)
            if k["kind"] == "frame_loop"
        ]
    for knob in knobs:
        if knob["kind"] == "frame_loop":
            ctx["frame"] = (knob["height"], knob["width"])
        row = trade.measure(lab, ctx, knob)
        if knob["kind"] == "copy":
            kind = ("d2h " + ("pinned" if knob["pinned"] else "pageable")) if cuda else "host copy"
            table.add(
                kind="copy",
                setting=kind,
                nbytes=knob["bytes"],
                pinned=knob["pinned"],
                seconds=row["seconds"],
                GB_per_s=row["GB_per_s"],
                error=row["error"],
            )
            print(f"  {kind:<13} {knob['bytes'] / MIB:9.3f} MiB  {row['GB_per_s']:8.2f} GB/s")
        else:
            width, height, overlap = knob["width"], knob["height"], knob["overlap"]
            table.add(
                kind="frame_loop",
                setting=f"{width}x{height} overlap={overlap}",
                width=width,
                height=height,
                overlap=overlap,
                frames=row["frames"],
                seconds=row["seconds"],
                frames_per_second=row["frames_per_second"],
                error=row["error"],
            )
            print(
                f"  frame loop {width}x{height} overlap={overlap!s:<5} "
                f"{row['frames_per_second']:8.1f} frames/s, {row['error']:.0%} shown wrong"
            )
    return table


def plot(table: ResultTable, path: Path):
    from matplotlib.figure import Figure

    fig = Figure(figsize=(11, 4.2), layout="constrained")
    left, right = fig.subplots(1, 2)
    copies = [r for r in table.rows if r["kind"] == "copy"]
    for setting in dict.fromkeys(r["setting"] for r in copies):
        rows = [r for r in copies if r["setting"] == setting]
        left.plot(
            [r["nbytes"] / MIB for r in rows], [r["GB_per_s"] for r in rows], "o-", label=setting
        )
    left.set_xscale("log")
    left.set_xlabel("block size (MiB)")
    left.set_ylabel("GB/s (higher is better)")
    left.set_title("copy bandwidth")
    left.grid(True, which="both", alpha=0.3)
    left.legend()
    loops = [r for r in table.rows if r["kind"] == "frame_loop"]
    labels = [
        f"{r['width']}x{r['height']}\n{'overlap' if r['overlap'] else 'serial'}" for r in loops
    ]
    right.bar(
        range(len(loops)),
        [r["frames_per_second"] for r in loops],
        color=["tab:blue" if r["overlap"] else "tab:gray" for r in loops],
    )
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
    parser.add_argument(
        "--out",
        default=None,
        help="result JSON (default: "
        "bench/results/<device>/lab0_interop.json); the plot goes next to it",
    )
    parser.add_argument(
        "--impl",
        default=None,
        help="solutions (the default where it exists), labs, or a folder holding lab0_interop/",
    )
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
