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

import pytest
import test_lab2_accel as visible
import torch
from test_lab2_accel import (
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
from course.core.types import Mesh
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
