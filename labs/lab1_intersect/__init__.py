"""Lab 1: ray/primitive intersection.

Fill in every function that raises ``NotImplementedError`` (the tasks below); the helpers
imported from ``course.core.raymath`` and ``course.given.lab1`` are given. Run the grader
for this lab with ``pytest tests/test_lab1_intersect.py`` (add ``-k moller_trumbore`` for
one task and ``-s`` to see the crack rates your variants print). The tests call your
kernels on the CPU and, where present, on CUDA. Every kernel here is batched: its tensor
arguments broadcast against each other over their leading dimensions, so rays ``(N, 1, 3)``
against triangles ``(1, M, 3)`` give ``(N, M)`` results, and rays ``(N, 3)`` against
triangles ``(N, 3)`` give one test per ray. Each kernel computes in the dtype of its inputs
(float16, bfloat16, float32 or float64: the speed/accuracy knob) on their device, with no
Python loop over rays or triangles.

Conventions shared by all kernels
---------------------------------
* A ray is ``origin + t * direction``; directions need not be unit length (``t`` is in
  units of the direction's length).
* A hit is accepted when ``t`` lies in the **closed** interval ``[t_min, t_max]``
  (``t == t_min`` and ``t == t_max`` are hits). ``t_min``/``t_max`` are Python numbers
  or float tensors that broadcast with the result.
* Triangle kernels return ``(t, u, v)``: ``t = inf`` where missed, and the barycentrics
  ``u, v`` of the hit point ``(1 - u - v) v0 + u v1 + v v2`` (``u = v = 0`` where
  missed). Both windings hit (no back-face culling).
* Degenerate input is a case, not an error: zero-area triangles, rays parallel to a
  triangle, zero direction components and NaN/inf coordinates give misses, never NaN
  outputs. A ray nearly parallel to a triangle (grazing) never reports a hit that the exact
  test clearly rules out, however far away it crosses the triangle's plane. Malformed input
  (wrong shape, integer dtype, mixed dtypes or devices) raises ``ValueError``/``TypeError``
  naming the argument.

Tasks (points), one file each
-----------------------------
1. ``simple.py``: ``intersect_simple``, plane + sub-triangle areas                   (3)
2. ``moller_trumbore.py``: ``moller_trumbore``, Möller–Trumbore with a relative
   determinant test                                                                  (3)
3. ``woop.py``: ``woop_precompute``, ``woop_unit``, Woop's unit-triangle test        (3)
4. ``watertight.py``: ``watertight``, Woop, Benthin, Wald 2013                       (3)
5. ``boxes_spheres.py``: ``safe_reciprocal``, ``ray_box`` (2) and ``ray_sphere`` (2)
6. ``closest.py``: ``closest_hit``, chunked brute force over a mesh                  (3)
7. ``accounting.py``: ``op_counts``, ``register_estimate``, ``occupancy_for``: the
   lecture's operation, register and occupancy accounting, measured on your kernels  (2)

The lab is this package: the graders load ``lab1_intersect/`` and call the functions this
file imports from its modules. Each module imports the helpers its code uses from
``course.core.raymath`` and ``course.given.lab1``; everything else there is one import
away. ``closest.py`` and ``accounting.py`` import the triangle kernels and pick one by
name (``globals()[variant]``), so a grader that stands a given kernel in for yours is seen
there too. Hand in the files you edit (see ``labs/README.md``): a file you leave out is
graded as this skeleton's, so it costs only its own tasks.

Each kernel's docstring states its contract (all four miss parallel, zero-area, NaN/inf and
far-crossing grazing cases; half precision suits only well-shaped triangles). Only
``watertight`` never **cracks**: a ray aimed at a vertex or a shared edge of a closed mesh
hits a triangle sharing it, not nothing or one behind. The grader's construction, as
``python bench/lab1_intersect.py --device cpu --crack-table`` measures it:

Pass-throughs (fp32, icosphere level 2: 1122 rays aimed at its 162 vertices
and at 1/2 and 1/4 of its edges, from outside / from the centre; the sphere moved by the offset):

========  ==================  ==================  ==================  ==================
offset    intersect_simple    moller_trumbore     woop_unit           watertight
========  ==================  ==================  ==================  ==================
0         6.6% / 8.4%         8.6% / 5.5%         17% / 9.6%          0 / 0
1e5       8.6% / 8.6%         0 / 0               25% / 30%           0 / 0
1e6       2.1% / 2.1%         0 / 0               36% / 31%           0 / 0
1e7       97% / 95%           90% / 90%           92% / 92%           90% / 90%
========  ==================  ==================  ==================  ==================

Largest |t - 1| of the rays that hit there (t = 1 at the aimed point):

========  ==================  ==================  ==================  ==================
offset    intersect_simple    moller_trumbore     woop_unit           watertight
========  ==================  ==================  ==================  ==================
0         1e-07               2e-07               2e-07               2e-07
1e5       0                   6e-08               0.02                2e-07
1e6       0                   6e-08               0.2                 1e-07
1e7       0                   0                   1                   0
========  ==================  ==================  ==================  ==================

The mesh after rounding, offsets 0, 1e5, 1e6, 1e7: distinct vertices 162, 162, 162, 18;
zero-area triangles 0, 0, 0, 90%.

Near the origin the three tests that evaluate a shared edge from their own data crack; far
away Möller–Trumbore survives by luck (the vertices sit on a coarse float grid) and Woop's
transform loses ``|x| / |edge|`` digits. At 1e7 the float32 spacing is the sphere's radius:
the mesh collapses, and even watertight misses most aimed points (its contract is about the
triangles that remain).

Scaled rather than moved, the limit is float32's range, and it depends on the directions:
``python bench/lab1_far.py`` measures it.

Far field (fp32, icosphere level 1 scaled by S: 80 rays aimed at its triangles'
centroids from 3 S away; hit rate with unit directions / with directions of
length ~S):

========  ==================  ==================  ==================  ==================
scale S   intersect_simple    moller_trumbore     woop_unit           watertight
========  ==================  ==================  ==================  ==================
1         1 / 1               1 / 1               1 / 1               1 / 1
1e+06     1 / 1               1 / 1               1 / 1               1 / 1
1e+12     1 / 1               1 / 1               1 / 1               1 / 1
1e+13     0.29 / 0.26         0.39 / 0            1 / 1               0.38 / 1
1e+16     0 / 0               0 / 0               1 / 1               0 / 1
1e+19     0 / 0               0 / 0               1 / 1               0 / 1
1e+22     0 / 0               0 / 0               1 / 1               0 / 0
1e+25     0 / 0               0 / 0               1 / 1               0 / 0
1e+30     0 / 0               0 / 0               1 / 1               0 / 0
========  ==================  ==================  ==================  ==================

With unit directions the simple, Möller–Trumbore and watertight tests form products of
three coordinates (``e2 . (s x e1)``, ``U Az``): of order ``S^3``, they overflow float32
(3.4e38) past ``S`` about 7e12 and every hit is lost. With directions that scale with the
scene, watertight's ``T`` and ``det`` are both of order ``S^2 |d|`` and it holds to 1e19
(1e22: overflow); Möller–Trumbore's ``det = e1 . (d x e2)`` overflows first. Woop's test
survives by rescaling: its transform, made once per triangle in float64, maps the triangle
to the unit one, so every product stays of order 1 up to float32's range (the offsets'
cancellation of ``|x| / |edge|`` digits, above, is the price). The other tests could rescale
the same way: a power of two ``2^-k`` per triangle (exact) applied to ``e1, e2, s`` and
``d``, about 12 more multiplications a pair, or a float64 fallback where a product
overflows (the watertight test's fallback, extended).
"""

from __future__ import annotations

from course.given.lab1 import BYTES_PER_PAIR, VARIANTS, accounting_inputs

from .accounting import occupancy_for, op_counts, register_estimate
from .boxes_spheres import ray_box, ray_sphere, safe_reciprocal
from .closest import closest_hit
from .moller_trumbore import moller_trumbore
from .simple import intersect_simple
from .watertight import watertight
from .woop import woop_precompute, woop_unit

__all__ = [
    # task 1
    "intersect_simple",
    # task 2
    "moller_trumbore",
    # task 3
    "woop_precompute",
    "woop_unit",
    # task 4
    "watertight",
    # task 5
    "safe_reciprocal",
    "ray_box",
    "ray_sphere",
    # task 6
    "closest_hit",
    # task 7
    "op_counts",
    "register_estimate",
    "occupancy_for",
    # given (course.given.lab1), part of the lab's interface: the kernels' names (for
    # closest_hit and the accounting), the tile size's unit, the accounting's one lane
    "VARIANTS",
    "BYTES_PER_PAIR",
    "accounting_inputs",
]
