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

Tasks (points), one file each:
  1. ``packing.py``, packed framebuffers (3): pack_rgba8, unpack_rgba8, linear_to_srgb8
  2. ``sharing.py``, zero-copy sharing (3): framebuffer_to_numpy, numpy_to_framebuffer,
     share_dlpack, cuda_array_interface
  3. ``download.py``, the PBO analogue (3): FrameDownloader (__init__, submit, receive),
     measure_copy_bandwidth, run_frame_loop
  4. ``frame_loop.py``, frame loop (2): render_rotating_triangle, FrameLoop (__init__, step)

The lab is this package: the graders load ``lab0_interop/`` and call the functions this
file imports from its modules. ``framebuffer.py`` holds the given framebuffer check
(``_check_framebuffer``) and the frame loop's clear colour (``BACKGROUND_RGBA``);
``frame_loop.py`` the given ``triangle_vertices``. A module calls another task's function
through its import (``from .packing import pack_rgba8`` in ``frame_loop.py``), so a grader
that stands a given function in for yours is seen there too. Hand in the files you edit
(see ``labs/README.md``): a file you leave out is graded as this skeleton's, so it costs
only its own tasks.

Run the grader with ``pytest tests/test_lab0_interop.py`` (add ``-k pack_rgba8`` to run the
tests of one function). Everything must work on the CPU and on CUDA with the same code: take
the device from the inputs, never call ``.cuda()``.

A framebuffer is a contiguous ``(H, W)`` int32 tensor: one 32-bit word per pixel holding
RGBA8 with R in bits 0-7, G in 8-15, B in 16-23 and A in 24-31 (GL_RGBA/GL_UNSIGNED_BYTE
read as one little-endian word).
"""

from __future__ import annotations

from course.measure.bench import time_fn

from .download import FrameDownloader, measure_copy_bandwidth, run_frame_loop
from .frame_loop import FrameLoop, render_rotating_triangle, triangle_vertices
from .framebuffer import BACKGROUND_RGBA, _check_framebuffer
from .packing import linear_to_srgb8, pack_rgba8, unpack_rgba8
from .sharing import (
    cuda_array_interface,
    framebuffer_to_numpy,
    numpy_to_framebuffer,
    share_dlpack,
)

__all__ = [
    # task 1
    "pack_rgba8",
    "unpack_rgba8",
    "linear_to_srgb8",
    # task 2
    "framebuffer_to_numpy",
    "numpy_to_framebuffer",
    "share_dlpack",
    "cuda_array_interface",
    # task 3
    "FrameDownloader",
    "measure_copy_bandwidth",
    "run_frame_loop",
    # task 4
    "render_rotating_triangle",
    "FrameLoop",
    # given: the frame loop's clear colour, the framebuffer check, the triangle's vertices,
    # the clock measure_copy_bandwidth reads (course.measure.bench)
    "BACKGROUND_RGBA",
    "_check_framebuffer",
    "triangle_vertices",
    "time_fn",
]
