"""Task 3: the visibility buffer: 64-bit (depth | id) keys (``pack_depth_id``,
``triangle_ids``), their atomic minimum (``depth_test``) and ``rasterize``, which resolves
screen-space triangles chunk by chunk.
"""

from __future__ import annotations

import math

import torch

from course.given.lab6 import (
    BYTES_PER_FRAGMENT,
    EMPTY,
    ID_BITS,
    ID_MASK,
    any_shape,
    check_screen,
    check_size,
    check_tensor,
    fragment_depth,
)

from .edges import bounding_boxes, coverage


def pack_depth_id(depth, triangle, depth_bits: int = 32):
    """64-bit keys that order fragments by depth, then by triangle id.

    depth: (N,) float, non-negative (nearer is smaller); triangle: (N,) int64 ids in
    ``[0, 2**32)``; depth_bits: 32 or 24. Returns (N,) int64
    ``key = (quantised_depth << 32) | triangle``: comparing keys as integers compares
    depths first and breaks exact ties by the lower id, so one ``atomicMin`` per fragment
    resolves visibility and keeps the winner's id.

    * 32 bits: the float32 bit pattern of the depth. For non-negative IEEE floats the bit
      pattern, read as an integer, increases with the value (exponent above mantissa, both
      unsigned; the sign bit is 0), so no conversion is needed and the full float precision
      is kept. ``-0.0`` has the sign bit set and must become ``+0.0`` first; NaN sorts as
      ``+inf`` (farthest).
    * 24 bits: a unorm24 depth buffer: ``round(clamp(depth, 0, 1) * (2**24 - 1))`` (computed
      in float64), for depths in [0, 1] (window z). Fewer bits: nearby surfaces quantise to
      equal keys and the id, not the depth, decides (z-fighting).

    Errors: ValueError or TypeError naming ``depth`` (not a 1-D float tensor), ``triangle``
    (not int64 of the length of ``depth``, or an id outside ``[0, 2**32)``: a negative id
    would fill the depth bits with ones) or ``depth_bits`` (not 24 or 32).

    Hints: ``x.view(torch.int32)`` reinterprets float32 bits; ``torch.where(depth > 0, depth,
    0)`` turns -0.0 (and NaN) into +0.0, so deal with NaN first (``torch.isnan``).
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    check_tensor(depth, "depth", (None,))
    check_tensor(triangle, "triangle", (depth.shape[0],), kind="int64", like=depth)
    if depth_bits not in (24, 32):
        raise ValueError(f"depth_bits: expected 24 or 32, got {depth_bits!r}")
    # BEGIN SOLUTION (task 3)
    if triangle.numel() and (int(triangle.min()) < 0 or int(triangle.max()) > ID_MASK):
        raise ValueError(
            f"triangle: expected ids in [0, 2**{ID_BITS}), got values in "
            f"[{int(triangle.min())}, {int(triangle.max())}]"
        )
    depth = torch.where(torch.isnan(depth), math.inf, depth)
    depth = torch.where(depth > 0, depth, torch.zeros_like(depth))  # -0.0 and below -> +0.0
    if depth_bits == 32:
        quantised = depth.to(torch.float32).view(torch.int32).to(torch.int64)
    else:
        # In float64: float32 would round depth * (2**24 - 1) before the rounding to an integer.
        quantised = torch.round(depth.to(torch.float64).clamp(max=1.0) * (2**24 - 1)).to(
            torch.int64
        )
    return (quantised << ID_BITS) | triangle
    # END SOLUTION


def triangle_ids(keys):
    """The triangle id in each key: (...) int64 -> (...) int64, -1 where ``EMPTY``.

    Hints: ``keys & ID_MASK``; ``torch.where``.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    check_tensor(keys, "keys", any_shape(keys), kind="int64")
    # BEGIN SOLUTION (task 3)
    return torch.where(keys == EMPTY, -1, keys & ID_MASK)
    # END SOLUTION


def depth_test(pixel, key, out):
    """Resolve fragments into a visibility buffer: ``out[p] = min(out[p], keys of p)``.

    pixel: (N,) int64 indices into ``out``; key: (N,) int64 packed keys; out: (P,) int64,
    updated in place and returned (start from ``EMPTY`` everywhere for a new frame).

    One ``scatter_reduce_(0, pixel, key, reduce="amin")``: for every pixel, the minimum over
    all its fragments, however many there are and in whatever order they come. It is the
    batched form of one ``atomicMin(&buffer[pixel], key)`` per GPU thread; a plain
    read-compare-write (``out[pixel] = minimum(out[pixel], key)``) is a race: among
    fragments of one pixel the last writer wins, not the nearest.

    Errors: ValueError or TypeError naming ``out`` (not a 1-D int64 tensor), ``key`` (not
    int64 of the length of ``pixel``) or ``pixel`` (not int64, or an index outside
    ``[0, P)``: check it first, torch's own error for it names no argument).

    Hints: ``Tensor.scatter_reduce_`` with ``reduce="amin"`` (``include_self=True``, the default,
    keeps what ``out`` already holds).
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    check_tensor(out, "out", (None,), kind="int64")
    check_tensor(pixel, "pixel", (None,), kind="int64", like=out)
    check_tensor(key, "key", (pixel.shape[0],), kind="int64", like=out)
    # BEGIN SOLUTION (task 3)
    if pixel.numel() and (int(pixel.min()) < 0 or int(pixel.max()) >= out.shape[0]):
        raise ValueError(
            f"pixel: expected indices in [0, {out.shape[0]}), got values in "
            f"[{int(pixel.min())}, {int(pixel.max())}]"
        )
    out.scatter_reduce_(0, pixel, key, reduce="amin")
    return out
    # END SOLUTION


def rasterize(
    screen,
    width: int,
    height: int,
    *,
    depth_bits: int = 32,
    cull_backfaces: bool = False,
    memory_budget_bytes: int = 2**28,
    out=None,
):
    """The visibility buffer of screen-space triangles.

    screen: (K, 3, 4) float ``(x, y, z_ndc, 1/w)`` (``to_screen``'s output); width, height:
    the viewport; depth_bits: 32 or 24 (see ``pack_depth_id``); cull_backfaces: as in
    ``coverage``; memory_budget_bytes: bounds the fragments alive at once; out: optional
    (width * height,) int64 buffer to write (every element is written). Returns the
    (width * height,) int64 keys: ``EMPTY`` where no triangle covers the pixel centre, else
    ``pack_depth_id(depth, k)`` of the nearest triangle ``k`` (an index into ``screen``);
    exact depth ties go to the lowest ``k``.

    Clear ``out`` to ``EMPTY``; walk the triangles in chunks (consecutive, as many triangles
    as fit) whose bounding boxes hold at most ``memory_budget_bytes // BYTES_PER_FRAGMENT``
    pixels (at least one triangle per chunk); per chunk: ``coverage``, the fragment depth
    (see ``fragment_depth``; fragments beyond the far plane, ``z_ndc > 1``, are dropped),
    ``pack_depth_id`` with the chunk's offset added to the ids, ``depth_test``. The atomic
    minimum makes the result independent of the chunking and of the triangle order: bit for
    bit the same keys.

    Errors: ValueError or TypeError naming ``screen`` (not a (K, 3, 4) float tensor) or
    ``out`` (not a (width * height,) int64 tensor on the screen's device); ValueError naming
    ``width`` / ``height`` (not positive ints <= 32768), ``depth_bits`` (not 24 or 32) or
    ``memory_budget_bytes`` (not a positive int).

    Hints: plan the chunks on the host: ``ends = torch.cumsum(sizes, 0).cpu()`` and
    ``torch.searchsorted(ends, before + per_chunk, right=True)`` find where a chunk ends; a
    Python loop over chunks (not triangles) is fine. ``fragment_depth`` is provided.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    check_screen(screen)
    if screen.shape[2] != 4:
        raise ValueError(
            f"screen: expected shape (K, 3, 4) (x, y, z_ndc, 1/w), got {tuple(screen.shape)}"
        )
    check_size(width, height)
    if depth_bits not in (24, 32):
        raise ValueError(f"depth_bits: expected 24 or 32, got {depth_bits!r}")
    if (
        isinstance(memory_budget_bytes, bool)
        or not isinstance(memory_budget_bytes, int)
        or memory_budget_bytes <= 0
    ):
        raise ValueError(
            f"memory_budget_bytes: expected a positive int, got {memory_budget_bytes!r}"
        )
    # BEGIN SOLUTION (task 3)
    if out is None:
        out = torch.empty(width * height, dtype=torch.int64, device=screen.device)
    check_tensor(out, "out", (width * height,), kind="int64", like=screen)
    out.fill_(EMPTY)
    boxes = bounding_boxes(screen, width, height)
    sizes = (boxes[:, 2] - boxes[:, 0]) * (boxes[:, 3] - boxes[:, 1])
    ends = torch.cumsum(sizes, 0).cpu()  # chunk planning on the host: one small copy
    per_chunk = max(1, memory_budget_bytes // BYTES_PER_FRAGMENT)
    K, first = screen.shape[0], 0
    while first < K:
        before = int(ends[first - 1]) if first else 0
        last = max(first + 1, int(torch.searchsorted(ends, before + per_chunk, right=True)))
        chunk = screen[first:last]
        triangle, pixel, bary = coverage(chunk, width, height, cull_backfaces)
        depth, in_range = fragment_depth(chunk, triangle, bary, depth_bits)
        keys = pack_depth_id(depth[in_range], triangle[in_range] + first, depth_bits)
        depth_test(pixel[in_range], keys, out)
        first = last
    return out
    # END SOLUTION
