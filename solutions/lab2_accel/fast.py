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
    # BEGIN SOLUTION (task 7)
    # Compaction starts only from _GRAPH_COMPACT_FROM rays with graphs, and costs ~15 small
    # ops of host time: the rays' columns and state are packed in one float and one int
    # tensor, gathered with the indices of the rays still running (padding included), and
    # written back in two scatters. With graphs kept, a look is one graph launch and one
    # read of the number of rays still running (counted in the graph); the call's set-up
    # (the root-box test and the packing of the rays, ~40 small ops) is one more graph of
    # that number of rays.
    packed_here = walk is None
    if packed_here:  # only the octants these rays go in
        walk = pack_bvh(bvh, mesh, torch.unique(ray_octants(rays.directions)).tolist())
    device = rays.device
    graphs = compile == "reduce-overhead" and device.type in _GRAPH_DEVICES
    cache = graphs and not packed_here
    # Every ray packed in one float and one int tensor (rows: see _STATE_ROWS), and which
    # rays enter the root's box; with graphs kept across calls, replayed from the graph of
    # this number of rays (~40 small ops of host time in one launch).
    inputs = (rays.origins, rays.directions, rays.t_min, rays.t_max)
    roots = (walk["base"], walk["lo"], walk["hi"])
    floats, ints, hit_root = (
        _start_graph(inputs, roots).run(inputs) if cache else _start(*inputs, *roots)
    )
    # The outputs as two (3, n) tensors, floats (t, u, v) and int32 (triangle, steps,
    # tests): a compaction writes its rays' results back in two ops, and the walk's
    # tensors come from one float and one int tensor in two gathers (_gather, _pack).
    out_f = floats[_COLUMNS:].clone()  # t = inf, u = v = 0
    out_i = ints[_TRIANGLE_ROW:].clone()  # triangle -1, no steps, no tests
    ray = hit_root.nonzero()[:, 0]  # the rest miss everything: they never start
    if not len(ray):
        return _hits(out_f, out_i)
    m = walk["nodes"]
    tables = (walk["boxes"], walk["links"], walk["slots"], walk["tri"])
    steps = (
        _fast_steps if compile is False else _compiled_fast_steps("in place" if graphs else compile)
    )
    # k steps as calls of `fuse` steps each (eager: one call of k); extra steps of finished
    # rays change nothing, so the counters never depend on the knobs.
    fuse = check_every if compile is False else min(fuse_steps, check_every)
    calls = -(-check_every // fuse)
    # Padded with finished rays to a graph size: the graphs of a size are captured once and
    # kept for every later traversal.
    fixed, state = _gather(floats, ints, ray, _graph_size(len(ray)) if cache else len(ray), m)
    # A compiled call gets tensors of their own (rows at any offset would be inputs of
    # another alignment, compiled apart); graphs copy the rows into their buffers.
    alone = compile is not False and not graphs
    if alone:
        fixed, state = _own(fixed, state)
    graph = None
    for _ in range(0, m + mesh.num_faces + 1, calls * fuse):  # a step per node or slot
        if graphs:
            if graph is None and cache:  # the graph of a look at this size, kept across calls
                graph = _step_graph(steps, fixed, state, tables, m, fuse, bool(any_hit), calls)
            elif graph is None:  # tables of this call only: a graph of one call, replayed
                graph = _StepGraph(steps, fixed, state, (tables, m, fuse, bool(any_hit)), 1)
            fixed, state = graph.run(fixed, state, 1 if cache else calls)
            active = int(graph.count)  # the one host sync per k steps
        else:
            for _ in range(calls):
                state = list(steps(fixed, state, tables, m, fuse, bool(any_hit)))
            active = int((state[0] < m).sum())  # the one host sync per k steps
        if active == 0:
            break
        # A compaction is ~15 small ops of host time (with graphs, copies into the buffers
        # of another cached graph): compact only when it saves the device far more.
        if (
            compact
            and active <= len(ray) // (8 if graphs else 2)
            and len(ray) >= _compact_from(graphs)
        ):
            floats, ints = _pack(fixed, state)
            _write_back(out_f, out_i, ray, floats, ints)
            keep = (state[0] < m).nonzero()[:, 0]  # padding never runs: keep < len(ray)
            ray = ray[keep]
            fixed, state = _gather(
                floats, ints, keep, _graph_size(len(keep)) if cache else len(keep), m
            )
            if alone:
                fixed, state = _own(fixed, state)
            graph = None
    _write_back(out_f, out_i, ray, *_pack(fixed, state))
    return _hits(out_f, out_i)
    # END SOLUTION


# BEGIN SOLUTION
_GRAPH_COMPACT_FROM = 1 << 16
"""With graphs, the fewest rays worth compacting. A GPU runs fewer rays than it holds
(an H200: 270K threads) in one wave, so a step over 18K rays costs what a step over 500
does (~2.5 us in a graph): below this, a compaction (hundreds of us of host time) saves
the device nothing (bench/results/nvidia-h200/lab2_floor/)."""


def _compact_from(graphs: bool) -> int:
    """The fewest rays a compaction may start from: on the CPU any number (a step costs
    per ray), with graphs ``_GRAPH_COMPACT_FROM``."""
    return _GRAPH_COMPACT_FROM if graphs else 0


def _hits(out_f, out_i):
    """``(Hits, counters)`` from the packed outputs."""
    return (
        Hits(t=out_f[0], triangle=out_i[0].long(), u=out_f[1], v=out_f[2]),
        {"steps": out_i[1].long(), "tests": out_i[2].long()},
    )


def _start(origins, directions, t_min, t_max, base, lo, hi):
    """A traversal's set-up, no host sync: ``(floats, ints, hit_root)``, the rays packed as
    at a compaction (floats (14, n): the ray columns, then t = inf, u = v = 0; ints (7, n)
    int32: the octant's row, then the state, triangle -1) and which rays enter the root's
    box ((n,) bool). base, lo, hi: the walk's octant rows and root box."""
    n, device = len(origins), origins.device
    inv = 1 / directions
    _, _, hit_root = slab_test(origins, inv, lo, hi, t_min, t_max)
    ints = torch.zeros(7, n, dtype=torch.int32, device=device)
    ints[0] = base[ray_octants(directions)]
    ints[_TRIANGLE_ROW] = -1
    hits = torch.zeros(3, n, dtype=origins.dtype, device=device)
    hits[0] = math.inf
    floats = torch.cat((origins.T, directions.T, inv.T, t_min[None], t_max[None], hits))
    return floats, ints, hit_root


class _StartGraph:
    """:func:`_start` for ``n`` rays captured in a CUDA graph, kept with the step graphs
    and replayed by every later traversal of as many rays with the same walk: the rays are
    copied into its buffers (one multi-tensor copy), and its outputs are read before the
    next traversal replays it (gathered into the walk's own tensors)."""

    def __init__(self, inputs, tables):
        self.inputs = [x.clone() for x in inputs]
        _start(*self.inputs, *tables)  # warm-up outside the capture (the allocator)
        self.graph = torch.cuda.CUDAGraph()
        side = torch.cuda.Stream()
        side.wait_stream(torch.cuda.current_stream())
        with torch.cuda.stream(side):
            self.graph.capture_begin()
            self.outputs = _start(*self.inputs, *tables)
            self.graph.capture_end()
        torch.cuda.current_stream().wait_stream(side)

    def run(self, inputs):
        """The outputs of :func:`_start` on ``inputs`` (origins, directions, t_min, t_max)."""
        torch._foreach_copy_(self.inputs, list(inputs))
        self.graph.replay()
        return self.outputs


def _start_graph(inputs, tables):
    """The cached :class:`_StartGraph` for these rays' shapes and these tables (the step
    graphs' cache, :func:`_cached`)."""
    key = (
        "start",
        len(inputs[0]),
        inputs[0].dtype,
        inputs[0].device,
        tuple(t.data_ptr() for t in tables),
    )
    return _cached(key, tables, lambda: _StartGraph(inputs, tables))


_GRAPH_DEVICES = ("cuda",)  # where "reduce-overhead" replays CUDA graphs

# The packed rows: floats = ray columns (ox, oy, oz, dx, dy, dz, ix, iy, iz, t_min, t_max)
# then t, u, v; ints = base (the octant's row), node, slot, end, triangle, steps, tests.
_COLUMNS = 11
_TRIANGLE_ROW = 4  # of ints: the outputs triangle, steps, tests are its last three rows
_STATE_ROWS = (
    (1, None),
    (2, None),
    (3, None),
    (None, 11),
    (4, None),
    (None, 12),
    (None, 13),
    (5, None),
    (6, None),
)  # node slot end t tri u v steps tests: (int row, float row)


def _gather(floats, ints, index, size: int, m: int):
    """``(fixed, state)`` of the rays ``index`` (columns of the packed tensors) padded to
    ``size`` with finished rays (copies of the first, node ``m``): two gathers and a fill.
    The tensors are rows of the gathered ones: views, contiguous."""
    real = len(index)
    if size > real:
        index = torch.cat((index, index.new_zeros(size - real)))
    f, i = floats.index_select(1, index), ints.index_select(1, index)
    if size > real:
        i[1, real:] = m  # the padding is finished: it never runs, its results are dropped
    return (f[:_COLUMNS], i[0]), [i[r] if r is not None else f[c] for r, c in _STATE_ROWS]


def _own(fixed, state):
    """``fixed`` and ``state`` as tensors of their own (copies of the packed rows)."""
    return (fixed[0].clone(), fixed[1].clone()), [x.clone() for x in state]


def _pack(fixed, state):
    """The inverse of :func:`_gather`: ``(floats, ints)`` of the current rays (3 ops)."""
    node, slot, end, t, tri, u, v, steps, tests = state
    return (
        torch.cat((fixed[0], torch.stack((t, u, v)))),
        torch.stack((fixed[1], node, slot, end, tri, steps, tests)),
    )


def _write_back(out_f, out_i, ray, floats, ints):
    """Results of the rays ``ray`` (the first ``len(ray)`` columns of the packed tensors)
    into the outputs: two scatters (floats' rows t, u, v; ints' rows triangle, steps,
    tests)."""
    out_f[:, ray] = floats[_COLUMNS:, : len(ray)]
    out_i[:, ray] = ints[_TRIANGLE_ROW:, : len(ray)]


def _fast_steps(fixed, state, tables, m: int, k: int, any_hit: bool):
    """``k`` steps of :func:`bvh_closest_hit_fast`: ``fixed`` (the (11, n) ray columns and
    the (n,) octant rows), ``state`` in, the new state out; nothing here waits for the
    device (what ``torch.compile`` fuses)."""
    columns, base = fixed
    for _ in range(k):
        state = _fast_step(*columns.unbind(0), base, *state, *tables, m, any_hit)
    return state


def _graph_size(n: int) -> int:
    """The number of rays a graph is captured for: ``n`` rounded up to a multiple of a
    sixteenth of its power of two (at most ~12% padding), so that the sizes a compaction
    produces repeat from call to call and their graphs are reused."""
    quantum = max(128, 1 << max(0, n.bit_length() - 4))
    return -(-n // quantum) * quantum


class _StepGraph:
    """The ``calls`` compiled calls of one look of :func:`bvh_closest_hit_fast`, updating
    the state in place (:func:`_fast_steps_in_place`), captured once in a CUDA graph for a
    number of rays and replayed at every look of every later traversal of that size: one
    graph launch per look instead of ``calls`` compiled calls (whose Python wrappers cost
    more host time than their kernels' device time), and no capture after a compaction
    once the sizes have been seen.

    The graph reads and writes its own buffers (``fixed`` and ``state`` of the capture);
    :meth:`run` copies other tensors of the same size into them first. A walk packed inside
    the call (``walk=None``) has tables no later call reads: its graphs hold one call,
    replayed ``calls`` times, and are not kept (a capture then costs one compiled call)."""

    def __init__(self, steps, fixed, state, args, calls: int):
        # Buffers of its own, each a tensor by itself: the step writes them in place (rows
        # of a packed tensor would make inductor copy them back), and run() fills them.
        fixed, state = _own(fixed, state)
        self.fixed, self.state, self.args = fixed, state, args
        # One call first, outside the capture, on a copy of the state: whatever the compiler
        # still has to (re)compile for these shapes happens there, and the walk itself
        # advances only by the graph's steps, so every traversal of these rays sees the
        # same sizes at its compactions and a warm one captures nothing.
        steps(fixed, [x.clone() for x in state], *args)
        # capture_begin/end on a side stream, not the torch.cuda.graph context: that one
        # runs gc.collect() and empties the cache at every capture (tens of ms each).
        self.graph = torch.cuda.CUDAGraph()
        side = torch.cuda.Stream()
        side.wait_stream(torch.cuda.current_stream())
        # The rays still running counted in the graph too: a look is one graph launch and
        # one read of a number.
        self.count = torch.zeros((), dtype=torch.int64, device=state[0].device)
        with torch.cuda.stream(side):
            self.graph.capture_begin()
            for _ in range(calls):
                steps(fixed, state, *args)
            self.count.copy_((state[0] < args[1]).sum())
            self.graph.capture_end()
        torch.cuda.current_stream().wait_stream(side)

    def run(self, fixed, state, replays: int = 1):
        """Replay ``replays`` times on ``fixed`` and ``state`` (copied into the graph's
        buffers unless they are them: one multi-tensor copy per dtype); returns ``(fixed,
        state)``, the buffers holding the new state (``count``: the rays still running)."""
        groups: dict = {}
        for mine, theirs in zip((*self.fixed, *self.state), (*fixed, *state)):
            if mine is not theirs:
                pair = groups.setdefault((mine.dtype, mine.dim()), ([], []))
                pair[0].append(mine)
                pair[1].append(theirs)
        for mine, theirs in groups.values():
            torch._foreach_copy_(mine, theirs)
        for _ in range(replays):
            self.graph.replay()
        return self.fixed, self.state


_GRAPHS: collections.OrderedDict = collections.OrderedDict()
_MAX_GRAPHS = 32


def _step_graph(steps, fixed, state, tables, m: int, fuse: int, any_hit: bool, calls: int):
    """The cached :class:`_StepGraph` for these tables and this size (:func:`_cached`)."""
    key = (
        len(fixed[1]),
        fixed[0].dtype,
        fixed[0].device,
        m,
        fuse,
        any_hit,
        calls,
        tuple(t.data_ptr() for t in tables),
    )
    return _cached(
        key, tables, lambda: _StepGraph(steps, fixed, state, (tables, m, fuse, any_hit), calls)
    )


def _cached(key, tables, make):
    """The graph cached under ``key``, or ``make()``'s, kept (least recently used ones
    dropped beyond ``_MAX_GRAPHS``). The key holds the tables' addresses and the entry the
    tables themselves, so a cached graph never reads freed memory."""
    entry = _GRAPHS.get(key)
    if entry is not None and all(a is b for a, b in zip(entry[0], tables)):
        _GRAPHS.move_to_end(key)
        return entry[1]
    graph = make()
    _GRAPHS[key] = (tables, graph)
    while len(_GRAPHS) > _MAX_GRAPHS:
        _GRAPHS.popitem(last=False)
    return graph


def _fast_step(
    ox,
    oy,
    oz,
    dx,
    dy,
    dz,
    ix,
    iy,
    iz,
    t_min,
    t_max,
    base,
    node,
    slot,
    end,
    best_t,
    best_tri,
    best_u,
    best_v,
    steps,
    tests,
    boxes,
    links,
    slots,
    tri_of,
    m: int,
    any_hit: bool,
):
    """One step of :func:`bvh_closest_hit_fast` for every ray: (n,) columns in, the new
    state out, no host sync, no scatter, no data-dependent Python control flow.
    Rays: origin, direction, inverse direction columns, ``t_min, t_max`` and ``base`` (the
    row of the octant's array, int32). State: ``node`` (``m`` = done), ``slot < end``: the
    leaf slots still to test, closest ``t, triangle, u, v``, counters. Tables:
    :func:`pack_bvh`'s ``boxes, links, slots, tri``."""
    active = node < m
    leafing = active & (slot < end)
    row = base + torch.where(active, node, 0)  # finished rays all read row 0: cached
    # The node's box, against [t_min, min(t_max, reach(closest t))]: the conservative slab
    # test (far widened by 1 + 2 gamma(3)) against the closest hit widened by its rounding.
    grow = 1 + 2 * gamma(3, ox.dtype)
    t_in, t_out = t_min, torch.minimum(t_max, reach(best_t))
    for a, (o, inv) in enumerate(((ox, ix), (oy, iy), (oz, iz))):
        t0 = (boxes[row, a] - o) * inv
        t1 = (boxes[row, 3 + a] - o) * inv
        t_in = torch.fmax(t_in, torch.minimum(t0, t1))
        t_out = torch.fmin(t_out, torch.maximum(t0, t1) * grow)
    entered = active & ~leafing & (t_in <= t_out)  # d != 0: some axis bounds t_out
    skip, first, count = links[row, 0], links[row, 1], links[row, 2]
    # The leaf slot (slot 0 for rays that are not in a leaf: cached, the result unused).
    s = torch.where(leafing, slot, 0)
    tri = slots[s]
    t, u, v, hit = moller_trumbore_rows(
        (ox, oy, oz),
        (dx, dy, dz),
        tri[:, 0:3].unbind(1),
        tri[:, 3:6].unbind(1),
        tri[:, 6:9].unbind(1),
        t_min,
        t_max,
    )
    index = tri_of[s]
    better = leafing & hit & ((t < best_t) | ((t == best_t) & (index < best_tri)))
    best_t = torch.where(better, t, best_t)
    best_tri = torch.where(better, index, best_tri)
    best_u = torch.where(better, u, best_u)
    best_v = torch.where(better, v, best_v)
    steps = steps + (active & ~leafing).int()  # box tests
    tests = tests + leafing.int()
    # Next: descend into an inner node, enter a leaf's slots, or skip the subtree.
    into_leaf = entered & (count > 0)
    leaf_done = leafing & (slot + 1 >= end)
    stay = into_leaf | (leafing & ~leaf_done)
    down = entered & (count == 0)
    node = torch.where(active & ~stay, torch.where(down, node + 1, skip), node)
    slot = torch.where(leafing, slot + 1, torch.where(into_leaf, first, slot))
    end = torch.where(into_leaf, first + count, end)
    if any_hit:
        node = torch.where(best_tri >= 0, m, node)
    return node, slot, end, best_t, best_tri, best_u, best_v, steps, tests


def _fast_steps_in_place(fixed, state, tables, m: int, k: int, any_hit: bool):
    """:func:`_fast_steps` writing the new state into ``state``'s tensors (for a CUDA graph
    replayed many times); elementwise, so each ray reads its state before it writes it."""
    for x, new in zip(state, _fast_steps(fixed, state, tables, m, k, any_hit)):
        x.copy_(new)
    return state


_COMPILED: dict = {}


def _compiled_fast_steps(mode):
    """``torch.compile`` of :func:`_fast_steps` (``"in place"``: of
    :func:`_fast_steps_in_place`, as ``"default"``), one per mode, kept across calls
    (dynamic shapes: compaction changes the number of rays without a recompile)."""
    mode = "default" if mode is True else mode
    if mode not in _COMPILED:
        # Every (k, any-hit, dtype) is a specialisation of its own: allow enough of them
        # that none falls back to eager after dynamo's default limit of 8.
        torch._dynamo.config.recompile_limit = max(torch._dynamo.config.recompile_limit, 64)
        fn = _fast_steps_in_place if mode == "in place" else _fast_steps
        _COMPILED[mode] = torch.compile(
            fn, mode="default" if mode == "in place" else mode, dynamic=True
        )
    return _COMPILED[mode]


# END SOLUTION
