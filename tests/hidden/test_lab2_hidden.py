"""Hidden grader for Lab 2 (not in the student handout; shown on Gradescope after the due
date): the contracts of the visible grader on scenes, seeds, leaf sizes, resolutions and
dtypes it does not use, so a submission tuned to the visible inputs fails here.

Scenes: slivers (long, thin triangles in every direction: each spans many cells and
straddles many splits), a random soup of another size in float64, and the same soup moved
by -2e4. Structures are built here as in the visible grader, so each task is graded on its
own; the brute-force reference and the comparisons are the visible grader's.
"""

from __future__ import annotations

import functools
import math

import pytest
import test_lab2_accel as visible
import torch
from test_lab2_accel import (
    F32,
    F64,
    GRID2_COUNTERS,
    cat_rays,
    check_bvh,
    compare,
    compare_fast,
    median_bvh,
    median_kdtree,
    mesh_of,
    mt64,
    on,
    rays_around,
    sah_cost,
    simple_two_level,
    uniform_grid,
)

from course.core.scenes import load_scene
from course.core.types import Mesh, Rays
from course.given.lab2_robust import reach
from course.grading.testing import generator

LAB_MODULE = "lab2_accel"
TASKS = visible.TASKS
pytestmark = pytest.mark.visibility("after_due_date")


@functools.cache
def hidden_scene(name: str) -> Mesh:
    """The named hidden scene (CPU)."""
    if name == "slivers":
        g = generator(2024)
        start = torch.rand(70, 1, 3, generator=g, dtype=F64)
        along = torch.randn(70, 1, 3, generator=g, dtype=F64)
        along = 0.7 * along / along.norm(dim=-1, keepdim=True)
        side = 0.02 * torch.randn(70, 1, 3, generator=g, dtype=F64)
        return mesh_of(torch.cat((start, start + along, start + along + side), 1))
    soup = load_scene("random_soup", device="cpu", dtype=F64, n=150, seed=4242).mesh
    corners = soup.vertices[soup.faces]
    if name == "soup64":
        return mesh_of(corners, dtype=F64)
    if name == "moved64":
        return mesh_of(corners - 2e4, dtype=F64)
    raise KeyError(name)


def hidden_rays(mesh: Mesh, seed: int, n: int = 90):
    """Rays around the scene, axis-parallel ones and NaN/inf ones, in the mesh's dtype."""
    return cat_rays(
        rays_around(mesh, n, seed, inside=0.4, clip=0.3, dtype=mesh.dtype),
        visible.axis_rays(mesh, seed + 1, 2, dtype=mesh.dtype),
        *([visible.bad_rays()] if mesh.dtype == torch.float32 else []),
    )


@pytest.mark.task(1)
@pytest.mark.points(0.5)
def test_grid_closest_hit_hidden_scenes(impl, device):
    for name, resolution in (
        ("slivers", None),
        ("slivers", (9, 2, 5)),
        ("soup64", (3, 7, 1)),
        ("moved64", None),
    ):
        mesh = on(hidden_scene(name), device)
        rays = hidden_rays(mesh, 501).to(device)
        compare(
            impl.grid_closest_hit(rays, mesh, uniform_grid(mesh, resolution), mt64),
            rays,
            mesh,
            f"grid_closest_hit(hidden scene {name}, resolution={resolution})",
            counters=("steps", "tests", "skipped"),
        )


@pytest.mark.task(2)
@pytest.mark.points(0.5)
def test_lbvh_sah_bvh_hidden_scenes(impl, device):
    for name in ("slivers", "soup64", "moved64"):
        mesh = on(hidden_scene(name), device)
        leaf_size = {"slivers": 2, "soup64": 3, "moved64": 5}[name]
        check_bvh(
            impl.build_lbvh(mesh, leaf_size),
            mesh,
            f"build_lbvh(hidden scene {name}, leaf_size={leaf_size})",
            leaf_size,
        )
        check_bvh(
            impl.build_sah_bvh(mesh, leaf_size, 7),
            mesh,
            f"build_sah_bvh(hidden scene {name}, leaf_size={leaf_size}, bins=7)",
            leaf_size,
        )
    mesh = on(hidden_scene("soup64"), device)
    got, median = sah_cost(impl.build_sah_bvh(mesh, 3, 12)), sah_cost(median_bvh(mesh, 3))
    assert got <= median, (
        f"build_sah_bvh(hidden soup, float64): SAH cost {got:.1f}, more "
        f"than the {median:.1f} of an object-median BVH"
    )


@pytest.mark.task(3)
@pytest.mark.points(0.5)
def test_bvh_closest_hit_stack_and_stackless_hidden_scenes(impl, device):
    for name, leaf_size in (("slivers", 3), ("soup64", 5), ("moved64", 1)):
        mesh = on(hidden_scene(name), device)
        rays = hidden_rays(mesh, 502).to(device)
        bvh = median_bvh(mesh, leaf_size)
        ref = visible.reference(rays.to("cpu"), on(mesh, "cpu"))
        for fn in (impl.bvh_closest_hit, impl.bvh_closest_hit_stackless):
            label = getattr(fn, "__name__", None) or getattr(fn, "_name", "traversal")
            compare(
                fn(rays, mesh, bvh, mt64),
                rays,
                mesh,
                f"{label}(hidden scene {name}, median BVH, leaf_size={leaf_size})",
                ref=ref,
            )


@pytest.mark.task(4)
@pytest.mark.points(0.5)
def test_kd_closest_hit_hidden_scenes(impl, device):
    for name, depth in (("slivers", 7), ("soup64", 5), ("moved64", 8)):
        mesh = on(hidden_scene(name), device)
        rays = hidden_rays(mesh, 503).to(device)
        compare(
            impl.kd_closest_hit(rays, mesh, median_kdtree(mesh, depth, 2), mt64),
            rays,
            mesh,
            f"kd_closest_hit(hidden scene {name}, spatial-median tree of depth {depth})",
        )


@pytest.mark.task(6)
@pytest.mark.points(0.5)
def test_two_level_closest_hit_hidden_scenes(impl, device):
    for name, top, sub, min_tri in (
        ("slivers", (4, 2, 3), (3, 5, 4), 5),
        ("soup64", (2, 3, 2), (6, 2, 3), 3),
        ("moved64", (3, 1, 2), (4, 4, 2), 6),
    ):
        mesh = on(hidden_scene(name), device)
        rays = hidden_rays(mesh, 504).to(device)
        mailbox = name != "soup64"
        compare(
            impl.two_level_closest_hit(
                rays, mesh, simple_two_level(mesh, top, sub, min_tri), mt64, mailbox=mailbox
            ),
            rays,
            mesh,
            f"two_level_closest_hit(hidden scene {name}, top {top}, sub-grids {sub}, "
            f"mailbox={mailbox})",
            counters=GRID2_COUNTERS,
        )


@pytest.mark.task(7)
@pytest.mark.points(0.5)
def test_fast_bvh_hidden_scenes(impl, device):
    for name, leaf_size, k in (("slivers", 2, 5), ("soup64", 4, 3), ("moved64", 3, 11)):
        mesh = on(hidden_scene(name), device)
        rays = hidden_rays(mesh, 505).to(device)
        compare_fast(
            impl.bvh_closest_hit_fast(rays, mesh, median_bvh(mesh, leaf_size), check_every=k),
            rays,
            mesh,
            f"bvh_closest_hit_fast(hidden scene {name}, leaf_size={leaf_size}, check_every={k})",
        )


# ---------------------------------------------------------------------------------------
# The BVH builds and walks, property by property (any correct builder passes: the checks
# follow from the docstrings, not from the reference's tree)


def node_sets(bvh) -> torch.Tensor:
    """(M, F) bool: the triangles under each node (the union of its leaves), CPU."""
    left, right = bvh["left"].cpu(), bvh["right"].cpu()
    first, count, tris = bvh["first"].cpu(), bvh["count"].cpu(), bvh["triangles"].cpu()
    m, f = len(left), len(tris)
    under = torch.zeros(m, f, dtype=torch.bool)
    for i in reversed(range(m)):  # children come after their parent in the layout
        if left[i] < 0:
            under[i, tris[first[i] : first[i] + count[i]]] = True
        else:
            under[i] = under[left[i]] | under[right[i]]
    return under


def centres_f64(mesh: Mesh):
    """(F, 3) float64 centres of the triangle bounds and the bounds (exact for float32)."""
    corners = mesh.triangles().cpu().double()
    lo, hi = corners.amin(1), corners.amax(1)
    return (lo + hi) / 2, lo, hi


def lbvh_scene() -> Mesh:
    """61 tiny triangles (bounds of half-size 2^-12) centred on the corners of a grid of
    quarters, each coordinate moved by 0 or 2^-11 (the 11th bit below the box's size): the
    centres' box is [1, 2]^3, every centre quantises exactly (most on a cell's lower face),
    runs of triangles share a 10-bit Morton code (split in the middle) and 11 bits would
    order them otherwise."""
    g = generator(2601)
    n = 61
    coarse = torch.randint(0, 5, (n, 3), generator=g).double() / 4
    jitter = torch.randint(0, 2, (n, 3), generator=g).double() / 2048
    centre = (coarse + jitter).clamp(max=1.0)
    centre[0], centre[1] = 0.0, 1.0
    # A run of 9 equal 10-bit codes (every third triangle from 30 on), its 11th x bits
    # alternating: the middle split and an 11-bit split part it differently.
    run = torch.arange(30, 57, 3)
    centre[run] = 0.5
    centre[run[::2], 0] += 1 / 2048
    h = 2.0**-12
    shape = torch.tensor([[-h, -h, -h], [h, h, h], [h, -h, h]], dtype=F64)
    return mesh_of(1.0 + centre[:, None] + shape)


def check_lbvh_tree(bvh, mesh: Mesh, leaf_size: int, bits: int, what: str) -> None:
    """The LBVH the docstring defines, whatever the order of a node's children: each node
    holds a contiguous range [s, e) of the triangles stable-sorted by Morton code, splits
    iff e - s > leaf_size, at the first code with the highest differing bit of codes[s] ^
    codes[e - 1] set (equal codes: the middle, either way for odd counts)."""
    check_bvh(bvh, mesh, what, leaf_size)
    c, _, _ = centres_f64(mesh)
    cmin, cmax = c.amin(0), c.amax(0)
    ext = cmax - cmin
    scale = torch.where(ext > 0, 2.0**bits / ext, 0.0)
    q = torch.floor((c - cmin) * scale).clamp(0, 2**bits - 1).long()
    codes = visible.interleave(q, bits)
    order = torch.sort(codes, stable=True).indices
    sorted_codes = codes[order]
    pos = torch.empty_like(order)
    pos[order] = torch.arange(len(order))
    under = node_sets(bvh)
    left, right = bvh["left"].cpu(), bvh["right"].cpu()
    ranges = []
    for i in range(len(left)):
        p = pos[under[i]]
        s, e = int(p.min()), int(p.max()) + 1
        if e - s != len(p):
            raise AssertionError(
                f"{what}: node {i} holds triangles at sorted positions {sorted(p.tolist())}: "
                f"expected a contiguous range of the triangles stable-sorted by their "
                f"{3 * bits}-bit Morton codes (ties in triangle order)"
            )
        ranges.append((s, e))
    for i, (s, e) in enumerate(ranges):
        inner = bool(left[i] >= 0)
        if inner != (e - s > leaf_size):
            raise AssertionError(
                f"{what}: node {i} holds {e - s} triangles and is "
                f"{'an inner node' if inner else 'a leaf'}: with leaf_size={leaf_size} a node "
                f"of more triangles splits, one of at most leaf_size is a leaf"
            )
        if not inner:
            continue
        differ = int(sorted_codes[s] ^ sorted_codes[e - 1])
        if differ:
            b = differ.bit_length() - 1
            flip = torch.tensor([(int(sorted_codes[e - 1]) >> b) << b])
            mids = {s + int(torch.searchsorted(sorted_codes[s:e], flip)[0])}
            rule = f"where bit {b} (the highest differing one) of the codes flips"
        else:
            mids = {(s + e) // 2, (s + e + 1) // 2}
            rule = "in the middle (all its codes are equal)"
        kids = sorted((ranges[int(left[i])], ranges[int(right[i])]))
        if not any(kids == [(s, mid), (mid, e)] for mid in mids):
            raise AssertionError(
                f"{what}: node {i} holds sorted positions [{s}, {e}) and its children "
                f"{kids[0]} and {kids[1]}: expected it to split at {sorted(mids)}, {rule}"
            )


@pytest.mark.task(2)
@pytest.mark.points(0.5)
def test_lbvh_is_the_morton_split_tree(impl, device):
    mesh = on(lbvh_scene(), device)
    default = impl.build_lbvh(mesh)
    check_lbvh_tree(default, mesh, 4, 10, "build_lbvh(61 triangles on a grid; defaults)")
    for leaf_size, bits in ((1, 10), (2, 3)):
        check_lbvh_tree(
            impl.build_lbvh(mesh, leaf_size, bits),
            mesh,
            leaf_size,
            bits,
            f"build_lbvh(61 triangles on a grid, leaf_size={leaf_size}, bits={bits})",
        )
    five = on(mesh_of(lbvh_scene().triangles()[:5]), device)
    check_lbvh_tree(impl.build_lbvh(five), five, 4, 10, "build_lbvh(5 triangles; defaults)")


def box_area(mask: torch.Tensor, lo: torch.Tensor, hi: torch.Tensor) -> torch.Tensor:
    """Surface area of the union of the boxes ``lo[j], hi[j]`` (F, 3) selected by each row
    of ``mask`` (..., F); 0 for an empty selection (float64)."""
    box_lo = torch.where(mask[..., None], lo, math.inf).amin(-2)
    box_hi = torch.where(mask[..., None], hi, -math.inf).amax(-2)
    ext = (box_hi - box_lo).clamp(min=0)
    return 2 * (ext[..., 0] * ext[..., 1] + ext[..., 1] * ext[..., 2] + ext[..., 2] * ext[..., 0])


def check_sah_tree(bvh, mesh: Mesh, leaf_size: int, bins: int, what: str) -> None:
    """The binned SAH build the docstring defines, whatever the order of a node's children:
    a node splits iff it holds more than leaf_size triangles, and its split costs no more
    than the cheapest of the documented candidates (bins of the centroids between the
    node's centroid bounds, A(left) N(left) + A(right) N(right) with the triangles' bounds,
    in float64; a relative 1e-5 for rounding); with no valid candidate, its halves."""
    check_bvh(bvh, mesh, what, leaf_size)
    c, lo, hi = centres_f64(mesh)
    under = node_sets(bvh)
    left, right = bvh["left"].cpu(), bvh["right"].cpu()
    k = torch.arange(bins - 1)
    for i in range(len(left)):
        ids = under[i].nonzero()[:, 0]
        n, inner = len(ids), bool(left[i] >= 0)
        if inner != (n > leaf_size):
            raise AssertionError(
                f"{what}: node {i} holds {n} triangles and is "
                f"{'an inner node' if inner else 'a leaf'}: with leaf_size={leaf_size} a node "
                f"of more triangles splits, one of at most leaf_size is a leaf"
            )
        if not inner:
            continue
        ci = c[ids]
        cmin, ext = ci.amin(0), ci.amax(0) - ci.amin(0)
        scale = torch.where(ext > 0, bins / ext, 0.0)
        b = torch.floor((ci - cmin) * scale).clamp(0, bins - 1).long()  # (n, 3)
        goes_left = b.T[:, None, :] <= k[None, :, None]  # (axis, after bin k, triangle)
        n_l = goes_left.sum(-1)
        cost = box_area(goes_left, lo[ids], hi[ids]) * n_l + box_area(
            ~goes_left, lo[ids], hi[ids]
        ) * (n - n_l)
        cost = torch.where((n_l > 0) & (n_l < n), cost, math.inf)
        best = float(cost.min())
        kids = torch.stack((under[int(left[i])], under[int(right[i])]))[:, ids]
        sizes = sorted(kids.sum(1).tolist())
        if best == math.inf:
            assert sizes == [n // 2, n - n // 2], (
                f"{what}: node {i} holds {n} triangles whose centroids share one bin on every "
                f"axis (no valid split): expected its range split in the middle, into "
                f"{[n // 2, n - n // 2]} triangles, got {sizes}"
            )
            continue
        got = float((box_area(kids, lo[ids], hi[ids]) * kids.sum(1)).sum())
        if got > best * (1 + 1e-5):
            axis, after = divmod(int(cost.argmin()), bins - 1)
            raise AssertionError(
                f"{what}: node {i} ({n} triangles) splits into {sizes[0]} + {sizes[1]} at a "
                f"cost A(left) N(left) + A(right) N(right) = {got:.6g}, "
                f"{got / best - 1:.3%} more than the cheapest of its {bins}-bin candidates: "
                f"{best:.6g}, after bin {after} on axis {axis} (bin = floor(bins (c - cmin) / "
                f"(cmax - cmin)) of the node's centroid bounds, clamped to [0, bins - 1])"
            )


@pytest.mark.task(2)
@pytest.mark.points(0.5)
def test_sah_bvh_picks_the_cheapest_binned_split(impl, device):
    soup = load_scene("random_soup", device="cpu", n=48, seed=2602).mesh
    mesh = on(soup, device)
    check_sah_tree(
        impl.build_sah_bvh(mesh), mesh, 4, 16, "build_sah_bvh(random soup of 48; defaults)"
    )
    for leaf_size, bins in ((1, 9), (2, 2)):
        check_sah_tree(
            impl.build_sah_bvh(mesh, leaf_size, bins),
            mesh,
            leaf_size,
            bins,
            f"build_sah_bvh(random soup of 48, leaf_size={leaf_size}, bins={bins})",
        )
    five = on(mesh_of(soup.triangles()[:5]), device)
    check_sah_tree(impl.build_sah_bvh(five), five, 4, 16, "build_sah_bvh(5 triangles; defaults)")
    # Centroids on bin boundaries, exactly (dyadic, centroid bounds [3, 4] in x, flat in y
    # and z): x = 3.5 is the lower face of bin 2 of 4, and the cheapest split puts it right.
    xs = torch.tensor([3.0, 3.0625, 3.3125, 3.5, 3.5625, 3.625, 4.0], dtype=F64)
    centre = torch.stack((xs, torch.full_like(xs, 0.5), torch.full_like(xs, 0.5)), 1)
    half = torch.tensor([1 / 64, 1 / 4, 1 / 4], dtype=F64)
    shape = torch.stack((-half, half, half * torch.tensor([1.0, -1.0, 1.0], dtype=F64)))
    row = on(mesh_of(centre[:, None] + shape), device)
    check_sah_tree(
        impl.build_sah_bvh(row, 1, 4),
        row,
        1,
        4,
        "build_sah_bvh(7 triangles in a row, centroids on bin boundaries, leaf_size=1, bins=4)",
    )


def reach_tie_case(dtype, device, beyond: bool):
    """``(mesh, bvh, rays)``: triangle 0 in the plane x = 1, triangle 1 in x = 2, each in a
    leaf of a root; two rays along +x from x = 0 hit triangle 0 at t = 1 (exactly), and the
    leaf of triangle 1 starts (its box's lower x: the rays' entry t) exactly at reach(1),
    or (``beyond``) at the next float above it."""
    one = torch.ones((), dtype=dtype)
    at = reach(one)
    if beyond:
        at = torch.nextafter(at, torch.tensor(math.inf, dtype=dtype))
    tri = torch.tensor([[0.0, -1.0, -1.0], [0.0, 3.0, -1.0], [0.0, -1.0, 3.0]], dtype=F64)
    corners = torch.stack((tri + torch.tensor([1.0, 0, 0], dtype=F64), tri))
    corners[1, :, 0] = 2.0
    mesh = mesh_of(corners, dtype=dtype, device=device)
    lo = torch.tensor([[1.0, -1.0, -1.0], [1.0, -1.0, -1.0], [0.0, -1.0, -1.0]], dtype=dtype)
    lo[2, 0] = at
    hi = torch.tensor([[2.0, 3.0, 3.0], [1.0, 3.0, 3.0], [2.0, 3.0, 3.0]], dtype=dtype)
    bvh = {
        "kind": "bvh",
        "lo": lo.to(device),
        "hi": hi.to(device),
        "left": torch.tensor([1, -1, -1], device=device),
        "right": torch.tensor([2, -1, -1], device=device),
        "first": torch.tensor([0, 0, 1], device=device),
        "count": torch.tensor([0, 1, 1], device=device),
        "triangles": torch.tensor([0, 1], device=device),
    }
    rays = Rays.create(
        torch.tensor([[0.0, 0.25, 0.25], [0.0, 0.5, 1.25]], dtype=dtype),
        torch.tensor([[1.0, 0.0, 0.0], [1.0, 0.0, 0.0]], dtype=dtype),
    ).to(device)
    return mesh, bvh, rays


@pytest.mark.task(3)
@pytest.mark.points(0.5)
def test_bvh_walks_keep_a_node_entered_at_reach(impl, device):
    for dtype, beyond in ((F32, False), (F32, True), (F64, False), (F64, True)):
        mesh, bvh, rays = reach_tie_case(dtype, device, beyond)
        result = impl.bvh_closest_hit(rays, mesh, bvh, mt64)
        stackless = impl.bvh_closest_hit_stackless(rays, mesh, bvh, mt64)
        where = "the next float above reach(1)" if beyond else "exactly reach(1)"
        what = (
            f"a root and two leaves ({dtype}): triangle 0 hit at t = 1, the leaf of triangle 1 "
            f"entered at {where}"
        )
        for name, got, want in (
            ("bvh_closest_hit", result, (2, 1) if beyond else (3, 2)),
            ("bvh_closest_hit_stackless", stackless, (3, 1) if beyond else (3, 2)),
        ):
            count = compare(got, rays, mesh, f"{name}({what})")
            for i in range(len(rays)):
                pair = (int(count["steps"][i]), int(count["tests"][i]))
                assert pair == want, (
                    f"{name}({what}), ray {i}: expected steps={want[0]}, tests={want[1]}, got "
                    f"steps={pair[0]}, tests={pair[1]}. A node entered at t <= reach(best_t) "
                    f"is kept (visited, its triangles tested), one entered beyond it culled"
                )
