"""Lab 2: acceleration structures.

Fill in every function that raises ``NotImplementedError`` (the tasks below); the code
marked "Provided" is given. Run the grader for this lab with
``pytest tests/test_lab2_accel.py`` (add ``-k grid`` for one task). The tests call your
code on the CPU and, where present, on CUDA: write device- and dtype-agnostic tensor code.
Traversals are graded on trees the grader builds itself, builders by the structure and
quality of what they build, so each task scores on its own.

Brute force tests every ray against every triangle: ``N x F`` tests. An acceleration
structure sorts the triangles into space once, so that a ray tests only the few near its
path. This lab builds the lecture's three structures as flat tensors, traverses them for
a whole batch of rays at once and **counts the work** each ray does, so that the trade
(build time, memory, traversal steps, triangle tests) can be measured instead of guessed.

Batching a traversal
--------------------
A GPU runs one thread per ray, each with its own loop. Here one Python loop iteration
advances *every active ray by one step* (one grid cell, one tree node): the per-ray state
(current cell or node, stack, closest hit) lives in tensors of the active rays, and rays
that finish are compacted away, so an iteration costs as much as the rays still running.
The loop runs as many iterations as the longest ray needs, never one per ray or triangle.

Conventions
-----------
* Rays and meshes are ``course.core.types.Rays`` / ``Mesh`` of one float dtype and device;
  every structure is a ``dict`` of tensors on that device (plus ``"kind"``), so it can be
  inspected, saved and sent anywhere.
* ``intersect(origins, directions, v0, v1, v2, t_min, t_max) -> (t, u, v)`` is the
  ray/triangle kernel, passed in (Lab 1's contract: broadcasting, ``t = inf`` on a miss,
  the closed interval ``[t_min, t_max]``). A structure only decides *which* pairs to test.
* Every ``*_closest_hit`` returns ``(Hits, counters)``: the hit of each ray exactly as
  brute force with the same ``intersect`` finds it (same triangle; among equal ``t`` the
  lowest triangle index), and per-ray ``(N,)`` int64 counters: ``"steps"`` (cells or nodes
  visited) and ``"tests"`` (ray/triangle tests run); the grid adds ``"skipped"`` (tests
  its mailbox avoided).
* Exact at the extremes: a ray aimed exactly at a vertex or an edge hits every triangle
  around that point at the same true ``t``, give or take rounding, and crosses the planes of
  cells, boxes and splits through it at a ``t`` that rounds on its own. The provided
  ``slab_test`` widens its far distance by ``1 + 2 gamma(3)`` (Ize 2013, "Robust BVH Ray
  Traversal"; pbrt-v4), so rounding never turns a box hit into a miss; compare a node's or
  cell's ``t`` with the closest hit through ``reach(best_t)`` (``course.given.lab2_robust``):
  keep what is entered up to ``reach(best_t)``, end at a cell or leaf only if ``reach(best_t)
  < t_exit``. Without that slack a walk drops the triangle brute force picks (ties to the
  lowest index) at a few rays in a hundred aimed at vertices.
* Degenerate input is a case, not an error: rays with zero (``+0.0`` or ``-0.0``)
  direction components, rays starting inside or on a cell or box boundary, NaN/inf rays
  (they miss), one triangle, coincident triangles, flat scenes. Malformed input raises
  ``ValueError``/``TypeError`` naming the argument; so does a mesh with NaN or inf
  vertices given to any builder (``build_*``: there are no bounds to sort it by), with
  the same ``mesh: expected finite vertices ...`` error from the provided
  ``check_mesh(mesh, finite=True)``.

Tasks (points), one file each
-----------------------------
1. ``grid.py``, the uniform grid: ``grid_resolution``, ``build_grid``,
   ``grid_closest_hit`` (3D DDA, mailboxing, the cell-interval test)          (4.5)
2. ``bvh_build.py``, BVH builds: ``morton_codes``, ``build_lbvh``, ``build_sah_bvh``
   (binned SAH)                                                                (3)
3. ``bvh_walk.py``, BVH traversal: ``bvh_closest_hit`` (stack, near child first),
   ``bvh_skip_indices`` and ``bvh_closest_hit_stackless``                    (3.5)
4. ``kdtree.py``, the kd-tree: ``build_kdtree`` (SAH over triangle bound planes),
   ``kd_pack`` / ``kd_unpack`` (the 8-byte node), ``kd_closest_hit`` (early exit) (3.5)
5. ``entry.py``: ``brute_force_closest_hit`` and ``closest_hit``, the common entry
   point (dispatch, the structure ``"auto"`` picks)                            (2)
6. ``two_level.py``, the two-level grid: ``build_two_level_grid`` (a coarse top grid,
   a sub-grid sized by the density heuristic in each crowded cell),
   ``two_level_closest_hit`` (nested DDA, mailboxing across both levels): the teapot
   in a stadium                                                              (4.5)
7. ``fast.py``: ``bvh_closest_hit_fast``, the BVH traversal with fixed shapes and fixed
   trip counts (no host sync inside the loop, ``torch.compile``-able), and its any-hit
   mode for shadow rays                                                      (3.5)
8. End to end: your builders and walks together on the teapot in a stadium, the work
   counters that show the trade (the other tasks are graded on structures built by
   the grader)                                                                 (1)

The lab is this package: the graders load ``lab2_accel/`` and call the functions this
file imports from its modules. Each module imports the given helpers (input checks,
bounds, the slab test, pairs, closest hits) its code uses from ``course.given.lab2``;
every other helper there is one import away. A module calls another task's function
through its import (``from .grid import build_grid``), so a grader that stands a given
function in for yours is seen there too. Hand in the files you edit (see
``labs/README.md``): a file you leave out is graded as this skeleton's, so it costs only
its own tasks.

What each structure buys, measured
----------------------------------
Build times, speed-ups over brute force, work per ray and rays per second of every
structure and traversal (on a shared 2-core CPU, against Embree, and on an H200) are in
``bench/results/``: ``cpu-2cores/lab2/``, ``cpu-2cores/lab2_embree/``,
``nvidia-h200/lab2/``, ``nvidia-h200/lab2_fused/`` and ``nvidia-h200/lab2_walk/``, each
with the ``bench/lab2_accel.py`` command that produced it. Every structure returns the
brute-force hits exactly: they trade build time and memory for speed, never accuracy.
"""

from __future__ import annotations

from course.given.lab2 import COUNTERS, STRUCTURES, choose_structure, pack_bvh, surface_area

from .bvh_build import build_lbvh, build_sah_bvh, morton_codes
from .bvh_walk import bvh_closest_hit, bvh_closest_hit_stackless, bvh_skip_indices
from .entry import brute_force_closest_hit, build, closest_hit
from .fast import bvh_closest_hit_fast
from .grid import build_grid, grid_closest_hit, grid_resolution
from .kdtree import build_kdtree, kd_closest_hit, kd_pack, kd_unpack
from .two_level import build_two_level_grid, two_level_closest_hit

__all__ = [
    # task 1
    "grid_resolution",
    "build_grid",
    "grid_closest_hit",
    # task 2
    "morton_codes",
    "build_lbvh",
    "build_sah_bvh",
    # task 3
    "bvh_closest_hit",
    "bvh_skip_indices",
    "bvh_closest_hit_stackless",
    # task 4
    "build_kdtree",
    "kd_pack",
    "kd_unpack",
    "kd_closest_hit",
    # task 5
    "brute_force_closest_hit",
    "build",
    "closest_hit",
    # task 6
    "build_two_level_grid",
    "two_level_closest_hit",
    # task 7
    "bvh_closest_hit_fast",
    # given (course.given.lab2), part of the lab's interface
    "COUNTERS",
    "STRUCTURES",
    "choose_structure",
    "pack_bvh",
    "surface_area",
]
