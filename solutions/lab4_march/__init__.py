"""Lab 4: ray marching.

Fill in every function that raises ``NotImplementedError`` (the tasks below); the helpers
marked "provided" are given. Run the grader for this lab with
``pytest tests/test_lab4_march.py`` (add ``-k march_box`` for one function). The tests call
your kernels on the CPU and, where present, on CUDA: write device- and dtype-agnostic
tensor code, and compare your numbers with the analytic references in the docstrings.

A participating medium inside an axis-aligned box, seen along rays: how much light does a
ray collect, and how much of the background still shines through? Every kernel here works
on a batch of N rays at once (no Python loop over rays; loops over steps, voxels and
sphere-tracing iterations are fine), on the device and in the dtype of its inputs.

Conventions shared by all kernels
---------------------------------
* Rays: ``origins (N, 3)`` and ``directions (N, 3)`` float (one of them may be a single
  ``(3,)`` shared by all rays). Directions need not be unit length: ray parameters ``t``
  (box entry and exit, sphere-tracing hits) are in units of ``|d|`` as in Lab 1, but every
  integral is over **world length** ``ds = |d| dt``. Rays start at ``t = 0``.
* The box: ``box_min, box_max`` (3,) (tensors of the rays' dtype and device, or sequences
  of numbers), closed. A grid ``(X, Y, Z)`` spans the box: voxel ``(i, j, k)`` covers
  ``box_min + [i, i+1] x [j, j+1] x [k, k+1] * voxel_size``, ``grid[i, j, k]`` is its value
  (x is the first axis, z the last).
* A medium: ``density`` (the extinction coefficient sigma_t, per unit length, >= 0) and
  ``emission`` (emitted radiance per unit length, q) are each a callable
  ``f(points (N, 3)) -> (N,)`` (emission may return ``(N, C)`` for C colour channels)
  evaluated at world points, or a grid tensor ``(X, Y, Z)`` (emission also
  ``(X, Y, Z, C)``) sampled with trilinear interpolation (:func:`sample_grid`).
* Emission–absorption: the radiance leaving the medium toward the ray's origin is
  ``L = int_0^D T(s) q(s) ds`` with transmittance ``T(s) = exp(-int_0^s sigma)``; a
  background ``L_bg`` behind the box adds ``T(D) L_bg`` (premultiplied colour/alpha).
* Degenerate rays are cases, not errors: rays that miss the box, NaN/inf origins or
  directions and zero directions integrate nothing (radiance 0, transmittance 1, no NaN).
  Malformed input (wrong shape, integer dtype, mixed dtypes or devices, an unknown
  integrator, a negative step count) raises ``ValueError``/``TypeError`` naming the argument.
* Every float dtype works, float16 and bfloat16 included: results come back in the
  inputs' dtype, never NaN, and are checked loosely there (about 2e-2 relative for
  float16 and 6e-2 for bfloat16 on a march); float32 and float64 meet the contracts below.

Tasks (points), one file each
-----------------------------
1. ``march.py``, the lecture's box ray marcher: ``ray_box_interval``, ``sample_grid``,
   ``march_box`` (front-to-back compositing, early termination, jittered offsets)    (3)
2. ``integrals.py``: ``segment_integral``, the energy-conserving per-step integral, exact
   for piecewise-constant media, against the Riemann sum                             (3)
3. ``scatter.py``, single scattering of a directional light: ``henyey_greenstein``,
   ``shadow_transmittance``, ``march_single_scatter``                                (3)
4. ``voxels.py``: ``build_occupancy``, ``voxel_walk``: exact integration over a voxel
   grid with a 3D DDA, and empty-space skipping over macro cells                     (3)
5. ``sphere_tracing.py``: ``sphere_trace``, signed-distance scenes, with
   over-relaxation                                                                   (3)

The lab is this package: the graders load ``lab4_march/`` and call the functions this
file imports from its modules. Each module imports the given helpers (input checks, SDF
primitives, status codes) its code uses from ``course.given.lab4``; every other helper
there is one import away. ``march.py`` also provides ``evaluate``, a field's values at
points (a callable's, or your ``sample_grid``'s for a grid), for every task that samples
a medium. A module calls another task's function through its import (``from .integrals
import segment_integral`` in ``march.py``), so a grader that stands a given function in
for yours is seen there too. Hand in the files you edit (see ``labs/README.md``): a file
you leave out is graded as this skeleton's, so it costs only its own tasks.

Accuracy (asserted by the grader)
---------------------------------
* ``march_box``, "riemann": first order, the error halves when the steps double (each
  step counts its sample as if nothing in front of it within the step absorbed).
* ``march_box``, "exact": exact to rounding for media constant over each step (any step
  count, even 1); second order for smooth media (midpoint rule).
* ``voxel_walk``: the optical depth is the exact sum over the voxels crossed, to float
  rounding, with no step count; a box at 1e5 keeps float32's relative accuracy.
* ``sphere_trace``: a hit when ``|f| <= epsilon t |d|``, the error of ``t`` relative to
  the distance, for scenes near and far.

Errors, samples per ray and speeds measured by ``bench/lab4_march.py``:
``bench/results/cpu-2cores/lab4/lab4_march.md`` (GPUs: ``bench/results/<gpu>/lab4/``).
"""

from __future__ import annotations

from course.given.lab4 import (
    HIT,
    INTEGRATORS,
    MISS,
    UNSURE,
    sdf_box,
    sdf_sphere,
    sdf_union,
)

from .integrals import segment_integral
from .march import evaluate, march_box, ray_box_interval, sample_grid
from .scatter import henyey_greenstein, march_single_scatter, shadow_transmittance
from .sphere_tracing import sphere_trace
from .voxels import build_occupancy, voxel_walk

__all__ = [
    # task 1
    "ray_box_interval",
    "sample_grid",
    "march_box",
    # task 2
    "segment_integral",
    # task 3
    "henyey_greenstein",
    "shadow_transmittance",
    "march_single_scatter",
    # task 4
    "build_occupancy",
    "voxel_walk",
    # task 5
    "sphere_trace",
    # provided: a field's values at points (march.py)
    "evaluate",
    # given (course.given.lab4), part of the lab's interface
    "INTEGRATORS",
    "MISS",
    "HIT",
    "UNSURE",
    "sdf_sphere",
    "sdf_box",
    "sdf_union",
]
