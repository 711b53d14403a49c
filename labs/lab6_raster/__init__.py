"""Lab 6: a compute rasterizer.

The lecture's last part: instead of shooting a ray per pixel, project every triangle to the
screen, loop over the pixels of its bounding box, test them with edge functions and resolve
visibility with an atomic minimum on a 64-bit key that packs depth and triangle id. This is
how compute-shader rasterizers (and the visibility buffers of modern engines) work; in
PyTorch the "threads" are the elements of a batch of fragments, and the atomic minimum is
``Tensor.scatter_reduce_(..., reduce="amin")``.

The pipeline, one task per stage::

    vertices --(1) MVP--> clip space --(1) clip--> screen triangles --(2) coverage--> fragments
    fragments --(3) pack (depth | id), atomic min--> visibility buffer (H*W,) int64
    visibility buffer --(4) barycentrics, 1/w--> perspective-correct attributes, shading
    (5) compare with ray-traced primary visibility; trace shadow rays from raster positions

Run the grader for this lab with ``pytest tests/test_lab6_raster.py`` (``-k coverage`` for
one function's tests, ``-s`` to see the measured disagreement with ray tracing). The tests
call your functions on the CPU and, where present, on CUDA: write device- and dtype-agnostic
tensor code, with no Python loop over triangles or pixels (a loop over chunks of triangles
sized by a memory budget is fine).

What the grader asserts
-----------------------
* Edges through pixel centres (grids, fans) and a jittered mesh covering the screen: every
  pixel covered exactly once; each triangle's pixels equal an exact integer top-left rule.
* Suzanne (968 triangles) rasterized vs float64 ray tracing through the same pixel centres:
  at least 99.5% of the ids equal, every other pixel within rounding of an edge.
* Perspective-correct barycentrics within 2e-4 (float32) of the exact ray/plane point.
* The same visibility buffer bit for bit whatever the triangle order and the chunking, and
  on the CPU and CUDA.

Disagreement with ray tracing, z-fighting of 24-bit window depth against 32-bit view depth
and throughput, measured by ``bench/lab6_raster.py``: ``bench/results/cpu-2cores/lab6/``
(GPUs: ``bench/results/<gpu>/lab6/``).

Conventions (those of ``course.core.camera``)
---------------------------------------------
* Clip space is OpenGL's: a point is visible when ``-w <= x, y, z <= w``; the near plane is
  ``z = -w``, which for ``course.core.camera.perspective`` is the plane ``w = near`` (eye-space
  ``z = -near``); ``w`` is the distance in front of the eye along the view axis.
* Screen space: pixel ``(row, col)`` has its centre at ``(x, y) = (col + 0.5, row + 0.5)``;
  row 0 is the top, so ``x = (x_ndc + 1) / 2 * width`` and ``y = (1 - y_ndc) / 2 * height``.
  Pixels are numbered row-major, ``pixel = row * width + col``, like ``primary_rays``.
* Winding: a triangle counter-clockwise seen from the front (``course.core.types.Mesh``) has a
  *positive* signed area ``E_12(v0)`` in screen space (the y flip turns the mathematical sign
  around; see ``edge_functions``).
* Degenerate input is a case, not an error: NaN/inf vertices, zero-area triangles and
  triangles outside the view cover nothing. Malformed input (wrong shape, dtype, device)
  raises ``ValueError``/``TypeError`` naming the argument.
* Positions are float32 or float64; every kernel computes in the dtype of its inputs (the
  per-vertex MVP transform excepted: float64, see ``to_clip_space``). Only element-wise
  operations touch the values that decide coverage and depth, so the CPU and CUDA give
  bit-identical visibility buffers.

Tasks (points), one file each
-----------------------------
1. ``clipping.py``: ``to_clip_space``, ``clip_triangles``, ``to_screen``: MVP, trivial
   reject, near-plane clipping, perspective divide and viewport                      (4)
2. ``edges.py``: ``edge_functions``, ``bounding_boxes``, ``coverage``: edge functions,
   the top-left fill rule, back-face culling                                         (3)
3. ``visibility.py``: ``pack_depth_id``, ``triangle_ids``, ``depth_test``,
   ``rasterize``: 64-bit (depth | id) keys, the atomic-min visibility buffer         (3)
4. ``shading.py``: ``perspective_correct``, ``resolve_pixels``, ``rasterize_mesh``,
   ``interpolate``, ``shade``: perspective-correct barycentrics, attributes,
   flat/smooth shading                                                               (3)
5. ``shadows.py``: ``traced_visibility``, ``world_positions``, ``shadow_epsilon``,
   ``hybrid_shadows``, ``traced_shadows``: raster vs ray-traced visibility, hybrid
   shadows                                                                           (2)
6. End to end: your ``rasterize_mesh`` (tasks 1-4 together) against ray tracing
   (the other tasks are graded on the reference's results of the tasks before them)  (2)

The lab is this package: the graders load ``lab6_raster/`` and call the functions this
file imports from its modules. Each module imports the given code (keys, input checks,
the near-plane crossing, fragment depth, the tracer's call) its code uses from
``course.given.lab6``; every other helper there is one import away. A module calls
another task's function through its import (``from .visibility import rasterize`` in
``shading.py``), so a grader that stands a given function in for yours is seen there
too. Hand in the files you edit (see ``labs/README.md``): a file you leave out is graded
as this skeleton's, so it costs only its own tasks.

The ray tracer of task 5 is a callable ``trace(origins, directions, t_min, t_max)`` taking
``(N, 3)``, ``(N, 3)``, ``(N,)``, ``(N,)`` tensors and returning an object with ``t (N,)``
(inf where missed) and ``triangle (N,)`` int64 (-1 where missed), e.g. ``course.core.types.Hits``:
any closest-hit tracer (Lab 1's ``closest_hit``, a BVH of Lab 2) fits.
"""

from __future__ import annotations

from course.given.lab6 import BYTES_PER_FRAGMENT, EMPTY, ID_BITS, ID_MASK

from .clipping import clip_triangles, to_clip_space, to_screen
from .edges import bounding_boxes, coverage, edge_functions
from .shading import interpolate, perspective_correct, rasterize_mesh, resolve_pixels, shade
from .shadows import (
    hybrid_shadows,
    shadow_epsilon,
    traced_shadows,
    traced_visibility,
    world_positions,
)
from .visibility import depth_test, pack_depth_id, rasterize, triangle_ids

__all__ = [
    # task 1
    "to_clip_space",
    "clip_triangles",
    "to_screen",
    # task 2
    "edge_functions",
    "bounding_boxes",
    "coverage",
    # task 3
    "pack_depth_id",
    "triangle_ids",
    "depth_test",
    "rasterize",
    # task 4
    "perspective_correct",
    "resolve_pixels",
    "rasterize_mesh",
    "interpolate",
    "shade",
    # task 5
    "traced_visibility",
    "world_positions",
    "shadow_epsilon",
    "hybrid_shadows",
    "traced_shadows",
    # given (course.given.lab6), part of the lab's interface
    "EMPTY",
    "ID_BITS",
    "ID_MASK",
    "BYTES_PER_FRAGMENT",
]
