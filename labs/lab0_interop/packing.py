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
    raise NotImplementedError("not implemented yet: pack_rgba8 (task 1)")


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
    raise NotImplementedError("not implemented yet: unpack_rgba8 (task 1)")


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
    raise NotImplementedError("not implemented yet: linear_to_srgb8 (task 1)")
