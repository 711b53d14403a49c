"""Lab 0 showcase: frames of the rotating triangle, through the whole interop pipeline.

FrameLoop renders into its one packed framebuffer on the device, a FrameDownloader brings
it to (pinned, on CUDA) host memory, unpack_rgba8 turns the words back into sRGB bytes
and course.core.image.from_srgb8 into the linear image the gallery expects.
"""

from __future__ import annotations

import torch

from course.core.image import from_srgb8
from course.measure.bench import time_fn


def render(lab, device, size: int = 256):
    """``(image (size, size, 3) float linear RGB, info)`` for the gallery."""
    device = torch.device(device)
    loop = lab.FrameLoop(size, size, device)
    downloader = lab.FrameDownloader((size, size), device, num_buffers=2)

    def frame():  # render + download + wait, no overlap: the latency of one frame
        downloader.submit(loop.step())
        return downloader.receive()

    timing = time_fn(frame, repeats=10, warmup=2, device=device)
    # The picture: four frames of the loop (0, 10, 20, 30 of its 120-frame turn), each
    # drawn into one quarter-size framebuffer and downloaded through the double-buffered
    # staging, as a 2 x 2 film strip.
    half = size // 2
    strip = lab.FrameLoop(half, half, device)
    small = lab.FrameDownloader((half, half), device, num_buffers=2)
    tiles = []
    for n in (0, 10, 20, 30):
        small.submit(lab.render_rotating_triangle(n, strip.framebuffer))
        tiles.append(from_srgb8(lab.unpack_rgba8(small.receive())[..., :3]))
    image = torch.ones(size, size, 3) * 0.6  # the strip's frame lines
    gap = 1
    for k, tile in enumerate(tiles):
        r, c = divmod(k, 2)
        image[r * half + gap : (r + 1) * half - gap, c * half + gap : (c + 1) * half - gap] = (
            tile.cpu()[gap : half - gap, gap : half - gap]
        )

    nbytes = size * size * 4
    info = {
        "frame_ms": timing.median * 1e3,
        "frames_per_second": 1 / timing.median,
        "frame_bytes": nbytes,
    }
    if device.type == "cuda":
        info["d2h_pageable_GBps"] = lab.measure_copy_bandwidth(nbytes, False, device)
        info["d2h_pinned_GBps"] = lab.measure_copy_bandwidth(nbytes, True, device)
    else:
        info["host_copy_GBps"] = lab.measure_copy_bandwidth(nbytes, False, device)
    return image, info
