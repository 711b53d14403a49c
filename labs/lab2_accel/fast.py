"""Task 7: ``bvh_closest_hit_fast``, the BVH traversal with fixed shapes and fixed trip counts
(no host sync inside the loop, ``torch.compile``-able), and its any-hit mode.
"""

from __future__ import annotations

import collections
import math

import torch

from course.core.raymath import gamma
from course.core.types import Hits, Mesh, Rays
from course.given.lab2 import (
    _positive_int,
    check_structure,
    check_trace_inputs,
    check_walk,
    moller_trumbore_rows,
    pack_bvh,
    ray_octants,
    slab_test,
)
from course.given.lab2_robust import reach


def bvh_closest_hit_fast(
    rays: Rays,
    mesh: Mesh,
    bvh: dict,
    any_hit: bool = False,
    check_every: int = 8,
    compile=False,
    compact: bool = True,
    walk: dict | None = None,
    fuse_steps: int = 1,
):
    """Closest (or any) hits through a BVH with fixed shapes: no host sync inside the loop,
    and no stack: a step any compiler can fuse with the next.

    rays: N rays; mesh: the BVH's mesh; bvh: a BVH dict; any_hit: stop each ray at its
    first hit (shadow rays: "is anything in ``[t_min, t_max]``?"); check_every: ``k``, the
    steps run between two looks at the rays (one host sync each); compile: False, True or
    a ``torch.compile`` mode for the steps; ``"reduce-overhead"`` compiles them as
    ``"default"`` and, on a GPU, replays the ``k`` steps of a look from one CUDA graph,
    captured once per (padded) number of rays and kept for later calls with the same
    ``walk`` (packed here: a graph of one step, replayed ``k`` times, not kept); compact:
    at a look, drop finished rays if at most half (an eighth with graphs) are still
    running; walk: ``pack_bvh(bvh, mesh)``, to pack a tree once and trace it many times
    (default: packed here, for the octants of these rays);
    fuse_steps: with ``compile``, the steps one compiled call runs (and fuses): the state
    could stay in registers across them, but the compile time grows with them (2 CPU
    cores: 21 s for 1 step, 2 minutes for 8) and 8 ran slower than 1 on the CPU and on an
    H200 (``bench/lab2_accel.py`` measures it).
    Returns ``(Hits, counters)`` like :func:`bvh_closest_hit` (``"steps"`` = node boxes
    tested, as :func:`bvh_closest_hit_stackless` counts them, ``"tests"`` = triangle tests);
    with ``any_hit`` the hit of a ray is *a* hit in its interval (the first found), not
    necessarily the closest.

    :func:`bvh_closest_hit` compacts the active rays every step (``nonzero``) and sizes
    its stack from ``sp.max()``: each is a host sync, and on a GPU a sync per step (plus
    a hundred small kernel launches) is the whole cost. A stack in a tensor is also a
    scatter per push, which ends every fused kernel. Here:

    * :func:`pack_bvh` lays the tree out once per ray octant, near child first, with skip
      links: the stackless walk of :func:`bvh_closest_hit_stackless` over the array of the
      ray's octant visits the nodes an ordered stack traversal would, and a ray's whole
      state is a few numbers: node, leaf slot, closest hit, counters;
    * every tensor keeps its shape: all rays step together, finished ones masked
      (``node == M``); rays that miss the root box never start;
    * a step does **one** box test and **one** triangle test per ray and keeps what its
      state asks for: outside a leaf, the node's box against ``[t_min, min(t_max,
      reach(best_t))]`` (hit: descend to ``i + 1``, or enter the leaf's slots; miss or
      beyond: ``skip``; ``reach`` keeps a tie at a vertex for the lowest index); inside a
      leaf, the next slot (Möller–Trumbore in the mesh's dtype; ties to the lowest
      triangle index); after the last slot, ``skip``;
    * the host looks only every ``k`` steps: stop when every ray is done, compact if few
      rays are left;
    * a step is gathers from read-only tables and elementwise ops, nothing else, so
      ``torch.compile`` turns it into **one kernel** (one thread per ray, the state in
      registers): the lecture's kernel, written in torch; on a GPU one CUDA graph holds
      the ``k`` steps between two looks. With a ``walk`` packed once, the rays are padded
      (with finished ones) to a few sizes, so the graphs of a size are captured once and
      replayed by every later traversal of that size: a warm traversal pays no capture and
      no compiled call.

    The triangle test is Lab 1's Möller–Trumbore (relative parallel test) written inline,
    in the mesh's dtype, so it can be fused; it agrees with brute force with that kernel
    (rounding may decide a ray grazing an edge differently when the ops are fused).

    Errors (the provided checks): TypeError or ValueError naming ``rays`` (not ``Rays``),
    ``mesh`` (not a ``Mesh``, or another dtype or device than the rays) or ``bvh`` (not a
    BVH dict of this mesh's device and triangles); ValueError naming ``check_every`` unless
    it is an int in 1..1024, ``fuse_steps`` unless it is an int in 1..64, ``compile`` unless
    it is False, True or a ``torch.compile`` mode, or ``walk`` unless it is None or
    :func:`pack_bvh`'s dict of this mesh, packed for every octant these rays go in.

    Hints: ``pack_bvh`` (provided) lays the tree out for you (``boxes``, ``links``,
    ``base``, ``slots``, ``tri``; ``ray_octants`` gives each ray's array). Write one step as
    a function of (n,) columns, state in and state out, with ``torch.where`` for the masked
    updates and plain indexing (``boxes[row, 0]``) for the gathers: no ``scatter_``, no
    in-place writes, no ``nonzero`` inside it. ``moller_trumbore_rows`` (provided) is the
    triangle test; it takes column tuples. Compile the ``k`` steps once
    (``torch.compile(fn, dynamic=True)``) and keep them, not per call.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    check_trace_inputs(rays, mesh, moller_trumbore_rows)
    check_structure(bvh, "bvh", "bvh", mesh)
    _positive_int(check_every, "check_every", 1, 1024)
    _positive_int(fuse_steps, "fuse_steps", 1, 64)
    if compile not in (
        False,
        True,
        "default",
        "reduce-overhead",
        "max-autotune",
        "max-autotune-no-cudagraphs",
    ):
        raise ValueError(f"compile: expected False, True or a torch.compile mode, got {compile!r}")
    if walk is not None:
        check_walk(walk, mesh, rays)
    raise NotImplementedError("not implemented yet: bvh_closest_hit_fast (task 7)")
