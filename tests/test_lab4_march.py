"""Grader for Lab 4: ray marching.

Every reference is computed here in float64 from the same (rounded) inputs, never stored,
and none of them marches the way the lab does:

=========================  ==============================================================
kernel                     reference
=========================  ==============================================================
ray_box_interval           per-axis slabs with the zero-direction case spelled out
sample_grid                ``torch.nn.functional.grid_sample`` (border, align_corners=False)
march_box, integrators     closed forms: homogeneous box ``q (1 - e^{-s D}) / s``; a linear
                           density ramp with constant emission (``erfcx``); two layers;
                           ``q = c sigma`` (``L = c (1 - T)``: energy conservation)
single scattering          closed form for a homogeneous box lit along an axis; otherwise a
                           2001-point Simpson quadrature with the light's optical depth in
                           closed form (homogeneous: slab test; quadratic density: exact)
voxel_walk                 every plane crossing of every ray, sorted; a voxel per segment
sphere_trace               analytic sphere and box intersections
=========================  ==============================================================

The extremes every kernel must survive: optical depths 0, 1e-8 and 1e8 (no NaN, the right
limits), rays that miss the box, start inside it, run along an axis with +0.0/-0.0
components, carry NaN/inf, a box at 1e5 in float32, zero and one step, float16/bfloat16
(loose properties only), and grazing rays for sphere tracing. On CUDA each kernel must
agree with its CPU result.
"""

from __future__ import annotations

import itertools
import math
from functools import partial
from types import SimpleNamespace

import pytest
import torch

from course.core.raymath import normalize as unit
from course.grading.testing import (
    assert_close,
    assert_equal,
    check_tensor,
    expect_error,
    generator,
    replaced,
)

LAB_MODULE = "lab4_march"
TASKS = {
    1: "The box ray marcher",
    2: "Emission–absorption accuracy",
    3: "Single scattering",
    4: "Exact voxel walk and empty-space skipping",
    5: "Sphere tracing",
}

INF = math.inf
F64 = torch.float64
MISS, HIT, UNSURE = 0, 1, 2
STATUS = {MISS: "MISS", HIT: "HIT", UNSURE: "UNSURE"}


# ---------------------------------------------------------------------------------------
# Media and scenes handed to the lab (module-level functions: they run next to it)


def ramp_density(p):
    """sigma = 0.5 + 2 x: linear along every ray."""
    return 0.5 + 2.0 * p[:, 0]


def x_density(p):
    """sigma = x: with one step along +x through [0, 1]^3, -log T is the sample's x."""
    return p[:, 0].clone()


def layer_density(p):
    """Two layers: sigma = 4 for x < 1/2, 0.5 behind."""
    return torch.where(p[:, 0] < 0.5, p.new_tensor(4.0), p.new_tensor(0.5))


def layer_emission(p):
    return torch.where(p[:, 0] < 0.5, p.new_tensor(0.2), p.new_tensor(1.0))


def rgb_emission(p):
    """Constant emission (0.6, 0.3, 0.1): an (N, 3) callable result."""
    return torch.tensor([0.6, 0.3, 0.1], dtype=p.dtype, device=p.device).expand(len(p), 3)


def blackbody_density(p):
    """A strongly varying density for the energy test (up to 300 per unit length)."""
    return 300.0 * torch.sin(7.0 * p[:, 0] + 3.0 * p[:, 1]).square() + 0.01


def blackbody_emission(p):
    """q = c sigma with c = 0.8: a medium in equilibrium at 'temperature' c."""
    return 0.8 * blackbody_density(p)


BOWL_CENTER = (0.5, 0.4, 0.6)


def bowl_density(p):
    """sigma = 0.3 + 3 |p - c|^2: quadratic along every line."""
    c = torch.tensor(BOWL_CENTER, dtype=p.dtype, device=p.device)
    return 0.3 + 3.0 * (p - c).square().sum(-1)


def negative_density(p):
    """Not an extinction coefficient: -1 everywhere (bad input)."""
    return -torch.ones(p.shape[0], dtype=p.dtype, device=p.device)


def wrong_shape_density(p):
    return p


def nan_density(p):
    """Not an extinction coefficient: NaN everywhere (bad input)."""
    return torch.full(p.shape[:1], math.nan, dtype=p.dtype, device=p.device)


def sdf_unit_sphere(p):
    return p.norm(dim=-1) - 1.0


SPHERE_5_C = (0.0, 0.0, 5.0)


def sdf_sphere_at_5(p):
    """The unit sphere at distance 5 along +z."""
    return (p - torch.tensor(SPHERE_5_C, dtype=p.dtype, device=p.device)).norm(dim=-1) - 1.0


SPHERE_C, SPHERE_R = (0.0, 0.0, 4.0), 1.0
BOX_C, BOX_H = (1.5, 0.3, 6.0), (0.6, 0.8, 0.5)


def sdf_two_solids(p):
    """A sphere and a box, unioned."""
    c = torch.tensor(SPHERE_C, dtype=p.dtype, device=p.device)
    sphere = (p - c).norm(dim=-1) - SPHERE_R
    q = (p - torch.tensor(BOX_C, dtype=p.dtype, device=p.device)).abs() - torch.tensor(
        BOX_H, dtype=p.dtype, device=p.device
    )
    box = q.clamp(min=0).norm(dim=-1) + q.amax(dim=-1).clamp(max=0)
    return torch.minimum(sphere, box)


def sdf_thin_slab(p):
    """A slab 0.02 thick at z = 5, and a sphere far to the side."""
    slab = (p[:, 2] - 5.0).abs() - 0.01
    side = (p - torch.tensor([30.0, 0.0, 5.0], dtype=p.dtype, device=p.device)).norm(dim=-1) - 1
    return torch.minimum(slab, side)


def sdf_ground(p):
    """The plane y = -1."""
    return p[:, 1] + 1.0


FAR_C, FAR_R = (0.0, 0.0, 1.0e5), 1.0e3


def sdf_far_sphere(p):
    c = torch.tensor(FAR_C, dtype=p.dtype, device=p.device)
    return (p - c).norm(dim=-1) - FAR_R


NEAR_C, NEAR_R = (0.0, 0.0, 0.01), 1.0e-3


def sdf_tiny_sphere(p):
    c = torch.tensor(NEAR_C, dtype=p.dtype, device=p.device)
    return (p - c).norm(dim=-1) - NEAR_R


def sdf_nan(p):
    return torch.full(p.shape[:1], math.nan, dtype=p.dtype, device=p.device)


def sdf_column(p):
    """The plane y = -1, returned as (N, 1): the wrong shape."""
    return (p[:, 1] + 1.0)[:, None]


# ---------------------------------------------------------------------------------------
# Checking helpers


def result_dict(result, what: str, keys, n: int, dtype, device, channels=None) -> dict:
    """A kernel's dict of results, each checked for shape, dtype and device."""
    assert isinstance(result, dict), (
        f"{what}: expected a dict with keys {sorted(keys)}, got {type(result).__name__}"
    )
    missing = [k for k in keys if k not in result]
    assert not missing, f"{what}: the result dict lacks {missing} (has {sorted(result)})"
    out = {}
    for key, kind in keys.items():
        shape = (n, channels) if key == "radiance" and channels else (n,)
        want = torch.int64 if kind == "int" else dtype
        out[key] = check_tensor(
            result[key], f"{what}[{key!r}]", shape=shape, dtype=want, device=device
        )
    return out


MARCH_KEYS = {"radiance": "float", "transmittance": "float", "samples": "int"}
WALK_KEYS = {
    "optical_depth": "float",
    "transmittance": "float",
    "radiance": "float",
    "steps": "int",
    "samples": "int",
}
TRACE_KEYS = {"t": "float", "status": "int", "steps": "int"}


def no_nan(what: str, **tensors):
    for name, x in tensors.items():
        bad = ~torch.isfinite(x.detach().cpu().double())
        if name == "t":
            bad &= ~(x.detach().cpu() == INF)
        if bad.any():
            i = tuple(bad.nonzero()[0].tolist())
            raise AssertionError(
                f"{what}: {int(bad.sum())} non-finite values in {name}, first at {i} "
                f"({x.detach().cpu()[i].item()!r}). Mask degenerate lanes with torch.where "
                f"before they meet a division or an exponential; never let a NaN out."
            )


def cpu_agrees(device, what, got: dict, fn, *args, rtol=1e-9, atol=1e-12, **kwargs):
    """On a GPU, the same call on the CPU must give the same answers (float64 inputs)."""
    if torch.device(device).type == "cpu":
        return
    moved = [a.cpu() if isinstance(a, torch.Tensor) else a for a in args]
    ref = fn(
        *moved, **{k: v.cpu() if isinstance(v, torch.Tensor) else v for k, v in kwargs.items()}
    )
    for key, value in got.items():
        other = ref[key] if isinstance(ref, dict) else ref
        if value.dtype.is_floating_point:
            assert_close(
                value,
                other,
                rtol=rtol,
                atol=atol,
                name=f"{what}: {key} on {device} vs on the CPU",
                where="ray",
            )
        else:
            assert_equal(value, other, name=f"{what}: {key} on {device} vs on the CPU", where="ray")


# ---------------------------------------------------------------------------------------
# References (float64, CPU)


def f64(*xs):
    return tuple(torch.as_tensor(x).detach().to("cpu", F64) for x in xs)


def ref_interval(o, d, lo, hi):
    """Slab test with the zero-direction case spelled out; t clipped to >= 0.
    Returns (near, far, hit), (N,) each, float64 (meaningful where hit)."""
    o, d, lo, hi = f64(o, d, lo, hi)
    zero = d == 0
    inside = (lo <= o) & (o <= hi)
    t0, t1 = (lo - o) / d, (hi - o) / d
    near = torch.where(zero, torch.where(inside, -INF, INF), torch.minimum(t0, t1))
    far = torch.where(zero, torch.where(inside, INF, -INF), torch.maximum(t0, t1))
    near = near.amax(-1).clamp(min=0)
    far = far.amin(-1)
    valid = torch.isfinite(o).all(-1) & torch.isfinite(d).all(-1) & (d != 0).any(-1)
    hit = valid & (near <= far)
    return near, far, hit


def phi(x):
    """(1 - e^{-x}) / x with phi(0) = 1, in float64."""
    return torch.where(x > 0, -torch.expm1(-x) / x.clamp(min=1e-300), torch.ones_like(x))


def box_rays(n: int, seed: int, lo, hi, dtype=F64):
    """Rays at a box (float64 built, rounded once to dtype): a quarter start inside, a
    tenth aim away (misses), some run along an axis with +0.0/-0.0 components, the rest
    come from outside toward a random point inside; lengths of d from 0.1 to 10."""
    g = generator(seed)
    lo64, hi64 = f64(lo, hi)
    size = hi64 - lo64
    inner = lo64 + size * (0.02 + 0.96 * torch.rand(n, 3, generator=g, dtype=F64))
    outer = lo64 + size * (torch.rand(n, 3, generator=g, dtype=F64) * 4 - 1.5)
    k = torch.arange(n)
    o = torch.where(
        (k % 4 == 0)[:, None],
        lo64 + size * (0.05 + 0.9 * torch.rand(n, 3, generator=g, dtype=F64)),
        outer,
    )
    d = inner - o
    d = torch.where((k % 4 == 0)[:, None], torch.randn(n, 3, generator=g, dtype=F64), d)
    d = torch.where((k % 10 == 3)[:, None], -d, d)
    # Axis-parallel rays: two components +0.0 or -0.0.
    axis_rows = k % 7 == 5
    for j in range(3):
        zero = axis_rows & (k % 3 != j)
        sign = torch.where(k % 2 == 0, 0.0, -0.0).to(F64)
        d[:, j] = torch.where(zero, sign, d[:, j])
        o[:, j] = torch.where(zero, inner[:, j], o[:, j])
    d = d * (10.0 ** (torch.rand(n, 1, generator=g, dtype=F64) * 2 - 1))
    return o.to(dtype), d.to(dtype)


def bad_rays(dtype=F64):
    """NaN/inf origins and directions, and zero directions, aimed at [0, 1]^3."""
    o, d = [], []
    base_o, base_d = [0.5, 0.5, -1.0], [0.0, 0.1, 1.0]
    for value in (math.nan, INF, -INF):
        for axis in range(3):
            x = list(base_o)
            x[axis] = value
            o.append(x)
            d.append(base_d)
            y = list(base_d)
            y[axis] = value
            o.append(base_o)
            d.append(y)
    o += [base_o, base_o]
    d += [[0.0, 0.0, 0.0], [-0.0, 0.0, -0.0]]
    return torch.tensor(o, dtype=dtype), torch.tensor(d, dtype=dtype)


def ramp_reference(o, d, lo, hi, q):
    """sigma = 0.5 + 2 x, constant emission q: radiance and transmittance in closed form.

    Along the ray (unit length s from the entry) sigma = a + b s with b = 2 d_x > 0, so
    int_0^D q e^{-(a s + b s^2 / 2)} ds = q sqrt(pi / 2b) (erfcx(z1) - e^{-tau} erfcx(z2)),
    z1 = a / sqrt(2b), z2 = (a + b D) / sqrt(2b), tau = a D + b D^2 / 2 (no overflow)."""
    o, d = f64(o, d)
    dn = d.norm(dim=-1)
    near, far, _ = ref_interval(o, d, lo, hi)
    length = (far - near) * dn
    entry = o + near[:, None] * d
    a = 0.5 + 2.0 * entry[:, 0]
    b = 2.0 * d[:, 0] / dn
    tau = a * length + b * length**2 / 2
    root = torch.sqrt(2 * b)
    radiance = (
        q
        * math.sqrt(math.pi)
        / root
        * (
            torch.special.erfcx(a / root)
            - torch.exp(-tau) * torch.special.erfcx((a + b * length) / root)
        )
    )
    return radiance, torch.exp(-tau)


def x_face_rays(n: int, seed: int, dtype=F64):
    """Rays entering [0, 1]^3 through x = 0 and leaving through x = 1 (d_x > 0)."""
    g = generator(seed)
    entry = torch.cat(
        [torch.zeros(n, 1, dtype=F64), 0.3 + 0.4 * torch.rand(n, 2, generator=g, dtype=F64)], 1
    )
    d = torch.cat(
        [torch.ones(n, 1, dtype=F64), 0.4 * torch.rand(n, 2, generator=g, dtype=F64) - 0.2], 1
    )
    d = d * (0.5 + torch.rand(n, 1, generator=g, dtype=F64))
    o = entry - (0.5 + torch.rand(n, 1, generator=g, dtype=F64)) * d
    return o.to(dtype), d.to(dtype)


def layer_reference(o, d):
    """Two layers split at x = 1/2 for rays through both x faces."""
    o, d = f64(o, d)
    near, far, _ = ref_interval(o, d, [0.0] * 3, [1.0] * 3)
    h = (far - near) * d.norm(dim=-1) / 2
    front = 0.2 * h * phi(4.0 * h)
    back = 1.0 * h * phi(0.5 * h)
    return front + torch.exp(-4.0 * h) * back, torch.exp(-4.5 * h)


def light_exit(points, light, lo, hi):
    """Distance from each point to where its ray toward the light leaves the box."""
    p, l = f64(points, light)
    near, far, hit = ref_interval(p, l.expand_as(p), lo, hi)
    return torch.where(hit, far - near, torch.zeros_like(far)), near


def simpson(values, length):
    """Composite Simpson over M (odd) equally spaced samples per row spanning ``length``."""
    m = values.shape[-1]
    w = torch.ones(m, dtype=F64)
    w[1:-1:2], w[2:-1:2] = 4.0, 2.0
    return (values * w).sum(-1) * length / (3 * (m - 1))


def scatter_reference(
    o, d, lo, hi, sigma_fn, shadow_depth_fn, light, albedo, irradiance, g, m=2001
):
    """Single scattering by quadrature along each view ray (float64): sigma_fn(points)
    gives sigma, shadow_depth_fn(points) the optical depth toward the light exactly."""
    o, d, light = f64(o, d, light)
    light = light / light.norm()
    dn = d.norm(dim=-1)
    u = d / dn[:, None]
    near, far, hit = ref_interval(o, d, lo, hi)
    length = torch.where(hit, (far - near) * dn, torch.zeros_like(near))
    s = torch.linspace(0, 1, m, dtype=F64)[None, :] * length[:, None]  # (N, M)
    points = (o + near[:, None] * d)[:, None, :] + s[..., None] * u[:, None, :]
    sigma = sigma_fn(points.reshape(-1, 3)).reshape(s.shape)
    # Optical depth along the view ray: cumulative Simpson is overkill; the trapezoid on
    # a fine grid has error ~1e-8 here, far below the tolerances.
    step = length[:, None] / (m - 1)
    depth = torch.cat(
        [
            torch.zeros(len(o), 1, dtype=F64),
            torch.cumsum((sigma[:, 1:] + sigma[:, :-1]) / 2 * step, dim=1),
        ],
        1,
    )
    lit = torch.exp(-shadow_depth_fn(points.reshape(-1, 3)).reshape(s.shape))
    cos = u @ light
    p = ref_phase(cos, g)
    integrand = sigma * torch.exp(-depth) * lit
    return simpson(integrand, length) * p * albedo * irradiance


def ref_phase(cos, g):
    cos = torch.as_tensor(cos, dtype=F64)
    return (1 - g * g) / (4 * math.pi * (1 + g * g - 2 * g * cos) ** 1.5)


def ref_optical_depth(o, d, lo, hi, grid, emission=None):
    """Every plane crossing of every ray, sorted; each segment takes the voxel of its
    midpoint. Returns (optical depth, radiance with the exact per-segment integral)."""
    o, d, lo, hi, grid = f64(o, d, lo, hi, grid)
    sizes = torch.tensor(grid.shape[:3])
    voxel = (hi - lo) / sizes
    near, far, hit = ref_interval(o, d, lo, hi)
    ts = [near[:, None], far[:, None]]
    for a in range(3):
        planes = lo[a] + torch.arange(int(sizes[a]) + 1, dtype=F64) * voxel[a]
        t = (planes[None, :] - o[:, a : a + 1]) / d[:, a : a + 1]
        ts.append(t)
    t = torch.cat(ts, 1)
    t = torch.where(torch.isfinite(t), t, far[:, None])
    t = torch.minimum(torch.maximum(t, near[:, None]), far[:, None]).sort(dim=1).values
    seg = (t[:, 1:] - t[:, :-1]) * d.norm(dim=-1, keepdim=True)
    mid = o[:, None, :] + ((t[:, 1:] + t[:, :-1]) / 2)[..., None] * d[:, None, :]
    cell = torch.floor((mid - lo) / voxel).long()
    cell = torch.minimum(cell.clamp(min=0), sizes - 1)
    sigma = grid[cell[..., 0], cell[..., 1], cell[..., 2]]
    seg = torch.where(hit[:, None], seg, torch.zeros_like(seg)).nan_to_num(0.0)
    depth = (sigma * seg).sum(1)
    if emission is None:
        return depth, None
    (emission,) = f64(emission)
    q = emission[cell[..., 0], cell[..., 1], cell[..., 2]]
    radiance = torch.zeros(q.shape[:1] + q.shape[2:], dtype=F64)
    transmittance = torch.ones(len(o), dtype=F64)
    for k in range(seg.shape[1]):
        w = seg[:, k] * phi(sigma[:, k] * seg[:, k])
        w = w[:, None] if q.ndim == 3 else w
        tr = transmittance[:, None] if q.ndim == 3 else transmittance
        radiance += tr * w * q[:, k]
        transmittance = transmittance * torch.exp(-sigma[:, k] * seg[:, k])
    return depth, radiance


def ref_voxel_steps(o, d, lo, hi, sizes, tol):
    """The voxels each ray's chord crosses (float64): 1 + the interior voxel planes it
    crosses, 0 for a miss. Returns (count, clear): ``clear`` where no two crossings and no
    crossing and an end of the chord lie within ``eps = tol * (1 + t_far)`` of each other
    (there rounding may decide either way) and the chord is longer than ``2 eps``."""
    o, d, lo, hi = f64(o, d, lo, hi)
    near, far, hit = ref_interval(o, d, lo, hi)
    voxel = (hi - lo) / torch.tensor(sizes, dtype=F64)
    t = torch.cat(
        [
            (lo[a] + torch.arange(1, sizes[a], dtype=F64)[None] * voxel[a] - o[:, a : a + 1])
            / d[:, a : a + 1]
            for a in range(3)
        ],
        1,
    )
    t = torch.where(torch.isfinite(t), t, -INF)  # planes the ray runs along: never crossed
    near, far = near[:, None], far[:, None]
    crossed = (t > near) & (t < far)
    count = torch.where(hit, 1 + crossed.sum(1), 0)
    eps = tol * (1 + far.abs().nan_to_num(0))
    inner = torch.where(crossed, t, INF).sort(1).values
    gaps = (inner[:, 1:] - inner[:, :-1]).nan_to_num(INF)
    close = ((t - near).abs() <= eps) | ((t - far).abs() <= eps)
    clear = ~hit | ((far - near > 2 * eps)[:, 0] & ~close.any(1) & (gaps > eps).all(1))
    return count, clear


def ref_sphere_hit(o, d, center, radius):
    """Returns (t, cos, clearance), (N,) each: the first t >= 0 where the ray meets the
    sphere's surface (the far root from inside; inf where missed), the cosine of the angle
    of incidence there, and the distance of the ray's line from the surface (< 0: through)."""
    o, d = f64(o, d)
    c = torch.tensor(center, dtype=F64)
    f = o - c
    a = (d * d).sum(-1)
    b = (f * d).sum(-1)
    perp = f - (b / a)[:, None] * d
    disc = a * (radius**2 - (perp * perp).sum(-1))
    root = disc.clamp(min=0).sqrt()
    t0, t1 = (-b - root) / a, (-b + root) / a
    t = torch.where(t0 >= 0, t0, torch.where(t1 >= 0, t1, torch.full_like(t0, INF)))
    t = torch.where(disc >= 0, t, torch.full_like(t0, INF))
    hit_point = o + torch.where(torch.isfinite(t), t, torch.zeros_like(t))[:, None] * d
    normal = unit(hit_point - c)
    cos = ((normal * d).sum(-1) / a.sqrt()).abs()
    clearance = perp.norm(dim=-1) - radius  # distance of the line from the surface
    return t, cos, clearance


def ref_box_hit(o, d, center, half):
    """Returns (t, cos, chord), (N,) each: the first surface crossing of a ray starting
    outside the box (inf where missed), the cosine of the angle of incidence there, and
    the length in t of the ray's chord through the box (how far from clipping an edge)."""
    o, d = f64(o, d)
    c, h = torch.tensor(center, dtype=F64), torch.tensor(half, dtype=F64)
    near, far, hit = ref_interval(o, d, c - h, c + h)
    t = torch.where(hit & (near > 0), near, torch.full_like(near, INF))
    p = o + torch.where(torch.isfinite(t), t, torch.zeros_like(t))[:, None] * d
    face = ((p - c).abs() / h).argmax(-1)
    cos = d.gather(1, face[:, None])[:, 0].abs() / d.norm(dim=-1)
    return t, cos, far - near


# ---------------------------------------------------------------------------------------
# Task 1: the box ray marcher


BOX_LO, BOX_HI = (-0.5, 0.0, 0.25), (0.5, 1.5, 1.0)


@pytest.mark.task(1)
@pytest.mark.points(0.5)
def test_ray_box_interval(impl, device):
    for dtype, tol in ((F64, 1e-12), (torch.float32, 2e-6)):
        o, d = box_rays(400, seed=11, lo=BOX_LO, hi=BOX_HI, dtype=dtype)
        # Rays starting exactly on a slab plane, running along it (+0.0 / -0.0).
        o[::13, 0], d[::13, 0] = BOX_LO[0], 0.0
        o[1::13, 1], d[1::13, 1] = BOX_HI[1], -0.0
        lo = torch.tensor(BOX_LO, dtype=dtype, device=device)
        hi = torch.tensor(BOX_HI, dtype=dtype, device=device)
        result = impl.ray_box_interval(o.to(device), d.to(device), lo, hi)
        assert isinstance(result, tuple) and len(result) == 3, (
            "ray_box_interval: return a tuple (t_near, t_far, hit)"
        )
        near = (
            check_tensor(
                result[0], "ray_box_interval t_near", shape=(400,), dtype=dtype, device=device
            )
            .cpu()
            .double()
        )
        far = (
            check_tensor(
                result[1], "ray_box_interval t_far", shape=(400,), dtype=dtype, device=device
            )
            .cpu()
            .double()
        )
        hit = check_tensor(
            result[2], "ray_box_interval hit", shape=(400,), dtype=torch.bool, device=device
        ).cpu()
        r_near, r_far, r_hit = ref_interval(o, d, BOX_LO, BOX_HI)
        clear = (r_far - r_near).abs() > 1e-4 * (1 + r_far.abs())
        wrong = (hit != r_hit) & (clear | (r_hit & (r_far > r_near)))
        if wrong.any():
            i = int(wrong.nonzero()[0, 0])
            raise AssertionError(
                f"ray_box_interval ({dtype}): {int(wrong.sum())} of 400 rays decided wrongly. "
                f"First: ray {i}, origin {o[i].tolist()}, direction {d[i].tolist()}: the slabs "
                f"give [{r_near[i].item():.6g}, {r_far[i].item():.6g}] "
                f"({'hit' if r_hit[i] else 'miss'}), you report {'a hit' if hit[i] else 'a miss'}"
                f". Zero direction components: 1/+0 = +inf and 1/-0 = -inf; a ray starting on a "
                f"slab plane gives 0 * inf = NaN there, which must drop out (torch.fmax/fmin)."
            )
        assert_close(
            near[hit],
            r_near[hit],
            rtol=tol,
            atol=tol,
            name=f"ray_box_interval ({dtype}): t_near of hits (clipped to t >= 0)",
            where="hit",
        )
        assert_close(
            far[hit],
            r_far[hit],
            rtol=tol,
            atol=tol,
            name=f"ray_box_interval ({dtype}): t_far of hits",
            where="hit",
        )
        assert_equal(
            near[~hit],
            torch.zeros(int((~hit).sum()), dtype=F64),
            name="ray_box_interval: t_near of misses must be 0",
            where="miss",
        )
        assert_equal(
            far[~hit],
            torch.zeros(int((~hit).sum()), dtype=F64),
            name="ray_box_interval: t_far of misses must be 0",
            where="miss",
        )
        assert r_hit.float().mean() > 0.5 and (~r_hit).sum() > 20, "test set-up: hits/misses"

    # NaN/inf and zero directions miss; a box far from the origin in float32.
    bo, bd = bad_rays(torch.float32)
    near, far, hit = impl.ray_box_interval(bo.to(device), bd.to(device), [0.0] * 3, [1.0] * 3)
    assert not hit.cpu().any(), (
        f"ray_box_interval: NaN/inf origins or directions and zero directions must miss; "
        f"got hits for rays {hit.cpu().nonzero()[:, 0].tolist()}"
    )
    no_nan("ray_box_interval (NaN/inf rays)", t_near=near, t_far=far)
    shift = 1e5
    lo64, hi64 = torch.tensor(BOX_LO, dtype=F64) + shift, torch.tensor(BOX_HI, dtype=F64) + shift
    o, d = box_rays(200, seed=12, lo=lo64, hi=hi64, dtype=torch.float32)
    lo32, hi32 = lo64.float(), hi64.float()
    near, far, hit = impl.ray_box_interval(
        o.to(device), d.to(device), lo32.to(device), hi32.to(device)
    )
    r_near, r_far, r_hit = ref_interval(o, d, lo32, hi32)
    both = hit.cpu() & r_hit
    assert both.sum() > 100, "ray_box_interval: rays at a box at 1e5 should hit it"
    scale = r_far[both].abs() + 1
    assert_close(
        far.cpu().double()[both] / scale,
        r_far[both] / scale,
        atol=1e-5,
        name="ray_box_interval (float32 box at 1e5): t_far relative to |t| + 1; "
        "subtract box - origin before dividing",
        where="hit",
    )

    o, d = box_rays(8, seed=13, lo=BOX_LO, hi=BOX_HI)
    lo = torch.tensor(BOX_LO, dtype=F64, device=device)
    expect_error(
        "origins",
        impl.ray_box_interval,
        o[:, :2].to(device),
        d.to(device),
        lo,
        lo + 1,
        case="origins of shape (N, 2)",
    )
    expect_error(
        "directions",
        impl.ray_box_interval,
        o.to(device),
        d.long().to(device),
        lo,
        lo + 1,
        case="int64 directions",
    )
    expect_error(
        "box_min",
        impl.ray_box_interval,
        o.to(device),
        d.to(device),
        lo[:2],
        lo + 1,
        case="box_min of shape (2,)",
    )
    expect_error(
        "box_min",
        impl.ray_box_interval,
        o.to(device),
        d.to(device),
        lo.float(),
        lo + 1,
        case="a float32 box_min with float64 rays",
        kinds=(TypeError,),
    )
    expect_error(
        ("box_min", "box_max"),
        impl.ray_box_interval,
        o.to(device),
        d.to(device),
        lo + 1,
        lo,
        case="box_min > box_max",
    )


@pytest.mark.task(1)
@pytest.mark.points(0.5)
def test_ray_box_interval_closed_box(impl, device):
    # The box is closed: a ray through an edge, or across a flat box, touches it at one t;
    # a ray along the diagonal d = (1, 1, 1) (every component exactly 1) passes a corner.
    o = torch.tensor(
        [[-1.0, 1.0, 0.5], [0.25, 0.5, 0.0], [-2.0, -2.0, -2.0]], dtype=F64, device=device
    )
    d = torch.tensor([[1.0, -1.0, 0.0], [0.0, 0.0, 2.0], [1.0, 1.0, 1.0]], dtype=F64, device=device)
    boxes = (
        ([0.0, 0.0, 0.0], [1.0, 1.0, 1.0]),
        ([0.0, 0.0, 0.5], [1.0, 1.0, 0.5]),
        ([-1.0, -1.0, -1.0], [-1.0, 1.0, 1.0]),
    )
    for k, ((lo, hi), want) in enumerate(zip(boxes, (1.0, 0.25, 1.0))):
        near, far, hit = impl.ray_box_interval(o[k : k + 1], d[k : k + 1], lo, hi)
        what = f"ray o={o[k].tolist()} d={d[k].tolist()} box {lo}..{hi}"
        assert bool(hit.cpu()[0]), (
            f"ray_box_interval ({what}): it touches the closed box at t = {want} "
            f"(t_near = t_far), so hit must be True (hit = t_near <= t_far)"
        )
        got = (float(near.cpu()[0]), float(far.cpu()[0]))
        assert abs(got[0] - want) <= 1e-12 and abs(got[1] - want) <= 1e-12, (
            f"ray_box_interval ({what}): expected t_near = t_far = {want}, got {got}"
        )


@pytest.mark.task(1)
@pytest.mark.points(0.5)
def test_sample_grid_trilinear(impl, device):
    g = generator(21)
    grid = torch.rand(3, 4, 5, generator=g, dtype=F64)
    color = torch.rand(3, 4, 5, 2, generator=g, dtype=F64)
    uvw = torch.rand(300, 3, generator=g, dtype=F64) * 1.4 - 0.2  # some outside: border
    uvw[:8] = torch.tensor(
        [
            [0.5, 0.5, 0.5],
            [1 / 6, 1 / 8, 1 / 10],
            [5 / 6, 7 / 8, 9 / 10],
            [0.0, 0.0, 0.0],
            [1.0, 1.0, 1.0],
            [0.5, 0.0, 1.0],
            [1 / 3, 0.25, 0.2],
            [0.999, 0.001, 0.5],
        ],
        dtype=F64,
    )

    def reference(grid, uvw):
        # grid_sample wants (N, C, D, H, W) = (1, C, Z, Y, X) and (x, y, z) in [-1, 1].
        g5 = (
            grid.permute(2, 1, 0, *range(3, grid.ndim))
            if grid.ndim == 3
            else grid.permute(3, 2, 1, 0)
        )
        g5 = g5[None, None] if grid.ndim == 3 else g5[None]
        out = torch.nn.functional.grid_sample(
            g5, (2 * uvw - 1)[None, None, None], align_corners=False, padding_mode="border"
        )
        return out[0, :, 0, 0].T if grid.ndim == 4 else out[0, 0, 0, 0]

    for dtype, tol in ((F64, 1e-13), (torch.float32, 2e-6)):
        got = check_tensor(
            impl.sample_grid(grid.to(device, dtype), uvw.to(device, dtype)),
            "sample_grid(grid (3, 4, 5), uvw (300, 3))",
            shape=(300,),
            dtype=dtype,
            device=device,
        )
        assert_close(
            got,
            reference(grid, uvw.to(dtype).double()),
            atol=tol,
            name=f"sample_grid ({dtype}): trilinear value between voxel centres "
            f"(grid[i, j, k] at ((i, j, k) + 0.5) / (X, Y, Z); x indexes the "
            f"first axis; clamped to the border)",
            where="point",
        )
    got = check_tensor(
        impl.sample_grid(color.to(device), uvw.to(device)),
        "sample_grid(grid (3, 4, 5, 2), uvw (300, 3))",
        shape=(300, 2),
        dtype=F64,
        device=device,
    )
    assert_close(
        got,
        reference(color, uvw),
        atol=1e-13,
        name="sample_grid: a grid with 2 channels (X, Y, Z, C)",
        where="point",
    )
    # Batched points (..., 3); a one-voxel grid is constant; NaN coordinates give 0.
    got = impl.sample_grid(grid.to(device), uvw.reshape(10, 30, 3).to(device))
    check_tensor(got, "sample_grid with uvw (10, 30, 3)", shape=(10, 30), dtype=F64, device=device)
    assert_close(
        got.reshape(-1),
        reference(grid, uvw),
        atol=1e-13,
        name="sample_grid with uvw of shape (10, 30, 3)",
        where="point",
    )
    one = torch.full((1, 1, 1), 0.7, dtype=F64, device=device)
    assert_close(
        impl.sample_grid(one, uvw.to(device)),
        torch.full((300,), 0.7, dtype=F64),
        atol=1e-15,
        name="sample_grid of a (1, 1, 1) grid: constant",
        where="point",
    )
    nan_points = torch.tensor([[math.nan, 0.5, 0.5], [0.5, 0.5, math.nan]], dtype=F64)
    got = impl.sample_grid(grid.to(device), nan_points.to(device))
    assert_equal(
        got,
        torch.zeros(2, dtype=F64),
        name="sample_grid at NaN coordinates must give 0 (never an index from a NaN)",
        where="point",
    )
    assert_equal(
        impl.sample_grid(color.to(device), nan_points.to(device)),
        torch.zeros(2, color.shape[-1], dtype=F64),
        name="sample_grid of a grid with channels (X, Y, Z, C) at NaN coordinates: 0 in every "
        "channel",
        where="point",
    )
    # An opaque voxel (+inf) next to an empty one, and an opaque one-voxel grid: inf where
    # the opaque voxel weighs, its neighbour's value where it weighs nothing (not 0 * inf).
    opaque = torch.tensor([math.inf, 0.0], dtype=F64).reshape(2, 1, 1)
    at = torch.tensor([[0.1, 0.5, 0.5], [0.5, 0.3, 0.9], [0.75, 0.5, 0.5], [1.2, 0.0, 1.0]])
    for field, want in (
        (opaque, [math.inf, math.inf, 0.0, 0.0]),
        (opaque[:1], [math.inf] * 4),
        (
            torch.stack([opaque, opaque.flip(0)], -1),
            [[math.inf, 0.0], [math.inf] * 2, [0.0, math.inf], [0.0, math.inf]],
        ),
    ):
        got = impl.sample_grid(field.to(device), at.to(F64).to(device)).cpu()
        assert got.tolist() == want, (
            f"sample_grid of the grid {field.squeeze().tolist()} (+inf is an opaque voxel) at "
            f"{at.tolist()}: expected {want}, got {got.tolist()}; a corner of weight 0 adds "
            f"nothing, even +inf (0 * inf is NaN)"
        )
    expect_error("grid", impl.sample_grid, grid[0].to(device), uvw.to(device), case="a 2-D grid")
    expect_error(
        "uvw", impl.sample_grid, grid.to(device), uvw[:, :2].to(device), case="uvw of shape (N, 2)"
    )
    expect_error(
        ("grid", "uvw"),
        impl.sample_grid,
        grid.float().to(device),
        uvw.to(device),
        case="a float32 grid with float64 uvw",
    )


def march(impl, *args, what="march_box", n=None, dtype=None, device=None, channels=None, **kwargs):
    result = impl.march_box(*args, **kwargs)
    return result_dict(result, what, MARCH_KEYS, n, dtype, device, channels)


def given_field(field, points, local):
    """A medium's values at N points (a callable at world points, a grid trilinearly at box
    coordinates, as ``sample_grid``): (N,) or (N, C)."""
    if not isinstance(field, torch.Tensor):
        return field(points).to(points.dtype)
    g5 = field.permute(2, 1, 0, *range(3, field.ndim))  # (Z, Y, X[, C])
    g5 = g5[None, None] if field.ndim == 3 else g5.permute(3, 0, 1, 2)[None]
    out = torch.nn.functional.grid_sample(
        g5.to(points.dtype),
        (2 * local - 1)[None, None, None],
        align_corners=False,
        padding_mode="border",
    )
    return out[0, :, 0, 0].T if field.ndim == 4 else out[0, 0, 0, 0]


def march_given_box(
    lab, origins, directions, box_min, box_max, density, emission, steps, integrator="exact"
):
    """The midpoint march of task 1, given (the grader's own interval, sampling and
    front-to-back loop), calling the lab's ``segment_integral`` (task 2) for each step: task
    2 is graded on its own, whatever the lab's ``march_box``. Returns ``march_box``'s dict."""
    like = {"dtype": origins.dtype, "device": origins.device}
    lo, hi = (torch.as_tensor(b).to(**like) for b in (box_min, box_max))
    near, far, hit = (x.to(origins.device) for x in ref_interval(origins, directions, lo, hi))
    near, far = (torch.where(hit, x, 0).to(origins.dtype) for x in (near, far))
    dt = (far - near) / max(steps, 1)
    ds = dt * directions.norm(dim=-1)
    radiance, transmittance = 0, torch.ones(len(origins), **like)
    for i in range(steps):
        offset = (origins - lo) + (near + (i + 0.5) * dt)[:, None] * directions
        # box coordinates; a flat axis (lo = hi) is read at its middle, as documented
        local = torch.where(hi > lo, offset / torch.where(hi > lo, hi - lo, 1), 0.5)
        points = lo + offset
        sigma = torch.where(hit, given_field(density, points, local), 0)
        weight, t_seg = lab.segment_integral(sigma, torch.where(hit, ds, 0), integrator)
        if emission is not None:
            q = torch.where(hit, given_field(emission, points, local), 0)
            radiance = radiance + transmittance * weight * q
        transmittance = transmittance * t_seg
    if not isinstance(radiance, torch.Tensor):
        radiance = torch.zeros(len(origins), **like)
    samples = torch.where(hit, steps, 0)
    return {"radiance": radiance, "transmittance": transmittance, "samples": samples}


def march_given(impl, *args, what="march_box", n=None, dtype=None, device=None, **kwargs):
    """``march_box``'s results from the given march (task 1) with the lab's
    ``segment_integral``: how task 2 reaches ``segment_integral`` through whole marches."""
    result = impl.probe(march_given_box, *args, **kwargs)
    return result_dict(
        result, f"{what} (the given march, your segment_integral)", MARCH_KEYS, n, dtype, device
    )


@pytest.mark.task(1)
@pytest.mark.points(1)
def test_march_box_homogeneous_and_layered(impl, device):
    sigma, q = 1.7, 0.6
    o, d = box_rays(240, seed=31, lo=BOX_LO, hi=BOX_HI)
    bo, bd = bad_rays()
    o, d = torch.cat([o, bo]), torch.cat([d, bd])
    n = len(o)
    near, far, hit = ref_interval(o, d, BOX_LO, BOX_HI)
    length = torch.where(hit, (far - near) * d.norm(dim=-1).nan_to_num(0), torch.zeros_like(near))
    want_l = q * length * phi(sigma * length)
    want_t = torch.exp(-sigma * length)
    clear = ~hit | ((far - near) > 1e-6)
    for dtype, tol in ((F64, 1e-12), (torch.float32, 3e-6)):
        lo = torch.tensor(BOX_LO, dtype=dtype, device=device)
        hi = torch.tensor(BOX_HI, dtype=dtype, device=device)
        dens = torch.full((1, 1, 1), sigma, dtype=dtype, device=device)
        emis = torch.full((2, 3, 2), q, dtype=dtype, device=device)
        for steps in (1, 3, 16):
            what = f"march_box (homogeneous box, {dtype}, steps={steps})"
            got = march(
                impl,
                o.to(device, dtype),
                d.to(device, dtype),
                lo,
                hi,
                dens,
                emis,
                steps,
                what=what,
                n=n,
                dtype=dtype,
                device=device,
            )
            no_nan(what, **{k: v for k, v in got.items() if k != "samples"})
            # The step count first: a loop one step short shows there, by its cause.
            want_samples = torch.where(hit, steps, 0)
            assert_equal(
                got["samples"].cpu()[clear],
                want_samples[clear],
                name=f"{what}: samples per ray ({steps} = steps for rays through the "
                f"box: the loop runs `steps` times; 0 for misses and NaN/inf "
                f"rays)",
                where="ray",
            )
            assert_close(
                got["transmittance"].cpu()[clear],
                want_t[clear],
                rtol=tol,
                atol=tol,
                name=f"{what}: transmittance exp(-sigma D), D in world units "
                f"(|d| times the span in t)",
                where="ray",
            )
            radiance = got["radiance"].cpu()[clear]
            # Updating T before adding the step's light dims every step by one step's
            # transmittance: name that order only when the numbers show it.
            late = want_l * torch.exp(-sigma * length / steps)
            hint = (
                " The radiance is one step's transmittance too dark: add L += T * q * w "
                "before updating T *= e^(-sigma ds)"
                if torch.allclose(radiance.double(), late[clear], rtol=10 * tol, atol=10 * tol)
                else ""
            )
            assert_close(
                radiance,
                want_l[clear],
                rtol=tol,
                atol=tol,
                name=f"{what}: radiance against q (1 - e^(-sigma D)) / sigma (exact for "
                f"a constant medium with any number of steps).{hint}",
                where="ray",
            )
    # Channels from a (X, Y, Z, C) grid and from an (N, C) callable.
    lo, hi = torch.tensor(BOX_LO, dtype=F64), torch.tensor(BOX_HI, dtype=F64)
    dens = torch.full((1, 1, 1), sigma, dtype=F64)
    rgb = torch.tensor([0.6, 0.3, 0.1], dtype=F64)
    for name, emission in (
        ("grid (1, 1, 1, 3)", rgb.expand(1, 1, 1, 3).clone().to(device)),
        ("callable returning (N, 3)", rgb_emission),
    ):
        got = march(
            impl,
            o.to(device),
            d.to(device),
            lo.to(device),
            hi.to(device),
            dens.to(device),
            emission,
            4,
            what=f"march_box (emission {name})",
            n=n,
            dtype=F64,
            device=device,
            channels=3,
        )
        assert_close(
            got["radiance"].cpu()[clear],
            (want_l[:, None] / q * rgb)[clear],
            rtol=1e-12,
            atol=1e-12,
            name=f"march_box: radiance (N, 3) with emission {name}",
            where="(ray, channel)",
        )
    # A purely absorbing medium (emission None) and an empty march (steps = 0).
    got = march(
        impl,
        o.to(device),
        d.to(device),
        lo.to(device),
        hi.to(device),
        dens.to(device),
        None,
        5,
        what="march_box (emission=None)",
        n=n,
        dtype=F64,
        device=device,
    )
    assert_equal(
        got["radiance"],
        torch.zeros(n, dtype=F64),
        name="march_box (emission=None): radiance",
        where="ray",
    )
    got = march(
        impl,
        o.to(device),
        d.to(device),
        lo.to(device),
        hi.to(device),
        dens.to(device),
        rgb.expand(1, 1, 1, 3).clone().to(device),
        0,
        what="march_box (steps=0)",
        n=n,
        dtype=F64,
        device=device,
        channels=3,
    )
    assert_equal(
        got["radiance"],
        torch.zeros(n, 3, dtype=F64),
        name="march_box (steps=0): an empty march emits nothing",
        where="ray",
    )
    assert_equal(
        got["transmittance"],
        torch.ones(n, dtype=F64),
        name="march_box (steps=0): transmittance 1",
        where="ray",
    )

    # Two layers (sigma 4 then 0.5; emission 0.2 then 1), steps aligned with the boundary:
    # exact, and only in front-to-back order.
    lo, hi = [0.0] * 3, [1.0] * 3
    o, d = x_face_rays(64, seed=32)
    want_l, want_t = layer_reference(o, d)
    for steps in (2, 4, 6):
        what = f"march_box (two layers, steps={steps})"
        got = march(
            impl,
            o.to(device),
            d.to(device),
            lo,
            hi,
            layer_density,
            layer_emission,
            steps,
            what=what,
            n=64,
            dtype=F64,
            device=device,
        )
        assert_close(
            got["radiance"],
            want_l,
            rtol=1e-12,
            atol=1e-13,
            name=f"{what}: radiance. The front layer's light is seen directly, the "
            f"back layer's through the front one: composite front to back, "
            f"L += T q w, then T *= T_step",
            where="ray",
        )
        assert_close(
            got["transmittance"], want_t, rtol=1e-12, name=f"{what}: transmittance", where="ray"
        )
    cpu_agrees(
        device,
        "march_box",
        got,
        impl.march_box,
        o.to(device),
        d.to(device),
        lo,
        hi,
        layer_density,
        layer_emission,
        6,
    )


@pytest.mark.task(1)
@pytest.mark.points(0.5)
def test_march_box_early_termination_and_jitter(impl, device):
    # Early termination: a dense box; rays stop once T < 1e-2 and lose at most that much.
    o, d = x_face_rays(64, seed=41)
    o = torch.cat([o, torch.tensor([[5.0, 5.0, 5.0]] * 8, dtype=F64)])  # 8 misses
    d = torch.cat([d, torch.tensor([[1.0, 0.0, 0.0]] * 8, dtype=F64)])
    sigma, q = 50.0, 1.0
    near, far, hit = ref_interval(o, d, [0.0] * 3, [1.0] * 3)
    length = torch.where(hit, (far - near) * d.norm(dim=-1), 0.0)
    want = q * length * phi(sigma * length)
    dens = torch.full((1, 1, 1), sigma, dtype=F64, device=device)
    emis = torch.full((1, 1, 1), q, dtype=F64, device=device)
    full = march(
        impl,
        o.to(device),
        d.to(device),
        [0.0] * 3,
        [1.0] * 3,
        dens,
        emis,
        64,
        what="march_box (dense, min_transmittance=0)",
        n=72,
        dtype=F64,
        device=device,
    )
    assert_equal(
        full["samples"],
        torch.where(hit, 64, 0),
        name="march_box with min_transmittance=0: every step is taken",
        where="ray",
    )
    for threshold in (1e-2, 0.3):
        what = f"march_box (dense box, min_transmittance={threshold})"
        got = march(
            impl,
            o.to(device),
            d.to(device),
            [0.0] * 3,
            [1.0] * 3,
            dens,
            emis,
            64,
            min_transmittance=threshold,
            what=what,
            n=72,
            dtype=F64,
            device=device,
        )
        samples = got["samples"].cpu()
        assert (
            (samples[hit] < 64).all() and (samples[hit] >= 1).all() and (samples[~hit] == 0).all()
        ), (
            f"{what}: each ray crossing the box should stop after a few of its 64 steps, once "
            f"its transmittance falls below {threshold}; samples per ray: {samples.tolist()}"
        )
        radiance = got["radiance"].cpu()
        lost = want - radiance
        bound = threshold * q / sigma * 1.0001 + 1e-12
        bad = (lost < -1e-12) | (lost > bound)
        assert not bad.any(), (
            f"{what}: the radiance may only lose what lies behind the stopping point, at most "
            f"min_transmittance * q / sigma = {bound:.3g}; ray {int(bad.nonzero()[0, 0])} lost "
            f"{lost[bad][0].item():.3g}"
        )
        tr = got["transmittance"].cpu()
        assert (tr[hit] < threshold).all() and (tr[hit] > 0).all(), (
            f"{what}: a stopped ray reports the transmittance it stopped with (below the "
            f"threshold, above 0); got {tr[hit][:5].tolist()}"
        )

    # Jitter: one offset xi per ray for all its steps. With sigma = x along +x through
    # [0, 1]^3 and S steps, -log T = (S (S - 1) / 2 + S xi) / S^2.
    n = 600
    o = torch.cat(
        [torch.full((n, 1), -1.0, dtype=F64), torch.rand(n, 2, generator=generator(42), dtype=F64)],
        1,
    )
    d = torch.tensor([[1.0, 0.0, 0.0]], dtype=F64).expand(n, 3)

    def offsets(steps, **kwargs):
        got = march(
            impl,
            o.to(device),
            d.to(device),
            [0.0] * 3,
            [1.0] * 3,
            x_density,
            None,
            steps,
            what=f"march_box (jitter, steps={steps})",
            n=n,
            dtype=F64,
            device=device,
            **kwargs,
        )
        tau = -torch.log(got["transmittance"].cpu())
        return (tau * steps * steps - steps * (steps - 1) / 2) / steps

    plain = offsets(1)
    assert_close(
        plain,
        torch.full((n,), 0.5, dtype=F64),
        atol=1e-12,
        name="march_box without jitter samples the middle of each step",
        where="ray",
    )
    xi = offsets(1, jitter=True, seed=7)
    assert ((xi >= -1e-12) & (xi <= 1 + 1e-12)).all(), (
        f"march_box(jitter=True): the offset within the step must lie in [0, 1]; recovered "
        f"offsets range {xi.min().item():.3g} .. {xi.max().item():.3g}"
    )
    assert abs(xi.mean().item() - 0.5) < 0.05 and abs(xi.std().item() - 12**-0.5) < 0.04, (
        f"march_box(jitter=True): offsets should be uniform in [0, 1) (mean 0.5, std 0.289), "
        f"got mean {xi.mean().item():.3f}, std {xi.std().item():.3f}"
    )
    assert_close(
        offsets(1, jitter=True, seed=7),
        xi,
        atol=0.0,
        name="march_box(jitter=True, seed=7) twice: the same seed must give the same offsets",
        where="ray",
    )
    assert_close(
        offsets(4, jitter=True, seed=7),
        xi,
        atol=1e-9,
        name="march_box(jitter=True, seed=7) with 4 steps: one offset per ray, the "
        "same for all its steps (and for any step count)",
        where="ray",
    )
    other = offsets(1, jitter=True, seed=8)
    assert (other - xi).abs().max() > 0.1, "march_box: another seed must give other offsets"
    assert_close(
        offsets(1, jitter=True),
        offsets(1, jitter=True, seed=0),
        atol=0.0,
        name="march_box(jitter=True) without a seed: the signature's default seed=0 "
        "(the same offsets as seed=0)",
        where="ray",
    )


@pytest.mark.task(1)
@pytest.mark.points(0.5)
def test_march_box_stops_only_below_threshold(impl, device):
    # "A ray whose T has dropped *below* min_transmittance stops": T equal to it goes on.
    o = torch.tensor([[-1.0, 0.3, 0.6], [-1.0, 0.7, 0.2]], dtype=F64)
    d = torch.tensor([[1.0, 0.1, 0.0], [2.0, 0.0, -0.1]], dtype=F64)
    steps = 8
    cases = (
        (
            "a dense box (density 1e4: T = 0 after one step), min_transmittance=0: T = 0 is "
            "not below 0",
            1e4,
            0.0,
        ),
        ("vacuum (density 0), min_transmittance=1: T = 1 is not below 1", 0.0, 1.0),
    )
    for what, sigma, floor in cases:
        got = march(
            impl,
            o.to(device),
            d.to(device),
            [0.0] * 3,
            [1.0] * 3,
            torch.full((1, 1, 1), sigma, dtype=F64, device=device),
            None,
            steps,
            min_transmittance=floor,
            what=f"march_box ({what})",
            n=2,
            dtype=F64,
            device=device,
        )
        samples = got["samples"].cpu().tolist()
        assert samples == [steps, steps], (
            f"march_box ({what}): every ray must take all {steps} steps, got samples "
            f"{samples}; stop only when T < min_transmittance"
        )


@pytest.mark.task(1)
@pytest.mark.points(0.5)
def test_march_box_extremes(impl, device):
    o, d = x_face_rays(32, seed=51)
    near, far, _ = ref_interval(o, d, [0.0] * 3, [1.0] * 3)
    length = (far - near) * d.norm(dim=-1)
    q = 0.5
    for dtype in (torch.float32, F64):
        for sigma in (0.0, 1e-8, 1e8):
            what = f"march_box (sigma={sigma:g}, {dtype})"
            dens = torch.full((1, 1, 1), sigma, dtype=dtype, device=device)
            emis = torch.full((1, 1, 1), q, dtype=dtype, device=device)
            for integrator in ("exact", "riemann"):
                got = march(
                    impl,
                    o.to(device, dtype),
                    d.to(device, dtype),
                    [0.0] * 3,
                    [1.0] * 3,
                    dens,
                    emis,
                    8,
                    integrator=integrator,
                    what=what,
                    n=32,
                    dtype=dtype,
                    device=device,
                )
                no_nan(
                    f"{what}, {integrator}",
                    radiance=got["radiance"],
                    transmittance=got["transmittance"],
                )
            got = march(
                impl,
                o.to(device, dtype),
                d.to(device, dtype),
                [0.0] * 3,
                [1.0] * 3,
                dens,
                emis,
                8,
                what=what,
                n=32,
                dtype=dtype,
                device=device,
            )
            want = q * length * phi(sigma * length)
            assert_close(
                got["radiance"],
                want,
                rtol=1e-5,
                name=f"{what}: radiance (limit q D for sigma -> 0, q / sigma for sigma -> inf)",
                where="ray",
            )
            assert_close(
                got["transmittance"],
                torch.exp(-sigma * length),
                rtol=1e-5,
                atol=1e-30,
                name=f"{what}: transmittance",
                where="ray",
            )
    # float16 / bfloat16: loose.
    sigma = 1.7
    want = q * length * phi(sigma * length)
    for dtype, tol in ((torch.float16, 2e-2), (torch.bfloat16, 6e-2)):
        what = f"march_box ({dtype})"
        got = march(
            impl,
            o.to(device, dtype),
            d.to(device, dtype),
            [0.0] * 3,
            [1.0] * 3,
            torch.full((1, 1, 1), sigma, dtype=dtype, device=device),
            torch.full((1, 1, 1), q, dtype=dtype, device=device),
            8,
            what=what,
            n=32,
            dtype=dtype,
            device=device,
        )
        no_nan(what, radiance=got["radiance"], transmittance=got["transmittance"])
        assert_close(got["radiance"], want, rtol=tol, name=f"{what}: radiance", where="ray")
        assert_close(
            got["transmittance"],
            torch.exp(-sigma * length),
            atol=tol,
            name=f"{what}: transmittance",
            where="ray",
        )
    # A varied grid in a box at 1e5, float32: the same answer as near the origin.
    g = generator(52)
    grid = torch.rand(4, 4, 4, generator=g, dtype=F64) * 3
    emis = torch.rand(4, 4, 4, generator=g, dtype=F64)
    results = []
    # A box of sides 2, 0.5 and 1.5 (grid coordinates are divided by each side), the rays
    # scaled with it; origins and corners exactly representable at both offsets (multiples
    # of 1/128 near the box).
    corner = torch.tensor([0.25, -0.5, 0.0], dtype=F64)
    side = torch.tensor([2.0, 0.5, 1.5], dtype=F64)
    oo = corner + torch.round(o * 64) / 64 * side
    dd = d * side
    for shift, dtype in ((0.0, F64), (1e5, torch.float32)):
        got = march(
            impl,
            (oo + shift).to(device, dtype),
            dd.to(device, dtype),
            (corner + shift).tolist(),
            (corner + side + shift).tolist(),
            grid.to(device, dtype),
            emis.to(device, dtype),
            16,
            what=f"march_box (box at {shift:g}, {dtype})",
            n=32,
            dtype=dtype,
            device=device,
        )
        results.append(got)
    # The float64 march at the origin against the grader's midpoint march (grids sampled
    # with grid_sample at box coordinates, the exact step in float64).
    want = march_given_box(
        SimpleNamespace(segment_integral=lambda s, ds, _: given_step(s, ds)),
        oo,
        dd,
        corner.tolist(),
        (corner + side).tolist(),
        grid,
        emis,
        16,
    )
    for key in ("radiance", "transmittance"):
        assert_close(
            results[0][key],
            want[key],
            rtol=1e-9,
            atol=1e-12,
            name=f"march_box (a varied 4x4x4 grid in a box of sides 2, 0.5, 1.5, float64): {key} "
            f"against a midpoint "
            f"march sampling the grids trilinearly at the box coordinates "
            f"((o - box_min) + t d) / (box_max - box_min)",
            where="ray",
        )
    assert_close(
        results[1]["radiance"],
        results[0]["radiance"],
        rtol=1e-4,
        atol=1e-6,
        name="march_box: float32 radiance of a varied grid in a box at 1e5 against "
        "the same scene at the origin in float64. Sample the grid at "
        "((o - box_min) + t d) / size, not at (o + t d - box_min) / size: the "
        "absolute point rounds to 1/128 at 1e5",
        where="ray",
    )
    # Bad input.
    dev = {"device": device}
    oo, dd = o.to(device), d.to(device)
    dens = torch.full((1, 1, 1), 1.0, dtype=F64, **dev)
    expect_error(
        "steps", impl.march_box, oo, dd, [0.0] * 3, [1.0] * 3, dens, None, -1, case="steps=-1"
    )
    expect_error(
        "steps", impl.march_box, oo, dd, [0.0] * 3, [1.0] * 3, dens, None, 2.5, case="steps=2.5"
    )
    expect_error(
        "integrator",
        impl.march_box,
        oo,
        dd,
        [0.0] * 3,
        [1.0] * 3,
        dens,
        None,
        4,
        integrator="midpoint",
        case="integrator='midpoint'",
    )
    expect_error(
        "density",
        impl.march_box,
        oo,
        dd,
        [0.0] * 3,
        [1.0] * 3,
        dens.long(),
        None,
        4,
        case="an int64 density grid",
    )
    expect_error(
        "emission",
        impl.march_box,
        oo,
        dd,
        [0.0] * 3,
        [1.0] * 3,
        dens,
        dens.float(),
        4,
        case="a float32 emission grid with float64 rays",
    )
    expect_error(
        "density",
        impl.march_box,
        oo,
        dd,
        [0.0] * 3,
        [1.0] * 3,
        wrong_shape_density,
        None,
        4,
        case="a density callable returning (N, 3)",
    )
    expect_error(
        "min_transmittance",
        impl.march_box,
        oo,
        dd,
        [0.0] * 3,
        [1.0] * 3,
        dens,
        None,
        4,
        min_transmittance=1.5,
        case="min_transmittance=1.5",
    )
    # A negative extinction would give T > 1: an error naming density, grid or callable.
    expect_error(
        "density",
        impl.march_box,
        oo,
        dd,
        [0.0] * 3,
        [1.0] * 3,
        -dens,
        None,
        4,
        case="a density grid of -1 (transmittance above 1)",
    )
    expect_error(
        "density",
        impl.march_box,
        oo,
        dd,
        [0.0] * 3,
        [1.0] * 3,
        negative_density,
        None,
        4,
        case="a density callable returning -1 (transmittance above 1)",
    )
    # A NaN extinction would make every transmittance behind it NaN: refused, not marched.
    nan_grid = torch.full_like(dens, math.nan)
    expect_error(
        "density",
        impl.march_box,
        oo,
        dd,
        [0.0] * 3,
        [1.0] * 3,
        nan_grid,
        None,
        4,
        kinds=(ValueError,),
        case="a density grid of NaN (check it before marching)",
    )
    expect_error(
        "density",
        impl.march_box,
        oo,
        dd,
        [0.0] * 3,
        [1.0] * 3,
        nan_density,
        None,
        4,
        kinds=(ValueError,),
        case="a density callable returning NaN (the provided evaluate checks its values: call it)",
    )
    # A flat box (z from 0.5 to 0.5) and rays in its plane: the chord runs along x and y, and
    # the grids (varying along z) are read at the flat axis's middle, box coordinate 0.5 as
    # documented, never 0 / 0 = NaN (which sample_grid turns into 0).
    flat_rays, flat_dirs = o.clone(), d.clone()
    flat_rays[:, 2], flat_dirs[:, 2] = 0.5, 0.0
    got = march(
        impl,
        flat_rays.to(device),
        flat_dirs.to(device),
        [0.0, 0.0, 0.5],
        [1.0, 1.0, 0.5],
        grid[:, :, :2].to(device),
        emis[:, :, :2].to(device),
        8,
        what="march_box (flat box z = 0.5, rays in its plane)",
        n=32,
        dtype=F64,
        device=device,
    )
    want = march_given_box(
        SimpleNamespace(segment_integral=lambda s, ds, _: given_step(s, ds)),
        flat_rays,
        flat_dirs,
        [0.0] * 3,
        [1.0] * 3,
        grid[:, :, :2],
        emis[:, :, :2],
        8,
    )
    for key in ("radiance", "transmittance"):
        assert_close(
            got[key],
            want[key],
            rtol=1e-9,
            atol=1e-12,
            name=f"march_box (a flat box z in [0.5, 0.5], rays in the plane z = 0.5, grids "
            f"varying along z): {key} against the same rays through the box [0, 1]^3. A flat "
            f"axis is read at its middle (0.5); it has size 0: do not divide by it",
            where="ray",
        )
    # The default steps is 64.
    plain = march(
        impl,
        o.to(device),
        d.to(device),
        [0.0] * 3,
        [1.0] * 3,
        grid.to(device),
        emis.to(device),
        what="march_box (default steps)",
        n=32,
        dtype=F64,
        device=device,
    )
    spelled = march(
        impl,
        o.to(device),
        d.to(device),
        [0.0] * 3,
        [1.0] * 3,
        grid.to(device),
        emis.to(device),
        64,
        integrator="exact",
        min_transmittance=0.0,
        jitter=False,
        seed=0,
        what="march_box (steps=64)",
        n=32,
        dtype=F64,
        device=device,
    )
    for key in MARCH_KEYS:
        assert_equal(
            plain[key],
            spelled[key],
            name=f"march_box: {key} with the default arguments vs steps=64, "
            f"integrator='exact', min_transmittance=0, jitter=False spelled out",
            where="ray",
        )


# ---------------------------------------------------------------------------------------
# Task 2: the per-step integral


@pytest.mark.task(2)
@pytest.mark.points(1)
def test_segment_integral_values_and_limits(impl, device):
    x = torch.cat([torch.tensor([0.0]), 10.0 ** torch.linspace(-30, 4, 69, dtype=F64)])
    lengths = torch.tensor([1e-3, 1.0, 7.0], dtype=F64)
    sigma = x[:, None] / lengths[None, :]  # (70, 3): sigma D = x for every length
    for dtype, tol in ((F64, 4e-15), (torch.float32, 4e-7)):
        s = sigma.to(dtype).to(device)
        ln = lengths[None, :].to(dtype).to(device)
        result = impl.segment_integral(s, ln, "exact")
        assert isinstance(result, tuple) and len(result) == 2, (
            "segment_integral: return a tuple (weight, transmittance)"
        )
        w = check_tensor(
            result[0], "segment_integral weight", shape=(70, 3), dtype=dtype, device=device
        )
        t = check_tensor(
            result[1], "segment_integral transmittance", shape=(70, 3), dtype=dtype, device=device
        )
        no_nan(f"segment_integral ({dtype})", weight=w, transmittance=t)
        # The reference from the rounded inputs.
        s64, l64 = s.cpu().double(), ln.cpu().double()
        ref_w = l64 * phi(s64 * l64)
        assert_close(
            w,
            ref_w,
            rtol=tol,
            atol=0,
            name=f"segment_integral ({dtype}, exact): weight (1 - e^(-sigma D)) / sigma "
            f"for sigma D from 0 to 1e4. Write it as D * (-expm1(-x) / x), x = "
            f"sigma D, with the limit D at x = 0 (1 - exp(-x) cancels for small x)",
            where="(x, length)",
        )
        x64 = s64 * l64  # exp(-x) inherits the rounding of the product, eps * x relative
        assert_close(
            t.cpu().double() / torch.exp(-x64).clamp(min=1e-300),
            torch.ones_like(x64),
            atol=tol * (1 + float(x64[x64 < 80].max())),
            mask=x64 < 80,
            name=f"segment_integral ({dtype}): transmittance exp(-sigma D), relative",
            where="(x, length)",
        )
    # Limits, one by one.
    cases = [
        (0.0, 2.0, 2.0, 1.0),
        (1e-8, 1.0, 1.0 - 0.5e-8, 1.0 - 1e-8),
        (1e8, 1.0, 1e-8, 0.0),
        (INF, 1.0, 0.0, 0.0),
        (INF, 0.0, 0.0, 1.0),
        (3.0, 0.0, 0.0, 1.0),
    ]
    s = torch.tensor([c[0] for c in cases], dtype=F64, device=device)
    ln = torch.tensor([c[1] for c in cases], dtype=F64, device=device)
    w, t = impl.segment_integral(s, ln, "exact")
    no_nan(
        "segment_integral (sigma in {0, 1e-8, 1e8, inf}, lengths 0 and 1)",
        weight=w,
        transmittance=t,
    )
    for i, (sg, length, ww, tt) in enumerate(cases):
        assert (
            abs(w.cpu()[i].item() - ww) <= 1e-15 + 1e-12 * ww
            and abs(t.cpu()[i].item() - tt) <= 1e-15
        ), (
            f"segment_integral(sigma={sg}, length={length}): expected weight {ww!r} and "
            f"transmittance {tt!r}, got {w.cpu()[i].item()!r} and {t.cpu()[i].item()!r} "
            f"(vacuum: the length; opaque: 1/sigma; a zero-length step: no step at all)"
        )
    # An endless step (length = inf, all that lies behind the last sample) is the limit,
    # never inf * 0 = NaN: the tail's 1/sigma, and vacuum forever adds endless light.
    endless = [(2.0, 0.5, 0.0), (0.25, 4.0, 0.0), (INF, 0.0, 0.0), (0.0, INF, 1.0)]
    for dtype in (F64, torch.float32):
        s = torch.tensor([c[0] for c in endless], dtype=dtype, device=device)
        w, t = impl.segment_integral(s, torch.full_like(s, INF), "exact")
        for i, (sg, ww, tt) in enumerate(endless):
            got = (w.cpu()[i].item(), t.cpu()[i].item())
            assert got == (ww, tt), (
                f"segment_integral(sigma={sg}, length=inf, {dtype}): expected weight {ww!r} "
                f"and transmittance {tt!r}, got {got[0]!r} and {got[1]!r}. An endless step "
                f"is the limit of D (1 - e^(-sigma D)) / sigma: 1/sigma (0 for sigma = inf), "
                f"and +inf in vacuum with transmittance 1; sigma * inf, inf * 0 and 0 * inf "
                f"are not answers"
            )
    w, t = impl.segment_integral(torch.tensor([0.0, 2.0], dtype=F64, device=device), INF, "riemann")
    assert w.cpu().tolist() == [INF, INF] and t.cpu().tolist() == [1.0, 0.0], (
        f"segment_integral(sigma=[0, 2], length=inf, 'riemann'): expected weights [inf, inf] "
        f"and transmittances [1, 0], got {w.cpu().tolist()} and {t.cpu().tolist()}"
    )
    # Numbers broadcast; the Riemann sum is the length; bad integrators are refused.
    w, t = impl.segment_integral(
        torch.tensor([0.5, 2.0], dtype=F64, device=device), 0.25, "riemann"
    )
    assert_close(
        w,
        torch.tensor([0.25, 0.25], dtype=F64),
        atol=0,
        name="segment_integral(..., 'riemann'): weight = length",
        where="element",
    )
    assert_close(
        t,
        torch.exp(-torch.tensor([0.125, 0.5], dtype=F64)),
        rtol=1e-15,
        name="segment_integral(..., 'riemann'): transmittance",
        where="element",
    )
    # float16 / bfloat16: no NaN, loosely right.
    for dtype, tol in ((torch.float16, 2e-3), (torch.bfloat16, 1.6e-2)):
        s = torch.tensor([0.0, 1e-4, 0.5, 3.0, 6e4, INF], dtype=dtype, device=device)
        w, t = impl.segment_integral(s, torch.ones_like(s), "exact")
        no_nan(f"segment_integral ({dtype})", weight=w, transmittance=t)
        assert_close(
            w,
            phi(s.cpu().double()),
            rtol=tol,
            atol=1e-4,
            name=f"segment_integral ({dtype}): weight",
            where="element",
        )
    expect_error(
        "integrator", impl.segment_integral, 1.0, 1.0, "trapezoid", case="integrator='trapezoid'"
    )
    expect_error(
        "sigma", impl.segment_integral, torch.ones(3, dtype=torch.int64), 1.0, case="int64 sigma"
    )
    for name, sigma, length in (("sigma", -0.5, 1.0), ("length", 0.5, -1.0)):
        expect_error(
            name,
            impl.segment_integral,
            torch.tensor([sigma, 1.0], dtype=F64, device=device),
            torch.tensor([length, 1.0], dtype=F64, device=device),
            case=f"a negative {name} (transmittance above 1)",
        )


def convergence(errors: dict) -> list:
    steps = sorted(errors)
    return [math.log2(errors[a] / errors[b]) for a, b in itertools.pairwise(steps)]


@pytest.mark.task(2)
@pytest.mark.points(1)
def test_segment_integral_convergence_order(impl, device):
    q = 0.7
    lo, hi = [0.0] * 3, [1.0] * 3
    o, d = x_face_rays(24, seed=61)
    near, far, _ = ref_interval(o, d, lo, hi)
    length = (far - near) * d.norm(dim=-1)
    homogeneous = q * length * phi(1.3 * length)
    ramp, ramp_t = ramp_reference(o, d, lo, hi, q)
    dens = torch.full((1, 1, 1), 1.3, dtype=F64, device=device)
    emis = torch.full((1, 1, 1), q, dtype=F64, device=device)
    report = []
    for integrator, order in (("riemann", 1.0), ("exact", 2.0)):
        errors = {"homogeneous": {}, "ramp": {}}
        for steps in (8, 16, 32, 64):
            got = march_given(
                impl,
                o.to(device),
                d.to(device),
                lo,
                hi,
                dens,
                emis,
                steps,
                integrator=integrator,
                what=f"march(integrator={integrator!r})",
                n=24,
                dtype=F64,
                device=device,
            )
            errors["homogeneous"][steps] = (got["radiance"].cpu() - homogeneous).abs().max().item()
            got = march_given(
                impl,
                o.to(device),
                d.to(device),
                lo,
                hi,
                ramp_density,
                emis,
                steps,
                integrator=integrator,
                what=f"march(integrator={integrator!r})",
                n=24,
                dtype=F64,
                device=device,
            )
            errors["ramp"][steps] = (got["radiance"].cpu() - ramp).abs().max().item()
            assert_close(
                got["transmittance"],
                ramp_t,
                rtol=1e-12,
                name=f"march({integrator!r}, steps={steps}): transmittance of the "
                f"linear ramp (the midpoint rule is exact for a linear density)",
                where="ray",
            )
        report.append(
            f"{integrator}: "
            + ", ".join(
                f"{case} errors {[f'{e:.2e}' for e in errs.values()]}"
                for case, errs in errors.items()
            )
        )
        if integrator == "exact":
            worst = max(errors["homogeneous"].values())
            assert worst < 1e-12, (
                f"segment_integral('exact') in the given march: a homogeneous box must come out "
                f"exact at every step count (error {worst:.2e}). The weight of a step is "
                f"(1 - e^(-sigma ds)) / sigma, not ds.\n" + "\n".join(report)
            )
        else:
            orders = convergence(errors["homogeneous"])
            assert all(0.85 < p < 1.25 for p in orders), (
                f"segment_integral('riemann'): the error on a homogeneous box should halve when "
                f"the steps double (first order); observed orders {orders}.\n" + "\n".join(report)
            )
        orders = convergence(errors["ramp"])
        assert all(order - 0.25 < p < order + 0.25 for p in orders), (
            f"segment_integral({integrator!r}) on a linear density ramp with constant emission: "
            f"expected convergence of order {order:g} (the error shrinks {2**order:g}x per "
            f"doubling of the steps), observed orders {[f'{p:.2f}' for p in orders]}.\n"
            + "\n".join(report)
        )
    ratio = errors["ramp"][64]
    assert ratio < 1e-4, f"segment_integral('exact'): ramp error {ratio:.2e} at 64 steps"


@pytest.mark.task(2)
@pytest.mark.points(1)
def test_segment_integral_conserves_energy(impl, device):
    """A medium whose emission is c sigma (equilibrium at 'temperature' c) can never shine
    brighter than c: L = c (1 - T). The exact integrator telescopes to exactly that for any
    density and any step count; the Riemann sum creates energy where steps are thick."""
    lo, hi = [0.0] * 3, [1.0] * 3
    o, d = box_rays(120, seed=71, lo=lo, hi=hi)
    _, _, hit = ref_interval(o, d, lo, hi)
    for dtype, tol in ((F64, 1e-12), (torch.float32, 2e-6)):
        for steps in (1, 4, 32):
            what = f"march(integrator='exact', steps={steps}, {dtype}) with q = 0.8 sigma"
            got = march_given(
                impl,
                o.to(device, dtype),
                d.to(device, dtype),
                lo,
                hi,
                blackbody_density,
                blackbody_emission,
                steps,
                what=what,
                n=120,
                dtype=dtype,
                device=device,
            )
            no_nan(what, radiance=got["radiance"], transmittance=got["transmittance"])
            assert_close(
                got["radiance"],
                0.8 * (1 - got["transmittance"].cpu().double()),
                rtol=tol,
                atol=tol,
                name=f"{what}: radiance must equal 0.8 (1 - T): each step adds "
                f"T q (1 - e^(-sigma ds)) / sigma = 0.8 (T_before - T_after)",
                where="ray",
            )
    got = march_given(
        impl,
        o.to(device),
        d.to(device),
        lo,
        hi,
        blackbody_density,
        blackbody_emission,
        4,
        integrator="riemann",
        what="march(integrator='riemann')",
        n=120,
        dtype=F64,
        device=device,
    )
    brightest = got["radiance"].cpu()[hit].max().item()
    assert brightest > 0.8 * 1.5, (
        f"march(integrator='riemann', steps=4) on a medium with q = 0.8 sigma (sigma up to "
        f"300): the Riemann sum T q ds should overshoot the physical bound 0.8 by far "
        f"(it ignores absorption within a step), got at most {brightest:.3g}. Is 'riemann' "
        f"really weight = ds?"
    )


# ---------------------------------------------------------------------------------------
# Task 3: single scattering


@pytest.mark.task(3)
@pytest.mark.points(1)
def test_henyey_greenstein(impl, device):
    theta = torch.linspace(0, math.pi, 400001, dtype=F64)
    cos, sin = torch.cos(theta), torch.sin(theta)
    for g in (-0.99, -0.9, -0.5, 0.0, 0.3, 0.9, 0.99):
        p = check_tensor(
            impl.henyey_greenstein(cos.to(device), g),
            f"henyey_greenstein(cos, {g})",
            shape=(len(cos),),
            dtype=F64,
            device=device,
        ).cpu()
        no_nan(f"henyey_greenstein(g={g})", p=p)
        total = 2 * math.pi * torch.trapezoid(p * sin, theta).item()
        assert abs(total - 1) < 1e-4, (
            f"henyey_greenstein(g={g}): the integral over the sphere, 2 pi int p(cos) sin dtheta, "
            f"is {total:.6f}, expected 1 (the phase function is a probability density: "
            f"(1 - g^2) / (4 pi (1 + g^2 - 2 g cos)^(3/2)))"
        )
        assert_close(
            p[::1000],
            ref_phase(cos[::1000], g),
            rtol=1e-12,
            name=f"henyey_greenstein(g={g})",
            where="angle",
        )
    # g > 0 scatters forward: brightest when looking toward the light (cos = +1).
    ends = impl.henyey_greenstein(torch.tensor([1.0, -1.0], dtype=F64, device=device), 0.6).cpu()
    assert ends[0] > 10 * ends[1], (
        f"henyey_greenstein(g=0.6): p(cos=+1) = {ends[0].item():.4g} should be far larger than "
        f"p(cos=-1) = {ends[1].item():.4g}: g > 0 scatters forward (check the sign of the "
        f"2 g cos term)"
    )
    # The isotropic limit, tensors of g, and symmetry p_g(cos) = p_{-g}(-cos).
    mu = torch.linspace(-1, 1, 101, dtype=F64, device=device)
    for g in (0.0, 1e-8, -1e-8):
        assert_close(
            impl.henyey_greenstein(mu, g),
            torch.full((101,), 1 / (4 * math.pi), dtype=F64),
            rtol=1e-7,
            name=f"henyey_greenstein(g={g}): isotropic 1 / (4 pi)",
            where="angle",
        )
    gs = torch.linspace(-0.95, 0.95, 101, dtype=F64, device=device)
    assert_close(
        impl.henyey_greenstein(mu, gs),
        impl.henyey_greenstein(-mu, -gs),
        rtol=1e-12,
        name="henyey_greenstein with a tensor g: p_g(cos) = p_(-g)(-cos)",
        where="element",
    )
    # float32 at the peak with |g| = 0.999: the denominator must not cancel.
    for g in (0.999, -0.999):
        g32 = torch.tensor(g, dtype=torch.float32).item()
        peak = torch.tensor(
            [1.0, 1 - 2**-20, 0.9999, -1.0, -1 + 2**-20, -0.9999], dtype=torch.float32
        )
        got = impl.henyey_greenstein(peak.to(device), g32)
        assert_close(
            got,
            ref_phase(peak.double(), g32),
            rtol=1e-4,
            name=f"henyey_greenstein (float32, g={g}) near cos = +-1, against float64 "
            f"from the same inputs: write 1 + g^2 - 2 g cos as "
            f"(1 - g)^2 + 2 g (1 - cos) (g >= 0) or (1 + g)^2 - 2 g (1 + cos) "
            f"(g < 0), sums without cancellation",
            where="angle",
        )
    for dtype in (torch.float16, torch.bfloat16):
        got = impl.henyey_greenstein(mu.to(dtype), 0.8)
        no_nan(f"henyey_greenstein ({dtype})", p=got)
        assert_close(
            got,
            ref_phase(mu.to(dtype).cpu().double(), 0.8),
            rtol=3e-2,
            name=f"henyey_greenstein ({dtype}, g=0.8)",
            where="angle",
        )
    for bad in (1.0, -1.0, 1.5):
        expect_error("g", impl.henyey_greenstein, mu, bad, kinds=(ValueError,), case=f"g={bad}")
    expect_error(
        "g",
        impl.henyey_greenstein,
        mu,
        torch.tensor([0.2, 1.0], dtype=F64, device=device),
        kinds=(ValueError,),
        case="a tensor g holding 1.0",
    )
    expect_error("cos_theta", impl.henyey_greenstein, [0.5, 0.2], 0.3, case="a list as cos_theta")
    # cos_theta past +-1 (rounding, or a caller's bug) is clamped: finite, the value at +-1.
    past = torch.tensor([2.0, 1.0 + 1e-6, -1.0 - 1e-6, -3.0], dtype=F64, device=device)
    for g in (0.5, -0.7, 0.0, 0.99):
        got = impl.henyey_greenstein(past, g)
        no_nan(f"henyey_greenstein(cos_theta past +-1, g={g})", p=got)
        assert_close(
            got,
            ref_phase(torch.tensor([1.0, 1.0, -1.0, -1.0], dtype=F64), g),
            rtol=1e-9,
            name=f"henyey_greenstein(cos_theta = 2, 1 + 1e-6, -1 - 1e-6, -3; "
            f"g={g}): clamp cos_theta to [-1, 1]",
            where="cos index",
        )


SCATTER_LO, SCATTER_HI = (0.0, 0.0, 0.0), (1.0, 2.0, 1.0)
BOXED_SIGMA = 0.7


def boxed_density(p):
    """sigma = 0.7 inside the scattering box (closed), 0 outside it."""
    lo = torch.tensor(SCATTER_LO, dtype=p.dtype, device=p.device)
    hi = torch.tensor(SCATTER_HI, dtype=p.dtype, device=p.device)
    inside = ((p >= lo) & (p <= hi)).all(-1)
    return torch.where(inside, BOXED_SIGMA, 0.0).to(p.dtype)


def scatter_rays(n, seed):
    """Camera-like rays at the scattering box from outside, a quarter from inside."""
    g = generator(seed)
    lo, hi = torch.tensor(SCATTER_LO, dtype=F64), torch.tensor(SCATTER_HI, dtype=F64)
    target = lo + (hi - lo) * (0.05 + 0.9 * torch.rand(n, 3, generator=g, dtype=F64))
    o = torch.tensor([0.5, 1.0, -2.5], dtype=F64) + torch.randn(n, 3, generator=g, dtype=F64)
    inside = torch.arange(n) % 4 == 0
    o = torch.where(inside[:, None], lo + (hi - lo) * torch.rand(n, 3, generator=g, dtype=F64), o)
    d = torch.where(inside[:, None], torch.randn(n, 3, generator=g, dtype=F64), target - o)
    return o, d


@pytest.mark.task(3)
@pytest.mark.points(0.5)
def test_shadow_transmittance(impl, device):
    sigma = 0.8
    light = torch.tensor([0.3, 1.0, 0.2], dtype=F64)
    g = generator(81)
    lo, hi = torch.tensor(SCATTER_LO, dtype=F64), torch.tensor(SCATTER_HI, dtype=F64)
    points = torch.cat(
        [
            lo + (hi - lo) * torch.rand(60, 3, generator=g, dtype=F64),
            torch.tensor(
                [
                    [0.5, -1.0, 0.5],
                    [0.5, 3.0, 0.5],
                    [-5.0, 0.5, 0.5],
                    [math.nan, 0.5, 0.5],
                    [0.5, INF, 0.5],
                ],
                dtype=F64,
            ),
        ]
    )
    dist, _ = light_exit(points, unit(light), lo, hi)  # 0 where the light ray misses
    dens = torch.full((1, 1, 1), sigma, dtype=F64, device=device)
    for steps in (1, 5):
        got = check_tensor(
            impl.shadow_transmittance(
                points.to(device),
                (2.5 * light).to(device),
                lo.to(device),
                hi.to(device),
                dens,
                steps,
            ),
            f"shadow_transmittance(steps={steps})",
            shape=(65,),
            dtype=F64,
            device=device,
        )
        no_nan("shadow_transmittance", transmittance=got)
        assert_close(
            got,
            torch.exp(-sigma * dist),
            rtol=1e-12,
            atol=1e-15,
            name=f"shadow_transmittance (homogeneous, steps={steps}): exp(-sigma L) with "
            f"L the distance from the point to where its ray toward the light "
            f"leaves the box (1 for rays that miss it, and for NaN/inf points)",
            where="point",
        )
    got = impl.shadow_transmittance(
        points.to(device), light.to(device), lo.to(device), hi.to(device), dens, 0
    )
    assert_equal(
        got,
        torch.ones(65, dtype=F64),
        name="shadow_transmittance(steps=0): no shadow march, transmittance 1",
        where="point",
    )
    # A quadratic density: the midpoint rule converges with order 2 to the exact depth.
    inner = points[:60]
    l = unit(light)
    length, _ = light_exit(inner, l, lo, hi)
    c = torch.tensor(BOWL_CENTER, dtype=F64)
    alpha = bowl_density(inner)
    beta = 6.0 * ((inner - c) * l).sum(-1)
    exact = alpha * length + beta * length**2 / 2 + length**3
    errors = {}
    for steps in (2, 4, 8, 16):
        got = impl.shadow_transmittance(
            inner.to(device), light.to(device), lo.to(device), hi.to(device), bowl_density, steps
        )
        errors[steps] = (-torch.log(got.cpu()) - exact).abs().max().item()
    orders = convergence(errors)
    assert all(1.8 < p < 2.2 for p in orders), (
        f"shadow_transmittance with a quadratic density: the optical depth should converge with "
        f"order 2 (midpoint samples at (k + 1/2) dt); errors {errors}, orders {orders}"
    )
    expect_error(
        "light_direction",
        impl.shadow_transmittance,
        inner.to(device),
        torch.zeros(3, dtype=F64, device=device),
        lo.to(device),
        hi.to(device),
        dens,
        4,
        case="a zero light direction",
    )
    expect_error(
        "points",
        impl.shadow_transmittance,
        inner[:, :2].to(device),
        light.to(device),
        lo.to(device),
        hi.to(device),
        dens,
        4,
        case="points of shape (N, 2)",
    )
    expect_error(
        "density",
        impl.shadow_transmittance,
        inner.to(device),
        light.to(device),
        lo.to(device),
        hi.to(device),
        torch.full((2, 2, 2), math.nan, dtype=F64, device=device),
        4,
        kinds=(ValueError,),
        case="a density grid of NaN (a NaN transmittance)",
    )


# march_single_scatter integrates its in-scattered source with march_box (task 1), which
# calls segment_integral (task 2): here the march is the given one below, so task 3 is graded
# on its own (its phase function, shadow march and source), whatever the lab's march_box.


def given_step(sigma, length):
    """The exact per-step integral (task 2), given: ``(phi(sigma ds) ds, e^(-sigma ds))``."""
    tau = sigma * length
    small = tau < 1e-6
    weight = torch.where(
        small, length * (1 - tau / 2), -torch.expm1(-tau) / torch.where(small, 1.0, sigma)
    )
    return weight, torch.exp(-tau)


def given_march_box(
    origins,
    directions,
    box_min,
    box_max,
    density,
    emission=None,
    steps=64,
    *,
    integrator="exact",
    min_transmittance=0.0,
    jitter=False,
    seed=0,
):
    """In place of the lab's ``march_box`` under ``march_single_scatter``: the grader's
    midpoint march with the exact step (``emission`` a callable of world points, one per
    ray, as the source is)."""
    assert integrator == "exact" and not jitter, "the given march is the midpoint, exact one"
    like = {"dtype": origins.dtype, "device": origins.device}
    lo, hi = (torch.as_tensor(b).to(**like) for b in (box_min, box_max))
    near, far, hit = (x.to(origins.device) for x in ref_interval(origins, directions, lo, hi))
    near, far = (torch.where(hit, x, 0).to(origins.dtype) for x in (near, far))
    dt = (far - near) / max(steps, 1)
    ds = torch.where(hit, dt * directions.norm(dim=-1), 0)
    radiance, transmittance = 0, torch.ones(len(origins), **like)
    samples = torch.zeros(len(origins), dtype=torch.int64, device=origins.device)
    for i in range(steps):
        active = hit & (transmittance >= min_transmittance)
        offset = (origins - lo) + (near + (i + 0.5) * dt)[:, None] * directions
        # box coordinates; a flat axis (lo = hi) is read at its middle, as documented
        local = torch.where(hi > lo, offset / torch.where(hi > lo, hi - lo, 1), 0.5)
        points = lo + offset
        sigma = torch.where(active, given_field(density, points, local), 0)
        weight, t_step = given_step(sigma, torch.where(active, ds, 0))
        q = given_field(emission, points, local)
        mask, seen = (
            (active, transmittance) if q.ndim == 1 else (active[:, None], transmittance[:, None])
        )
        radiance = radiance + seen * (weight if q.ndim == 1 else weight[:, None]) * torch.where(
            mask, q, 0
        )
        transmittance = transmittance * t_step
        samples += active
    return {"radiance": radiance, "transmittance": transmittance, "samples": samples}


def given_sample_grid(grid, uvw):
    """In place of the lab's ``sample_grid`` (task 1) under ``march_single_scatter``:
    trilinear at box coordinates, clamped to the border, 0 at NaN/inf coordinates."""
    flat = uvw.reshape(-1, 3)
    finite = torch.isfinite(flat).all(-1)
    values = given_field(grid, flat, torch.nan_to_num(flat, nan=0.5, posinf=2.0, neginf=-1.0))
    values = torch.where(finite[:, None] if values.ndim == 2 else finite, values, 0)
    return values.reshape(*uvw.shape[:-1], *grid.shape[3:])


def probe_single_scatter(lab, *args, **kwargs):
    """``march_single_scatter`` next to the lab, on the given march and grid sampling."""
    with replaced(lab, {"march_box": given_march_box, "sample_grid": given_sample_grid}):
        return lab.march_single_scatter(*args, **kwargs)


def scatter_grid():
    """A (4, 5, 3) density grid for the scattering box, 0.2 .. 1.7, varying on every axis."""
    return 0.2 + 1.5 * torch.rand(4, 5, 3, generator=generator(141), dtype=F64)


SHIFTED_LO, SHIFTED_HI = (2.0, -3.0, 0.5), (3.0, -1.0, 1.5)  # the scattering box, moved


def scatter_grid_density(p):
    """The medium of ``scatter_grid()`` as a callable: its trilinear field at world points
    of the scattering box moved to ``SHIFTED_LO`` .. ``SHIFTED_HI``."""
    lo, hi = (torch.tensor(b, dtype=F64, device=p.device) for b in (SHIFTED_LO, SHIFTED_HI))
    q = p.double()
    return given_field(scatter_grid().to(p.device), q, (q - lo) / (hi - lo)).to(p.dtype)


FLAT_LO, FLAT_HI = (0.0, 0.0, 0.5), (1.0, 2.0, 0.5)  # the scattering box, flattened to z = 0.5


def flat_grid():
    """``scatter_grid()``'s first two layers: (4, 5, 2), varying along z."""
    return scatter_grid()[:, :, :2].clone()


def flat_grid_density(p):
    """The medium of ``flat_grid()`` in the flat box as a callable: read at the flat axis's
    middle (box coordinate 0.5), as the docstrings say a grid is."""
    lo, hi = (torch.tensor(b, dtype=F64, device=p.device) for b in (FLAT_LO, FLAT_HI))
    q = p.double()
    local = (q - lo) / torch.where(hi > lo, hi - lo, 1.0)
    local[:, 2] = 0.5
    return given_field(flat_grid().to(p.device), q, local).to(p.dtype)


def single_scatter(impl, *args, **kwargs):
    """The lab's ``march_single_scatter`` (tasks 1 and 2 given)."""
    return impl.probe(probe_single_scatter, *args, **kwargs)


@pytest.mark.task(3)
@pytest.mark.points(0.5)
def test_shadow_transmittance_only_inside_box(impl, device):
    # Only the part of the light ray inside the box counts: a callable density that is not
    # zero outside the box must not be sampled there (points outside the box, light through).
    sigma = BOXED_SIGMA
    lo, hi = torch.tensor(SCATTER_LO, dtype=F64), torch.tensor(SCATTER_HI, dtype=F64)
    light = torch.tensor([0.05, 1.0, -0.03], dtype=F64)
    g = generator(83)
    start = torch.rand(16, 3, generator=g, dtype=F64) * 0.6 + 0.2
    points = torch.stack([start[:, 0], -1.0 - start[:, 1], start[:, 2]], -1)
    near, far, hit = ref_interval(points, unit(light).expand_as(points), lo, hi)
    assert bool(hit.all()), "test set-up: the light rays cross the box"
    want = torch.exp(-sigma * (far - near))
    got = impl.shadow_transmittance(
        points.to(device), light.to(device), lo.to(device), hi.to(device), boxed_density, steps=4
    )
    got = check_tensor(got, "shadow_transmittance", shape=(16,), dtype=F64, device=device)
    assert_close(
        got.cpu(),
        want,
        rtol=1e-6,
        atol=1e-9,
        name="shadow_transmittance (points below the box, homogeneous box, density 0 "
        "outside it): exp(-sigma * chord); march from t_near to t_far, not from the point",
        where="point",
    )


@pytest.mark.task(3)
@pytest.mark.points(0.5)
def test_shadow_transmittance_grid_in_offset_box(impl, device):
    # A grid density in a box away from the origin: sampled at box coordinates
    # (p - box_min) / size; compared with a float64 midpoint march using grid_sample.
    lo = torch.tensor([1.0, -2.0, 0.5], dtype=F64)
    hi = torch.tensor([3.0, -1.0, 1.5], dtype=F64)
    g = generator(85)
    grid = torch.rand(4, 3, 5, generator=g, dtype=F64) * 2.0
    points = lo + (hi - lo) * torch.rand(24, 3, generator=g, dtype=F64)
    light = torch.tensor([0.3, 1.0, 0.2], dtype=F64)
    steps = 4
    near, far, hit = ref_interval(points, unit(light).expand_as(points), lo, hi)
    dt = (far - near) / steps
    depth = torch.zeros(24, dtype=F64)
    for k in range(steps):
        p = points + (near + (k + 0.5) * dt)[:, None] * unit(light)
        depth = depth + given_field(grid, p, (p - lo) / (hi - lo)) * dt
    want = torch.exp(-torch.where(hit, depth, 0.0))
    got = impl.shadow_transmittance(
        points.to(device), light.to(device), lo.to(device), hi.to(device), grid.to(device), steps
    )
    got = check_tensor(got, "shadow_transmittance", shape=(24,), dtype=F64, device=device)
    assert_close(
        got.cpu(),
        want,
        rtol=1e-6,
        atol=1e-9,
        name="shadow_transmittance (random grid density in the box (1, -2, 0.5)..(3, -1, 1.5), "
        "4 midpoint steps): grids are sampled at (p - box_min) / (box_max - box_min)",
        where="point",
    )
    default = impl.shadow_transmittance(
        points.to(device), light.to(device), lo.to(device), hi.to(device), grid.to(device)
    )
    explicit = impl.shadow_transmittance(
        points.to(device), light.to(device), lo.to(device), hi.to(device), grid.to(device), 16
    )
    assert_close(
        check_tensor(default, "shadow_transmittance", shape=(24,), dtype=F64, device=device).cpu(),
        explicit.cpu(),
        rtol=1e-12,
        atol=0.0,
        name="shadow_transmittance: the default is steps=16",
        where="point",
    )
    # A flat box (z = 0.5), points and light in its plane: a grid varying along z is read at
    # the flat axis's middle (0.5), like the same medium as a callable (do not divide by 0).
    flat = torch.tensor(FLAT_LO, dtype=F64) + torch.tensor([1.0, 2.0, 0.0], dtype=F64) * torch.rand(
        24, 3, generator=g, dtype=F64
    )
    flat_light = torch.tensor([0.3, 1.0, 0.0], dtype=F64)
    got, twin = (
        check_tensor(
            impl.shadow_transmittance(
                flat.to(device), flat_light.to(device), FLAT_LO, FLAT_HI, field, 4
            ),
            "shadow_transmittance (flat box)",
            shape=(24,),
            dtype=F64,
            device=device,
        ).cpu()
        for field in (flat_grid().to(device), flat_grid_density)
    )
    assert (twin < 1).all() and twin.min() < 0.5, "test set-up: the flat medium shadows"
    assert_close(
        got,
        twin,
        rtol=1e-9,
        atol=1e-12,
        name="shadow_transmittance (a flat box z = 0.5, points and light in its plane, a grid "
        "varying along z): against the same medium as a callable read at the flat axis's "
        "middle (box coordinate 0.5)",
        where="point",
    )


@pytest.mark.task(3)
@pytest.mark.points(1)
def test_single_scatter_matches_closed_form(impl, device):
    """A homogeneous box lit straight from above (light toward +y): the light's path from any
    point inside leaves through the top face, so along a view ray entering at height y_e with
    unit direction u, L = a sigma p(u_y) E e^{-sigma (y_max - y_e)} D phi(sigma (1 - u_y) D)."""
    sigma, albedo, irradiance, g = 1.3, 0.8, 2.0, 0.4
    o, d = scatter_rays(48, seed=91)
    near, far, _ = ref_interval(o, d, SCATTER_LO, SCATTER_HI)
    u = unit(d)
    length = (far - near) * d.norm(dim=-1)
    entry = o + near[:, None] * d
    want = (
        albedo
        * sigma
        * ref_phase(u[:, 1], g)
        * irradiance
        * torch.exp(-sigma * (SCATTER_HI[1] - entry[:, 1]))
        * length
        * phi(sigma * (1 - u[:, 1]) * length)
    )
    dens = torch.full((1, 1, 1), sigma, dtype=F64, device=device)
    light = torch.tensor([0.0, 1.0, 0.0], dtype=F64, device=device)
    errors = {}
    for steps in (16, 32, 64):
        what = f"march_single_scatter(steps={steps}, shadow_steps=1)"
        result = single_scatter(
            impl,
            o.to(device),
            d.to(device),
            SCATTER_LO,
            SCATTER_HI,
            dens,
            albedo,
            light,
            irradiance,
            g,
            steps,
            1,
        )
        got = result_dict(result, what, MARCH_KEYS, 48, F64, device)
        no_nan(what, radiance=got["radiance"], transmittance=got["transmittance"])
        assert_close(
            got["transmittance"],
            torch.exp(-sigma * length),
            rtol=1e-12,
            name=f"{what}: transmittance of the view ray",
            where="ray",
        )
        errors[steps] = ((got["radiance"].cpu() - want).abs() / want.clamp(min=1e-3)).max().item()
    assert errors[64] < 2e-3, (
        f"march_single_scatter on a homogeneous box lit along +y: relative error {errors[64]:.3g} "
        f"at 64 steps against the closed form (errors {errors}). The source is albedo sigma "
        f"p(d . l) E T_light, T_light from a shadow march toward the light, integrated with "
        f"the exact per-step weight."
    )
    orders = convergence(errors)
    assert all(p > 1.7 for p in orders), (
        f"march_single_scatter (exact integrator): error should fall ~4x per doubling of the "
        f"steps; errors {errors}, orders {orders}"
    )
    # Coloured albedo and irradiance, more shadow steps (exact already), g < 0.
    rgb = torch.tensor([0.9, 0.5, 0.2], dtype=F64, device=device)
    result = single_scatter(
        impl,
        o.to(device),
        d.to(device),
        SCATTER_LO,
        SCATTER_HI,
        dens,
        rgb,
        light,
        2.0 * rgb,
        -0.3,
        64,
        4,
    )
    got = result_dict(
        result,
        "march_single_scatter(albedo (3,), light_irradiance (3,))",
        MARCH_KEYS,
        48,
        F64,
        device,
        channels=3,
    )
    scale = (ref_phase(u[:, 1], -0.3) / ref_phase(u[:, 1], g) / irradiance)[:, None] * (
        rgb.cpu() * 2.0 * rgb.cpu() / albedo
    )
    assert_close(
        got["radiance"],
        want[:, None] * scale,
        rtol=3e-3,
        atol=1e-6,
        name="march_single_scatter with albedo (3,) and light_irradiance (3,), g=-0.3: "
        "radiance (N, 3)",
        where="(ray, channel)",
    )
    cpu_agrees(
        device,
        "march_single_scatter",
        got,
        partial(single_scatter, impl),
        o.to(device),
        d.to(device),
        SCATTER_LO,
        SCATTER_HI,
        dens,
        rgb,
        light,
        2.0 * rgb,
        -0.3,
        64,
        4,
    )
    # A dense box (T falls to e^-19) with the default min_transmittance=0: no ray stops early.
    dense = torch.full((1, 1, 1), 8.0, dtype=F64, device=device)
    what = "march_single_scatter(sigma=8, steps=16, the default min_transmittance=0)"
    got = result_dict(
        single_scatter(
            impl,
            o.to(device),
            d.to(device),
            SCATTER_LO,
            SCATTER_HI,
            dense,
            albedo,
            light,
            irradiance,
            g,
            16,
            1,
        ),
        what,
        MARCH_KEYS,
        48,
        F64,
        device,
    )
    _, _, hit = ref_interval(o, d, SCATTER_LO, SCATTER_HI)
    assert_equal(
        got["samples"],
        torch.where(hit, 16, 0).long(),
        where="ray",
        name=f"{what}: samples (min_transmittance=0 never stops a march: every ray "
        f"that meets the box takes every step)",
    )
    assert_close(
        got["transmittance"],
        torch.exp(-8.0 * length),
        rtol=1e-10,
        atol=0,
        name=f"{what}: transmittance of the view ray e^(-sigma D)",
        where="ray",
    )
    # Directions of any length: 1e-170 (|d|^2 underflows, so d / |d| is inf and NaN), and
    # NaN/inf/zero directions. The phase p(d . l) of such rays must not turn into NaN.
    bo, bd = bad_rays()
    short_o, short_d = torch.cat([o[:8], bo]), torch.cat([d[:8] * 1e-170, bd])
    what = (
        "march_single_scatter (directions of length 1e-170, whose |d| underflows to 0, "
        "and NaN/inf/zero directions)"
    )
    got = result_dict(
        single_scatter(
            impl,
            short_o.to(device),
            short_d.to(device),
            SCATTER_LO,
            SCATTER_HI,
            dens,
            albedo,
            light,
            irradiance,
            g,
            8,
            1,
        ),
        what,
        MARCH_KEYS,
        len(short_o),
        F64,
        device,
    )
    no_nan(what, radiance=got["radiance"], transmittance=got["transmittance"])
    # A grid is sampled at box coordinates (x - box_min) / (box_max - box_min) (the box is
    # 1 x 2 x 1, away from the origin): the same medium as a grid and as a callable of world
    # points scatters alike.
    what = (
        "march_single_scatter (a (4, 5, 3) grid density in the box (2, -3, 0.5)..(3, -1, 1.5), "
        "steps=32, shadow_steps=4)"
    )
    shift = torch.tensor(SHIFTED_LO, dtype=F64) - torch.tensor(SCATTER_LO, dtype=F64)
    got, twin = (
        result_dict(
            single_scatter(
                impl,
                (o + shift).to(device),
                d.to(device),
                SHIFTED_LO,
                SHIFTED_HI,
                field,
                albedo,
                light,
                irradiance,
                g,
                32,
                4,
            ),
            what,
            MARCH_KEYS,
            48,
            F64,
            device,
        )
        for field in (scatter_grid().to(device), scatter_grid_density)
    )
    assert_close(
        got["radiance"],
        twin["radiance"],
        rtol=1e-9,
        atol=1e-12,
        where="ray",
        name=f"{what}: radiance against the same trilinear medium given as a callable "
        f"of world points (the source's sigma: the grid sampled at box "
        f"coordinates (x - box_min) / (box_max - box_min))",
    )
    expect_error(
        "g",
        impl.march_single_scatter,
        o.to(device),
        d.to(device),
        SCATTER_LO,
        SCATTER_HI,
        dens,
        albedo,
        light,
        1.0,
        1.0,
        8,
        1,
        case="g=1.0",
    )
    expect_error(
        "shadow_steps",
        impl.march_single_scatter,
        o.to(device),
        d.to(device),
        SCATTER_LO,
        SCATTER_HI,
        dens,
        albedo,
        light,
        1.0,
        0.3,
        8,
        -1,
        case="shadow_steps=-1",
    )
    expect_error(
        "albedo",
        impl.march_single_scatter,
        o.to(device),
        d.to(device),
        SCATTER_LO,
        SCATTER_HI,
        dens,
        -0.5,
        light,
        1.0,
        0.3,
        8,
        1,
        case="albedo=-0.5",
    )
    # sigma_s / sigma_t above 1 scatters more light than the medium removes.
    for bad in (1.5, torch.tensor([0.5, 1.2, 0.5], dtype=F64, device=device)):
        expect_error(
            "albedo",
            impl.march_single_scatter,
            o.to(device),
            d.to(device),
            SCATTER_LO,
            SCATTER_HI,
            dens,
            bad,
            light,
            1.0,
            0.3,
            8,
            1,
            kinds=(ValueError,),
            case=f"albedo={bad} (an albedo is in [0, 1])",
        )
    expect_error(
        "albedo",
        impl.march_single_scatter,
        o.to(device),
        d.to(device),
        SCATTER_LO,
        SCATTER_HI,
        dens,
        1.0 + 1e-12,
        light,
        kinds=(ValueError,),
        case="albedo=1 + 1e-12 (check the number as given, not rounded to float32)",
    )
    # The ends of [0, 1] are albedos: 0 (absorbing only) and 1 (conservative scattering).
    for edge in (0.0, 1.0):
        what = f"march_single_scatter (albedo={edge:g})"
        got = result_dict(
            single_scatter(
                impl,
                o.to(device),
                d.to(device),
                SCATTER_LO,
                SCATTER_HI,
                dens,
                edge,
                light,
                irradiance,
                g,
                8,
                1,
            ),
            what,
            MARCH_KEYS,
            48,
            F64,
            device,
        )
        scaled = single_scatter(
            impl,
            o.to(device),
            d.to(device),
            SCATTER_LO,
            SCATTER_HI,
            dens,
            0.5,
            light,
            irradiance,
            g,
            8,
            1,
        )
        assert_close(
            got["radiance"],
            2 * edge * scaled["radiance"],
            rtol=1e-12,
            atol=1e-300,
            name=f"{what}: radiance (albedo {edge:g} is allowed; the light is albedo times that "
            f"of albedo 1)",
            where="ray",
        )
    # A flat box (z = 0.5) with the rays and the light in its plane: the grid (varying along
    # z) is read at the flat axis's middle (0.5), like the same medium given as a callable.
    fo, fd = o.clone(), d.clone()
    fo[:, 2], fd[:, 2] = 0.5, 0.0
    flat_light = torch.tensor([0.3, 1.0, 0.0], dtype=F64)
    what = "march_single_scatter (a flat box z = 0.5, rays and light in its plane)"
    got, twin = (
        result_dict(
            single_scatter(
                impl,
                fo.to(device),
                fd.to(device),
                FLAT_LO,
                FLAT_HI,
                field,
                albedo,
                flat_light.to(device),
                irradiance,
                g,
                16,
                4,
            ),
            what,
            MARCH_KEYS,
            48,
            F64,
            device,
        )
        for field in (flat_grid().to(device), flat_grid_density)
    )
    assert twin["radiance"].abs().max() > 0.01, "test set-up: light scattered in the flat box"
    for key in ("radiance", "transmittance"):
        assert_close(
            got[key],
            twin[key],
            rtol=1e-9,
            atol=1e-12,
            where="ray",
            name=f"{what}: {key} of a grid varying along z against the same medium as a "
            f"callable read at the flat axis's middle (0.5; never 0 / 0 = NaN)",
        )
    # The defaults: light_irradiance=1, g=0, steps=64, shadow_steps=16.
    plain, spelled = (
        result_dict(
            single_scatter(
                impl,
                o.to(device),
                d.to(device),
                SCATTER_LO,
                SCATTER_HI,
                bowl_density,
                albedo,
                light,
                *extra,
            ),
            "march_single_scatter (defaults)",
            MARCH_KEYS,
            48,
            F64,
            device,
        )
        for extra in ((), (1.0, 0.0, 64, 16))
    )
    for key in MARCH_KEYS:
        assert_equal(
            plain[key],
            spelled[key],
            name=f"march_single_scatter: {key} with the default arguments vs "
            f"light_irradiance=1, g=0, steps=64, shadow_steps=16 spelled out",
            where="ray",
        )


@pytest.mark.task(3)
@pytest.mark.points(0.5)
def test_single_scatter_oblique_light_against_quadrature(impl, device):
    """An oblique light (the exit face changes along the ray) and a quadratic density: the
    reference integrates 2001 points per ray with the light's optical depth exact."""
    light = torch.tensor([0.4, 1.0, -0.5], dtype=F64)
    lu = unit(light)
    lo, hi = torch.tensor(SCATTER_LO, dtype=F64), torch.tensor(SCATTER_HI, dtype=F64)
    o, d = scatter_rays(24, seed=101)
    albedo, irradiance, g = 0.9, 1.5, 0.6

    def homogeneous_shadow(p):
        length, _ = light_exit(p, lu, lo, hi)
        return 0.9 * length

    def bowl_shadow(p):
        length, _ = light_exit(p, lu, lo, hi)
        beta = 6.0 * ((p - torch.tensor(BOWL_CENTER, dtype=F64)) * lu).sum(-1)
        return bowl_density(p) * length + beta * length**2 / 2 + length**3

    cases = (
        (
            "homogeneous sigma = 0.9",
            torch.full((1, 1, 1), 0.9, dtype=F64),
            lambda p: torch.full(p.shape[:1], 0.9, dtype=F64),
            homogeneous_shadow,
            1,
        ),
        ("quadratic density", bowl_density, bowl_density, bowl_shadow, 12),
    )
    for name, density, sigma_fn, shadow_fn, shadow_steps in cases:
        want = scatter_reference(o, d, lo, hi, sigma_fn, shadow_fn, light, albedo, irradiance, g)
        field = density.to(device) if isinstance(density, torch.Tensor) else density
        what = (
            f"march_single_scatter ({name}, oblique light, steps=128, shadow_steps={shadow_steps})"
        )
        result = single_scatter(
            impl,
            o.to(device),
            d.to(device),
            lo.to(device),
            hi.to(device),
            field,
            albedo,
            light.to(device),
            irradiance,
            g,
            128,
            shadow_steps,
        )
        got = result_dict(result, what, MARCH_KEYS, 24, F64, device)
        assert_close(
            got["radiance"],
            want,
            rtol=2e-3,
            atol=1e-5,
            name=f"{what}: radiance against a fine quadrature",
            where="ray",
        )
    # Without enough shadow steps the quadratic case is visibly off; with more it converges.
    errs = []
    for shadow_steps in (1, 4):
        result = single_scatter(
            impl,
            o.to(device),
            d.to(device),
            lo.to(device),
            hi.to(device),
            bowl_density,
            albedo,
            light.to(device),
            irradiance,
            g,
            128,
            shadow_steps,
        )
        errs.append((result["radiance"].cpu() - want).abs().max().item())
    assert errs[1] < errs[0] / 4, (
        f"march_single_scatter: shadow_steps 1 -> 4 should cut the error of the quadratic "
        f"density case by far more than 4x (midpoint rule, order 2); errors {errs}"
    )


# ---------------------------------------------------------------------------------------
# Task 4: exact voxel walk and empty-space skipping


# Voxels of (1/8, 1/4, 1/8): every voxel plane is exact in every dtype, also shifted by 1e5,
# so a ray lying in a plane has one right answer (the voxel on the plane's positive side).
WALK_LO, WALK_HI = (-0.25, 0.125, 0.0), (0.5, 1.375, 0.875)


def sparse_grid(shape, seed, fill=0.4):
    g = generator(seed)
    grid = torch.rand(*shape, generator=g, dtype=F64) * 2
    return torch.where(
        torch.rand(*shape, generator=g, dtype=F64) < fill, grid, torch.zeros_like(grid)
    )


def walk_rays(n, seed, lo, hi, dtype=F64):
    """box_rays plus rays starting exactly on internal voxel planes, running along them."""
    o, d = box_rays(n, seed, lo, hi, dtype=F64)
    lo64, hi64 = f64(lo, hi)
    voxel = (hi64 - lo64) / torch.tensor([6.0, 5.0, 7.0])
    o[::11, 0] = lo64[0] + 2 * voxel[0]
    d[::11, 0] = 0.0
    o[3::11, 2] = lo64[2] + 4 * voxel[2]
    d[3::11, 2] = -0.0
    return o.to(dtype), d.to(dtype)


def walk(impl, *args, what, n, dtype, device, channels=None, **kwargs):
    return result_dict(
        impl.voxel_walk(*args, **kwargs), what, WALK_KEYS, n, dtype, device, channels
    )


@pytest.mark.task(4)
@pytest.mark.points(1)
def test_voxel_walk_optical_depth_exact(impl, device):
    grid = sparse_grid((6, 5, 7), seed=111)
    o, d = walk_rays(300, seed=112, lo=WALK_LO, hi=WALK_HI)
    bo, bd = bad_rays()
    o, d = torch.cat([o, bo]), torch.cat([d, bd])
    n = len(o)
    for dtype, eps in ((F64, 2.2e-16), (torch.float32, 1.2e-7)):
        oo, dd, gg = o.to(dtype), d.to(dtype), grid.to(dtype)
        lo, hi = torch.tensor(WALK_LO, dtype=dtype), torch.tensor(WALK_HI, dtype=dtype)
        want, _ = ref_optical_depth(oo, dd, lo, hi, gg)
        what = f"voxel_walk ({dtype})"
        got = walk(
            impl,
            oo.to(device),
            dd.to(device),
            lo.to(device),
            hi.to(device),
            gg.to(device),
            what=what,
            n=n,
            dtype=dtype,
            device=device,
        )
        no_nan(what, **{k: v for k, v in got.items()})
        scale = 2.0 * (dd.double().norm(dim=-1) * 3).nan_to_num(0) + 1  # sigma_max * chord + 1
        assert_close(
            got["optical_depth"].cpu().double() / scale,
            want / scale,
            atol=64 * eps,
            name=f"{what}: optical depth against the exact sum over the voxels crossed "
            f"(relative to sigma_max * chord). Compute each boundary's t from the "
            f"integer voxel index, (index * voxel - (o - box_min)) / d; step the "
            f"axis whose boundary is nearest; +0.0/-0.0 components never step",
            where="ray",
        )
        assert_close(
            got["transmittance"],
            torch.exp(-got["optical_depth"].cpu().double()),
            rtol=8 * eps,
            name=f"{what}: transmittance = exp(-optical depth)",
            where="ray",
        )
        _, _, hit = ref_interval(oo, dd, lo, hi)
        steps = got["steps"].cpu()
        assert (
            (steps[~hit] == 0).all()
            and (steps <= 6 + 5 + 7 + 1).all()
            and (steps[hit & (want > 0)] >= 1).all()
        ), (
            f"{what}: steps per ray must be 0 for misses, at least 1 through the medium and at "
            f"most X + Y + Z + 1 = 19; got {steps.tolist()}"
        )
        count, clear = ref_voxel_steps(oo, dd, lo, hi, (6, 5, 7), 1e-9 if dtype == F64 else 1e-4)
        assert clear.double().mean() > 0.8, "test set-up: most rays cross no corner"
        assert_equal(
            steps[clear],
            count[clear],
            where="ray (of those crossing no edge)",
            name=f"{what}: steps = the voxels the chord crosses (1 + the voxel planes "
            f"it crosses inside the box). A ray leaves the grid when its index "
            f"leaves 0 .. size - 1 or t reaches t_far, whichever comes first "
            f"(rounding may put the last plane a hair before t_far)",
        )
        assert_equal(
            got["samples"],
            steps,
            where="ray",
            name=f"{what}: samples (voxels whose density was read) without occupancy = steps: "
            f"every voxel stepped through is read, and a ray that has left reads nothing more",
        )
    cpu_agrees(
        device,
        "voxel_walk",
        got,
        impl.voxel_walk,
        oo.to(device),
        dd.to(device),
        lo.to(device),
        hi.to(device),
        gg.to(device),
        rtol=1e-5,
        atol=1e-6,
    )
    # A box at 1e5 in float32 keeps the accuracy it has near the origin.
    shift = 1e5
    oo = (torch.round(o[:300] * 64) / 64 + shift).float()
    dd = d[:300].float()
    lo, hi = (
        (torch.tensor(WALK_LO, dtype=F64) + shift).float(),
        (torch.tensor(WALK_HI, dtype=F64) + shift).float(),
    )
    want, _ = ref_optical_depth(oo, dd, lo, hi, grid.float())
    got = walk(
        impl,
        oo.to(device),
        dd.to(device),
        lo.to(device),
        hi.to(device),
        grid.float().to(device),
        what="voxel_walk (box at 1e5)",
        n=300,
        dtype=torch.float32,
        device=device,
    )
    scale = 2.0 * dd.double().norm(dim=-1) * 3 + 1
    assert_close(
        got["optical_depth"].cpu().double() / scale,
        want / scale,
        atol=64 * 1.2e-7,
        name="voxel_walk (float32 box at 1e5): optical depth. Work relative to the box "
        "(o - box_min), never with absolute coordinates: at 1e5 they round to "
        "1/128",
        where="ray",
    )


@pytest.mark.task(4)
@pytest.mark.points(1)
def test_voxel_walk_emission_and_extremes(impl, device):
    grid = sparse_grid((6, 5, 7), seed=121)
    color = sparse_grid((6, 5, 7, 3), seed=122, fill=0.6)
    o, d = walk_rays(200, seed=123, lo=WALK_LO, hi=WALK_HI)
    lo, hi = torch.tensor(WALK_LO, dtype=F64), torch.tensor(WALK_HI, dtype=F64)
    _, want_l = ref_optical_depth(o, d, lo, hi, grid, color)
    what = "voxel_walk (emission (6, 5, 7, 3))"
    got = walk(
        impl,
        o.to(device),
        d.to(device),
        lo.to(device),
        hi.to(device),
        grid.to(device),
        color.to(device),
        what=what,
        n=200,
        dtype=F64,
        device=device,
        channels=3,
    )
    assert_close(
        got["radiance"],
        want_l,
        rtol=1e-10,
        atol=1e-12,
        name=f"{what}: radiance, each voxel's segment integrated exactly and "
        f"composited front to back",
        where="(ray, channel)",
    )
    got = walk(
        impl,
        o.to(device),
        d.to(device),
        lo.to(device),
        hi.to(device),
        grid.to(device),
        color[..., 0].contiguous().to(device),
        what="voxel_walk (emission (6, 5, 7))",
        n=200,
        dtype=F64,
        device=device,
    )
    assert_close(
        got["radiance"],
        want_l[:, 0],
        rtol=1e-10,
        atol=1e-12,
        name="voxel_walk with an (X, Y, Z) emission grid: radiance (N,)",
        where="ray",
    )
    got = walk(
        impl,
        o.to(device),
        d.to(device),
        lo.to(device),
        hi.to(device),
        grid.to(device),
        what="voxel_walk (emission=None)",
        n=200,
        dtype=F64,
        device=device,
    )
    assert_equal(
        got["radiance"],
        torch.zeros(200, dtype=F64),
        name="voxel_walk(emission=None): radiance",
        where="ray",
    )
    # Extreme densities: 0, 1e-8 and 1e8 voxels; no NaN, exact limits.
    for sigma in (0.0, 1e-8, 1e8):
        dens = torch.where(grid > 0, grid.new_tensor(sigma), 0.0)
        emis = torch.full((6, 5, 7), 0.5, dtype=F64)
        tau, rad = ref_optical_depth(o, d, lo, hi, dens, emis)
        what = f"voxel_walk (voxels of density {sigma:g})"
        got = walk(
            impl,
            o.to(device),
            d.to(device),
            lo.to(device),
            hi.to(device),
            dens.to(device),
            emis.to(device),
            what=what,
            n=200,
            dtype=F64,
            device=device,
        )
        no_nan(what, **{k: v for k, v in got.items()})
        assert_close(
            got["optical_depth"],
            tau,
            rtol=1e-10,
            atol=1e-300,
            name=f"{what}: optical depth",
            where="ray",
        )
        assert_close(
            got["radiance"], rad, rtol=1e-9, atol=1e-15, name=f"{what}: radiance", where="ray"
        )
    # One voxel; float16 (loose); bad input.
    one = torch.full((1, 1, 1), 0.7, dtype=F64)
    tau, _ = ref_optical_depth(o, d, lo, hi, one)
    got = walk(
        impl,
        o.to(device),
        d.to(device),
        lo.to(device),
        hi.to(device),
        one.to(device),
        what="voxel_walk (one voxel)",
        n=200,
        dtype=F64,
        device=device,
    )
    assert_close(
        got["optical_depth"],
        tau,
        rtol=1e-12,
        atol=1e-15,
        name="voxel_walk of a (1, 1, 1) grid: sigma times the chord",
        where="ray",
    )
    for dtype, tol in ((torch.float16, 2e-2), (torch.bfloat16, 8e-2)):
        oo, dd = o.to(dtype), d.to(dtype)
        tau, _ = ref_optical_depth(oo, dd, lo.to(dtype), hi.to(dtype), grid.to(dtype))
        got = walk(
            impl,
            oo.to(device),
            dd.to(device),
            lo.to(dtype).to(device),
            hi.to(dtype).to(device),
            grid.to(dtype).to(device),
            what=f"voxel_walk ({dtype})",
            n=200,
            dtype=dtype,
            device=device,
        )
        no_nan(f"voxel_walk ({dtype})", optical_depth=got["optical_depth"])
        bad = (got["optical_depth"].cpu().double() - tau).abs() > tol * (tau + 1)
        assert bad.float().mean() < 0.05, (
            f"voxel_walk ({dtype}): {int(bad.sum())} of 200 optical depths off by more than "
            f"{tol:g} (relative to 1 + tau); low precision may blur voxel boundaries, not more"
        )
    oo, dd = o.to(device), d.to(device)
    args = (oo, dd, lo.to(device), hi.to(device))
    expect_error(
        "density",
        impl.voxel_walk,
        *args,
        ramp_density,
        case="a callable density",
        kinds=(TypeError,),
    )
    expect_error(
        "density",
        impl.voxel_walk,
        *args,
        -grid.to(device),
        case="negative densities",
        kinds=(ValueError,),
    )
    expect_error(
        "density",
        impl.voxel_walk,
        *args,
        torch.full_like(grid, math.nan).to(device),
        case="NaN densities (a NaN transmittance)",
        kinds=(ValueError,),
    )
    expect_error(
        "emission",
        impl.voxel_walk,
        *args,
        grid.to(device),
        torch.ones(6, 5, 6, dtype=F64, device=device),
        case="emission of another shape",
    )
    expect_error(
        "occupancy",
        impl.voxel_walk,
        *args,
        grid.to(device),
        None,
        torch.ones(3, 3, 3, dtype=torch.bool, device=device),
        2,
        case="an occupancy grid of the wrong shape (3, 3, 3) for macro_cell=2",
    )
    expect_error(
        "macro_cell", impl.voxel_walk, *args, grid.to(device), None, None, 0, case="macro_cell=0"
    )
    # A flat box (z from 0.5 to 0.5): voxels of no volume, so nothing is met, not even by
    # rays lying in its plane (whose chord along x and y is not empty).
    fo, fd = o.clone(), d.clone()
    fo[:, 2], fd[:, 2] = 0.5, 0.0
    what = "voxel_walk (a flat box z = 0.5, rays in its plane)"
    got = walk(
        impl,
        fo.to(device),
        fd.to(device),
        [WALK_LO[0], WALK_LO[1], 0.5],
        [WALK_HI[0], WALK_HI[1], 0.5],
        grid.to(device),
        color.to(device),
        what=what,
        n=200,
        dtype=F64,
        device=device,
        channels=3,
    )
    for key, want in (("optical_depth", 0), ("radiance", 0), ("steps", 0), ("samples", 0)):
        bad = got[key].cpu() != want
        assert not bad.any(), (
            f"{what}: {key} must be {want} for every ray (a flat box has voxels of no volume; "
            f"do not divide by its voxel size 0), got {got[key].cpu()[bad][:4].tolist()} on "
            f"{int(bad.sum())} rays"
        )


def blob_grid(n=24):
    """Two small dense blobs in an otherwise empty grid, and a lone voxel."""
    x = (torch.arange(n, dtype=F64) + 0.5) / n
    p = torch.stack(torch.meshgrid(x, x, x, indexing="ij"), -1)
    grid = torch.zeros(n, n, n, dtype=F64)
    for c, r in (((0.3, 0.3, 0.6), 0.12), ((0.7, 0.6, 0.3), 0.09)):
        dist = (p - torch.tensor(c, dtype=F64)).norm(dim=-1)
        grid = grid + torch.where(dist < r, 3.0 * (1 - dist / r), 0.0)
    grid[n - 3, 1, n - 2] = 5.0  # a lone voxel: a macro cell must not hide it
    return grid


@pytest.mark.task(4)
@pytest.mark.points(1)
def test_voxel_walk_empty_space_skipping(impl, device):
    grid = blob_grid()
    emission = (grid > 0) * 0.5 + torch.zeros(24, 24, 24, dtype=F64)
    emission[0, 23, 0] = 2.0  # emits without absorbing: still occupied
    colour = emission[..., None] * torch.tensor([1.0, 0.5, 0.25], dtype=F64)
    colour[2, 20, 5] = torch.tensor([0.0, 0.0, 0.3], dtype=F64)  # blue only, no density
    for m in (1, 3, 4, 5, 8):
        occ = check_tensor(
            impl.build_occupancy(grid.to(device), m),
            f"build_occupancy(grid, {m})",
            shape=(-(-24 // m),) * 3,
            dtype=torch.bool,
            device=device,
        ).cpu()
        busy = grid > 0
        want = torch.zeros_like(occ)
        for i, j, k in busy.nonzero().tolist():
            want[i // m, j // m, k // m] = True
        assert_equal(
            occ,
            want,
            name=f"build_occupancy(density, macro_cell={m}): True exactly "
            f"where some voxel of the macro cell has density > 0 (the last block of an "
            f"axis may be partial)",
            where="macro cell",
        )
        occ_e = impl.build_occupancy(grid.to(device), m, emission.to(device)).cpu()
        want[0, 23 // m, 0] = True
        assert_equal(
            occ_e,
            want,
            name=f"build_occupancy(density, {m}, emission): emitting voxels are occupied too",
            where="macro cell",
        )
        occ_c = check_tensor(
            impl.build_occupancy(grid.to(device), m, colour.to(device)),
            f"build_occupancy(grid, {m}, emission (24, 24, 24, 3))",
            shape=(-(-24 // m),) * 3,
            dtype=torch.bool,
            device=device,
        ).cpu()
        want[2 // m, 20 // m, 5 // m] = True
        assert_equal(
            occ_c,
            want,
            name=f"build_occupancy(density, {m}, emission (X, Y, Z, C)): "
            "a voxel emitting in any channel is occupied",
            where="macro cell",
        )

    o, d = box_rays(300, seed=131, lo=[0.0] * 3, hi=[1.0] * 3)
    lo, hi = torch.zeros(3, dtype=F64, device=device), torch.ones(3, dtype=F64, device=device)
    # Rays through the lone voxel, along and across macro-cell planes.
    lone = torch.tensor([[(21 + 0.5) / 24, 1.5 / 24, 22.5 / 24]], dtype=F64)
    o[:6] = lone + torch.tensor(
        [[-2.0, 0, 0], [0, -2.0, 0], [0, 0, 2.0], [-2, -1.0, 1.0], [2.0, 2.0, -2.0], [-1.0, 0, 0]],
        dtype=F64,
    )
    d[:6] = lone - o[:6]
    want_tau, want_l = ref_optical_depth(o, d, lo.cpu(), hi.cpu(), grid, emission)
    plain = walk(
        impl,
        o.to(device),
        d.to(device),
        lo,
        hi,
        grid.to(device),
        emission.to(device),
        what="voxel_walk (no skipping)",
        n=300,
        dtype=F64,
        device=device,
    )
    assert_close(
        plain["optical_depth"],
        want_tau,
        rtol=1e-12,
        atol=1e-14,
        name="voxel_walk (blobs, no skipping): optical depth",
        where="ray",
    )
    totals = {None: (plain["steps"].sum().item(), plain["samples"].sum().item())}
    # The defaults: macro_cell=1 for build_occupancy and voxel_walk alike.
    occ = check_tensor(
        impl.build_occupancy(grid.to(device), emission=emission.to(device)),
        "build_occupancy(grid, emission=emission) (the default macro_cell=1)",
        shape=(24, 24, 24),
        dtype=torch.bool,
        device=device,
    )
    got = walk(
        impl,
        o.to(device),
        d.to(device),
        lo,
        hi,
        grid.to(device),
        emission.to(device),
        occ,
        what="voxel_walk (occupancy of build_occupancy(grid, emission=emission), default "
        "macro_cell=1)",
        n=300,
        dtype=F64,
        device=device,
    )
    assert_close(
        got["optical_depth"],
        plain["optical_depth"],
        rtol=1e-12,
        atol=1e-14,
        name="voxel_walk (the default macro_cell=1, with occupancy): optical depth as without",
        where="ray",
    )
    for m in (1, 4, 8):
        occ = impl.build_occupancy(grid.to(device), m, emission.to(device))
        what = f"voxel_walk (occupancy with macro_cell={m})"
        got = walk(
            impl,
            o.to(device),
            d.to(device),
            lo,
            hi,
            grid.to(device),
            emission.to(device),
            occ,
            m,
            what=what,
            n=300,
            dtype=F64,
            device=device,
        )
        assert_close(
            got["optical_depth"],
            want_tau,
            rtol=1e-12,
            atol=1e-14,
            name=f"{what}: skipping must not change the optical depth. Only skip a "
            f"macro cell whose occupancy is False, to that macro cell's exit",
            where="ray",
        )
        assert_close(
            got["radiance"],
            want_l,
            rtol=1e-10,
            atol=1e-13,
            name=f"{what}: radiance unchanged by skipping",
            where="ray",
        )
        totals[m] = (got["steps"].sum().item(), got["samples"].sum().item())
        assert (got["samples"].cpu() <= plain["samples"].cpu()).all(), (
            f"{what}: no ray may read more voxels than without skipping"
        )
    # Colour emission (X, Y, Z, 3): skipped macro cells add no light in any channel.
    _, want_c = ref_optical_depth(o, d, lo.cpu(), hi.cpu(), grid, colour)
    occ = impl.build_occupancy(grid.to(device), 4, colour.to(device))
    what = "voxel_walk (emission (24, 24, 24, 3), occupancy with macro_cell=4)"
    got = walk(
        impl,
        o.to(device),
        d.to(device),
        lo,
        hi,
        grid.to(device),
        colour.to(device),
        occ,
        4,
        what=what,
        n=300,
        dtype=F64,
        device=device,
        channels=3,
    )
    assert_close(
        got["radiance"],
        want_c,
        rtol=1e-10,
        atol=1e-13,
        where="(ray, channel)",
        name=f"{what}: radiance unchanged by skipping (an empty macro cell emits nothing)",
    )
    report = ", ".join(f"macro_cell={m}: {s} steps / {r} samples" for m, (s, r) in totals.items())
    assert totals[1][1] < 0.5 * totals[None][1], (
        f"voxel_walk: with a per-voxel occupancy grid, empty voxels are not sampled: expected "
        f"far fewer density reads than without skipping ({report})"
    )
    assert totals[4][0] < 0.6 * totals[None][0] and totals[8][0] < totals[None][0], (
        f"voxel_walk: macro cells of 4^3 and 8^3 voxels should cross empty space in fewer "
        f"steps ({report})"
    )


# ---------------------------------------------------------------------------------------
# Task 5: sphere tracing


def trace(impl, *args, what, n, dtype=F64, device="cpu", **kwargs):
    return result_dict(impl.sphere_trace(*args, **kwargs), what, TRACE_KEYS, n, dtype, device)


def status_counts(status):
    return {STATUS[s]: int((status.cpu() == s).sum()) for s in STATUS}


def camera_rays(n, seed, spread=0.45):
    g = generator(seed)
    x = torch.rand(n, 2, generator=g, dtype=F64) * 2 - 1
    d = torch.stack([x[:, 0] * spread + 0.2, x[:, 1] * spread, torch.ones(n, dtype=F64)], -1)
    scale = 0.5 + 2 * torch.rand(n, 1, generator=g, dtype=F64)  # directions not unit
    return torch.zeros(n, 3, dtype=F64), d * scale


@pytest.mark.task(5)
@pytest.mark.points(1)
def test_sphere_trace_matches_analytic(impl, device):
    o, d = camera_rays(600, seed=141)
    ts, cs, clear_s = ref_sphere_hit(o, d, SPHERE_C, SPHERE_R)
    tb, cb, depth_b = ref_box_hit(o, d, BOX_C, BOX_H)
    t_ref = torch.minimum(ts, tb)
    cos = torch.where(ts <= tb, cs, cb)
    eps = 1e-5
    # Judge: hits with incidence cos > 0.15 that do not just clip an edge; misses that pass
    # both solids by a margin.
    b_lo = torch.tensor(BOX_C, dtype=F64) - torch.tensor(BOX_H, dtype=F64)
    b_hi = torch.tensor(BOX_C, dtype=F64) + torch.tensor(BOX_H, dtype=F64)
    margin_b = ref_interval(o, d, b_lo - 0.05, b_hi + 0.05)[2]
    judged_hit = (
        torch.isfinite(t_ref)
        & (cos > 0.15)
        & ((ts <= tb) & (clear_s < -0.05) | (tb < ts) & (depth_b > 0.05))
    )
    judged_miss = ~torch.isfinite(t_ref) & (clear_s > 0.05) & ~margin_b
    assert judged_hit.sum() > 100 and judged_miss.sum() > 100, "test set-up: hits and misses"
    for dtype, tol in ((F64, eps), (torch.float32, eps)):
        what = f"sphere_trace (sphere and box, {dtype}, epsilon={eps:g})"
        got = trace(
            impl,
            o.to(device, dtype),
            d.to(device, dtype),
            sdf_two_solids,
            t_max=50.0,
            max_steps=400,
            epsilon=eps,
            what=what,
            n=600,
            dtype=dtype,
            device=device,
        )
        status, t, steps = got["status"].cpu(), got["t"].cpu().double(), got["steps"].cpu()
        wrong = judged_hit & (status != HIT)
        if wrong.any():
            i = int(wrong.nonzero()[0, 0])
            raise AssertionError(
                f"{what}: {int(wrong.sum())} of {int(judged_hit.sum())} clear hits not reported "
                f"as HIT ({status_counts(status[judged_hit])}). First: ray {i}, direction "
                f"{d[i].tolist()}, analytic t = {t_ref[i].item():.6g}, got status "
                f"{STATUS.get(int(status[i]), status[i])} after {int(steps[i])} steps."
            )
        wrong = judged_miss & (status == HIT)
        assert not wrong.any(), (
            f"{what}: {int(wrong.sum())} rays that pass both solids by > 0.05 report a HIT "
            f"(first: ray {int(wrong.nonzero()[0, 0])})"
        )
        assert (status[judged_miss] == MISS).all(), (
            f"{what}: rays clearly missing should end as MISS once t > t_max "
            f"({status_counts(status[judged_miss])})"
        )
        # |f| <= eps t |d| at the hit: t off by at most eps t / cos (plus rounding).
        bound = (4 * tol / cos + 1e-6) * t_ref
        assert_close(
            t[judged_hit],
            t_ref[judged_hit],
            atol=0,
            rtol=float((bound / t_ref)[judged_hit].max()),
            name=f"{what}: t of clear hits (t in units of |d|: directions are not unit)",
            where="hit",
        )
        bad = judged_hit & ((t - t_ref).abs() > bound)
        assert not bad.any(), (
            f"{what}: hit t off by more than 4 epsilon t / cos(incidence) for ray "
            f"{int(bad.nonzero()[0, 0])}"
        )
        assert ((steps >= 1) & (steps <= 400)).all(), (
            f"{what}: steps must count sdf evaluations per ray (1 .. max_steps)"
        )
        assert (t[status != HIT] == INF).all(), f"{what}: t must be inf unless HIT"
    # NaN/inf rays and NaN distances: misses without an evaluation error.
    bo, bd = bad_rays()
    got = trace(
        impl,
        bo.to(device),
        bd.to(device),
        sdf_unit_sphere,
        what="sphere_trace (NaN/inf rays)",
        n=len(bo),
        device=device,
    )
    assert (got["status"].cpu() == MISS).all() and (got["t"].cpu() == INF).all(), (
        f"sphere_trace: NaN/inf rays and zero directions must be MISS with t = inf, got "
        f"statuses {got['status'].cpu().tolist()}"
    )
    got = trace(
        impl,
        o[:5].to(device),
        d[:5].to(device),
        sdf_nan,
        what="sphere_trace (NaN sdf)",
        n=5,
        device=device,
    )
    assert (got["status"].cpu() == MISS).all(), (
        "sphere_trace: an sdf returning NaN must end the ray as a MISS"
    )
    got = trace(
        impl,
        o.to(device),
        d.to(device),
        sdf_two_solids,
        t_max=50.0,
        max_steps=400,
        epsilon=eps,
        what="sphere_trace",
        n=600,
        device=device,
    )
    cpu_agrees(
        device,
        "sphere_trace",
        got,
        impl.sphere_trace,
        o.to(device),
        d.to(device),
        sdf_two_solids,
        50.0,
        400,
        eps,
        rtol=1e-9,
    )
    # bfloat16: loosely right for a unit sphere.
    got = trace(
        impl,
        o.to(torch.bfloat16).to(device),
        d.to(torch.bfloat16).to(device),
        sdf_two_solids,
        t_max=50.0,
        max_steps=200,
        epsilon=1e-2,
        what="sphere_trace (bfloat16)",
        n=600,
        dtype=torch.bfloat16,
        device=device,
    )
    found = (got["status"].cpu() == HIT) & judged_hit
    assert found.sum() > 0.9 * judged_hit.sum(), "sphere_trace (bfloat16): most clear hits found"
    # Bad input.
    oo, dd = o.to(device), d.to(device)
    expect_error(
        "relaxation",
        impl.sphere_trace,
        oo,
        dd,
        sdf_unit_sphere,
        relaxation=2.0,
        case="relaxation=2.0",
    )
    expect_error(
        "relaxation",
        impl.sphere_trace,
        oo,
        dd,
        sdf_unit_sphere,
        relaxation=0.5,
        case="relaxation=0.5",
    )
    expect_error(
        "epsilon", impl.sphere_trace, oo, dd, sdf_unit_sphere, epsilon=0.0, case="epsilon=0"
    )
    expect_error(
        "max_steps", impl.sphere_trace, oo, dd, sdf_unit_sphere, max_steps=0, case="max_steps=0"
    )
    expect_error("sdf", impl.sphere_trace, oo, dd, 3.0, case="sdf=3.0", kinds=(TypeError,))
    # Unbounded, the relative test |f| <= epsilon t |d| accepts any distance far enough out
    # (an SDF of 1 everywhere would "hit" at t = 1e4): t_max must be finite.
    expect_error(
        "t_max", impl.sphere_trace, oo, dd, sdf_unit_sphere, t_max=math.inf, case="t_max=inf"
    )


@pytest.mark.task(5)
@pytest.mark.points(1)
def test_sphere_trace_grazing_and_inside(impl, device):
    # Rays passing a unit sphere at clearances 1e-3 .. 1e-2 (well above epsilon t): the steps
    # shrink near the tangent point; they must never be reported as hits.
    n = 64
    g = generator(151)
    clearance = 10 ** (-3 + torch.rand(n, generator=g, dtype=F64))
    side = unit(torch.randn(n, 3, generator=g, dtype=F64) * torch.tensor([1.0, 1.0, 0.0]))
    o = side * (1 + clearance)[:, None] + torch.tensor([0.0, 0.0, -4.0], dtype=F64)
    d = torch.tensor([[0.0, 0.0, 1.0]], dtype=F64).expand(n, 3)
    few = trace(
        impl,
        o.to(device),
        d.to(device),
        sdf_unit_sphere,
        t_max=20.0,
        max_steps=24,
        epsilon=1e-6,
        what="sphere_trace (grazing, max_steps=24)",
        n=n,
        device=device,
    )
    status = few["status"].cpu()
    assert not (status == HIT).any(), (
        f"sphere_trace: rays passing the sphere at clearances 1e-3..1e-2 are misses; with "
        f"max_steps=24 they run out of steps and must be UNSURE, never HIT "
        f"({status_counts(status)}). Only |f| <= epsilon t |d| makes a hit."
    )
    assert (status == UNSURE).all() and (few["steps"].cpu() == 24).all(), (
        f"sphere_trace (grazing, max_steps=24): a ray undecided after max_steps evaluations is "
        f"UNSURE ({status_counts(status)}, steps {few['steps'].cpu().tolist()[:8]} ...)"
    )
    many = trace(
        impl,
        o.to(device),
        d.to(device),
        sdf_unit_sphere,
        t_max=20.0,
        max_steps=3000,
        epsilon=1e-6,
        what="sphere_trace (grazing, max_steps=3000)",
        n=n,
        device=device,
    )
    assert (many["status"].cpu() == MISS).all(), (
        f"sphere_trace (grazing, max_steps=3000): with enough steps every ray escapes past "
        f"t_max: MISS ({status_counts(many['status'])})"
    )
    steps = many["steps"].cpu()
    assert steps.min() > 30, (
        f"sphere_trace: grazing rays need many steps (they shrink near the tangent point); "
        f"counted only {steps.min().item()} sdf evaluations for some ray"
    )
    # Rays starting inside find where they leave the sphere; t_max shorter than the hit
    # gives a miss.
    m = 80
    start = (
        unit(torch.randn(m, 3, generator=g, dtype=F64))
        * 0.9
        * torch.rand(m, 1, generator=g, dtype=F64)
    )
    dirs = torch.randn(m, 3, generator=g, dtype=F64) * 2
    t_exit, _, _ = ref_sphere_hit(start, dirs, (0.0, 0.0, 0.0), 1.0)
    got = trace(
        impl,
        start.to(device),
        dirs.to(device),
        sdf_unit_sphere,
        t_max=20.0,
        max_steps=200,
        epsilon=1e-7,
        what="sphere_trace (from inside)",
        n=m,
        device=device,
    )
    assert (got["status"].cpu() == HIT).all(), (
        f"sphere_trace: rays starting inside the sphere (sdf < 0) must find where they leave it "
        f"(step by |f|): {status_counts(got['status'])}"
    )
    assert_close(
        got["t"],
        t_exit,
        rtol=1e-5,
        name="sphere_trace from inside: t of the exit point",
        where="ray",
    )
    short = trace(
        impl,
        torch.tensor([[0.0, 0.0, -4.0]], dtype=F64, device=device),
        torch.tensor([[0.0, 0.0, 1.0]], dtype=F64, device=device),
        sdf_unit_sphere,
        t_max=2.5,
        what="sphere_trace (t_max=2.5)",
        n=1,
        device=device,
    )
    assert short["status"].item() == MISS and short["t"].item() == INF, (
        f"sphere_trace with t_max=2.5 and the surface at t=3: MISS, got "
        f"{STATUS.get(short['status'].item())} at t={short['t'].item()}"
    )


@pytest.mark.task(5)
@pytest.mark.points(0.5)
def test_sphere_trace_over_relaxation(impl, device):
    # A thin slab 5 away: an over-relaxed step of 1.9 * 4.99 jumps right through it. The
    # unbounding spheres then fail to overlap, and the ray must step back.
    n = 16
    g = generator(161)
    d = torch.cat(
        [torch.rand(n, 2, generator=g, dtype=F64) * 0.2 - 0.1, torch.ones(n, 1, dtype=F64)], 1
    )
    o = torch.zeros(n, 3, dtype=F64)
    want = 4.99 / d[:, 2]
    for omega in (1.0, 1.5, 1.9):
        what = f"sphere_trace (thin slab, relaxation={omega})"
        got = trace(
            impl,
            o.to(device),
            d.to(device),
            sdf_thin_slab,
            t_max=50.0,
            max_steps=200,
            epsilon=1e-6,
            relaxation=omega,
            what=what,
            n=n,
            device=device,
        )
        assert (got["status"].cpu() == HIT).all(), (
            f"{what}: every ray must hit the slab 0.02 thick at z = 5 "
            f"({status_counts(got['status'])}). When |f_prev| + |f| < the last step, the "
            f"over-relaxed step may have jumped over a surface: go back to t_prev + |f_prev| and "
            f"continue with omega = 1 (Keinert et al. 2014)"
        )
        assert_close(got["t"], want, rtol=1e-5, name=f"{what}: t", where="ray")
    # Rays at shallow angles to a ground plane: the same hits, in fewer steps.
    m = 48
    angle = torch.deg2rad(2 + 10 * torch.rand(m, generator=g, dtype=F64))
    azimuth = 2 * math.pi * torch.rand(m, generator=g, dtype=F64)
    d = torch.stack(
        [
            torch.cos(angle) * torch.cos(azimuth),
            -torch.sin(angle),
            torch.cos(angle) * torch.sin(azimuth),
        ],
        -1,
    )
    o = torch.zeros(m, 3, dtype=F64)
    want = 1.0 / torch.sin(angle)
    counts = {}
    for omega in (1.0, 1.5):
        what = f"sphere_trace (ground plane at shallow angles, relaxation={omega})"
        got = trace(
            impl,
            o.to(device),
            d.to(device),
            sdf_ground,
            t_max=100.0,
            max_steps=2000,
            epsilon=1e-6,
            relaxation=omega,
            what=what,
            n=m,
            device=device,
        )
        assert (got["status"].cpu() == HIT).all(), f"{what}: all rays hit the plane"
        assert_close(got["t"], want, rtol=1e-4, name=f"{what}: t", where="ray")
        counts[omega] = got["steps"].sum().item()
    assert counts[1.5] < 0.85 * counts[1.0], (
        f"sphere_trace: over-relaxation (omega = 1.5) should save steps on rays running at "
        f"shallow angles to a plane; steps {counts}. Step omega |f| while the unbounding "
        f"spheres overlap."
    )


@pytest.mark.task(5)
@pytest.mark.points(0.5)
def test_sphere_trace_relative_epsilon(impl, device):
    # A sphere of radius 1e3 at 1e5, float32: positions round to ~0.008 there, so an absolute
    # tolerance of 1e-4 is never met; a relative one (epsilon t |d|) is.
    n = 64
    g = generator(171)
    d = torch.cat(
        [torch.rand(n, 2, generator=g, dtype=F64) * 0.012 - 0.006, torch.ones(n, 1, dtype=F64)], 1
    )
    o = torch.zeros(n, 3, dtype=F64)
    eps = 1e-4
    t_ref, cos, _ = ref_sphere_hit(o, d.float().double(), FAR_C, FAR_R)
    judged = torch.isfinite(t_ref) & (cos > 0.2)
    assert judged.sum() > 32, "test set-up: hits"
    got = trace(
        impl,
        o.float().to(device),
        d.float().to(device),
        sdf_far_sphere,
        t_max=3e5,
        max_steps=200,
        epsilon=eps,
        what="sphere_trace (sphere at 1e5, float32)",
        n=n,
        dtype=torch.float32,
        device=device,
    )
    status = got["status"].cpu()
    assert (status[judged] == HIT).all(), (
        f"sphere_trace (float32 sphere of radius 1e3 at 1e5, epsilon=1e-4): the clear hits "
        f"must be found ({status_counts(status[judged])}). Test |f| <= epsilon t |d| (relative "
        f"to the distance): an absolute |f| <= epsilon is below float32's spacing at 1e5."
    )
    t = got["t"].cpu().double()
    assert_close(
        t[judged],
        t_ref[judged],
        rtol=4 * eps / 0.2,
        name="sphere_trace (sphere at 1e5): t",
        where="hit",
    )
    # A sphere of radius 1e-3 at 0.01: the tolerance must shrink with the distance too.
    d = torch.cat(
        [torch.rand(n, 2, generator=g, dtype=F64) * 0.12 - 0.06, torch.ones(n, 1, dtype=F64)], 1
    )
    t_ref, cos, _ = ref_sphere_hit(o, d, NEAR_C, NEAR_R)
    judged = torch.isfinite(t_ref) & (cos > 0.3)
    assert judged.sum() > 16, "test set-up: hits on the tiny sphere"
    got = trace(
        impl,
        o.to(device),
        d.to(device),
        sdf_tiny_sphere,
        t_max=1.0,
        max_steps=200,
        epsilon=eps,
        what="sphere_trace (sphere of radius 1e-3 at 0.01)",
        n=n,
        device=device,
    )
    t = got["t"].cpu()
    assert (got["status"].cpu()[judged] == HIT).all(), "sphere_trace: hits on the tiny sphere"
    assert_close(
        t[judged],
        t_ref[judged],
        rtol=2 * eps / 0.3,
        name="sphere_trace (sphere of radius 1e-3 at 0.01, epsilon=1e-4): t must be "
        "within epsilon t / cos of the surface; an absolute tolerance of 1e-4 is "
        "a tenth of the sphere's radius here",
        where="hit",
    )


@pytest.mark.task(5)
@pytest.mark.points(0.5)
def test_sphere_trace_direction_length(impl, device):
    # The hit test is |f| <= epsilon t |d|: the same rays with |d| = 1e-4 and 1e2 find the
    # same world points (t scales as 1 / |d|).
    n = 32
    g = generator(173)
    d = torch.cat(
        [torch.rand(n, 2, generator=g, dtype=F64) * 0.3 - 0.15, torch.ones(n, 1, dtype=F64)], 1
    )
    d = unit(d)
    o = torch.zeros(n, 3, dtype=F64)
    centre, radius, eps = SPHERE_5_C, 1.0, 1e-4
    t_ref, cos, _ = ref_sphere_hit(o, d, centre, radius)
    judged = torch.isfinite(t_ref) & (cos > 0.3)
    assert judged.sum() > 8, "test set-up: hits"
    for scale in (1e-4, 1e2):
        got = trace(
            impl,
            o.to(device),
            (d * scale).to(device),
            sdf_sphere_at_5,
            t_max=1e6,
            max_steps=200,
            epsilon=eps,
            what=f"sphere_trace (|d| = {scale:g})",
            n=n,
            device=device,
        )
        assert (got["status"].cpu()[judged] == HIT).all(), (
            f"sphere_trace (|d| = {scale:g}): the clear hits must be found "
            f"({status_counts(got['status'][judged])})"
        )
        assert_close(
            got["t"].cpu()[judged] * scale,
            t_ref[judged],
            rtol=4 * eps / 0.3,
            name=f"sphere_trace (unit sphere at distance 5, |d| = {scale:g}, epsilon=1e-4): "
            "t |d| must be within epsilon t |d| / cos of the surface; the tolerance is "
            "relative to the world distance t |d|, not to t",
            where="hit",
        )


@pytest.mark.task(5)
@pytest.mark.points(0.5)
def test_sphere_trace_exact_boundaries(impl, device):
    # The ground plane y = -1 with dyadic distances, so every t below is exact.
    rays = {
        "starting on the surface": ((0.0, -1.0, 0.0), (0.25, 1.0, 0.5), HIT, 0.0),
        "zero direction, on the surface": ((0.0, -1.0, 0.0), (0.0, 0.0, 0.0), MISS, INF),
        "NaN x, on the surface": ((math.nan, -1.0, 0.0), (0.0, 1.0, 0.0), MISS, INF),
        "surface exactly at t_max = 4": ((0.0, 3.0, 0.0), (0.0, -1.0, 0.0), HIT, 4.0),
        "first step lands on the surface past t_max": (
            (0.0, 3.5, 0.0),
            (0.0, -1.0, 0.0),
            MISS,
            INF,
        ),
        "parallel to the surface": ((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), MISS, INF),
    }
    o = torch.tensor([r[0] for r in rays.values()], dtype=F64, device=device)
    d = torch.tensor([r[1] for r in rays.values()], dtype=F64, device=device)
    n = len(rays)
    what = "sphere_trace (ground plane y = -1, t_max=4)"
    got = trace(impl, o, d, sdf_ground, t_max=4.0, max_steps=64, what=what, n=n, device=device)
    status, t = got["status"].cpu(), got["t"].cpu()
    for i, (case, (_, _, want, t_want)) in enumerate(rays.items()):
        assert status[i].item() == want and t[i].item() == t_want, (
            f"{what}, ray {case}: expected {STATUS[want]} at t={t_want}, got "
            f"{STATUS.get(status[i].item(), status[i].item())} at t={t[i].item()}. A hit is "
            f"|f| <= epsilon t |d| (f = 0 at t = 0 is a hit; t = t_max is not beyond t_max); a "
            f"ray past t_max misses even where it lands on a surface; zero directions and "
            f"NaN rays miss without a hit test."
        )
    # Over-relaxed, a ray starting on the surface is a hit at its first evaluation too: there
    # is no previous sphere yet (|f_prev| + |f| = 0 >= the last step, 0: they overlap).
    what = "sphere_trace (starting on the ground plane, relaxation=1.5)"
    on = trace(
        impl, o[:1], d[:1], sdf_ground, t_max=4.0, relaxation=1.5, what=what, n=1, device=device
    )
    got = (on["status"].item(), on["t"].item(), on["steps"].item())
    assert got == (HIT, 0.0, 1), (
        f"{what}: expected a HIT at t = 0 after 1 evaluation, got "
        f"{STATUS.get(got[0], got[0])} at t = {got[1]} after {got[2]} evaluations"
    )
    # One evaluation only: the ray from y = 3 stands at t = 4 = t_max, undecided: UNSURE.
    what = "sphere_trace (surface at t_max = 4, max_steps=1)"
    one = trace(
        impl, o[3:4], d[3:4], sdf_ground, t_max=4.0, max_steps=1, what=what, n=1, device=device
    )
    assert one["status"].item() == UNSURE and one["steps"].item() == 1, (
        f"{what}: after its one evaluation the ray is at t = 4, not past t_max = 4 and not "
        f"decided: UNSURE with 1 step, got {STATUS.get(one['status'].item())} with "
        f"{one['steps'].item()} steps"
    )
    expect_error(
        "sdf",
        impl.sphere_trace,
        o,
        d,
        sdf_column,
        case="an sdf returning shape (N, 1) instead of (N,)",
        kinds=(ValueError,),
    )
    # Over-relaxation stepping back on rays with |d| far from 1: the backward step is a world
    # length, so it is divided by |d| like every other step.
    g = generator(181)
    m = 16
    dirs = torch.cat(
        [torch.rand(m, 2, generator=g, dtype=F64) * 0.2 - 0.1, torch.ones(m, 1, dtype=F64)], 1
    )
    want = 4.99 / dirs[:, 2]
    for scale in (1e-3, 1e3):
        what = f"sphere_trace (thin slab, relaxation=1.9, |d| ~ {scale:g})"
        runs = {
            omega: trace(
                impl,
                torch.zeros(m, 3, dtype=F64, device=device),
                (dirs * scale).to(device),
                sdf_thin_slab,
                t_max=50.0 / scale,
                max_steps=200,
                epsilon=1e-6,
                relaxation=omega,
                what=what,
                n=m,
                device=device,
            )
            for omega in (1.0, 1.9)
        }
        got = runs[1.9]
        extra = runs[1.9]["steps"].cpu() - runs[1.0]["steps"].cpu()
        assert (extra <= 2).all(), (
            f"{what}: the first over-relaxed step jumps through the slab and fails; from the "
            f"last safe point the ray must continue with omega = 1, which is the plain march's "
            f"path, so it may take at most a step or two more than relaxation=1; it took "
            f"{extra.max().item()} more"
        )
        assert (got["status"].cpu() == HIT).all(), (
            f"{what}: every ray must hit the slab ({status_counts(got['status'])}); going back "
            f"to the last safe point is t_prev + |f_prev| / |d|"
        )
        assert_close(got["t"].cpu() * scale, want, rtol=1e-5, name=f"{what}: t |d|", where="ray")
    # The defaults are t_max=100, max_steps=128, epsilon=1e-4, relaxation=1: rays at shallow
    # angles to the ground (hits near t = 100, some needing many steps) and one straight down
    # onto the plane at t = 105 tell them apart.
    angle = torch.deg2rad(torch.linspace(0.4, 3.0, 23, dtype=F64))
    dirs = torch.stack([torch.cos(angle), -torch.sin(angle), torch.zeros_like(angle)], -1)
    dirs = torch.cat([dirs, torch.tensor([[0.0, -1.0, 0.0]], dtype=F64)])  # the plane at t = 105
    origin = torch.zeros(24, 3, dtype=F64, device=device)
    origin[-1, 1] = 104.0
    plain = trace(
        impl,
        origin,
        dirs.to(device),
        sdf_ground,
        what="sphere_trace (defaults)",
        n=24,
        device=device,
    )
    spelled = trace(
        impl,
        origin,
        dirs.to(device),
        sdf_ground,
        100.0,
        128,
        1e-4,
        1.0,
        what="sphere_trace (t_max=100, max_steps=128, epsilon=1e-4, relaxation=1)",
        n=24,
        device=device,
    )
    for key in TRACE_KEYS:
        assert_equal(
            plain[key],
            spelled[key],
            name=f"sphere_trace: {key} with the default arguments vs t_max=100, max_steps=128, "
            f"epsilon=1e-4, relaxation=1 spelled out",
            where="ray",
        )
