"""Tests of the given Triton kernels (course/kernels/triton_intersect.py): course code, not graded.

The kernels are checked against a float64 brute force written here, on a random soup and
on a closed mesh, plus the edge cases of the lab's contract (closed ``[t_min, t_max]``,
ties, degenerate triangles, NaN rays, padding of the ray block).

Triton decides between compiling and interpreting when it is imported, from the
environment variable ``TRITON_INTERPRET``. So the CPU check runs this file as a script in a
subprocess that sets ``TRITON_INTERPRET=1`` first: the kernels then run in Triton's
interpreter, whatever this pytest process has imported. On a machine with CUDA the same
cases also run compiled, in process.

Usage as the subprocess: ``python tests/test_triton_intersect.py INPUTS.pt OUTPUTS.pt``.
"""

from __future__ import annotations

import importlib.util
import math
import os
import subprocess
import sys
from pathlib import Path

import pytest
import torch

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:  # run as a script: make `import course` work from a checkout
    sys.path.insert(0, str(REPO))

from course.core.raymath import normalize as _unit
from course.grading.testing import run_in_triton_interpreter

HAVE_TRITON = importlib.util.find_spec("triton") is not None
needs_triton = pytest.mark.skipif(
    not HAVE_TRITON,
    reason="triton is not installed (pip install triton); the kernels cannot run without it",
)

# Kernel configurations under test: odd block sizes and unroll factors on purpose, so ray
# blocks are partly empty and the unrolled loop runs over the layout's padding.
CONFIGS = {
    "mt": ("mt_closest_hit_triton", {"block_rays": 32, "num_warps": 1, "unroll": 4}),
    "mt_division_free": (
        "mt_closest_hit_triton",
        {"block_rays": 64, "num_warps": 2, "unroll": 2, "division_free": True},
    ),
    "unit": ("unit_closest_hit_triton", {"block_rays": 32, "num_warps": 1, "unroll": 1}),
}

# Tolerances of the comparison with the float64 reference. fp32 Cramer's rule loses
# digits as the system gets ill-conditioned (grazing rays, small far triangles), so the
# bounds scale with each pair's condition number (see `reference`); C_FP32 is measured
# (the errors of fp32 Möller–Trumbore stay within 2-4 units), with room for the kernels'
# approximate division.
EPS32 = 2.0**-24
C_FP32 = 16.0
T_RTOL = 1e-5  # relative error of t allowed for every well-conditioned pair

# --------------------------------------------------------------------------------------
# Scenes (float32 geometry; the reference recomputes it in float64)
# --------------------------------------------------------------------------------------


def soup_case(n_rays: int = 70, n_tris: int = 50, seed: int = 0) -> dict:
    """Triangles of mixed sizes in the unit cube; half the rays aim at triangle interiors
    (certain hits), half at random points (hits and misses), all from outside the cube."""
    g = torch.Generator().manual_seed(seed)
    size = torch.exp(torch.empty(n_tris).uniform_(math.log(0.02), math.log(0.4), generator=g))
    centre = torch.rand(n_tris, 1, 3, generator=g)
    tris = centre + size[:, None, None] * (2 * torch.rand(n_tris, 3, 3, generator=g) - 1)
    bary = -torch.log(torch.rand(n_rays, 3, generator=g))  # uniform on the triangle
    bary = bary / bary.sum(1, keepdim=True)
    pick = torch.randint(n_tris, (n_rays,), generator=g)
    aimed = (bary[:, :, None] * tris[pick]).sum(1)
    target = torch.where(
        torch.arange(n_rays)[:, None] % 2 == 0, aimed, torch.rand(n_rays, 3, generator=g)
    )
    origins = 0.5 + 2.0 * _unit(torch.randn(n_rays, 3, generator=g))
    return {
        "origins": origins,
        "directions": target - origins,
        "triangles": tris,
        "t_min": 0.0,
        "t_max": math.inf,
    }


def closed_mesh() -> tuple[torch.Tensor, torch.Tensor, str]:
    """(vertices, faces, name): the course's icosphere when course.core.scenes can be imported
    (it needs trimesh), else an octahedron, the smallest closed mesh with shared edges."""
    try:
        from course.core.scenes import load_scene
    except ImportError:
        vertices = torch.tensor(
            [[1.0, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]]
        )
        faces = torch.tensor(
            [[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]]
        )
        return vertices, faces, "octahedron"
    mesh = load_scene("icosphere", level=1, device="cpu", dtype=torch.float32).mesh
    return mesh.vertices, mesh.faces, "icosphere1"


def closed_case(seed: int = 1) -> dict:
    """Rays from outside a closed mesh at its edge midpoints, its vertices and random
    points: every one enters the mesh, and most pass within rounding of a shared edge."""
    vertices, faces, name = closed_mesh()
    g = torch.Generator().manual_seed(seed)
    edges = torch.cat([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]).sort(1).values
    edges = edges.unique(dim=0)
    targets = torch.cat(
        [vertices[edges].mean(1), vertices, 0.5 * _unit(torch.randn(16, 3, generator=g))]
    )
    normal = _unit(targets)
    origins = targets + 2.0 * _unit(normal + 0.5 * _unit(torch.randn(len(targets), 3, generator=g)))
    return {
        "origins": origins,
        "directions": targets - origins,
        "triangles": vertices[faces],
        "t_min": 0.0,
        "t_max": math.inf,
        "mesh": name,
    }


def contract_case() -> dict:
    """Exact little scenes for the contract, one ray each (values chosen to be exact in
    fp32: the triangle is the unit right triangle at z = 1, so t = 1 exactly)."""
    tri = torch.tensor([[-0.25, -0.25, 1.0], [0.75, -0.25, 1.0], [-0.25, 0.75, 1.0]])
    far = tri + torch.tensor([0.0, 0.0, 1.0])  # the same, at t = 2
    flat = torch.tensor([[0.0, 0.0, 0.5], [1.0, 1.0, 0.5], [2.0, 2.0, 0.5]])  # zero area
    triangles = torch.stack([far, tri, tri, flat])  # index 1 and 2 tie
    up = [0.0, 0.0, 1.0]
    rays = [  # (name, origin, direction, t_min, t_max, expected triangle, expected t)
        ("nearest", [0, 0, 0], up, 0.0, math.inf, 1, 1.0),
        ("t_max closed", [0, 0, 0], up, 0.0, 1.0, 1, 1.0),
        ("t_max below", [0, 0, 0], up, 0.0, 1.0 - 2**-24, -1, math.inf),
        ("t_min closed", [0, 0, 0], up, 1.0, math.inf, 1, 1.0),
        ("t_min above", [0, 0, 0], up, 1.0 + 2**-23, math.inf, 0, 2.0),
        ("backwards", [0, 0, 3], up, 0.0, math.inf, -1, math.inf),
        ("parallel", [0, 0, 0.5], [1.0, 1.0, 0.0], 0.0, math.inf, -1, math.inf),
        ("zero direction", [0, 0, 0], [0.0, 0.0, 0.0], 0.0, math.inf, -1, math.inf),
        ("NaN origin", [math.nan, 0, 0], up, 0.0, math.inf, -1, math.inf),
        ("NaN direction", [0, 0, 0], [0.0, math.nan, 1.0], 0.0, math.inf, -1, math.inf),
        ("outside", [2, 2, 0], up, 0.0, math.inf, -1, math.inf),
    ]
    return {
        "origins": torch.tensor([r[1] for r in rays], dtype=torch.float32),
        "directions": torch.tensor([r[2] for r in rays], dtype=torch.float32),
        "triangles": triangles,
        "t_min": torch.tensor([r[3] for r in rays], dtype=torch.float32),
        "t_max": torch.tensor([r[4] for r in rays], dtype=torch.float32),
        "names": [r[0] for r in rays],
        "expected_triangle": torch.tensor([r[5] for r in rays]),
        "expected_t": torch.tensor([r[6] for r in rays], dtype=torch.float32),
    }


def all_cases() -> dict:
    return {"soup": soup_case(), "closed": closed_case(), "contract": contract_case()}


# --------------------------------------------------------------------------------------
# Running the kernels (in this process, or in the interpreter subprocess)
# --------------------------------------------------------------------------------------


def run_kernels(cases: dict, device: str) -> dict:
    """Every configuration on every case: ``{case: {config: (t, triangle, u, v)}}`` on the
    CPU, plus ``"info"``: compiled_kernel_info of each config and ``"interpreting"``."""
    from course.kernels import triton_intersect as ti

    out: dict = {"interpreting": ti.interpreting(), "info": {}}
    for case_name, case in cases.items():
        args = [
            case["origins"].to(device),
            case["directions"].to(device),
            case["triangles"].to(device),
        ]
        bounds = [
            b.to(device) if isinstance(b, torch.Tensor) else b
            for b in (case["t_min"], case["t_max"])
        ]
        out[case_name] = {}
        for config, (fn_name, kwargs) in CONFIGS.items():
            result = getattr(ti, fn_name)(*args, *bounds, **kwargs)
            out[case_name][config] = tuple(x.cpu() for x in result)
    case = cases["contract"]
    for config, (fn_name, kwargs) in CONFIGS.items():
        info = ti.compiled_kernel_info(
            getattr(ti, fn_name),
            case["origins"].to(device),
            case["directions"].to(device),
            case["triangles"].to(device),
            **kwargs,
        )
        out["info"][config] = (info.n_regs, info.n_spills, info.num_warps)
    empty = torch.zeros(0, 3, device=device)
    out["empty"] = tuple(
        x.shape
        for x in ti.mt_closest_hit_triton(empty, empty, cases["soup"]["triangles"].to(device))
    )
    return out


def run_interpreted(tmp_path: Path) -> dict:
    """run_kernels in a fresh Python with TRITON_INTERPRET=1 set before triton's import."""
    cases = all_cases()
    return cases, run_in_triton_interpreter(__file__, cases, tmp_path)


# --------------------------------------------------------------------------------------
# The float64 reference and the comparison
# --------------------------------------------------------------------------------------


def reference(case: dict) -> dict:
    """All pairs in float64 by Cramer's rule, on the fp32 inputs: (N, M) tensors.

    t, u, v: the solution (NaN or inf where det = 0); in_range: t in [t_min, t_max];
    t_tol: relative error of t an fp32 kernel may make, max(T_RTOL, C eps |d||e1||e2|/|det|);
    uv_tol: absolute error of u, v, C eps |o - v0||d| max(|e1|, |e2|) / |det|.
    """
    o = case["origins"].double()[:, None]
    d = case["directions"].double()[:, None]
    tri = case["triangles"].double()[None]
    v0, e1, e2 = tri[..., 0, :], tri[..., 1, :] - tri[..., 0, :], tri[..., 2, :] - tri[..., 0, :]
    p = torch.linalg.cross(d, e2)
    det = (e1 * p).sum(-1)
    s = o - v0
    q = torch.linalg.cross(s, e1)
    u = (s * p).sum(-1) / det
    v = (d * q).sum(-1) / det
    t = (e2 * q).sum(-1) / det
    n = case["origins"].shape[0]
    t_lo = torch.as_tensor(case["t_min"], dtype=torch.float64).expand(n)[:, None]
    t_hi = torch.as_tensor(case["t_max"], dtype=torch.float64).expand(n)[:, None]
    norm = torch.linalg.vector_norm
    scale = norm(d, dim=-1) / det.abs()
    t_tol = (C_FP32 * EPS32 * scale * norm(e1, dim=-1) * norm(e2, dim=-1)).clamp(min=T_RTOL)
    uv_tol = (
        C_FP32 * EPS32 * scale * norm(s, dim=-1) * torch.maximum(norm(e1, dim=-1), norm(e2, dim=-1))
    )
    return {
        "t": t,
        "u": u,
        "v": v,
        "in_range": (t >= t_lo) & (t <= t_hi) & (det != 0),
        "t_tol": t_tol,
        "uv_tol": uv_tol,
    }


def check_against_reference(case: dict, result, label: str, max_mismatch: float) -> None:
    """The kernel's closest hits agree with the float64 brute force.

    Rules, per ray, with each pair's own tolerances (see `reference`): a hit must be on a
    triangle the reference hits to within ``uv_tol`` of its border, at the reference's t
    (``t_tol``, 1e-5 for well-conditioned pairs), with u, v within ``uv_tol``; no triangle
    the reference hits *solidly* (more than ``uv_tol`` inside) may be nearer; a miss is
    allowed only when no triangle is hit solidly. Choosing another triangle than the
    reference's exact winner is thus allowed only on an edge or at a tie, and only for a
    fraction ``max_mismatch`` of the rays.
    """
    t_k, id_k, u_k, v_k = (x.double() for x in result)
    ref = reference(case)
    t, u, v, tol = ref["t"], ref["u"], ref["v"], ref["uv_tol"]
    w = 1 - u - v
    near = ref["in_range"] & (u >= -tol) & (v >= -tol) & (w >= -tol)
    solid = ref["in_range"] & (u > tol) & (v > tol) & (w > tol)
    exact = ref["in_range"] & (u >= 0) & (v >= 0) & (w >= 0)
    inf = torch.tensor(math.inf, dtype=torch.float64)
    t_solid = torch.where(solid, t, inf)
    t_exact = torch.where(exact, t, inf)
    ref_id = torch.where(torch.isfinite(t_exact.amin(1)), torch.argmin(t_exact, 1), -1)
    for i in range(len(t_k)):
        where = (
            f"{label}, ray {i} (origin {case['origins'][i].tolist()}, "
            f"direction {case['directions'][i].tolist()})"
        )
        j, k = int(id_k[i]), int(t_solid[i].argmin())
        if j < 0:
            assert not math.isfinite(t_solid[i, k]), (
                f"{where}: the kernel missed, but the reference hits triangle {k} well inside "
                f"its edges (u, v = {float(u[i, k]):.4g}, {float(v[i, k]):.4g}) at "
                f"t = {float(t[i, k]):.9g}"
            )
            assert math.isinf(t_k[i]) and u_k[i] == 0 and v_k[i] == 0, (
                f"{where}: a miss must report t = inf, u = v = 0; got t = {float(t_k[i])}, "
                f"u = {float(u_k[i])}, v = {float(v_k[i])}"
            )
            continue
        assert 0 <= j < t.shape[1] and bool(near[i, j]), (
            f"{where}: the kernel reports triangle {j}, which the reference does not hit "
            f"(reference u, v = {float(u[i, j]):.4g}, {float(v[i, j]):.4g}, "
            f"t = {float(t[i, j]):.6g}, tolerance {float(tol[i, j]):.2g})"
        )
        rel, rtol = abs(float(t_k[i] - t[i, j])) / abs(float(t[i, j])), float(ref["t_tol"][i, j])
        assert rel <= rtol, (
            f"{where}: t = {float(t_k[i]):.9g} on triangle {j}, reference "
            f"{float(t[i, j]):.9g}: relative error {rel:.2e} > {rtol:.2e}"
        )
        assert float(t_k[i]) <= float(t_solid[i, k]) * (1 + 2 * float(ref["t_tol"][i, k])), (
            f"{where}: the kernel's hit at t = {float(t_k[i]):.9g} (triangle {j}) is behind "
            f"the solid hit of triangle {k} at t = {float(t[i, k]):.9g}: the minimum over "
            f"triangles is wrong"
        )
        err = max(abs(float(u_k[i] - u[i, j])), abs(float(v_k[i] - v[i, j])))
        assert err <= float(tol[i, j]), (
            f"{where}: barycentrics (u, v) = ({float(u_k[i]):.7g}, {float(v_k[i]):.7g}) on "
            f"triangle {j}, reference ({float(u[i, j]):.7g}, {float(v[i, j]):.7g}): error "
            f"{err:.2e} > {float(tol[i, j]):.2e}"
        )
    mismatch = (id_k != ref_id).double().mean().item()
    assert mismatch <= max_mismatch, (
        f"{label}: {mismatch:.1%} of the rays chose another triangle than the float64 "
        f"reference (allowed {max_mismatch:.0%}). Each one is individually legal (a ray on a "
        f"shared edge or at a tie in t may take either triangle), but this many suggests a "
        f"systematic error: compare the kernel's edge tests with the reference's"
    )


def check_all(cases: dict, out: dict) -> None:
    for config in CONFIGS:
        check_against_reference(
            cases["soup"], out["soup"][config], f"soup, {config}", max_mismatch=0.03
        )
        # The closed mesh's rays aim at shared edges and vertices on purpose: many of them
        # may go to the other neighbour (fp32 vs float64 rounding), so only the rules bind.
        check_against_reference(
            cases["closed"],
            out["closed"][config],
            f"{cases['closed']['mesh']}, {config}",
            max_mismatch=1.0,
        )
        check_contract(cases["contract"], out["contract"][config], config)
    assert out["empty"] == (torch.Size([0]),) * 4, f"empty ray batch: got shapes {out['empty']}"


def check_contract(case: dict, result, config: str) -> None:
    t_k, id_k, u_k, v_k = result
    for i, name in enumerate(case["names"]):
        want_id, want_t = int(case["expected_triangle"][i]), float(case["expected_t"][i])
        got = (
            f"triangle {int(id_k[i])}, t = {float(t_k[i])}, u = {float(u_k[i])}, "
            f"v = {float(v_k[i])}"
        )
        assert int(id_k[i]) == want_id and float(t_k[i]) == want_t, (
            f"{config}, contract case {name!r}: expected triangle {want_id} at t = {want_t}, "
            f"got {got} (t_min = {float(case['t_min'][i])}, t_max = {float(case['t_max'][i])};"
            f" the interval is closed and ties go to the lower index)"
        )
        assert not (torch.isnan(u_k[i]) or torch.isnan(v_k[i])), (
            f"{config}, contract case {name!r}: NaN barycentrics ({got}); a kernel must "
            f"never let a NaN travel"
        )


# --------------------------------------------------------------------------------------
# Tests
# --------------------------------------------------------------------------------------


@needs_triton
def test_interpreter_matches_float64_reference(tmp_path):
    cases, out = run_interpreted(tmp_path)
    assert out["interpreting"], "the subprocess did not run Triton's interpreter"
    check_all(cases, out)
    for config, (n_regs, n_spills, num_warps) in out["info"].items():
        assert n_regs is None and n_spills is None, (
            f"{config}: the interpreter compiles nothing, so compiled_kernel_info should "
            f"report None registers/spills, got {n_regs}/{n_spills}"
        )
        assert num_warps == CONFIGS[config][1]["num_warps"]


@needs_triton
@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
def test_compiled_matches_float64_reference():
    from course.kernels import triton_intersect as ti

    if ti.interpreting():
        pytest.skip("TRITON_INTERPRET=1 is set in this process: nothing is compiled")
    cases = all_cases()
    cases["soup_large"] = soup_case(n_rays=4099, n_tris=300, seed=2)
    out = run_kernels(cases, "cuda")
    check_all(cases, out)
    for config in CONFIGS:
        check_against_reference(
            cases["soup_large"],
            out["soup_large"][config],
            f"soup 4099x300, {config}",
            max_mismatch=0.01,
        )
    for config, (n_regs, n_spills, _) in out["info"].items():
        assert isinstance(n_regs, int) and n_regs > 0, f"{config}: n_regs = {n_regs!r}"
        assert isinstance(n_spills, int) and n_spills >= 0, f"{config}: n_spills = {n_spills!r}"


@needs_triton
def test_bad_arguments_raise_clear_errors():
    from course.kernels import triton_intersect as ti

    case = soup_case(n_rays=4, n_tris=3)
    o, d, tri = case["origins"], case["directions"], case["triangles"]
    bad = [
        ({"origins": o[:, :2]}, ValueError, "origins"),
        ({"directions": d[:3]}, ValueError, "directions"),
        ({"triangles": tri[:, :2]}, ValueError, "triangles"),
        ({"origins": o.long()}, ValueError, "origins"),
        ({"block_rays": 48}, ValueError, "block_rays"),
        ({"num_warps": 3}, ValueError, "num_warps"),
        ({"unroll": 32}, ValueError, "unroll"),
        ({"t_max": torch.ones(5)}, ValueError, "t_max"),
        ({"triangles": ti.unit_layout(tri)}, ValueError, "layout"),
    ]
    for change, error, word in bad:
        kwargs = {"origins": o, "directions": d, "triangles": tri, **change}
        with pytest.raises(error, match=word):
            ti.mt_closest_hit_triton(**kwargs)
    if not ti.interpreting():
        with pytest.raises(ValueError, match="CUDA"):
            ti.mt_closest_hit_triton(o, d, tri)  # CPU tensors, compiled kernels


def test_import_without_triton_fails_only_on_call():
    code = (
        "import sys; sys.modules['triton'] = None\n"
        "import torch\n"
        "from course.kernels import triton_intersect as ti\n"
        "layout = ti.mt_layout(torch.rand(2, 3, 3))\n"
        "try:\n"
        "    ti.mt_closest_hit_triton(torch.zeros(1, 3), torch.ones(1, 3), layout)\n"
        "except ImportError as err:\n"
        "    print('ImportError:', err)\n"
    )
    env = dict(os.environ, PYTHONPATH=str(REPO))
    proc = subprocess.run(
        [sys.executable, "-c", code],
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert proc.returncode == 0, f"importing without triton failed:\n{proc.stderr[-2000:]}"
    assert "ImportError:" in proc.stdout and "triton" in proc.stdout, (
        f"calling a kernel without triton should raise an ImportError naming triton; "
        f"got: {proc.stdout!r}"
    )


def test_unit_layout_maps_the_triangle_to_the_unit_triangle():
    from course.kernels.triton_intersect import unit_layout

    tri = torch.tensor(
        [
            [[1.0, 2.0, 3.0], [4.0, 2.5, 3.0], [1.5, 5.0, 4.0]],
            [[0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [2.0, 2.0, 2.0]],
        ]
    )  # 2nd: degenerate
    layout = unit_layout(tri)
    assert layout.data.shape == (12, 16) and layout.count == 2
    m = layout.data[:, 0].double().reshape(3, 4)
    corners = torch.cat([tri[0].double(), torch.ones(3, 1, dtype=torch.float64)], 1)
    mapped = corners @ m.T
    want = torch.tensor([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype=torch.float64)
    assert torch.allclose(mapped, want, atol=1e-6), (
        f"unit_layout should map v0, v1, v2 to (0,0,0), (1,0,0), (0,1,0); got\n{mapped}"
    )
    never = layout.data[:, 1].reshape(3, 4)
    assert never[0, 3] == -1 and (never[:, :3] == 0).all(), (
        f"a degenerate triangle should get the never-hit transform, got\n{never}"
    )


if __name__ == "__main__":  # the interpreter subprocess: python THIS INPUTS OUTPUTS
    torch.save(run_kernels(torch.load(sys.argv[1], weights_only=False), "cpu"), sys.argv[2])
