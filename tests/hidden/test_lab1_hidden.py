"""Hidden grader for Lab 1 (not in the student handout; shown on Gradescope after the due
date): the contracts of the visible grader on soups, seeds, ray intervals, boxes, spheres
and dtypes it does not use, so a submission tuned to the visible inputs fails here.

The references are the visible grader's (Cramer's rule, slabs, the sphere's quadratic, all
in float64, judging only the clear-cut pairs).
"""

from __future__ import annotations

import pytest
import test_lab1_intersect as visible
import torch
from test_lab1_intersect import (
    F64,
    INF,
    TRIANGLE_KERNELS,
    checked,
    compare_closest,
    compare_hits,
    intersect,
    rays_at,
    ref_box,
    ref_sphere,
    ref_triangle,
    soup,
    soup_scene,
)

from course.grading.testing import assert_close, check_tensor, generator

LAB_MODULE = "lab1_intersect"
TASKS = visible.TASKS
pytestmark = pytest.mark.visibility("after_due_date")


def check_kernel_hidden(impl, variant, device):
    """One kernel on a soup of 37 triangles far from the unit cube's corner, 121 rays with
    their own [t_min, t_max] intervals, and on triangles with corners symmetric about the
    origin, in float32 and float64."""
    tris = soup(37, seed=5151) * 3 - 1
    o64, d64, _ = rays_at(tris, 121, seed=5152)
    g = generator(5153)
    t_min = torch.where(torch.rand(121, 1, generator=g) < 0.3, 0.4, 0.0).double()
    t_max = torch.where(torch.rand(121, 1, generator=g) < 0.3, 0.9, INF).double()
    for dtype in (torch.float32, F64):
        o, d, tri, lo, hi = (x.to(device, dtype) for x in (o64, d64, tris, t_min, t_max))
        v0, v1, v2 = tri[None, :, 0], tri[None, :, 1], tri[None, :, 2]
        got = checked(
            intersect(impl, variant, o[:, None], d[:, None], v0, v1, v2, lo, hi),
            variant,
            (121, 37),
            dtype,
            device,
        )
        eps = torch.finfo(dtype).eps
        ref = ref_triangle(o[:, None], d[:, None], v0, v1, v2, lo, hi, margin_eps=eps)
        assert ref[3].sum() > 20, "test set-up: too few hits"
        compare_hits(
            variant,
            f"hidden soup, 121 rays x 37 triangles with per-ray intervals, {dtype}",
            got,
            ref,
            eps,
        )

    # Triangles with two corners opposite each other through the world origin (a quad centred
    # on the origin, split along a diagonal, has them): ordinary triangles all the same.
    g = generator(5157)
    a = torch.rand(3, 4, 3, generator=g, dtype=F64) * 2 - 1
    b = torch.rand(3, 4, 3, generator=g, dtype=F64) * 2 - 1
    tris = torch.cat(
        [
            torch.stack([a[0], -a[0], b[0]], 1),
            torch.stack([a[1], b[1], -a[1]], 1),
            torch.stack([b[2], a[2], -a[2]], 1),
        ]
    )
    o64, d64, _ = rays_at(tris, 60, seed=5158)
    for dtype in (torch.float32, F64):
        o, d, tri = (x.to(device, dtype) for x in (o64, d64, tris))
        v0, v1, v2 = tri[None, :, 0], tri[None, :, 1], tri[None, :, 2]
        got = checked(
            intersect(impl, variant, o[:, None], d[:, None], v0, v1, v2),
            variant,
            (60, 12),
            dtype,
            device,
        )
        eps = torch.finfo(dtype).eps
        ref = ref_triangle(o[:, None], d[:, None], v0, v1, v2, margin_eps=eps)
        assert ref[3].sum() > 20, "test set-up: too few hits"
        compare_hits(
            variant,
            f"12 triangles with v1 = -v0, v2 = -v0 or v2 = -v1 (two corners "
            f"symmetric about the origin), 60 rays, {dtype}",
            got,
            ref,
            eps,
        )


@pytest.mark.task(1)
@pytest.mark.points(0.5)
def test_intersect_simple_hidden_soup(impl, device):
    check_kernel_hidden(impl, "intersect_simple", device)


@pytest.mark.task(2)
@pytest.mark.points(0.5)
def test_moller_trumbore_hidden_soup(impl, device):
    check_kernel_hidden(impl, "moller_trumbore", device)


@pytest.mark.task(3)
@pytest.mark.points(0.5)
def test_woop_unit_hidden_soup(impl, device):
    check_kernel_hidden(impl, "woop_unit", device)


@pytest.mark.task(4)
@pytest.mark.points(0.5)
def test_watertight_hidden_soup(impl, device):
    check_kernel_hidden(impl, "watertight", device)


@pytest.mark.task(5)
@pytest.mark.points(0.5)
def test_ray_box_ray_sphere_hidden_cases(impl, device):
    n = 257
    o, d, lo, hi = visible.box_case(n, seed=5154)
    t_min = torch.where(torch.arange(n) % 4 == 1, 0.2, 0.0)
    t_max = torch.where(torch.arange(n) % 6 == 2, 0.7, INF)
    near, far, hit = impl.ray_box(
        o.to(device),
        impl.safe_reciprocal(d.to(device)),
        lo.to(device),
        hi.to(device),
        t_min.to(device),
        t_max.to(device),
    )
    hit = check_tensor(hit, "ray_box hit", shape=(n,), dtype=torch.bool, device=device).cpu()
    r_near, r_far, r_hit = ref_box(o, d, lo, hi, t_min, t_max)
    clear = (r_far - r_near).abs() > 1e-5 * (r_near.abs() + r_far.abs()).nan_to_num(0, 1, 1) + 1e-6
    wrong = (hit != r_hit) & (clear | r_hit)
    assert not wrong.any(), (
        f"ray_box (hidden boxes and rays): {int(wrong.sum())} rays decided against the float64 "
        f"slabs, first ray {int(wrong.nonzero()[0, 0])}"
    )
    both = hit & r_hit & clear
    for name, got, want in (("t_near", near, r_near), ("t_far", far, r_far)):
        assert_close(
            got.cpu().double()[both],
            want[both],
            rtol=1e-5,
            atol=1e-6,
            name=f"ray_box {name} (hidden cases)",
            where="ray",
        )
    g = generator(5155)
    centre = torch.rand(n, 3, generator=g, dtype=F64) * 4 - 2
    radius = torch.rand(n, generator=g, dtype=F64) * 0.8 + 0.05
    origin = torch.randn(n, 3, generator=g, dtype=F64) * 3
    aim = centre + torch.randn(n, 3, generator=g, dtype=F64) * radius[:, None]
    direction = aim - origin
    for dtype in (torch.float32, F64):
        t = impl.ray_sphere(
            origin.to(device, dtype),
            direction.to(device, dtype),
            centre.to(device, dtype),
            radius.to(device, dtype),
        )
        t = (
            check_tensor(
                t[0] if isinstance(t, tuple) else t,
                "ray_sphere t",
                shape=(n,),
                dtype=dtype,
                device=device,
            )
            .cpu()
            .double()
        )
        want, disc = ref_sphere(
            origin.to(dtype), direction.to(dtype), centre.to(dtype), radius.to(dtype)
        )
        clear = disc.abs() > 1e-3 * (direction.norm(dim=1) * radius) ** 2
        assert bool(((t < INF) == (want < INF))[clear].all()), (
            f"ray_sphere ({dtype}, hidden spheres): a clear-cut ray decided against the "
            f"float64 quadratic"
        )
        hit = clear & (want < INF)
        assert_close(
            t[hit],
            want[hit],
            rtol=1e-4 if dtype == torch.float32 else 1e-10,
            name=f"ray_sphere ({dtype}, hidden spheres): t",
            where="ray",
        )


@pytest.mark.task(6)
@pytest.mark.points(0.5)
def test_closest_hit_hidden_soup(impl, device):
    rays, mesh, ref = soup_scene(77, 150, seed=5156, device=device)
    # the default variant first, as the visible test does: a skeleton earns nothing here;
    # on the given Möller–Trumbore, so a mistake in task 2 costs task 2 only
    hits = visible.closest(impl, rays, mesh, memory_budget_bytes=2**14)
    visible.check_hits(hits, len(rays), torch.float32, device, "default")
    compare_closest(
        hits, ref, "hidden soup of 77 + 2 triangles, the default variant, a 16 KB memory budget"
    )
    for variant in [v for v in visible.implemented_variants(impl) if v in TRIANGLE_KERNELS]:
        hits = impl.closest_hit(rays, mesh, variant, 2**14)
        visible.check_hits(hits, len(rays), torch.float32, device, variant)
        compare_closest(
            hits,
            ref,
            f"hidden soup of 77 + 2 triangles, variant={variant!r}, a 16 KB memory budget",
        )


# ---------------------------------------------------------------- promises, one at a time

# Direction lengths far from 1: "directions need not be unit length (t is in units of the
# direction's length)", so every tolerance that involves d must scale with |d|.
LENGTHS = (1e-4, 1.0, 1e2)


def grazing_case(slope: float):
    """Rays ``slope`` off the plane z = 0 of the triangle (0,0,0), (1,0,0), (0,1,0), each
    crossing it at t = 0.3 (unit speed along (1, 0.2, -slope)): four well inside, two well
    outside. Returns float64 ``o, d, v0, v1, v2`` and the expected hits."""
    starts = torch.tensor(
        [[0.1, 0.3], [0.2, 0.1], [0.05, 0.05], [0.3, 0.25], [0.9, 0.6], [-0.5, 0.2]], dtype=F64
    )
    o = torch.cat((starts, torch.full((6, 1), 0.3 * slope, dtype=F64)), 1)
    d = torch.tensor([1.0, 0.2, -slope], dtype=F64).expand(6, 3)
    cross = starts + 0.3 * torch.tensor([1.0, 0.2], dtype=F64)
    inside = (cross >= 0).all(1) & (cross.sum(1) <= 1)
    corners = torch.tensor([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype=F64)
    return o, d, *(c.expand(6, 3) for c in corners), inside


def check_any_direction_length(impl, device, variant):
    for slope in (3e-4, 2e-3):
        o, d, v0, v1, v2, inside = grazing_case(slope)
        for dtype in (torch.float32, F64):
            for k in LENGTHS:
                args = [x.to(device, dtype) for x in (o, d * k, v0, v1, v2)]
                t, _, _ = checked(intersect(impl, variant, *args), variant, (6,), dtype, device)
                t = t.cpu().double()
                hit = t < INF
                case = (
                    f"{variant} ({dtype}): rays {slope:g} off the triangle's plane with "
                    f"directions of length {k:g}"
                )
                assert bool((hit == inside).all()), (
                    f"{case}: hits {hit.tolist()}, expected {inside.tolist()} (the same as "
                    f"with unit directions). A tolerance that compares a quantity scaled by "
                    f"|d| with one that is not (e.g. |det| against eps |e1| |e2| without "
                    f"|d|) decides differently for short and long directions."
                )
                assert_close(
                    t[inside] * k,
                    torch.full((int(inside.sum()),), 0.3, dtype=F64),
                    rtol=2e-3 if dtype == torch.float32 else 1e-9,
                    name=f"{case}: t * |d| (t is in units of |d|)",
                    where="ray",
                )


@pytest.mark.task(1)
@pytest.mark.points(0.25)
def test_intersect_simple_any_direction_length(impl, device):
    check_any_direction_length(impl, device, "intersect_simple")


@pytest.mark.task(2)
@pytest.mark.points(0.25)
def test_moller_trumbore_any_direction_length(impl, device):
    check_any_direction_length(impl, device, "moller_trumbore")


@pytest.mark.task(3)
@pytest.mark.points(0.25)
def test_woop_unit_any_direction_length(impl, device):
    check_any_direction_length(impl, device, "woop_unit")


@pytest.mark.task(4)
@pytest.mark.points(0.25)
def test_watertight_any_direction_length(impl, device):
    check_any_direction_length(impl, device, "watertight")


def woop_float64(v0, v1, v2):
    """The map of ``woop_precompute``'s docstring, in float64: the inverse of the frame
    [e1 e2 n] (unit n) and the offsets -r . v0, by a route of its own (a linear solve)."""
    e1, e2 = v1 - v0, v2 - v0
    n = torch.linalg.cross(e1, e2, dim=-1)
    n = n / n.norm(dim=-1, keepdim=True)
    frame = torch.stack((e1, e2, n), dim=-1)
    rows = torch.linalg.solve(frame, torch.eye(3, dtype=F64).expand_as(frame))
    return torch.cat((rows, -(rows @ v0[..., None])), dim=-1)


@pytest.mark.task(3)
@pytest.mark.points(0.25)
def test_woop_precompute_rounded_once_from_float64(impl, device):
    g = generator(5157)
    v0 = torch.randn(64, 3, generator=g, dtype=F64) * 4
    v1 = v0 + torch.randn(64, 3, generator=g, dtype=F64)
    v2 = v0 + torch.randn(64, 3, generator=g, dtype=F64)
    got = impl.woop_precompute(*(x.float().to(device) for x in (v0, v1, v2)))
    got = (
        check_tensor(
            got, "woop_precompute(...)", shape=(64, 3, 4), dtype=torch.float32, device=device
        )
        .cpu()
        .double()
    )
    # The float32 corners are the input: the float64 map of *those* corners, rounded once,
    # is within one float32 ulp (2**-23 relative) of each entry; entries that cancel to
    # about zero get an allowance from the size of their row.
    want = woop_float64(*(x.float().double() for x in (v0, v1, v2)))
    scale = want.abs().amax(-1, keepdim=True).expand_as(want)
    assert_close(
        got,
        want,
        rtol=2.0**-23,
        atol=0,
        mask=want.abs() > 1e-6 * scale,
        name="woop_precompute in float32: each entry against the float64 map rounded "
        "once (about one ulp; compute it in float64 and cast at the end)",
        where="(triangle, row, column)",
    )
    # The third row is the unit normal: z' is the signed distance from the plane, and
    # v0 + n goes to (0, 0, 1).
    n = torch.linalg.cross(v1 - v0, v2 - v0, dim=-1)
    n = n / n.norm(dim=-1, keepdim=True)
    lifted = torch.cat((v0 + n, torch.ones(64, 1, dtype=F64)), 1)[..., None]
    image = (got @ lifted)[..., 0]
    assert_close(
        image,
        torch.tensor([0.0, 0, 1]).double().expand(64, 3),
        atol=1e-5,
        name="woop_precompute: the transform applied to v0 + n (unit normal) should "
        "be (0, 0, 1): the third row is n itself, not e1 x e2",
        where="triangle",
    )


@pytest.mark.task(5)
@pytest.mark.points(0.25)
def test_ray_sphere_negative_radius_misses(impl, device):
    o = torch.tensor([[0.0, 0, -5], [0, 0, 0], [0.2, 0.1, -3]], device=device)
    d = torch.tensor([[0.0, 0, 1], [1, 0, 0], [0, 0, 2]], device=device)
    centre = torch.zeros(3, 3, device=device)
    for radius in (-1.0, torch.tensor([-1.0, -0.5, -2.0], device=device)):
        t = impl.ray_sphere(o, d, centre, radius)
        t = check_tensor(t, "ray_sphere t", shape=(3,), dtype=torch.float32, device=device)
        assert bool((t.cpu() == INF).all()), (
            f"ray_sphere with a negative radius ({radius}) returned t = {t.cpu().tolist()}: "
            f"the docstring says a negative radius gives inf. r * r hides the sign, so test "
            f"r >= 0 yourself."
        )
