"""Grader for Lab 2: acceleration structures.

Every traversal is judged against brute force computed here, on the CPU, with this module's
own triangle kernel (``mt64``: Möller–Trumbore in float64, rounded once to the input dtype),
which is also the ``intersect`` callable the lab receives. With the same kernel on the same
(ray, triangle) pair the lab and the reference compute bit-identical ``t``, so a structure
must return *the* brute-force hit: same triangle (among equal ``t`` the lowest index), same
``t``, ``u``, ``v``. A different triangle is accepted only if it is hit at the same ``t`` to
within rounding (a tie at a shared edge).

Traversals are graded on structures built *here* (a uniform grid, an object-median BVH, a
spatial-median kd-tree with straddling triangles, a two-level grid), so a task is graded on
its own: a broken builder does not cost the traversal's points, and the other way round.
Where a function builds on another task's function (``closest_hit`` dispatching to the
walks, ``build_two_level_grid`` building its top grid with ``build_grid``), it runs with
stand-ins from this module in place of the lab's own (``with_given``). Only the last task
(``END_TO_END``) runs the lab's whole chain: its own builders and walks together. The
builders are judged by structure (every triangle in a leaf, boxes that contain their
children and triangles, the depth-first layout) and by quality (the SAH cost of the tree,
computed here).

Scenes: random soups, "shards" (big random triangles that span many cells and straddle
splits, among small ones), an icosphere (closed: rays from outside must find the near
side), and a slice of the teapot in a stadium (Suzanne, 968 triangles, inside a room a
thousand times larger: the case that defeats a uniform grid). Extremes: rays parallel to the
axes with +0.0 and -0.0 components, rays starting inside the scene, on cell boundaries and
in split planes, rays that miss the scene, NaN/inf rays, a single triangle, coincident
triangles, a scene translated by 1e5, one shrunk 100 times, and t_min/t_max clipping.
"""

from __future__ import annotations

import functools
import itertools
import math

import pytest
import torch

from course.core.scenes import load_scene
from course.core.types import Hits, Mesh, Rays
from course.given.lab2 import (
    STRUCTURES,
    choose_structure,
    grid_resolutions,
    moller_trumbore_rows,
    pack_bvh,
    ray_octants,
)
from course.grading.testing import (
    assert_close,
    assert_equal,
    check_tensor,
    expect_error,
    generator,
    replaced,
)

LAB_MODULE = "lab2_accel"
TASKS = {
    1: "Uniform grid: build, 3D DDA, mailboxing",
    2: "BVH builds: LBVH and binned SAH",
    3: "BVH traversal: stack and stackless",
    4: "kd-tree: SAH build, packing, traversal",
    5: "The common entry point: dispatch and the structure chooser",
    6: "The two-level grid: teapot in a stadium",
    7: "Sync-free BVH traversal: fixed shapes, any-hit",
    8: "End to end: your builders and walks on the teapot in a stadium",
}
END_TO_END = 8  # the one task graded on the lab's own chain; every other task on its own

INF = math.inf
F32, F64 = torch.float32, torch.float64


# ---------------------------------------------------------------------------------------
# The triangle kernel handed to the lab (module level: it travels by reference)


def mt64(origins, directions, v0, v1, v2, t_min=0.0, t_max=INF):
    """Möller–Trumbore in float64, results rounded to the inputs' dtype.

    Broadcasts like Lab 1's kernels; ``(t, u, v)`` with ``t = inf`` (and u = v = 0) on a
    miss; the interval ``[t_min, t_max]`` is closed and compared in float64.
    """
    dtype, device = origins.dtype, origins.device
    o, d, a, b, c = (x.to(F64) for x in (origins, directions, v0, v1, v2))
    t_min = torch.as_tensor(t_min, device=device).to(F64)
    t_max = torch.as_tensor(t_max, device=device).to(F64)
    e1, e2 = b - a, c - a
    p = torch.linalg.cross(d, e2, dim=-1)
    det = (e1 * p).sum(-1)
    inv = 1 / det
    s = o - a
    q = torch.linalg.cross(s, e1, dim=-1)
    u = (s * p).sum(-1) * inv
    v = (d * q).sum(-1) * inv
    t = (e2 * q).sum(-1) * inv
    hit = (det != 0) & (u >= 0) & (v >= 0) & (u + v <= 1) & (t >= t_min) & (t <= t_max)
    inf = torch.full((), INF, dtype=F64, device=device)
    zero = torch.zeros((), dtype=F64, device=device)
    return (
        torch.where(hit, t, inf).to(dtype),
        torch.where(hit, u, zero).to(dtype),
        torch.where(hit, v, zero).to(dtype),
    )


# ---------------------------------------------------------------------------------------
# Scenes (float64 geometry rounded once to float32, on the CPU; moved per test)


def mesh_of(corners: torch.Tensor, dtype=F32, device="cpu") -> Mesh:
    """A triangle soup (F, 3, 3) as a Mesh."""
    corners = corners.to(dtype)
    return Mesh(
        vertices=corners.reshape(-1, 3).to(device),
        faces=torch.arange(3 * len(corners), device=device).reshape(-1, 3),
    )


@functools.cache
def scene(name: str) -> Mesh:
    """The named test scene (float32, CPU)."""
    if name == "soup":
        return load_scene("random_soup", device="cpu", n=200, seed=7).mesh
    if name == "shards":
        # 24 big triangles (edges up to ~0.8) among 96 small ones: spans and straddlers.
        g = generator(21)
        centre = 0.2 + 0.6 * torch.rand(24, 1, 3, generator=g, dtype=F64)
        big = centre + 0.4 * (2 * torch.rand(24, 3, 3, generator=g, dtype=F64) - 1)
        small = load_scene("random_soup", device="cpu", dtype=F64, n=96, seed=22).mesh
        return mesh_of(torch.cat((big, small.vertices[small.faces])))
    if name == "ico":
        return load_scene("icosphere", device="cpu", level=3).mesh
    if name == "teapot":
        return load_scene("teapot_in_stadium", device="cpu", subdivisions=0).mesh
    if name == "slabs":
        # Six big triangles through the unit cube: every one spans many cells.
        g = generator(31)
        return mesh_of(torch.rand(6, 3, 3, generator=g, dtype=F64) * 1.4 - 0.2)
    if name == "tiny":
        soup = load_scene("random_soup", device="cpu", dtype=F64, n=200, seed=7).mesh
        return mesh_of(soup.vertices[soup.faces] * 0.01)
    if name == "far":
        soup = load_scene("random_soup", device="cpu", dtype=F64, n=120, seed=41).mesh
        return mesh_of(soup.vertices[soup.faces] + 1e5)
    if name == "single":
        return mesh_of(
            torch.tensor([[[0.1, 0.2, 0.5], [0.9, 0.3, 0.5], [0.4, 0.8, 0.5]]], dtype=F64)
        )
    if name == "coincident":
        one = torch.tensor([[0.1, 0.2, 0.3], [0.9, 0.3, 0.6], [0.4, 0.8, 0.4]], dtype=F64)
        return mesh_of(one.expand(40, 3, 3))
    raise KeyError(name)


def on(mesh: Mesh, device) -> Mesh:
    return Mesh(vertices=mesh.vertices.to(device), faces=mesh.faces.to(device))


def bounds(mesh: Mesh):
    v = mesh.vertices.to("cpu", F64)
    return v.amin(0), v.amax(0)


def rays_around(
    mesh: Mesh, n: int, seed: int, inside: float = 0.25, clip: float = 0.15, dtype=F32
) -> Rays:
    """n rays at the scene: most from a sphere around its bounds aimed at random points in
    them, a fraction ``inside`` starting inside the bounds in random directions; a fraction
    ``clip`` gets a random t_max (some hits lie beyond it), a few a t_min > 0."""
    g = generator(seed)
    lo, hi = bounds(mesh)
    centre, radius = (lo + hi) / 2, float((hi - lo).norm()) / 2 + 1e-3
    out = torch.randn(n, 3, generator=g, dtype=F64)
    origins = centre + 1.5 * radius * out / out.norm(dim=1, keepdim=True)
    targets = lo + (hi - lo) * torch.rand(n, 3, generator=g, dtype=F64)
    directions = targets - origins
    starts_inside = torch.rand(n, generator=g, dtype=F64) < inside
    inner = lo + (hi - lo) * torch.rand(n, 3, generator=g, dtype=F64)
    origins = torch.where(starts_inside[:, None], inner, origins)
    directions = torch.where(
        starts_inside[:, None], torch.randn(n, 3, generator=g, dtype=F64), directions
    )
    t_max = torch.where(
        torch.rand(n, generator=g, dtype=F64) < clip,
        torch.rand(n, generator=g, dtype=F64) * 1.2,
        torch.full((n,), INF, dtype=F64),
    )
    t_min = torch.where(torch.rand(n, generator=g, dtype=F64) < 0.05, 0.3, 0.0)
    return Rays.create(origins.to(dtype), directions.to(dtype), t_min.to(dtype), t_max.to(dtype))


def teapot_rays(n: int, seed: int) -> Rays:
    """Rays in the stadium: 3/4 aimed at the teapot from a few units away, 1/4 anywhere."""
    g = generator(seed)
    mesh = scene("teapot")
    teapot = mesh.vertices[mesh.faces[:968]].reshape(-1, 3).to(F64)
    lo, hi = teapot.amin(0), teapot.amax(0)
    out = torch.randn(n, 3, generator=g, dtype=F64)
    origins = (lo + hi) / 2 + 2.0 * out / out.norm(dim=1, keepdim=True)
    origins[:, 1] = origins[:, 1].abs() + lo[1]  # above the floor
    targets = lo + (hi - lo) * torch.rand(n, 3, generator=g, dtype=F64)
    anywhere = torch.randn(n, 3, generator=g, dtype=F64)
    directions = torch.where(torch.arange(n)[:, None] % 4 == 3, anywhere, targets - origins)
    return Rays.create(origins.float(), directions.float())


def axis_rays(mesh: Mesh, seed: int, per_axis: int = 24, dtype=F32) -> Rays:
    """Rays parallel to the axes, in both directions, their zero components +0.0 or -0.0
    (mixed), from outside and from inside the bounds."""
    g = generator(seed)
    lo, hi = bounds(mesh)
    rays_o, rays_d = [], []
    for axis in range(3):
        for sign in (1.0, -1.0):
            o = lo + (hi - lo) * torch.rand(per_axis, 3, generator=g, dtype=F64)
            outside = torch.arange(per_axis) % 2 == 0
            o[outside, axis] = (lo[axis] - 0.5) if sign > 0 else (hi[axis] + 0.5)
            d = torch.zeros(per_axis, 3, dtype=F64)
            d[:, axis] = sign
            negative_zero = torch.rand(per_axis, 3, generator=g) < 0.5
            d = torch.where(negative_zero & (d == 0), torch.tensor(-0.0, dtype=F64), d)
            rays_o.append(o)
            rays_d.append(d)
    return Rays.create(torch.cat(rays_o).to(dtype), torch.cat(rays_d).to(dtype))


def cat_rays(*batches: Rays) -> Rays:
    return Rays(
        *(
            torch.cat([getattr(r, f) for r in batches])
            for f in ("origins", "directions", "t_min", "t_max")
        )
    )


def bad_rays(n_each: int = 3) -> Rays:
    """NaN and inf origins and directions, and a zero direction: all must miss."""
    nan, inf = math.nan, INF
    o = [
        [nan, 0.5, 0.5],
        [0.5, inf, 0.5],
        [-2.0, 0.5, 0.5],
        [-2.0, 0.5, 0.5],
        [0.5, 0.5, 0.5],
        [-2.0, 0.4, 0.6],
    ]
    d = [
        [1.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [nan, 0.0, 0.0],
        [inf, 1.0, 0.0],
        [0.0, 0.0, 0.0],
        [1.0, nan, 0.0],
    ]
    return Rays.create(torch.tensor(o), torch.tensor(d))


# ---------------------------------------------------------------------------------------
# The reference: brute force with mt64 (CPU), and the comparison


def reference(rays: Rays, mesh: Mesh):
    """(t, triangle, u, v) of the nearest hit per ray, ties to the lowest index (CPU)."""
    o, d = rays.origins.cpu(), rays.directions.cpu()
    t_lo, t_hi = rays.t_min.cpu(), rays.t_max.cpu()
    tri = mesh.triangles().cpu()
    n = len(o)
    out_t = torch.full((n,), INF, dtype=rays.dtype)
    out_i = torch.full((n,), -1, dtype=torch.int64)
    out_u, out_v = torch.zeros(n, dtype=rays.dtype), torch.zeros(n, dtype=rays.dtype)
    chunk = max(1, 2**18 // len(tri))
    for r0 in range(0, n, chunk):
        s = slice(r0, r0 + chunk)
        t, u, v = mt64(
            o[s, None],
            d[s, None],
            tri[None, :, 0],
            tri[None, :, 1],
            tri[None, :, 2],
            t_lo[s, None],
            t_hi[s, None],
        )
        best = t.argmin(dim=1, keepdim=True)  # the first of equal minima: the lowest index
        tb = t.gather(1, best)[:, 0]
        hit = tb < INF
        out_t[s] = tb
        out_i[s] = torch.where(hit, best[:, 0], -1)
        out_u[s], out_v[s] = u.gather(1, best)[:, 0], v.gather(1, best)[:, 0]
    return out_t, out_i, out_u, out_v


def describe(rays: Rays, i: int) -> str:
    o, d = rays.origins[i].tolist(), rays.directions[i].tolist()
    return (
        f"origin {[float(f'{x:.6g}') for x in o]}, direction "
        f"{[float(f'{x:.6g}') for x in d]}, t in [{rays.t_min[i].item():.4g}, "
        f"{rays.t_max[i].item():.4g}]"
    )


def check_result(result, n: int, dtype, device, what: str, counters=("steps", "tests")):
    """The ``(Hits, counters)`` pair, each part checked for type, shape, dtype, device."""
    if not (isinstance(result, tuple) and len(result) == 2):
        raise AssertionError(
            f"{what}: expected a tuple (Hits, counters), got {type(result).__name__}"
        )
    hits, count = result
    assert isinstance(hits, Hits), (
        f"{what}: expected course.core.types.Hits first, got {type(hits).__name__}"
    )
    for name in ("t", "u", "v"):
        check_tensor(
            getattr(hits, name), f"{what}: Hits.{name}", shape=(n,), dtype=dtype, device=device
        )
    check_tensor(
        hits.triangle, f"{what}: Hits.triangle", shape=(n,), dtype=torch.int64, device=device
    )
    # The miss contract (course.core.types.Hits): triangle -1, t = inf, u = v = 0.
    tri = hits.triangle.cpu()
    if (tri < -1).any():
        i = int((tri < -1).nonzero()[0, 0])
        raise AssertionError(
            f"{what}: Hits.triangle[{i}] = {int(tri[i])}: a miss is -1, a hit "
            f"a triangle index ({int((tri < -1).sum())} rays below -1)"
        )
    miss = tri == -1
    for name, want in (("t", math.inf), ("u", 0.0), ("v", 0.0)):
        value = getattr(hits, name).cpu()[miss]
        wrong = value != want
        if wrong.any():
            i = int(miss.nonzero()[:, 0][wrong][0])
            raise AssertionError(
                f"{what}: ray {i} misses (triangle -1) but Hits.{name} = "
                f"{getattr(hits, name)[i].item()}: a miss has {name} = {want}"
            )
    assert isinstance(count, dict), (
        f"{what}: expected a dict of counters second, got {type(count).__name__}"
    )
    for name in counters:
        if name not in count:
            raise AssertionError(f"{what}: counters lack {name!r} (got {sorted(count)})")
        check_tensor(
            count[name], f"{what}: counters[{name!r}]", shape=(n,), dtype=torch.int64, device=device
        )
        if (count[name] < 0).any():
            raise AssertionError(f"{what}: counters[{name!r}] has negative entries")
    return hits, {k: v.cpu() for k, v in count.items()}


def compare(
    result, rays: Rays, mesh: Mesh, what: str, counters=("steps", "tests"), ref=None, walks=True
):
    """The structure's hits must be brute force's; returns the counters (CPU). ``walks``:
    the method visits cells or nodes (every ray that tests a triangle took a step)."""
    hits, count = check_result(result, len(rays), rays.dtype, rays.device, what, counters)
    rays, mesh = rays.to("cpu"), on(mesh, "cpu")
    ref_t, ref_i, ref_u, ref_v = reference(rays, mesh) if ref is None else ref
    t, tri, u, v = (x.cpu() for x in (hits.t, hits.triangle, hits.u, hits.v))
    wrong = (tri >= 0) != (ref_i >= 0)
    if wrong.any():
        i = int(wrong.nonzero()[0, 0])
        if ref_i[i] >= 0:
            detail = (
                f"brute force hits triangle {int(ref_i[i])} at t={ref_t[i].item():.9g}, "
                f"you report a miss"
            )
        else:
            detail = (
                f"brute force finds no hit in [t_min, t_max], you report triangle "
                f"{int(tri[i])} at t={t[i].item():.9g}"
            )
        raise AssertionError(
            f"{what}: {int(wrong.sum())} of {len(rays)} rays hit where brute "
            f"force misses or the other way round. First: ray {i} ({describe(rays, i)}): "
            f"{detail}."
        )
    other = (tri != ref_i) & (ref_i >= 0)
    if other.any():
        # Another triangle is fine only as a tie: hit by the same ray at the same t.
        i = other.nonzero()[:, 0]
        corners = mesh.triangles()[tri[i].clamp(min=0)]
        t_other, _, _ = mt64(
            rays.origins[i],
            rays.directions[i],
            corners[:, 0],
            corners[:, 1],
            corners[:, 2],
            rays.t_min[i],
            rays.t_max[i],
        )
        tol = 4 * torch.finfo(rays.dtype).eps * ref_t[i].abs()
        bad = ~((t_other - ref_t[i]).abs() <= tol) | ~((t[i] - ref_t[i]).abs() <= tol)
        if bad.any():
            j = int(i[bad.nonzero()[0, 0]])
            raise AssertionError(
                f"{what}: {int(bad.sum())} rays report another triangle than brute force. First: "
                f"ray {j} ({describe(rays, j)}): expected triangle {int(ref_i[j])} at "
                f"t={ref_t[j].item():.9g}, got triangle {int(tri[j])} at t={t[j].item():.9g} "
                f"(that triangle is hit at t={t_other[bad][0].item():.9g}). A nearer hit was "
                f"missed: a cell, node or leaf skipped, or the walk stopped too early."
            )
    same = tri == ref_i
    tol = 1e-6
    assert_close(t[same], ref_t[same], rtol=tol, name=f"{what}: t of the hits", where="hit")
    assert_close(u[same], ref_u[same], rtol=tol, atol=tol, name=f"{what}: u", where="hit")
    assert_close(v[same], ref_v[same], rtol=tol, atol=tol, name=f"{what}: v", where="hit")
    missed = tri < 0
    assert_equal(
        t[missed],
        torch.full((int(missed.sum()),), INF, dtype=t.dtype),
        name=f"{what}: t of misses (inf)",
        where="miss",
    )
    assert_equal(
        u[missed],
        torch.zeros(int(missed.sum()), dtype=u.dtype),
        name=f"{what}: u of misses (0)",
        where="miss",
    )
    # Work: a hit needs a triangle test, and a triangle test needs a visited cell or node.
    hit = tri >= 0
    if "tests" in count and (count["tests"][hit] < 1).any():
        i = int((hit & (count["tests"] < 1)).nonzero()[0, 0])
        raise AssertionError(
            f"{what}: ray {i} hits a triangle but counters['tests'] is "
            f"{int(count['tests'][i])}: count every ray/triangle test"
        )
    if walks and (count["steps"][count["tests"] > 0] < 1).any():
        raise AssertionError(
            f"{what}: rays with triangle tests but counters['steps'] == 0: "
            f"count every cell or node a ray visits"
        )
    return count


# ---------------------------------------------------------------------------------------
# Structures built here, independent of the lab's builders


def median_bvh(mesh: Mesh, leaf_size: int = 2) -> dict:
    """An object-median BVH in the lab's depth-first layout (recursive; small meshes)."""
    corners = mesh.triangles().cpu()
    tri_lo, tri_hi = corners.amin(1), corners.amax(1)
    centre = (tri_lo + tri_hi) / 2
    nodes: list[list] = []
    order: list[int] = []

    def build(ids):
        i = len(nodes)
        nodes.append([tri_lo[ids].amin(0), tri_hi[ids].amax(0), -1, -1, 0, 0])
        if len(ids) <= leaf_size:
            nodes[i][4:] = [len(order), len(ids)]
            order.extend(ids.tolist())
            return i
        spread = centre[ids].amax(0) - centre[ids].amin(0)
        axis = int(spread.argmax())
        ids = ids[torch.sort(centre[ids, axis], stable=True).indices]
        nodes[i][2] = build(ids[: len(ids) // 2])
        nodes[i][3] = build(ids[len(ids) // 2 :])
        return i

    build(torch.arange(mesh.num_faces))
    device = mesh.device
    col = list(zip(*nodes))
    return {
        "kind": "bvh",
        "lo": torch.stack(col[0]).to(device),
        "hi": torch.stack(col[1]).to(device),
        **{
            k: torch.tensor(col[j], dtype=torch.int64, device=device)
            for j, k in ((2, "left"), (3, "right"), (4, "first"), (5, "count"))
        },
        "triangles": torch.tensor(order, dtype=torch.int64, device=device),
    }


def median_kdtree(
    mesh: Mesh, max_depth: int = 10, leaf_size: int = 3, at_vertices: bool = False
) -> dict:
    """A spatial-median kd-tree: split the longest axis of the node's box in the middle;
    a triangle whose bounds reach the plane goes to both sides (recursive; small meshes).
    ``at_vertices``: move each plane to the triangle bound nearest the middle (inside the
    box), as an SAH build over bound planes does: vertices then lie in split planes."""
    corners = mesh.triangles().cpu()
    tri_lo, tri_hi = corners.amin(1), corners.amax(1)
    lo, hi = tri_lo.amin(0), tri_hi.amax(0)
    split, axis, left, lists = [0.0], [-1], [-1], [None]

    def build(i, box_lo, box_hi, ids, depth):
        if len(ids) <= leaf_size or depth == max_depth:
            lists[i] = ids
            return
        a = int((box_hi - box_lo).argmax())
        s = float((box_lo[a] + box_hi[a]) / 2)
        s = float(torch.tensor(s, dtype=box_lo.dtype))  # representable in the mesh dtype
        if at_vertices:
            planes = torch.cat((tri_lo[ids, a], tri_hi[ids, a]))
            planes = planes[(planes > box_lo[a]) & (planes < box_hi[a])]
            if len(planes):
                s = float(planes[(planes.double() - s).abs().argmin()])
        child = len(split)
        split[i], axis[i], left[i] = s, a, child
        split.extend([0.0, 0.0])
        axis.extend([-1, -1])
        left.extend([-1, -1])
        lists.extend([None, None])
        below_hi, above_lo = box_hi.clone(), box_lo.clone()
        below_hi[a] = above_lo[a] = s
        build(child, box_lo, below_hi, ids[tri_lo[ids, a] <= s], depth + 1)
        build(child + 1, above_lo, box_hi, ids[tri_hi[ids, a] >= s], depth + 1)

    build(0, lo, hi, torch.arange(mesh.num_faces), 0)
    count = [0 if x is None else len(x) for x in lists]
    first = [0, *itertools.accumulate(count)][:-1]
    device = mesh.device
    flat = torch.cat([x for x in lists if x is not None]) if any(count) else torch.zeros(0)
    return {
        "kind": "kd",
        "lo": lo.to(device),
        "hi": hi.to(device),
        "split": torch.tensor(split, dtype=mesh.dtype, device=device),
        "axis": torch.tensor(axis, dtype=torch.int64, device=device),
        "left": torch.tensor(left, dtype=torch.int64, device=device),
        "first": torch.tensor(first, dtype=torch.int64, device=device),
        "count": torch.tensor(count, dtype=torch.int64, device=device),
        "triangles": flat.to(torch.int64).to(device),
    }


def grid_padding(lo: torch.Tensor, hi: torch.Tensor) -> float:
    """A margin around the box [lo, hi]: relative to its size, plus a few ulps of its
    coordinates (so that a scene far from the origin keeps it after rounding); 1 for a point."""
    eps = torch.finfo(lo.dtype).eps
    pad = 1e-3 * float((hi - lo).amax()) + 64 * eps * float(
        torch.maximum(lo.abs(), hi.abs()).amax()
    )
    return pad if pad > 0 else 1.0


def uniform_grid(
    mesh: Mesh, resolution=None, density: float = 2.0, pad: float | None = None
) -> dict:
    """A uniform grid in the lab's layout, built here one triangle at a time (small meshes):
    the padded scene box, ``grid_resolutions`` cells (or ``resolution``), every triangle in
    each cell its padded bounds reach. It takes ``build_grid``'s arguments, so that a test
    can also hand it to the lab in place of the lab's own builder. ``pad``: the margin
    (default ``grid_padding``); 0 lays the cells on the scene's bounds, and a triangle whose
    lower bound lies on a cell boundary is listed only in the cell above it."""
    corners = mesh.triangles().cpu()
    tri_lo, tri_hi = corners.amin(1), corners.amax(1)
    pad = grid_padding(tri_lo.amin(0), tri_hi.amax(0)) if pad is None else pad
    lo, hi = tri_lo.amin(0) - pad, tri_hi.amax(0) + pad
    if resolution is None:
        res = grid_resolutions((hi - lo)[None], torch.tensor([mesh.num_faces]), density)[0]
    else:
        res = torch.tensor(resolution, dtype=torch.int64)
    width = (hi - lo) / res
    c_lo = torch.minimum(torch.floor((tri_lo - pad - lo) / width).long().clamp(min=0), res - 1)
    c_hi = torch.minimum(torch.floor((tri_hi + pad - lo) / width).long().clamp(min=0), res - 1)
    pairs = []
    for t in range(mesh.num_faces):
        xs, ys, zs = (torch.arange(int(c_lo[t, a]), int(c_hi[t, a]) + 1) for a in range(3))
        z, y, x = torch.meshgrid(zs, ys, xs, indexing="ij")
        cid = (x + res[0] * (y + res[1] * z)).reshape(-1)
        pairs.append(torch.stack((cid, torch.full_like(cid, t)), 1))
    pairs = torch.cat(pairs)
    pairs = pairs[torch.argsort(pairs[:, 0] * mesh.num_faces + pairs[:, 1])]
    count = torch.bincount(pairs[:, 0], minlength=int(res.prod()))
    grid = {
        "kind": "grid",
        "lo": lo,
        "hi": hi,
        "resolution": res,
        "cell_start": torch.cumsum(count, 0) - count,
        "cell_count": count,
        "triangles": pairs[:, 1].contiguous(),
        "tri_cell_lo": c_lo,
        "tri_cell_hi": c_hi,
    }
    return {k: v.to(mesh.device) if isinstance(v, torch.Tensor) else v for k, v in grid.items()}


# ---------------------------------------------------------------------------------------
# Given stand-ins for the lab's own functions of other tasks. A function that builds on
# another task's function (closest_hit dispatching to the walks, build_two_level_grid
# building its top grid with build_grid) is graded with the stand-ins in place of the lab's
# own, through ``with_given``: a mistake in the other task then costs that task's points
# only. Each stand-in takes the arguments of the function it replaces.


def given_bvh(mesh: Mesh, leaf_size: int = 4, *_, **__) -> dict:
    """In place of build_sah_bvh / build_lbvh: the object-median BVH built here."""
    return median_bvh(mesh, leaf_size)


def given_kdtree(mesh: Mesh, *_, **__) -> dict:
    """In place of build_kdtree: the spatial-median kd-tree built here."""
    return median_kdtree(mesh)


def given_two_level_grid(mesh: Mesh, *_, **__) -> dict:
    """In place of build_two_level_grid: the two-level grid built here."""
    return simple_two_level(mesh)


def given_walk(rays: Rays, mesh: Mesh):
    """In place of a structure's walk: brute force's hits, with counters of a walk (one
    step, all F triangles tested, nothing skipped), on the rays' device."""
    t, tri, u, v = reference(rays.to("cpu"), on(mesh, "cpu"))
    device, n = rays.device, len(rays)
    hits = Hits(t=t.to(device), triangle=tri.to(device), u=u.to(device), v=v.to(device))
    return hits, {
        "steps": torch.ones(n, dtype=torch.int64, device=device),
        "tests": torch.full((n,), mesh.num_faces, dtype=torch.int64, device=device),
        "skipped": torch.zeros(n, dtype=torch.int64, device=device),
    }


GIVEN_WALKS = {
    "grid_closest_hit": "given_walk",
    "two_level_closest_hit": "given_walk",
    "bvh_closest_hit": "given_walk",
    "bvh_closest_hit_stackless": "given_walk",
    "kd_closest_hit": "given_walk",
}
GIVEN_BUILDERS = {
    "build_grid": "uniform_grid",
    "build_two_level_grid": "given_two_level_grid",
    "build_lbvh": "given_bvh",
    "build_sah_bvh": "given_bvh",
    "build_kdtree": "given_kdtree",
}


def _walk_arguments(rays, mesh, structure, intersect, mailbox=True):
    """A walk's parameters (``grid_closest_hit``'s; the others lack ``mailbox``)."""
    return {"rays": rays, "mesh": mesh, "mailbox": mailbox}


def with_given(lab, given: dict, call: str, *args, **kwargs):
    """Run ``lab.<call>(*args, **kwargs)`` next to the lab with the lab's functions named in
    ``given`` replaced by this module's stand-ins (lab function name -> stand-in name).
    Returns ``(result, calls)``: ``calls`` lists, in order, each replaced function the call
    used, as ``(name, options)``; a grid walk's options are ``{"mailbox": ...}``."""
    calls = []

    def stand_in(name):
        fn = globals()[given[name]]

        def replaced_by_given(*a, **k):
            if name not in GIVEN_WALKS:
                calls.append((name, {}))
                return fn(*a, **k)
            bound = _walk_arguments(*a, **k)
            grid_walk = name in ("grid_closest_hit", "two_level_closest_hit")
            calls.append((name, {"mailbox": bound["mailbox"]} if grid_walk else {}))
            return fn(bound["rays"], bound["mesh"])

        return replaced_by_given

    with replaced(lab, {name: stand_in(name) for name in given}):
        result = getattr(lab, call)(*args, **kwargs)
    return result, calls


# ---------------------------------------------------------------------------------------
# Structure checks and the SAH cost


def field(structure, key, what, shape, dtype, device):
    assert isinstance(structure, dict), f"{what}: expected a dict, got {type(structure).__name__}"
    if key not in structure:
        raise AssertionError(f"{what}: no {key!r} in the dict (keys: {sorted(structure)})")
    return check_tensor(
        structure[key], f"{what}[{key!r}]", shape=shape, dtype=dtype, device=device
    ).cpu()


def check_bvh(bvh, mesh: Mesh, what: str, leaf_size: int | None = None) -> None:
    """Structure of a BVH dict: a binary tree in depth-first layout, every triangle in
    exactly one leaf, every box containing its children and its triangles."""
    device, f = mesh.device, mesh.num_faces
    if bvh.get("kind") != "bvh":
        raise AssertionError(f"{what}: expected kind 'bvh', got {bvh.get('kind')!r}")
    lo = field(bvh, "lo", what, (None, 3), mesh.dtype, device)
    m = len(lo)
    hi = field(bvh, "hi", what, (m, 3), mesh.dtype, device)
    left, right, first, count = (
        field(bvh, k, what, (m,), torch.int64, device) for k in ("left", "right", "first", "count")
    )
    tris = field(bvh, "triangles", what, (f,), torch.int64, device)
    leaf = left < 0
    inner = (~leaf).nonzero()[:, 0]
    assert_equal(
        left[inner],
        inner + 1,
        name=f"{what}: left child of inner node i (the depth-first layout puts it at i + 1)",
        where="inner node",
    )
    bad = (right[inner] <= inner + 1) | (right[inner] >= m)
    assert not bad.any(), (
        f"{what}: inner node {int(inner[bad][0])} has right child "
        f"{int(right[inner][bad][0])}: expected after its left subtree, < {m}"
    )
    children = torch.sort(torch.cat((left[inner], right[inner]))).values
    assert_equal(
        children,
        torch.arange(1, m),
        name=f"{what}: the children of all inner nodes (every node but the root exactly once)",
        where="position",
    )
    assert (right[leaf] == -1).all(), f"{what}: leaves must have right == -1"
    assert (count[leaf] >= 1).all(), f"{what}: a leaf with no triangles"
    if leaf_size is not None and (count[leaf] > leaf_size).any():
        raise AssertionError(
            f"{what}: a leaf holds {int(count[leaf].max())} triangles, "
            f"more than leaf_size={leaf_size}"
        )
    leaves = leaf.nonzero()[:, 0]
    starts = first[leaves].sort()
    ends = starts.values + count[leaves][starts.indices]
    covers = (
        (starts.values[0] == 0)
        and bool((starts.values[1:] == ends[:-1]).all())
        and int(ends[-1]) == f
    )
    assert covers, f"{what}: the leaves' ranges [first, first + count) must tile 0..{f}"
    assert_equal(
        tris.sort().values,
        torch.arange(f),
        name=f"{what}: sorted triangles (each triangle exactly once)",
        where="position",
    )
    # Bounds: parents contain children, leaves their triangles (exact comparisons).
    for child in (left[inner], right[inner]):
        inside = (lo[inner] <= lo[child]).all(1) & (hi[inner] >= hi[child]).all(1)
        if not inside.all():
            i = int(inner[~inside][0])
            raise AssertionError(
                f"{what}: node {i}'s box [{lo[i].tolist()}, {hi[i].tolist()}] "
                f"does not contain its child's box"
            )
    owner = torch.repeat_interleave(leaves, count[leaves])
    k = (
        torch.repeat_interleave(first[leaves], count[leaves])
        + torch.arange(len(owner))
        - torch.repeat_interleave(torch.cumsum(count[leaves], 0) - count[leaves], count[leaves])
    )
    corners = mesh.triangles().cpu()[tris[k]]
    inside = (lo[owner] <= corners.amin(1)).all(1) & (hi[owner] >= corners.amax(1)).all(1)
    if not inside.all():
        j = int((~inside).nonzero()[0, 0])
        raise AssertionError(
            f"{what}: leaf {int(owner[j])} does not contain its triangle {int(tris[k][j])}"
        )


def sah_cost(bvh) -> float:
    """The SAH cost of a BVH, relative to its root: one unit per inner node and per
    triangle test, each weighted by the probability A(node) / A(root) of visiting it."""
    lo, hi = bvh["lo"].cpu().double(), bvh["hi"].cpu().double()
    ext = (hi - lo).clamp(min=0)
    area = 2 * (ext[:, 0] * ext[:, 1] + ext[:, 1] * ext[:, 2] + ext[:, 2] * ext[:, 0])
    leaf = bvh["left"].cpu() < 0
    return float((area[~leaf].sum() + (area[leaf] * bvh["count"].cpu()[leaf]).sum()) / area[0])


def check_kdtree(tree, mesh: Mesh, what: str) -> None:
    """Structure of a kd dict: children in pairs, planes inside their boxes, every
    triangle in some leaf, every leaf's triangles touching its box."""
    device = mesh.device
    if tree.get("kind") != "kd":
        raise AssertionError(f"{what}: expected kind 'kd', got {tree.get('kind')!r}")
    lo = field(tree, "lo", what, (3,), mesh.dtype, device)
    hi = field(tree, "hi", what, (3,), mesh.dtype, device)
    split = field(tree, "split", what, (None,), mesh.dtype, device)
    m = len(split)
    axis, left, first, count = (
        field(tree, k, what, (m,), torch.int64, device) for k in ("axis", "left", "first", "count")
    )
    tris = field(tree, "triangles", what, (None,), torch.int64, device)
    leaf = axis < 0
    inner = (~leaf).nonzero()[:, 0]
    assert ((axis >= -1) & (axis <= 2)).all(), f"{what}: axis must be -1 (leaf), 0, 1 or 2"
    assert (left[leaf] == -1).all(), f"{what}: leaves must have left == -1"
    children = torch.sort(torch.cat((left[inner], left[inner] + 1))).values
    assert_equal(
        children,
        torch.arange(1, m),
        name=f"{what}: the children (left, left + 1) "
        "of all inner nodes (every node but the root exactly once)",
        where="position",
    )
    # Boxes top-down, one tree level at a time.
    box_lo, box_hi = lo.expand(m, 3).clone(), hi.expand(m, 3).clone()
    level = torch.zeros(1, dtype=torch.int64)
    while len(level):
        level = level[axis[level] >= 0]
        a, s = axis[level], split[level]
        bad = (s < box_lo[level, a]) | (s > box_hi[level, a])
        if bad.any():
            i = int(level[bad][0])
            raise AssertionError(
                f"{what}: node {i} splits axis {int(axis[i])} at "
                f"{split[i].item()!r}, outside its box"
            )
        below, above = left[level], left[level] + 1
        box_lo[below], box_hi[below] = box_lo[level], box_hi[level]
        box_lo[above], box_hi[above] = box_lo[level], box_hi[level]
        box_hi[below, a] = s
        box_lo[above, a] = s
        level = torch.cat((below, above))
    leaves = leaf.nonzero()[:, 0]
    if (first[leaves] < 0).any() or (first[leaves] + count[leaves] > len(tris)).any():
        raise AssertionError(
            f"{what}: a leaf's range [first, first + count) runs outside "
            f"triangles (length {len(tris)})"
        )
    owner = torch.repeat_interleave(leaves, count[leaves])
    k = (
        torch.repeat_interleave(first[leaves], count[leaves])
        + torch.arange(len(owner))
        - torch.repeat_interleave(torch.cumsum(count[leaves], 0) - count[leaves], count[leaves])
    )
    listed = tris[k]
    assert ((listed >= 0) & (listed < mesh.num_faces)).all(), f"{what}: bad triangle index"
    missing = torch.ones(mesh.num_faces, dtype=torch.bool)
    missing[listed] = False
    assert not missing.any(), (
        f"{what}: triangle {int(missing.nonzero()[0, 0])} is in no leaf "
        f"({int(missing.sum())} triangles missing)"
    )
    corners = mesh.triangles().cpu()[listed]
    touch = (corners.amin(1) <= box_hi[owner]).all(1) & (corners.amax(1) >= box_lo[owner]).all(1)
    if not touch.all():
        j = int((~touch).nonzero()[0, 0])
        raise AssertionError(
            f"{what}: leaf {int(owner[j])} lists triangle {int(listed[j])}, "
            f"whose bounds do not reach the leaf's box"
        )


# ---------------------------------------------------------------------------------------
# Task 1: the uniform grid


def heuristic_resolution(extent, n: int, lam: float, max_cells: int = 2**22):
    """The docstring's heuristic, in float64: ``(rx, ry, rz)``, or None where a value lies
    within 1e-6 of a rounding or thinness boundary (either answer is right there)."""
    target = min(lam * n, max_cells)
    free = [a for a in range(3) if extent[a] > 0]
    k = 0.0
    while free:
        k = (target / math.prod(extent[a] for a in free)) ** (1 / len(free))
        if any(abs(extent[a] * k - 1) < 1e-6 for a in free):
            return None
        thin = [a for a in free if extent[a] * k < 1]
        if not thin:
            break
        free = [a for a in free if a not in thin]
    x = [extent[a] * k for a in free]
    if any(abs(v - math.floor(v) - 0.5) < 1e-6 for v in x):
        return None
    return tuple(max(1, round(extent[a] * k)) if a in free else 1 for a in range(3))


@pytest.mark.task(1)
@pytest.mark.points(1)
def test_grid_resolution_and_build(impl, device):
    # The heuristic: about lambda N cells, nearly cubic; thin axes get one cell.
    # (10, 10, 0.37): k * extent_z = 1.9 >= 1, so z is not thin: round(1.9) = 2 cells.
    for extent, n, lam in (
        ((1, 1, 1), 1000, 2.0),
        ((4, 1, 2), 500, 3.0),
        ((1, 1, 0), 800, 2.0),
        ((10, 0.01, 10), 5000, 1.0),
        ((1, 1, 1), 1, 2.0),
        ((10, 10, 0.37), 5000, 1.0),
        ((2, 3, 5), 777, 2.5),
        ((10, 10, 0.2), 5000, 1.0),  # k * extent_z = 1.26: not thin, round(1.26) = 1 cell
        ((1, 2, 3), 10**7, 2.0),  # capped at max_cells = 2**22
        ((10, 1, 1), 1000, None),  # the default density, 2: (58, 6, 6)
    ):
        res = (
            impl.grid_resolution(extent, n) if lam is None else impl.grid_resolution(extent, n, lam)
        )
        lam = 2.0 if lam is None else lam
        assert (
            isinstance(res, tuple)
            and len(res) == 3
            and all(isinstance(r, int) and r >= 1 for r in res)
        ), f"grid_resolution{extent, n, lam}: expected a tuple of 3 ints >= 1, got {res!r}"
        cells, aim = math.prod(res), min(lam * n, 2**22)  # the default max_cells
        assert aim / 2.5 <= cells <= aim * 2.5 or aim < 8, (
            f"grid_resolution(extent={extent}, N={n}, density={lam}) = {res}: {cells} cells, "
            f"expected about min(lambda N, max_cells) = {aim:g}"
        )
        widths = [e / r for e, r in zip(extent, res) if r > 1]
        assert not widths or max(widths) <= 2.0 * min(widths), (
            f"grid_resolution(extent={extent}, ...) = {res}: cell sizes {widths} are far from cubes"
        )
        # A one-cell axis is thin (thinner than a cell: k * extent < 1) or rounds to one cell
        # (k * extent < 1.5): never much wider than the cells of the other axes.
        single = [e for e, r in zip(extent, res) if r == 1 and e > 0]
        assert not (widths and single) or max(single) <= 2.0 * min(widths), (
            f"grid_resolution(extent={extent}, N={n}, density={lam}) = {res}: an axis of "
            f"extent {max(single):g} gets one cell, {max(single) / min(widths):.2f} times as "
            f"wide as the cells of the other axes ({min(widths):.4g}): only an axis with "
            f"k * extent < 1 is thin (drops out with one cell); others get round(k * extent)"
        )
        for e, r in zip(extent, res):
            if e == 0:
                assert r == 1, (
                    f"grid_resolution(extent={extent}, ...) = {res}: a flat axis needs one cell"
                )
        want = heuristic_resolution(extent, n, lam)
        assert want is None or res == want, (
            f"grid_resolution(extent={extent}, N={n}, density={lam}) = {res}, expected {want}: "
            f"r_i = round(k * extent_i) with k = (lambda N / prod extent_i) ** (1/d) over the "
            f"d axes that are not thin (k * extent_i >= 1); a thin axis gets one cell and k is "
            f"solved again without it"
        )
    expect_error("density", impl.grid_resolution, (1, 1, 1), 10, -1.0, case="density=-1")
    expect_error("extent", impl.grid_resolution, (1, 1), 10, case="a 2-element extent")
    # The build: CSR lists that are exactly each triangle's box of cells, and that box is
    # conservative (every cell the triangle's bounds touch) and tight (no farther).
    # "tiny": the soup shrunk 100 times: the padding must shrink with the scene.
    for name, resolution in (
        ("soup", None),
        ("teapot", None),
        ("shards", (7, 3, 5)),
        ("single", None),
        ("tiny", None),
        ("far", None),
        ("far, negative", None),
        ("a point at the origin", None),
    ):
        if name == "far, negative":
            mesh = on(mesh_of(-scene("far").triangles().double()), device)
        elif name == "a point at the origin":
            mesh = on(mesh_of(torch.zeros(1, 3, 3, dtype=F64)), device)
        else:
            mesh = on(scene(name), device)
        grid = impl.build_grid(mesh, resolution)
        what = f"build_grid({name}, resolution={resolution})"
        assert isinstance(grid, dict) and grid.get("kind") == "grid", (
            f"{what}: expected a dict with kind 'grid'"
        )
        f = mesh.num_faces
        lo = field(grid, "lo", what, (3,), mesh.dtype, device)
        hi = field(grid, "hi", what, (3,), mesh.dtype, device)
        res = field(grid, "resolution", what, (3,), torch.int64, device)
        if resolution is not None:
            assert res.tolist() == list(resolution), f"{what}: resolution {res.tolist()}"
        else:
            want = heuristic_resolution((hi - lo).tolist(), f, 2.0)
            assert want is None or res.tolist() == list(want), (
                f"{what}: resolution {res.tolist()}, expected {list(want)}: with resolution=None, "
                f"grid_resolution(hi - lo, F, density) of the grid's own box, density = 2"
            )
        assert (lo < hi).all(), (
            f"{what}: the grid's box [{lo.tolist()}, {hi.tolist()}] must have a thickness on "
            f"every axis (a flat scene, a single point: pad it)"
        )
        c = int(res.prod())
        start = field(grid, "cell_start", what, (c,), torch.int64, device)
        count = field(grid, "cell_count", what, (c,), torch.int64, device)
        tris = field(grid, "triangles", what, (None,), torch.int64, device)
        c_lo = field(grid, "tri_cell_lo", what, (f, 3), torch.int64, device)
        c_hi = field(grid, "tri_cell_hi", what, (f, 3), torch.int64, device)
        v_lo, v_hi = bounds(mesh)
        assert (lo.double() <= v_lo).all() and (hi.double() >= v_hi).all(), (
            f"{what}: the grid's box [{lo.tolist()}, {hi.tolist()}] must contain the scene"
        )
        assert_equal(
            start,
            torch.cumsum(count, 0) - count,
            name=f"{what}: cell_start (the exclusive prefix sum of cell_count)",
            where="cell",
        )
        assert int(count.sum()) == len(tris), (
            f"{what}: cell_count sums to {int(count.sum())}, but triangles has {len(tris)} entries"
        )
        # Expected (triangle, cell) pairs from the declared boxes of cells.
        span = c_hi - c_lo + 1
        assert (span >= 1).all() and (c_lo >= 0).all() and (c_hi < res).all(), (
            f"{what}: tri_cell_lo/hi must be boxes inside the grid"
        )
        pairs = []
        for t in range(f):
            xs, ys, zs = (torch.arange(int(c_lo[t, a]), int(c_hi[t, a]) + 1) for a in range(3))
            z, y, x = torch.meshgrid(zs, ys, xs, indexing="ij")
            cid = (x + res[0] * (y + res[1] * z)).reshape(-1)
            pairs.append(torch.stack((cid, torch.full_like(cid, t)), 1))
        want = torch.cat(pairs)
        want = want[torch.argsort(want[:, 0] * f + want[:, 1])]
        cell_of = torch.repeat_interleave(torch.arange(c), count)
        got = torch.stack((cell_of, tris), 1)
        got = got[torch.argsort(got[:, 0] * f + got[:, 1])]
        assert got.shape == want.shape and torch.equal(got, want), (
            f"{what}: the cell lists must hold exactly the (cell, triangle) pairs of each "
            f"triangle's box tri_cell_lo..tri_cell_hi ({len(want)} pairs), got {len(got)}"
        )
        # Conservative and tight against the triangles' bounds.
        width = (hi.double() - lo.double()) / res
        corners = mesh.triangles().cpu().double()
        first = torch.floor((corners.amin(1) - lo.double()) / width).long().clamp(min=0)
        last = torch.minimum(torch.floor((corners.amax(1) - lo.double()) / width).long(), res - 1)
        assert ((c_lo <= first) & (c_hi >= last)).all(), (
            f"{what}: a triangle's box of cells misses a cell its bounds overlap"
        )
        assert ((c_lo >= first - 1) & (c_hi <= last + 1)).all(), (
            f"{what}: a triangle is listed in cells more than one cell beyond its bounds"
        )
        # ... and no farther than a small pad: floor((tri_lo - pad - lo) / w) to
        # floor((tri_hi + pad - lo) / w), with a pad of at most 1e-3 of the scene's size and
        # a few ulps of its coordinates.
        size = float((corners.amax((0, 1)) - corners.amin((0, 1))).amax())
        slack = 1e-3 * size + 64 * torch.finfo(mesh.dtype).eps * float(corners.abs().amax())
        near_lo = torch.floor((corners.amin(1) - slack - lo.double()) / width).long().clamp(min=0)
        near_hi = torch.floor((corners.amax(1) + slack - lo.double()) / width).long()
        near_hi = torch.minimum(near_hi, res - 1)
        loose = (c_lo < near_lo) | (c_hi > near_hi)
        if size > 0 and loose.any():
            t = int(loose.any(1).nonzero()[0, 0])
            raise AssertionError(
                f"{what}: triangle {t} (bounds {corners[t].amin(0).tolist()} .. "
                f"{corners[t].amax(0).tolist()}) is listed in the cells {c_lo[t].tolist()} .. "
                f"{c_hi[t].tolist()}, beyond the cells its bounds (padded by a small pad) "
                f"overlap, {near_lo[t].tolist()} .. {near_hi[t].tolist()}: floor((tri_lo - pad "
                f"- lo) / w) to floor((tri_hi + pad - lo) / w)"
            )
    expect_error(
        "resolution",
        impl.build_grid,
        on(scene("soup"), device),
        (0, 4, 4),
        case="resolution (0, 4, 4)",
    )


@pytest.mark.task(1)
@pytest.mark.points(1)
def test_grid_closest_hit_matches_brute_force(impl, device):
    for name, resolution in (
        ("soup", None),
        ("shards", None),
        ("shards", (16, 16, 16)),
        ("shards", (1, 1, 1)),
        ("shards", (7, 2, 11)),
        ("ico", None),
        ("teapot", None),
    ):
        mesh = on(scene(name), device)
        rays = teapot_rays(200, 3) if name == "teapot" else rays_around(mesh, 240, 5)
        rays = rays.to(device)
        grid = uniform_grid(mesh, resolution)  # built here: the walk is graded on its own
        compare(
            impl.grid_closest_hit(rays, mesh, grid, mt64),
            rays,
            mesh,
            f"grid_closest_hit({name}, a grid built by the grader, resolution={resolution})",
            counters=("steps", "tests", "skipped"),
        )
    expect_error(
        "intersect",
        impl.grid_closest_hit,
        rays,
        mesh,
        grid,
        "mt",
        case="intersect='mt' (not callable)",
    )


def boundary_scene():
    """Two tiny triangles in opposite corners of the unit cube (the grid's bounds) and a
    big one in the plane x = 0.8 covering only y, z in [0.6, 1]."""
    tiny = torch.tensor(
        [
            [[0.0, 0.0, 0.0], [0.01, 0.0, 0.0], [0.0, 0.01, 0.0]],
            [[1.0, 1.0, 1.0], [0.99, 1.0, 1.0], [1.0, 0.99, 1.0]],
            [[0.8, 0.6, 0.6], [0.8, 1.0, 0.6], [0.8, 0.6, 1.0]],
        ],
        dtype=F64,
    )
    return mesh_of(tiny)


@pytest.mark.task(1)
@pytest.mark.points(1)
def test_grid_dda_extremes(impl, device):
    # Exact step counts along an empty row of an 8 x 8 x 8 grid (y, z = 0.47, 0.53 avoid
    # every triangle), with -0.0 and +0.0 in the zero components.
    mesh = on(boundary_scene(), device)
    grid = uniform_grid(mesh, (8, 8, 8))
    o = torch.tensor(
        [
            [-1.0, 0.47, 0.53],
            [2.0, 0.47, 0.53],
            [0.4, 0.47, 0.53],
            [0.4, 0.47, 0.53],
            [0.47, -1.0, 0.53],
            [0.47, 0.53, 2.0],
            [-1.0, 2.0, 0.5],
            [0.4, 0.47, 0.53],
        ]
    )
    d = torch.tensor(
        [
            [1.0, 0.0, -0.0],
            [-1.0, -0.0, 0.0],
            [1.0, -0.0, -0.0],
            [-1.0, 0.0, 0.0],
            [0.0, 1.0, -0.0],
            [-0.0, 0.0, -1.0],
            [1.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
        ]
    )
    t_max = torch.tensor([INF] * 7 + [0.2])  # the last stops at x = 0.6: cells 3 and 4
    rays = Rays.create(o, d, 0.0, t_max).to(device)
    hits, count = check_result(
        impl.grid_closest_hit(rays, mesh, grid, mt64),
        len(rays),
        F32,
        device,
        "grid_closest_hit (axis rays, 8^3 grid)",
    )
    want = [8, 8, 5, 4, 8, 8, 0, 2]  # cells 0..7; 7..0; 3..7; 3..0; ...; misses the grid; 3..4
    got = count["steps"].tolist()
    if got != want:
        i = next(j for j in range(len(want)) if got[j] != want[j])
        raise AssertionError(
            f"grid_closest_hit: ray {i} ({describe(rays.to('cpu'), i)}) runs along an empty row "
            f"of the 8 x 8 x 8 grid over the unit cube and must visit {want[i]} cells, visited "
            f"{got[i]} (all steps: {got}, expected {want}). Check the first cell, t_next for "
            f"step +1 (the cell's upper face) and -1 (its lower face), t_next = inf for zero "
            f"components (+0.0 and -0.0), and the exit at t_max / the grid's far side."
        )
    assert (hits.triangle.cpu() == -1).all(), "grid_closest_hit: these rays hit nothing"
    assert (count["tests"] == 0).all(), "grid_closest_hit: empty cells hold nothing to test"
    # Rays starting exactly on cell boundaries, in the plane of the big triangle, and
    # axis-parallel rays with mixed zeros: brute force decides.
    lo, hi, res = grid["lo"].cpu().double(), grid["hi"].cpu().double(), grid["resolution"].cpu()
    w = (hi - lo) / res
    on_plane = (lo + 5 * w).float()  # boundary planes of cell 5 on each axis
    g = generator(51)
    p = torch.rand(40, 3, generator=g) * 0.3 + 0.65
    axis = torch.arange(40) % 3
    p[torch.arange(40), axis] = on_plane[axis]
    d = torch.zeros(40, 3)
    d[torch.arange(40), axis] = torch.where(torch.arange(40) % 2 == 0, 1.0, -1.0)
    d = torch.where(d == 0, torch.where(torch.rand(40, 3, generator=g) < 0.5, -0.0, 0.0), d)
    d[::4] += torch.rand(10, 3, generator=g) * 0.2  # some slanted
    boundary = Rays.create(p, d)
    rays = cat_rays(boundary, axis_rays(mesh, 52, 8), bad_rays())
    compare(
        impl.grid_closest_hit(rays.to(device), mesh, grid, mt64),
        rays.to(device),
        mesh,
        "grid_closest_hit (rays on cell boundaries, axis-parallel, NaN/inf)",
        counters=("steps", "tests", "skipped"),
    )
    # Axis-parallel rays in a real scene, a single flat triangle, far from the origin,
    # coincident triangles.
    for name in ("shards", "single", "far", "coincident"):
        mesh = on(scene(name), device)
        rays = cat_rays(axis_rays(mesh, 53, 6), rays_around(mesh, 80, 54)).to(device)
        compare(
            impl.grid_closest_hit(rays, mesh, uniform_grid(mesh), mt64),
            rays,
            mesh,
            f"grid_closest_hit({name}: axis-parallel and random rays)",
            counters=("steps", "tests", "skipped"),
        )


@pytest.mark.task(1)
@pytest.mark.points(1)
def test_grid_mailboxing(impl, device):
    # Six big triangles, each listed in many of the 12^3 cells: without a mailbox a ray tests
    # one triangle once per cell it shares with it.
    mesh = on(scene("slabs"), device)
    grid = uniform_grid(mesh, (12, 12, 12))
    rays = rays_around(mesh, 300, 61, clip=0.0).to(device)
    ref = reference(rays.to("cpu"), on(mesh, "cpu"))
    with_box = compare(
        impl.grid_closest_hit(rays, mesh, grid, mt64, mailbox=True),
        rays,
        mesh,
        "grid_closest_hit(mailbox=True)",
        ("steps", "tests", "skipped"),
        ref,
    )
    without = compare(
        impl.grid_closest_hit(rays, mesh, grid, mt64, mailbox=False),
        rays,
        mesh,
        "grid_closest_hit(mailbox=False)",
        ("steps", "tests", "skipped"),
        ref,
    )
    most = int(with_box["tests"].max())
    assert most <= mesh.num_faces, (
        f"grid_closest_hit(mailbox=True): a ray ran {most} triangle tests in a scene of "
        f"{mesh.num_faces} triangles: the mailbox must stop every repeated test of a triangle"
    )
    assert int(without["tests"].sum()) > 2 * int(with_box["tests"].sum()), (
        "grid_closest_hit(mailbox=False) should repeat tests of triangles that span cells: "
        f"{int(without['tests'].sum())} tests without the mailbox, "
        f"{int(with_box['tests'].sum())} with it"
    )
    assert_equal(
        with_box["steps"],
        without["steps"],
        name="grid_closest_hit: steps with and without the mailbox (it must not change the walk)",
        where="ray",
    )
    assert_equal(
        with_box["tests"] + with_box["skipped"],
        without["tests"],
        name="grid_closest_hit: tests + skipped with the mailbox == tests without it",
        where="ray",
    )
    assert (without["skipped"] == 0).all(), "grid_closest_hit(mailbox=False) skipped tests"


# ---------------------------------------------------------------------------------------
# Task 2: BVH builds


def interleave(q: torch.Tensor, bits: int) -> torch.Tensor:
    """The expected code: bit i of x, y, z at bits 3i + 2, 3i + 1, 3i (one bit at a time)."""
    code = torch.zeros(len(q), dtype=torch.int64)
    for i in range(bits):
        for axis in range(3):
            code += ((q[:, axis] >> i) & 1) << (3 * i + 2 - axis)
    return code


@pytest.mark.task(2)
@pytest.mark.points(1)
def test_morton_codes(impl, device):
    g = generator(71)
    for bits in (10, 4, 1, 16):
        q = torch.randint(0, 2**bits, (300, 3), generator=g)
        q[:3] = torch.tensor([[0, 0, 0], [2**bits - 1] * 3, [1, 0, 2**bits - 1]]) % 2**bits
        lo = torch.tensor([-2.0, 0.5, 10.0], dtype=F64)
        size = torch.tensor([4.0, 1.0, 0.25], dtype=F64)
        points = lo + (q.double() + 0.5) / 2**bits * size  # cell centres: no rounding doubt
        codes = impl.morton_codes(
            points.float().to(device), lo.float().to(device), (lo + size).float().to(device), bits
        )
        check_tensor(
            codes, f"morton_codes(bits={bits})", shape=(300,), dtype=torch.int64, device=device
        )
        assert_equal(
            codes.cpu(),
            interleave(q, bits),
            name=f"morton_codes(bits={bits}) of cell "
            "centres (x's bit i at code bit 3i+2, y's at 3i+1, z's at 3i)",
            where="point",
        )
    # The box's corners and beyond clamp; a flat axis quantises to 0.
    lo, hi = torch.zeros(3, device=device), torch.ones(3, device=device)
    edge = torch.tensor([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [-5.0, 2.0, 0.5]], device=device)
    codes = impl.morton_codes(edge, lo, hi, 10).cpu()
    assert codes.tolist()[:2] == [0, 2**30 - 1], (
        f"morton_codes: the box's corners lo and hi must get codes 0 and 2^30 - 1, got "
        f"{codes.tolist()[:2]} (clamp q to [0, 2^bits - 1])"
    )
    assert codes[2] == interleave(torch.tensor([[0, 1023, 512]]), 10)[0], (
        "morton_codes: points outside the box clamp to its faces"
    )
    default = impl.morton_codes(edge, lo, hi).cpu()
    assert default.tolist() == codes.tolist(), (
        f"morton_codes(points, lo, hi): the default is bits=10, the 30-bit code: expected "
        f"{codes.tolist()}, got {default.tolist()}"
    )
    nan = impl.morton_codes(torch.tensor([[math.nan, 0.5, 0.25]], device=device), lo, hi).cpu()
    assert nan[0] == interleave(torch.tensor([[0, 512, 256]]), 10)[0], (
        f"morton_codes: a NaN coordinate quantises to 0: the point (nan, 0.5, 0.25) has q = "
        f"(0, 512, 256), code {int(interleave(torch.tensor([[0, 512, 256]]), 10)[0])}; got "
        f"{int(nan[0])}"
    )
    flat = impl.morton_codes(
        torch.tensor([[0.3, 0.7, 5.0]], device=device),
        lo,
        torch.tensor([1.0, 1.0, 0.0], device=device),
        10,
    ).cpu()
    assert flat[0] == interleave(torch.tensor([[307, 716, 0]]), 10)[0], (
        "morton_codes: an axis with hi == lo quantises to 0"
    )
    expect_error("bits", impl.morton_codes, edge, lo, hi, 22, case="bits=22 (66-bit codes)")
    expect_error("points", impl.morton_codes, edge[:, :2], lo, hi, case="points of shape (3, 2)")


@pytest.mark.task(2)
@pytest.mark.points(1)
def test_lbvh_structure_and_quality(impl, device):
    for name in ("soup", "ico", "teapot", "shards", "single", "coincident"):
        mesh = on(scene(name), device)
        for leaf_size in (1, 4):
            bvh = impl.build_lbvh(mesh, leaf_size)
            check_bvh(bvh, mesh, f"build_lbvh({name}, leaf_size={leaf_size})", leaf_size)
    # Quality: splitting at the highest differing Morton bit clusters space about as well as
    # an object-median split does (the SAH cost of a middle-of-the-range split is far worse).
    for name in ("soup", "ico"):
        mesh = on(scene(name), device)
        got, median = sah_cost(impl.build_lbvh(mesh, 4)), sah_cost(median_bvh(mesh, 4))
        assert got <= 1.25 * median, (
            f"build_lbvh({name}): SAH cost {got:.1f}, an object-median BVH costs {median:.1f}: "
            f"split each range where the highest differing bit of its Morton codes flips"
        )
    expect_error("leaf_size", impl.build_lbvh, on(scene("soup"), device), 0, case="leaf_size=0")


@pytest.mark.task(2)
@pytest.mark.points(1)
def test_sah_bvh_structure_and_quality(impl, device):
    for name in ("soup", "ico", "teapot", "shards", "single", "coincident", "far"):
        mesh = on(scene(name), device)
        for leaf_size, bins in ((1, 8), (4, 16)):
            bvh = impl.build_sah_bvh(mesh, leaf_size, bins)
            check_bvh(
                bvh, mesh, f"build_sah_bvh({name}, leaf_size={leaf_size}, bins={bins})", leaf_size
            )
    # Quality: the SAH beats the object median, by far in the teapot in a stadium.
    for name, factor in (("soup", 1.0), ("ico", 1.0), ("teapot", 0.5)):
        mesh = on(scene(name), device)
        got, median = sah_cost(impl.build_sah_bvh(mesh, 4, 16)), sah_cost(median_bvh(mesh, 4))
        assert got <= factor * median, (
            f"build_sah_bvh({name}): SAH cost {got:.1f}, expected at most {factor} x the "
            f"{median:.1f} of an object-median BVH. The cost of a split is A(left) N(left) + "
            f"A(right) N(right) with A the area of the union of the *triangle* bounds per side"
        )
    mesh = on(scene("soup"), device)
    expect_error("leaf_size", impl.build_sah_bvh, mesh, 0, case="leaf_size=0")
    expect_error("bins", impl.build_sah_bvh, mesh, 4, 1, case="bins=1")


# ---------------------------------------------------------------------------------------
# Task 3: BVH traversal (on BVHs built here)


CHAIN = 40  # deeper than a 32-entry stack


def chain_scene(device):
    """``(mesh, bvh, kd, rays)``: CHAIN triangles in the planes x = 0, 1, ..., as a chain
    (each inner node: one triangle's leaf and the chain of the ones above it), and two rays
    coming down x from above: they enter the chain first at every node, so each node pushes
    its leaf, and the stack holds CHAIN - 1 entries before the first hit."""
    f = CHAIN
    x = torch.arange(f, dtype=F64)[:, None]
    corners = torch.stack(
        (
            torch.cat((x, torch.zeros(f, 2, dtype=F64)), 1),
            torch.cat((x, torch.ones(f, 1, dtype=F64), torch.zeros(f, 1, dtype=F64)), 1),
            torch.cat((x, torch.zeros(f, 1, dtype=F64), torch.ones(f, 1, dtype=F64)), 1),
        ),
        1,
    )
    mesh = mesh_of(corners, device=device)
    k = torch.arange(f - 1)
    # Depth-first: chain node k is 2k, its leaf 2k + 1, the next chain node 2k + 2; the
    # last chain node's right child is the leaf of triangle f - 1 (node 2f - 2).
    m = 2 * f - 1
    left, right = torch.full((m,), -1), torch.full((m,), -1)
    left[2 * k], right[2 * k] = 2 * k + 1, 2 * k + 2
    leaf_tri = torch.full((m,), -1)
    leaf_tri[2 * k + 1] = k
    leaf_tri[m - 1] = f - 1
    lo, hi = torch.zeros(m, 3, dtype=F32), torch.ones(m, 3, dtype=F32)
    for i in range(m):
        if leaf_tri[i] >= 0:
            lo[i, 0] = hi[i, 0] = float(leaf_tri[i])
        else:
            lo[i, 0], hi[i, 0] = float(i // 2), float(f - 1)
    is_leaf = leaf_tri >= 0
    bvh = {
        "kind": "bvh",
        "lo": lo.to(device),
        "hi": hi.to(device),
        "left": left.to(device),
        "right": right.to(device),
        "first": torch.where(is_leaf, leaf_tri, 0).to(device),
        "count": is_leaf.long().to(device),
        "triangles": torch.arange(f, device=device),
    }
    # The kd chain: node 2k splits x at k + 0.5, lower child (2k + 1) the leaf of triangle k.
    kd = {
        "kind": "kd",
        "lo": torch.tensor([0.0, 0.0, 0.0], device=device),
        "hi": torch.tensor([f - 1.0, 1.0, 1.0], device=device),
        "split": torch.where(left >= 0, torch.arange(m) // 2 + 0.5, 0.0).float().to(device),
        "axis": torch.where(left >= 0, 0, -1).to(device),
        "left": left.to(device),
        "first": torch.where(is_leaf, leaf_tri, 0).to(device),
        "count": is_leaf.long().to(device),
        "triangles": torch.arange(f, device=device),
    }
    rays = Rays.create(  # the last one crosses every box and misses every triangle
        torch.tensor([[f + 1.0, 0.2, 0.2], [f + 3.0, 0.1, 0.6], [f + 1.0, 0.9, 0.9]]),
        torch.tensor([[-1.0, 0.0, 0.0], [-2.0, 0.01, 0.0], [-1.0, 0.0, 0.0]]),
    ).to(device)
    return mesh, bvh, kd, rays


def check_chain_miss(count, what: str) -> None:
    """The chain's first two rays test one triangle (the hit culls every other leaf); its
    last ray crosses every box and hits nothing: it visits each of the 2 CHAIN - 1 nodes
    once and tests each triangle once, no more."""
    tests = count["tests"][:2].tolist()
    assert tests == [1, 1], (
        f"{what}: rays 0 and 1 hit triangle {CHAIN - 1} in the first leaf they reach, and every "
        f"other leaf is entered beyond that hit: one triangle test each, got {tests}. A node "
        f"entered beyond reach(closest t) is culled when it is popped, with the t it was "
        f"entered at (its own, not its sibling's)"
    )
    got = (int(count["steps"][2]), int(count["tests"][2]))
    assert got == (2 * CHAIN - 1, CHAIN), (
        f"{what}: a ray through every box of the chain that hits nothing must visit each of "
        f"its {2 * CHAIN - 1} nodes once and test each of its {CHAIN} triangles once; got "
        f"steps={got[0]}, tests={got[1]}: a walk ends when its stack is empty"
    )


@pytest.mark.task(3)
@pytest.mark.points(1)
def test_bvh_stack_traversal(impl, device):
    # A tree deeper than 32, walked so that the stack fills up: it must grow.
    mesh, bvh, _, rays = chain_scene(device)
    what = (
        f"bvh_closest_hit(a chain of {CHAIN} nodes, rays that push every leaf: the stack "
        f"needs {CHAIN - 1} entries)"
    )
    check_chain_miss(compare(impl.bvh_closest_hit(rays, mesh, bvh, mt64), rays, mesh, what), what)
    for name, leaf_size in (("soup", 1), ("shards", 3), ("ico", 2), ("teapot", 4)):
        mesh = on(scene(name), device)
        rays = teapot_rays(200, 81) if name == "teapot" else rays_around(mesh, 240, 82)
        rays = rays.to(device)
        bvh = median_bvh(mesh, leaf_size)
        count = compare(
            impl.bvh_closest_hit(rays, mesh, bvh, mt64),
            rays,
            mesh,
            f"bvh_closest_hit({name}, median BVH, leaf_size={leaf_size})",
        )
        if name == "ico":
            # From outside a closed sphere, the near side holds the hit: near child first
            # tests about 4 triangles per ray here; far child first about 9.
            mean = count["tests"].double().mean().item()
            assert mean <= 6.0, (
                f"bvh_closest_hit: {mean:.2f} triangle tests per ray into a closed icosphere; "
                f"visiting the near child first (pop it first: push it last) and culling nodes "
                f"beyond the closest hit needs about 4"
            )
    # Rays that miss the root box visit nothing.
    mesh = on(scene("soup"), device)
    away = Rays.create(torch.full((5, 3), 3.0), torch.tensor([[1.0, 0, 0]] * 5)).to(device)
    _, count = check_result(
        impl.bvh_closest_hit(away, mesh, median_bvh(mesh), mt64),
        5,
        F32,
        device,
        "bvh_closest_hit (rays away from the scene)",
    )
    assert (count["tests"] == 0).all(), "bvh_closest_hit: rays that miss the root test nothing"


def skip_reference(bvh) -> list[int]:
    """Next node after each subtree, by recursion over the depth-first layout."""
    left, right = bvh["left"].tolist(), bvh["right"].tolist()
    end = [0] * len(left)

    def walk(i):
        end[i] = i + 1 if left[i] < 0 else (walk(left[i]), walk(right[i]))[1]
        return end[i]

    walk(0)
    return end


def leaf_tests_bound(rays: Rays, bvh, hit=None) -> torch.Tensor:
    """(N,) int64: the triangles in the leaves whose box (padded by 1e-5 of the root's
    size) the ray's segment [t_min, t_max] crosses, in float64: the most triangle tests a
    walk that tests only the leaves it hits can run (CPU).

    hit: brute force's ``(t, triangle)`` per ray, for a walk that goes through the leaves in
    array order (stackless) and culls by the closest hit: once it has tested the leaf holding
    the hit, it has that hit, and no later leaf entered beyond it is tested."""
    leaf = (bvh["left"].cpu() < 0).nonzero()[:, 0]
    lo, hi = bvh["lo"].cpu().double(), bvh["hi"].cpu().double()
    pad = 1e-5 * float((hi[0] - lo[0]).amax())
    lo, hi = lo[leaf] - pad, hi[leaf] + pad
    o, d = rays.origins.double()[:, None], rays.directions.double()[:, None]
    t0, t1 = (lo - o) / d, (hi - o) / d  # 0 / 0 = NaN (in a slab plane): no bound
    near, far = torch.minimum(t0, t1), torch.maximum(t0, t1)
    near = torch.where(near.isnan(), -INF, near).amax(-1)
    far = torch.where(far.isnan(), INF, far).amin(-1)
    entry = torch.maximum(near, rays.t_min.double()[:, None])
    crossed = entry <= torch.minimum(far, rays.t_max.double()[:, None])
    if hit is not None:
        t_hit, tri = (x.cpu() for x in hit)
        # The node (in array order) of the leaf holding each triangle; M for a miss.
        m, first, count = len(bvh["left"]), bvh["first"].cpu(), bvh["count"].cpu()
        node_of = torch.full((len(bvh["triangles"]) + 1,), m, dtype=torch.int64)
        for i in leaf.tolist():
            node_of[bvh["triangles"].cpu()[first[i] : first[i] + count[i]]] = i
        hit_node = node_of[torch.where(tri >= 0, tri, len(node_of) - 1)]
        culled = (leaf[None] > hit_node[:, None]) & (entry > t_hit.double()[:, None])
        crossed &= ~culled
    return (crossed.long() * bvh["count"].cpu()[leaf]).sum(1)


@pytest.mark.task(3)
@pytest.mark.points(1)
def test_bvh_stackless_traversal(impl, device):
    # A hand-made tree: 0 -> (1, 4), 1 -> (2, 3), 4 -> (5, 6).
    tree = {
        "left": torch.tensor([1, 2, -1, -1, 5, -1, -1], device=device),
        "right": torch.tensor([4, 3, -1, -1, 6, -1, -1], device=device),
    }
    got = impl.bvh_skip_indices(tree)
    check_tensor(got, "bvh_skip_indices", shape=(7,), dtype=torch.int64, device=device)
    assert got.tolist() == [7, 4, 3, 4, 7, 6, 7], (
        f"bvh_skip_indices of the tree 0 -> (1, 4), 1 -> (2, 3), 4 -> (5, 6): expected "
        f"[7, 4, 3, 4, 7, 6, 7] (the node after each subtree, 7 = past the end), got "
        f"{got.tolist()}"
    )
    for name, leaf_size in (("soup", 1), ("shards", 3), ("ico", 2), ("teapot", 4)):
        mesh = on(scene(name), device)
        bvh = median_bvh(mesh, leaf_size)
        assert impl.bvh_skip_indices(bvh).tolist() == skip_reference(bvh), (
            f"bvh_skip_indices({name}): wrong links"
        )
        rays = teapot_rays(200, 91) if name == "teapot" else rays_around(mesh, 240, 92)
        rays = rays.to(device)
        stackless = compare(
            impl.bvh_closest_hit_stackless(rays, mesh, bvh, mt64),
            rays,
            mesh,
            f"bvh_closest_hit_stackless({name}, median BVH)",
        )
        hit_root = stackless["steps"] >= 1
        assert hit_root.any(), "bvh_closest_hit_stackless: count a step per node visited"
        if name == "soup":
            # A ray alone: the walk runs until its last ray is done, one ray included.
            ref_t, ref_i, _, _ = reference(rays.to("cpu"), on(mesh, "cpu"))
            i = int((ref_i >= 0).nonzero()[0, 0])
            compare(
                impl.bvh_closest_hit_stackless(rays[i : i + 1], mesh, bvh, mt64),
                rays[i : i + 1],
                mesh,
                f"bvh_closest_hit_stackless({name}, median BVH, ray {i} alone)",
            )
            # Rays that miss the root box test it (one step) and skip the whole tree.
            away = Rays.create(torch.full((4, 3), 3.0), torch.tensor([[1.0, 0, 0]] * 4))
            _, count = check_result(
                impl.bvh_closest_hit_stackless(away.to(device), mesh, bvh, mt64),
                4,
                F32,
                device,
                "bvh_closest_hit_stackless (rays away from the scene)",
            )
            assert (count["steps"] <= 1).all() and (count["tests"] == 0).all(), (
                f"bvh_closest_hit_stackless: rays that miss the root box must skip the whole "
                f"tree after testing it (a missed box jumps to skip[i], even an inner node's): "
                f"got steps {count['steps'].tolist()}, tests {count['tests'].tolist()}"
            )
        # A leaf whose box the ray misses is skipped: its triangles are never tested.
        most = leaf_tests_bound(rays.to("cpu"), bvh)
        over = stackless["tests"] > most
        if over.any():
            i = int(over.nonzero()[0, 0])
            raise AssertionError(
                f"bvh_closest_hit_stackless({name}, median BVH): {int(over.sum())} rays test "
                f"triangles of leaves whose box they miss. First: ray {i} "
                f"({describe(rays.to('cpu'), i)}) "
                f"ran {int(stackless['tests'][i])} tests, its segment crosses leaf boxes of "
                f"{int(most[i])} triangles: test a leaf's triangles only if its box is hit"
            )
        # ... or is entered beyond the closest hit found so far: the box test's interval is
        # [t_min, min(t_max, reach(best_t))]. After the leaf holding brute force's hit (in
        # array order), no leaf entered beyond that hit is tested.
        ref_t, ref_i, _, _ = reference(rays.to("cpu"), on(mesh, "cpu"))
        most = leaf_tests_bound(rays.to("cpu"), bvh, (ref_t, ref_i))
        over = stackless["tests"] > most
        if over.any():
            i = int(over.nonzero()[0, 0])
            raise AssertionError(
                f"bvh_closest_hit_stackless({name}, median BVH): {int(over.sum())} rays test "
                f"triangles of leaves entered beyond their closest hit, after the leaf that "
                f"holds it. First: ray {i} ({describe(rays.to('cpu'), i)}) ran "
                f"{int(stackless['tests'][i])} tests, at most {int(most[i])} expected: "
                f"slab-test each box against [t_min, min(t_max, reach(best_t))], not "
                f"[t_min, t_max]"
            )


@pytest.mark.task(3)
@pytest.mark.points(1)
def test_bvh_traversal_extremes(impl, device):
    cases = []
    for name in ("single", "coincident", "far", "shards"):
        mesh = on(scene(name), device)
        rays = cat_rays(axis_rays(mesh, 101, 6), rays_around(mesh, 60, 102), bad_rays())
        cases.append((name, mesh, median_bvh(mesh, 2), rays))
    # Rays in the planes of the root box's faces, along them (0 * inf = NaN in the slabs).
    mesh = on(scene("soup"), device)
    lo, hi = bounds(mesh)
    g = generator(103)
    p = lo + (hi - lo) * torch.rand(30, 3, generator=g, dtype=F64)
    p[:10, 0], p[10:20, 1], p[20:, 2] = lo[0], hi[1], lo[2]
    d = torch.randn(30, 3, generator=g, dtype=F64)
    d[:10, 0], d[10:20, 1], d[20:, 2] = 0.0, -0.0, 0.0
    faces = Rays.create(p.float(), d.float())
    cases.append(
        (
            "soup, rays in the root's face planes",
            mesh,
            median_bvh(mesh, 2),
            cat_rays(faces, axis_rays(mesh, 104, 6)),
        )
    )
    # float64 rays and mesh.
    m64 = Mesh(
        vertices=scene("shards").vertices.double().to(device),
        faces=scene("shards").faces.to(device),
    )
    cases.append(("shards, float64", m64, median_bvh(m64, 3), rays_around(m64, 80, 105, dtype=F64)))
    for name, mesh, bvh, rays in cases:
        rays = rays.to(device)
        ref = reference(rays.to("cpu"), on(mesh, "cpu"))
        for fn in (impl.bvh_closest_hit, impl.bvh_closest_hit_stackless):
            label = getattr(fn, "__name__", None) or getattr(fn, "_name", "traversal")
            compare(fn(rays, mesh, bvh, mt64), rays, mesh, f"{label}({name})", ref=ref)
    # Bad input, named.
    mesh = on(scene("shards"), device)
    rays = rays_around(mesh, 8, 106).to(device)
    m64 = Mesh(vertices=mesh.vertices.double(), faces=mesh.faces)
    expect_error(
        "mesh",
        impl.bvh_closest_hit,
        rays,
        m64,
        median_bvh(m64),
        mt64,
        case="a float64 mesh with float32 rays",
    )
    expect_error(
        "bvh",
        impl.bvh_closest_hit,
        rays,
        mesh,
        uniform_grid(mesh),
        mt64,
        case="a grid passed as the bvh",
    )
    # Coincident triangles: the tie goes to the lowest index, whatever leaf it sits in.
    mesh = on(scene("coincident"), device)
    rays = Rays.create(
        torch.tensor([[0.4, 0.4, -1.0], [0.45, 0.4, 2.0]]),
        torch.tensor([[0.0, 0.0, 1.0], [-0.0, 0.0, -1.0]]),
    )
    for fn in (impl.bvh_closest_hit, impl.bvh_closest_hit_stackless):
        hits, _ = fn(rays.to(device), mesh, median_bvh(mesh, 3), mt64)
        assert hits.triangle.tolist() == [0, 0], (
            f"BVH traversal: 40 coincident triangles, the rays hit all at the same t: the "
            f"lowest index (0) must win for both rays, got {hits.triangle.tolist()}"
        )
    # Two overlapping triangles in the plane z = 0.5, triangle 1 in the left leaf: the ray
    # hits it at t = 1.5, and the right leaf (triangle 0), flat, is entered at t = 1.5 too:
    # a node is culled only if its entry t is *beyond* the closest hit, so triangle 0 wins.
    flat = mesh_of(
        torch.tensor(
            [
                [[0.25, 0.25, 0.5], [1.0, 0.25, 0.5], [0.25, 1.0, 0.5]],
                [[0.0, 0.0, 0.5], [0.75, 0.0, 0.5], [0.0, 0.75, 0.5]],
            ],
            dtype=F64,
        ),
        device=device,
    )
    rays = Rays.create(
        torch.tensor([[0.3125, 0.3125, -1.0], [0.3125, 0.3125, 2.0]]),
        torch.tensor([[0.0, -0.0, 1.0], [-0.0, 0.0, -1.0]]),
    ).to(device)
    bvh = median_bvh(flat, 1)
    assert bvh["triangles"].tolist() == [1, 0], "test set-up: triangle 1 in the left leaf"
    for fn in (impl.bvh_closest_hit, impl.bvh_closest_hit_stackless):
        hits, _ = fn(rays, flat, bvh, mt64)
        label = getattr(fn, "__name__", None) or getattr(fn, "_name", "traversal")
        assert hits.triangle.tolist() == [0, 0] and hits.t.tolist() == [1.5, 1.5], (
            f"{label}: two overlapping triangles in the plane z = 0.5, both hit at t = 1.5, "
            f"triangle 1's leaf first; the other leaf's box (flat) is entered at t = 1.5, "
            f"not beyond the closest hit: visit it, the lowest index (0) must win; got "
            f"triangles {hits.triangle.tolist()} at t = {hits.t.tolist()}"
        )
    # A ray aimed exactly at the vertex two triangles of Suzanne share (float32, exact
    # bits): both are hit at t = 0.99999994, and the box of triangle 0's leaf is entered at
    # a t that rounds a little beyond that. Whichever leaf comes first, the walk must keep a
    # node entered up to reach(best_t), not best_t: the lowest index (0) wins.
    h = float.fromhex
    shared = [h("0x1.8cp-1"), h("0x1.cp-2"), h("0x1.1p-2")]
    pair = mesh_of(
        torch.tensor(
            [
                [
                    shared,
                    [h("0x1.98p-1"), h("0x1.ep-4"), h("0x1.3cp-1")],
                    [h("0x1.a4p-1"), h("0x1.ap-3"), h("0x1.5p-2")],
                ],
                [
                    shared,
                    [h("0x1.3cp-1"), h("0x1.2cp-1"), h("0x1.5p-2")],
                    [h("0x1.48p-1"), h("0x1.c8p-2"), h("0x1.5cp-1")],
                ],
            ],
            dtype=F64,
        ),
        device=device,
    )
    at_vertex = Rays.create(  # the ray twice: both must report triangle 0
        torch.tensor([[h("-0x1.50a902p-1"), h("0x1.2eadb2p+1"), h("0x1.69731cp+0")]] * 2),
        torch.tensor([[h("0x1.6e5482p+0"), h("-0x1.ed5b66p+0"), h("-0x1.25731cp+0")]] * 2),
    ).to(device)
    ref_t, ref_i, _, _ = reference(at_vertex.to("cpu"), on(pair, "cpu"))
    assert ref_i.tolist() == [0, 0], "test set-up: brute force picks triangle 0"
    tri_lo, tri_hi = (x.to(device) for x in (pair.triangles().amin(1), pair.triangles().amax(1)))
    for order in ([1, 0], [0, 1]):
        two_leaves = {
            "kind": "bvh",
            "lo": torch.stack((tri_lo.amin(0), tri_lo[order[0]], tri_lo[order[1]])),
            "hi": torch.stack((tri_hi.amax(0), tri_hi[order[0]], tri_hi[order[1]])),
            "left": torch.tensor([1, -1, -1], device=device),
            "right": torch.tensor([2, -1, -1], device=device),
            "first": torch.tensor([0, 0, 1], device=device),
            "count": torch.tensor([0, 1, 1], device=device),
            "triangles": torch.tensor(order, device=device),
        }
        for fn in (impl.bvh_closest_hit, impl.bvh_closest_hit_stackless):
            hits, _ = fn(at_vertex, pair, two_leaves, mt64)
            label = getattr(fn, "__name__", None) or getattr(fn, "_name", "traversal")
            assert hits.triangle.tolist() == [0, 0], (
                f"{label}: a ray aimed exactly at the vertex triangles 0 and 1 share, both hit "
                f"at t = {ref_t[0].item():.9g}, triangle {order[0]}'s leaf first: got triangle "
                f"{hits.triangle.tolist()[0]}, brute force picks 0 (ties to the lowest index). "
                f"The other leaf's box is entered at a t that rounds a little beyond the hit: "
                f"cull a node only if its entry t is beyond reach(best_t) "
                f"(course.given.lab2_robust), not beyond best_t"
            )


# ---------------------------------------------------------------------------------------
# Task 4: the kd-tree


@pytest.mark.task(4)
@pytest.mark.points(1)
def test_kd_pack_unpack(impl, device):
    # Node 0 splits x at 0.25 (children 1, 2); node 1 is a leaf of 3 triangles from 0; node
    # 2 splits z at -1.5 (children 3, 4); leaves 3 and 4 hold 2 and 0 triangles from 3.
    tree = {
        "split": torch.tensor([0.25, 0.0, -1.5, 0.0, 0.0], device=device),
        "axis": torch.tensor([0, -1, 2, -1, -1], device=device),
        "left": torch.tensor([1, -1, 3, -1, -1], device=device),
        "first": torch.tensor([0, 0, 0, 3, 5], device=device),
        "count": torch.tensor([0, 3, 0, 2, 0], device=device),
    }
    packed = impl.kd_pack(tree)
    check_tensor(packed, "kd_pack", shape=(5, 2), dtype=torch.int32, device=device)
    words = packed.cpu().long() & 0xFFFFFFFF
    split_bits = torch.tensor([0.25, -1.5]).view(torch.int32).long() & 0xFFFFFFFF
    assert words[[0, 2], 0].tolist() == split_bits.tolist(), (
        "kd_pack: word 0 of an inner node must hold the float32 bits of split "
        "(split.view(torch.int32))"
    )
    assert words[[1, 3, 4], 0].tolist() == [3, 2, 0], "kd_pack: word 0 of a leaf is its count"
    want = [1 | 0 << 29, 0 | 1 << 31, 1 | 2 << 29, 3 | 1 << 31, 5 | 1 << 31]
    got = words[:, 1].tolist()
    assert got == want, (
        "kd_pack: word 1 = leftOffset (bits 0-28) | splitAxis << 29 | leaf << 31, with "
        "leftOffset = left - i for inner nodes and first for leaves: expected "
        f"{[hex(w) for w in want]}, got {[hex(w) for w in got]}"
    )
    assert (packed[:, 1].cpu() < 0).tolist() == [False, True, False, True, True], (
        "kd_pack: the leaf bit is the sign bit of word 1 as int32"
    )
    back = impl.kd_unpack(packed)
    for key, dtype in (
        ("split", F32),
        ("axis", torch.int64),
        ("left", torch.int64),
        ("first", torch.int64),
        ("count", torch.int64),
    ):
        check_tensor(back[key], f"kd_unpack(...)[{key!r}]", shape=(5,), dtype=dtype, device=device)
    leaf = tree["axis"].cpu() < 0
    assert_equal(back["axis"].cpu(), tree["axis"].cpu(), name="kd_unpack: axis", where="node")
    assert_equal(back["left"].cpu(), tree["left"].cpu(), name="kd_unpack: left", where="node")
    zero = torch.zeros(5, dtype=torch.int64)
    assert_equal(
        back["split"].cpu(),
        torch.where(leaf, 0.0, tree["split"].cpu()),
        name="kd_unpack: split (0 for leaves)",
        where="node",
    )
    assert_equal(
        back["first"].cpu(),
        torch.where(leaf, tree["first"].cpu(), zero),
        name="kd_unpack: first (0 for inner nodes)",
        where="node",
    )
    assert_equal(
        back["count"].cpu(),
        torch.where(leaf, tree["count"].cpu(), zero),
        name="kd_unpack: count (0 for inner nodes)",
        where="node",
    )
    # Leaves whose lists start anywhere (every offset > 0) pack; a count of 2^31 does not fit.
    later = dict(tree, first=torch.tensor([0, 4, 0, 7, 9], device=device))
    words = impl.kd_pack(later).cpu().long() & 0xFFFFFFFF
    assert (words[[1, 3, 4], 1] & (2**29 - 1)).tolist() == [4, 7, 9], (
        "kd_pack: a leaf's leftOffset is its first (here 4, 7, 9: every offset > 0 fits)"
    )
    huge = dict(tree, count=torch.tensor([0, 2**31, 0, 2, 0], device=device))
    expect_error("tree", impl.kd_pack, huge, case="a leaf of 2^31 triangles (needs 32 bits)")
    # A round trip through a real tree, and an offset too big for 29 bits.
    kd = median_kdtree(on(scene("soup"), device))
    back = impl.kd_unpack(impl.kd_pack(kd))
    for key in ("axis", "left"):
        assert_equal(
            back[key].cpu(), kd[key].cpu(), name=f"kd_unpack(kd_pack(tree))[{key!r}]", where="node"
        )
    big = dict(tree, first=torch.tensor([0, 2**29, 0, 3, 5], device=device))
    expect_error("tree", impl.kd_pack, big, case="a leaf starting at 2^29 (needs 30 bits)")


@pytest.mark.task(4)
@pytest.mark.points(1)
def test_kd_closest_hit(impl, device):
    # A tree deeper than 32, walked so that the stack fills up: it must grow.
    mesh, _, kd, rays = chain_scene(device)
    what = (
        f"kd_closest_hit(a chain of {CHAIN} nodes, rays that push every leaf: the stack "
        f"needs {CHAIN - 1} entries)"
    )
    check_chain_miss(compare(impl.kd_closest_hit(rays, mesh, kd, mt64), rays, mesh, what), what)
    # Trees built here: spatial-median planes, straddling triangles in both children. A hit
    # found in a leaf may lie beyond it; only a hit inside the leaf's interval ends the walk.
    for name, depth in (("shards", 10), ("soup", 8), ("ico", 10), ("teapot", 12), ("slabs", 6)):
        mesh = on(scene(name), device)
        rays = teapot_rays(200, 111) if name == "teapot" else rays_around(mesh, 240, 112)
        rays = cat_rays(rays, axis_rays(mesh, 113, 4)).to(device)
        tree = median_kdtree(mesh, depth)
        compare(
            impl.kd_closest_hit(rays, mesh, tree, mt64),
            rays,
            mesh,
            f"kd_closest_hit({name}, spatial-median tree of depth {depth})",
        )
    # Rays lying in the root's split plane with a zero component there (0 * inf = NaN).
    mesh = on(scene("shards"), device)
    tree = median_kdtree(mesh, 10)
    a, s = int(tree["axis"][0]), tree["split"][0].item()
    g = generator(114)
    p = torch.rand(40, 3, generator=g)
    p[:, a] = s
    d = torch.randn(40, 3, generator=g)
    d[:, a] = torch.where(torch.arange(40) % 2 == 0, 0.0, -0.0)
    rays = cat_rays(Rays.create(p, d), bad_rays()).to(device)
    compare(
        impl.kd_closest_hit(rays, mesh, tree, mt64),
        rays,
        mesh,
        "kd_closest_hit (rays in the root's split plane, NaN/inf rays)",
    )


def kd_node_costs(t_lo, t_hi, box, knobs):
    """The docstring's SAH cost of every event of one node (float64): per axis
    ``(position, cost)``, the node's triangles' bounds clipped to its box, sorted by
    (position, start before end); ``inf`` for planes not strictly inside the box."""
    traversal, inter, bonus = knobs
    lo, hi = box
    ext = hi - lo
    area = 2 * (ext[0] * ext[1] + ext[1] * ext[2] + ext[2] * ext[0])
    n = len(t_lo)
    out = []
    for a in range(3):
        pos = torch.cat((t_lo[:, a], t_hi[:, a])).clamp(float(lo[a]), float(hi[a]))
        is_end = torch.cat((torch.zeros(n), torch.ones(n))).double()
        order = torch.argsort(pos * 0 + is_end, stable=True)
        order = order[torch.argsort(pos[order], stable=True)]
        pos, is_end = pos[order], is_end[order]
        below = torch.cumsum(1 - is_end, 0) - (1 - is_end)  # starts before the event
        above = n - torch.cumsum(is_end, 0)  # ends after it
        e1, e2 = ext[(a + 1) % 3], ext[(a + 2) % 3]
        a_below = 2 * (e1 * e2 + (pos - lo[a]) * (e1 + e2))
        a_above = 2 * (e1 * e2 + (hi[a] - pos) * (e1 + e2))
        empty = ((below == 0) | (above == 0)).double()
        cost = traversal + inter * (1 - bonus * empty) * (a_below * below + a_above * above) / area
        out.append((pos, torch.where((pos > lo[a]) & (pos < hi[a]), cost, INF)))
    return out


def kd_root_costs(mesh: Mesh, traversal: float, intersect: float, bonus: float):
    """:func:`kd_node_costs` of the root: every triangle, in the scene's bounds."""
    corners = mesh.triangles().cpu().double()
    t_lo, t_hi = corners.amin(1), corners.amax(1)
    return kd_node_costs(t_lo, t_hi, (t_lo.amin(0), t_hi.amax(0)), (traversal, intersect, bonus))


@pytest.mark.task(4)
@pytest.mark.points(1)
def test_kdtree_build(impl, device):
    # The root's split, by the documented cost: the cheapest event over the three axes, and
    # only if it beats a leaf (intersect_cost * n). Any of equally cheap planes will do.
    for name in ("soup", "teapot", "far"):
        mesh = on(scene(name), device)
        n = mesh.num_faces
        for traversal, inter, bonus in ((1.0, 2.0, 0.5), (1.0, 2.0, 0.0), (0.6 * n, 1.0, 0.9)):
            knobs = dict(traversal_cost=traversal, intersect_cost=inter, empty_bonus=bonus)
            what = ", ".join(f"{k}={v:g}" for k, v in knobs.items())
            what = f"build_kdtree({name}, max_depth=1, {what})"
            tree = impl.build_kdtree(mesh, max_depth=1, leaf_size=1, **knobs)
            check_kdtree(tree, mesh, what)
            costs = kd_root_costs(mesh, traversal, inter, bonus)
            best = min(float(c.min()) for _, c in costs)
            axis = int(tree["axis"][0])
            if axis < 0:
                assert best >= inter * n * (1 - 1e-6), (
                    f"{what}: the root is a leaf, but its cheapest split costs {best:.6g} "
                    f"< a leaf's intersect_cost * n = {inter * n:g}: it must split"
                )
                continue
            assert best < inter * n * (1 + 1e-6), (
                f"{what}: the root splits, but its cheapest split costs {best:.6g}, no less "
                f"than a leaf's intersect_cost * n = {inter * n:g}: cost = traversal + "
                f"intersect * (1 - bonus if a side is empty) * (A_b N_b + A_a N_a) / A"
            )
            pos, cost = costs[axis]
            value = float(tree["split"][0])
            mine = cost[pos == value]
            mine = float(mine.min()) if len(mine) else INF
            assert mine <= best * (1 + 1e-6), (
                f"{what}: the root splits axis {axis} at {value!r}, where the SAH cost is "
                f"{mine:.6g}; the cheapest event costs {best:.6g}. cost = traversal + "
                f"intersect * (1 - bonus if a side is empty) * (A_below N_below + A_above "
                f"N_above) / A_node, the bonus only where a side is empty"
            )
    for name in ("soup", "shards", "ico", "teapot", "single", "coincident", "far"):
        mesh = on(scene(name), device)
        tree = impl.build_kdtree(mesh)
        what = f"build_kdtree({name})"
        check_kdtree(tree, mesh, what)
        rays = (
            teapot_rays(150, 121)
            if name == "teapot"
            else cat_rays(rays_around(mesh, 150, 122), axis_rays(mesh, 123, 3))
        )
        rays = rays.to(device)
        count = compare(
            impl.kd_closest_hit(rays, mesh, tree, mt64), rays, mesh, f"kd_closest_hit on {what}"
        )
        if name == "teapot":
            at_teapot = torch.arange(len(rays)) % 4 != 3
            mean = count["tests"][at_teapot].double().mean().item()
            assert mean <= 0.05 * mesh.num_faces, (
                f"{what}: rays at the teapot run {mean:.1f} triangle tests on average, "
                f"{mean / mesh.num_faces:.1%} of the scene: the SAH should cut the empty "
                f"stadium away and the teapot into small leaves"
            )
    mesh = on(scene("soup"), device)
    leaf = impl.build_kdtree(mesh, max_depth=0)
    check_kdtree(leaf, mesh, "build_kdtree(max_depth=0)")
    assert len(leaf["axis"]) == 1, "build_kdtree(max_depth=0): expected a single leaf"
    expect_error("max_depth", impl.build_kdtree, mesh, -1, case="max_depth=-1")


# ---------------------------------------------------------------------------------------
# Task 5: the common entry point and the trade


@pytest.mark.task(5)
@pytest.mark.points(1)
def test_closest_hit_entry_point(impl, device):
    mesh = on(scene("shards"), device)
    rays = rays_around(mesh, 150, 131).to(device)
    ref = reference(rays.to("cpu"), on(mesh, "cpu"))
    count = compare(
        impl.brute_force_closest_hit(rays, mesh, mt64),
        rays,
        mesh,
        "brute_force_closest_hit",
        ref=ref,
        walks=False,
    )
    assert (count["tests"] == mesh.num_faces).all(), (
        "brute_force_closest_hit: every ray tests every triangle (counters['tests'] == F)"
    )
    compare(
        impl.brute_force_closest_hit(rays, mesh, mt64, 2**12),
        rays,
        mesh,
        "brute_force_closest_hit(memory_budget_bytes=4096)",
        ref=ref,
        walks=False,
    )
    # Structures built here, and the walks given (brute force standing in for the lab's own
    # walks of tasks 1, 3, 4 and 6): closest_hit is graded on its dispatch alone. A walk it
    # calls must be the structure's own, with the option passed on.
    structures = {
        "grid": uniform_grid(mesh),
        "grid2": simple_two_level(mesh),
        "bvh": median_bvh(mesh, 2),
        "kd": median_kdtree(mesh),
    }
    walk_of = {
        "grid": "grid_closest_hit",
        "grid2": "two_level_closest_hit",
        "bvh": "bvh_closest_hit",
        "kd": "kd_closest_hit",
    }
    for kind, options in (
        ("grid", {}),
        ("grid", {"mailbox": False}),
        ("grid2", {}),
        ("grid2", {"mailbox": False}),
        ("bvh", {}),
        ("bvh", {"stackless": True}),
        ("kd", {}),
    ):
        what = f"closest_hit({kind}, {options})"
        result, calls = impl.probe(
            with_given, GIVEN_WALKS, "closest_hit", rays, mesh, structures[kind], mt64, **options
        )
        walk = "bvh_closest_hit_stackless" if options.get("stackless") else walk_of[kind]
        want = (walk, {"mailbox": options.get("mailbox", True)} if kind.startswith("grid") else {})
        calls = [(name, dict(opts)) for name, opts in calls]
        assert calls in ([], [want]), (
            f"{what}: the structure must go to {walk}"
            f"{'(..., mailbox=' + str(want[1]['mailbox']) + ')' if want[1] else ''}, once; "
            f"closest_hit called {calls or 'no walk'}"
        )
        compare(result, rays, mesh, f"{what} (with the walks given)", ref=ref)
    compare(
        impl.closest_hit(rays, mesh, None, mt64),
        rays,
        mesh,
        "closest_hit(None)",
        ref=ref,
        walks=False,
    )
    # Bad input, named.
    expect_error(
        "structure",
        impl.closest_hit,
        rays,
        mesh,
        {"kind": "octree"},
        mt64,
        case="structure={'kind': 'octree'}",
    )
    expect_error(
        "rays",
        impl.closest_hit,
        (rays.origins, rays.directions),
        mesh,
        None,
        mt64,
        case="a tuple instead of Rays",
    )
    m64 = Mesh(vertices=mesh.vertices.double(), faces=mesh.faces)
    expect_error(
        "mesh", impl.closest_hit, rays, m64, None, mt64, case="a float64 mesh with float32 rays"
    )
    expect_error(
        "intersect", impl.closest_hit, rays, mesh, None, "mt", case="intersect='mt' (not callable)"
    )
    expect_error(
        "memory_budget_bytes",
        impl.brute_force_closest_hit,
        rays,
        mesh,
        mt64,
        0,
        case="memory_budget_bytes=0",
    )


@pytest.mark.task(END_TO_END)
@pytest.mark.points(1)
def test_counters_show_the_trade(impl, device):
    # End to end, with the lab's own builders and walks (every other test grades one of
    # them on structures built here): the teapot in a stadium. A uniform grid sized for the
    # whole room puts the teapot into a cell or two, so its rays test hundreds of
    # triangles; a BVH adapts. (So does an SAH kd-tree: test_kdtree_build; a
    # spatial-median one would not.) A failure names the builder when a structure built
    # here in its place repairs the run, else the walks.
    mesh = on(scene("teapot"), device)
    rays = teapot_rays(160, 141).to(device)
    ref = reference(rays.to("cpu"), on(mesh, "cpu"))
    grid, bvh = impl.build_grid(mesh), impl.build_sah_bvh(mesh, 4)
    try:
        the_trade(impl, mesh, rays, ref, grid, bvh)
    except AssertionError as error:
        wrong = []
        for name, given in (
            ("build_grid", (uniform_grid(mesh), bvh)),
            ("build_sah_bvh", (grid, median_bvh(mesh, 4))),
        ):
            try:
                the_trade(impl, mesh, rays, ref, *given)
                wrong.append(name)
            except AssertionError:
                pass
        hint = (
            f"the step that is wrong: {' or '.join(wrong)} (with a structure built by the "
            f"grader in its place the run is right)"
            if wrong
            else "the builders are not the cause (structures built by the grader in their place "
            "fail too): see the walks' tests (grid_closest_hit, bvh_closest_hit, "
            "bvh_closest_hit_stackless, bvh_closest_hit_fast) and closest_hit's"
        )
        raise AssertionError(f"the teapot in a stadium, end to end: {hint}.\n{error}") from None


def the_trade(impl, mesh: Mesh, rays: Rays, ref, grid: dict, bvh: dict) -> None:
    """The lab's walks on ``grid`` and ``bvh`` through ``closest_hit``: brute force's hits,
    and counters that show what each structure buys on the teapot in a stadium."""
    at_teapot = torch.arange(len(rays)) % 4 != 3
    mean = {}
    for kind, structure, options in (
        ("grid", grid, {}),
        ("bvh", bvh, {}),
        ("bvh stackless", bvh, {"stackless": True}),
    ):
        count = compare(
            impl.closest_hit(rays, mesh, structure, mt64, **options),
            rays,
            mesh,
            f"closest_hit on the {kind} (build_grid / build_sah_bvh) of the teapot in a stadium",
            ref=ref,
        )
        mean[kind] = {k: count[k][at_teapot].double().mean().item() for k in ("steps", "tests")}
    f = mesh.num_faces
    assert mean["grid"]["tests"] >= 0.1 * f, (
        f"grid: rays at the teapot run {mean['grid']['tests']:.1f} tests on average; with "
        f"about 2 cells per triangle over the whole stadium the teapot fills one or two "
        f"cells, so they should test a good part of its {f - 12} triangles. Count every test."
    )
    for kind in ("bvh", "bvh stackless"):
        assert mean[kind]["tests"] <= 0.05 * f, (
            f"{kind}: rays at the teapot run {mean[kind]['tests']:.1f} triangle tests on average "
            f"(of {f} triangles); a tree adapts to the teapot and needs far fewer"
        )
    assert mean["bvh stackless"]["steps"] > mean["bvh"]["steps"], (
        "BVH: the stackless walk (always left first, no culling by a near hit) should visit "
        f"more nodes than the stack traversal: {mean['bvh stackless']['steps']:.1f} vs "
        f"{mean['bvh']['steps']:.1f}"
    )
    compare_fast(
        impl.bvh_closest_hit_fast(rays, mesh, bvh),
        rays,
        mesh,
        "bvh_closest_hit_fast on the build_sah_bvh(teapot)",
        ref=ref,
    )


# ---------------------------------------------------------------------------------------
# Task 6: the two-level grid


def simple_two_level(mesh: Mesh, top_res=(3, 3, 3), sub_res=(5, 4, 3), min_triangles=6) -> dict:
    """A two-level grid in the lab's layout, built here with loops over cells (small scenes):
    a fixed top resolution, a fixed sub-grid resolution, generous padding."""
    corners = mesh.triangles().cpu()
    dtype = corners.dtype
    tri_lo, tri_hi = corners.amin(1), corners.amax(1)
    eps = torch.finfo(dtype).eps

    def padding(lo, hi):
        pad = 1e-3 * float((hi - lo).amax()) + 64 * eps * float(
            torch.maximum(lo.abs(), hi.abs()).amax()
        )
        return pad if pad > 0 else 1.0

    pad = padding(tri_lo.amin(0), tri_hi.amax(0))
    lo, hi = tri_lo.amin(0) - pad, tri_hi.amax(0) + pad
    res = torch.tensor(top_res)
    w = (hi - lo) / res
    c_lo = torch.minimum(torch.floor((tri_lo - pad - lo) / w).long().clamp(min=0), res - 1)
    c_hi = torch.minimum(torch.floor((tri_hi + pad - lo) / w).long().clamp(min=0), res - 1)
    big = (tri_hi - tri_lo).amax(1) >= w.amin()
    sres = torch.tensor(sub_res)
    direct, sub_of, boxes, cell_lists, entry_lo, entry_hi = [], [], [], [], [], []
    for cid in range(math.prod(top_res)):
        c = torch.tensor([cid % res[0], (cid // res[0]) % res[1], cid // (res[0] * res[1])])
        ids = ((c_lo <= c) & (c_hi >= c)).all(1).nonzero()[:, 0]
        small = ids[~big[ids]]
        if len(small) <= min_triangles:
            direct.append(ids)
            sub_of.append(-1)
            continue
        direct.append(ids[big[ids]])
        sub_of.append(len(boxes))
        blo = torch.maximum(tri_lo[small].amin(0), lo + c * w)
        bhi = torch.minimum(tri_hi[small].amax(0), lo + (c + 1) * w)
        spad = padding(blo, bhi)
        blo, bhi = blo - spad, bhi + spad
        boxes.append((blo, bhi))
        sw = (bhi - blo) / sres
        s_lo = torch.minimum(
            torch.floor((tri_lo[small] - spad - blo) / sw).long().clamp(min=0), sres - 1
        )
        s_hi = torch.minimum(
            torch.floor((tri_hi[small] + spad - blo) / sw).long().clamp(min=0), sres - 1
        )
        for sid in range(math.prod(sub_res)):
            q = torch.tensor(
                [sid % sres[0], (sid // sres[0]) % sres[1], sid // (sres[0] * sres[1])]
            )
            inside = ((s_lo <= q) & (s_hi >= q)).all(1)
            cell_lists.append(small[inside])
            entry_lo.append(s_lo[inside])
            entry_hi.append(s_hi[inside])
    count = torch.tensor([len(x) for x in direct], dtype=torch.int64)
    sub_count = torch.tensor([len(x) for x in cell_lists], dtype=torch.int64)
    n_sub = len(boxes)
    dev = mesh.device
    empty3 = torch.zeros((0, 3), dtype=torch.int64)
    out = {
        "kind": "grid2",
        "lo": lo,
        "hi": hi,
        "resolution": res,
        "cell_start": torch.cumsum(count, 0) - count,
        "cell_count": count,
        "triangles": torch.cat(direct).long(),
        "tri_cell_lo": c_lo,
        "tri_cell_hi": c_hi,
        "big": big,
        "sub_of": torch.tensor(sub_of, dtype=torch.int64),
        "sub_lo": torch.stack([b[0] for b in boxes]) if n_sub else torch.zeros((0, 3), dtype=dtype),
        "sub_hi": torch.stack([b[1] for b in boxes]) if n_sub else torch.zeros((0, 3), dtype=dtype),
        "sub_resolution": sres.expand(n_sub, 3).clone(),
        "sub_cell_base": torch.arange(n_sub, dtype=torch.int64) * math.prod(sub_res),
        "sub_cell_start": torch.cumsum(sub_count, 0) - sub_count,
        "sub_cell_count": sub_count,
        "sub_triangles": torch.cat(cell_lists).long()
        if cell_lists
        else torch.zeros(0, dtype=torch.int64),
        "sub_tri_cell_lo": torch.cat(entry_lo) if entry_lo else empty3,
        "sub_tri_cell_hi": torch.cat(entry_hi) if entry_hi else empty3,
    }
    return {k: v.to(dev) if isinstance(v, torch.Tensor) else v for k, v in out.items()}


GRID2_COUNTERS = ("steps", "tests", "skipped")


def check_two_level(g, mesh: Mesh, what: str, density: float, min_triangles: int = 16) -> None:
    """Structure of a two-level grid: the top lists and sub-grids together list every
    triangle in every top cell its bounds reach, a top cell has a sub-grid iff it holds more
    than ``min_triangles`` small triangles, sub-grids sit in their cells and cover their
    triangles, and each sub-grid's resolution follows the density heuristic."""
    device, f = mesh.device, mesh.num_faces
    assert isinstance(g, dict) and g.get("kind") == "grid2", (
        f"{what}: expected a dict with kind 'grid2'"
    )
    lo = field(g, "lo", what, (3,), mesh.dtype, device).double()
    hi = field(g, "hi", what, (3,), mesh.dtype, device).double()
    res = field(g, "resolution", what, (3,), torch.int64, device)
    c = int(res.prod())
    start, count = (
        field(g, k, what, (c,), torch.int64, device) for k in ("cell_start", "cell_count")
    )
    tris = field(g, "triangles", what, (None,), torch.int64, device)
    c_lo, c_hi = (
        field(g, k, what, (f, 3), torch.int64, device) for k in ("tri_cell_lo", "tri_cell_hi")
    )
    big = field(g, "big", what, (f,), torch.bool, device)
    sub_of = field(g, "sub_of", what, (c,), torch.int64, device)
    s = int((sub_of >= 0).sum())
    sub_lo = field(g, "sub_lo", what, (s, 3), mesh.dtype, device).double()
    sub_hi = field(g, "sub_hi", what, (s, 3), mesh.dtype, device).double()
    sres = field(g, "sub_resolution", what, (s, 3), torch.int64, device)
    base = field(g, "sub_cell_base", what, (s,), torch.int64, device)
    sc = int(sres.prod(1).sum()) if s else 0
    s_start, s_count = (
        field(g, k, what, (sc,), torch.int64, device) for k in ("sub_cell_start", "sub_cell_count")
    )
    s_tris = field(g, "sub_triangles", what, (None,), torch.int64, device)
    k2 = len(s_tris)
    e_lo, e_hi = (
        field(g, k, what, (k2, 3), torch.int64, device)
        for k in ("sub_tri_cell_lo", "sub_tri_cell_hi")
    )
    assert_equal(
        sub_of[sub_of >= 0].sort().values,
        torch.arange(s),
        name=f"{what}: sub_of (each sub-grid belongs to exactly one top cell)",
        where="position",
    )
    assert_equal(
        base,
        torch.cumsum(sres.prod(1), 0) - sres.prod(1),
        name=f"{what}: sub_cell_base (the exclusive prefix sum of the sub-grids' cell counts)",
        where="sub-grid",
    )
    assert_equal(start, torch.cumsum(count, 0) - count, name=f"{what}: cell_start", where="cell")
    assert_equal(
        s_start,
        torch.cumsum(s_count, 0) - s_count,
        name=f"{what}: sub_cell_start",
        where="sub cell",
    )
    assert int(count.sum()) == len(tris) and int(s_count.sum()) == k2, (
        f"{what}: the cell counts must sum to the lengths of the triangle lists"
    )
    width = (hi - lo) / res
    corners = mesh.triangles().cpu().double()
    t_lo, t_hi = corners.amin(1), corners.amax(1)
    assert ((lo <= t_lo.amin(0)) & (hi >= t_hi.amax(0))).all(), (
        f"{what}: the top grid's box must contain the scene"
    )
    first = torch.floor((t_lo - lo) / width).long().clamp(min=0)
    last = torch.minimum(torch.floor((t_hi - lo) / width).long(), res - 1)
    assert ((c_lo <= first) & (c_hi >= last) & (c_lo >= first - 1) & (c_hi <= last + 1)).all(), (
        f"{what}: tri_cell_lo/hi must be each triangle's box of top cells (all the cells its "
        f"bounds overlap, at most one more)"
    )
    wide = (t_hi - t_lo).amax(1) >= 1.001 * width.amin()
    assert big[wide].all(), (
        f"{what}: a triangle at least one top cell wide must be big "
        f"(listed directly, never in a sub-grid): {int((wide & ~big).sum())} "
        f"are not"
    )
    # Every (triangle, top cell) overlap: in the cell's direct list, or (small triangles of
    # a cell with a sub-grid) in that sub-grid.
    cell_of = torch.repeat_interleave(torch.arange(c), count)
    listed = set(zip(cell_of.tolist(), tris.tolist()))
    sub_cell_owner = (
        torch.repeat_interleave(torch.arange(s), sres.prod(1))
        if s
        else torch.zeros(0, dtype=torch.int64)
    )
    entry_sub_cell = torch.repeat_interleave(torch.arange(sc), s_count)
    entry_sub = sub_cell_owner[entry_sub_cell]
    in_sub = set(zip(entry_sub.tolist(), s_tris.tolist()))
    n_small = [0] * c  # small triangles per top cell
    for t in range(f):
        for x in range(int(c_lo[t, 0]), int(c_hi[t, 0]) + 1):
            for y in range(int(c_lo[t, 1]), int(c_hi[t, 1]) + 1):
                for z in range(int(c_lo[t, 2]), int(c_hi[t, 2]) + 1):
                    cid = x + int(res[0]) * (y + int(res[1]) * z)
                    n_small[cid] += not big[t]
                    sg = int(sub_of[cid])
                    ok = (cid, t) in listed or (sg >= 0 and not big[t] and (sg, t) in in_sub)
                    if not ok:
                        raise AssertionError(
                            f"{what}: triangle {t} overlaps top cell {(x, y, z)} but is neither "
                            f"in its direct list nor in its sub-grid"
                        )
    wrong = [i for i in range(c) if (n_small[i] > min_triangles) != (int(sub_of[i]) >= 0)]
    if wrong:
        i = wrong[0]
        raise AssertionError(
            f"{what}: top cell {i} holds {n_small[i]} small triangles and "
            f"{'has' if int(sub_of[i]) >= 0 else 'lacks'} a sub-grid: a cell gets one iff it "
            f"holds more than min_triangles={min_triangles} ({len(wrong)} cells wrong)"
        )
    dense_direct = sub_of[cell_of] >= 0
    assert big[tris[dense_direct]].all(), (
        f"{what}: a cell with a sub-grid lists only its big triangles directly (the small ones "
        f"are in the sub-grid)"
    )
    assert not big[s_tris].any(), f"{what}: a big triangle sits in a sub-grid"
    # Sub-grids: inside their top cell (to within padding), covering their triangles.
    if s == 0:
        return
    owner_cell = torch.zeros(s, dtype=torch.int64)
    owner_cell[sub_of[sub_of >= 0]] = (sub_of >= 0).nonzero()[:, 0]
    cc = torch.stack(
        (owner_cell % res[0], (owner_cell // res[0]) % res[1], owner_cell // (res[0] * res[1])), 1
    )
    slack = 1e-3 * width.amax() + 64 * torch.finfo(mesh.dtype).eps * float(
        torch.maximum(lo.abs(), hi.abs()).amax()
    )  # the padding: relative, and a few ulps
    cell_lo, cell_hi = lo + cc * width, lo + (cc + 1) * width
    assert ((sub_lo >= cell_lo - slack) & (sub_hi <= cell_hi + slack) & (sub_lo < sub_hi)).all(), (
        f"{what}: a sub-grid's box must lie inside its top cell: it holds what of its "
        f"triangles lies in that cell"
    )
    sw = (sub_hi - sub_lo) / sres
    clip_lo = torch.maximum(t_lo[s_tris], cell_lo[entry_sub])
    clip_hi = torch.minimum(t_hi[s_tris], cell_hi[entry_sub])
    box_first = torch.floor((clip_lo - sub_lo[entry_sub]) / sw[entry_sub]).long()
    box_last = torch.floor((clip_hi - sub_lo[entry_sub]) / sw[entry_sub]).long()
    ok = (box_first >= -1) & (box_last <= sres[entry_sub])
    assert ok.all(), f"{what}: a sub-grid's box does not cover its triangles (clipped to the cell)"
    top_cell = sres[entry_sub] - 1
    box_first = torch.minimum(box_first.clamp(min=0), top_cell)
    box_last = torch.minimum(box_last.clamp(min=0), top_cell)
    # Tight: at most one cell, or the padding (a few ulps: many cells far from the origin), more.
    loose_first = torch.minimum(
        torch.floor((clip_lo - slack - sub_lo[entry_sub]) / sw[entry_sub]).long().clamp(min=0),
        top_cell,
    )
    loose_last = torch.minimum(
        torch.floor((clip_hi + slack - sub_lo[entry_sub]) / sw[entry_sub]).long().clamp(min=0),
        top_cell,
    )
    assert (
        (e_lo <= box_first)
        & (e_hi >= box_last)
        & (e_lo >= loose_first - 1)
        & (e_hi <= loose_last + 1)
    ).all(), (
        f"{what}: sub_tri_cell_lo/hi must be each entry's box of sub cells (the cells its "
        f"bounds overlap inside the sub-grid, no more than padding needs)"
    )
    local = entry_sub_cell - base[entry_sub]
    rx, ry = sres[entry_sub, 0], sres[entry_sub, 1]
    q = torch.stack((local % rx, (local // rx) % ry, local // (rx * ry)), 1)
    assert ((e_lo <= q) & (q <= e_hi)).all(), (
        f"{what}: an entry of a sub cell's list lies outside its own sub_tri_cell_lo..hi box"
    )
    pairs = (e_hi - e_lo + 1).prod(1)
    per = {}
    for sg, t, p in zip(entry_sub.tolist(), s_tris.tolist(), pairs.tolist()):
        per[(sg, t)] = per.get((sg, t), 0) + 1
        assert per[(sg, t)] <= p, f"{what}: a triangle listed twice in one sub cell"
    counts = torch.zeros(s, dtype=torch.int64)
    for sg, _ in per:
        counts[sg] += 1
    cells = sres.prod(1).double()
    ok = (cells <= density * counts * 2.5 + 8) & (
        (cells >= density * counts / 2.5) | (density * counts < 8)
    )
    if not ok.all():
        i = int((~ok).nonzero()[0, 0])
        raise AssertionError(
            f"{what}: sub-grid {i} holds {int(counts[i])} triangles in "
            f"{sres[i].tolist()} cells: expected about density x n = "
            f"{density * int(counts[i]):g} (the heuristic of grid_resolution)"
        )


def two_level_of(impl, mesh: Mesh, *args, **kwargs) -> dict:
    """The lab's ``build_two_level_grid`` with the top grid built by this module's
    ``uniform_grid`` in place of the lab's ``build_grid`` (task 1), so that a mistake in
    the uniform grid does not cost the two-level grid's points."""
    grid, _ = impl.probe(
        with_given, {"build_grid": "uniform_grid"}, "build_two_level_grid", mesh, *args, **kwargs
    )
    return grid


@pytest.mark.task(6)
@pytest.mark.points(1)
def test_two_level_build(impl, device):
    # A cell gets a sub-grid iff it holds *more* than min_triangles small triangles: with
    # min_triangles at the most any cell holds, none does.
    soup = on(scene("soup"), device)
    g = two_level_of(impl, soup)
    c_lo, c_hi, big = (g[k].cpu() for k in ("tri_cell_lo", "tri_cell_hi", "big"))
    res = g["resolution"].cpu()
    n_small = torch.zeros(int(res.prod()), dtype=torch.int64)
    for t in (~big).nonzero()[:, 0].tolist():
        x, y, z = (torch.arange(int(c_lo[t, a]), int(c_hi[t, a]) + 1) for a in range(3))
        zz, yy, xx = torch.meshgrid(z, y, x, indexing="ij")
        n_small[(xx + res[0] * (yy + res[1] * zz)).reshape(-1)] += 1
    most = int(n_small.max())
    assert most > 0, "test set-up: some small triangles wanted"
    g = two_level_of(impl, soup, 1 / 16, 2.0, most)
    assert int((g["sub_of"] >= 0).sum()) == 0, (
        f"build_two_level_grid(soup, min_triangles={most}): "
        f"{int((g['sub_of'] >= 0).sum())} top cells got a sub-grid, but none holds more than "
        f"{most} small triangles: a cell gets one iff it holds MORE than min_triangles"
    )
    check_two_level(g, soup, f"build_two_level_grid(soup, min_triangles={most})", 2.0, most)
    for name in ("teapot", "soup", "shards", "far", "single", "coincident"):
        mesh = on(scene(name), device)
        g = two_level_of(impl, mesh)
        check_two_level(g, mesh, f"build_two_level_grid({name})", 2.0)
    # The teapot sits in crowded top cells: their sub-grids must hold (nearly) all of it, in
    # boxes about its size, not the stadium's.
    mesh = on(scene("teapot"), device)
    g = two_level_of(impl, mesh, top_density=1 / 16, density=2.0, min_triangles=16)
    in_sub = torch.unique(g["sub_triangles"].cpu())
    teapot = int((in_sub < 968).sum())
    assert teapot >= 0.95 * 968, (
        f"build_two_level_grid(teapot in a stadium): only {teapot} of the teapot's 968 "
        f"triangles are in sub-grids: its top cells are crowded and need them"
    )
    extent = (g["sub_hi"] - g["sub_lo"]).cpu().double().amax(1)
    assert float(extent.max()) <= 1.0, (
        f"build_two_level_grid(teapot in a stadium): a sub-grid {float(extent.max()):.3g} "
        f"across, for a teapot 0.2 across: bound each sub-grid by its *small* triangles "
        f"(the stadium's floor runs under the teapot: keep it out as a big triangle)"
    )
    g8 = two_level_of(impl, mesh, density=8.0)
    check_two_level(g8, mesh, "build_two_level_grid(teapot, density=8)", 8.0)
    # Stretched: a top grid of three different resolutions, so a cell's coordinates from its
    # index x + rx (y + ry z) go wrong if two of them are confused.
    stretched = on(
        Mesh(scene("teapot").vertices * torch.tensor([3.0, 1.0, 0.5]), scene("teapot").faces),
        device,
    )
    g = two_level_of(impl, stretched)
    assert len(set(g["resolution"].tolist())) == 3 and int((g["sub_of"] >= 0).sum()) > 0, (
        f"test set-up: resolution {g['resolution'].tolist()} and some sub-grids wanted"
    )
    check_two_level(g, stretched, "build_two_level_grid(teapot stretched 3 x 1 x 0.5)", 2.0)
    expect_error(
        "min_triangles", impl.build_two_level_grid, mesh, 1 / 16, 2.0, -1, case="min_triangles=-1"
    )
    expect_error("density", impl.build_two_level_grid, mesh, 1 / 16, 0.0, case="density=0")
    expect_error("top_density", impl.build_two_level_grid, mesh, -1.0, case="top_density=-1")


@pytest.mark.task(6)
@pytest.mark.points(2)
def test_two_level_matches_brute_force(impl, device):
    # Two-level grids built here (fixed resolutions), so the traversal is graded on its own.
    cases = [
        ("teapot", (3, 3, 3), (6, 5, 4), 6),
        ("shards", (2, 3, 2), (5, 4, 3), 6),
        ("soup", (3, 3, 3), (4, 4, 4), 4),
        ("ico", (2, 2, 2), (5, 5, 5), 8),
        ("far", (2, 2, 3), (4, 3, 5), 4),
        ("coincident", (2, 2, 2), (3, 3, 3), 4),
        ("single", (2, 2, 2), (3, 3, 3), 0),
    ]
    for name, top, sub, min_tri in cases:
        mesh = on(scene(name), device)
        g = simple_two_level(mesh, top, sub, min_tri)
        if name == "teapot":
            rays = cat_rays(teapot_rays(200, 151), axis_rays(mesh, 152, 4))
        else:
            rays = cat_rays(rays_around(mesh, 160, 153), axis_rays(mesh, 154, 4), bad_rays())
        rays = rays.to(device)
        ref = reference(rays.to("cpu"), on(mesh, "cpu"))
        compare(
            impl.two_level_closest_hit(rays, mesh, g, mt64),
            rays,
            mesh,
            f"two_level_closest_hit({name}, top {top}, sub-grids {sub})",
            counters=GRID2_COUNTERS,
            ref=ref,
        )
        # A ray that walks alone (the other one misses the grid): each loop runs until its
        # last ray is done, one ray included.
        hits = (ref[1] >= 0).nonzero()[:, 0]
        if len(hits):
            i = int(hits[len(hits) // 2])
            lone = cat_rays(rays[i : i + 1], bad_rays(1)[2:3].to(device))
            compare(
                impl.two_level_closest_hit(lone, mesh, g, mt64),
                lone,
                mesh,
                f"two_level_closest_hit({name}, top {top}, sub-grids {sub}: ray {i} alone, "
                f"with a ray that misses the grid)",
                counters=GRID2_COUNTERS,
            )
    # Rays along the top cells' boundary planes and through their corners.
    mesh = on(scene("shards"), device)
    g = simple_two_level(mesh, (3, 3, 3), (4, 4, 4), 4)
    lo, hi = g["lo"].cpu().double(), g["hi"].cpu().double()
    w = (hi - lo) / 3
    gen = generator(155)
    p = lo + (hi - lo) * torch.rand(60, 3, generator=gen, dtype=F64)
    axis = torch.arange(60) % 3
    p[torch.arange(60), axis] = (lo + w)[axis]  # in a boundary plane between top cells
    d = torch.randn(60, 3, generator=gen, dtype=F64)
    d[torch.arange(60), axis] = torch.where(torch.arange(60) % 2 == 0, 0.0, -0.0).double()
    corner = lo + w * torch.tensor([1.0, 2.0, 1.0], dtype=F64)  # a corner of 8 top cells
    through = corner - torch.randn(20, 3, generator=gen, dtype=F64).abs() * 2
    rays = cat_rays(
        Rays.create(p.float(), d.float()), Rays.create(through.float(), (corner - through).float())
    ).to(device)
    compare(
        impl.two_level_closest_hit(rays, mesh, g, mt64),
        rays,
        mesh,
        "two_level_closest_hit (rays in top-cell boundary planes and through corners)",
        counters=GRID2_COUNTERS,
    )
    # The lab's own build, far from the origin and on the teapot.
    for name in ("far", "teapot"):
        mesh = on(scene(name), device)
        rays = (
            teapot_rays(160, 156)
            if name == "teapot"
            else cat_rays(rays_around(mesh, 120, 157), axis_rays(mesh, 158, 4))
        )
        rays = rays.to(device)
        compare(
            impl.two_level_closest_hit(rays, mesh, two_level_of(impl, mesh), mt64),
            rays,
            mesh,
            f"two_level_closest_hit on build_two_level_grid({name})",
            counters=GRID2_COUNTERS,
        )


@pytest.mark.task(6)
@pytest.mark.points(1)
def test_two_level_mailboxing_and_work(impl, device):
    # Mailboxing changes the tests, never the walk or the hits.
    mesh = on(scene("shards"), device)
    g = simple_two_level(mesh, (3, 3, 3), (6, 6, 6), 4)
    rays = rays_around(mesh, 200, 161, clip=0.0).to(device)
    ref = reference(rays.to("cpu"), on(mesh, "cpu"))
    with_box = compare(
        impl.two_level_closest_hit(rays, mesh, g, mt64, mailbox=True),
        rays,
        mesh,
        "two_level_closest_hit(mailbox=True)",
        GRID2_COUNTERS,
        ref,
    )
    without = compare(
        impl.two_level_closest_hit(rays, mesh, g, mt64, mailbox=False),
        rays,
        mesh,
        "two_level_closest_hit(mailbox=False)",
        GRID2_COUNTERS,
        ref,
    )
    assert_equal(
        with_box["steps"],
        without["steps"],
        name="two_level_closest_hit: steps with "
        "and without the mailbox (it must not change the walk)",
        where="ray",
    )
    assert_equal(
        with_box["tests"] + with_box["skipped"],
        without["tests"],
        name="two_level_closest_hit: tests + skipped with the mailbox == tests without it",
        where="ray",
    )
    assert int(without["tests"].sum()) > 1.3 * int(with_box["tests"].sum()), (
        "two_level_closest_hit(mailbox=True): big triangles span top cells and sub cells; "
        f"the mailbox should avoid their repeats: {int(with_box['tests'].sum())} tests with "
        f"it, {int(without['tests'].sum())} without"
    )
    # The point of it all: rays at the teapot test a few triangles, not the whole teapot.
    mesh = on(scene("teapot"), device)
    rays = teapot_rays(160, 162).to(device)
    at_teapot = torch.arange(len(rays)) % 4 != 3
    count = compare(
        impl.two_level_closest_hit(rays, mesh, two_level_of(impl, mesh), mt64),
        rays,
        mesh,
        "two_level_closest_hit(build_two_level_grid(teapot in a stadium))",
        GRID2_COUNTERS,
    )
    mean = count["tests"][at_teapot].double().mean().item()
    steps = count["steps"][at_teapot].double().mean().item()
    assert mean <= 0.05 * mesh.num_faces, (
        f"two-level grid: rays at the teapot run {mean:.1f} triangle tests on average "
        f"({mean / mesh.num_faces:.1%} of the scene): the teapot's sub-grids should give it "
        f"cells its own size (a uniform grid tests most of it)"
    )
    assert steps <= 100, f"two-level grid: {steps:.0f} cells per ray at the teapot: too many"


# ---------------------------------------------------------------------------------------
# Task 7: sync-free BVH traversal (its own float32 Möller–Trumbore: rounding may decide
# a ray that grazes an edge, or runs nearly parallel to a triangle, differently)


def grazed(rays: Rays, mesh: Mesh, i: torch.Tensor, tri: torch.Tensor, margin=1e-5):
    """(len(i),) bool: ray i[j] passes within ``margin`` (barycentric, relative) of triangle
    tri[j]'s edges, or nearly parallel to its plane: where float32 may decide either way."""
    corners = mesh.triangles().cpu().double()[tri.clamp(min=0)]
    o, d = rays.origins[i].double(), rays.directions[i].double()
    e1, e2 = corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]
    p = torch.linalg.cross(d, e2, dim=-1)
    det = (e1 * p).sum(-1)
    s = o - corners[:, 0]
    u = (s * p).sum(-1) / det
    v = (d * torch.linalg.cross(s, e1, dim=-1)).sum(-1) / det
    edge = torch.stack((u, v, 1 - u - v), 1).abs().amin(1) <= margin
    flat = det.abs() <= 1e-4 * d.norm(dim=1) * e1.norm(dim=1) * e2.norm(dim=1)
    return (edge | flat | ~torch.isfinite(det)) & (tri >= 0)


def compare_fast(result, rays: Rays, mesh: Mesh, what: str, ref=None, any_hit=False):
    """Like ``compare``, for a kernel that rounds on its own: a ray may differ from brute
    force only where it grazes an edge of (or runs parallel to) the triangles involved.
    With ``any_hit`` a ray must hit iff brute force does, and its hit must be real."""
    hits, count = check_result(result, len(rays), rays.dtype, rays.device, what)
    rays, mesh = rays.to("cpu"), on(mesh, "cpu")
    ref_t, ref_i, _, _ = reference(rays, mesh) if ref is None else ref
    t, tri = hits.t.cpu(), hits.triangle.cpu()
    # float32 rounds t by about eps * (coordinates) / |d|: an absolute part, and a relative one.
    reach = (
        rays.origins.abs().amax(1).double() + float(mesh.vertices.abs().amax())
    ) / rays.directions.double().norm(dim=1)
    slack = 1e-6 * reach.nan_to_num(0.0, posinf=0.0)
    if any_hit:
        differ = (tri >= 0) != (ref_i >= 0)
    else:
        tol = 1e-5 * ref_t.abs().nan_to_num(posinf=0.0) + slack
        same_t = ((t - ref_t).abs() <= tol) | ((tri < 0) & (ref_i < 0))
        differ = (tri != ref_i) & ~same_t
    idx = differ.nonzero()[:, 0]
    excused = grazed(rays, mesh, idx, ref_i[idx]) | grazed(rays, mesh, idx, tri[idx])
    bad = idx[~excused]
    if len(bad):
        i = int(bad[0])
        raise AssertionError(
            f"{what}: {len(bad)} of {len(rays)} rays disagree with brute force (not at an edge). "
            f"First: ray {i} ({describe(rays, i)}): brute force: triangle {int(ref_i[i])} at "
            f"t={ref_t[i].item():.9g}; you: triangle {int(tri[i])} at t={t[i].item():.9g}"
        )
    assert len(idx) <= max(2, 0.02 * len(rays)), (
        f"{what}: {len(idx)} of {len(rays)} rays disagree with brute force (edges): too many"
    )
    # A reported hit must be real: that triangle, at that t, inside [t_min, t_max].
    hit = (tri >= 0).nonzero()[:, 0]
    corners = mesh.triangles()[tri[hit]]
    t_check, _, _ = mt64(
        rays.origins[hit],
        rays.directions[hit],
        corners[:, 0],
        corners[:, 1],
        corners[:, 2],
        rays.t_min[hit],
        rays.t_max[hit],
    )
    fake = ~((t_check - t[hit]).abs() <= 1e-5 * t[hit].abs() + slack[hit]) & ~grazed(
        rays, mesh, hit, tri[hit]
    )
    if fake.any():
        i = int(hit[fake][0])
        raise AssertionError(
            f"{what}: ray {i} reports triangle {int(tri[i])} at "
            f"t={t[i].item():.9g}, but the ray hits it at "
            f"t={t_check[fake][0].item():.9g} (inf: not at all in [t_min, t_max])"
        )
    if (count["tests"][tri >= 0] < 1).any():
        raise AssertionError(f"{what}: rays with a hit but counters['tests'] == 0")
    if (count["steps"][count["tests"] > 0] < 1).any():
        raise AssertionError(f"{what}: rays with triangle tests but counters['steps'] == 0")
    return {k: v.cpu() for k, v in count.items()}


def shadow_rays(mesh: Mesh, seed: int, n: int = 160) -> Rays:
    """Rays from points on the surface (t_min = 1e-4 keeps them off their own triangle)
    towards a point light above the scene, t_max just short of it."""
    g = generator(seed)
    corners = mesh.triangles().cpu().double()
    pick = torch.randint(0, len(corners), (n,), generator=g)
    w = torch.rand(n, 3, generator=g, dtype=F64)
    w = w / w.sum(1, keepdim=True)
    points = (corners[pick] * w[:, :, None]).sum(1)
    lo, hi = bounds(mesh)
    light = (lo + hi) / 2 + torch.tensor([0.3, 1.0, 0.2], dtype=F64) * (hi - lo).norm()
    return Rays.create(points.float(), (light - points).float(), 1e-4, 1 - 1e-4)


@pytest.mark.task(7)
@pytest.mark.points(2)
def test_fast_bvh_matches_brute_force(impl, device):
    for name, leaf_size, k in (
        ("soup", 1, 1),
        ("shards", 3, 4),
        ("ico", 2, 8),
        ("teapot", 4, 3),
        ("far", 2, 16),
        ("coincident", 3, 2),
        ("single", 1, 1),
        ("slabs", 2, 64),
    ):
        mesh = on(scene(name), device)
        bvh = median_bvh(mesh, leaf_size)
        if name == "teapot":
            rays = cat_rays(teapot_rays(200, 171), axis_rays(mesh, 172, 4))
        else:
            rays = cat_rays(rays_around(mesh, 160, 173), axis_rays(mesh, 174, 4), bad_rays())
        rays = rays.to(device)
        count = compare_fast(
            impl.bvh_closest_hit_fast(rays, mesh, bvh, check_every=k),
            rays,
            mesh,
            f"bvh_closest_hit_fast({name}, median BVH, leaf_size={leaf_size}, check_every={k})",
        )
        if name == "ico":
            mean = count["tests"].double().mean().item()
            assert mean <= 6.0, (
                f"bvh_closest_hit_fast: {mean:.2f} triangle tests per ray into a closed "
                f"icosphere; visit the near child first and cull nodes beyond the closest hit"
            )
            nodes = count["steps"].double().mean().item()
            assert nodes <= 45.0, (
                f"bvh_closest_hit_fast: {nodes:.1f} node visits per ray into a closed icosphere "
                f"(an ordered walk needs about 30): skip the subtree of a missed box, and cull "
                f"boxes beyond the closest hit"
            )
    # Coincident triangles: the tie goes to the lowest index.
    mesh = on(scene("coincident"), device)
    rays = Rays.create(
        torch.tensor([[0.4, 0.4, -1.0], [0.45, 0.4, 2.0]]),
        torch.tensor([[0.0, 0.0, 1.0], [-0.0, 0.0, -1.0]]),
    ).to(device)
    hits, _ = impl.bvh_closest_hit_fast(rays, mesh, median_bvh(mesh, 3))
    assert hits.triangle.tolist() == [0, 0], (
        f"bvh_closest_hit_fast: 40 coincident triangles hit at the same t: the lowest index "
        f"(0) must win, got {hits.triangle.tolist()}"
    )
    # float64 in, float64 out.
    m64 = Mesh(
        vertices=scene("shards").vertices.double().to(device),
        faces=scene("shards").faces.to(device),
    )
    rays = rays_around(m64, 80, 175, dtype=F64).to(device)
    compare_fast(
        impl.bvh_closest_hit_fast(rays, m64, median_bvh(m64, 3)),
        rays,
        m64,
        "bvh_closest_hit_fast (float64)",
    )


@pytest.mark.task(7)
@pytest.mark.points(1)
def test_fast_bvh_any_hit_and_knobs(impl, device):
    for name in ("ico", "shards", "teapot"):
        mesh = on(scene(name), device)
        bvh = median_bvh(mesh, 2)
        rays = cat_rays(shadow_rays(mesh, 181), rays_around(mesh, 80, 182)).to(device)
        ref = reference(rays.to("cpu"), on(mesh, "cpu"))
        any_count = compare_fast(
            impl.bvh_closest_hit_fast(rays, mesh, bvh, any_hit=True),
            rays,
            mesh,
            f"bvh_closest_hit_fast({name}, any_hit=True)",
            ref=ref,
            any_hit=True,
        )
        closest = compare_fast(
            impl.bvh_closest_hit_fast(rays, mesh, bvh),
            rays,
            mesh,
            f"bvh_closest_hit_fast({name})",
            ref=ref,
        )
        assert int(any_count["steps"].sum()) < int(closest["steps"].sum()), (
            f"bvh_closest_hit_fast({name}, any_hit=True): {int(any_count['steps'].sum())} node "
            f"visits, as many as the closest-hit search ({int(closest['steps'].sum())}): a "
            f"shadow ray is done at its first hit"
        )
    # The knobs change when the host looks, never what the rays find or do.
    mesh = on(scene("soup"), device)
    bvh = median_bvh(mesh, 3)
    rays = rays_around(mesh, 150, 183).to(device)
    base_hits, base = impl.bvh_closest_hit_fast(rays, mesh, bvh, check_every=1)
    for k, compact in ((2, True), (7, False), (1000, True)):
        hits, count = impl.bvh_closest_hit_fast(rays, mesh, bvh, check_every=k, compact=compact)
        for key in ("steps", "tests"):
            assert_equal(
                count[key].cpu(),
                base[key].cpu(),
                name=f"bvh_closest_hit_fast("
                f"check_every={k}, compact={compact}): counters[{key!r}] (the same as "
                f"check_every=1)",
                where="ray",
            )
        assert_equal(
            hits.triangle.cpu(),
            base_hits.triangle.cpu(),
            name=f"bvh_closest_hit_fast(check_every={k}, compact={compact}): triangles",
            where="ray",
        )
    # A tree packed once and reused gives the same walk; one packed for other octants is
    # refused, naming the argument.
    hits, count = impl.bvh_closest_hit_fast(rays, mesh, bvh, walk=pack_bvh(bvh, mesh))
    assert_equal(
        count["steps"].cpu(),
        base["steps"].cpu(),
        name="bvh_closest_hit_fast(walk="
        "pack_bvh(bvh, mesh)): counters['steps'] (the same as packing inside)",
        where="ray",
    )
    assert_equal(
        hits.triangle.cpu(),
        base_hits.triangle.cpu(),
        name="bvh_closest_hit_fast(walk=pack_bvh(bvh, mesh)): triangles",
        where="ray",
    )
    other = int(ray_octants(rays.directions[:1].cpu())[0]) ^ 7
    expect_error(
        "walk",
        impl.bvh_closest_hit_fast,
        rays,
        mesh,
        bvh,
        walk=pack_bvh(bvh, mesh, octants=[other]),
        case="a walk without the rays' octants",
    )
    expect_error(
        "walk",
        impl.bvh_closest_hit_fast,
        rays,
        mesh,
        bvh,
        walk=bvh,
        case="a BVH dict passed as the walk",
    )
    expect_error(
        "fuse_steps", impl.bvh_closest_hit_fast, rays, mesh, bvh, fuse_steps=0, case="fuse_steps=0"
    )
    expect_error(
        "check_every", impl.bvh_closest_hit_fast, rays, mesh, bvh, False, 0, case="check_every=0"
    )
    expect_error(
        "compile",
        impl.bvh_closest_hit_fast,
        rays,
        mesh,
        bvh,
        False,
        8,
        "fast",
        case="compile='fast'",
    )
    expect_error(
        "bvh",
        impl.bvh_closest_hit_fast,
        rays,
        mesh,
        uniform_grid(mesh),
        case="a grid passed as the bvh",
    )


def corner_and_far_rays(mesh: Mesh, quick: int, far: int, seed: int) -> Rays:
    """``quick`` rays starting in the corners of the bounds of ``mesh`` (a sphere), outside
    it, aimed away: they enter the root's box and leave the tree within about 10 steps; then
    ``far`` rays from a sphere of 4x the bounds aimed into the mesh (about 30 steps)."""
    g = generator(seed)
    lo, hi = (b.float() for b in bounds(mesh))
    centre, half = (lo + hi) / 2, (hi - lo) / 2
    sign = 2.0 * torch.randint(0, 2, (quick, 3), generator=g) - 1
    origins = centre + sign * half * (0.97 + 0.02 * torch.rand(quick, 3, generator=g))
    directions = sign * (0.5 + torch.rand(quick, 3, generator=g))
    u = torch.nn.functional.normalize(torch.randn(far, 3, generator=g), dim=1)
    start = centre + 4 * half * u
    aim = centre + half * (0.5 * torch.randn(far, 3, generator=g)).clamp(-1, 1)
    return Rays.create(torch.cat((origins, start)), torch.cat((directions, aim - start)))


@pytest.mark.task(7)
@pytest.mark.points(0.5)
@pytest.mark.gpu
def test_fast_bvh_cached_graphs_compact(impl):
    # CUDA only: compile="reduce-overhead" with a walk packed once replays cached CUDA
    # graphs, whose rays are padded with finished ones to a graph size. 72,000 rays (a graph
    # of 73,728), 90% of them done within the first look (the reference's steps: at most 9
    # for a corner ray; over 16 for 6,994 of the far ones): the walk compacts, and only the
    # rays still running (never the padding) must go on.
    mesh = on(scene("ico"), "cuda")
    bvh = median_bvh(mesh, 2)
    walk = pack_bvh(bvh, mesh)
    rays = corner_and_far_rays(mesh, 64_800, 7_200, 191).to("cuda")
    what = (
        'bvh_closest_hit_fast(compile="reduce-overhead", walk=pack_bvh(...), check_every=16) '
        "of 72,000 rays, 64,800 of them done within 16 steps"
    )
    runs = [
        check_result(
            impl.bvh_closest_hit_fast(
                rays, mesh, bvh, walk=walk, check_every=16, compile="reduce-overhead"
            ),
            len(rays),
            F32,
            rays.device,
            f"{what}, call {call}",
        )
        for call in (1, 2)  # the second replays the graphs the first captured
    ]
    eager, eager_count = check_result(
        impl.bvh_closest_hit_fast(rays, mesh, bvh, walk=walk, check_every=16),
        len(rays),
        F32,
        rays.device,
        "bvh_closest_hit_fast(walk=..., check_every=16), eager",
    )
    for call, (hits, count) in enumerate(runs, 1):
        # Fused arithmetic may decide a ray grazing an edge the other way: 1 in 1000.
        same = (hits.triangle == eager.triangle).cpu()
        assert int((~same).sum()) <= len(rays) // 1000, (
            f"{what}, call {call}: {int((~same).sum())} of {len(rays)} rays hit another "
            f"triangle than the eager walk (first: ray {int((~same).nonzero()[0, 0])}); at a "
            f"compaction keep only the rays still running, never the padding rows"
        )
        for key in ("steps", "tests"):
            assert_equal(
                count[key].cpu()[same],
                eager_count[key].cpu()[same],
                where="ray",
                name=f"{what}, call {call}: counters[{key!r}] against the eager walk",
            )


def test_pack_bvh_lays_out_each_octant_near_first():
    """The given layout of the sync-free walk: per octant, a depth-first array of the same
    nodes with skip links, the child nearer along the split axis first; also for a BVH whose
    nodes are not numbered depth first."""
    mesh = scene("teapot")
    bvh = median_bvh(mesh, 3)
    m = len(bvh["left"])
    perm = torch.cat(
        (torch.zeros(1, dtype=torch.int64), 1 + torch.randperm(m - 1, generator=generator(190)))
    )  # the root stays node 0
    new_id = torch.empty_like(perm).scatter_(0, perm, torch.arange(m))
    shuffled = dict(
        bvh,
        lo=bvh["lo"][perm],
        hi=bvh["hi"][perm],
        first=bvh["first"][perm],
        count=bvh["count"][perm],
        **{
            k: torch.where(bvh[k][perm] >= 0, new_id[bvh[k][perm].clamp(min=0)], -1)
            for k in ("left", "right")
        },
    )
    for tree in (bvh, shuffled):
        walk = pack_bvh(tree, mesh)
        assert walk["nodes"] == m and walk["base"].tolist() == [o * m for o in range(8)]
        boxes = walk["boxes"].view(8, m, 6)
        skip, first, count = walk["links"].long().view(8, m, 3).unbind(2)
        key = torch.cat((tree["lo"], tree["hi"]), 1)
        for o in range(8):
            # The same nodes (as boxes), every row's subtree ending where its skip link says.
            assert torch.equal(torch.sort(boxes[o], 0).values, torch.sort(key, 0).values)
            inner = (count[o] == 0).nonzero()[:, 0]
            a, b = inner + 1, skip[o, inner + 1]
            assert bool((skip[o, b] == skip[o, inner]).all()) and bool((b < skip[o, inner]).all())
            leaf = count[o] > 0
            assert torch.equal(skip[o, leaf], leaf.nonzero()[:, 0] + 1)
            # The leaves' slot ranges tile the slots 0 .. F - 1 (each triangle in one leaf).
            starts, ends = first[o, leaf], first[o, leaf] + count[o, leaf]
            order = torch.argsort(starts)
            assert int(starts[order[0]]) == 0 and int(ends[order[-1]]) == mesh.num_faces
            assert torch.equal(starts[order[1:]], ends[order[:-1]])
            # Near first: along the axis the two centres differ most, the first child's centre
            # is lower for rays going up that axis, higher for rays going down.
            ca = boxes[o, a, :3] + boxes[o, a, 3:]
            cb = boxes[o, b, :3] + boxes[o, b, 3:]
            axis = (cb - ca).abs().argmax(1)
            gap = (cb - ca).gather(1, axis[:, None])[:, 0]
            down = torch.tensor([(o >> i) & 1 for i in range(3)], dtype=torch.bool)[axis]
            assert bool(torch.where(down, gap <= 0, gap >= 0).all()), f"octant {o}: far child first"
    walk = pack_bvh(bvh, mesh, octants=[5, 2])
    assert walk["base"].tolist() == [-1, -1, 0, -1, -1, m, -1, -1]
    assert ray_octants(torch.tensor([[1.0, -0.0, 2.0], [-1.0, 0.0, -3.0]])).tolist() == [2, 5]
    expect_error("octants", pack_bvh, bvh, mesh, octants=[8], case="octant 8")


# ---------------------------------------------------------------------------------------
# Task 5 (continued): closest_hit(structure="auto") builds what the chooser picks, only that


def builds_of_auto(lab, rays, mesh, intersect):
    """Run ``closest_hit(rays, mesh, "auto", intersect)`` next to the lab with its builders
    and walks given (this module's, recorded); returns ``(builder names called, hit
    triangles)``."""
    (hits, _), calls = with_given(
        lab, {**GIVEN_BUILDERS, **GIVEN_WALKS}, "closest_hit", rays, mesh, "auto", intersect
    )
    return [name for name, _ in calls if name in GIVEN_BUILDERS], hits.triangle.cpu().tolist()


@pytest.mark.task(5)
@pytest.mark.points(1)
def test_auto_builds_only_its_choice(impl, device):
    want_builder = {
        ("grid", None): "build_grid",
        ("grid2", None): "build_two_level_grid",
        ("bvh", "sah"): "build_sah_bvh",
        ("bvh", "lbvh"): "build_lbvh",
        ("kd", None): "build_kdtree",
    }
    seen = set()
    for name, n_rays in (("ico", 400), ("teapot", 200), ("soup", 300), ("soup", 1000)):
        mesh = on(scene(name), device)
        kind, knobs, reason = choose_structure(mesh, n_rays)
        assert kind in STRUCTURES and isinstance(knobs, dict) and len(reason) > 20
        seen.add(kind)
        # The chooser sees len(rays) as its hint.
        rays = teapot_rays(n_rays, 191) if name == "teapot" else rays_around(mesh, n_rays, 192)
        rays = rays.to(device)
        called, triangles = impl.probe(builds_of_auto, rays, mesh, mt64)
        builder = want_builder[(kind, knobs.get("method", "sah") if kind == "bvh" else None)]
        assert called == [builder], (
            f"closest_hit(structure='auto') on {name} with {len(rays)} rays: the chooser picks "
            f"{kind} {knobs} ({reason}); expected exactly one call of {builder}, got {called}: "
            f"build only what the chooser picked, and nothing it will not use"
        )
        ref_i = reference(rays.to("cpu"), on(mesh, "cpu"))[1]
        assert triangles == ref_i.tolist(), (
            f"closest_hit(structure='auto') on {name}: hits differ from brute force"
        )
    assert {"grid", "grid2", "bvh"} <= seen, f"the chooser's picks: {seen}"
    assert choose_structure(on(scene("soup"), device), 300)[1] == {"method": "lbvh"}
    assert choose_structure(on(scene("soup"), device), 1000)[1] == {"method": "sah"}
    # The chooser's judgement on the lecture's cases.
    assert choose_structure(on(scene("teapot"), device))[0] == "bvh", (
        "choose_structure: the teapot in a stadium, many rays: an SAH BVH"
    )
    assert choose_structure(on(scene("ico"), device))[0] == "grid", (
        "choose_structure: a small, evenly tessellated sphere: a uniform grid"
    )
    expect_error(
        "structure",
        impl.closest_hit,
        rays_around(on(scene("soup"), device), 4, 193).to(device),
        on(scene("soup"), device),
        "octree",
        mt64,
        case="structure='octree'",
    )


def test_builders_reject_nonfinite_vertices(impl, device):
    """Ungraded (the check is the provided ``check_mesh(mesh, finite=True)``): every builder
    rejects a mesh with a NaN or inf vertex with the same ValueError naming ``mesh``."""
    mesh = on(scene("ico"), device)
    builders = ("build_grid", "build_lbvh", "build_sah_bvh", "build_kdtree", "build_two_level_grid")
    for bad in (math.nan, math.inf, -math.inf):
        vertices = mesh.vertices.clone()
        vertices[3, 1] = bad
        broken = Mesh(vertices=vertices, faces=mesh.faces)
        messages = set()
        for name in builders:
            try:
                getattr(impl, name)(broken)
            except ValueError as error:
                messages.add(str(error).splitlines()[0])
                continue
            raise AssertionError(
                f"{name} accepted a mesh with a vertex coordinate {bad}: "
                f"expected ValueError naming 'mesh' (keep the provided "
                f"check_mesh(mesh, finite=True))"
            )
        assert len(messages) == 1 and next(iter(messages)).startswith("mesh: "), (
            f"builders given a vertex coordinate {bad}: expected one and the same error "
            f"naming 'mesh' from all of {', '.join(builders)}, got {sorted(messages)}"
        )


# ---------------------------------------------------------------------------------------
# Rays aimed exactly at vertices and edge midpoints: every walk at its extremes. Such a ray
# hits several triangles at the same true t; their computed t differ by rounding, and the
# planes of cells, boxes and splits through the vertex are crossed at a t that rounds on its
# own. Each walk must still return brute force's triangle (the smallest computed t, ties to
# the lowest index): a structure may visit more, never less.

VERTEX_SCENES = ("ico", "suzanne", "soup", "terrain")
VERTEX_SHIFTS = (0.0, 1e5)  # near the origin, and far from it (float32 spacing 1/128)
LATTICE = 6  # the terrain's quads per side: its vertices lie on integer x and y


def mt_rows(origins, directions, v0, v1, v2, t_min=0.0, t_max=INF):
    """Brute force's kernel for ``bvh_closest_hit_fast``: the provided
    ``moller_trumbore_rows`` (the mesh's dtype, edges ``v1 - v0``, ``v2 - v0``), broadcast
    like Lab 1's kernels, ``(t, u, v)`` with ``t = inf`` and u = v = 0 on a miss."""
    o, d, a, b, c = torch.broadcast_tensors(origins, directions, v0, v1, v2)
    t_min = torch.as_tensor(t_min, dtype=o.dtype, device=o.device).expand(o.shape[:-1])
    t_max = torch.as_tensor(t_max, dtype=o.dtype, device=o.device).expand(o.shape[:-1])
    t, u, v, hit = moller_trumbore_rows(o, d, a, b - a, c - a, t_min, t_max)
    return torch.where(hit, t, INF), torch.where(hit, u, 0.0), torch.where(hit, v, 0.0)


@functools.cache
def vertex_scene(name: str, shift: float) -> Mesh:
    """The scenes aimed at (float32, CPU), moved by ``shift`` on every axis: a small
    icosphere, Suzanne, a random soup, and a terrain over an integer lattice (the planes of
    an aligned grid, and of boxes and splits at triangle bounds, pass through its vertices)."""
    if name == "terrain":
        g = generator(61)
        xy = (
            torch.stack(
                torch.meshgrid(
                    torch.arange(LATTICE + 1.0), torch.arange(LATTICE + 1.0), indexing="ij"
                ),
                -1,
            )
            .reshape(-1, 2)
            .to(F64)
        )
        z = torch.rand(len(xy), 1, generator=g, dtype=F64).float().double()
        vertices = torch.cat((xy, z), 1)
        q = torch.arange(LATTICE)
        i, j = (x.reshape(-1) for x in torch.meshgrid(q, q, indexing="ij"))
        a, b = i * (LATTICE + 1) + j, (i + 1) * (LATTICE + 1) + j
        faces = torch.cat((torch.stack((a, b, a + 1), 1), torch.stack((b, b + 1, a + 1), 1)))
    else:
        kwargs = {"ico": {"level": 1}, "soup": {"n": 60, "seed": 3}}.get(name, {})
        source = {"ico": "icosphere", "soup": "random_soup"}.get(name, name)
        m = load_scene(source, device="cpu", dtype=F64, **kwargs).mesh
        vertices, faces = m.vertices, m.faces
    return Mesh(vertices=(vertices.to(F64) + shift).float(), faces=faces)


@functools.cache
def _vertex_case(name: str, shift: float, device: str, kernel: str):
    """``(mesh, rays, (triangle, t))``: a ray at every vertex and every edge midpoint of the
    scene from random points around it (outside its bounds), and brute force's hits
    (computed on ``device``, as the walk's intersect is: the same bits)."""
    mesh = vertex_scene(name, shift)
    v = mesh.vertices.to(F64)
    edges = torch.sort(mesh.faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), dim=1).values
    edges = torch.unique(edges, dim=0)
    targets = torch.cat((v, (v[edges[:, 0]] + v[edges[:, 1]]) / 2))
    lo, hi = v.amin(0), v.amax(0)
    g = generator(62)
    out = torch.randn(len(targets), 3, generator=g, dtype=F64)
    origins = (lo + hi) / 2 + 0.75 * float((hi - lo).norm()) * out / out.norm(dim=1, keepdim=True)
    rays = Rays.create(origins.float(), (targets - origins).float()).to(device)
    mesh = on(mesh, device)
    fn = mt64 if kernel == "mt64" else mt_rows
    tri = mesh.triangles()
    t, _, _ = fn(
        rays.origins[:, None],
        rays.directions[:, None],
        tri[None, :, 0],
        tri[None, :, 1],
        tri[None, :, 2],
        rays.t_min[:, None],
        rays.t_max[:, None],
    )
    best = t.argmin(dim=1)  # the first of equal minima: the lowest index
    t_best = t.gather(1, best[:, None])[:, 0]
    return mesh, rays, (torch.where(t_best < INF, best, -1).cpu(), t_best.cpu())


def vertex_cases(device, kernel: str = "mt64"):
    """``(label, mesh, rays, reference)`` of every vertex scene, near and far."""
    for name, shift in itertools.product(VERTEX_SCENES, VERTEX_SHIFTS):
        mesh, rays, ref = _vertex_case(name, shift, str(device), kernel)
        yield f"{name}{f' moved by {shift:g}' if shift else ''}", mesh, rays, ref


def compare_at_vertices(result, rays: Rays, ref, what: str, counters=("steps", "tests")):
    """Every ray must report brute force's triangle, exactly (its t then follows: the same
    kernel on the same pair)."""
    hits, _ = check_result(result, len(rays), rays.dtype, rays.device, what, counters)
    tri, t = hits.triangle.cpu(), hits.t.cpu()
    ref_tri, ref_t = ref
    wrong = (tri != ref_tri).nonzero()[:, 0]
    if len(wrong):
        i = int(wrong[0])
        raise AssertionError(
            f"{what}: {len(wrong)} of {len(rays)} rays aimed exactly at a vertex or an edge "
            f"midpoint report another triangle than brute force. First: ray {i} "
            f"({describe(rays.to('cpu'), i)}): brute force: triangle {int(ref_tri[i])} at "
            f"t={ref_t[i].item():.9g}; you: triangle {int(tri[i])} at t={t[i].item():.9g}. "
            f"Such a ray hits every triangle around the point at the same t, give or take "
            f"rounding, and crosses the planes of cells, boxes and splits through it at a t "
            f"that rounds on its own: comparing the two without slack drops the triangle brute "
            f"force picks (the smallest t, ties to the lowest index). Keep a node or cell "
            f"entered up to reach(closest t), and end at a cell or leaf only if reach(closest "
            f"t) < its exit (reach: course.given.lab2_robust)."
        )


@pytest.mark.task(1)
@pytest.mark.points(0.5)
def test_grid_exact_at_vertices_and_edges(impl, device):
    for label, mesh, rays, ref in vertex_cases(device):
        grid = uniform_grid(mesh)
        compare_at_vertices(
            impl.grid_closest_hit(rays, mesh, grid, mt64),
            rays,
            ref,
            f"grid_closest_hit({label}, a grid built by the grader)",
            GRID2_COUNTERS,
        )
        if label.startswith("terrain"):
            # Cells on the lattice, unpadded: rays through cell corners, and triangles
            # listed only in the cell above the boundary their vertex lies on.
            grid = uniform_grid(mesh, (LATTICE, LATTICE, 1), pad=0.0)
            compare_at_vertices(
                impl.grid_closest_hit(rays, mesh, grid, mt64),
                rays,
                ref,
                f"grid_closest_hit({label}, unpadded cells on its lattice)",
                GRID2_COUNTERS,
            )


@pytest.mark.task(3)
@pytest.mark.points(0.5)
def test_bvh_walks_exact_at_vertices_and_edges(impl, device):
    for label, mesh, rays, ref in vertex_cases(device):
        bvh = median_bvh(mesh, 2)
        for walk in ("bvh_closest_hit", "bvh_closest_hit_stackless"):
            compare_at_vertices(
                getattr(impl, walk)(rays, mesh, bvh, mt64),
                rays,
                ref,
                f"{walk}({label}, median BVH, leaf_size=2)",
            )


@pytest.mark.task(4)
@pytest.mark.points(0.5)
def test_kd_exact_at_vertices_and_edges(impl, device):
    for label, mesh, rays, ref in vertex_cases(device):
        tree = median_kdtree(mesh, 10, at_vertices=True)
        compare_at_vertices(
            impl.kd_closest_hit(rays, mesh, tree, mt64),
            rays,
            ref,
            f"kd_closest_hit({label}, planes at triangle bounds)",
        )


@pytest.mark.task(6)
@pytest.mark.points(0.5)
def test_two_level_exact_at_vertices_and_edges(impl, device):
    for label, mesh, rays, ref in vertex_cases(device):
        compare_at_vertices(
            impl.two_level_closest_hit(rays, mesh, simple_two_level(mesh), mt64),
            rays,
            ref,
            f"two_level_closest_hit({label}, built by the grader)",
            GRID2_COUNTERS,
        )


@pytest.mark.task(7)
@pytest.mark.points(0.5)
def test_fast_bvh_exact_at_vertices_and_edges(impl, device):
    # Brute force with the walk's own kernel, moller_trumbore_rows: the same bits per pair
    # (compile=False: no fused rounding), so the same triangle is required.
    for label, mesh, rays, ref in vertex_cases(device, "rows"):
        compare_at_vertices(
            impl.bvh_closest_hit_fast(rays, mesh, median_bvh(mesh, 2), check_every=4),
            rays,
            ref,
            f"bvh_closest_hit_fast({label}, median BVH, leaf_size=2)",
        )


# ---------------------------------------------------------------------------------------
# Exact work and decisions: the cells a walk visits, the SAH decisions of a kd build


def cells_crossed(rays: Rays, lo, hi, res, t_stop):
    """Per ray, in float64: how many cells a DDA over the grid ``lo, hi, res`` visits from
    its entry into the box to ``t_stop`` (its hit; t_max and the box's exit also stop it):
    1 + the cell boundaries crossed, 0 for a ray that misses the box. Returns ``(cells,
    clean)``: ``clean`` marks the rays whose entry, stop and crossings all lie at least
    1e-4 apart, so that rounding decides nothing."""
    o, d = rays.origins.cpu().double(), rays.directions.cpu().double()
    lo, hi, res = lo.cpu().double(), hi.cpu().double(), res.cpu()
    t0, t1 = (lo - o) / d, (hi - o) / d
    t_in = torch.maximum(torch.minimum(t0, t1).amax(1), rays.t_min.cpu().double())
    t_out = torch.minimum(torch.maximum(t0, t1).amin(1), rays.t_max.cpu().double())
    stop = torch.minimum(t_out, t_stop.cpu().double())
    width = (hi - lo) / res
    cells = torch.zeros(len(o), dtype=torch.int64)
    clean = torch.ones(len(o), dtype=torch.bool)
    for i in range(len(o)):
        a_in, a_stop = float(t_in[i]), float(stop[i])
        if not a_in <= a_stop:  # misses the box (or its interval)
            clean[i] = not abs(a_in - float(t_out[i])) <= 1e-4 * (1 + abs(a_in))
            continue
        marks = [a_in, a_stop]
        for a in range(3):
            k = torch.arange(1, int(res[a]), dtype=F64)
            t = (lo[a] + k * width[a] - o[i, a]) / d[i, a]
            near = t[(t > a_in - 1e-3) & (t < a_stop + 1e-3)]
            cells[i] += int(((near > a_in) & (near < a_stop)).sum())
            marks += near.tolist()
        cells[i] += 1
        m = torch.tensor(sorted(marks), dtype=F64)
        clean[i] = bool(((m[1:] - m[:-1]) > 1e-4 * (1 + m[1:].abs())).all())
    return cells, clean


def step_rays(mesh: Mesh, seed: int) -> Rays:
    """Rays from around the scene and from inside it, no component zero, some stopped by
    t_max inside the grid: a DDA's cells are then well defined."""
    rays = rays_around(mesh, 240, seed, clip=0.3)
    d = rays.directions
    d = torch.where(d.abs() < 1e-3, torch.full_like(d, 1e-3), d)
    return Rays.create(rays.origins, d, rays.t_min, rays.t_max)


def check_cells_visited(count, rays: Rays, mesh: Mesh, grid: dict, what: str) -> None:
    """``count["steps"]`` must be the cells each ray crosses up to its hit (see
    ``cells_crossed``), exactly, for the rays where no rounding decides."""
    t_hit = reference(rays.to("cpu"), on(mesh, "cpu"))[0]
    want, clean = cells_crossed(rays, grid["lo"], grid["hi"], grid["resolution"], t_hit)
    assert int(clean.sum()) >= len(rays) // 2, "test set-up: most rays should be clean"
    got = count["steps"].cpu()
    bad = (clean & (got != want)).nonzero()[:, 0]
    if len(bad):
        i = int(bad[0])
        raise AssertionError(
            f"{what}: ray {i} ({describe(rays.to('cpu'), i)}) crosses {int(want[i])} cells of "
            f"the {grid['resolution'].tolist()} grid from its entry to its hit at t="
            f"{t_hit[i].item():.6g} (or t_max, or the grid's far side), but counters['steps'] "
            f"is {int(got[i])} ({len(bad)} rays off). A walk starts in the cell holding o + "
            f"t_enter d, visits each cell once, and ends in the cell where the closest hit "
            f"lies, at t_max, or where it leaves the grid."
        )


@pytest.mark.task(1)
@pytest.mark.points(0.5)
def test_grid_steps_are_the_cells_crossed(impl, device):
    mesh = on(scene("shards"), device)
    grid = uniform_grid(mesh, (7, 5, 9))
    rays = step_rays(mesh, 71).to(device)
    count = compare(
        impl.grid_closest_hit(rays, mesh, grid, mt64),
        rays,
        mesh,
        "grid_closest_hit(shards, a 7 x 5 x 9 grid built by the grader)",
        counters=GRID2_COUNTERS,
    )
    check_cells_visited(count, rays, mesh, grid, "grid_closest_hit(shards, 7 x 5 x 9 grid)")


@pytest.mark.task(6)
@pytest.mark.points(0.5)
def test_two_level_steps_on_plain_cells(impl, device):
    # No top cell crowded enough for a sub-grid: the walk is the uniform grid's DDA.
    mesh = on(scene("shards"), device)
    grid2 = simple_two_level(mesh, (7, 5, 9), min_triangles=mesh.num_faces)
    rays = step_rays(mesh, 72).to(device)
    what = "two_level_closest_hit(shards, a 7 x 5 x 9 top grid without sub-grids)"
    count = compare(
        impl.two_level_closest_hit(rays, mesh, grid2, mt64),
        rays,
        mesh,
        what,
        counters=GRID2_COUNTERS,
    )
    assert (grid2["sub_of"] < 0).all(), "test set-up: no sub-grids wanted"
    check_cells_visited(count, rays, mesh, grid2, what)


def kd_nodes(tree):
    """Per node of a kd dict (CPU): its box ``(lo, hi)`` (float64, from the splits), its
    depth and its triangles (the union of the leaf lists below it), as Python lists."""
    axis, left, split = (tree[k].cpu() for k in ("axis", "left", "split"))
    first, count, tris = (tree[k].cpu() for k in ("first", "count", "triangles"))
    m = len(axis)
    boxes = [None] * m
    depth = [0] * m
    boxes[0] = (tree["lo"].cpu().double(), tree["hi"].cpu().double())
    order = [0]
    for i in order:  # top-down: parents before children
        if axis[i] >= 0:
            a, s, c = int(axis[i]), float(split[i]), int(left[i])
            lo, hi = boxes[i]
            below_hi, above_lo = hi.clone(), lo.clone()
            below_hi[a] = above_lo[a] = s
            boxes[c], boxes[c + 1] = (lo, below_hi), (above_lo, hi)
            depth[c] = depth[c + 1] = depth[i] + 1
            order += [c, c + 1]
    members = [set() for _ in range(m)]
    for i in reversed(order):  # bottom-up
        if axis[i] < 0:
            members[i] = set(tris[int(first[i]) : int(first[i]) + int(count[i])].tolist())
        else:
            members[i] = members[int(left[i])] | members[int(left[i]) + 1]
    return boxes, depth, [sorted(x) for x in members]


def check_kd_sah(tree, mesh: Mesh, what: str, knobs, leaf_size: int, max_depth: int) -> None:
    """Every node of a kd-tree decides as the docstring says: it splits iff it holds more
    than ``leaf_size`` triangles, lies above ``max_depth`` and its cheapest event beats a
    leaf; it splits at a cheapest event; and (a scene whose bounds are all distinct and
    triangles not flat, so that no two events tie) a triangle goes below iff its lower
    bound lies below the plane, above iff its upper bound lies above it."""
    corners = mesh.triangles().cpu().double()
    t_lo, t_hi = corners.amin(1), corners.amax(1)
    assert (t_lo < t_hi).all(), "test set-up: no flat triangles"
    for a in range(3):
        bounds_a = torch.cat((t_lo[:, a], t_hi[:, a]))
        assert len(torch.unique(bounds_a)) == len(bounds_a), "test set-up: distinct bounds"
    inter = knobs[1]
    boxes, depth, members = kd_nodes(tree)
    axis, split, left = (tree[k].cpu() for k in ("axis", "split", "left"))
    for i in range(len(axis)):
        s_ids = torch.tensor(members[i], dtype=torch.int64)
        n = len(s_ids)
        costs = kd_node_costs(t_lo[s_ids], t_hi[s_ids], boxes[i], knobs)
        best = min((float(c.min()) for _, c in costs if len(c)), default=INF)
        may_split = n > leaf_size and depth[i] < max_depth
        where = (
            f"{what}: node {i} (depth {depth[i]}, {n} triangles, box "
            f"{boxes[i][0].tolist()} .. {boxes[i][1].tolist()})"
        )
        if axis[i] < 0:
            assert not (may_split and best < inter * n * (1 - 1e-6)), (
                f"{where} is a leaf, but its cheapest split costs {best:.6g} < a leaf's "
                f"intersect_cost * n = {inter * n:g}: with more than leaf_size={leaf_size} "
                f"triangles and below max_depth={max_depth} it must split"
            )
            continue
        assert may_split, (
            f"{where} splits, but a node with at most leaf_size={leaf_size} triangles, or at "
            f"max_depth={max_depth}, is a leaf"
        )
        assert best < inter * n * (1 + 1e-6), (
            f"{where} splits, but its cheapest split costs {best:.6g}, no less than a "
            f"leaf's intersect_cost * n = {inter * n:g}: it must stay a leaf"
        )
        a, s = int(axis[i]), float(split[i])
        pos, cost = costs[a]
        mine = cost[pos == s]
        mine = float(mine.min()) if len(mine) else INF
        assert mine <= best * (1 + 1e-6), (
            f"{where} splits axis {a} at {s!r}, where the SAH cost is {mine:.6g}; its "
            f"cheapest event costs {best:.6g} (cost = traversal + intersect * (1 - bonus if "
            f"a side is empty) * (A_below N_below + A_above N_above) / A_node, over the "
            f"node's triangles' bounds clipped to its box)"
        )
        c = int(left[i])
        for child, side, want in (
            (c, "below", [t for t in members[i] if t_lo[t, a] < s]),
            (c + 1, "above", [t for t in members[i] if t_hi[t, a] > s]),
        ):
            assert members[child] == want, (
                f"{where} splits axis {a} at {s!r}: its {side} child holds the triangles "
                f"{members[child]}, expected {want}: a triangle goes below iff its start "
                f"event comes before the split event (lower bound < plane, here where no two "
                f"bounds are equal), above iff its end event comes after it"
            )


def kd_soup(seed: int, n: int = 24) -> Mesh:
    """Small triangles in three clusters (empty space to cut away), all bounds distinct."""
    g = generator(seed)
    centre = torch.rand(3, 3, generator=g, dtype=F64)[torch.arange(n) % 3]
    centre = centre + 0.15 * torch.rand(n, 3, generator=g, dtype=F64)
    corners = centre[:, None] + 0.08 * (torch.rand(n, 3, 3, generator=g, dtype=F64) - 0.5)
    return mesh_of(corners)


@pytest.mark.task(4)
@pytest.mark.points(0.5)
def test_kdtree_every_node_follows_the_sah(impl, device):
    # Every node, not just the root: the documented decision with the default knobs
    # (leaf_size=2, traversal 1, intersect 2, bonus 0.5) and others.
    for seed, n in ((164, 24), (153, 16)):
        mesh = on(kd_soup(seed, n), device)
        tree = impl.build_kdtree(mesh)
        what = f"build_kdtree({n} small triangles in three clusters, seed {seed}, default knobs)"
        check_kdtree(tree, mesh, what)
        max_depth = round(8 + 1.3 * math.log2(mesh.num_faces))
        check_kd_sah(tree, mesh, what, (1.0, 2.0, 0.5), 2, max_depth)
    mesh = on(kd_soup(133), device)
    for leaf_size, knobs, max_depth in ((3, (0.5, 1.0, 0.9), 4), (1, (2.0, 1.5, 0.0), 9)):
        traversal, inter, bonus = knobs
        tree = impl.build_kdtree(mesh, max_depth, leaf_size, traversal, inter, bonus)
        what = (
            f"build_kdtree(three clusters, max_depth={max_depth}, leaf_size={leaf_size}, "
            f"traversal_cost={traversal}, intersect_cost={inter}, empty_bonus={bonus})"
        )
        check_kdtree(tree, mesh, what)
        check_kd_sah(tree, mesh, what, knobs, leaf_size, max_depth)
    # A split that only ties with a leaf does not beat it: two triangles, each split costs
    # 0.75 + 1 * (4 * 1 + 6 * 1) / 8 = 2 = intersect_cost * n, exactly (dyadic values).
    corners = torch.tensor(
        [
            [[0.0, 0.0, 0.0], [0.5, 1.0, 0.0], [0.0, 1.0, 1.0]],
            [[1.0, 0.0, 0.0], [1.5, 1.0, 0.0], [1.0, 1.0, 1.0]],
        ],
        dtype=F64,
    )
    mesh = on(mesh_of(corners), device)
    tree = impl.build_kdtree(mesh, 4, 1, 0.75, 1.0, 0.5)
    assert len(tree["axis"]) == 1, (
        "build_kdtree(two triangles x in [0, 0.5] and [1, 1.5], leaf_size=1, traversal_cost="
        f"0.75, intersect_cost=1): {len(tree['axis'])} nodes, expected a single leaf: the "
        "cheapest split costs 0.75 + 1 * (4 * 1 + 6 * 1) / 8 = 2, exactly a leaf's "
        "intersect_cost * n = 2, and a node splits only if the split BEATS the leaf"
    )


def octant_clusters(counts=(17,) * 8, scale: float = 1.0, shift: float = 0.0) -> Mesh:
    """A cluster of small triangles (bounds about 0.03 x 0.02 x 0.01 of ``scale``, spread
    over 0.2 x 0.1 x 0.05) at each corner of a cube of side ``scale``, ``counts[i]``
    triangles at corner i (x fastest): one cluster per top cell of a 2 x 2 x 2 top grid
    at top_density 1/16. A count of -n puts n triangles shrunk to the point (0, 0, 0)
    there (corner 0 only, ``shift`` 0)."""
    g = generator(181)
    parts = []
    for i, n in enumerate(counts):
        corner = torch.tensor([i % 2, (i // 2) % 2, i // 4], dtype=F64)
        if n < 0:
            parts.append(torch.zeros(-n, 3, 3, dtype=F64))
            continue
        centre = corner + torch.rand(n, 1, 3, generator=g, dtype=F64) * torch.tensor(
            [0.2, 0.1, 0.05], dtype=F64
        )
        parts.append(
            centre
            + torch.rand(n, 3, 3, generator=g, dtype=F64)
            * torch.tensor([0.03, 0.02, 0.01], dtype=F64)
        )
    return mesh_of(torch.cat(parts) * scale + shift)


def check_sub_grids(g, mesh: Mesh, what: str, density: float) -> None:
    """What check_two_level leaves loose: ``sub_of`` is -1 for plain cells; each sub-grid's
    box is its small triangles' bounds (clipped to the cell) padded by a small pad: strictly
    larger (a few ulps of the coordinates at least), at most 1e-3 of its size plus a few
    ulps larger; its resolution is exactly ``grid_resolutions`` of that box for its small
    triangles; each entry's box of sub cells is exactly the cells its padded bounds reach."""
    sub_of = g["sub_of"].cpu()
    plain = sub_of < 0
    assert (sub_of[plain] == -1).all(), (
        f"{what}: sub_of holds {sorted(set(sub_of[plain].tolist()))} for plain cells, "
        f"expected -1 (no sub-grid)"
    )
    s = int((~plain).sum())
    if s == 0:
        return
    lo, hi, res = g["lo"].cpu().double(), g["hi"].cpu().double(), g["resolution"].cpu()
    width = (hi - lo) / res
    sub_lo, sub_hi = g["sub_lo"].cpu().double(), g["sub_hi"].cpu().double()
    sres, s_count = g["sub_resolution"].cpu(), g["sub_cell_count"].cpu()
    s_tris = g["sub_triangles"].cpu()
    e_lo, e_hi = g["sub_tri_cell_lo"].cpu(), g["sub_tri_cell_hi"].cpu()
    entry_sub = torch.repeat_interleave(
        torch.repeat_interleave(torch.arange(s), sres.prod(1)), s_count
    )
    corners = mesh.triangles().cpu().double()
    t_lo, t_hi = corners.amin(1), corners.amax(1)
    eps = torch.finfo(mesh.dtype).eps
    owner = torch.zeros(s, dtype=torch.int64)
    owner[sub_of[~plain]] = (~plain).nonzero()[:, 0]
    cc = torch.stack((owner % res[0], (owner // res[0]) % res[1], owner // (res[0] * res[1])), 1)
    n_small = torch.zeros(s, dtype=torch.int64)
    for i in range(s):
        tris = torch.unique(s_tris[entry_sub == i])
        n_small[i] = len(tris)
        cell_lo, cell_hi = lo + cc[i] * width, lo + (cc[i] + 1) * width
        b_lo = torch.maximum(t_lo[tris].amin(0), cell_lo)
        b_hi = torch.minimum(t_hi[tris].amax(0), cell_hi)
        size = float((b_hi - b_lo).amax())
        slack = 1e-3 * size + 64 * eps * float(torch.maximum(b_lo.abs(), b_hi.abs()).amax())
        slack = slack if size > 0 else 1e-3 * float(width.amin())  # a point: any thickness
        ok = (sub_lo[i] < b_lo) & (sub_hi[i] > b_hi)
        ok &= (sub_lo[i] >= b_lo - slack) & (sub_hi[i] <= b_hi + slack)
        assert ok.all(), (
            f"{what}: sub-grid {i} (top cell {cc[i].tolist()}) has the box "
            f"{sub_lo[i].tolist()} .. {sub_hi[i].tolist()}; its small triangles' bounds, "
            f"clipped to the cell, are {b_lo.tolist()} .. {b_hi.tolist()}: expected them "
            f"padded by more than nothing and at most {slack:.3g} (relative to the sub-grid's "
            f"own size, plus a few ulps of its coordinates)"
        )
        sw = (sub_hi[i] - sub_lo[i]) / sres[i]
        k = (entry_sub == i).nonzero()[:, 0]
        c_lo = torch.maximum(t_lo[s_tris[k]], cell_lo)
        c_hi = torch.minimum(t_hi[s_tris[k]], cell_hi)
        near_lo = torch.floor((c_lo - slack - sub_lo[i]) / sw).long().clamp(min=0)
        near_hi = torch.minimum(torch.floor((c_hi + slack - sub_lo[i]) / sw).long(), sres[i] - 1)
        loose = (e_lo[k] < near_lo) | (e_hi[k] > near_hi)
        if loose.any():
            j = int(k[loose.any(1)][0])
            raise AssertionError(
                f"{what}: sub-grid {i}'s entry of triangle {int(s_tris[j])} spans the sub cells "
                f"{e_lo[j].tolist()} .. {e_hi[j].tolist()}, beyond the cells its bounds "
                f"(padded) reach, at most {near_lo[loose.any(1)][0].tolist()} .. "
                f"{near_hi[loose.any(1)][0].tolist()}: floor((tri_lo - pad - sub_lo) / w) to "
                f"floor((tri_hi + pad - sub_lo) / w), as in build_grid"
            )
    want = grid_resolutions(g["sub_hi"] - g["sub_lo"], n_small.to(g["sub_lo"].device), density)
    bad = (want.cpu() != sres).any(1)
    if bad.any():
        i = int(bad.nonzero()[0, 0])
        raise AssertionError(
            f"{what}: sub-grid {i} holds {int(n_small[i])} small triangles in a box of size "
            f"{(sub_hi[i] - sub_lo[i]).tolist()}: resolution {sres[i].tolist()}, expected "
            f"grid_resolutions(sub_hi - sub_lo, n, density={density:g}) = {want[i].tolist()} "
            f"(n: the sub-grid's small triangles)"
        )


@pytest.mark.task(6)
@pytest.mark.points(0.5)
def test_build_two_level_grid_sub_grids_exactly(impl, device):
    # Eight clusters of 17 small triangles, one in each cell of a 2 x 2 x 2 top grid: with
    # the default min_triangles (16) each cell is crowded and gets a sub-grid, with the
    # default density (2). Near the origin, far from it, shrunk, and with 17 triangles
    # shrunk to the point (0, 0, 0) (a sub-grid box of size 0 needs a thickness).
    for label, mesh in (
        ("", octant_clusters()),
        (" moved by 1e5 (scaled 100)", octant_clusters(scale=100.0, shift=1e5)),
        (" shrunk 100 times", octant_clusters(scale=0.01)),
        (" (17 points at the origin)", octant_clusters((-17,) + (17,) * 7)),
        (" (17 points at the origin), shrunk", octant_clusters((-17,) + (17,) * 7, 0.01)),
        (" but 5 in one (a plain cell)", octant_clusters((5,) + (17,) * 7)),
    ):
        mesh = on(mesh, device)
        g = two_level_of(impl, mesh)
        what = f"build_two_level_grid(8 clusters of 17 small triangles{label})"
        assert g["resolution"].tolist() == [2, 2, 2], "test set-up: a 2 x 2 x 2 top grid"
        check_two_level(g, mesh, what, 2.0)
        check_sub_grids(g, mesh, what, 2.0)
    # A sub-grid 1950 wide at x = 1e5 (under a big triangle, in a single flat top cell):
    # 1e-4 of its size (0.195) is about its coordinates' 16 ulps-worth (0.194): a pad that
    # drops the ulps term, or subtracts it, leaves nothing after rounding to float32.
    i = torch.arange(17, dtype=F64)[:, None]
    x0, y0 = 1e5 + 121.25 * i, 10.0 + i
    small = torch.stack(
        (
            torch.cat((x0, y0, torch.ones_like(i)), 1),
            torch.cat((x0 + 10, y0, torch.ones_like(i)), 1),
            torch.cat((x0, y0 + 5, 3 * torch.ones_like(i)), 1),
        ),
        1,
    )
    floor = torch.tensor([[[-3000.0, 0.0, 0.0], [5000.0, 8000.0, 0.0], [0.0, 4000.0, 10.0]]])
    mesh = on(mesh_of(torch.cat((small, floor.double() + torch.tensor([1e5, 0.0, 0.0])))), device)
    g = two_level_of(impl, mesh)
    what = "build_two_level_grid(17 small triangles 1950 wide at x = 1e5, on a big floor)"
    assert int((g["sub_of"] >= 0).sum()) == 1, "test set-up: one sub-grid"
    check_two_level(g, mesh, what, 2.0)
    check_sub_grids(g, mesh, what, 2.0)
    # The top grid at the default top_density, 1/16: 208 triangles, (3, 2, 2) cells.
    mesh = on(octant_clusters((26,) * 8), device)
    g = two_level_of(impl, mesh)
    extent = (g["hi"] - g["lo"]).cpu().double().tolist()
    want = heuristic_resolution(extent, mesh.num_faces, 1 / 16)
    assert want == (3, 2, 2), "test set-up: a top grid of (3, 2, 2) cells"
    assert tuple(g["resolution"].tolist()) == want, (
        f"build_two_level_grid(8 clusters of 26 small triangles): top resolution "
        f"{g['resolution'].tolist()}, expected {list(want)}: the top grid is build_grid's at "
        f"density=top_density (default 1/16)"
    )
    # A triangle exactly one top cell wide is big ("at least one top cell wide").
    base = octant_clusters()
    g = two_level_of(impl, on(base, device))
    w = float(((g["hi"] - g["lo"]) / g["resolution"]).amin())  # in the mesh's dtype
    # x from w to 2 w (exact: 2 w - w = w), inside the scene's bounds
    wide = torch.tensor([[[w, 0.5, 0.5], [2 * w, 0.5, 0.5], [w, 0.52, 0.5]]], dtype=F32)
    mesh = on(mesh_of(torch.cat((base.triangles(), wide))), device)
    g = two_level_of(impl, mesh)
    what = "build_two_level_grid(8 clusters and a triangle exactly one top cell wide)"
    width = (g["hi"] - g["lo"]) / g["resolution"]
    assert float(width.amin()) == w, "test set-up: the same top grid"
    assert bool(g["big"][-1]), (
        f"{what}: the triangle {w!r} wide, exactly the top cells' smallest width, is not "
        f"big: a triangle whose bounds are AT LEAST one top cell wide on some axis is big"
    )
    check_two_level(g, mesh, what, 2.0)
    # min_triangles=0: a top cell with a single small triangle gets a sub-grid for one.
    mesh = on(octant_clusters((1,) + (17,) * 7), device)
    g = two_level_of(impl, mesh, 1 / 16, 3.0, 0)
    what = "build_two_level_grid(a cluster of 1 and 7 of 17 triangles, density=3, min_triangles=0)"
    check_two_level(g, mesh, what, 3.0, 0)
    check_sub_grids(g, mesh, what, 3.0)


def in_plane_case(lower_first: bool, shift: float = 0.0):
    """A hand-built kd-tree whose root splits z at 0.5, and rays lying in that plane
    (o_z = 0.5, d_z = +0.0 or -0.0) along x: they hit triangle 0 (x = 2) at t = 2 and
    triangle 1 (x = 5) at t = 5, each exactly at an edge in the plane (dyadic values: exact).
    Triangle 0 hangs below the plane, triangle 1 stands on it, triangle 2 (x = 10, never
    hit) stretches the box. ``lower_first``: the split event is triangle 0's end (triangle
    1's start comes before it: triangle 1 in both children, 0 below only); else the roles
    of the sides swap (triangle 0 stands on the plane, 1 hangs below it)."""
    z = (0.0, 1.0) if lower_first else (1.0, 0.0)
    corners = torch.tensor(
        [
            [[2.0, 0.0, 0.5], [2.0, 1.0, 0.5], [2.0, 0.5, z[0]]],
            [[5.0, 0.0, 0.5], [5.0, 1.0, 0.5], [5.0, 0.5, z[1]]],
            [[10.0, 0.9, 0.9], [10.0, 1.0, 0.9], [10.0, 0.9, 1.0]],
        ],
        dtype=F64,
    )
    if not lower_first:
        corners[2, :, 2] -= 0.9  # below the plane, with the near triangle
    mesh = mesh_of(corners + shift)
    below, above = ([0, 1], [1, 2]) if lower_first else ([1, 2], [0, 1])
    tree = {
        "kind": "kd",
        "lo": torch.tensor([2.0, 0.0, 0.0]) + shift,
        "hi": torch.tensor([10.0, 1.0, 1.0]) + shift,
        "split": torch.tensor([0.5 + shift, 0.0, 0.0]),
        "axis": torch.tensor([2, -1, -1]),
        "left": torch.tensor([1, -1, -1]),
        "first": torch.tensor([0, 0, len(below)]),
        "count": torch.tensor([0, len(below), len(above)]),
        "triangles": torch.tensor(below + above),
    }
    o = torch.tensor([[0.0, 0.25, 0.5]] * 4, dtype=F64) + shift
    d = torch.tensor([[1.0, 0.0, 0.0], [1.0, 0.0, -0.0], [1.0, 0.1, 0.0], [1.0, -0.0, -0.0]])
    rays = Rays.create(o.float(), d)
    return mesh, tree, rays


@pytest.mark.task(4)
@pytest.mark.points(0.5)
def test_kd_rays_in_a_split_plane_visit_both_children(impl, device):
    # A ray lying in a split plane (o[axis] == split, d[axis] = +0.0 or -0.0) visits the
    # lower child first ("== split with d[axis] <= 0"), then the upper one whatever it found:
    # both children hold the whole interval, so no early exit may skip the second. Either
    # child may list the near triangle alone (a split at a triangle's end or start event).
    # Near the origin and moved by 1e5.
    for lower_first in (True, False):
        for shift in (0.0, 1e5):
            mesh, tree, rays = in_plane_case(lower_first, shift)
            mesh, rays = on(mesh, device), rays.to(device)
            tree = {k: v.to(device) if isinstance(v, torch.Tensor) else v for k, v in tree.items()}
            side = "lower" if lower_first else "upper"
            compare(
                impl.kd_closest_hit(rays, mesh, tree, mt64),
                rays,
                mesh,
                f"kd_closest_hit(rays in the root's split plane z = {0.5 + shift:g} with d_z = "
                f"+0.0 or -0.0; only the {side} child lists the near triangle, both list the "
                f"far one: such a ray visits both children, and a hit in the first one visited "
                f"must not end it before the second)",
            )
