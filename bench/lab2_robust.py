"""What Lab 2's robust traversal costs: steps, triangle tests and time of every walk with the
conservative comparisons (``slab_test``'s far distance widened by ``1 + 2 gamma(3)``, the
closest hit widened by ``course.given.lab2_robust.reach``) against the same walk without them,
and how many rays aimed at vertices and edge midpoints each gets wrong.

Usage: ``python bench/lab2_robust.py [--json PATH] [--repeats 3]`` (CPU, one thread).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import sys
import time
from pathlib import Path

import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from course.core.labs import load_lab  # noqa: E402
from course.core.scenes import load_scene  # noqa: E402
from course.core.types import Mesh, Rays  # noqa: E402
from course.given import lab2_blocks  # noqa: E402
from course.given.lab2 import moller_trumbore_rows  # noqa: E402


def plain_slab_test(origins, inv_directions, lo, hi, t_lo, t_hi):
    """``slab_test`` without the widened far distance (the walk before the fix)."""
    t0 = (lo - origins) * inv_directions
    t1 = (hi - origins) * inv_directions
    near, far = torch.minimum(t0, t1), torch.maximum(t0, t1)
    t_near = torch.fmax(t_lo, torch.fmax(torch.fmax(near[..., 0], near[..., 1]), near[..., 2]))
    t_far = torch.fmin(t_hi, torch.fmin(torch.fmin(far[..., 0], far[..., 1]), far[..., 2]))
    valid = (
        torch.isfinite(origins).all(-1) & (inv_directions.abs() > 0).all(-1) & (lo <= hi).all(-1)
    )
    return t_near, t_far, (t_near <= t_far) & (t_near < math.inf) & valid


@contextlib.contextmanager
def without_widening(lab):
    """The lab's walks with ``reach`` the identity and the plain slab test."""
    mods = [
        sys.modules[lab.__name__ + "." + m]
        for m in ("grid", "two_level", "bvh_walk", "kdtree", "fast")
    ]
    saved = [
        (m, k, getattr(m, k))
        for m in mods
        for k in ("reach", "slab_test", "gamma")
        if hasattr(m, k)
    ]
    for m, k, _ in saved:
        setattr(
            m,
            k,
            {"reach": lambda t: t, "slab_test": plain_slab_test, "gamma": lambda n, dtype: 0.0}[k],
        )
    try:
        yield
    finally:
        for m, k, v in saved:
            setattr(m, k, v)


def mt(o, d, a, b, c, t_min=0.0, t_max=math.inf):
    """The fast walk's kernel, broadcast: brute force with the same bits per pair."""
    o, d, a, b, c = torch.broadcast_tensors(o, d, a, b, c)
    shape = o.shape[:-1]
    t, u, v, hit = moller_trumbore_rows(
        o,
        d,
        a,
        b - a,
        c - a,
        torch.as_tensor(t_min, dtype=o.dtype).expand(shape),
        torch.as_tensor(t_max, dtype=o.dtype).expand(shape),
    )
    return torch.where(hit, t, math.inf), torch.where(hit, u, 0.0), torch.where(hit, v, 0.0)


def brute(rays, mesh):
    tri = mesh.triangles()
    t, _, _ = mt(
        rays.origins[:, None],
        rays.directions[:, None],
        tri[None, :, 0],
        tri[None, :, 1],
        tri[None, :, 2],
    )
    best = t.argmin(1)
    return torch.where(t.gather(1, best[:, None])[:, 0] < math.inf, best, -1)


def workloads(shift: float):
    """(name, mesh, rays): Suzanne moved by ``shift``, rays at every vertex and edge
    midpoint, and as many random rays at its bounds."""
    m = load_scene("suzanne", device="cpu", dtype=torch.float64).mesh
    v = m.vertices + shift
    mesh = Mesh(vertices=v.float(), faces=m.faces)
    e = torch.unique(torch.sort(m.faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), 1).values, dim=0)
    at = torch.cat((v, (v[e[:, 0]] + v[e[:, 1]]) / 2))
    lo, hi = v.amin(0), v.amax(0)
    g = torch.Generator().manual_seed(3)
    out = torch.randn(len(at), 3, generator=g, dtype=torch.float64)
    origins = (lo + hi) / 2 + float((hi - lo).norm()) * out / out.norm(dim=1, keepdim=True)
    anywhere = lo + (hi - lo) * torch.rand(len(at), 3, generator=g, dtype=torch.float64)
    label = f"suzanne+{shift:g}" if shift else "suzanne"
    return [
        (f"{label} vertices", mesh, Rays.create(origins.float(), (at - origins).float())),
        (f"{label} random", mesh, Rays.create(origins.float(), (anywhere - origins).float())),
    ]


def walks(lab, mesh):
    grid, grid2 = lab.build_grid(mesh), lab.build_two_level_grid(mesh)
    lbvh, sah, kd = lab.build_lbvh(mesh), lab.build_sah_bvh(mesh), lab.build_kdtree(mesh)
    return {
        "grid": lambda r: lab.grid_closest_hit(r, mesh, grid, mt),
        "grid2": lambda r: lab.two_level_closest_hit(r, mesh, grid2, mt),
        "lbvh": lambda r: lab.bvh_closest_hit(r, mesh, lbvh, mt),
        "sah": lambda r: lab.bvh_closest_hit(r, mesh, sah, mt),
        "sah stackless": lambda r: lab.bvh_closest_hit_stackless(r, mesh, sah, mt),
        "kd": lambda r: lab.kd_closest_hit(r, mesh, kd, mt),
        "fast": lambda r: lab.bvh_closest_hit_fast(r, mesh, sah),
    }


def run(lab, fn, rays, ref, repeats):
    best = math.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        hits, count = fn(rays)
        best = min(best, time.perf_counter() - t0)
    return {
        "steps": float(count["steps"].double().mean()),
        "tests": float(count["tests"].double().mean()),
        "seconds": best,
        "wrong": int((hits.triangle != ref).sum()),
    }


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", type=Path, default=None)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    lab = load_lab("lab2_accel", "solutions", ROOT)
    rows = []
    for shift in (0.0, 1e5):
        for name, mesh, rays in workloads(shift):
            ref = brute(rays, mesh)
            for walk, fn in walks(lab, mesh).items():
                robust = run(lab, fn, rays, ref, args.repeats)
                with without_widening(lab):
                    plain = run(lab, fn, rays, ref, args.repeats)
                rows.append(
                    {"rays": name, "n": len(rays), "walk": walk, "robust": robust, "plain": plain}
                )
                print(
                    f"{name:<24} {walk:<14} steps {plain['steps']:7.2f} -> "
                    f"{robust['steps']:7.2f}  tests {plain['tests']:7.2f} -> "
                    f"{robust['tests']:7.2f}  time {plain['seconds']:.3f} -> "
                    f"{robust['seconds']:.3f} s  wrong {plain['wrong']} -> {robust['wrong']}",
                    flush=True,
                )
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(
            json.dumps(
                {
                    "command": "python bench/lab2_robust.py --json " + str(args.json),
                    "threads": 1,
                    "rows": rows,
                },
                indent=1,
            )
            + "\n"
        )


assert lab2_blocks.slab_test  # the widened test the walks import (course.given.lab2_blocks)

if __name__ == "__main__":
    main()
