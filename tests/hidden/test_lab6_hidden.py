"""Hidden grader for Lab 6 (not in the student handout; shown on Gradescope after the due
date): the contracts of the visible grader on meshes, viewports, seeds, lights and dtypes
it does not use, so a submission tuned to the visible inputs fails here.

As in the visible grader, each task is graded on its own (rasterize with the given
coverage, tasks 4-5 from the reference's visibility buffer) and the last task runs the
lab's whole pipeline.
"""

from __future__ import annotations

import dataclasses

import pytest
import test_lab6_raster as visible
import torch
from test_lab6_raster import (
    END_TO_END,
    F64,
    W_CASES,
    check_exactly_once,
    check_visibility,
    exact_clip_fraction,
    grid_mesh,
    layered_scene,
    rasterized,
    ray_plane_barycentrics,
    reference_keys,
    reference_shadows,
    resolved,
    scene,
    slanted_scene,
    trace_shadow_scene,
)

from course.core.camera import primary_rays
from course.grading.testing import (
    assert_close,
    assert_equal,
    assert_fraction,
    check_tensor,
    generator,
)

LAB_MODULE = "lab6_raster"
TASKS = visible.TASKS
reference = visible.reference  # the fixture: the reference's results of earlier tasks
pytestmark = pytest.mark.visibility("after_due_date")


def hidden_clip_cases(f: int, seed: int) -> torch.Tensor:
    """Random clip-space triangles, many crossing the near plane, some behind the eye."""
    g = generator(seed)
    w = torch.rand(f, 3, generator=g, dtype=F64) * 3 - 0.8
    xy = (torch.rand(f, 3, 2, generator=g, dtype=F64) * 2.4 - 1.2) * (w.abs()[..., None] + 0.3)
    z = (torch.rand(f, 3, generator=g, dtype=F64) * 2 - 1) * (w.abs() + 0.7)
    return torch.cat([xy, z[..., None], w[..., None]], -1)


@pytest.mark.task(1)
@pytest.mark.points(0.5)
def test_clip_triangles_hidden_cases(impl, device):
    clip64 = hidden_clip_cases(160, 6061)
    frac, keep, margin = exact_clip_fraction(clip64)
    assert bool((margin > 1e-4).all()), "test set-up: a clipped corner too close to w = 0"
    for dtype, tol in ((torch.float32, 1e-4), (F64, 1e-9)):
        clipped, source, weights = impl.clip_triangles(clip64.to(device, dtype))
        check_tensor(
            clipped, "clip_triangles(...)[0]", shape=(None, 3, 4), dtype=dtype, device=device
        )
        source, weights = source.cpu(), weights.cpu().double()
        area = torch.zeros(len(clip64), dtype=F64).index_add_(0, source, torch.linalg.det(weights))
        assert_close(
            area,
            torch.where(keep, frac, 0.0),
            atol=tol,
            name=(
                f"clip_triangles ({dtype}, hidden cases): the area of each input's outputs as a "
                f"fraction of its own (the part with z + w >= 0; 0 when rejected or with a "
                f"clipped corner at w <= 0)"
            ),
            where="input triangle",
        )
        assert bool((clipped[..., 3].cpu() > 0).all()), (
            f"clip_triangles ({dtype}, hidden cases): an output corner at w <= 0"
        )
    # The degenerate cases with their corners rotated: the corner order must not matter.
    names = list(W_CASES)
    clip = torch.tensor([W_CASES[n] for n in names], dtype=F64)[:, [2, 0, 1]]
    _, source, _ = impl.clip_triangles(clip.to(device))
    assert source.numel() == 0, (
        f"clip_triangles (corners rotated): the triangles with "
        f"{sorted({names[i] for i in source.cpu().tolist()})} came out: a corner at w <= 0 "
        f"must never reach the divide"
    )


@pytest.mark.task(2)
@pytest.mark.points(0.5)
def test_coverage_hidden_meshes(impl, device):
    # Edges through pixel centres on a 23 x 17 viewport, and a jittered mesh on the 1/16 grid.
    xs = torch.arange(-3.5, 27.0, 5.0)
    ys = torch.arange(-1.5, 21.0, 4.0)
    for flip in (None, True):
        check_exactly_once(
            impl,
            grid_mesh(xs, ys, flip=flip),
            23,
            17,
            f"hidden 23x17 grid, diagonals {flip}",
            device,
        )
    xs = torch.arange(-4.0, 28.0, 5.25, dtype=F64)  # on the 1/16 grid: an exact reference
    ys = torch.arange(-2.0, 20.0, 4.375, dtype=F64)
    jitter = (
        torch.round(
            (torch.rand(len(ys), len(xs), 2, generator=generator(6062), dtype=F64) - 0.5) * 2 * 16
        )
        / 16
    )
    jitter[0] = jitter[-1] = 0
    jitter[:, 0] = jitter[:, -1] = 0
    check_exactly_once(
        impl, grid_mesh(xs, ys, jitter), 23, 17, "hidden jittered mesh on the 1/16 grid", device
    )


@pytest.mark.task(3)
@pytest.mark.points(0.5)
def test_rasterize_hidden_layers(impl, device):
    screen, width, height = layered_scene(6063)
    for depth_bits, dtype in ((32, F64), (24, torch.float32)):
        want = reference_keys(screen.float().double(), width, height, depth_bits, dtype)
        keys = rasterized(
            impl,
            screen.float().to(device, dtype),
            width,
            height,
            depth_bits=depth_bits,
            memory_budget_bytes=2**12,
        )
        assert_equal(
            keys,
            want,
            name=(
                f"rasterize (hidden layered scene, depth_bits={depth_bits}, {dtype}, small "
                f"memory budget)"
            ),
            where="pixel",
        )


@pytest.mark.task(4)
@pytest.mark.points(0.5)
def test_perspective_correct_resolve_pixels_hidden(impl, reference, device):
    g = generator(6064)
    b = torch.rand(77, 3, generator=g, dtype=F64)
    b = b / b.sum(-1, keepdim=True)
    inv_w = torch.rand(77, 3, generator=g, dtype=F64) * 50 + 1e-3
    q = b * inv_w
    got = impl.perspective_correct(b.to(device), inv_w.to(device))
    assert_close(
        got,
        q / q.sum(-1, keepdim=True),
        atol=1e-14,
        name="perspective_correct (float64, hidden weights)",
        where="point",
    )
    mesh, _, camera = slanted_scene(device, F64)
    camera = dataclasses.replace(camera, width=53, height=37, eye=(0.3, 0.5, 0.9))
    face, bary = resolved(impl, reference, mesh, camera)
    covered = face >= 0
    rays = primary_rays(camera, device="cpu", dtype=F64)
    f = face.reshape(-1)[covered.reshape(-1)]
    exact, _ = ray_plane_barycentrics(
        mesh.triangles().cpu()[f],
        rays.origins[covered.reshape(-1)],
        rays.directions[covered.reshape(-1)],
    )
    assert_close(
        bary[covered].double(),
        exact,
        atol=1e-9,
        name=(
            "resolve_pixels (float64, hidden 53x37 view of the slanted floor): barycentrics vs the "
            "exact ray/plane point"
        ),
        where="covered pixel",
    )


@pytest.mark.task(5)
@pytest.mark.points(0.5)
def test_hybrid_shadows_hidden_light(impl, reference, device):
    mesh, camera = scene("shadow_scene")
    light = torch.tensor([-0.3, 0.6, 0.8])
    face, bary = (x.cpu() for x in reference.rasterize_mesh(mesh.to(device), camera))
    shadowed = check_tensor(
        impl.hybrid_shadows(
            trace_shadow_scene, mesh.to(device), face.to(device), bary.to(device), light.to(device)
        ),
        "hybrid_shadows(...)",
        shape=face.shape,
        dtype=torch.bool,
        device=device,
    ).cpu()
    _, ref_shadowed, _ = reference_shadows(mesh, camera, light)
    assert 0.02 < ref_shadowed.double().mean().item() < 0.7, "test set-up: shadow fraction"
    assert_fraction(
        shadowed.reshape(-1) != ref_shadowed,
        name=("hybrid_shadows (hidden light direction) vs float64 shadow rays"),
        at_most=0.02,
        where="pixel",
    )


@pytest.mark.task(END_TO_END)
@pytest.mark.points(0.5)
def test_rasterize_mesh_hidden_viewport(impl, device):
    mesh, camera = scene("suzanne")
    camera = dataclasses.replace(camera, width=71, height=53)
    face, _ = visible.pipeline(impl, mesh.to(device), camera)
    check_visibility(
        face, mesh, camera, "rasterize_mesh of Suzanne (hidden 71x53 view)", agree=0.995
    )
