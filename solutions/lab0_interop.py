"""Lab 0: interop — sharing buffers between compute and display, in PyTorch terms.

The lecture's CUDA/OpenGL interop sequence and what each step becomes here:

    OpenGL + CUDA                               PyTorch
    -------------------------------------------------------------------------------
    glBufferData (a PBO of W*H RGBA8 texels)    torch.empty((H, W), dtype=torch.int32)
    cudaGraphicsGLRegisterBuffer                a DLPack capsule / CUDA array interface
    cudaGraphicsMapResources + GetMappedPointer torch.from_dlpack(...), tensor.numpy()
    kernel<<<...>>> writes the pixels           render_rotating_triangle(i, out=fb)
    cudaGraphicsUnmapResources                  an event recorded after the writes
    glTexSubImage2D from the PBO + draw         an async copy to pinned host memory,
                                                then display (imshow, a PNG, a widget)

Tasks (points):
  1. Packed framebuffers (3): pack_rgba8, unpack_rgba8, linear_to_srgb8
  2. Zero-copy sharing (3): framebuffer_to_numpy, numpy_to_framebuffer, share_dlpack,
     cuda_array_interface
  3. The PBO analogue (3): FrameDownloader, measure_copy_bandwidth, run_frame_loop
  4. Frame loop (2): render_rotating_triangle, FrameLoop

A framebuffer is a contiguous ``(H, W)`` int32 tensor: one 32-bit word per pixel holding
RGBA8 with R in bits 0-7, G in 8-15, B in 16-23 and A in 24-31 (GL_RGBA/GL_UNSIGNED_BYTE
read as one little-endian word).
"""

from __future__ import annotations

import collections
import math
import time

import numpy as np
import torch

from course.core.image import srgb_encode
from course.measure.bench import time_fn

BACKGROUND_RGBA = (16, 16, 24, 255)  # the frame loop's clear colour, 8-bit sRGB


def _check_framebuffer(fb, name: str) -> torch.Tensor:
    """Raise unless ``fb`` is a contiguous 2-D int32 tensor (a packed framebuffer)."""
    if not isinstance(fb, torch.Tensor):
        raise TypeError(f"{name}: expected a torch.Tensor framebuffer of shape (H, W) int32, "
                        f"got {type(fb).__name__}")
    if fb.dim() != 2:
        raise ValueError(f"{name}: expected a framebuffer of shape (H, W), got shape "
                         f"{tuple(fb.shape)}")
    if fb.dtype != torch.int32:
        raise ValueError(f"{name}: expected dtype torch.int32 (packed RGBA8), got {fb.dtype}")
    if not fb.is_contiguous():
        raise ValueError(f"{name}: expected a contiguous framebuffer (row-major, strides "
                         f"(W, 1)), got strides {fb.stride()}; a display reads one flat block")
    return fb


# --------------------------------------------------------------------------------------
# Task 1: packed framebuffers


def pack_rgba8(rgba: torch.Tensor) -> torch.Tensor:
    """Pack ``rgba: (H, W, 4) uint8`` into one int32 word per pixel, ``(H, W)``.

    word = R | G << 8 | B << 16 | A << 24, stored as two's complement int32 (alpha >= 128
    gives a negative word). Same device as the input; any H, W >= 1 and any strided input
    (a crop, every other column, a channel-last view of a planar image) give the words of
    its pixels; the result is a new contiguous tensor.
    """
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


def unpack_rgba8(packed: torch.Tensor) -> torch.Tensor:
    """Unpack ``packed: (H, W) int32`` words into ``(H, W, 4) uint8`` RGBA; inverse of pack."""
    if not isinstance(packed, torch.Tensor):
        raise TypeError(f"packed: expected a torch.Tensor (H, W) int32, "
                        f"got {type(packed).__name__}")
    if packed.dim() != 2:
        raise ValueError(f"packed: expected shape (H, W), got {tuple(packed.shape)}")
    if packed.dtype != torch.int32:
        raise ValueError(f"packed: expected dtype torch.int32, got {packed.dtype}")
    shifts = torch.tensor([0, 8, 16, 24], dtype=torch.int32, device=packed.device)
    # >> on int32 is arithmetic (copies the sign bit in); the mask keeps only the byte.
    return ((packed.unsqueeze(-1) >> shifts) & 0xFF).to(torch.uint8)


def linear_to_srgb8(img: torch.Tensor) -> torch.Tensor:
    """Encode a linear RGB image ``(H, W, 3)`` float (any float dtype) as sRGB uint8.

    code = floor(255 * srgb_encode(clamp(x, 0, 1)) + 0.5), computed in at least float32;
    NaN -> 0, -inf -> 0, +inf -> 255. Same device as the input.
    """
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


# --------------------------------------------------------------------------------------
# Task 2: zero-copy sharing


def framebuffer_to_numpy(fb: torch.Tensor) -> np.ndarray:
    """A numpy view of a CPU framebuffer ``fb: (H, W) int32``: same memory, no copy."""
    _check_framebuffer(fb, "fb")
    if fb.device.type != "cpu":
        raise ValueError(f"fb: expected a CPU framebuffer (numpy cannot see {fb.device} "
                         f"memory); download it first, e.g. with a FrameDownloader")
    return fb.numpy()


def numpy_to_framebuffer(arr: np.ndarray) -> torch.Tensor:
    """A tensor view of ``arr: (H, W) int32`` C-contiguous numpy array: same memory."""
    if not isinstance(arr, np.ndarray):
        raise TypeError(f"arr: expected a numpy.ndarray (H, W) int32, got {type(arr).__name__}")
    if arr.ndim != 2:
        raise ValueError(f"arr: expected shape (H, W), got {arr.shape}")
    if arr.dtype != np.int32:
        raise ValueError(f"arr: expected dtype int32, got {arr.dtype}")
    if not arr.flags.c_contiguous:
        raise ValueError(f"arr: expected a C-contiguous array, got strides {arr.strides}")
    return torch.from_numpy(arr)


def share_dlpack(fb: torch.Tensor) -> torch.Tensor:
    """Re-import ``fb: (H, W) int32`` (any device) through its DLPack export.

    The result is a new tensor object over the same memory, as any DLPack consumer
    (CuPy, JAX, numba, TensorFlow) would see it.
    """
    _check_framebuffer(fb, "fb")
    # from_dlpack calls fb.__dlpack__(stream=...): on CUDA the producer makes the
    # consumer's stream wait for work already queued on fb.
    return torch.from_dlpack(fb)


def cuda_array_interface(fb: torch.Tensor) -> dict:
    """The CUDA Array Interface (version 3) dict describing a CUDA framebuffer.

    Keys: shape (H, W), typestr "<i4", data (pointer, False), strides None (C-contiguous),
    version 3, stream (the producer's stream: 1 stands for the legacy default stream).
    """
    _check_framebuffer(fb, "fb")
    if fb.device.type != "cuda":
        raise ValueError(f"fb: the CUDA array interface describes device memory; got a "
                         f"framebuffer on {fb.device}")
    stream = torch.cuda.current_stream(fb.device).cuda_stream
    return {"shape": tuple(fb.shape), "typestr": "<i4", "data": (fb.data_ptr(), False),
            "strides": None, "version": 3, "stream": stream if stream != 0 else 1}


# --------------------------------------------------------------------------------------
# Task 3: the PBO analogue


class FrameDownloader:
    """A ring of ``num_buffers`` host staging buffers for frames of ``shape`` on ``device``.

    On CUDA the buffers are pinned and copies run on a side stream, so the next frame can
    render while the previous one downloads; on the CPU the same calls copy synchronously.
    """

    def __init__(self, shape, device, num_buffers: int = 2):
        if (not isinstance(shape, (tuple, list, torch.Size)) or len(shape) != 2
                or not all(isinstance(s, int) and s > 0 for s in shape)):
            raise ValueError(f"shape: expected (H, W) with positive ints, got {shape!r}")
        if not isinstance(num_buffers, int) or num_buffers < 1:
            raise ValueError(f"num_buffers: expected an int >= 1, got {num_buffers!r}")
        self.shape = tuple(shape)
        self.device = torch.device(device)
        cuda = self.device.type == "cuda"
        # Pinned (page-locked) memory lets the DMA engine copy without a bounce buffer.
        self.buffers = [torch.empty(self.shape, dtype=torch.int32, pin_memory=cuda)
                        for _ in range(num_buffers)]
        self.stream = torch.cuda.Stream(self.device) if cuda else None
        self.done = [None] * num_buffers  # per slot: event recorded after its copy
        self.pending = collections.deque()  # slots submitted and not yet received, oldest first
        self.next_slot = 0

    def submit(self, frame: torch.Tensor) -> None:
        """Start copying ``frame: (H, W) int32`` on ``device`` into the next staging buffer."""
        _check_framebuffer(frame, "frame")
        if tuple(frame.shape) != self.shape or frame.device.type != self.device.type:
            raise ValueError(f"frame: expected shape {self.shape} on {self.device}, got "
                             f"{tuple(frame.shape)} on {frame.device}")
        if len(self.pending) == len(self.buffers):
            raise RuntimeError(f"all {len(self.buffers)} staging buffers are in flight: "
                               f"receive() a frame before submitting another")
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

    def receive(self) -> torch.Tensor:
        """The oldest submitted frame, as its host staging buffer, once its copy finished.

        The buffer is reused by a later submit(): read or copy it before submitting again.
        """
        if not self.pending:
            raise RuntimeError("receive(): no frame was submitted")
        slot = self.pending.popleft()
        if self.done[slot] is not None:
            self.done[slot].synchronize()
        return self.buffers[slot]


def measure_copy_bandwidth(nbytes: int, pinned: bool, device, repeats: int = 5) -> float:
    """Device-to-host copy bandwidth in GB/s (1e9 bytes/s) for a block of ``nbytes``.

    On CUDA the destination is pinned or pageable host memory. On the CPU there is no
    device: this measures a host-to-host copy and ``pinned`` is ignored.
    """
    if not isinstance(nbytes, int) or nbytes < 1:
        raise ValueError(f"nbytes: expected a positive int, got {nbytes!r}")
    if not isinstance(repeats, int) or repeats < 1:
        raise ValueError(f"repeats: expected an int >= 1, got {repeats!r}")
    device = torch.device(device)
    cuda = device.type == "cuda"
    src = torch.ones(nbytes, dtype=torch.uint8, device=device)
    dst = torch.empty(nbytes, dtype=torch.uint8, pin_memory=cuda and pinned)
    timing = time_fn(dst.copy_, src, non_blocking=cuda and pinned, repeats=repeats, warmup=1,
                     device=device)
    return nbytes / timing.median / 1e9


def run_frame_loop(render, n_frames: int, shape, device, overlap: bool = True,
                   display=None) -> dict:
    """Render, download and display ``n_frames`` frames of ``shape`` on ``device``.

    render(frame_index, out): writes frame ``frame_index`` into ``out`` (H, W) int32.
    display(frame_index, host_frame): optional; its return values are collected in order.
    With ``overlap`` the loop renders frame i while frame i-1 downloads and is displayed
    (two device framebuffers, two staging buffers); without it every frame waits for its
    own download. Returns frames, seconds, frames_per_second, overlap and displayed.
    """
    if not callable(render):
        raise TypeError(f"render: expected a callable render(frame_index, out), got "
                        f"{type(render).__name__}")
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
    return {"frames": n_frames, "seconds": seconds, "frames_per_second": n_frames / seconds,
            "overlap": overlap, "displayed": displayed}


# --------------------------------------------------------------------------------------
# Task 4: frame loop


def triangle_vertices(frame_index: int, width: int, height: int, period: int = 120):
    """The rotating triangle's vertices at ``frame_index``, as three (x, y) float pairs.

    Pixel coordinates (x right, y down); v_k = (W/2 + r cos a_k, H/2 - r sin a_k) with
    r = 0.4 min(W, H), a_k = 2 pi ((frame_index mod period) / period + k / 3).
    """
    theta = 2 * math.pi * (frame_index % period) / period
    r = 0.4 * min(width, height)
    return [(width / 2 + r * math.cos(theta + 2 * math.pi * k / 3),
             height / 2 - r * math.sin(theta + 2 * math.pi * k / 3)) for k in range(3)]


def render_rotating_triangle(frame_index: int, out: torch.Tensor, *, period: int = 120):
    """Draw frame ``frame_index`` of the rotating RGB triangle into ``out: (H, W) int32``.

    Pixel (x, y) samples its centre (x + 0.5, y + 0.5). Vertices: ``triangle_vertices``.
    Inside (all barycentrics >= 0): colour floor(255 b_k + 0.5) from red, green, blue at
    v0, v1, v2, alpha 255. Outside: BACKGROUND_RGBA. Writes ``out`` in place, returns it.

    Accuracy contract: float32 is fine; pixels whose centre lies within 1e-4 pixel of an
    edge may go either way.
    """
    if isinstance(frame_index, bool) or not isinstance(frame_index, int):
        raise TypeError(f"frame_index: expected an int, got {type(frame_index).__name__}")
    if isinstance(period, bool) or not isinstance(period, int) or period < 1:
        raise ValueError(f"period: expected an int >= 1, got {period!r}")
    if not isinstance(out, torch.Tensor) or out.dim() != 2 or out.dtype != torch.int32:
        got = (f"{tuple(out.shape)} {out.dtype}" if isinstance(out, torch.Tensor)
               else type(out).__name__)
        raise ValueError(f"out: expected a framebuffer (H, W) int32, got {got}")
    height, width = out.shape
    (x0, y0), (x1, y1), (x2, y2) = triangle_vertices(frame_index, width, height, period)
    dev = out.device
    px = torch.arange(width, device=dev, dtype=torch.float32).view(1, -1) + 0.5
    py = torch.arange(height, device=dev, dtype=torch.float32).view(-1, 1) + 0.5

    def edge(ax, ay, bx, by):  # twice the signed area of (a, b, pixel centre)
        return (bx - ax) * (py - ay) - (by - ay) * (px - ax)

    area = (x1 - x0) * (y2 - y0) - (y1 - y0) * (x2 - x0)
    bary = torch.stack([edge(x1, y1, x2, y2), edge(x2, y2, x0, y0), edge(x0, y0, x1, y1)],
                       dim=-1) / area  # (H, W, 3): weights of v0, v1, v2
    inside = (bary >= 0).all(dim=-1, keepdim=True)
    rgb = torch.floor(bary.clamp(0, 1) * 255 + 0.5)
    background = torch.tensor(BACKGROUND_RGBA[:3], dtype=rgb.dtype, device=dev)
    rgb = torch.where(inside, rgb, background)
    alpha = torch.full_like(rgb[..., :1], 255)
    out.copy_(pack_rgba8(torch.cat([rgb, alpha], dim=-1).to(torch.uint8)))
    return out


class FrameLoop:
    """The display loop's producer: one ``(height, width)`` framebuffer on ``device``, reused.

    step() renders the next frame of the rotating triangle into the same framebuffer (like
    a registered PBO: allocated once, written every frame) and returns it.

    Attributes: ``framebuffer`` (height, width) int32 on ``device``; ``frame_index``, the
    frame the next step() renders (starts at 0); ``period`` as in render_rotating_triangle.
    """

    def __init__(self, width: int, height: int, device, *, period: int = 120):
        for name, value in (("width", width), ("height", height)):
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"{name}: expected a positive int, got {value!r}")
        self.period = period
        self.frame_index = 0
        self.framebuffer = torch.empty((height, width), dtype=torch.int32,
                                       device=torch.device(device))

    def step(self) -> torch.Tensor:
        """Render frame ``frame_index`` into the framebuffer, advance, return the framebuffer."""
        render_rotating_triangle(self.frame_index, self.framebuffer, period=self.period)
        self.frame_index += 1
        return self.framebuffer
