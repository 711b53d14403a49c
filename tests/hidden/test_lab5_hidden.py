"""Hidden grader for Lab 5 (not in the student handout; shown on Gradescope after the due
date): the contracts of the visible grader on slicings, phase asymmetries, volumes, blend
factors, seeds and dtypes it does not use, so a submission tuned to the visible inputs
fails here. The references are the formulas themselves, in float64.
"""

from __future__ import annotations

import pytest
import test_lab5_froxel as visible
import torch
from test_lab5_froxel import F32, F64, hg, phi64, quadrature, ref_depths

from course.grading.testing import assert_close, check_tensor, generator

LAB_MODULE = "lab5_froxel"
TASKS = visible.TASKS
pytestmark = pytest.mark.visibility("after_due_date")


@pytest.mark.task(1)
@pytest.mark.points(0.5)
def test_slice_depths_depth_to_slice_hidden_slicings(impl, device):
    g = generator(5051)
    for near, far, slices in ((0.05, 250.0, 24), (3.0, 7.5, 5), (1e-3, 1e3, 97)):
        for dtype, rtol in ((F64, 1e-12), (F32, 1e-6)):
            z = check_tensor(
                impl.slice_depths(near, far, slices, dtype, device),
                f"slice_depths({near}, {far}, {slices})",
                shape=(slices + 1,),
                dtype=dtype,
                device=device,
            )
            assert_close(
                z,
                ref_depths(near, far, slices),
                rtol=rtol,
                where="boundary",
                name=f"slice_depths({near}, {far}, {slices}, {dtype}, hidden)",
            )
        k = torch.rand(211, generator=g, dtype=F64) * slices
        depth = near * (far / near) ** (k / slices)
        for dtype, atol in ((F64, 1e-9), (F32, 3e-5 * slices)):
            got = impl.depth_to_slice(depth.to(dtype).to(device), near, far, slices)
            assert_close(
                got,
                k,
                atol=atol,
                where="depth",
                name=f"depth_to_slice (near={near}, far={far}, {dtype}, hidden)",
            )


@pytest.mark.task(3)
@pytest.mark.points(0.5)
def test_henyey_greenstein_hidden_g(impl, device):
    c = torch.linspace(-1, 1, 53, dtype=F64)
    for g in (-0.8, -0.15, 0.6, 0.95):
        got = check_tensor(
            impl.henyey_greenstein(c.to(device), g),
            f"henyey_greenstein(g={g})",
            shape=(53,),
            dtype=F64,
            device=device,
        )
        assert_close(
            got,
            hg(c, g),
            rtol=1e-10,
            where="cos index",
            name=f"henyey_greenstein(cos, g={g}, hidden)",
        )
        total, mean = quadrature(lambda x, gg: impl.henyey_greenstein(x.to(device), gg), g)
        assert abs(total - 1) < 2e-3 and abs(mean - g) < 2e-3, (
            f"henyey_greenstein(g={g}): integral {total:.5f} (want 1), mean cosine {mean:.5f} "
            f"(want g)"
        )


@pytest.mark.task(5)
@pytest.mark.points(0.5)
def test_temporal_blend_hidden_volume(impl, device):
    g = generator(5053)
    cur = torch.rand(3, 7, 2, 4, generator=g, dtype=F64)
    his = torch.rand(3, 7, 2, 4, generator=g, dtype=F64)
    valid = torch.rand(3, 7, 2, generator=g) < 0.4
    for alpha in (0.2, 0.05):
        got = impl.temporal_blend(cur.to(device), his.to(device), valid.to(device), alpha)
        want = torch.where(valid[..., None], (1 - alpha) * his + alpha * cur, cur)
        assert_close(
            got,
            want,
            rtol=1e-12,
            atol=1e-15,
            where="froxel [k, j, i, c]",
            name=f"temporal_blend(alpha={alpha}) of a hidden 3x7x2 volume, 4 channels",
        )


@pytest.mark.task(6)
@pytest.mark.points(0.5)
def test_slice_integral_hidden_values(impl, device):
    g = generator(5054)
    s = torch.rand(150, 2, generator=g, dtype=F64) * 5
    sigma = 10 ** (torch.rand(150, generator=g, dtype=F64) * 10 - 7)
    d = 10 ** (torch.rand(150, generator=g, dtype=F64) * 3 - 1)
    for dtype, rtol in ((F64, 1e-12), (F32, 2e-6)):
        integral, trans = impl.slice_integral(
            s.to(dtype).to(device), sigma.to(dtype).to(device), d.to(dtype).to(device)
        )
        check_tensor(
            integral, "slice_integral integral", shape=(150, 2), dtype=dtype, device=device
        )
        sig, length = sigma.to(dtype).double(), d.to(dtype).double()
        tau = sig * length
        assert_close(
            integral,
            s.to(dtype).double() * (length * phi64(tau))[:, None],
            rtol=rtol * 4,
            atol=1e-30,
            where="element",
            name=f"slice_integral ({dtype}, hidden values): (S - S e^(-sigma D)) / sigma",
        )
        assert_close(
            trans,
            torch.exp(-tau),
            rtol=rtol * 4,
            atol=torch.finfo(dtype).tiny,
            where="element",
            name=f"slice_integral ({dtype}, hidden values): transmittance",
        )
