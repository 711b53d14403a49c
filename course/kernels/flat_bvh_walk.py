"""The flat BVH's torch walk (``trace_flat_torch``) and the ray checks every tracer of it
shares (``check_rays``, ``check_ray_bounds``, ``valid_rays``). Part of
:mod:`course.kernels.flat_bvh`.
"""

from __future__ import annotations

import math

import torch

from course.core.types import Hits
from course.given.lab2_blocks import expand_ranges
from course.kernels.flat_bvh_build import _one_cpu_thread
from course.kernels.flat_bvh_layout import EXIT_SCALE, HIT_SLACK, STACK_DEPTH, FlatBVH

# --------------------------------------------------------------------------------------
# Tracing
# --------------------------------------------------------------------------------------


def check_rays(origins, directions, t_min, t_max):
    """Validate a tracer's ray arguments; returns float32 ``(o, d, t_lo, t_hi)``, each
    contiguous, (N, 3), (N, 3), (N,), (N,), on the origins' device.

    origins, directions: (N, 3) float tensors; t_min, t_max: numbers or (N,) tensors.
    Raises TypeError/ValueError naming the argument.
    """
    o, d, (lo, lo_value), (hi, hi_value) = check_ray_bounds(origins, directions, t_min, t_max)
    n, device = o.shape[0], o.device
    full = {"dtype": torch.float32, "device": device}
    return (
        o,
        d,
        torch.full((n,), lo_value, **full) if lo is None else lo,
        torch.full((n,), hi_value, **full) if hi is None else hi,
    )


def check_ray_bounds(origins, directions, t_min, t_max):
    """:func:`check_rays` for kernels that take numbers as numbers: returns ``(o, d,
    (t_lo, t_lo_value), (t_hi, t_hi_value))`` where a bound given as a number comes back
    as ``(None, value)`` and one given as a tensor as ``((N,) float32 tensor, 0.0)``.
    """
    for name, x in (("origins", origins), ("directions", directions)):
        if not isinstance(x, torch.Tensor):
            raise TypeError(f"{name}: expected a (N, 3) float tensor, got {type(x).__name__}")
        if not x.is_floating_point():
            raise TypeError(f"{name}: expected a floating-point tensor, got {x.dtype}")
        if x.ndim != 2 or x.shape[1] != 3:
            raise ValueError(f"{name}: expected shape (N, 3), got {tuple(x.shape)}")
    if directions.shape != origins.shape:
        raise ValueError(
            f"directions: expected shape {tuple(origins.shape)} like origins, "
            f"got {tuple(directions.shape)}"
        )
    if directions.device != origins.device:
        raise ValueError(
            f"directions: expected device {origins.device} like origins, got {directions.device}"
        )
    n, device = origins.shape[0], origins.device
    bounds = []
    for name, x in (("t_min", t_min), ("t_max", t_max)):
        if isinstance(x, torch.Tensor):
            if x.device != device:
                raise ValueError(f"{name}: expected device {device} like origins, got {x.device}")
            if x.shape not in (torch.Size([n]), torch.Size([])):
                raise ValueError(f"{name}: expected shape ({n},) or a scalar, got {tuple(x.shape)}")
            if not x.is_floating_point():
                raise TypeError(f"{name}: expected a floating-point tensor, got {x.dtype}")
            bounds.append((x.to(torch.float32).expand(n).contiguous(), 0.0))
        elif isinstance(x, (int, float)) and not isinstance(x, bool):
            bounds.append((None, float(x)))
        else:
            raise TypeError(f"{name}: expected a number or a ({n},) tensor, got {type(x).__name__}")
    return (
        origins.to(torch.float32).contiguous(),
        directions.to(torch.float32).contiguous(),
        *bounds,
    )


def valid_rays(
    o: torch.Tensor, d: torch.Tensor, t_lo: torch.Tensor, t_hi: torch.Tensor
) -> torch.Tensor:
    """(N,) bool: rays that can hit anything (finite, nonzero direction, t_min <= t_max)."""
    return (
        torch.isfinite(o).all(1)
        & torch.isfinite(d).all(1)
        & (d != 0).any(1)
        & ~torch.isnan(t_lo)
        & ~torch.isnan(t_hi)
        & (t_lo <= t_hi)
    )


def _slab(o, inv, lo, hi, t_lo, t_hi):
    """Rays (n, 3) against boxes (n, 3): the box-test contract of the module docstring."""
    t0 = (lo - o) * inv
    t1 = (hi - o) * inv
    near = torch.minimum(t0, t1).nan_to_num(nan=-math.inf, posinf=math.inf, neginf=-math.inf)
    far = torch.maximum(t0, t1).nan_to_num(nan=math.inf, posinf=math.inf, neginf=-math.inf)
    enter = torch.maximum(t_lo, near.amax(1))
    far = far.amin(1)
    # Widened away from zero (a negative distance is scaled toward it), by multiplications:
    # the exit by its own rounding, then the interval's end by the triangle test's.
    leave = torch.minimum(t_hi, far * torch.where(far >= 0, EXIT_SCALE, 2.0 - EXIT_SCALE))
    leave = leave * torch.where(leave >= 0, 1.0 + HIT_SLACK, 1.0 - HIT_SLACK)
    return enter, enter <= leave


def _mt(o, d, rows):
    """Möller–Trumbore of rays (n, 3) against rows (n, 12) of the triangle layout, float32.

    Returns (t, u, v); NaN/inf where det = 0 (comparisons with them fail: a miss)."""
    v0, e1, e2 = rows[:, 0:3], rows[:, 4:7], rows[:, 8:11]
    p = torch.linalg.cross(d, e2)
    det = (e1 * p).sum(1)
    inv = 1.0 / det
    s = o - v0
    q = torch.linalg.cross(s, e1)
    return (e2 * q).sum(1) * inv, (s * p).sum(1) * inv, (d * q).sum(1) * inv


def trace_flat_torch(
    bvh: FlatBVH, origins, directions, t_min=0.0, t_max=math.inf, any_hit: bool = False
) -> Hits:
    """The traversal contract (module docstring) in vectorised torch: the CPU fallback.

    Every ray takes one step per iteration (visit a node, or test its current leaf's
    triangles, all of them at once), working only on the rays still alive; the Python loop
    runs over traversal steps, never over rays. Same arguments as ``trace_bvh``, with
    the BVH given; returns float32 Hits on the rays' device.
    """
    o, d, t_lo, t_hi = check_rays(origins, directions, t_min, t_max)
    with _one_cpu_thread(o.device):
        return _walk(bvh.to(o.device), o, d, t_lo, t_hi, any_hit)


def _walk(bvh: FlatBVH, o, d, t_lo, t_hi, any_hit: bool) -> Hits:
    device, n = o.device, o.shape[0]
    nodes, ints, rows = bvh.nodes, bvh.node_ints, bvh.triangles
    tri_index = bvh.order
    inv = 1.0 / d
    best_t = t_hi.clone()
    best_row = torch.full((n,), -1, dtype=torch.int64, device=device)
    best_u = torch.zeros(n, device=device)
    best_v = torch.zeros(n, device=device)
    stack = torch.zeros(n, STACK_DEPTH, dtype=torch.int64, device=device)
    sp = torch.zeros(n, dtype=torch.int64, device=device)
    node = torch.zeros(n, dtype=torch.int64, device=device)
    alive = valid_rays(o, d, t_lo, t_hi)
    _, root_hit = _slab(o, inv, nodes[0, :3].expand(n, 3), nodes[0, 3:6].expand(n, 3), t_lo, t_hi)
    alive &= root_hit
    big = torch.iinfo(torch.int64).max
    lane = alive.nonzero()[:, 0]
    while len(lane):
        nd = node[lane]
        count = ints[nd, 7].long()
        leaf = count > 0
        # Leaves: all their triangles at once (count <= leaf_size), then pop.
        lf = lane[leaf]
        if len(lf):
            first = ints[nd[leaf], 6].long()
            owner, row = expand_ranges(first, count[leaf])
            ray = lf[owner]
            t, u, v = _mt(o[ray], d[ray], rows[row])
            tri = tri_index[row]
            ok = (u >= 0) & (v >= 0) & (u + v <= 1) & (t >= t_lo[ray]) & (t <= best_t[ray])
            if any_hit:
                # One hit per ray (its first pair), so t, row, u, v come from one triangle.
                pair = torch.arange(len(ray), device=device)
                first_pair = torch.full((n,), len(ray), dtype=torch.int64, device=device)
                first_pair.scatter_reduce_(0, ray[ok], pair[ok], "amin")
                win = pair[ok & (first_pair[ray] == pair)]
                wr = ray[win]
                best_t[wr], best_row[wr] = t[win], row[win]
                best_u[wr], best_v[wr] = u[win], v[win]
                alive[wr] = False
            else:
                # Per ray: the smallest t, then the lowest original index at that t, against
                # the best so far (current best_row's index competes only at equal t).
                t_ok = torch.where(ok, t, math.inf)
                nearest = best_t.clone().scatter_reduce_(0, ray, t_ok, "amin")
                cur_tri = torch.where(best_row >= 0, tri_index[best_row.clamp(min=0)], big)
                cand = ok & (t == nearest[ray])
                low = torch.where(best_t == nearest, cur_tri, big)
                low = low.scatter_reduce(0, ray[cand], tri[cand], "amin")
                win = cand & (tri == low[ray])
                wr = ray[win]
                best_t[wr], best_row[wr] = t[win], row[win]
                best_u[wr], best_v[wr] = u[win], v[win]
        # Interior nodes: test both children, go to the nearer hit, push the farther.
        inner = lane[~leaf]
        if len(inner):
            a = nd[~leaf] + 1
            b = ints[nd[~leaf], 6].long()
            oi, ii, lo_i, hi_i = o[inner], inv[inner], t_lo[inner], best_t[inner]
            ta, ha = _slab(oi, ii, nodes[a, :3], nodes[a, 3:6], lo_i, hi_i)
            tb, hb = _slab(oi, ii, nodes[b, :3], nodes[b, 3:6], lo_i, hi_i)
            b_first = hb & (~ha | (tb < ta))
            near = torch.where(b_first, b, a)
            far = torch.where(b_first, a, b)
            both = ha & hb
            push = inner[both]
            stack[push, sp[push]] = far[both]
            sp[push] += 1
            node[inner] = near
            # Neither child hit: pop, like after a leaf.
            popping = torch.cat([lf, inner[~(ha | hb)]])
        else:
            popping = lf
        popping = popping[alive[popping]]
        empty = sp[popping] == 0
        alive[popping[empty]] = False
        pop = popping[~empty]
        sp[pop] -= 1
        node[pop] = stack[pop, sp[pop]]
        lane = lane[alive[lane]]
    hit = best_row >= 0
    tri = torch.where(hit, tri_index[best_row.clamp(min=0)], -1)
    return Hits(
        t=torch.where(hit, best_t, math.inf),
        triangle=tri,
        u=torch.where(hit, best_u, 0.0),
        v=torch.where(hit, best_v, 0.0),
    )
