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
        got = checked(intersect(impl, variant, o[:, None], d[:, None], v0, v1, v2, lo, hi),
                      variant, (121, 37), dtype, device)
        eps = torch.finfo(dtype).eps
        ref = ref_triangle(o[:, None], d[:, None], v0, v1, v2, lo, hi, margin_eps=eps)
        assert ref[3].sum() > 20, "test set-up: too few hits"
        compare_hits(variant, f"hidden soup, 121 rays x 37 triangles with per-ray intervals, "
                     f"{dtype}", got, ref, eps)

    # Triangles with two corners opposite each other through the world origin (a quad centred
    # on the origin, split along a diagonal, has them): ordinary triangles all the same.
    g = generator(5157)
    a = torch.rand(3, 4, 3, generator=g, dtype=F64) * 2 - 1
    b = torch.rand(3, 4, 3, generator=g, dtype=F64) * 2 - 1
    tris = torch.cat([torch.stack([a[0], -a[0], b[0]], 1), torch.stack([a[1], b[1], -a[1]], 1),
                      torch.stack([b[2], a[2], -a[2]], 1)])
    o64, d64, _ = rays_at(tris, 60, seed=5158)
    for dtype in (torch.float32, F64):
        o, d, tri = (x.to(device, dtype) for x in (o64, d64, tris))
        v0, v1, v2 = tri[None, :, 0], tri[None, :, 1], tri[None, :, 2]
        got = checked(intersect(impl, variant, o[:, None], d[:, None], v0, v1, v2),
                      variant, (60, 12), dtype, device)
        eps = torch.finfo(dtype).eps
        ref = ref_triangle(o[:, None], d[:, None], v0, v1, v2, margin_eps=eps)
        assert ref[3].sum() > 20, "test set-up: too few hits"
        compare_hits(variant, f"12 triangles with v1 = -v0, v2 = -v0 or v2 = -v1 (two corners "
                     f"symmetric about the origin), 60 rays, {dtype}", got, ref, eps)


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
    near, far, hit = impl.ray_box(o.to(device), impl.safe_reciprocal(d.to(device)),
                                  lo.to(device), hi.to(device), t_min.to(device),
                                  t_max.to(device))
    hit = check_tensor(hit, "ray_box hit", shape=(n,), dtype=torch.bool, device=device).cpu()
    r_near, r_far, r_hit = ref_box(o, d, lo, hi, t_min, t_max)
    clear = (r_far - r_near).abs() > 1e-5 * (r_near.abs() + r_far.abs()).nan_to_num(0, 1, 1) \
        + 1e-6
    wrong = (hit != r_hit) & (clear | r_hit)
    assert not wrong.any(), (
        f"ray_box (hidden boxes and rays): {int(wrong.sum())} rays decided against the float64 "
        f"slabs, first ray {int(wrong.nonzero()[0, 0])}")
    both = hit & r_hit & clear
    for name, got, want in (("t_near", near, r_near), ("t_far", far, r_far)):
        assert_close(got.cpu().double()[both], want[both], rtol=1e-5, atol=1e-6,
                     name=f"ray_box {name} (hidden cases)", where="ray")
    g = generator(5155)
    centre = torch.rand(n, 3, generator=g, dtype=F64) * 4 - 2
    radius = torch.rand(n, generator=g, dtype=F64) * 0.8 + 0.05
    origin = torch.randn(n, 3, generator=g, dtype=F64) * 3
    aim = centre + torch.randn(n, 3, generator=g, dtype=F64) * radius[:, None]
    direction = aim - origin
    for dtype in (torch.float32, F64):
        t = impl.ray_sphere(origin.to(device, dtype), direction.to(device, dtype),
                            centre.to(device, dtype), radius.to(device, dtype))
        t = check_tensor(t[0] if isinstance(t, tuple) else t, "ray_sphere t", shape=(n,),
                         dtype=dtype, device=device).cpu().double()
        want, disc = ref_sphere(origin.to(dtype), direction.to(dtype), centre.to(dtype),
                                radius.to(dtype))
        clear = disc.abs() > 1e-3 * (direction.norm(dim=1) * radius) ** 2
        assert bool(((t < INF) == (want < INF))[clear].all()), (
            f"ray_sphere ({dtype}, hidden spheres): a clear-cut ray decided against the "
            f"float64 quadratic")
        hit = clear & (want < INF)
        assert_close(t[hit], want[hit], rtol=1e-4 if dtype == torch.float32 else 1e-10,
                     name=f"ray_sphere ({dtype}, hidden spheres): t", where="ray")


@pytest.mark.task(6)
@pytest.mark.points(0.5)
def test_closest_hit_hidden_soup(impl, device):
    rays, mesh, ref = soup_scene(77, 150, seed=5156, device=device)
    # the default variant first, as the visible test does: a skeleton earns nothing here;
    # on the given Möller–Trumbore, so a mistake in task 2 costs task 2 only
    hits = visible.closest(impl, rays, mesh, memory_budget_bytes=2**14)
    visible.check_hits(hits, len(rays), torch.float32, device, "default")
    compare_closest(hits, ref, "hidden soup of 77 + 2 triangles, the default variant, a 16 KB "
                    "memory budget")
    for variant in [v for v in visible.implemented_variants(impl) if v in TRIANGLE_KERNELS]:
        hits = impl.closest_hit(rays, mesh, variant, 2**14)
        visible.check_hits(hits, len(rays), torch.float32, device, variant)
        compare_closest(hits, ref, f"hidden soup of 77 + 2 triangles, variant={variant!r}, "
                        f"a 16 KB memory budget")
