"""Tests of the given fused marcher (course/kernels/triton_march.py): course code, not graded.

The kernel is checked against a float64 marcher written here with ``grid_sample`` as its
trilinear lookup (an independent implementation of the same cell-centred, border-clamped
convention), on random rays through a random grid, plus the contract's edge cases:
axis-parallel rays with ±0.0 components, rays starting inside, misses and NaN rays, one
and many steps, early termination, RGB and scalar sources, a box far from the origin.

As in tests/test_triton_intersect.py, the CPU check runs this file as a script in a
subprocess with ``TRITON_INTERPRET=1`` set before Triton is imported; with CUDA the same
cases also run compiled, in process.

Usage as the subprocess: ``python tests/test_triton_march.py INPUTS.pt OUTPUTS.pt``.
"""

from __future__ import annotations

import importlib.util
import math
import sys
from pathlib import Path

import pytest
import torch
import torch.nn.functional as F

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:  # run as a script: make `import course` work from a checkout
    sys.path.insert(0, str(REPO))

from course.grading.testing import (
    OLD_INTERPRETER_REASON,
    assert_close,
    assert_equal,
    run_in_triton_interpreter,
    triton_interpreter_too_old,
)

HAVE_TRITON = importlib.util.find_spec("triton") is not None
needs_triton = pytest.mark.skipif(
    not HAVE_TRITON,
    reason="triton is not installed (pip install triton); the kernel cannot run without it",
)
F64 = torch.float64

old_interpreter = pytest.mark.skipif(triton_interpreter_too_old(), reason=OLD_INTERPRETER_REASON)


def make_case(seed: int, n: int = 61, offset: float = 0.0, channels: int = 3) -> dict:
    """Random rays at a [offset + (0, 0, 0), offset + (2, 1, 1.5)] box with random grids."""
    g = torch.Generator().manual_seed(seed)
    lo = torch.tensor([offset, offset, offset], dtype=F64)
    size = torch.tensor([2.0, 1.0, 1.5], dtype=F64)
    target = lo + size * torch.rand(n, 3, generator=g, dtype=F64)
    origins = lo + size / 2 + 2.5 * torch.randn(n, 3, generator=g, dtype=F64)
    origins[:6] = lo + size * torch.rand(6, 3, generator=g, dtype=F64)  # inside the box
    directions = target - origins
    directions[6:9] = torch.tensor([[1.0, 0.0, -0.0], [-0.0, -1.0, 0.0], [0.0, 0.0, 1.0]])
    origins[6:9] = lo + size * torch.tensor(
        [[-0.5, 0.3, 0.6], [0.2, 1.7, 0.4], [0.7, 0.5, -2.0]], dtype=F64
    )
    origins[9] = lo + size * torch.tensor([0.0, 0.5, 0.5], dtype=F64)  # on the x slab plane
    directions[9] = torch.tensor([0.0, 1.0, 0.0])  # ... and parallel to it
    directions[10] = -directions[10]  # pointing away: most of these miss
    origins[11, 1] = math.nan
    directions[12] = 0.0
    directions[13, 2] = math.inf
    density = 3.0 * torch.rand(5, 4, 6, generator=g)
    density[1] = 0.0  # vacuum cells: the small-x series
    density[3, 2] = 400.0  # nearly opaque cells: early termination has something to stop
    source = (
        torch.rand(5, 4, 6, channels, generator=g)
        if channels > 1
        else torch.rand(5, 4, 6, generator=g)
    )
    return {
        "origins": origins.float(),
        "directions": directions.float(),
        "box_min": lo.tolist(),
        "box_max": (lo + size).tolist(),
        "density": density,
        "source": source,
    }


def all_cases() -> dict:
    return {
        "rgb": make_case(0),
        "scalar": make_case(1, channels=1, n=40),
        "far": make_case(2, n=40, offset=1e5),
    }


# Small step counts: the interpreter runs every operation of every step in Python.
RUNS = {
    "steps1": {"steps": 1},
    "steps6": {"steps": 6},
    "steps0": {"steps": 0},
    "early": {"steps": 6, "min_transmittance": 0.3},
}


def run_kernel(cases: dict, device: str) -> dict:
    from course.kernels.triton_march import march_grid_triton

    out = {}
    for name, case in cases.items():
        for run, knobs in RUNS.items():
            args = [
                case["origins"].to(device),
                case["directions"].to(device),
                case["box_min"],
                case["box_max"],
                case["density"].to(device),
                case["source"].to(device),
            ]
            result = march_grid_triton(*args, block_rays=64, num_warps=1, **knobs)
            kernel = result.pop("kernel")
            out[name, run] = {k: v.cpu() for k, v in result.items()}
            if kernel is not None and device == "cuda":
                out["regs", name, run] = (kernel.n_regs, kernel.n_spills)
    from course.kernels.triton_march import bake_light_triton

    for name, case in cases.items():
        for light, steps, scale in BAKES:
            out["bake", name, light, steps, scale] = bake_light_triton(
                case["density"].to(device),
                case["box_min"],
                case["box_max"],
                light,
                steps,
                scale=scale,
                block=32,
                num_warps=1,
            ).cpu()
    empty = torch.zeros(0, 3)
    case = cases["rgb"]
    out["empty"] = march_grid_triton(
        empty.to(device),
        empty.to(device),
        case["box_min"],
        case["box_max"],
        case["density"].to(device),
        case["source"].to(device),
    )["radiance"].shape
    return out


# Light directions (toward the light; one along an axis, with a -0.0: ray-parallel slabs),
# step counts and scales of the bake.
BAKES = [((0.5, 0.8, -0.3), 5, None), ((0.0, -0.0, 2.0), 1, None), ((-0.4, 0.2, 0.9), 7, 2.7)]


def run_interpreted(tmp_path: Path) -> tuple[dict, dict]:
    cases = all_cases()
    return cases, run_in_triton_interpreter(__file__, cases, tmp_path)


# --------------------------------------------------------------------------------------
# The float64 reference
# --------------------------------------------------------------------------------------


def sample(grid: torch.Tensor, uvw: torch.Tensor) -> torch.Tensor:
    """Cell-centred trilinear lookup with border clamping via grid_sample: (N, C)."""
    volume = (grid if grid.ndim == 4 else grid[..., None]).to(F64).permute(3, 2, 1, 0)[None]
    coords = (2 * uvw - 1).reshape(1, -1, 1, 1, 3)  # x, y, z order: (W=X, H=Y, D=Z)
    values = F.grid_sample(
        volume, coords, mode="bilinear", padding_mode="border", align_corners=False
    )
    return values.reshape(volume.shape[1], -1).T


def reference(case: dict, steps: int, min_transmittance: float = 0.0) -> dict:
    o, d = case["origins"].to(F64), case["directions"].to(F64)
    lo, hi = torch.tensor(case["box_min"], dtype=F64), torch.tensor(case["box_max"], dtype=F64)
    size = hi - lo
    rel = o - lo
    with torch.no_grad():
        t0, t1 = (0 - rel) / d, (size - rel) / d
        t_near = torch.fmax(
            torch.minimum(t0, t1).nan_to_num(nan=-math.inf).amax(1), torch.zeros(())
        )
        t_far = torch.maximum(t0, t1).nan_to_num(nan=math.inf).amin(1)
    hit = (
        torch.isfinite(o).all(1)
        & torch.isfinite(d).all(1)
        & (d != 0).any(1)
        & (t_near <= t_far)
        & torch.isfinite(t_far)
    )
    t_near = torch.where(hit, t_near, 0)
    dt = torch.where(hit, t_far - t_near, 0) / max(steps, 1)
    ds = dt * d.norm(dim=1)
    channels = 1 if case["source"].ndim == 3 else case["source"].shape[3]
    radiance = torch.zeros(len(o), channels, dtype=F64)
    transmittance = torch.ones(len(o), dtype=F64)
    samples = torch.zeros(len(o), dtype=torch.int64)
    for i in range(steps):
        active = hit & (transmittance >= min_transmittance)
        t = t_near + (i + 0.5) * dt
        uvw = torch.where(hit[:, None], (rel + t[:, None] * d) / size, 0.5)
        sigma = sample(case["density"], uvw)[:, 0]
        x = sigma * ds
        ratio = torch.where(x > 0, -torch.expm1(-x) / x, 1)
        weight = torch.where(active, ds * ratio, 0) * transmittance
        radiance += weight[:, None] * sample(case["source"], uvw)
        transmittance = torch.where(active, transmittance * torch.exp(-x), transmittance)
        samples += active
    if case["source"].ndim == 3:
        radiance = radiance[:, 0]
    return {"radiance": radiance, "transmittance": transmittance, "samples": samples}


def bake_reference(case: dict, light, steps: int, scale) -> torch.Tensor:
    """Float64 transmittance to the light from every voxel centre (midpoint rule)."""
    density = case["density"].to(F64)
    lo, hi = torch.tensor(case["box_min"], dtype=F64), torch.tensor(case["box_max"], dtype=F64)
    size = hi - lo
    n = torch.tensor(density.shape, dtype=F64)
    idx = torch.stack(
        torch.meshgrid(*(torch.arange(k, dtype=F64) for k in density.shape), indexing="ij"), -1
    ).reshape(-1, 3)
    rel = (idx + 0.5) / n * size
    d = torch.tensor(light, dtype=F64)
    d = d / d.norm()
    with torch.no_grad():
        t0, t1 = (0 - rel) / d, (size - rel) / d
    t_far = torch.maximum(t0, t1).nan_to_num(nan=math.inf).amin(1)
    dt = t_far / max(steps, 1)
    depth = torch.zeros(len(rel), dtype=F64)
    for k in range(steps):
        depth += sample(density, (rel + ((k + 0.5) * dt)[:, None] * d) / size)[:, 0] * dt
    lit = torch.exp(-depth).reshape(density.shape)
    return lit if scale is None else scale * density * lit


def check_bakes(cases: dict, out: dict, where: str) -> None:
    for name, case in cases.items():
        for light, steps, scale in BAKES:
            got = out["bake", name, light, steps, scale]
            want = bake_reference(case, light, steps, scale)
            assert got.dtype == torch.float32 and got.shape == want.shape, where
            # float32 sample positions (an FMA apart when compiled) in grids with 0 -> 400
            # jumps between neighbouring cells: as for the march, ~1e-4 of optical depth.
            assert_close(
                got.double(),
                want,
                name=f"bake ({where}, {name}, light {light}, {steps} steps, scale {scale})",
                atol=2e-5,
                rtol=1e-3,
                where="voxel",
            )


def check_all(cases: dict, out: dict, where: str) -> None:
    check_bakes(cases, out, where)
    for name, case in cases.items():
        for run, knobs in RUNS.items():
            want = reference(case, **knobs)
            got = out[name, run]
            what = f"{where}, case {name}, {run}"
            assert got["radiance"].shape == want["radiance"].shape, what
            # Near an early-termination threshold a rounding may stop a ray one step
            # apart: compare those rays only for the bound the contract gives.
            same = got["samples"] == want["samples"]
            if "min_transmittance" not in knobs:
                assert_equal(got["samples"], want["samples"], name=f"samples ({what})", where="ray")
            assert same.float().mean() >= 0.97, f"{what}: samples differ on too many rays"
            rows = same.nonzero()[:, 0]
            # The grids jump from 0 to 400 between neighbouring cells: a sample position
            # that rounds one ulp apart (an FMA contraction in the compiled kernel) moves
            # sigma by up to ~1e-4 there, so the optical depth carries that much.
            assert_close(
                got["radiance"][rows].double(),
                want["radiance"][rows],
                name=f"radiance ({what})",
                atol=2e-5,
                rtol=1e-3,
                where="ray",
            )
            assert_close(
                got["transmittance"][rows].double(),
                want["transmittance"][rows],
                name=f"transmittance ({what})",
                atol=2e-6,
                rtol=1e-3,
                where="ray",
            )
            assert torch.isfinite(got["radiance"]).all(), f"{what}: non-finite radiance"
    assert out["empty"] == torch.Size([0, 3])


@needs_triton
@old_interpreter
def test_interpreted_matches_float64_reference(tmp_path):
    cases, out = run_interpreted(tmp_path)
    check_all(cases, out, "TRITON_INTERPRET=1")
    # Misses and NaN/inf/zero-direction rays: nothing sampled, T = 1.
    for run in RUNS:
        got = out["rgb", run]
        assert_equal(
            got["samples"][11:14],
            torch.zeros(3, dtype=torch.int64),
            name=f"samples of NaN/inf/zero rays ({run})",
            where="ray",
        )
        assert_equal(got["transmittance"][11:14], torch.ones(3), name="transmittance", where="ray")


@needs_triton
def test_bad_input_is_named():
    from course.grading.testing import expect_error
    from course.kernels import triton_march as tm

    case = make_case(0, n=20)
    args = [
        case["origins"],
        case["directions"],
        case["box_min"],
        case["box_max"],
        case["density"],
        case["source"],
    ]
    expect_error(["steps"], tm.march_grid_triton, *args, steps=-1)
    expect_error(["source"], tm.march_grid_triton, *args[:5], case["source"][:2])
    expect_error(
        ["box_min"], tm.march_grid_triton, args[0], args[1], [0, 0, 0], [0, 1, 1], *args[4:]
    )
    expect_error(["origins"], tm.march_grid_triton, case["origins"][:, :2], *args[1:])
    expect_error(
        ["light_direction"],
        tm.bake_light_triton,
        case["density"],
        case["box_min"],
        case["box_max"],
        (0.0, 0.0, 0.0),
    )
    expect_error(
        ["steps"],
        tm.bake_light_triton,
        case["density"],
        case["box_min"],
        case["box_max"],
        (0.0, 1.0, 0.0),
        -2,
    )
    expect_error(
        ["density"],
        tm.bake_light_triton,
        case["source"],
        case["box_min"],
        case["box_max"],
        (0.0, 1.0, 0.0),
    )


@needs_triton
@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
def test_compiled_matches_float64_reference():
    from course.kernels import triton_intersect as ti

    if ti.interpreting():
        pytest.skip("TRITON_INTERPRET=1 is set in this process: nothing is compiled")
    cases = all_cases()
    out = run_kernel(cases, "cuda")
    check_all(cases, out, "compiled")
    n_regs, n_spills = out["regs", "rgb", "steps6"]
    assert isinstance(n_regs, int) and n_regs > 0 and n_spills >= 0


if __name__ == "__main__":
    cases_in = torch.load(sys.argv[1], weights_only=False)
    torch.save(run_kernel(cases_in, "cpu"), sys.argv[2])
