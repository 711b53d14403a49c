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

Tasks (points)
--------------
1. ``intersect_simple``   plane + sub-triangle areas                          (3)
2. ``moller_trumbore``    Möller–Trumbore with a relative determinant test      (3)
3. ``woop_precompute``, ``woop_unit``   Woop's unit-triangle test              (3)
4. ``watertight``         Woop, Benthin, Wald 2013                              (3)
5. ``safe_reciprocal``, ``ray_box`` (2) and ``ray_sphere`` (2)
6. ``closest_hit``        chunked brute force over a mesh                       (3)
7. ``op_counts``, ``register_estimate``, ``occupancy_for``   the lecture's
   operation, register and occupancy accounting, measured on your kernels       (2)

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

import math

import torch

from course.core.raymath import (
    check_inputs,
    check_triangle_inputs,
    cross,
    dot,
    gamma,
    masked_result,
)
from course.core.types import Hits, Mesh, Rays
from course.given.lab1 import (
    BYTES_PER_PAIR,
    VARIANTS,  # noqa: F401  (the kernels' names, for callers of closest_hit)
    accounting_inputs,
    affine_row,
    check_closest_hit_inputs,
)

# ---------------------------------------------------------------------------------------
# Task 1: the simple test


def intersect_simple(origins, directions, v0, v1, v2, t_min=0.0, t_max=math.inf):
    """The lecture's first test: intersect the plane, then test the point by areas.

    origins, directions: (..., 3) float; v0, v1, v2: (..., 3) float, the corners;
    t_min, t_max: numbers or tensors broadcastable with the result.
    Returns ``(t, u, v)`` of the broadcast shape.

    1. The plane through the triangle has the (unnormalised) normal ``n = e1 x e2``,
       ``e1 = v1 - v0``, ``e2 = v2 - v0``; the ray meets it at
       ``t = n . (v0 - o) / (n . d)`` (no hit when ``n . d == 0``: parallel ray).
    2. At ``p = o + t d``, the three sub-triangles ``(p, v1, v2)``, ``(p, v2, v0)``,
       ``(p, v0, v1)`` have signed areas ``A_i = n . ((vj - p) x (vk - p)) / 2|n|``;
       ``p`` is inside when all three are >= 0.
    3. The barycentrics are the area ratios ``u = A_1 / A``, ``v = A_2 / A`` with the full
       area ``A = |n| / 2`` (compared in units of ``|n|^2`` to avoid square roots).
    4. A ray nearly parallel to the plane crosses it far away (``t`` up to ~1e7 for
       ``cos = 1e-7``). There the differences ``vj - p`` round to almost the same vector, the
       areas to noise of size ``eps |v - p|^2 |n|`` (often exactly 0, which passes ``>= 0``):
       a false hit. Accept only where ``16 eps R^2 |n|_max <= n . n``, with
       ``R = |v0 - p|_max + max(|e1|_max, |e2|_max)`` bounding every ``|vi - p|_max`` and
       ``eps = torch.finfo(dtype).eps``: beyond about ``1 / sqrt(16 eps)`` triangle sizes
       (700 in float32) the test cannot tell inside from outside. It costs real hits only on
       slivers (``|n| < 64 eps |e|_max^2``).

    Accuracy: not watertight (neighbouring triangles round ``p`` and their areas
    differently), and ``p`` carries the error of ``t`` into the inside test.

    Hints: ``cross`` and ``dot`` are provided; build the hit mask from the
    comparisons and finish with ``masked_result(hit, t, u, v)``.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    t_min, t_max = check_triangle_inputs(origins, directions, v0, v1, v2, t_min, t_max)
    raise NotImplementedError("not implemented yet: intersect_simple (task 1)")


# ---------------------------------------------------------------------------------------
# Task 2: Möller–Trumbore


def moller_trumbore(origins, directions, v0, v1, v2, t_min=0.0, t_max=math.inf):
    """Möller & Trumbore 1997: solve ``o + t d = v0 + u e1 + v e2`` by Cramer's rule.

    Same arguments and results as :func:`intersect_simple`.

    With ``p = d x e2``, ``det = e1 . p``, ``s = o - v0``, ``q = s x e1``:
    ``u = s . p / det``, ``v = d . q / det``, ``t = e2 . q / det``; inside when
    ``u >= 0, v >= 0, u + v <= 1``.

    The parallel test is *relative*: ``|det| <= eps * |d| |e1| |e2|`` (max-norms) means the
    ray is parallel to the plane to within rounding. The textbook absolute test
    ``|det| < 1e-6`` instead rejects every triangle smaller than about 1e-3 (``det`` scales
    with the triangle's area) and accepts garbage for huge ones.

    Accuracy: not watertight (each triangle computes the shared edge from its own ``v0``).

    Hints: ``torch.finfo(dtype).eps``; ``x.abs().amax(-1)`` is a max-norm.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    t_min, t_max = check_triangle_inputs(origins, directions, v0, v1, v2, t_min, t_max)
    raise NotImplementedError("not implemented yet: moller_trumbore (task 2)")


# ---------------------------------------------------------------------------------------
# Task 3: Woop's unit-triangle test


def woop_precompute(v0, v1, v2):
    """The affine map that takes each triangle to the unit triangle (Woop 2004).

    v0, v1, v2: (..., 3) float. Returns ``(..., 3, 4)`` of the same dtype: rows
    ``[r_i | c_i]`` with ``x' = r_i . x + c_i`` such that ``v0 -> (0, 0, 0)``,
    ``v1 -> (1, 0, 0)``, ``v2 -> (0, 1, 0)`` and ``v0 + n -> (0, 0, 1)`` for the unit normal
    ``n = e1 x e2 / |e1 x e2|`` (so z' is the signed distance to the plane). It is the
    inverse of the matrix with columns ``[e1 e2 n]``, whose rows are
    ``(e2 x n) / |e1 x e2|``, ``(n x e1) / |e1 x e2|`` and ``n``; then ``c_i = -r_i . v0``.

    Computed in float64 and rounded once (it runs once per triangle, offline). A
    degenerate triangle (``e1 x e2 == 0``) gets the zero transform, which every ray misses
    (``t = -0 / 0`` is NaN).

    Hints: do the arithmetic on ``v0.double()`` etc. and ``.to(v0.dtype)`` at the end;
    ``rows @ v0[..., None]`` applies three rows at once; ``torch.where`` picks the zero
    transform for degenerate triangles.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    check_inputs({"v0": (v0, (3,)), "v1": (v1, (3,)), "v2": (v2, (3,))})
    raise NotImplementedError("not implemented yet: woop_precompute (task 3)")


def woop_unit(origins, directions, transform, t_min=0.0, t_max=math.inf):
    """Intersect rays with unit triangles given by :func:`woop_precompute` transforms.

    origins, directions: (..., 3) float; transform: (..., 3, 4) float; returns ``(t, u, v)``.

    One row at a time, each with an early exit (on a GPU, a warp skips the rest once
    all its lanes fail; batched, the rejections accumulate in a mask):
    z: ``t = -o'z / d'z``, reject outside ``[t_min, t_max]``;
    x: ``u = o'x + t d'x``, reject outside ``[0, 1]``;
    y: ``v = o'y + t d'y``, reject ``v < 0`` or ``u + v > 1``.

    Accuracy: the transform's offsets are about ``|v0| / |edge|``; far from the origin
    ``r . o + c`` cancels those digits, so the test degrades like ``eps |x| / |edge|``.

    Hints: ``transform[..., 2, :]`` is the z row; the given ``affine_row`` gives
    ``(r . o + c, r . d)`` for one row.
    """
    # Provided: validates the arguments; s: {name: tensor}, the scalars in the kernel's dtype.
    _, s = check_inputs(
        {"origins": (origins, (3,)), "directions": (directions, (3,)),
         "transform": (transform, (3, 4))}, {"t_min": t_min, "t_max": t_max})
    raise NotImplementedError("not implemented yet: woop_unit (task 3)")


# ---------------------------------------------------------------------------------------
# Task 4: watertight


def watertight(origins, directions, v0, v1, v2, t_min=0.0, t_max=math.inf):
    """Woop, Benthin & Wald 2013, "Watertight Ray/Triangle Intersection" (JCGT 2(1)).

    Same arguments and results as :func:`intersect_simple`.

    1. Per ray: ``kz = argmax |d|``, ``kx = (kz + 1) % 3``, ``ky = (kx + 1) % 3`` (swapped
       when ``d[kz] < 0`` to keep the winding), shear ``Sx = d[kx] / d[kz]``,
       ``Sy = d[ky] / d[kz]``, ``Sz = 1 / d[kz]``: the ray becomes the +z axis.
    2. Per vertex ``V`` (A, B, C = v0, v1, v2, relative to the origin):
       ``Vx = V[kx] - Sx V[kz]``, ``Vy = V[ky] - Sy V[kz]``.
    3. 2D edge functions ``U = Cx By - Cy Bx``, ``V = Ax Cy - Ay Cx``, ``W = Bx Ay - By Ax``;
       where any of them rounds to exactly 0, all three are recomputed in float64 from
       the same sheared floats (products of two floats are exact there), so every sign is
       exact (the double fallback; nothing to do for float64 inputs).
    4. Miss on mixed signs, or ``det = U + V + W == 0``, or a zero-area triangle
       (``e1 x e2 == 0``: after the rounded shear it may have a sliver of noise area).
    5. ``T = U Az + V Bz + W Cz`` with ``Vz = Sz V[kz]``; compare ``T`` with ``t_min det``
       and ``t_max det`` (sign-corrected) without dividing. Only hits divide:
       ``t = T / det``, ``u = V / det``, ``v = W / det``.

    Contract: **watertight**. A shared edge gives the two triangles the same edge function
    with opposite signs, bit for bit, so a ray through a shared edge or vertex of a closed
    mesh hits at least one of the triangles sharing it. (Holds in eager PyTorch, where
    every product is rounded; a compiler that fuses ``a*b - c*d`` into an FMA breaks it.)

    Hints: ``torch.argmax(d.abs(), dim=-1, keepdim=True)`` and
    ``torch.take_along_dim(x, k, dim=-1)`` pick per-ray components with broadcasting;
    for the fallback, index the lanes that need it with a boolean mask, compute in
    ``float64``, cast back and write them into (a full-shape copy of) U, V, W.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    t_min, t_max = check_triangle_inputs(origins, directions, v0, v1, v2, t_min, t_max)
    raise NotImplementedError("not implemented yet: watertight (task 4)")


# ---------------------------------------------------------------------------------------
# Task 5: boxes and spheres


def safe_reciprocal(directions):
    """``1 / d`` per component, keeping the sign of zero: ``1/+0 = +inf``, ``1/-0 = -inf``.

    directions: (..., 3) float. IEEE division already does this; the point of the
    function is that nothing replaces zeros by a small epsilon (which would turn an
    axis-parallel ray into a slightly tilted one) or drops the sign of ``-0.0``.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    check_inputs({"directions": (directions, (3,))})
    raise NotImplementedError("not implemented yet: safe_reciprocal (task 5)")


def ray_box(origins, inv_directions, box_min, box_max, t_min=0.0, t_max=math.inf):
    """Slab test of rays against axis-aligned boxes (Kay & Kajiya; Ize 2013).

    origins, inv_directions: (..., 3) float, ``inv_directions = safe_reciprocal(d)``;
    box_min, box_max: (..., 3) float; t_min, t_max: numbers or tensors broadcastable with
    the result. Returns ``(t_near, t_far, hit)`` of the broadcast shape: the parametric
    interval of the ray inside the box clipped to ``[t_min, t_max]`` (float, meaningful where
    ``hit``) and ``hit`` (bool)::

        hit = (t_near <= t_far) & (t_near < inf) & finite origin
              & every |inv_direction| > 0 (no NaN, no infinite direction) & box_min <= box_max

    Per axis the slab gives ``t0 = (min - o) / d``, ``t1 = (max - o) / d``, ordered by
    min/max; the box interval is the intersection of the three slabs and ``[t_min, t_max]``.
    * Axis-parallel rays: ``1/±0 = ±inf`` puts the slab at ``[-inf, inf]`` (inside it) or
      entirely at one infinity (outside it). On the far side that is ``[-inf, -inf]``
      (``t_far = -inf``: miss); on the near side ``[inf, inf]``, so ``t_near = t_far = inf``
      with ``t_max = inf``, where ``inf <= inf`` holds: hence ``t_near < inf`` above.
    * A ray starting *on* a slab plane with ``d = 0`` gives ``0 * inf = NaN``: that slab
      says nothing, so the reduction over the slabs drops NaN (``fmax``/``fmin``).
    * Conservative: ``t_far`` is scaled by ``1 + 2 gamma(3)`` (Ize 2013, "Robust BVH Ray
      Traversal"), so rounding never turns a hit into a miss (a few ``gamma(3)`` is as good:
      ``t_far`` is graded to about 1e-5, and a ray missing the box by less may go either
      way); an empty box (``min > max`` on any axis; a flat box ``min == max`` is not empty)
      and a ray with NaN/inf components never hit.

    Hints: ``torch.minimum``/``maximum`` keep NaN, ``torch.fmin``/``fmax`` drop it.
    """
    # Provided: validates the arguments; s: {name: tensor}, the scalars in the kernel's dtype.
    _, s = check_inputs(
        {"origins": (origins, (3,)), "inv_directions": (inv_directions, (3,)),
         "box_min": (box_min, (3,)), "box_max": (box_max, (3,))},
        {"t_min": t_min, "t_max": t_max})
    raise NotImplementedError("not implemented yet: ray_box (task 5)")


def ray_sphere(origins, directions, center, radius, t_min=0.0, t_max=math.inf):
    """Nearest intersection of rays with spheres in ``[t_min, t_max]``; ``inf`` for a miss.

    origins, directions, center: (..., 3) float; radius: number or tensor (...) float.
    Returns ``t`` of the broadcast shape.

    ``|f + t d|^2 = r^2`` with ``f = o - c``: ``a t^2 + 2 b t + c = 0``, ``a = d.d``,
    ``b = f.d``, ``c = f.f - r^2``. Two precision fixes (Ray Tracing Gems, ch. 7):
    * the discriminant ``b^2 - a c`` cancels catastrophically for a small sphere far away;
      the equal ``a (r^2 - |l|^2)`` with ``l = f - (b/a) d`` (the part of ``f``
      perpendicular to the ray) does not;
    * ``q = -(b + sign(b) sqrt(disc))``, roots ``c / q`` and ``q / a``: no subtraction of
      nearly equal numbers for the smaller root.
    The nearer root in ``[t_min, t_max]`` wins, else the farther (a ray starting inside the
    sphere, or spawned on it with ``t_min > 0``, finds the far side). NaN/inf origins or
    directions, a zero direction and a negative radius give ``inf``, never NaN.

    Hints: ``torch.copysign(x, b)`` is ``sign(b) |x|`` with a sign for zero.
    """
    # Provided: validates the arguments; s: {name: tensor}, the scalars in the kernel's dtype.
    _, s = check_inputs(
        {"origins": (origins, (3,)), "directions": (directions, (3,)), "center": (center, (3,))},
        {"radius": radius, "t_min": t_min, "t_max": t_max})
    raise NotImplementedError("not implemented yet: ray_sphere (task 5)")


# ---------------------------------------------------------------------------------------
# Task 6: closest hit by brute force


def closest_hit(rays: Rays, mesh: Mesh, variant: str = "moller_trumbore",
                memory_budget_bytes: int = 2**28) -> Hits:
    """The nearest hit of every ray among all triangles of ``mesh``, by brute force.

    rays: N rays; mesh: F triangles, same dtype and device; variant: the name of a
    triangle kernel of this lab (see ``VARIANTS``). Returns ``Hits`` (N,): ``t`` (inf
    where missed), ``triangle`` (-1 where missed), ``u, v`` (0 where missed).

    Memory: a kernel call on ``n`` rays x ``m`` triangles makes temporaries of ``n m`` pairs,
    so the work goes in tiles of at most ``P = memory_budget_bytes // (BYTES_PER_PAIR *
    element size)`` pairs: ``m = min(F, P)`` triangles and ``max(1, P // m)`` rays per tile
    (all triangles at once when they fit, else chunks of triangles for one ray at a time).
    Each tile is reduced to its nearest hit per ray; its local triangle index plus the
    tile's offset replaces the running best only when strictly nearer, so ties in ``t`` go
    to the lowest triangle index whatever the tiling.

    Hints: ``globals()[variant]`` is the kernel; ``mesh.triangles()`` gives (F, 3, 3)
    corners; ``Hits.miss(n, dtype, device)`` is the starting value; for the lowest index
    among equal t, take the min over ``torch.where(t == t_min_row, index, large)``.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    check_closest_hit_inputs(rays, mesh, variant, memory_budget_bytes)
    raise NotImplementedError("not implemented yet: closest_hit (task 6)")


# ---------------------------------------------------------------------------------------
# Task 7: operation counts, registers, occupancy


def op_counts(variant: str) -> dict:
    """Floating-point operations of one test of ``variant`` (a name in ``VARIANTS``).

    Runs ``course.measure.accounting.count_ops`` on this module's kernel with
    ``accounting_inputs(variant)`` and one lane. Returns the counts as a dict with the
    keys ``mul, add, div, sqrt, fma, compare, abs, select, other`` and ``cycles_bound``,
    the lecture's lower bound ``4 * (N_mul + |N_add - N_mul|)`` with ``N_mul`` read as the
    number of mul/add pairs a mad can fuse, ``min(mul, add)``. A name not in ``VARIANTS``
    raises ValueError naming ``variant`` (``accounting_inputs`` does: call it first).

    Hints: ``from course.measure.accounting import count_ops``;
    ``count_ops(fn, *args, lanes=1)`` returns an ``OpCounts`` with the fields named above.
    """
    raise NotImplementedError("not implemented yet: op_counts (task 7)")


def register_estimate(variant: str) -> int:
    """Registers one thread of ``variant`` needs, estimated from the values alive at once.

    ``course.measure.accounting.live_values`` on ``accounting_inputs(variant)`` (one lane); its
    ``peak_last_use`` (every value dies at its last use, as a register allocator frees it),
    rounded up. A name not in ``VARIANTS`` raises ValueError naming ``variant``.

    Hints: ``from course.measure.accounting import live_values``; ``math.ceil``.
    """
    raise NotImplementedError("not implemented yet: register_estimate (task 7)")


def occupancy_for(variant: str, arch: str = "g80", block_size: int = 64):
    """Occupancy of a kernel running ``variant`` with ``register_estimate(variant)``
    registers per thread on ``arch`` (a name in ``course.measure.occupancy.PRESETS``) with
    ``block_size`` threads per block: a ``course.measure.occupancy.Occupancy``.

    Hints: ``from course.measure.occupancy import PRESETS, occupancy``; unknown arch
    names raise ValueError naming ``arch``.
    """
    raise NotImplementedError("not implemented yet: occupancy_for (task 7)")
