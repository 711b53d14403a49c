"""Lab 2: acceleration structures (reference solution).

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
* Degenerate input is a case, not an error: rays with zero (``+0.0`` or ``-0.0``)
  direction components, rays starting inside or on a cell or box boundary, NaN/inf rays
  (they miss), one triangle, coincident triangles, flat scenes. Malformed input raises
  ``ValueError``/``TypeError`` naming the argument; so does a mesh with NaN or inf
  vertices given to any builder (``build_*``: there are no bounds to sort it by), with
  the same ``mesh: expected finite vertices ...`` error from the provided
  ``check_mesh(mesh, finite=True)``.

Tasks (points)
--------------
1. Uniform grid: ``grid_resolution``, ``build_grid``, ``grid_closest_hit`` (3D DDA,
   mailboxing, the cell-interval test)                                         (4)
2. BVH builds: ``morton_codes``, ``build_lbvh``, ``build_sah_bvh`` (binned SAH)  (3)
3. BVH traversal: ``bvh_closest_hit`` (stack, near child first),
   ``bvh_skip_indices`` and ``bvh_closest_hit_stackless``                      (3)
4. kd-tree: ``build_kdtree`` (SAH over triangle bound planes), ``kd_pack`` /
   ``kd_unpack`` (the 8-byte node), ``kd_closest_hit`` (early exit)            (3)
5. ``brute_force_closest_hit`` and ``closest_hit``: the common entry point (dispatch,
   the structure ``"auto"`` picks)                                            (2)
6. The two-level grid: ``build_two_level_grid`` (a coarse top grid, a sub-grid sized
   by the density heuristic in each crowded cell), ``two_level_closest_hit`` (nested
   DDA, mailboxing across both levels): the teapot in a stadium                (4)
7. ``bvh_closest_hit_fast``: the BVH traversal with fixed shapes and fixed trip counts
   (no host sync inside the loop, ``torch.compile``-able), and its any-hit mode for
   shadow rays                                                                (3)
8. End to end: your builders and walks together on the teapot in a stadium, the work
   counters that show the trade (the other tasks are graded on structures built by
   the grader)                                                                (1)

What each structure buys, measured
----------------------------------
``bench/lab2_accel.py --device cpu --threads 1`` on a shared 2-core CPU, 48 x 48 primary
rays; speed-ups over brute force in the same run (on a CPU only such ratios mean
anything, and repeated runs vary by about 30%). Every row returns the brute-force hits
exactly: the structures trade build time and memory for speed, never accuracy. The
stackless BVH walk visits 3x the nodes of the stack traversal (23 vs 7 on the bunny).

==========================  ======================  ======================  ======================
                            uniform grid (λ = 2)    BVH: SAH / LBVH         kd-tree (SAH)
==========================  ======================  ======================  ======================
build, bunny (69K)          0.04 s: one sort of     1.0 s / 0.09 s          5.9 s: an event sweep
                            (triangle, cell) pairs                          per level
bunny: speed-up, work per   x660; 11.8 cells, 9.6   x530 / x470; 7 / 8      x310; 19 nodes, 5.6
ray                         tests                   nodes, 1.5 tests        tests
teapot in a stadium (3.9K)  x0.8: a ray at the      x35 / x13 (the LBVH's   x12; 18 tests
                            teapot tests all 2.9K   Morton grid spans the
                            of its triangles        stadium)
repeated tests              big triangles span      none: every triangle    straddlers sit in
                            cells: the mailbox      in one leaf             several leaves
                            saves 20-25%
coincident triangles        one cell, all tested    median fallback: no     one leaf: no plane
                                                    endless split           inside the box
axis-parallel rays, +-0.0   step 0, t_next = inf    1/+-0 = +-inf slabs     t_split = +-inf: the
                                                                            near child
==========================  ======================  ======================  ======================

The two-level grid and the sync-free traversal (``bench/lab2_accel.py --small --threads 2``,
``bench/results/cpu-2cores/lab2/``; on an H200, ``bench/results/nvidia-h200/lab2/``):

* teapot in a stadium (3.9K triangles): the uniform grid tests 2,900 triangles per ray and
  runs at x0.7 brute force; the two-level grid tests 9 (8 cells per ray) and runs 10x the
  uniform grid (x7 brute force), close to the SAH BVH's stack traversal.
* bunny, primary rays: the stack traversal 7.6K rays/s (65K rays, 2 threads); trimesh's
  numpy query 100 rays/s. Against Embree on the same 65K rays, every walk warm
  (``bench/lab2_accel.py --device cpu --parts embree``, ``bench/results/cpu-2cores/
  lab2_embree/``, on a loaded shared machine): on one thread the sync-free walk under
  ``torch.compile`` runs at **0.11x Embree** (0.43 M against 3.9 M rays/s), eager at
  0.020x, the stack traversal at 0.017x; with two torch threads on the loaded two cores
  the torch walks fall 50-100x (the benches take ``course.core.device.free_cpus()`` threads).
  On an H200 with 1M rays (``bench/results/nvidia-h200/lab2_fused/``): 2.9 M eager, 21 M
  compiled, **105-137 M rays/s** compiled and replayed from CUDA graphs (k = 16-32); with
  the graphs of each size kept across calls 143 M (k = 16,
  ``bench/results/nvidia-h200/lab2_walk/``); the stack traversal 0.25 M. The LBVH of
  bunny_x16 (1.1M triangles) builds in 10 ms there.
* ``choose_structure`` (given) reads triangle count, crowding and size spread and picks:
  a grid for small even scenes, the two-level grid for crowded scenes with few rays, the
  SAH BVH for many rays, the LBVH when the build dominates; never the kd-tree (slowest
  build, no faster walk here).

The reference in parts
----------------------
This file is the module the graders, benches and mutants load (by its path, like a
student's ``labs/lab2_accel.py``); the tasks' code lies in ``solutions/lab2_accel_parts/``,
one file per task (``task1_grid.py`` ... ``task7_fast.py``). The imports below are the
lab's (the skeleton's given helpers and what the reference uses besides); then
``course.core.files.run_parts`` compiles each part under its own file name and runs it, in
task order, in *this* module's namespace. So the reference is one module, as a student's
file is: its functions call each other through this module's globals (a grader that
replaces ``build_grid`` here is seen by ``closest_hit``), its private helpers and caches
(``_GRAPHS``) are this module's, and a traceback or ``inspect.getsource`` of a function
shows the part's file and line (not of a class: ``inspect`` looks for it in this file).
A part imports nothing (but ``from __future__ import annotations``): it uses the names
imported here and those the other parts define. What reads the reference's text instead
of importing it (mutants, the sandbox's signatures, the meta tests) finds its files with
``module_files`` and ``defining_file`` of ``course.core.files``.
"""

from __future__ import annotations

import collections
import math

import torch

from course.core.files import run_parts as _run_parts
from course.core.raymath import gamma
from course.core.types import Hits, Mesh, Rays
from course.given.lab2 import (  # given helpers
    COUNTERS,
    MAX_PAIRS,
    OFFSET_BITS,
    STRUCTURE_KEYS,
    STRUCTURES,
    TreeLevels,
    _positive_int,
    add_count,
    as_hits,
    assemble_bvh,
    check_bins,
    check_grid_inputs,
    check_kd_fields,
    check_kd_knobs,
    check_leaf_size,
    check_links,
    check_memory_budget,
    check_mesh,
    check_morton_inputs,
    check_packed,
    check_resolution,
    check_structure,
    check_trace_inputs,
    check_two_level_knobs,
    check_walk,
    choose_structure,
    expand_ranges,
    grid_resolutions,
    intersect_pairs,
    moller_trumbore_rows,
    new_closest,
    new_counters,
    pack_bvh,
    pair_chunks,
    ray_octants,
    slab_test,
    surface_area,
    test_ranges,
    triangle_bounds,
)

# =======================================================================================
# Provided helpers (not tasks): input checks, bounds, the slab test, pairs, closest hits


# =======================================================================================
# Tasks 1-7: solutions/lab2_accel_parts/, run here (see "The reference in parts" above)

_run_parts(globals())
del _run_parts
