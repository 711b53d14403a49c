"""Lab 1 speed/accuracy benchmark: every triangle test at every precision, and the Triton kernels.

    python bench/lab1_intersect.py --device cpu|cuda [--rays N --tris M] [--out DIR]

For each torch variant of the lab (``intersect_simple``, ``moller_trumbore``,
``woop_unit``, ``watertight``, run through the reference ``closest_hit``) at each
precision (fp16, bf16, fp32, fp64) it measures

* throughput: ray-triangle tests per second (``rays x triangles / seconds``), brute force
  over a random soup;
* error against the exact hits on the same rays (float64 brute force, course code, as
  ``rtcourse bench --lab 1`` measures it: ``error``, the rays whose hit differs): the hit/miss
  disagreement rate, the rate of hits on another triangle, and the median and maximum
  relative error of t where both chose the same triangle;
* the crack (pass-through) rate: rays aimed at the vertices and at points of the shared
  edges of a closed icosphere, from outside and from its centre, with the sphere at the
  origin and translated by 1e5, 1e6 and 1e7; a ray passed through a crack when its first hit
  is not one of the triangles sharing the aimed vertex or edge (it missed, or it slipped
  through to a triangle behind).

On CUDA it adds ``torch.compile`` of Möller–Trumbore (fp32) and the Triton kernels of
``course.kernels.triton_intersect``: registers and spills of each compiled configuration, the
occupancy they allow (``course.measure.occupancy``) and the throughput, over num_warps x rays per
thread (block sizes): occupancy against speed.

``--crack-table`` prints only the float32 pass-through table, the one quoted in the lab's
docstring (``tests/meta/test_lab1_crack_table.py`` re-runs it and compares), and writes it to
``lab1_cracks.md``.

Writes ``lab1_intersect.json`` (a ResultTable with the command line), ``lab1_intersect.md``
and Pareto plots (throughput against disagreement and against crack rate) into ``--out``,
by default ``bench/results/<device_name>/lab1/``. On the CPU only ratios between rows of
one run mean anything; absolute numbers count on a GPU.
"""

from __future__ import annotations

import argparse
import math
import os
import shlex
import sys
import time
from pathlib import Path

import torch

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))  # run from a checkout without installing

from course.core.device import default_device, set_cpu_threads
from course.core.types import Hits, Mesh, Rays
from course.kernels import triton_intersect as ti
from course.measure.bench import (
    ResultTable,
    add_impl_option,
    device_name,
    load_lab,
    pareto_plot,
    time_fn,
    trade_plot,
)
from course.measure.occupancy import PRESETS, occupancy
from course.tools.trade import lab1 as trade
from course.tools.trade.common import exact_hits

# The kernels measured: the references in the course repository, the student's labs/ in the
# handout (RTCOURSE_IMPL, or --impl, picks another); main() reloads them for --impl.
LAB = load_lab("lab1_intersect", os.environ.get("RTCOURSE_IMPL"), root=REPO)
VARIANTS, closest_hit, moller_trumbore = LAB.VARIANTS, LAB.closest_hit, LAB.moller_trumbore

DTYPES = trade.DTYPES
OFFSETS = {"0": 0.0, "1e5": 1e5, "1e6": 1e6, "1e7": 1e7}

# Sizes: (rays, triangles) of the torch variants, rays of the Triton kernels, icosphere level;
# memory: closest_hit's budget for its (rays, triangles) tiles; on a GPU a small budget
# makes tiles so small that kernel launches, not arithmetic, set the time.
SIZES = {
    "cpu": {
        "rays": 1024,
        "tris": 256,
        "triton_rays": 0,
        "ico_level": 2,
        "repeats": 5,
        "warmup": 1,
        "memory": 2**28,
    },
    "cuda": {
        "rays": 65536,
        "tris": 2048,
        "triton_rays": 1 << 20,
        "ico_level": 4,
        "repeats": 10,
        "warmup": 2,
        "memory": 2**32,
    },
}

# The Triton sweep: num_warps x rays per thread (block_rays = 32 * num_warps * rays/thread).
NUM_WARPS = (1, 2, 4, 8)
RAYS_PER_THREAD = (1, 2, 4, 8)
UNROLLS = (1, 2, 4, 8)
TRITON_KERNELS = {  # row name: (function, layout builder, extra keywords)
    "triton_mt": (ti.mt_closest_hit_triton, ti.mt_layout, {}),
    "triton_mt_divfree": (ti.mt_closest_hit_triton, ti.mt_layout, {"division_free": True}),
    "triton_unit": (ti.unit_closest_hit_triton, ti.unit_layout, {}),
}


# --------------------------------------------------------------------------------------
# Scenes and rays (built in float64, cast per precision)
# --------------------------------------------------------------------------------------


def load_meshes(tris: int, ico_level: int) -> tuple[Mesh, Mesh, str]:
    """(random soup, icosphere, where they came from), float64 on the CPU.

    course.core.scenes builds both but needs trimesh; where trimesh is missing (a bare GPU
    machine) the fallbacks below build the same geometry with torch alone.
    """
    try:
        from course.core.scenes import load_scene
    except ImportError:
        return _soup_fallback(tris, 0), _icosphere_fallback(ico_level), "bench fallback"
    soup = load_scene("random_soup", n=tris, seed=0, device="cpu", dtype=torch.float64).mesh
    ico = load_scene("icosphere", level=ico_level, device="cpu", dtype=torch.float64).mesh
    return soup, ico, "course.core.scenes"


def _soup_fallback(n: int, seed: int) -> Mesh:
    """course.core.scenes' random_soup, step for step (same triangles for a seed)."""
    g = torch.Generator().manual_seed(seed)
    size = torch.exp(
        torch.empty(n, dtype=torch.float64).uniform_(math.log(1e-3), math.log(0.25), generator=g)
    )
    centre = size[:, None] + (1 - 2 * size[:, None]) * torch.rand(
        n, 3, dtype=torch.float64, generator=g
    )
    offsets = (2 * torch.rand(n, 3, 3, dtype=torch.float64, generator=g) - 1) * size[:, None, None]
    vertices = (centre[:, None, :] + offsets).reshape(-1, 3)
    return Mesh(vertices=vertices, faces=torch.arange(3 * n).reshape(n, 3))


def _icosphere_fallback(level: int) -> Mesh:
    """A unit icosphere like trimesh's: the icosahedron, each face split in 4 ``level``
    times, the vertices pushed to the sphere after each split. Closed: every edge is
    shared by two faces."""
    phi = (1 + 5**0.5) / 2
    vertices = torch.tensor(
        [
            [-1, phi, 0],
            [1, phi, 0],
            [-1, -phi, 0],
            [1, -phi, 0],
            [0, -1, phi],
            [0, 1, phi],
            [0, -1, -phi],
            [0, 1, -phi],
            [phi, 0, -1],
            [phi, 0, 1],
            [-phi, 0, -1],
            [-phi, 0, 1],
        ],
        dtype=torch.float64,
    )
    faces = torch.tensor(
        [
            [0, 11, 5],
            [0, 5, 1],
            [0, 1, 7],
            [0, 7, 10],
            [0, 10, 11],
            [1, 5, 9],
            [5, 11, 4],
            [11, 10, 2],
            [10, 7, 6],
            [7, 1, 8],
            [3, 9, 4],
            [3, 4, 2],
            [3, 2, 6],
            [3, 6, 8],
            [3, 8, 9],
            [4, 9, 5],
            [2, 4, 11],
            [6, 2, 10],
            [8, 6, 7],
            [9, 8, 1],
        ]
    )
    for _ in range(level):
        edges = torch.cat([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]).sort(1).values
        unique, index = edges.unique(dim=0, return_inverse=True)
        mid = len(vertices) + index.reshape(3, -1)  # new vertex of edge (0,1), (1,2), (2,0)
        vertices = torch.cat([vertices, vertices[unique].mean(1)])
        vertices = vertices / vertices.norm(dim=1, keepdim=True)
        a, b, c = faces.unbind(1)
        ab, bc, ca = mid
        faces = torch.cat(
            [torch.stack(f, 1) for f in ((a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca))]
        )
    return Mesh(vertices=vertices / vertices.norm(dim=1, keepdim=True), faces=faces)


soup_rays = trade.soup_rays  # the rays of rtcourse bench --lab 1


def crack_scene(mesh: Mesh, offset: float, dtype: torch.dtype):
    """The closed ``mesh`` moved by ``offset`` (on every axis) and rounded to ``dtype``, with
    rays aimed at its vertices and at the points at 1/2 and 1/4 of every edge, computed from
    the *rounded* vertices: from outside towards the centre (the first ``T`` rays), then from
    the centre outwards (the next ``T``). (The grader's construction.)

    Returns ``(rays, mesh, incident)``: ``incident`` (2T, F) bool marks the triangles that
    share the aimed vertex or edge. On a convex closed mesh the first hit of every such ray
    is one of them; a ray whose first hit is not (a miss, or a triangle behind the aimed point)
    has passed through a crack."""
    vertices = (mesh.vertices + offset).to(dtype)
    exact = vertices.double()
    faces = mesh.faces
    edges = torch.cat([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    edges = edges.sort(1).values.unique(dim=0)
    targets = torch.cat(
        [exact] + [exact[edges[:, 0]] * (1 - f) + exact[edges[:, 1]] * f for f in (0.5, 0.25)]
    )
    has = (faces[None, :, :] == torch.arange(len(exact))[:, None, None]).any(-1)  # (V, F)
    on_edge = has[edges[:, 0]] & has[edges[:, 1]]
    incident = torch.cat([has, on_edge, on_edge]).repeat(2, 1)
    centre = torch.full((3,), offset, dtype=torch.float64)
    radial = (targets - centre) / (targets - centre).norm(dim=1, keepdim=True)
    origins = torch.cat([centre + 3 * radial, centre.expand_as(targets)]).to(dtype)
    directions = (targets.repeat(2, 1) - origins.double()).to(dtype)
    return Rays.create(origins, directions), Mesh(vertices, faces), incident


def pass_through(hits: Hits, incident: torch.Tensor) -> torch.Tensor:
    """(R,) bool: rays of ``crack_scene`` whose first hit is not a triangle sharing the
    aimed vertex or edge (including rays that hit nothing)."""
    triangle = hits.triangle.cpu()
    there = incident.gather(1, triangle.clamp(min=0)[:, None])[:, 0]
    return ~(there & (triangle >= 0))


def crack_rates(trace, ico: Mesh, dtype: torch.dtype, device) -> dict:
    """Pass-through rates of the rays of ``crack_scene``, per offset and side.

    trace(rays, mesh) -> Hits runs one variant on rays and mesh in ``dtype``. Keys:
    ``crack_out_<offset>`` (rays from outside), ``crack_in_<offset>`` (from the centre),
    ``crack_origin``, ``crack_1e6`` (both sides together, what the Pareto plots show) and
    ``aim_err_<offset>``: the largest ``|t - 1|`` among the rays that did hit there (``t = 1``
    is the aimed point: how far from it, in units of the distance to it, the hit was put)."""
    rates = {}
    for name, offset in OFFSETS.items():
        rays, mesh, incident = crack_scene(ico, offset, dtype)
        hits = trace(rays.to(device), mesh.to(device))
        passed = pass_through(hits, incident)
        half = len(passed) // 2
        err = (hits.t.cpu().double() - 1).abs()[~passed]
        rates[f"aim_err_{name}"] = err.max().item() if len(err) else math.nan
        rates[f"crack_out_{name}"] = passed[:half].double().mean().item()
        rates[f"crack_in_{name}"] = passed[half:].double().mean().item()
        if name in ("0", "1e6"):
            rates["crack_origin" if name == "0" else "crack_1e6"] = passed.double().mean().item()
    return rates


def crack_table(ico_level: int, device, dtype: torch.dtype = torch.float32, variants=None) -> str:
    """The pass-through table of the lab's docstring: every variant in ``dtype`` on the
    icosphere of ``ico_level``, rays from outside / from the centre, per offset."""
    variants = list(variants or VARIANTS)
    _, ico, _ = load_meshes(1, ico_level)
    rays, _, _ = crack_scene(ico, 0.0, dtype)
    rates = {}
    for variant in variants:

        def trace(r, m, variant=variant):
            return closest_hit(r, m, variant=variant)

        rates[variant] = crack_rates(trace, ico, dtype, device)
    dname = next(k for k, v in DTYPES.items() if v == dtype)
    first = (
        f"Pass-throughs ({dname}, icosphere level {ico_level}: {len(rays) // 2} rays aimed "
        f"at its {ico.num_vertices} vertices"
    )
    second = (
        "and at 1/2 and 1/4 of its edges, from outside / from the centre; the sphere moved "
        "by the offset):"
    )
    lines = [first, second, ""]
    width = max(len(v) for v in variants) + 2
    rule = "=" * 8 + "  " + "  ".join("=" * width for _ in variants)
    lines += [rule, "offset    " + "  ".join(v.ljust(width) for v in variants).rstrip(), rule]
    for name in OFFSETS:
        cells = [
            f"{_pct(rates[v][f'crack_out_{name}'])} / {_pct(rates[v][f'crack_in_{name}'])}"
            for v in variants
        ]
        lines.append(name.ljust(10) + "  ".join(c.ljust(width) for c in cells).rstrip())
    lines += [
        rule,
        "",
        "Largest |t - 1| of the rays that hit there (t = 1 at the aimed point):",
        "",
        rule,
        "offset    " + "  ".join(v.ljust(width) for v in variants).rstrip(),
        rule,
    ]
    for name in OFFSETS:
        cells = [f"{rates[v][f'aim_err_{name}']:.1g}" for v in variants]
        lines.append(name.ljust(10) + "  ".join(c.ljust(width) for c in cells).rstrip())
    shape = _rounded_mesh(ico, dtype)
    distinct = ", ".join(str(v) for v, _ in shape.values())
    flat = ", ".join(_pct(z) for _, z in shape.values())
    offsets = ", ".join(OFFSETS)
    lines += [
        rule,
        "",
        f"The mesh after rounding, offsets {offsets}: distinct vertices {distinct};",
        f"zero-area triangles {flat}.",
    ]
    return "\n".join(lines)


def _rounded_mesh(ico: Mesh, dtype: torch.dtype) -> dict:
    """Per offset: (distinct vertices, fraction of zero-area triangles) of the rounded mesh."""
    shape = {}
    for name, offset in OFFSETS.items():
        _, mesh, _ = crack_scene(ico, offset, dtype)
        tri = mesh.triangles().double()
        normal = torch.linalg.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        shape[name] = (
            len(mesh.vertices.unique(dim=0)),
            (normal == 0).all(-1).double().mean().item(),
        )
    return shape


def _pct(rate: float) -> str:
    """A rate as the table prints it: 0 exactly, else a percentage to 2 significant digits."""
    if rate == 0:
        return "0"
    return f"{100 * rate:.2g}%" if rate < 0.1 else f"{100 * rate:.0f}%"


# --------------------------------------------------------------------------------------
# Errors
# --------------------------------------------------------------------------------------


def accuracy(hits: Hits, ref: Hits) -> dict:
    """Disagreement with the float64 reference: hit/miss, triangle, and t where both agree."""
    got, want = hits.hit.cpu(), ref.hit.cpu()
    same = got & want & (hits.triangle.cpu() == ref.triangle.cpu())
    t, t_ref = hits.t.cpu().double()[same], ref.t.cpu()[same]
    rel = (t - t_ref).abs() / t_ref.abs()
    return {
        "disagreement": (got != want).double().mean().item(),
        "wrong_triangle": (got & want & ~same).double().mean().item(),
        "t_rel_err_median": rel.median().item() if len(rel) else math.nan,
        "t_rel_err_max": rel.max().item() if len(rel) else math.nan,
    }


# --------------------------------------------------------------------------------------
# The torch variants
# --------------------------------------------------------------------------------------


def bench_torch(
    table: ResultTable,
    soup: Mesh,
    ico: Mesh,
    rays: Rays,
    ref: Hits,
    device,
    cfg: dict,
    variants,
    dtypes,
) -> None:
    pairs = len(rays) * soup.num_faces
    for variant in variants:
        for dname in dtypes:
            dtype = DTYPES[dname]

            def trace(r, m, variant=variant):
                return closest_hit(r, m, variant=variant, memory_budget_bytes=cfg["memory"])

            started = time.perf_counter()
            # The row rtcourse bench --lab 1 measures (seconds, error against the exact
            # hits), then this script's own columns on the same hits.
            ctx = {
                "device": device,
                "repeats": cfg["repeats"],
                "rays": rays,
                "soup": soup,
                "exact": (ref.t, ref.triangle),
                "pairs": pairs,
                "memory": cfg["memory"],
            }
            shared = trade.measure(LAB, ctx, {"variant": variant, "dtype": dname})
            row = table.add(
                impl="torch",
                variant=variant,
                dtype=dname,
                rays=len(rays),
                tris=soup.num_faces,
                seconds=shared["seconds"],
                tests_per_s=pairs / shared["seconds"],
                error=shared["error"],
                **accuracy(shared["hits"], ref),
                **crack_rates(trace, ico, dtype, device),
            )
            _log(row, started)


def _compiled_mt_closest():
    """``torch.compile`` of one tile of Möller–Trumbore brute force plus its min-reduction:
    the compiler fuses the (rays, triangles) tile away."""

    def tile(o, d, v0, v1, v2):
        t, _, _ = moller_trumbore(o[:, None], d[:, None], v0[None], v1[None], v2[None])
        t_best, index = t.min(dim=1)
        return t_best, index

    return torch.compile(tile, dynamic=False)


def bench_compile(
    table: ResultTable,
    soup: Mesh,
    ico: Mesh,
    rays: Rays,
    ref: Hits,
    device,
    cfg: dict,
    chunk: int = 8192,
) -> None:
    tile = _compiled_mt_closest()

    def trace(r: Rays, m: Mesh) -> Hits:
        v0, v1, v2 = m.triangles().unbind(1)
        n = len(r)
        pad = -n % chunk  # whole chunks only: one compiled shape
        o = torch.nn.functional.pad(r.origins, (0, 0, 0, pad))
        d = torch.nn.functional.pad(r.directions, (0, 0, 0, pad))
        parts = [
            tile(o[i : i + chunk], d[i : i + chunk], v0, v1, v2) for i in range(0, n + pad, chunk)
        ]
        t = torch.cat([p[0] for p in parts])[:n]
        index = torch.cat([p[1] for p in parts])[:n]
        hit = torch.isfinite(t)
        zero = torch.zeros_like(t)
        return Hits(t=t, triangle=torch.where(hit, index, -1), u=zero, v=zero)

    started = time.perf_counter()
    r, m = rays.to(device, torch.float32), soup.to(device, torch.float32)
    trace(r, m)  # compile outside the timing
    timing = time_fn(trace, r, m, repeats=cfg["repeats"], warmup=cfg["warmup"])
    row = table.add(
        impl="torch.compile",
        variant="moller_trumbore",
        dtype="fp32",
        rays=len(rays),
        tris=soup.num_faces,
        seconds=timing.median,
        tests_per_s=len(rays) * soup.num_faces / timing.median,
        **accuracy(trace(r, m), ref),
        **crack_rates(trace, ico, torch.float32, device),
    )
    _log(row, started)


# --------------------------------------------------------------------------------------
# The Triton kernels
# --------------------------------------------------------------------------------------


def arch_preset(device):
    """The course.measure.occupancy preset of the device's generation (the newest not newer)."""
    major, minor = torch.cuda.get_device_capability(device)
    older = [
        a
        for a in PRESETS.values()
        if tuple(map(int, a.compute_capability.split("."))) <= (major, minor)
    ]
    return max(older, key=lambda a: tuple(map(int, a.compute_capability.split("."))))


def _triton_trace(fn, builder, extra):
    def trace(r: Rays, m: Mesh) -> Hits:
        t, index, u, v = fn(
            r.origins, r.directions, builder(m.triangles()), r.t_min, r.t_max, **extra
        )
        return Hits(t=t, triangle=index, u=u, v=v)

    return trace


def bench_triton(
    table: ResultTable, soup: Mesh, ico: Mesh, rays: Rays, ref: Hits, device, n_rays: int, cfg: dict
) -> None:
    arch = arch_preset(device)
    big = soup_rays(n_rays).to(device, torch.float32)
    pairs = n_rays * soup.num_faces
    triangles = soup.to(device, torch.float32).triangles()
    for name, (fn, builder, extra) in TRITON_KERNELS.items():
        started = time.perf_counter()
        trace = _triton_trace(fn, builder, extra)
        errors = {
            **accuracy(trace(rays.to(device, torch.float32), soup.to(device, torch.float32)), ref),
            **crack_rates(trace, ico, torch.float32, device),
        }
        layout = builder(triangles)  # built once, like an acceleration structure
        configs = [(w, k * 32 * w, ti.DEFAULT_UNROLL) for w in NUM_WARPS for k in RAYS_PER_THREAD]
        configs += [
            (ti.DEFAULT_NUM_WARPS, ti.DEFAULT_BLOCK_RAYS, u)
            for u in UNROLLS
            if u != ti.DEFAULT_UNROLL
        ]
        for num_warps, block_rays, unroll in configs:
            launch = dict(block_rays=block_rays, num_warps=num_warps, unroll=unroll, **extra)
            info = ti.compiled_kernel_info(fn, big.origins, big.directions, layout, **launch)
            occ = (
                occupancy(arch, info.n_regs, info.threads_per_block, info.shared_bytes or 0)
                if info.n_regs
                else None
            )
            timing = time_fn(
                fn,
                big.origins,
                big.directions,
                layout,
                repeats=2 * cfg["repeats"],
                warmup=cfg["warmup"],
                **launch,
            )
            row = table.add(
                impl="triton",
                variant=name,
                dtype="fp32",
                rays=n_rays,
                tris=soup.num_faces,
                seconds=timing.median,
                tests_per_s=pairs / timing.median,
                num_warps=num_warps,
                block_rays=block_rays,
                rays_per_thread=block_rays // (32 * num_warps),
                unroll=unroll,
                n_regs=info.n_regs,
                n_spills=info.n_spills,
                occupancy=occ.occupancy if occ else None,
                warps_per_sm=occ.active_warps if occ else None,
                occupancy_limit=occ.limiter if occ else None,
                occupancy_arch=arch.name,
                **errors,
            )
            _log(row, started)


# --------------------------------------------------------------------------------------
# Output
# --------------------------------------------------------------------------------------


def _log(row: dict, started: float) -> None:
    keys = ("impl", "variant", "dtype", "num_warps", "block_rays", "unroll", "n_regs", "occupancy")
    label = " ".join(
        f"{row[k]}" if k in ("impl", "variant", "dtype") else f"{k}={row[k]}"
        for k in keys
        if row.get(k) is not None
    )
    print(
        f"{label}: {row['tests_per_s'] / 1e9:.3g} G tests/s, disagreement "
        f"{row['disagreement']:.2%}, crack@1e6 {row['crack_1e6']:.2%} "
        f"({time.perf_counter() - started:.1f} s)",
        flush=True,
    )


def plot_rows(table: ResultTable) -> list[dict]:
    """What the Pareto plots show: every torch row and the fastest config of each Triton kernel."""
    # Colour = variant (series), label = precision: short labels keep the plot readable.
    rows = [
        dict(r, series=r["variant"] if r["impl"] == "torch" else r["impl"], setting=r["dtype"])
        for r in table.rows
        if r["impl"] != "triton"
    ]
    for name in TRITON_KERNELS:
        sweep = [r for r in table.rows if r["impl"] == "triton" and r["variant"] == name]
        if sweep:
            best = max(sweep, key=lambda r: r["tests_per_s"])
            rows.append(dict(best, series="triton", setting=name.removeprefix("triton_")))
    return rows


def occupancy_plot(table: ResultTable, path: Path) -> None:
    """Triton sweep: throughput against occupancy, one colour per kernel."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(6.4, 4.8), layout="constrained")
    ax = fig.add_subplot()
    for name in TRITON_KERNELS:
        rows = [r for r in table.rows if r["variant"] == name and r.get("occupancy") is not None]
        ax.scatter(
            [r["occupancy"] for r in rows],
            [r["tests_per_s"] / 1e9 for r in rows],
            label=name,
            alpha=0.8,
        )
        for r in rows:
            ax.annotate(
                f"{r['n_regs']}r w{r['num_warps']} x{r['rays_per_thread']}",
                (r["occupancy"], r["tests_per_s"] / 1e9),
                textcoords="offset points",
                xytext=(3, 3),
                fontsize=6,
            )
    ax.set_xlabel("occupancy (active warps / max warps per SM)")
    ax.set_ylabel("G ray-triangle tests / s")
    ax.set_title("Triton brute force: occupancy is not speed")
    ax.grid(True, alpha=0.3)
    ax.legend()
    fig.savefig(path, dpi=150)


def write_outputs(table: ResultTable, out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    table.to_json(out / "lab1_intersect.json")
    meta = table.metadata
    device = (
        f"Device: {meta['device']}; torch {meta['torch']}, triton {meta.get('triton')}; "
        f"{meta['date']}."
    )
    legend = (
        "tests_per_s: ray-triangle tests per second; error: the hit differs from the "
        "exact one (float64 brute force; rtcourse bench --lab 1's error); disagreement: "
        "hit/miss differs from it; wrong_triangle: both hit, other triangle; "
        "t_rel_err_*: on rays where both chose the same triangle; crack_*: fraction of "
        "rays aimed at shared edges/vertices of a closed icosphere whose first hit is "
        "not a triangle sharing them (crack_out_X: from outside, crack_in_X: from the "
        "centre, the sphere moved by X; crack_origin, crack_1e6: both sides)."
    )
    header = [f"# {table.name}", "", device, "", f"Command: `{meta['command']}`", "", legend, ""]
    (out / "lab1_intersect.md").write_text("\n".join(header) + table.to_markdown() + "\n")
    rows = plot_rows(table)
    # The plot rtcourse bench --lab 1 draws, from the same rows: seconds against error.
    trade_plot(
        [r for r in rows if r["impl"] == "torch"],
        [],
        [r for r in rows if r["impl"] != "torch"],
        path=out / "pareto_error.png",
        title="Lab 1: seconds against hits differing from exact",
    )
    for y, title in (
        ("disagreement", "hit/miss disagreement with the exact hits"),
        ("crack_1e6", "crack rate, closed icosphere moved by 1e6"),
    ):
        fig = pareto_plot(rows, x="tests_per_s", y=y, label="setting", group="series", title=title)
        fig.axes[0].set_ylim(bottom=0)  # rates: the symlog axis need not show negatives
        fig.savefig(out / f"pareto_{y}.png", dpi=150)
    if any(r.get("occupancy") is not None for r in table.rows):
        occupancy_plot(table, out / "triton_occupancy.png")


# --------------------------------------------------------------------------------------


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--device", default=None, help="cpu or cuda (default: cuda if present)")
    parser.add_argument("--rays", type=int, help="rays of the torch variants")
    parser.add_argument("--tris", type=int, help="triangles of the random soup")
    parser.add_argument("--triton-rays", type=int, help="rays of the Triton sweep (0: skip)")
    parser.add_argument("--ico-level", type=int, help="icosphere subdivisions (crack test)")
    parser.add_argument("--repeats", type=int, help="timed runs per setting (median reported)")
    parser.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=VARIANTS)
    parser.add_argument("--dtypes", nargs="+", default=list(DTYPES), choices=list(DTYPES))
    parser.add_argument("--no-compile", action="store_true", help="skip torch.compile (CUDA)")
    parser.add_argument(
        "--threads",
        type=int,
        default=None,
        help="CPU threads for torch (default: the free cores, course.core.device.free_cpus)",
    )
    parser.add_argument(
        "--crack-table",
        action="store_true",
        help="print only the float32 pass-through table of the lab's docstring",
    )
    parser.add_argument(
        "--out", type=Path, help="output folder (default: bench/results/<device_name>/lab1)"
    )
    add_impl_option(parser)
    args = parser.parse_args(argv)
    global LAB, closest_hit, moller_trumbore
    LAB = load_lab("lab1_intersect", args.impl, root=REPO)
    closest_hit, moller_trumbore = LAB.closest_hit, LAB.moller_trumbore

    threads = set_cpu_threads(args.threads)
    device = default_device(args.device)
    cfg = dict(SIZES["cuda" if device.type == "cuda" else "cpu"])
    for key in ("rays", "tris", "triton_rays", "ico_level", "repeats"):
        if getattr(args, key) is not None:
            cfg[key] = getattr(args, key)
    out = args.out or REPO / "bench" / "results" / device_name(device) / "lab1"

    if args.crack_table:
        text = crack_table(cfg["ico_level"], device, variants=args.variants)
        command = shlex.join(
            ["python", "bench/lab1_intersect.py", *(sys.argv[1:] if argv is None else argv)]
        )
        out.mkdir(parents=True, exist_ok=True)
        (out / "lab1_cracks.md").write_text(
            f"# Lab 1: pass-throughs at shared edges and vertices\n\nDevice: "
            f"{device_name(device)}; torch {torch.__version__}.\n\nCommand: `{command}`\n\n"
            f"```\n{text}\n```\n"
        )
        print(text)
        print(f"wrote {out / 'lab1_cracks.md'}")
        return

    torch.manual_seed(0)
    soup, ico, source = load_meshes(cfg["tris"], cfg["ico_level"])
    rays = soup_rays(cfg["rays"])
    table = ResultTable("Lab 1: ray/triangle intersection, speed against accuracy", device)
    table.metadata.update(
        command=shlex.join([Path(sys.executable).name, *sys.argv])
        if argv is None
        else shlex.join(["python", "bench/lab1_intersect.py", *argv]),
        triton=_triton_version(),
        scenes=source,
        sizes=cfg,
        cpu_threads=threads,
        load_average=list(os.getloadavg()),
        crack_rays=len(crack_scene(ico, 0.0, torch.float64)[0]),
        icosphere_faces=ico.num_faces,
        reference="float64 brute force (course.tools.trade.common.exact_hits)",
        lab_file=str(LAB.__file__),
    )
    print(f"{table.metadata['device']}: {cfg}, scenes from {source}", flush=True)

    started = time.perf_counter()

    def reference(r: Rays, m: Mesh) -> Hits:
        return closest_hit(r, m, variant="watertight", memory_budget_bytes=cfg["memory"])

    # Every row is compared with the exact hits (float64 brute force, course code), as
    # rtcourse bench --lab 1 compares them: a wrong closest_hit cannot be its own yardstick.
    exact_t, exact_triangle = exact_hits(rays, soup)
    ref = Hits(
        t=exact_t, triangle=exact_triangle, u=torch.zeros_like(exact_t), v=torch.zeros_like(exact_t)
    )
    try:
        ref_cracks = crack_rates(reference, ico, torch.float64, device)
    except NotImplementedError as exc:  # the handout: every row runs closest_hit
        raise SystemExit(
            f"lab1_intersect: every row runs the lab's closest_hit; write it first ({exc})"
        ) from None
    print(
        f"reference: {ref.hit.double().mean().item():.1%} of the rays hit, "
        f"reference cracks {ref_cracks} ({time.perf_counter() - started:.1f} s)",
        flush=True,
    )

    bench_torch(table, soup, ico, rays, ref, device, cfg, args.variants, args.dtypes)
    if device.type == "cuda":
        if not args.no_compile:
            bench_compile(table, soup, ico, rays, ref, device, cfg)
        if cfg["triton_rays"] and _triton_version():
            bench_triton(table, soup, ico, rays, ref, device, cfg["triton_rays"], cfg)
    else:
        print("Triton and torch.compile rows run on CUDA only", flush=True)
    write_outputs(table, out)
    print(f"wrote {out}")


def _triton_version() -> str | None:
    try:
        import triton
    except ImportError:
        return None
    return triton.__version__


if __name__ == "__main__":
    main()
