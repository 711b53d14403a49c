"""Lab 3: organising the tracer.

Fill in every function that raises ``NotImplementedError`` (the tasks below); the helpers
imported from ``course.given.lab3`` are given. Run the grader for this lab with
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
  ``check_*`` helpers do that: call them first, as the skeleton does).

Tasks (points)
--------------
1. ``offset_origins``, ``reflect``, ``surface_at``, ``shade_direct``, ``render_whitted``:
   Whitted backward tracing                                                        (9)
2. ``render_wavefront``: separate kernels with compaction, optional material sort  (3)
3. ``render_uber``: the uber kernel on fixed-size buffers, under ``torch.compile``  (2)
4. ``render_persistent``: persistent workers fed from a global queue               (2)
5. ``layout_indexed``, ``layout_float4``, ``layout_woop``, ``intersect_layout``    (2)
6. End to end: ``render_whitted`` with your own building blocks (the other tasks'
   renderers are graded with given ones)                                          (1)

What the organisations cost, measured
-------------------------------------
``bench/lab3_wavefront.py --device cpu --threads 1`` on a shared 2-core CPU, 32 x 32
pixels, shadows and two bounces, the BVH tracer ``course.kernels.trace.trace_bvh``; every
organisation returns the reference image (relative error <= 1e-6 where the shading
decisions agree; 0.4% of the Cornell box's pixels flip a shadow decision at an exact corner).

=======================  =============================  ========================
                         Cornell box (36 triangles)     bunny (69K triangles)
=======================  =============================  ========================
lanes traced: wavefront  1,179 closest + 1,153 shadow   1,459 + 1,322
  full-size loop         2,048 + 1,153                  2,048 + 1,322
  uber (every lane)      3,072 + 3,072                  3,072 + 6,144
persistent pool of N/4   5 steps, 8% lanes idle         6 steps, 5% idle
=======================  =============================  ========================

At this size a CPU is bound by the number of calls, not of rays, so the uber kernel's
2-4x more lanes cost little (its images/s are within 2x of the others, either way, from
run to run); at 1024 x 1024 on a GPU the lanes are the bill. A bounce in the Cornell box
keeps 15% of the rays (only mirror hits reflect), which is what compaction saves.
"""

from __future__ import annotations

import torch

from course.core.types import Hits, Mesh
from course.given.lab3 import (  # noqa: F401  (given helpers)
    LAYOUTS,
    MAX_DEPTH,
    OFFSET,
    StageClock,
    WhittedScene,
    check_layout_inputs,
    check_mesh,
    check_order,
    check_pool_size,
    check_render_inputs,
    check_scene,
    check_surface_inputs,
    check_vectors,
    dot,
    face_normals,
    float_as_index,
    index_as_float,
    normalize,
    offset_scale,
    pair_tiles,
)

# =======================================================================================
# Task 1: Whitted building blocks and backward tracing


def offset_origins(points: torch.Tensor, normals: torch.Tensor) -> torch.Tensor:
    """Secondary-ray origins lifted off the surface along its normal.

    points: (N, 3) hit points; normals: (N, 3) unit normals facing the incoming ray; both
    float32 or float64. Returns (N, 3): ``p + n * offset * max(1, |p|_inf)`` with
    ``offset = offset_scale(points.dtype)`` (1e-4 in float32).

    Why: the hit point ``p = o + t d`` is rounded, so it lies a little above or *below* the
    surface. A shadow or reflected ray started there can hit its own triangle at ``t ~ 0``:
    speckled self-shadowing ("acne"). Lifting the origin along the normal by more than the
    rounding error cures it; the rounding grows with the coordinates' magnitude, hence the
    ``max(1, |p|_inf)`` (at 1e5 a fixed offset would vanish in the rounding).

    Hints: ``points.abs().amax(dim=1, keepdim=True).clamp(min=1)``.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    check_vectors(None, points=points, normals=normals)
    raise NotImplementedError("not implemented yet: offset_origins (task 1)")


def reflect(directions: torch.Tensor, normals: torch.Tensor) -> torch.Tensor:
    """Mirror reflection: ``r = d - 2 (d . n) n``, renormalised to unit length.

    directions: (N, 3) unit incoming directions; normals: (N, 3) unit normals. Returns
    (N, 3) unit. The normal component of ``d`` flips, the tangential one stays; the result
    does not depend on which side ``n`` faces (but the *origin* of the reflected ray does:
    it is offset to the side the ray came from). A grazing ``d`` (``d . n = 0``) goes on
    unchanged.

    Hints: ``dot`` and ``normalize`` are given.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    check_vectors(None, directions=directions, normals=normals)
    raise NotImplementedError("not implemented yet: reflect (task 1)")


def surface_at(scene: WhittedScene, origins: torch.Tensor, directions: torch.Tensor,
               hits: Hits):
    """What a ray sees at its hit: ``(points, normals, material)``.

    scene: the scene; origins, directions: (N, 3) the rays; hits: their ``Hits`` from
    ``trace``. Returns

    * points: (N, 3) ``o + t d`` at the hit;
    * normals: (N, 3) the unit geometric normal of the hit triangle (``face_normals``),
      **flipped to face the ray** (``n . d <= 0``): shading and offsets happen on the side
      the ray arrives from, whichever way the triangle is wound;
    * material: (N,) int64 ``scene.material[triangle]``.

    Rays that missed get points and normals 0 and material -1 (``t = inf`` must not turn
    into ``inf * 0 = NaN`` anywhere).

    ``hits`` is taken as given: the ``Hits`` of these N rays from ``trace``. Any other value
    is outside the contract (it need not be checked, nor raise any particular error).

    Hints: ``hits.hit`` is the mask of hits; index with ``hits.triangle.clamp(min=0)`` and
    mask the misses with ``torch.where``.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    check_scene(scene)
    n = check_vectors(  # noqa: F841 (n: the number of rays, for your code)
        scene.vertices, origins=origins, directions=directions)
    raise NotImplementedError("not implemented yet: surface_at (task 1)")


def shade_direct(scene: WhittedScene, points: torch.Tensor, normals: torch.Tensor,
                 directions: torch.Tensor, material: torch.Tensor, trace):
    """Ambient and direct light at N hits, with a shadow ray per visible light.

    points: (N, 3) hit points ``p`` (not offset); normals: (N, 3) unit, facing the ray;
    directions: (N, 3) the incoming rays' unit directions ``d``; material: (N,) int64;
    trace: the tracer. Returns ``(radiance (N, 3), shadow_rays)``: ``shadow_rays`` (int) is
    the number of shadow rays traced.

    Per the contract (``course.given.lab3``), with ``p_off = offset_origins(p, n)``,
    ``v = -d``, ``s = shininess[m]``::

        L = ambient * kd[m]
          + sum over lights with n . l > 0 and an unblocked shadow ray (p_off, l):
                E (n . l) (kd[m] / pi + ks[m] (s + 8) / (8 pi) max(0, n . h)^s),  h = normalize(l + v)

    Point light ``i``: ``l = (P_i - p_off) / dist``, ``E = I_i / dist^2``; its shadow ray
    looks for any hit in ``[0, dist - offset * max(1, |P_i|_inf)]``: it must **stop short of
    the light** (a lamp on a wall is not hidden by that wall, and nothing behind the lamp
    shadows it). Directional light ``j``: ``l = dir_directions[j]``, ``E =
    dir_irradiance[j]``, ``t_max = inf``.

    Trace only the shadow rays that can matter: toward lights with ``n . l > 0`` (the
    others cannot contribute) -- all of them in **one** ``trace(..., any_hit=True)`` call.

    Hints: work on ``(N, L, 3)`` tensors (point lights then directional ones, ``torch.cat``);
    ``(cos > 0).nonzero(as_tuple=True)`` lists the (hit, light) pairs that need a shadow ray.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    n = check_surface_inputs(  # noqa: F841 (n: the number of points, for your code)
        scene, points, normals, directions, material, trace)
    raise NotImplementedError("not implemented yet: shade_direct (task 1)")


def render_whitted(scene: WhittedScene, origins: torch.Tensor, directions: torch.Tensor,
                   trace, max_depth: int = MAX_DEPTH) -> torch.Tensor:
    """Backward (Whitted) ray tracing, one loop over bounces on full-size buffers.

    scene; origins, directions: (N, 3) primary rays; trace: the tracer; max_depth: the
    number of reflections a path may take (0: primary rays only). Returns (N, 3) radiance.

    Keep per pixel a ray, a throughput (3,) (the product of the mirrors' ``kr`` so far) and
    an ``alive`` flag. Each bounce ``depth = 0 .. max_depth``:

    1. trace **all N** rays (a dead one with an empty interval, e.g. ``t_max = -inf``);
    2. a live ray that missed adds ``throughput * background``;
    3. a live ray that hit adds ``throughput * shade_direct(...)``;
    4. it lives on if its material reflects (``any(kr > 0)``) and ``depth < max_depth``:
       new ray ``(offset_origins(p, n), reflect(d, n))``, throughput ``*= kr[m]``.

    Adding ``throughput * (direct at each bounce)`` is the recursion ``L = direct + kr *
    L(reflected)`` unrolled. Stop early once no ray is alive.

    Hints: ``surface_at``, ``shade_direct`` (on the hits: ``x[hit]``), ``offset_origins``,
    ``reflect``, and ``torch.where(alive[:, None], new, old)`` to update the buffers.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    n = check_render_inputs(  # noqa: F841 (n: the number of rays, for your code)
        scene, origins, directions, trace, max_depth)
    raise NotImplementedError("not implemented yet: render_whitted (task 1)")


# =======================================================================================
# Task 2: separate kernels with compaction ("wavefront")


def render_wavefront(scene: WhittedScene, origins: torch.Tensor, directions: torch.Tensor,
                     trace, max_depth: int = MAX_DEPTH, sort_by_material: bool = False):
    """The tracer as separate stages over a compacted queue of live rays.

    Same arguments and image as :func:`render_whitted`; sort_by_material: sort the shading
    queue by material before shading. Returns ``(image (N, 3), stats)``.

    The queue holds, per live ray, its pixel index, origin, direction and throughput. Stages:

    * **generate**: the queue of the N primary rays;
    * **trace**: closest hits of the queue's rays (one ``trace`` call);
    * **shade**: misses add ``throughput * background`` to their pixels (``index_add_``) and
      leave the queue (compaction); the hits are optionally sorted by material (coherent
      shading: on a GPU, a warp whose rays share a material takes one branch) and add
      ``throughput * shade_direct(...)``;
    * **spawn**: only mirror hits with ``depth < max_depth`` stay (compaction again), with
      their reflected rays and throughput ``*= kr``.

    Repeat trace -> shade -> spawn for ``depth = 0 .. max_depth`` or until the queue is empty.
    ``stats`` (plain Python data), one list entry per bounce that traced rays:

    ===================  =======================================================
    ``closest_rays``     rays traced in the trace stage (the queue's length)
    ``hits``             of those, rays that hit something
    ``shadow_rays``      shadow rays traced by the shade stage
    ``reflected_rays``   rays spawned for the next bounce
    ``material_runs``    runs of equal material in the shading queue (the number of
                         distinct materials when sorted)
    ``seconds``          ``{"generate", "trace", "shade", "spawn"}``: seconds per stage
                         (``StageClock`` does it; shadow rays count as shading)
    ===================  =======================================================

    Hints: compact with a mask, ``x = x[keep]``, applied to *every* per-ray tensor alike;
    ``torch.argsort(material, stable=True)`` sorts; ``clock = StageClock(device)`` and
    ``with clock("trace"): ...``.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    n = check_render_inputs(  # noqa: F841 (n: the number of rays, for your code)
        scene, origins, directions, trace, max_depth)
    if not isinstance(sort_by_material, bool):
        raise TypeError(f"sort_by_material: expected a bool, got {sort_by_material!r}")
    raise NotImplementedError("not implemented yet: render_wavefront (task 2)")


# =======================================================================================
# Task 3: the uber kernel


def render_uber(scene: WhittedScene, origins: torch.Tensor, directions: torch.Tensor, trace,
                max_depth: int = MAX_DEPTH, compile=False) -> torch.Tensor:
    """The bounce loop as one fused program over fixed-size lane buffers.

    Same arguments and image as :func:`render_whitted`; compile: False (eager), True
    (``torch.compile`` with inductor) or a ``torch.compile`` backend, by name (e.g.
    ``"eager"``: capture only) or a callable (``backend=`` of ``torch.compile``). Returns
    (N, 3).

    A GPU uber kernel is one thread per pixel running TRAVERSE -> INTERSECT -> SHADE ->
    (reflect) as a state machine: no ray state goes back to memory between stages, but a
    thread whose ray is done idles until its whole warp is. Write the torch analogue: N
    lanes (and N x L shadow lanes) whose buffers **never change size**. Each bounce:

    1. ``trace`` all N lanes (dead lanes: an empty interval);
    2. a step function builds the hits' surfaces and all N x L shadow rays (an empty
       interval where a lane is dead or ``n . l <= 0``);
    3. ``trace`` all N x L shadow lanes with ``any_hit=True``;
    4. a step function shades, accumulates the image and spawns (``torch.where``).

    The two step functions must contain no data-dependent shapes (no ``x[mask]``,
    ``nonzero``, ``.item()``, ``if`` on tensor values), so ``torch.compile(step,
    backend=..., fullgraph=True)`` captures each as one graph of fixed-size tensors and
    fuses it (the grader inspects the captured graphs); the tracer stays outside (on a GPU
    the Triton uber kernel fuses the traversal too: ``course.kernels.triton_tracer``). TypeError
    for a ``compile`` of another type.

    Hints: pass the scene's tensors to the step functions one by one (not the dataclass);
    cache the compiled functions (``functools.cache``) so a second call does not recompile.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    n = check_render_inputs(  # noqa: F841 (n: the number of rays, for your code)
        scene, origins, directions, trace, max_depth)
    if not (isinstance(compile, (bool, str)) or callable(compile)):
        raise TypeError(f"compile: expected a bool or a torch.compile backend (a name or a "
                        f"callable), got {compile!r}")
    raise NotImplementedError("not implemented yet: render_uber (task 3)")


# =======================================================================================
# Task 4: persistent workers


def render_persistent(scene: WhittedScene, origins: torch.Tensor, directions: torch.Tensor,
                      trace, max_depth: int = MAX_DEPTH, pool_size: int = 4096):
    """A fixed pool of ray slots that keep taking work from one global queue until done.

    Same arguments and image as :func:`render_whitted`; pool_size: the number of slots
    (lanes), >= 1. Returns ``(image (N, 3), stats)``.

    A work item is ``(pixel, origin, direction, depth, throughput)``; the queue starts with
    the N primary rays. Each **step**:

    1. fill the empty slots from the head of the queue (first in, first out);
    2. stop if no slot holds work;
    3. the busy slots trace, shade (background for misses, ``shade_direct`` for hits) and
       add to their pixels; a mirror hit with ``depth < max_depth`` **appends** its reflected
       ray (depth + 1, throughput ``* kr``) to the tail of the queue;
    4. the slots are free again.

    Nothing may be lost or done twice: every item generated is processed exactly once.
    ``stats`` (plain Python data): ``pool_size``; ``steps``; ``active_lanes`` (list: busy
    slots per step); ``idle_fraction`` = ``1 - sum(active_lanes) / (pool_size * steps)``;
    ``work_generated`` (primary rays + reflections appended); ``work_processed``;
    ``shadow_rays``.

    Persistent threads (Aila & Laine 2009) replace "one launch per bounce, sized to its
    rays" by one launch of as many workers as the GPU holds at once, each looping "fetch,
    trace, shade, push" until the queue is empty: no relaunch, mixed depths in one batch,
    idle lanes only at the tail.

    Hints: keep the queue and the pool as dicts of tensors; ``(pool['pixel'] < 0)`` marks
    empty slots; the queue's head index is a Python int.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    n = check_render_inputs(  # noqa: F841 (n: the number of rays, for your code)
        scene, origins, directions, trace, max_depth)
    check_pool_size(pool_size)
    raise NotImplementedError("not implemented yet: render_persistent (task 4)")


# =======================================================================================
# Task 5: geometry layouts


def layout_indexed(mesh: Mesh) -> dict:
    """Indexed geometry: shared vertices and an index triple per triangle.

    mesh: F triangles. Returns ``{"kind": "indexed", "vertices": (V, 3) the mesh's,
    "faces": (F, 3) int32, "bytes_per_triangle": float}`` (vertex bytes + index bytes, per
    triangle). Compact (a vertex is stored once, shared by ~6 triangles of a closed mesh),
    but a triangle test first gathers three vertices through the indices: dependent loads.

    Hints: ``x.numel() * x.element_size()`` is a tensor's size in bytes.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    check_mesh(mesh)
    raise NotImplementedError("not implemented yet: layout_indexed (task 5)")


def layout_float4(mesh: Mesh, order: torch.Tensor | None = None) -> dict:
    """Three float4 per triangle, the triangle's index in the w components.

    mesh: F triangles; order: (F,) int64 permutation: slot ``k`` holds triangle
    ``order[k]`` (a BVH stores its leaves' triangles contiguously in leaf order); None for
    ``arange(F)``. Returns ``{"kind": "float4", "triangles": (F, 3, 4) the mesh's dtype,
    "bytes_per_triangle": float}``: ``triangles[k, j, :3]`` is corner ``j`` of triangle
    ``order[k]``, and every ``triangles[k, j, 3]`` holds ``order[k]`` bit for bit
    (``index_as_float``). One aligned 16-byte load per corner and no indirection; the index
    in w tells a hit's original triangle after reordering.

    Hints: ``mesh.triangles()`` gives (F, 3, 3) corners; ``torch.cat`` the w column.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    check_mesh(mesh)
    index = check_order(order, mesh)  # noqa: F841 (the permutation; arange(F) for None)
    raise NotImplementedError("not implemented yet: layout_float4 (task 5)")


def layout_woop(mesh: Mesh) -> dict:
    """Woop's unit-triangle test: a precomputed affine map per triangle (3 float4 rows).

    mesh: F triangles. Returns ``{"kind": "woop", "transforms": (F, 3, 4) the mesh's dtype,
    "bytes_per_triangle": float}``. ``M = transforms[f]`` maps world space to the triangle's
    space: ``M [v0, 1] = (0, 0, 0)``, ``M [v1, 1] = (1, 0, 0)``, ``M [v2, 1] = (0, 1, 0)``.
    It is the inverse of the affine frame with columns ``e1 = v1 - v0``, ``e2 = v2 - v0``,
    the **unit** normal ``normalize(e1 x e2)`` and the origin ``v0``: ``M[:, :3] = F^-1``,
    ``M[:, 3] = -F^-1 v0``. Compute it in float64, then cast. A degenerate triangle (zero
    area) has no such map: fill its rows with NaN, which no ray hits.

    The test then costs two transformed coordinates and a division (the lecture: mul 20,
    add 20, div 1) and needs no vertices at all: 48 bytes in float32, like float4.

    Hints: ``torch.linalg.inv_ex`` returns ``info != 0`` for singular frames.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    check_mesh(mesh)
    raise NotImplementedError("not implemented yet: layout_woop (task 5)")


def intersect_layout(layout: dict, origins: torch.Tensor, directions: torch.Tensor,
                     t_min: torch.Tensor, t_max: torch.Tensor) -> Hits:
    """Closest hits of N rays against every triangle of a layout (brute force, in tiles).

    layout: from ``layout_indexed``/``layout_float4``/``layout_woop``; origins, directions:
    (N, 3); t_min, t_max: (N,), of the layout's dtype. Returns ``Hits``: the nearest hit in
    ``[t_min, t_max]`` per ray, ``triangle`` the **original** triangle index (for float4:
    read from w with ``float_as_index``), among equal ``t`` the lowest index; ``t = inf``,
    ``triangle = -1``, ``u = v = 0`` for misses; NaN/inf rays miss.

    * indexed: gather the corners ``vertices[faces]``, then Möller–Trumbore;
    * float4: Möller–Trumbore on ``triangles[..., :3]``;
    * woop: ``o' = M [o, 1]``, ``d' = M [d, 0]``, ``t = -o'_z / d'_z``, ``(u, v) = (o'_x + t
      d'_x, o'_y + t d'_y)``; a hit iff ``u, v >= 0`` and ``u + v <= 1`` (``d'_z = 0``:
      parallel, no hit).

    Tiles of at most ``MEMORY_BUDGET_BYTES / BYTES_PER_PAIR`` (ray, triangle) pairs:
    ``pair_tiles(N, F)`` yields them.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    kind, f = check_layout_inputs(  # noqa: RUF059 (the layout's kind and F, for your code)
        layout, origins, directions, t_min, t_max)
    raise NotImplementedError("not implemented yet: intersect_layout (task 5)")
