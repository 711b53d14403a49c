"""Lab 0's trade: the staging paths that bring a frame from the device to the host.

Knobs: device-to-host copies into pageable and pinned memory (on the CPU a host copy,
one row per size: there is no device), and the frame loop with and without overlapping the
download of frame i-1 with the rendering of frame i. Error: for the frame loop, the
fraction of frames displayed wrong (missing, out of order, or not the frame rendered:
a staging buffer reused too early); a copy is exact by construction (0).
"""

from __future__ import annotations

import torch

MODULE = "lab0_interop"
TITLE = "interop: staging paths (copies, the frame loop)"
ERROR_NAME = "fraction of frames displayed wrong"
ERROR = (
    "frame loop: fraction of frames displayed wrong (missing, out of order, or another "
    "frame's pixels); copies: 0 (exact)"
)
KIB, MIB = 1 << 10, 1 << 20


def prepare(device, quick: bool) -> dict:
    cuda = device.type == "cuda"
    sizes = [256 * KIB, 4 * MIB] if quick else [256 * KIB, 4 * MIB, 64 * MIB]
    frame = (1080, 1920) if cuda and not quick else (90, 160) if quick else (270, 480)
    return {
        "device": device,
        "quick": quick,
        "repeats": 3 if quick else 10,
        "sizes": sizes,
        "frame": frame,
        "frames": 8 if quick else (60 if cuda else 12),
        "pinned": (False, True) if cuda else (False,),
    }


def knobs(ctx: dict) -> list[dict]:
    cuda = ctx["device"].type == "cuda"
    rows = [
        {
            "setting": f"copy {'pinned' if pinned else 'pageable' if cuda else 'host'} "
            f"{nbytes // KIB} KiB",
            "kind": "copy",
            "pinned": pinned,
            "bytes": nbytes,
        }
        for nbytes in ctx["sizes"]
        for pinned in ctx["pinned"]
    ]
    height, width = ctx["frame"]
    rows += [
        {
            "setting": f"frame loop {width}x{height} {'overlap' if overlap else 'serial'}",
            "kind": "frame_loop",
            "overlap": overlap,
            "bytes": 4 * width * height,
        }
        for overlap in (False, True)
    ]
    return rows


def render_stripes(frame_index: int, out: torch.Tensor) -> None:
    """Frame ``frame_index``: every pixel holds ``frame_index * 1000 + its column``, so a
    displayed frame says which frame it is and whether it is whole."""
    width = out.shape[1]
    out.copy_(
        (torch.arange(width, device=out.device, dtype=torch.int32) + 1000 * frame_index).expand_as(
            out
        )
    )


def checksum(frame_index: int, host_frame) -> tuple[int, bool]:
    """(frame index, whether the displayed frame is exactly frame ``frame_index``)."""
    host = torch.as_tensor(host_frame)
    expected = (torch.arange(host.shape[1], dtype=torch.int32) + 1000 * frame_index).expand(
        host.shape
    )
    return frame_index, bool(torch.equal(host.cpu().to(torch.int32), expected))


def measure(lab, ctx: dict, knob: dict) -> dict:
    device = ctx["device"]
    if knob["kind"] == "copy":
        gbps = lab.measure_copy_bandwidth(
            knob["bytes"], knob["pinned"], device, repeats=ctx["repeats"]
        )
        return {"seconds": knob["bytes"] / gbps / 1e9, "error": 0.0, "GB_per_s": gbps}
    n = ctx["frames"]
    lab.run_frame_loop(render_stripes, 2, ctx["frame"], device, overlap=knob["overlap"])
    result = lab.run_frame_loop(
        render_stripes, n, ctx["frame"], device, overlap=knob["overlap"], display=checksum
    )
    shown = list(result.get("displayed") or [])
    right = sum(1 for i, entry in enumerate(shown[:n]) if tuple(entry) == (i, True))
    return {
        "seconds": result["seconds"] / n,
        "error": 1.0 - right / n,
        "frames": n,
        "frames_per_second": result["frames_per_second"],
    }
