"""Given: the packed framebuffer's input check and the frame loop's clear colour, for every
task of the lab (not a task: nothing to write here).
"""

from __future__ import annotations

import torch

BACKGROUND_RGBA = (16, 16, 24, 255)  # the frame loop's clear colour, 8-bit sRGB


def _check_framebuffer(fb, name: str) -> torch.Tensor:
    """Raise unless ``fb`` is a contiguous 2-D int32 tensor (a packed framebuffer).

    Given: use it in tasks 2-4 so that every function reports bad framebuffers the same way.
    """
    if not isinstance(fb, torch.Tensor):
        raise TypeError(
            f"{name}: expected a torch.Tensor framebuffer of shape (H, W) int32, "
            f"got {type(fb).__name__}"
        )
    if fb.dim() != 2:
        raise ValueError(
            f"{name}: expected a framebuffer of shape (H, W), got shape {tuple(fb.shape)}"
        )
    if fb.dtype != torch.int32:
        raise ValueError(f"{name}: expected dtype torch.int32 (packed RGBA8), got {fb.dtype}")
    if not fb.is_contiguous():
        raise ValueError(
            f"{name}: expected a contiguous framebuffer (row-major, strides "
            f"(W, 1)), got strides {fb.stride()}; a display reads one flat block"
        )
    return fb
