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
