"""Task 1: packed framebuffers: ``pack_rgba8``, ``unpack_rgba8``, ``linear_to_srgb8``."""

from __future__ import annotations

import torch

from course.core.image import srgb_encode  # for linear_to_srgb8

# Task 1: packed framebuffers (3 points)
#
# A display wants 4 bytes per pixel in one flat block. Packing the four channels into one
# int32 word lets one thread write a whole pixel with one 32-bit store (coalesced), exactly
# what a CUDA kernel writing a GL_RGBA8 PBO does.


def pack_rgba8(rgba: torch.Tensor) -> torch.Tensor:
    """Pack ``rgba: (H, W, 4) uint8`` into one int32 word per pixel, ``(H, W)``.

    word = R | G << 8 | B << 16 | A << 24, stored as two's complement int32 (alpha >= 128
    gives a negative word). Same device as the input; any H, W >= 1 and any strided input
    (a crop, every other column, a channel-last view of a planar image) give the words of
    its pixels; the result is a new contiguous tensor.

    Example: RGBA (0x12, 0x34, 0x56, 0x78) -> 0x78563412; (255, 0, 0, 255) -> 0xFF0000FF,
    which as an int32 is 0xFF0000FF - 2**32 = -16776961.

    Errors: TypeError if ``rgba`` is not a tensor; ValueError naming ``rgba`` for a wrong
    shape or a dtype other than uint8.

    Hints:
    - uint8 << 8 overflows in uint8. Widen first: int64 holds any 32-bit unsigned word.
    - Words >= 2**31 do not fit an int32: subtract 2**32 (two's complement) before
      converting, so the conversion never depends on overflow behaviour.
    - (Curious: on a little-endian machine ``rgba.view(torch.int32)`` gives the same bits
      without any arithmetic. Why does it need a contiguous input?)
    """
    # BEGIN SOLUTION (task 1)
    if not isinstance(rgba, torch.Tensor):
        raise TypeError(f"rgba: expected a torch.Tensor (H, W, 4) uint8, got {type(rgba).__name__}")
    if rgba.dim() != 3 or rgba.shape[-1] != 4:
        raise ValueError(f"rgba: expected shape (H, W, 4), got {tuple(rgba.shape)}")
    if rgba.dtype != torch.uint8:
        raise ValueError(f"rgba: expected dtype torch.uint8, got {rgba.dtype}")
    c = rgba.to(torch.int64)  # room for the 32-bit unsigned word before wrapping
    word = c[..., 0] | (c[..., 1] << 8) | (c[..., 2] << 16) | (c[..., 3] << 24)
    word = torch.where(word >= 2**31, word - 2**32, word)  # two's complement, explicitly
    return word.to(torch.int32)
    # END SOLUTION


def unpack_rgba8(packed: torch.Tensor) -> torch.Tensor:
    """Unpack ``packed: (H, W) int32`` words into ``(H, W, 4) uint8`` RGBA; inverse of pack.

    unpack_rgba8(pack_rgba8(x)) == x for every x, and pack_rgba8(unpack_rgba8(w)) == w for
    every bit pattern w (negative words included). Same device as the input.

    Errors: TypeError if ``packed`` is not a tensor; ValueError naming ``packed`` for a
    wrong shape or a dtype other than int32.

    Hints:
    - Shift each channel down to bits 0-7 and mask with 0xFF. On int32, ``>>`` is an
      arithmetic shift: a negative word shifts ones in at the top, which the mask removes.
    - Integer division is not a shift for negative numbers (C truncates towards zero).
    - Broadcasting ``packed.unsqueeze(-1) >> shifts`` with shifts = [0, 8, 16, 24] does all
      four channels at once.
    """
    # BEGIN SOLUTION (task 1)
    if not isinstance(packed, torch.Tensor):
        raise TypeError(
            f"packed: expected a torch.Tensor (H, W) int32, got {type(packed).__name__}"
        )
    if packed.dim() != 2:
        raise ValueError(f"packed: expected shape (H, W), got {tuple(packed.shape)}")
    if packed.dtype != torch.int32:
        raise ValueError(f"packed: expected dtype torch.int32, got {packed.dtype}")
    shifts = torch.tensor([0, 8, 16, 24], dtype=torch.int32, device=packed.device)
    # >> on int32 is arithmetic (copies the sign bit in); the mask keeps only the byte.
    return ((packed.unsqueeze(-1) >> shifts) & 0xFF).to(torch.uint8)
    # END SOLUTION


def linear_to_srgb8(img: torch.Tensor) -> torch.Tensor:
    """Encode a linear RGB image ``(H, W, 3)`` float (any float dtype) as sRGB uint8.

    code = floor(255 * srgb(clamp(x, 0, 1)) + 0.5) (round half up), where srgb is the sRGB
    OETF: ``12.92 x`` for x <= 0.0031308, else ``1.055 x^(1/2.4) - 0.055``
    (``course.core.image.srgb_encode``). NaN -> 0, -inf -> 0, +inf -> 255. Same device.

    Accuracy contract: every input gets the code the float64 formula gives, except inputs
    whose 255 * srgb + 0.5 lies within about 1e-4 of an integer (a decision boundary).

    Errors: TypeError if ``img`` is not a tensor; ValueError naming ``img`` for a wrong
    shape or a non-float dtype.

    Hints:
    - float16 has 11 significant bits: 255 * x + 0.5 is not exact in it, and bfloat16 is
      worse. Convert to at least float32 first (``torch.promote_types`` keeps float64).
    - ``torch.nan_to_num`` and ``clamp`` before encoding; ``.to(torch.uint8)`` on a value
      outside [0, 255] or NaN is not defined behaviour you can rely on.
    - ``floor(v + 0.5)`` is not ``torch.round(v)``: round() sends halves to the even code.
    """
    # BEGIN SOLUTION (task 1)
    if not isinstance(img, torch.Tensor):
        raise TypeError(f"img: expected a torch.Tensor (H, W, 3) float, got {type(img).__name__}")
    if img.dim() != 3 or img.shape[-1] != 3:
        raise ValueError(f"img: expected shape (H, W, 3), got {tuple(img.shape)}")
    if not img.is_floating_point():
        raise ValueError(f"img: expected a floating-point dtype, got {img.dtype}")
    # fp16 cannot even hold 255 * x + 0.5 exactly: widen before any arithmetic.
    x = img.to(torch.promote_types(img.dtype, torch.float32))
    x = torch.nan_to_num(x, nan=0.0, posinf=1.0, neginf=0.0).clamp(0.0, 1.0)
    return torch.floor(srgb_encode(x) * 255 + 0.5).to(torch.uint8)
    # END SOLUTION
