"""Hidden grader for Lab 4 (not in the student handout; shown on Gradescope after the due
date): the contracts of the visible grader on boxes, media, grids, seeds, step counts and
dtypes it does not use, so a submission tuned to the visible inputs fails here.

The references are the visible grader's (slabs, closed forms, exact sums over voxels,
analytic sphere and box hits, all in float64).
"""

from __future__ import annotations

import math

import pytest
import test_lab4_march as visible
import torch
from test_lab4_march import (
    BOX_C,
    BOX_H,
    F64,
    HIT,
    MISS,
    SPHERE_C,
    SPHERE_R,
    bad_rays,
    box_rays,
    march,
    phi,
    ref_box_hit,
    ref_interval,
    ref_optical_depth,
    ref_phase,
    ref_sphere_hit,
    sdf_two_solids,
    sparse_grid,
    trace,
    walk,
)

from course.grading.testing import assert_close, check_tensor

LAB_MODULE = "lab4_march"
TASKS = visible.TASKS
pytestmark = pytest.mark.visibility("after_due_date")

# A box the visible grader does not use (corners exact in float32, as the references take
# them from Python floats).
LO, HI = (-0.375, 0.25, -1.125), (0.875, 1.375, 0.125)


@pytest.mark.task(1)
@pytest.mark.points(0.5)
def test_ray_box_interval_march_box_hidden_box(impl, device):
    o, d = box_rays(311, seed=4141, lo=LO, hi=HI)
    bo, bd = bad_rays()
    o, d = torch.cat([o, bo]), torch.cat([d, bd])
    near, far, hit = ref_interval(o, d, LO, HI)
    clear = ~hit | ((far - near) > 1e-6)
    length = torch.where(hit, (far - near) * d.norm(dim=-1).nan_to_num(0), torch.zeros_like(near))
    sigma, q = 0.35, 1.3
    for dtype, tol in ((F64, 1e-12), (torch.float32, 3e-6)):
        lo = torch.tensor(LO, dtype=dtype, device=device)
        hi = torch.tensor(HI, dtype=dtype, device=device)
        got_near, got_far, got_hit = impl.ray_box_interval(
            o.to(device, dtype), d.to(device, dtype), lo, hi
        )
        got_hit = got_hit.cpu()
        assert bool((got_hit == hit)[clear].all()), (
            f"ray_box_interval ({dtype}, hidden box): a clear-cut ray decided wrongly"
        )
        both = got_hit & hit
        assert_close(
            got_near.cpu().double()[both],
            near[both],
            rtol=tol,
            atol=tol,
            name=f"ray_box_interval ({dtype}, hidden box): t_near",
            where="hit",
        )
        assert_close(
            got_far.cpu().double()[both],
            far[both],
            rtol=tol,
            atol=tol,
            name=f"ray_box_interval ({dtype}, hidden box): t_far",
            where="hit",
        )
        dens = torch.full((2, 1, 3), sigma, dtype=dtype, device=device)
        emis = torch.full((1, 2, 1), q, dtype=dtype, device=device)
        what = f"march_box (hidden box, sigma={sigma}, q={q}, {dtype}, steps=7)"
        got = march(
            impl,
            o.to(device, dtype),
            d.to(device, dtype),
            lo,
            hi,
            dens,
            emis,
            7,
            what=what,
            n=len(o),
            dtype=dtype,
            device=device,
        )
        assert_close(
            got["radiance"].cpu()[clear],
            (q * length * phi(sigma * length))[clear],
            rtol=tol,
            atol=tol,
            name=f"{what}: radiance q (1 - e^(-sigma D)) / sigma",
            where="ray",
        )
        assert_close(
            got["transmittance"].cpu()[clear],
            torch.exp(-sigma * length)[clear],
            rtol=tol,
            atol=tol,
            name=f"{what}: transmittance",
            where="ray",
        )


@pytest.mark.task(2)
@pytest.mark.points(0.5)
def test_segment_integral_hidden_values(impl, device):
    x = torch.cat([torch.tensor([0.0, 5e-324]), 10.0 ** torch.linspace(-25, 3, 41, dtype=F64)])
    lengths = torch.tensor([3e-2, 2.5], dtype=F64)
    sigma = x[:, None] / lengths[None, :]
    for dtype, tol in ((F64, 4e-15), (torch.float32, 4e-7)):
        s, ln = sigma.to(device, dtype), lengths[None, :].to(device, dtype)
        w, t = impl.segment_integral(s, ln, "exact")
        w = check_tensor(
            w, "segment_integral weight", shape=tuple(sigma.shape), dtype=dtype, device=device
        )
        s64, l64 = s.cpu().double(), ln.cpu().double()
        assert_close(
            w,
            l64 * phi(s64 * l64),
            rtol=tol,
            atol=0,
            where="(x, length)",
            name=f"segment_integral ({dtype}, hidden sigma D): weight (1 - e^(-sigma D)) / sigma",
        )
        x64 = s64 * l64
        assert_close(
            t.cpu().double(),
            torch.exp(-x64),
            rtol=tol * 80,
            atol=0,
            mask=x64 < 80,
            where="(x, length)",
            name=f"segment_integral ({dtype}): transmittance",
        )


@pytest.mark.task(3)
@pytest.mark.points(0.5)
def test_henyey_greenstein_hidden_g(impl, device):
    theta = torch.linspace(0, math.pi, 200001, dtype=F64)
    cos, sin = torch.cos(theta), torch.sin(theta)
    for g in (-0.75, -0.2, 0.45, 0.8):
        p = check_tensor(
            impl.henyey_greenstein(cos.to(device), g),
            f"henyey_greenstein(cos, {g})",
            shape=(len(cos),),
            dtype=F64,
            device=device,
        ).cpu()
        total = 2 * math.pi * torch.trapezoid(p * sin, theta).item()
        assert abs(total - 1) < 1e-4, f"henyey_greenstein(g={g}): integrates to {total:.6f}"
        assert_close(
            p[::997],
            ref_phase(cos[::997], g),
            rtol=1e-12,
            name=f"henyey_greenstein(g={g}, hidden)",
            where="angle",
        )


@pytest.mark.task(4)
@pytest.mark.points(0.5)
def test_voxel_walk_hidden_grid(impl, device):
    grid = sparse_grid((5, 8, 3), seed=4143, fill=0.55)
    o, d = box_rays(250, seed=4144, lo=LO, hi=HI)
    for dtype, eps in ((F64, 2.2e-16), (torch.float32, 1.2e-7)):
        oo, dd, gg = o.to(dtype), d.to(dtype), grid.to(dtype)
        lo, hi = torch.tensor(LO, dtype=dtype), torch.tensor(HI, dtype=dtype)
        want, _ = ref_optical_depth(oo, dd, lo, hi, gg)
        what = f"voxel_walk ({dtype}, hidden 5x8x3 grid)"
        got = walk(
            impl,
            oo.to(device),
            dd.to(device),
            lo.to(device),
            hi.to(device),
            gg.to(device),
            what=what,
            n=len(o),
            dtype=dtype,
            device=device,
        )
        scale = 2.0 * (dd.double().norm(dim=-1) * 3).nan_to_num(0) + 1
        assert_close(
            got["optical_depth"].cpu().double() / scale,
            want / scale,
            atol=64 * eps,
            name=f"{what}: optical depth against the exact sum over the voxels",
            where="ray",
        )


@pytest.mark.task(5)
@pytest.mark.points(0.5)
def test_sphere_trace_hidden_rays(impl, device):
    o, d = visible.camera_rays(300, seed=4145, spread=0.35)
    ts, cs, clear_s = ref_sphere_hit(o, d, SPHERE_C, SPHERE_R)
    tb, cb, depth_b = ref_box_hit(o, d, BOX_C, BOX_H)
    t_ref, cos = torch.minimum(ts, tb), torch.where(ts <= tb, cs, cb)
    b_lo = torch.tensor(BOX_C, dtype=F64) - torch.tensor(BOX_H, dtype=F64)
    b_hi = torch.tensor(BOX_C, dtype=F64) + torch.tensor(BOX_H, dtype=F64)
    judged_hit = (
        torch.isfinite(t_ref)
        & (cos > 0.2)
        & ((ts <= tb) & (clear_s < -0.05) | (tb < ts) & (depth_b > 0.05))
    )
    judged_miss = (
        ~torch.isfinite(t_ref) & (clear_s > 0.05) & ~ref_interval(o, d, b_lo - 0.05, b_hi + 0.05)[2]
    )
    assert judged_hit.sum() > 30 and judged_miss.sum() > 30, "test set-up: hits and misses"
    eps = 3e-5
    for dtype in (F64, torch.float32):
        what = f"sphere_trace (hidden rays, {dtype}, epsilon={eps:g})"
        got = trace(
            impl,
            o.to(device, dtype),
            d.to(device, dtype),
            sdf_two_solids,
            t_max=40.0,
            max_steps=500,
            epsilon=eps,
            what=what,
            n=300,
            dtype=dtype,
            device=device,
        )
        status, t = got["status"].cpu(), got["t"].cpu().double()
        assert bool((status[judged_hit] == HIT).all()), f"{what}: a clear hit not reported"
        assert bool((status[judged_miss] == MISS).all()), f"{what}: a clear miss not MISS"
        bound = (4 * eps / cos + 1e-6) * t_ref
        assert_close(
            t[judged_hit],
            t_ref[judged_hit],
            atol=0,
            rtol=float((bound / t_ref)[judged_hit].max()),
            name=f"{what}: t of the hits against the analytic surfaces",
            where="ray",
        )
