"""Lab 4's trade: step counts and quadrature of ``march_box``.

Knobs: the integrator (``riemann``: left Riemann sums; ``exact``: the exact per-segment
emission-absorption integral) and the step count, on a homogeneous box and on a linear
density ramp. Error: the largest relative error of the radiance against the closed form
(float64; the ramp's with ``erfcx``), on rays crossing the unit cube. On CUDA the fused
``course.kernels.triton_march.march_grid_triton`` (exact integrator) adds rows.
"""

from __future__ import annotations

import math

import torch

from course.tools.trade.common import F64, relative_error, timed

MODULE = "lab4_march"
TITLE = "ray marching: step count and quadrature"
ERROR_NAME = "max relative radiance error"
ERROR = (
    "largest relative error of the radiance against the closed form (float64), "
    "homogeneous box and density ramp"
)
INTEGRATORS = ("riemann", "exact")
Q, SIGMA = 0.7, 1.3  # emission and the homogeneous box's density
BOX = ([0.0] * 3, [1.0] * 3)


def x_face_rays(n: int, seed: int = 0):
    """Rays entering [0, 1]^3 through x = 0 and leaving through x = 1 (unit directions)."""
    g = torch.Generator().manual_seed(seed)
    entry = torch.cat(
        [torch.zeros(n, 1, dtype=F64), 0.3 + 0.4 * torch.rand(n, 2, generator=g, dtype=F64)], 1
    )
    d = torch.cat(
        [torch.ones(n, 1, dtype=F64), 0.4 * torch.rand(n, 2, generator=g, dtype=F64) - 0.2], 1
    )
    d = d / d.norm(dim=1, keepdim=True)
    return entry - 0.5 * d, d


def phi(x):
    """(1 - e^{-x}) / x, 1 at x = 0."""
    return torch.where(x > 0, -torch.expm1(-x) / x.clamp(min=1e-300), torch.ones_like(x))


def chord(o, d, lo, hi):
    """(t_near, t_far) of rays that hit the box, float64 (unit directions)."""
    lo, hi = torch.tensor(lo, dtype=F64), torch.tensor(hi, dtype=F64)
    t0, t1 = (lo - o) / d, (hi - o) / d
    return torch.minimum(t0, t1).amax(-1).clamp(min=0), torch.maximum(t0, t1).amin(-1)


def ramp_density(p):
    """sigma = 0.5 + 2 x: a module-level function, so a sandboxed lab can be passed it."""
    return 0.5 + 2.0 * p[:, 0]


def ramp_reference(o, d, q):
    """Radiance of constant emission ``q`` in ``ramp_density`` over [0, 1]^3, closed form."""
    near, far = chord(o, d, *BOX)
    length = far - near
    a = 0.5 + 2.0 * (o[:, 0] + near * d[:, 0])
    b = 2.0 * d[:, 0]
    root = torch.sqrt(2 * b)
    tau = a * length + b * length**2 / 2
    return (
        q
        * math.sqrt(math.pi)
        / root
        * (
            torch.special.erfcx(a / root)
            - torch.exp(-tau) * torch.special.erfcx((a + b * length) / root)
        )
    )


def prepare(
    device,
    quick: bool,
    rays: int | None = None,
    max_steps: int | None = None,
    repeats: int | None = None,
) -> dict:
    """The rays and exact radiances; ``rays``, ``max_steps``, ``repeats`` override the sizes
    ``quick`` and the device choose (bench/lab4_march.py passes its own)."""
    n = rays or (256 if quick else (1 << 18 if device.type == "cuda" else 4096))
    o, d = x_face_rays(n)
    near, far = chord(o, d, *BOX)
    return {
        "device": device,
        "quick": quick,
        "repeats": repeats or (2 if quick else 5),
        "rays": n,
        "max_steps": max_steps or (16 if quick else 256),
        "origins": o.float().to(device),
        "directions": d.float().to(device),
        "exact": {
            "homogeneous": Q * (far - near) * phi(SIGMA * (far - near)),
            "ramp": ramp_reference(o, d, Q),
        },
        "density": {
            "homogeneous": torch.full((1, 1, 1), SIGMA, device=device),
            "ramp": ramp_density,
        },
        "emission": torch.full((1, 1, 1), Q, device=device),
    }


def knobs(ctx: dict) -> list[dict]:
    steps = [2**k for k in range(int(math.log2(ctx["max_steps"])) + 1)]
    return [
        {
            "setting": f"{medium} {integrator} {n}",
            "medium": medium,
            "integrator": integrator,
            "steps": n,
        }
        for medium in ("homogeneous", "ramp")
        for integrator in INTEGRATORS
        for n in steps
    ]


def measure(lab, ctx: dict, knob: dict) -> dict:
    result, seconds = timed(
        ctx,
        lab.march_box,
        ctx["origins"],
        ctx["directions"],
        *BOX,
        ctx["density"][knob["medium"]],
        ctx["emission"],
        knob["steps"],
        integrator=knob["integrator"],
    )
    return {
        "seconds": seconds,
        "error": relative_error(result["radiance"], ctx["exact"][knob["medium"]]),
        "rays": ctx["rays"],
        "steps": knob["steps"],
    }


def fused(ctx: dict) -> list[dict]:
    """``march_grid_triton`` (exact integrator, one launch) on the homogeneous box."""
    try:
        from course.kernels.triton_launch import triton_available
        from course.kernels.triton_march import march_grid_triton
    except ImportError:
        return []
    if not triton_available():
        return []
    rows = []
    # The same homogeneous medium as a 2^3 grid: Triton specialises an int argument equal
    # to 1 (a grid's size) into a constant, which the kernel's size arithmetic cannot take.
    density = torch.full((2, 2, 2), SIGMA, device=ctx["device"])
    emission = torch.full((2, 2, 2), Q, device=ctx["device"])
    for knob in knobs(ctx):
        if knob["medium"] != "homogeneous" or knob["integrator"] != "exact":
            continue
        result, seconds = timed(
            ctx,
            march_grid_triton,
            ctx["origins"],
            ctx["directions"],
            *BOX,
            density,
            emission,
            knob["steps"],
        )
        rows.append(
            {
                **knob,
                "setting": f"fused {knob['setting']}",
                "seconds": seconds,
                "error": relative_error(result["radiance"], ctx["exact"]["homogeneous"]),
                "rays": ctx["rays"],
                "steps": knob["steps"],
            }
        )
    return rows
