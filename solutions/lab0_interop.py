"""Lab 0: interop — sharing buffers between compute and display, in PyTorch terms.

In the lecture a CUDA kernel draws straight into an OpenGL pixel buffer object (PBO):

    glBufferData          allocate the PBO once (W*H RGBA8 texels)
    register              cudaGraphicsGLRegisterBuffer: tell CUDA about the buffer, once
    map                   cudaGraphicsMapResources + GetMappedPointer: a device pointer
    kernel writes         kernel<<<grid, block>>>(ptr, ...): one thread per pixel
    unmap                 cudaGraphicsUnmapResources: hand the buffer back to GL
    draw                  glTexSubImage2D from the PBO, draw a textured quad, swap

No pixel crosses the PCIe bus and nothing is allocated per frame. In this lab you build the
same pipeline with PyTorch pieces:

    the PBO               a contiguous (H, W) int32 tensor: one packed RGBA8 word per pixel
    register / map        zero-copy views: DLPack, numpy, the CUDA array interface
    kernel writes         a vectorised tensor kernel writing into `out` in place
    unmap                 an event recorded after the writes (later work waits on it)
    draw                  an async copy into pinned host memory, then display

Tasks (points):
  1. Packed framebuffers (3): pack_rgba8, unpack_rgba8, linear_to_srgb8
  2. Zero-copy sharing (3): framebuffer_to_numpy, numpy_to_framebuffer, share_dlpack,
     cuda_array_interface
  3. The PBO analogue (3): FrameDownloader (__init__, submit, receive),
     measure_copy_bandwidth, run_frame_loop
  4. Frame loop (2): render_rotating_triangle, FrameLoop (__init__, step)

Run the grader with ``pytest tests/test_lab0_interop.py`` (add ``-k pack_rgba8`` to run the
tests of one function). Everything must work on the CPU and on CUDA with the same code: take
the device from the inputs, never call ``.cuda()``.

A framebuffer is a contiguous ``(H, W)`` int32 tensor: one 32-bit word per pixel holding
RGBA8 with R in bits 0-7, G in 8-15, B in 16-23 and A in 24-31 (GL_RGBA/GL_UNSIGNED_BYTE
read as one little-endian word).
"""

from __future__ import annotations

import collections  # a deque makes a good FIFO of in-flight frames
import math
import time  # for run_frame_loop

import numpy as np
import torch

from course.core.image import srgb_encode  # for linear_to_srgb8
from course.measure.bench import time_fn  # for measure_copy_bandwidth

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


# --------------------------------------------------------------------------------------
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


# --------------------------------------------------------------------------------------
# Task 2: zero-copy sharing (3 points)
#
# "Register + map" gives CUDA a pointer into memory GL owns: two APIs, one buffer. The
# PyTorch equivalents are views: another library's array over the tensor's memory. A view
# is only possible for a contiguous block of the expected type, so check first.


def framebuffer_to_numpy(fb: torch.Tensor) -> np.ndarray:
    """A numpy view of a CPU framebuffer ``fb: (H, W) int32``: same memory, no copy.

    A write through the array is visible in ``fb`` and vice versa;
    ``arr.__array_interface__['data'][0] == fb.data_ptr()``.

    Errors: ValueError naming ``fb`` for a non-contiguous, non-int32 or non-2-D tensor
    (``_check_framebuffer``) and for a CUDA tensor (numpy cannot address GPU memory: the
    caller must download it explicitly; a hidden copy would break the contract).

    Hint: ``Tensor.numpy()`` shares memory; ``np.array(t)`` and ``.copy()`` do not.
    """
    # BEGIN SOLUTION (task 2)
    _check_framebuffer(fb, "fb")
    if fb.device.type != "cpu":
        raise ValueError(
            f"fb: expected a CPU framebuffer (numpy cannot see {fb.device} "
            f"memory); download it first, e.g. with a FrameDownloader"
        )
    return fb.numpy()
    # END SOLUTION


def numpy_to_framebuffer(arr: np.ndarray) -> torch.Tensor:
    """A tensor view of ``arr: (H, W) int32`` C-contiguous numpy array: same memory.

    Errors: TypeError if ``arr`` is not an ndarray; ValueError naming ``arr`` for a wrong
    ndim, a dtype other than int32 or a non-C-contiguous array (``arr.flags.c_contiguous``).

    Hint: ``torch.from_numpy`` shares memory; ``torch.tensor(arr)`` copies.
    """
    # BEGIN SOLUTION (task 2)
    if not isinstance(arr, np.ndarray):
        raise TypeError(f"arr: expected a numpy.ndarray (H, W) int32, got {type(arr).__name__}")
    if arr.ndim != 2:
        raise ValueError(f"arr: expected shape (H, W), got {arr.shape}")
    if arr.dtype != np.int32:
        raise ValueError(f"arr: expected dtype int32, got {arr.dtype}")
    if not arr.flags.c_contiguous:
        raise ValueError(f"arr: expected a C-contiguous array, got strides {arr.strides}")
    return torch.from_numpy(arr)
    # END SOLUTION


def share_dlpack(fb: torch.Tensor) -> torch.Tensor:
    """Re-import ``fb: (H, W) int32`` (any device) through its DLPack export.

    DLPack is the common zero-copy exchange format of array libraries (CuPy, JAX, numba,
    TensorFlow, numpy): the producer exports a capsule (pointer, shape, strides, dtype,
    device), the consumer wraps it. Return the tensor that ``torch.from_dlpack`` builds: a
    new tensor object (not ``fb`` itself) over the same memory, on the same device.

    Errors: ValueError naming ``fb`` as in ``_check_framebuffer``.

    Hint: ``torch.from_dlpack(fb)`` calls ``fb.__dlpack__(stream=...)``; on CUDA the
    producer orders the consumer's stream after work already queued on ``fb``.
    """
    # BEGIN SOLUTION (task 2)
    _check_framebuffer(fb, "fb")
    return torch.from_dlpack(fb)
    # END SOLUTION


def cuda_array_interface(fb: torch.Tensor) -> dict:
    """The CUDA Array Interface (version 3) dict describing a CUDA framebuffer.

    Keys: ``shape`` (H, W) as a tuple, ``typestr`` "<i4" (little-endian 4-byte int),
    ``data`` (fb.data_ptr(), False) — the pointer and a read-only flag, ``strides`` None
    (meaning C-contiguous), ``version`` 3 and ``stream``: the stream a consumer must
    synchronise with (1 means the legacy default stream; 0 is not allowed). numba, CuPy and
    ``torch.as_tensor`` build a view from such a dict alone.

    Errors: ValueError naming ``fb`` as in ``_check_framebuffer``, and for a CPU tensor.

    Hint: ``torch.cuda.current_stream(fb.device).cuda_stream`` is 0 for the default stream.
    """
    # BEGIN SOLUTION (task 2)
    _check_framebuffer(fb, "fb")
    if fb.device.type != "cuda":
        raise ValueError(
            f"fb: the CUDA array interface describes device memory; got a "
            f"framebuffer on {fb.device}"
        )
    stream = torch.cuda.current_stream(fb.device).cuda_stream
    return {
        "shape": tuple(fb.shape),
        "typestr": "<i4",
        "data": (fb.data_ptr(), False),
        "strides": None,
        "version": 3,
        "stream": stream if stream != 0 else 1,
    }
    # END SOLUTION


# --------------------------------------------------------------------------------------
# Task 3: the PBO analogue (3 points)
#
# When the display lives on the host, the frame must cross the bus. Done naively
# (``fb.cpu()``) that allocates pageable memory every frame and blocks until the copy
# ends, so rendering and copying take turns. The PBO trick: copy into a buffer the DMA
# engine can read directly (pinned memory), asynchronously, into one of a few buffers used
# in turn, so frame i renders while frame i-1 downloads.


class FrameDownloader:
    """A ring of ``num_buffers`` host staging buffers for frames of ``shape`` on ``device``.

    On CUDA the buffers are pinned and copies run on a side stream, so the next frame can
    render while the previous one downloads; on the CPU the same calls copy synchronously.
    """

    def __init__(self, shape, device, num_buffers: int = 2):
        """Allocate everything once: ``num_buffers`` host buffers of ``shape`` int32.

        shape: (H, W) positive ints; device: where submitted frames live ("cpu", "cuda").
        On CUDA allocate the buffers with ``pin_memory=True`` (pinned, page-locked memory:
        the GPU's DMA engine reads it directly, so ``copy_(non_blocking=True)`` is truly
        asynchronous) and create a side ``torch.cuda.Stream`` for the copies. Pinned memory
        needs CUDA, so on the CPU allocate plain buffers and no stream.

        Errors: ValueError naming ``shape`` unless it is two positive ints, and naming
        ``num_buffers`` unless it is an int >= 1.

        Hint: keep a FIFO (``collections.deque``) of the slots in flight and the index of
        the next slot to write.
        """
        # BEGIN SOLUTION (task 3)
        if (
            not isinstance(shape, (tuple, list, torch.Size))
            or len(shape) != 2
            or not all(isinstance(s, int) and s > 0 for s in shape)
        ):
            raise ValueError(f"shape: expected (H, W) with positive ints, got {shape!r}")
        if not isinstance(num_buffers, int) or num_buffers < 1:
            raise ValueError(f"num_buffers: expected an int >= 1, got {num_buffers!r}")
        self.shape = tuple(shape)
        self.device = torch.device(device)
        cuda = self.device.type == "cuda"
        # Pinned (page-locked) memory lets the DMA engine copy without a bounce buffer.
        self.buffers = [
            torch.empty(self.shape, dtype=torch.int32, pin_memory=cuda) for _ in range(num_buffers)
        ]
        self.stream = torch.cuda.Stream(self.device) if cuda else None
        self.done = [None] * num_buffers  # per slot: event recorded after its copy
        self.pending = collections.deque()  # slots submitted and not yet received, oldest first
        self.next_slot = 0
        # END SOLUTION

    def submit(self, frame: torch.Tensor) -> None:
        """Start copying ``frame: (H, W) int32`` on ``device`` into the next staging buffer.

        On CUDA, in this order:
        1. record an event on the current stream (after the kernels that wrote ``frame``)
           and make the side stream wait for it: the copy must not read a half-drawn frame;
        2. on the side stream, ``buffer.copy_(frame, non_blocking=True)`` and record a
           "copy done" event for that slot;
        3. ``frame.record_stream(side_stream)``: the caching allocator must not reuse
           ``frame``'s memory before the side stream read it.
        On the CPU, just copy.

        Errors: RuntimeError when all ``num_buffers`` buffers are in flight (submitted, not
        yet received): the copy would overwrite a frame nobody has seen. ValueError naming
        ``frame`` for a wrong shape, dtype, device or a non-contiguous tensor.
        """
        # BEGIN SOLUTION (task 3)
        _check_framebuffer(frame, "frame")
        if tuple(frame.shape) != self.shape or frame.device.type != self.device.type:
            raise ValueError(
                f"frame: expected shape {self.shape} on {self.device}, got "
                f"{tuple(frame.shape)} on {frame.device}"
            )
        if len(self.pending) == len(self.buffers):
            raise RuntimeError(
                f"all {len(self.buffers)} staging buffers are in flight: "
                f"receive() a frame before submitting another"
            )
        slot = self.next_slot
        if self.stream is None:
            self.buffers[slot].copy_(frame)
        else:
            rendered = torch.cuda.Event()
            rendered.record()  # on the current stream, after the kernels that wrote frame
            self.stream.wait_event(rendered)
            with torch.cuda.stream(self.stream):
                self.buffers[slot].copy_(frame, non_blocking=True)
                done = torch.cuda.Event()
                done.record()
            # The allocator must not hand frame's memory out again before the copy read it.
            frame.record_stream(self.stream)
            self.done[slot] = done
        self.pending.append(slot)
        self.next_slot = (slot + 1) % len(self.buffers)
        # END SOLUTION

    def receive(self) -> torch.Tensor:
        """The oldest submitted frame (first in, first out), once its copy finished.

        Returns the host staging buffer itself (no copy: like mapping the PBO for reading),
        after waiting for its "copy done" event (``event.synchronize()``). The buffer is
        reused by a later submit(): read or copy it before submitting again.

        Errors: RuntimeError when no frame is in flight.
        """
        # BEGIN SOLUTION (task 3)
        if not self.pending:
            raise RuntimeError("receive(): no frame was submitted")
        slot = self.pending.popleft()
        if self.done[slot] is not None:
            self.done[slot].synchronize()
        return self.buffers[slot]
        # END SOLUTION


def measure_copy_bandwidth(nbytes: int, pinned: bool, device, repeats: int = 5) -> float:
    """Device-to-host copy bandwidth in GB/s (1e9 bytes/s) for a block of ``nbytes``:
    ``nbytes / median / 1e9`` with ``median`` the seconds per copy that the given ``time_fn``
    reports over ``repeats`` copies (the graders may stub that clock).

    On CUDA: a device tensor of ``nbytes`` uint8 copied into pinned (``pinned=True``) or
    pageable host memory. On the CPU there is no device: measure a host-to-host copy and
    ignore ``pinned`` (say so in what you report).

    Errors: ValueError naming ``nbytes`` unless it is a positive int (``repeats`` alike).

    Hints:
    - Allocate both buffers once, outside the timed function.
    - ``time_fn(fn, *args, repeats=..., warmup=1, device=device)`` returns a Timing in
      seconds per call (CUDA events on the GPU).
    - ``dst.copy_(src, non_blocking=True)`` is asynchronous only into pinned memory.
    """
    # BEGIN SOLUTION (task 3)
    if not isinstance(nbytes, int) or nbytes < 1:
        raise ValueError(f"nbytes: expected a positive int, got {nbytes!r}")
    if not isinstance(repeats, int) or repeats < 1:
        raise ValueError(f"repeats: expected an int >= 1, got {repeats!r}")
    device = torch.device(device)
    cuda = device.type == "cuda"
    src = torch.ones(nbytes, dtype=torch.uint8, device=device)
    dst = torch.empty(nbytes, dtype=torch.uint8, pin_memory=cuda and pinned)
    timing = time_fn(
        dst.copy_, src, non_blocking=cuda and pinned, repeats=repeats, warmup=1, device=device
    )
    return nbytes / timing.median / 1e9
    # END SOLUTION


def run_frame_loop(
    render, n_frames: int, shape, device, overlap: bool = True, display=None
) -> dict:
    """Render, download and display ``n_frames`` frames of ``shape`` on ``device``.

    render(frame_index, out): writes frame ``frame_index`` into ``out`` (H, W) int32.
    display(frame_index, host_frame): optional; its return values are collected in order.

    With ``overlap`` use two device framebuffers and a FrameDownloader with two staging
    buffers: render frame i, submit it, then receive and display frame i-1 (the GPU renders
    frame i meanwhile); after the loop display the last frame. Without ``overlap`` use one
    framebuffer and receive + display each frame right after submitting it. Allocate
    nothing inside the loop.

    Returns a dict: ``frames`` (n_frames), ``seconds`` (wall time of the loop, with the
    device synchronised before and after), ``frames_per_second`` (float), ``overlap``, and
    ``displayed`` (display's return values, frame 0 first; [] without display).

    Errors: TypeError naming ``render`` (or ``display``) if it is not callable; ValueError
    naming ``n_frames`` unless it is an int >= 1.

    Hint: with two framebuffers, framebuffer i % 2 was last read by frame i-2's copy, which
    you already received (waited for) — so rendering into it is safe.
    """
    # BEGIN SOLUTION (task 3)
    if not callable(render):
        raise TypeError(
            f"render: expected a callable render(frame_index, out), got {type(render).__name__}"
        )
    if display is not None and not callable(display):
        raise TypeError(f"display: expected None or a callable, got {type(display).__name__}")
    if not isinstance(n_frames, int) or n_frames < 1:
        raise ValueError(f"n_frames: expected an int >= 1, got {n_frames!r}")
    device = torch.device(device)
    downloader = FrameDownloader(shape, device, num_buffers=2)
    framebuffers = [torch.empty(shape, dtype=torch.int32, device=device) for _ in range(2)]
    displayed = []

    def show(index):
        host = downloader.receive()
        if display is not None:
            displayed.append(display(index, host))

    if device.type == "cuda":
        torch.cuda.synchronize(device)
    start = time.perf_counter()
    for i in range(n_frames):
        # framebuffers[i % 2] was last read by frame i-2's copy, received (waited for) already.
        fb = framebuffers[i % 2] if overlap else framebuffers[0]
        render(i, fb)
        downloader.submit(fb)
        if not overlap:
            show(i)
        elif i > 0:
            show(i - 1)  # frame i renders on the GPU meanwhile
    if overlap:
        show(n_frames - 1)
    if device.type == "cuda":
        torch.cuda.synchronize(device)
    seconds = time.perf_counter() - start
    return {
        "frames": n_frames,
        "seconds": seconds,
        "frames_per_second": n_frames / seconds,
        "overlap": overlap,
        "displayed": displayed,
    }
    # END SOLUTION


# --------------------------------------------------------------------------------------
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
