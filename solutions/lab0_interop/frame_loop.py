"""Task 4: the frame loop: ``render_rotating_triangle``, ``FrameLoop`` (``__init__``,
``step``); and the given ``triangle_vertices``.
"""

from __future__ import annotations

import math

import torch

from .framebuffer import BACKGROUND_RGBA
from .packing import pack_rgba8

# Task 4: frame loop (2 points)
#
# The compute-rasterizer tutorial's first frame: a triangle, rotating, drawn by a kernel
# that evaluates three edge functions at every pixel centre (one thread per pixel). Here
# "one thread per pixel" becomes "one tensor element per pixel": no Python loop over pixels.


def triangle_vertices(frame_index: int, width: int, height: int, period: int = 120):
    """The rotating triangle's vertices at ``frame_index``, as three (x, y) float pairs.

    Given. Pixel coordinates (x right, y down); v_k = (W/2 + r cos a_k, H/2 - r sin a_k)
    with r = 0.4 min(W, H), a_k = 2 pi ((frame_index mod period) / period + k / 3).
    """
    theta = 2 * math.pi * (frame_index % period) / period
    r = 0.4 * min(width, height)
    return [
        (
            width / 2 + r * math.cos(theta + 2 * math.pi * k / 3),
            height / 2 - r * math.sin(theta + 2 * math.pi * k / 3),
        )
        for k in range(3)
    ]


def render_rotating_triangle(frame_index: int, out: torch.Tensor, *, period: int = 120):
    """Draw frame ``frame_index`` of the rotating RGB triangle into ``out: (H, W) int32``.

    Pixel (x, y) samples its centre p = (x + 0.5, y + 0.5). With the vertices v0, v1, v2 of
    ``triangle_vertices(frame_index, W, H, period)`` and the edge function
    E(a, b, p) = (b.x - a.x)(p.y - a.y) - (b.y - a.y)(p.x - a.x), the barycentrics are
    b0 = E(v1, v2, p) / A, b1 = E(v2, v0, p) / A, b2 = E(v0, v1, p) / A, A = E(v0, v1, v2).
    Inside (all b_k >= 0): RGBA (floor(255 b0 + 0.5), floor(255 b1 + 0.5),
    floor(255 b2 + 0.5), 255) — red at v0, green at v1, blue at v2. Outside:
    BACKGROUND_RGBA. Every pixel of ``out`` is written, in place; returns ``out``.

    Accuracy contract: float32 is fine; pixels whose centre lies within 1e-4 pixel of an
    edge may go either way. The frame repeats every ``period`` frames.

    Errors: TypeError naming ``frame_index`` unless it is an int; ValueError naming
    ``period`` unless it is an int >= 1; ValueError naming ``out`` unless it is a 2-D int32
    tensor.

    Hints:
    - ``torch.arange(W) + 0.5`` as a row and ``torch.arange(H) + 0.5`` as a column
      broadcast to the (H, W) grid; create them on ``out.device``.
    - Dividing by A makes the test orientation-independent: no winding order to get wrong.
    - ``torch.where`` picks triangle or background colour; ``pack_rgba8`` packs; finish
      with ``out.copy_(...)`` (writing into ``out`` is the point: no new framebuffer).
    """
    # BEGIN SOLUTION (task 4)
    if isinstance(frame_index, bool) or not isinstance(frame_index, int):
        raise TypeError(f"frame_index: expected an int, got {type(frame_index).__name__}")
    if isinstance(period, bool) or not isinstance(period, int) or period < 1:
        raise ValueError(f"period: expected an int >= 1, got {period!r}")
    if not isinstance(out, torch.Tensor) or out.dim() != 2 or out.dtype != torch.int32:
        got = (
            f"{tuple(out.shape)} {out.dtype}"
            if isinstance(out, torch.Tensor)
            else type(out).__name__
        )
        raise ValueError(f"out: expected a framebuffer (H, W) int32, got {got}")
    height, width = out.shape
    (x0, y0), (x1, y1), (x2, y2) = triangle_vertices(frame_index, width, height, period)
    dev = out.device
    px = torch.arange(width, device=dev, dtype=torch.float32).view(1, -1) + 0.5
    py = torch.arange(height, device=dev, dtype=torch.float32).view(-1, 1) + 0.5

    def edge(ax, ay, bx, by):  # twice the signed area of (a, b, pixel centre)
        return (bx - ax) * (py - ay) - (by - ay) * (px - ax)

    area = (x1 - x0) * (y2 - y0) - (y1 - y0) * (x2 - x0)
    bary = (
        torch.stack([edge(x1, y1, x2, y2), edge(x2, y2, x0, y0), edge(x0, y0, x1, y1)], dim=-1)
        / area
    )  # (H, W, 3): weights of v0, v1, v2
    inside = (bary >= 0).all(dim=-1, keepdim=True)
    rgb = torch.floor(bary.clamp(0, 1) * 255 + 0.5)
    background = torch.tensor(BACKGROUND_RGBA[:3], dtype=rgb.dtype, device=dev)
    rgb = torch.where(inside, rgb, background)
    alpha = torch.full_like(rgb[..., :1], 255)
    out.copy_(pack_rgba8(torch.cat([rgb, alpha], dim=-1).to(torch.uint8)))
    return out
    # END SOLUTION


class FrameLoop:
    """The display loop's producer: one ``(height, width)`` framebuffer on ``device``, reused.

    step() renders the next frame of the rotating triangle into the same framebuffer (like
    a registered PBO: allocated once, written every frame) and returns it.

    Attributes: ``framebuffer`` (height, width) int32 on ``device``; ``frame_index``, the
    frame the next step() renders (starts at 0); ``period`` as in render_rotating_triangle.
    """

    def __init__(self, width: int, height: int, device, *, period: int = 120):
        """Allocate the framebuffer (height, width) int32 on ``device`` once; start at frame 0.

        Errors: ValueError naming ``width`` / ``height`` unless each is a positive int.
        """
        # BEGIN SOLUTION (task 4)
        for name, value in (("width", width), ("height", height)):
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"{name}: expected a positive int, got {value!r}")
        self.period = period
        self.frame_index = 0
        self.framebuffer = torch.empty(
            (height, width), dtype=torch.int32, device=torch.device(device)
        )
        # END SOLUTION

    def step(self) -> torch.Tensor:
        """Render the current frame into the framebuffer, advance the frame index, and
        return the framebuffer (the same tensor every time: check ``data_ptr()``)."""
        # BEGIN SOLUTION (task 4)
        render_rotating_triangle(self.frame_index, self.framebuffer, period=self.period)
        self.frame_index += 1
        return self.framebuffer
        # END SOLUTION
