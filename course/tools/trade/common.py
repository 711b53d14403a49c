"""What every lab's trade module shares: the exact answers brute force gives, timing one
setting, and the error measures."""

from __future__ import annotations

import math

import torch

from course.core.types import Mesh, Rays
from course.measure.bench import time_fn

F64 = torch.float64


def timed(ctx: dict, fn, *args, **kwargs):
    """``(result, seconds)``: the first call's result (it is also the warm-up) and the median
    of ``ctx["repeats"]`` timed calls (:func:`course.measure.bench.time_fn`)."""
    result = fn(*args, **kwargs)
    timing = time_fn(fn, *args, repeats=ctx["repeats"], warmup=0, device=ctx["device"], **kwargs)
    return result, timing.median


def exact_hits(rays: Rays, mesh: Mesh, pairs: int = 1 << 20) -> tuple[torch.Tensor, torch.Tensor]:
    """``(t, triangle)`` of every ray's closest hit, by float64 brute force on the CPU (every
    ray against every triangle, Möller–Trumbore without an epsilon): the exact answer
    Labs 1, 2 and 6 are measured against, whatever the implementation under test does.
    ``t`` is inf and ``triangle`` -1 where a ray misses."""
    o, d = rays.origins.detach().to("cpu", F64), rays.directions.detach().to("cpu", F64)
    t_min, t_max = rays.t_min.detach().to("cpu", F64), rays.t_max.detach().to("cpu", F64)
    corners = mesh.vertices.detach().to("cpu", F64)[mesh.faces.cpu()]
    v0, e1, e2 = corners[:, 0], corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]
    best_t = torch.full((len(o),), math.inf, dtype=F64)
    best = torch.full((len(o),), -1, dtype=torch.int64)
    step = max(1, pairs // max(1, len(v0)))
    for start in range(0, len(o), step):
        sl = slice(start, start + step)
        oo, dd = o[sl, None], d[sl, None]
        p = torch.linalg.cross(dd.expand(-1, len(e2), -1), e2[None].expand(len(oo), -1, -1))
        det = (e1[None] * p).sum(-1)
        inv = 1.0 / det
        s = oo - v0[None]
        u = (s * p).sum(-1) * inv
        q = torch.linalg.cross(s, e1[None].expand_as(s))
        v = (dd * q).sum(-1) * inv
        t = (e2[None] * q).sum(-1) * inv
        ok = (
            (det != 0)
            & (u >= 0)
            & (v >= 0)
            & (u + v <= 1)
            & (t >= t_min[sl, None])
            & (t <= t_max[sl, None])
        )
        t = torch.where(ok, t, math.inf)
        tb, ib = t.min(1)
        best_t[sl], best[sl] = tb, torch.where(torch.isfinite(tb), ib, -1)
    return best_t, best


def hit_disagreement(t, triangle, exact_t, exact_triangle, rel: float = 1e-4) -> float:
    """Fraction of rays whose hit is not the exact one: hit where it missed (or the other
    way), or another triangle at another distance (a triangle sharing the exact hit's
    point, within ``rel`` of its ``t``, counts as the same hit: an edge or a vertex)."""
    t = t.detach().to("cpu", F64)
    triangle = triangle.detach().cpu()
    got, want = triangle >= 0, exact_triangle >= 0
    same_t = (t - exact_t).abs() <= rel * exact_t.abs().clamp(min=1e-30)
    wrong = (got != want) | (got & want & (triangle != exact_triangle) & ~same_t)
    return wrong.double().mean().item()


def relative_error(got, want, floor: float = 1e-12) -> float:
    """The largest ``|got - want| / |want|`` (``want`` floored at ``floor``), float64."""
    got = got.detach().to("cpu", F64).reshape(want.shape)
    return ((got - want).abs() / want.abs().clamp(min=floor)).max().item()
