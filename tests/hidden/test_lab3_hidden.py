"""Hidden grader for Lab 3 (not in the student handout; shown on Gradescope after the due
date): the contracts of the visible grader on views, image sizes, depth limits, pool sizes
and seeds it does not use, so a submission tuned to the visible inputs fails here.

Views: the Cornell box from a low corner (13 x 13 rays), and the courtyard moved by
(300, -20, 55) seen from the other side (float64 there: at that distance float32 has no
room for the 1e-4 offset). The renderers run with the given building blocks, as in the
visible grader, so each task is graded on its own.
"""

from __future__ import annotations

import dataclasses
import functools
import math

import pytest
import test_lab3_wavefront as visible
import torch
from test_lab3_wavefront import (
    F32,
    F64,
    INF,
    check_layout_hits,
    check_shadow_count,
    compare_images,
    expected_shadow_rays,
    random_frames,
    with_blocks,
)

from course.core.camera import primary_rays
from course.core.types import Mesh
from course.given.lab3 import (
    face_normals,
    make_scene,
    offset_scale,
    render_reference,
    trace_brute_force,
    translated,
    whitted_camera,
)
from course.grading.testing import assert_close, assert_equal, check_tensor, generator

LAB_MODULE = "lab3_wavefront"
TASKS = visible.TASKS
pytestmark = pytest.mark.visibility("after_due_date")

OFFSET = (300.0, -20.0, 55.0)
VIEWS = ("cornell_corner", "courtyard_moved")


def view(name: str, dtype, device):
    """(scene, origins, directions) of a hidden view."""
    if name == "cornell_corner":
        scene = visible.scene_on("cornell_mirror", dtype, device)
        camera = dataclasses.replace(
            whitted_camera("cornell_mirror"),
            eye=(0.8, 0.25, 2.6),
            target=(-0.3, 1.1, -0.4),
            width=13,
            height=13,
        )
        shift = torch.zeros(3, dtype=F64)
    else:
        scene = translated(visible.scene_on("courtyard_both", F64, device), OFFSET)
        camera = dataclasses.replace(
            visible.COURTYARD_CAMERA,
            eye=(-1.7, 1.2, -3.4),
            target=(0.3, 0.2, 0.1),
            width=11,
            height=11,
        )
        shift = torch.tensor(OFFSET, dtype=F64)
    rays = primary_rays(camera, device="cpu", dtype=F64)
    return scene, (rays.origins + shift).to(device, dtype), rays.directions.to(device, dtype)


def views(device):
    yield from (("cornell_corner", dtype) for dtype in (F32, F64))
    yield "courtyard_moved", F64


@functools.cache
def expected(name: str, dtype, max_depth: int) -> torch.Tensor:
    scene, o, d = view(name, dtype, "cpu")
    return render_reference(scene, o, d, max_depth)


def tol(name: str):
    return visible.FAR_TOL if name == "courtyard_moved" else None


@pytest.mark.task(1)
@pytest.mark.points(0.5)
def test_offset_origins_reflect_hidden_frames(impl, device):
    for dtype, seed in ((F32, 41), (F64, 42)):
        points, normals = random_frames(131, seed, dtype)
        got = check_tensor(
            impl.offset_origins(points.to(device), normals.to(device)),
            "offset_origins",
            shape=(131, 3),
            dtype=dtype,
            device=device,
        ).cpu()
        p, n = points.double(), normals.double()
        want = p + n * offset_scale(dtype) * p.abs().amax(1, keepdim=True).clamp(min=1)
        assert_close(
            got,
            want.to(dtype),
            rtol=4 * torch.finfo(dtype).eps,
            atol=torch.finfo(dtype).tiny,
            where="(ray, axis)",
            name=f"offset_origins ({dtype}, hidden frames)",
        )
        d = torch.randn(131, 3, generator=generator(seed + 1), dtype=F64)
        d = (d / d.norm(dim=1, keepdim=True)).to(dtype)
        r = check_tensor(
            impl.reflect(d.to(device), normals.to(device)),
            "reflect",
            shape=(131, 3),
            dtype=dtype,
            device=device,
        ).cpu()
        dd = d.double()
        eps = 8 * torch.finfo(dtype).eps
        assert_close(
            r,
            dd - 2 * (dd * n).sum(1, keepdim=True) * n,
            rtol=eps,
            atol=eps,
            where="(ray, axis)",
            name=f"reflect ({dtype}, hidden directions)",
        )


@pytest.mark.task(1)
@pytest.mark.points(0.5)
def test_surface_at_shade_direct_hidden_views(impl, device):
    for name, dtype in views(device):
        scene, o, d = view(name, dtype, device)
        zeros = torch.zeros(len(o), dtype=dtype, device=device)
        hits = trace_brute_force(scene, o, d, zeros, zeros + INF)
        points, normals, material = impl.surface_at(scene, o, d, hits)
        h = hits.hit
        n = face_normals(scene)[hits.triangle[h]]
        n = torch.where(((n * d[h]).sum(1) > 0)[:, None], -n, n)
        assert_close(
            normals[h].cpu().double(),
            n.cpu().double(),
            atol=16 * torch.finfo(dtype).eps,
            where="(hit, axis)",
            name=f"surface_at ({name}, {dtype}): normals facing the ray",
        )
        assert bool((material[~h] == -1).all()), f"surface_at ({name}): -1 where missed"
        p = o[h] + hits.t[h, None] * d[h]
        assert_close(
            points[h].cpu().double(),
            p.cpu().double(),
            rtol=16 * torch.finfo(dtype).eps,
            atol=16 * torch.finfo(dtype).eps,
            where="(hit, axis)",
            name=f"surface_at ({name}, {dtype}): points o + t d",
        )
        radiance, shadow_rays = impl.shade_direct(
            scene, p, n, d[h], scene.material[hits.triangle[h]], trace_brute_force
        )
        want = render_reference(scene.to("cpu"), o[h].cpu(), d[h].cpu(), 0)
        compare_images(
            radiance,
            want,
            f"shade_direct on the hidden view {name} ({dtype})",
            dtype,
            device,
            tol=tol(name),
        )
        check_shadow_count(
            shadow_rays,
            expected_shadow_rays(scene, p, n),
            f"shade_direct on the hidden view {name} ({dtype})",
        )


def grazing_frames(n: int, seed: int, light: torch.Tensor):
    """float32 hit frames where both the view and the light graze the surface: unit normals
    with ``n . l`` and ``-n . d`` of 1e-9 .. 1e-6, kept where ``n . d < 0 < n . l`` in
    float32 (facing the ray, the light above)."""
    g = generator(seed)
    l = light.double()
    u = torch.randn(n, 3, generator=g, dtype=F64)
    tilt = 10 ** (-3 * torch.rand(n, 2, generator=g, dtype=F64) - 6)
    normal = u - (u @ l)[:, None] * l + tilt[:, :1] * l
    normal = normal / normal.norm(dim=1, keepdim=True)
    t = torch.randn(n, 3, generator=g, dtype=F64)
    t = t - (t * normal).sum(1, keepdim=True) * normal - tilt[:, 1:] * normal
    normal, d = normal.float(), (t / t.norm(dim=1, keepdim=True)).float()
    keep = ((normal * d).sum(1) < 0) & ((normal * light.float()).sum(1) > 0)
    return normal[keep], d[keep]


@pytest.mark.task(1)
@pytest.mark.points(0.25)
def test_shade_direct_grazing_view_and_light(impl, device):
    """A view and a light that both graze the surface, a shininess of 12.5: h lies a hair
    above the surface, where rounding can put n . h below 0; max(0, n . h)^s keeps the
    radiance finite (a negative number to a fractional power is NaN)."""
    mesh = Mesh(
        torch.tensor([[-9.0, -9.0, -9.0], [-8.0, -9.0, -9.0], [-9.0, -8.0, -9.0]], device=device),
        torch.tensor([[0, 1, 2]], device=device),
    )
    scene = make_scene(
        mesh,
        [0],
        {"kd": [[0.5, 0.4, 0.3]], "ks": [[0.6, 0.6, 0.6]], "shininess": [12.5], "kr": [[0, 0, 0]]},
        dir_lights=[((0.3, 0.8, 0.5), (2.0, 2.0, 2.0))],
        ambient=(0.1, 0.1, 0.1),
    )
    light = scene.dir_directions[0].cpu()
    normals, d = grazing_frames(4000, 43, light)
    points = torch.rand(len(d), 3, generator=generator(44)).float()
    m = torch.zeros(len(d), dtype=torch.int64)
    radiance, _ = impl.shade_direct(
        scene, points.to(device), normals.to(device), d.to(device), m.to(device), trace_brute_force
    )
    radiance = (
        check_tensor(
            radiance, "shade_direct (grazing frames)", shape=(len(d), 3), dtype=F32, device=device
        )
        .cpu()
        .double()
    )
    n64, d64, l64 = normals.double(), d.double(), light.double()
    cos = n64 @ l64
    h = l64 - d64
    h = h / h.norm(dim=1, keepdim=True)
    lobe = (12.5 + 8) / (8 * math.pi) * (n64 * h).sum(1).clamp(min=0) ** 12.5
    kd, ks = scene.kd[0].cpu().double(), scene.ks[0].cpu().double()
    want = 0.1 * kd + torch.where(cos > 0, 2.0 * cos, 0)[:, None] * (
        kd / math.pi + ks * lobe[:, None]
    )
    bad = ~torch.isfinite(radiance).all(1)
    assert not bad.any(), (
        f"shade_direct: {int(bad.sum())} of {len(d)} grazing hits (view and light both within "
        f"1e-6 of the surface, shininess 12.5) give NaN, first hit {int(bad.nonzero()[0, 0])}: "
        f"rounding can make n . h slightly negative there; the lobe is max(0, n . h)^s"
    )
    assert_close(
        radiance,
        want,
        rtol=1e-5,
        atol=1e-6,
        where="(hit, channel)",
        name="shade_direct (grazing view and light): ambient plus a vanishing direct term",
    )


@pytest.mark.task(1)
@pytest.mark.points(0.5)
def test_render_whitted_hidden_views_and_depths(impl, device):
    for name, dtype in views(device):
        scene, o, d = view(name, dtype, device)
        for max_depth in (1, 3):
            image = with_blocks(impl, "render_whitted", scene, o, d, trace_brute_force, max_depth)
            compare_images(
                image,
                expected(name, dtype, max_depth),
                f"render_whitted on the hidden view {name}, max_depth={max_depth} ({dtype})",
                dtype,
                device,
                tol=tol(name),
            )


@pytest.mark.task(2)
@pytest.mark.points(0.5)
def test_render_wavefront_hidden_views_and_depths(impl, device):
    for name, dtype in views(device):
        scene, o, d = view(name, dtype, device)
        for max_depth, sort in ((1, True), (3, False)):
            image, stats = with_blocks(
                impl, "render_wavefront", scene, o, d, trace_brute_force, max_depth, sort
            )
            what = (
                f"render_wavefront on the hidden view {name}, max_depth={max_depth}, "
                f"sort_by_material={sort} ({dtype})"
            )
            compare_images(
                image, expected(name, dtype, max_depth), what, dtype, device, tol=tol(name)
            )
            assert stats["closest_rays"][0] == len(o), (
                f"{what}: stats['closest_rays'][0] is {stats['closest_rays'][0]}, expected "
                f"every primary ray ({len(o)})"
            )


@pytest.mark.task(3)
@pytest.mark.points(0.5)
def test_render_uber_hidden_views(impl, device):
    for name, dtype in views(device):
        scene, o, d = view(name, dtype, device)
        compare_images(
            impl.render_uber(scene, o, d, trace_brute_force, 3),
            expected(name, dtype, 3),
            f"render_uber on the hidden view {name}, max_depth=3 ({dtype})",
            dtype,
            device,
            tol=tol(name),
        )


@pytest.mark.task(4)
@pytest.mark.points(0.5)
def test_render_persistent_hidden_views_and_pools(impl, device):
    for name, dtype in views(device):
        scene, o, d = view(name, dtype, device)
        for pool_size in (7, 333):
            image, stats = with_blocks(
                impl, "render_persistent", scene, o, d, trace_brute_force, 2, pool_size
            )
            what = f"render_persistent on the hidden view {name}, pool_size={pool_size} ({dtype})"
            compare_images(image, expected(name, dtype, 2), what, dtype, device, tol=tol(name))
            assert max(stats["active_lanes"]) <= pool_size, (
                f"{what}: more active lanes than the pool has slots"
            )


@pytest.mark.task(5)
@pytest.mark.points(0.5)
def test_intersect_layout_hidden_soup(impl, device):
    for dtype, seed in ((F32, 77), (F64, 78)):
        g = generator(seed)
        corners = torch.rand(57, 3, 3, generator=g, dtype=F64).to(dtype)
        mesh = Mesh(
            corners.reshape(-1, 3).to(device), torch.arange(171, device=device).reshape(-1, 3)
        )
        scene = make_scene(
            mesh,
            torch.zeros(57, dtype=torch.int64),
            {"kd": [[1, 1, 1]], "ks": [[0, 0, 0]], "shininess": [1], "kr": [[0, 0, 0]]},
            dir_lights=[((0, 1, 0), (1, 1, 1))],
        )
        o, d, t_min, t_max = visible.soup_rays(dtype, device, 170, seed)
        want = trace_brute_force(scene, o, d, t_min, t_max)
        order = torch.randperm(57, generator=g).to(device)
        for what, layout in (
            ("indexed", impl.layout_indexed(mesh)),
            ("float4 in a shuffled order", impl.layout_float4(mesh, order)),
            ("woop", impl.layout_woop(mesh)),
        ):
            check_layout_hits(
                impl.intersect_layout(layout, o, d, t_min, t_max),
                want,
                f"intersect_layout ({what}, hidden soup, {dtype})",
                dtype,
            )


# ---------------------------------------------------------------- promises, one at a time

# Coplanar triangles at z = 2 (three pairs that cover the same points, two of them exact
# copies) and one at z = 3 behind them: rays along +z from z = 0 meet them at exactly t = 2
# (or 3), so ties in t are exact and t equals the bound of a closed interval exactly.
TIE_TRIANGLES = [
    [(10, 10, 2), (12, 10, 2), (10, 12, 2)],
    [(1, 1, 2), (3, 1, 2), (1, 3, 2)],
    [(0, 0, 2), (4, 0, 2), (0, 4, 2)],
    [(1, 1, 2), (1, 3, 2), (3, 1, 2)],  # triangle 1, wound the other way
    [(10, 10, 2), (12, 10, 2), (10, 12, 2)],  # a copy of triangle 0
    [(0, 0, 3), (20, 0, 3), (0, 20, 3)],
]
TIE_RAYS = [(1.5, 1.5), (0.5, 0.5), (10.5, 10.5), (5.0, 5.0), (30.0, 30.0), (2.0, 1.25)]


def tie_case(dtype, device):
    corners = torch.tensor(TIE_TRIANGLES, dtype=dtype)
    mesh = Mesh(
        corners.reshape(-1, 3).to(device),
        torch.arange(corners.shape[0] * 3).reshape(-1, 3).to(device),
    )
    scene = make_scene(
        mesh,
        torch.zeros(mesh.num_faces, dtype=torch.int64),
        {"kd": [[1, 1, 1]], "ks": [[0, 0, 0]], "shininess": [1], "kr": [[0, 0, 0]]},
        dir_lights=[((0, 1, 0), (1, 1, 1))],
    )
    xy = torch.tensor(TIE_RAYS, dtype=dtype)
    o = torch.cat((xy, torch.zeros(len(xy), 1, dtype=dtype)), 1).to(device)
    d = torch.tensor([[0.0, 0, 1]], dtype=dtype).expand(len(xy), 3).contiguous().to(device)
    return mesh, scene, o, d


@pytest.mark.task(5)
@pytest.mark.points(0.25)
@pytest.mark.parametrize("dtype", [F32, F64], ids=["f32", "f64"])
def test_intersect_layout_exact_ties_and_closed_interval(impl, device, dtype):
    mesh, scene, o, d = tie_case(dtype, device)
    n, f = len(o), mesh.num_faces
    reverse = torch.arange(f - 1, -1, -1, device=device)
    layouts = {
        "indexed": impl.layout_indexed(mesh),
        "woop": impl.layout_woop(mesh),
        "float4 in reverse order": impl.layout_float4(mesh, reverse),
    }
    zeros = torch.zeros(n, dtype=dtype, device=device)
    intervals = {
        "[0, inf]": (zeros, zeros + INF),
        "[2, 2] (a hit exactly at t_min = t_max)": (zeros + 2, zeros + 2),
        "[0, 2]": (zeros, zeros + 2),
        "[2, inf]": (zeros + 2, zeros + INF),
    }
    for what, layout in layouts.items():
        for interval, (t_min, t_max) in intervals.items():
            expected = trace_brute_force(scene, o, d, t_min, t_max)
            for pairs in (None, 2):
                if pairs is None:
                    hits = impl.intersect_layout(layout, o, d, t_min, t_max)
                else:
                    hits = impl.probe(
                        visible.intersect_in_small_tiles, pairs, layout, o, d, t_min, t_max
                    )
                case = (
                    f"intersect_layout ({what}, {dtype}, t in {interval}"
                    + (f", tiles of {pairs} pairs" if pairs else "")
                    + ")"
                )
                check_layout_hits(hits, expected, case, dtype)
                assert_equal(
                    hits.triangle.cpu(),
                    expected.triangle.cpu(),
                    where="ray",
                    name=f"{case}: triangle. Coplanar copies give exact ties in t, "
                    f"which go to the lowest original index whatever tile or "
                    f"slot they come in (an equal t in a later tile wins when "
                    f"its index is lower); the interval is closed",
                )


@pytest.mark.task(2)
@pytest.mark.points(0.25)
def test_render_wavefront_material_runs_in_queue_order(impl, device):
    scene = visible.scene_on("cornell_mirror", F64, device)
    o, d = visible.camera_rays("cornell_mirror", F64, device)
    zeros = torch.zeros(len(o), dtype=F64, device=device)
    hits = trace_brute_force(scene, o, d, zeros, zeros + INF)
    material = scene.material[hits.triangle[hits.hit]].cpu()
    runs = 1 + int((material[1:] != material[:-1]).sum())
    for sort, want in ((False, runs), (True, len(material.unique()))):
        _, stats = with_blocks(impl, "render_wavefront", scene, o, d, trace_brute_force, 1, sort)
        got = stats["material_runs"][0] if isinstance(stats, dict) else None
        assert got == want, (
            f"render_wavefront(sort_by_material={sort}) on the Cornell box: "
            f"stats['material_runs'][0] = {got!r}, expected {want}: the runs of equal "
            f"material in the shading queue as it is shaded (in pixel order when not sorted, "
            f"since compaction keeps the order; one run per material when sorted)"
        )
