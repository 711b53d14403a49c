# Lab 2 reference, task 7: the sync-free BVH walk (bvh_closest_hit_fast, CUDA graphs).
# Run by solutions/lab2_accel.py in its own namespace: its imports and the other parts'
# functions are this file's globals (see that file's docstring).
from __future__ import annotations

# =======================================================================================
# Task 7: sync-free BVH traversal


def bvh_closest_hit_fast(rays: Rays, mesh: Mesh, bvh: dict, any_hit: bool = False,
                         check_every: int = 8, compile=False, compact: bool = True,
                         walk: dict | None = None, fuse_steps: int = 1):
    """Closest (or any) hits through a BVH with fixed shapes: no host sync inside the loop,
    and no stack: a step any compiler can fuse with the next.

    rays: N rays; mesh: the BVH's mesh; bvh: a BVH dict; any_hit: stop each ray at its
    first hit (shadow rays: "is anything in ``[t_min, t_max]``?"); check_every: ``k``, the
    steps run between two looks at the rays (a look reads how many still run: on a GPU one
    look late, see below); compile: False, True or a ``torch.compile`` mode for the steps;
    ``"reduce-overhead"`` compiles them as ``"default"`` and, on a GPU, replays the ``k``
    steps of a look from one CUDA graph, captured once per (padded) number of rays and
    kept for later calls with the same ``walk`` (packed here: a graph of one step,
    replayed ``k`` times, not kept); compact: at a look, drop finished rays if at most
    half (a quarter with graphs) may still be running; walk: ``pack_bvh(bvh, mesh)``, to
    pack a tree once and trace it many times (default: packed here, for the octants of
    these rays);
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
      (``node == M``); rays that miss the root box never start (one host sync, before any
      step is queued). The rays live in two tensors, one column each (floats: origin,
      direction, inverse, ``t_min, t_max``, closest ``t, u, v``; int32: octant row, node,
      slot, end, counters, triangle, the ray's column in the outputs), with at least one
      finished padding column after them;
    * a step does **one** box test and **one** triangle test per ray and keeps what its
      state asks for: outside a leaf, the node's box (hit: descend to ``i + 1``, or enter
      the leaf's slots; miss or beyond the closest hit: ``skip``); inside a leaf, the next
      slot (Möller–Trumbore in the mesh's dtype; ties to the lowest triangle index);
      after the last slot, ``skip``;
    * the host looks only every ``k`` steps: stop when every ray is done, compact if few
      rays are left. On a GPU a look queues its steps, then copies the count of running
      rays asynchronously to pinned host memory and records an event; the host then waits
      only on the *previous* look's event, so the device always has the next look queued
      while the host reads a count and decides. Rays only finish, so that count bounds
      the rays running now: it sizes a compaction, and the one look too many run at the
      end only steps finished rays. A compaction has no sync either: a cumulative sum of
      the running flags gives each running ray its new column, scattered into an index
      vector whose other entries point at the padding column; two ``index_select`` gather
      both tensors straight into the next buffers (with graphs: the next graph's own), and
      one indexed write per tensor puts every ray's results in the outputs (padding into
      a spare last column);
    * a step is gathers from read-only tables and elementwise ops, nothing else, so
      ``torch.compile`` turns it into **one kernel** (one thread per ray, the state in
      registers): the lecture's kernel, written in torch; on a GPU one CUDA graph holds
      the ``k`` steps between two looks. With a ``walk`` packed once, the rays are padded
      (with finished ones) to a few sizes, so the graphs of a size are captured once and
      replayed by every later traversal of that size: a warm traversal pays no capture and
      no compiled call. A warm look is a graph launch, a copy and an event on the host.

    The triangle test is Lab 1's Möller–Trumbore (relative parallel test) written inline,
    in the mesh's dtype, so it can be fused; it agrees with brute force with that kernel
    (rounding may decide a ray grazing an edge differently when the ops are fused).
    """
    check_trace_inputs(rays, mesh, moller_trumbore_rows)
    check_structure(bvh, "bvh", "bvh", mesh)
    _positive_int(check_every, "check_every", 1, 1024)
    _positive_int(fuse_steps, "fuse_steps", 1, 64)
    if compile not in (False, True, "default", "reduce-overhead", "max-autotune",
                       "max-autotune-no-cudagraphs"):
        raise ValueError(f"compile: expected False, True or a torch.compile mode, got {compile!r}")
    o, d, inv = rays.origins, rays.directions, 1 / rays.directions
    octant = ray_octants(d)  # the array whose order is near-first for the ray
    packed_here = walk is None  # fresh tables: no later call can reuse graphs that read them
    if packed_here:  # only the octants these rays go in
        walk = pack_bvh(bvh, mesh, torch.unique(octant).tolist())
    else:
        check_walk(walk, mesh, rays)
    n, device, dtype = len(rays), rays.device, rays.dtype
    m = walk["nodes"]
    _, _, hit_root = slab_test(o, inv, walk["lo"], walk["hi"], rays.t_min, rays.t_max)
    # The outputs (t, u, v) and (steps, tests, triangle), one column per ray and one more:
    # the column padding rays write to, so a write-back needs no mask.
    out_f = torch.zeros((3, n + 1), dtype=dtype, device=device)
    out_f[0] = math.inf
    out_i = torch.zeros((3, n + 1), dtype=torch.int32, device=device)
    out_i[2] = -1
    # The rest miss everything: they never start. The one blocking sync before the steps,
    # while the device has only this setup queued; it sizes the first buffers exactly.
    ray = hit_root.nonzero()[:, 0]
    graphs = compile == "reduce-overhead" and device.type in _GRAPH_DEVICES
    steps = _fast_steps if compile is False else _compiled_fast_steps(compile)
    # k steps as calls of `fuse` steps each (eager: one call of k); extra steps of finished
    # rays change nothing, so the counters never depend on the knobs.
    fuse = check_every if compile is False else min(fuse_steps, check_every)
    calls = -(-check_every // fuse)
    how = "cached" if graphs and not packed_here else "graph" if graphs else "eager"
    args = ((walk["boxes"], walk["links"], walk["slots"], walk["tri"]), m, fuse, bool(any_hit))
    if len(ray):
        run = _ray_buffers(how, _size(how, len(ray)), steps, dtype, device, args, calls)
        _start(run, rays, inv, walk["base"][octant[ray]], ray, m)
        looks = _Looks(device)
        for _ in range(0, m + mesh.num_faces + 1, calls * fuse):  # a step per node or slot
            looks.put(run.run())  # k steps queued, then the number of rays still running
            bound = looks.get()  # an earlier look's count (None: none read yet)
            if bound is None:
                continue
            if bound == 0:  # every ray was done at that look: the later steps did nothing
                break
            # Rays only finish: at most `bound` run now. Compact only when it saves the device
            # far more than it costs (about ten small ops, no sync).
            size = _size(how, bound)
            if compact and bound <= run.size // (4 if graphs else 2) and size < run.size:
                new = _ray_buffers(how, size, steps, dtype, device, args, calls)
                _compact(run, new, m, out_f, out_i)
                run = new
        _write_back(run, out_f, out_i)
    return (Hits(t=out_f[0, :n], triangle=out_i[2, :n].long(), u=out_f[1, :n], v=out_f[2, :n]),
            {"steps": out_i[0, :n].long(), "tests": out_i[1, :n].long()})


# A walk's rays, one column each, in two tensors (so a compaction is two gathers): floats
# (_FLOATS rows: ox oy oz dx dy dz ix iy iz t_min t_max, read only, then the closest t u v)
# and int32 (_INTS rows: the octant's base row, read only; node (m: done), slot, end, steps,
# tests, closest triangle; the ray's column in the outputs, n for padding).
_FIXED, _FLOATS = 11, 14
_BASE, _NODE, _STEPS, _TRI, _RAY, _INTS = 0, 1, 4, 6, 7, 8
_GRAPH_DEVICES = ("cuda",)  # where "reduce-overhead" replays CUDA graphs
_LAG = {"cuda": 1}  # per device: looks queued beyond the one whose count is read


def _fast_steps(floats, ints, tables, m: int, k: int, any_hit: bool):
    """``k`` steps of :func:`bvh_closest_hit_fast` on the rays' buffers (``floats``,
    ``ints``: see ``_FLOATS``), updated in place; nothing here waits for the device (what
    ``torch.compile`` fuses). Elementwise, so each ray reads its state before it writes it."""
    columns = floats.unbind(0)
    base, node, slot, end, steps, tests, tri, _ = ints.unbind(0)
    t, u, v = columns[_FIXED:]
    state = (node, slot, end, t, tri, u, v, steps, tests)
    for _ in range(k):
        state = _fast_step(*columns[:_FIXED], base, *state, *tables, m, any_hit)
    node, slot, end, t, tri, u, v, steps, tests = state
    floats[_FIXED:].copy_(torch.stack((t, u, v)))
    ints[_NODE:_RAY].copy_(torch.stack((node, slot, end, steps, tests, tri)))


def _graph_size(n: int) -> int:
    """The number of rays a graph is captured for: ``n`` rounded up to a multiple of a
    sixteenth of its power of two (at most ~12% padding), so that the sizes a compaction
    produces repeat from call to call and their graphs are reused."""
    quantum = max(128, 1 << max(0, n.bit_length() - 4))
    return -(-n // quantum) * quantum


def _size(how: str, count: int) -> int:
    """The columns of the buffers for ``count`` rays: at least one more, a finished padding
    ray (what a compaction fills the columns past the running rays with); with cached
    graphs, a graph size."""
    return _graph_size(count + 1) if how == "cached" else count + 1


def _ray_buffers(how: str, size: int, steps, dtype, device, args, calls: int):
    """Buffers of ``size`` columns, and what steps them: ``"cached"``, a kept
    :class:`_StepGraph`; ``"graph"``, one of this call (one compiled call, replayed
    ``calls`` times); ``"eager"``, :class:`_Steps` (eager or compiled calls)."""
    if how == "cached":
        return _step_graph(steps, size, dtype, device, args, calls)
    if how == "graph":
        return _StepGraph(steps, size, dtype, device, args, 1, calls)
    return _Steps(steps, size, dtype, device, args, calls)


def _start(run, rays, inv, base, ray, m: int) -> None:
    """Write the rays ``ray`` (their octants' ``base`` rows) to the first columns of
    ``run``'s buffers, not started; every later column a finished padding ray."""
    floats, ints, s = run.floats, run.ints, len(ray)
    floats[:_FIXED, :s] = torch.cat((rays.origins, rays.directions, inv, rays.t_min[:, None],
                                     rays.t_max[:, None]), 1)[ray].T
    floats[_FIXED] = math.inf
    floats[_FIXED + 1:] = 0
    ints[_BASE, :s] = base
    ints[_BASE, s:] = 0  # any row of the tables: padding reads but never uses it
    ints[_NODE:_TRI] = 0  # node, slot, end, steps, tests
    ints[_NODE, s:] = m
    ints[_TRI] = -1
    ints[_RAY, :s] = ray
    ints[_RAY, s:] = len(rays)


def _write_back(run, out_f, out_i) -> None:
    """Every ray of ``run`` to its column of the outputs (padding to the last column)."""
    ray = run.ints[_RAY]
    out_f[:, ray] = run.floats[_FIXED:]
    out_i[:, ray] = run.ints[_STEPS:_RAY]


def _compact(src, dst, m: int, out_f, out_i) -> None:
    """The rays still running in ``src`` to the first columns of ``dst`` (more columns than
    they), the rest of ``dst`` copies of ``src``'s last column (padding, never running); the
    rays of ``src`` written back first (those that finished are written there only). No host
    sync: positions come from a cumulative sum, scattered into an index vector."""
    _write_back(src, out_f, out_i)
    running = src.ints[_NODE] < m
    position = torch.where(running, running.cumsum(0), 0)  # 1 + the column in dst; 0: none
    index = torch.full((dst.size + 1,), src.size - 1, dtype=torch.int64, device=running.device)
    index.scatter_(0, position, torch.arange(src.size, device=running.device))
    torch.index_select(src.floats, 1, index[1:], out=dst.floats)
    torch.index_select(src.ints, 1, index[1:], out=dst.ints)


def _new_buffers(size: int, dtype, device, m: int):
    """Buffers of ``size`` finished rays."""
    ints = torch.zeros((_INTS, size), dtype=torch.int32, device=device)
    ints[_NODE] = m
    return torch.zeros((_FLOATS, size), dtype=dtype, device=device), ints


class _Steps:
    """The rays' buffers, stepped by ``calls`` calls of ``steps`` (eager or compiled)."""

    def __init__(self, steps, size: int, dtype, device, args, calls: int):
        self.size, self.steps, self.args, self.calls = size, steps, args, calls
        self.floats = torch.empty((_FLOATS, size), dtype=dtype, device=device)
        self.ints = torch.empty((_INTS, size), dtype=torch.int32, device=device)

    def run(self):
        """The steps of one look; returns the number of rays still running (a tensor)."""
        for _ in range(self.calls):
            self.steps(self.floats, self.ints, *self.args)
        return (self.ints[_NODE] < self.args[1]).sum()


class _StepGraph:
    """The ``calls`` compiled calls of one look of :func:`bvh_closest_hit_fast`, updating
    its own buffers (``floats``, ``ints``) in place, and the count of rays still running
    after them (``count``), captured once in a CUDA graph for a number of rays and replayed
    at every look of every later traversal of that size: one graph launch per look instead
    of ``calls`` compiled calls (whose Python wrappers cost more host time than their
    kernels' device time), and no capture after a compaction once the sizes have been seen.

    A traversal writes its rays into the buffers (a compaction gathers straight into the
    next graph's). A walk packed inside the call (``walk=None``) has tables no later call
    reads: its graphs hold one call, replayed ``replays`` times, and are not kept (a
    capture then costs one compiled call)."""

    def __init__(self, steps, size: int, dtype, device, args, calls: int, replays: int = 1):
        self.size, self.replays = size, replays
        self.floats, self.ints = _new_buffers(size, dtype, device, args[1])
        self.count = torch.zeros((), dtype=torch.int64, device=device)
        # One call first, outside the capture, on copies: whatever the compiler still has
        # to (re)compile for these shapes happens there.
        steps(self.floats.clone(), self.ints.clone(), *args)
        # capture_begin/end on a side stream, not the torch.cuda.graph context: that one
        # runs gc.collect() and empties the cache at every capture (tens of ms each).
        self.graph = torch.cuda.CUDAGraph()
        side = torch.cuda.Stream()
        side.wait_stream(torch.cuda.current_stream())
        with torch.cuda.stream(side):
            self.graph.capture_begin()
            for _ in range(calls):
                steps(self.floats, self.ints, *args)
            self.count.copy_((self.ints[_NODE] < args[1]).sum())
            self.graph.capture_end()
        torch.cuda.current_stream().wait_stream(side)

    def run(self):
        """Replay: the steps of one look; returns ``count`` (rewritten by the next replay)."""
        for _ in range(self.replays):
            self.graph.replay()
        return self.count


class _Looks:
    """The counts of rays still running, read ``_LAG[device]`` looks late: on a GPU each is
    copied (asynchronously) to pinned host memory behind its look, with an event, and the
    host waits only on the event of an earlier look, so the device always has the next
    look queued while the host decides. Rays only finish, so a late count bounds the
    number running now; a look too many only steps finished rays. Elsewhere (lag 0) a
    count is read at once."""

    def __init__(self, device):
        self.lag, self.cuda = _LAG.get(device.type, 0), device.type == "cuda"
        self.pending = collections.deque()
        if self.cuda:  # a slot per look in flight, reused only once read
            host = torch.empty(self.lag + 2, dtype=torch.int64, pin_memory=True)
            self.slots = list(host.unbind())
            self.events = [torch.cuda.Event() for _ in self.slots]
            self.next = 0

    def put(self, count) -> None:
        """The count (a 0-d device tensor) of the look just queued."""
        if not self.cuda:
            self.pending.append(int(count))
            return
        i, self.next = self.next, (self.next + 1) % len(self.slots)
        self.slots[i].copy_(count, non_blocking=True)
        self.events[i].record()
        self.pending.append(i)

    def get(self):
        """The oldest count not yet read, once ``lag`` later looks are queued (else None)."""
        if len(self.pending) <= self.lag:
            return None
        i = self.pending.popleft()
        if not self.cuda:
            return i
        self.events[i].synchronize()
        return int(self.slots[i])


_GRAPHS: collections.OrderedDict = collections.OrderedDict()
_MAX_GRAPHS = 32


def _step_graph(steps, size: int, dtype, device, args, calls: int):
    """The cached :class:`_StepGraph` for these tables and this size (least recently used
    ones dropped beyond ``_MAX_GRAPHS``). The key holds the tables' addresses and the entry
    the tables themselves, so a cached graph never reads freed memory."""
    tables = args[0]
    key = (size, dtype, torch.device(device), *args[1:], calls,
           tuple(t.data_ptr() for t in tables))
    entry = _GRAPHS.get(key)
    if entry is not None and all(a is b for a, b in zip(entry[0], tables)):
        _GRAPHS.move_to_end(key)
        return entry[1]
    graph = _StepGraph(steps, size, dtype, device, args, calls)
    _GRAPHS[key] = (tables, graph)
    while len(_GRAPHS) > _MAX_GRAPHS:
        _GRAPHS.popitem(last=False)
    return graph


def _fast_step(ox, oy, oz, dx, dy, dz, ix, iy, iz, t_min, t_max, base,
               node, slot, end, best_t, best_tri, best_u, best_v, steps, tests,
               boxes, links, slots, tri_of, m: int, any_hit: bool):
    """One step of :func:`bvh_closest_hit_fast` for every ray: (n,) columns in, the new
    state out, no host sync, no scatter, no data-dependent Python control flow.
    Rays: origin, direction, inverse direction columns, ``t_min, t_max`` and ``base`` (the
    row of the octant's array, int32). State: ``node`` (``m`` = done), ``slot < end``: the
    leaf slots still to test, closest ``t, triangle, u, v``, counters. Tables:
    :func:`pack_bvh`'s ``boxes, links, slots, tri``."""
    active = node < m
    leafing = active & (slot < end)
    row = base + torch.where(active, node, 0)  # finished rays all read row 0: cached
    # The node's box, against [t_min, min(t_max, closest t)] (the conservative slab test).
    grow = 1 + 2 * gamma(3, ox.dtype)
    t_in, t_out = t_min, torch.minimum(t_max, best_t)
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
    t, u, v, hit = moller_trumbore_rows((ox, oy, oz), (dx, dy, dz), tri[:, 0:3].unbind(1),
                                        tri[:, 3:6].unbind(1), tri[:, 6:9].unbind(1), t_min,
                                        t_max)
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


_COMPILED: dict = {}


def _compiled_fast_steps(mode):
    """``torch.compile`` of :func:`_fast_steps`, one per mode, kept across calls (dynamic
    shapes: compaction changes the number of rays without a recompile). ``True`` and
    ``"reduce-overhead"`` compile as ``"default"``: on a GPU the walk replays its own CUDA
    graphs (the compiler's would skip a function that writes its inputs anyway)."""
    mode = "default" if mode in (True, "reduce-overhead") else mode
    if mode not in _COMPILED:
        # Every (k, any-hit, dtype) is a specialisation of its own: allow enough of them
        # that none falls back to eager after dynamo's default limit of 8.
        torch._dynamo.config.recompile_limit = max(torch._dynamo.config.recompile_limit, 64)
        _COMPILED[mode] = torch.compile(_fast_steps, mode=mode, dynamic=True)
    return _COMPILED[mode]
