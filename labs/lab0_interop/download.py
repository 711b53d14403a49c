"""Task 3: the PBO analogue: ``FrameDownloader`` (``__init__``, ``submit``, ``receive``),
``measure_copy_bandwidth``, ``run_frame_loop``.
"""

from __future__ import annotations

import collections  # a deque makes a good FIFO of in-flight frames
import time  # for run_frame_loop

import torch

from course.measure.bench import time_fn  # for measure_copy_bandwidth

from .framebuffer import _check_framebuffer

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
        raise NotImplementedError("not implemented yet: FrameDownloader.__init__ (task 3)")

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
        raise NotImplementedError("not implemented yet: FrameDownloader.submit (task 3)")

    def receive(self) -> torch.Tensor:
        """The oldest submitted frame (first in, first out), once its copy finished.

        Returns the host staging buffer itself (no copy: like mapping the PBO for reading),
        after waiting for its "copy done" event (``event.synchronize()``). The buffer is
        reused by a later submit(): read or copy it before submitting again.

        Errors: RuntimeError when no frame is in flight.
        """
        raise NotImplementedError("not implemented yet: FrameDownloader.receive (task 3)")


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
    raise NotImplementedError("not implemented yet: measure_copy_bandwidth (task 3)")


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
    raise NotImplementedError("not implemented yet: run_frame_loop (task 3)")
