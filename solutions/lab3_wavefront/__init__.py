"""Lab 3: organising the tracer.

Fill in every function that raises ``NotImplementedError`` (the tasks below); what is
imported from ``course.given.lab3`` is given. Run the grader for this lab with
``pytest tests/test_lab3_wavefront.py`` (add ``-k render_whitted`` for one function). The
tests call your code on the CPU and, where present, on CUDA: write device- and
dtype-agnostic tensor code, with no Python loop over rays or pixels (a loop over bounces or
steps is fine).

A Whitted ray tracer follows light backwards: from the eye through each pixel (primary
rays), from each hit toward each light (shadow rays: is anything in between?), and off
mirrors (reflected rays, up to a depth limit). *What* it computes is fixed by the shading
contract in ``course.given.lab3`` (read its docstring first); this lab is about *how*
the work is organised on a machine that runs thousands of rays at once:

* **one loop over full-size buffers** (task 1): simple, every lane traced every bounce;
* **separate kernels** (task 2, "wavefront"): generate -> trace -> shade -> spawn, each a
  pass over a compacted queue of the rays still alive; easy to profile and to reorder (sort
  by material), at the price of writing every ray's state to memory between stages;
* **one uber kernel** (task 3): the whole bounce loop fused, each lane a small state machine
  on fixed-size buffers, no memory round trips, but lanes idle once their ray is done;
* **persistent workers** (task 4): a fixed pool of lanes that keep fetching work items from
  a global queue until it is empty, instead of one launch per bounce;
* and where the triangles live (task 5): indexed vertices, three float4 per triangle, or
  Woop's precomputed unit-triangle transforms: bytes per triangle against work per test.

Conventions
-----------
* A scene is a ``course.given.lab3.WhittedScene`` (float32 or float64; half precision
  is rejected: it cannot hold the secondary-ray offset). Rays are ``origins (N, 3)`` and
  unit ``directions (N, 3)`` of the scene's dtype and device; an image is ``(N, 3)``
  linear radiance, pixel ``i`` for ray ``i``.
* ``trace(scene, origins, directions, t_min, t_max, any_hit) -> Hits`` is the tracer, passed
  in (Lab 2's BVH behind it, or ``trace_brute_force``): ``t = inf``, ``triangle = -1`` where
  a ray missed. Call it once per stage for a whole batch, never per ray.
* Every renderer returns the image of ``render_reference`` (the slow, obvious reference)
  up to rounding, whatever its organisation: that is what the grader checks.
* Degenerate input is a case, not an error: rays with NaN/inf components or a zero
  direction return the background; zero direction components (+0.0 or -0.0) are ordinary.
  Malformed input raises ``ValueError``/``TypeError`` naming the argument (the given
  ``check_*`` functions do that: call them first, as the skeleton does).

Tasks (points), one file each
-----------------------------
1. ``whitted.py``: ``offset_origins``, ``reflect``, ``surface_at``, ``shade_direct``,
   ``render_whitted``: Whitted backward tracing                                    (9)
2. ``wavefront.py``: ``render_wavefront``, separate kernels with compaction, optional
   material sort                                                                   (3)
3. ``uber.py``: ``render_uber``, the uber kernel on fixed-size buffers, under
   ``torch.compile``                                                               (2)
4. ``persistent.py``: ``render_persistent``, persistent workers fed from a global
   queue                                                                           (2)
5. ``layouts.py``: ``layout_indexed``, ``layout_float4``, ``layout_woop``,
   ``intersect_layout``                                                            (2)
6. End to end: ``render_whitted`` with your own building blocks (the other tasks'
   renderers are graded with given ones)                                          (1)

The lab is this package: the graders load ``lab3_wavefront/`` and call the functions this
file imports from its modules. Each module imports from ``course.given.lab3`` what its
code uses; everything else there is one import away. The renderers of tasks 2 and 4 call
task 1's building blocks through their import (``from .whitted import shade_direct``),
so a grader that stands a given block in for yours is seen there too. Hand in the files
you edit (see ``labs/README.md``): a file you leave out is graded as this skeleton's, so
it costs only its own tasks.

What the organisations cost
---------------------------
``bench/lab3_wavefront.py`` traces every organisation on the Cornell box and the bunny and
counts the lanes each traces; ``bench/results/cpu-2cores/lab3/`` holds a run (the tables,
lanes and Pareto plots) and ``bench/results/nvidia-h200/lab3_gpu/`` one on a GPU. Every
organisation returns the reference image; on a small CPU run the count of calls, not of
rays, sets the time, while at 1024 x 1024 on a GPU the lanes are the bill.
"""

from __future__ import annotations

from course.given.lab3 import LAYOUTS, MAX_DEPTH, OFFSET, StageClock, WhittedScene

from .layouts import intersect_layout, layout_float4, layout_indexed, layout_woop
from .persistent import render_persistent
from .uber import render_uber
from .wavefront import render_wavefront
from .whitted import offset_origins, reflect, render_whitted, shade_direct, surface_at

__all__ = [
    # task 1
    "offset_origins",
    "reflect",
    "surface_at",
    "shade_direct",
    "render_whitted",
    # task 2
    "render_wavefront",
    # task 3
    "render_uber",
    # task 4
    "render_persistent",
    # task 5
    "layout_indexed",
    "layout_float4",
    "layout_woop",
    "intersect_layout",
    # given (course.given.lab3), part of the lab's interface
    "LAYOUTS",
    "MAX_DEPTH",
    "OFFSET",
    "StageClock",
    "WhittedScene",
]
