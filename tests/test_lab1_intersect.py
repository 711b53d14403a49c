"""Grader for Lab 1: ray/primitive intersection.

References are computed here in float64, never stored: Cramer's rule for triangles (written
differently from every variant), an explicit per-axis slab test for boxes and the
quadratic in float64 for spheres. Comparisons judge only *definite* cases: a ray whose
float64 barycentrics lie within rounding distance of an edge, or that grazes the plane, may
go either way in float32 and is not judged (its fraction is reported).

Which variant must survive which extreme (see the table in the lab's docstring):

===============================  ================================  =======================
case                             watertight                        simple, MT, woop
===============================  ================================  =======================
rays aimed at shared edges and   asserted: no cracks (each ray's   no crash, no NaN; crack
vertices of a closed icosphere,  first hit is a triangle sharing   rate measured and
translated by 0, 1e5, 1e6        the aimed edge or vertex)         printed (they do crack)
rays nearly parallel to a        asserted: no hit the float64      same
triangle (cos 1e-3 .. 1e-7),     reference clearly rules out
past icosphere, Suzanne, bunny
exact inside/outside decision    asserted (double fallback)        not asserted
for axis-parallel rays
tiny triangle, scaled scenes,    asserted                          asserted
degenerate input, NaN/inf,
t interval, self-hits
float16 / bfloat16               well-shaped triangles only        same
===============================  ================================  =======================

A crack is a ray aimed at a shared edge or vertex whose first hit is not one of the triangles
sharing it: it hit nothing, or it slipped through to the far side. The measured rates are in
the lab's docstring (``bench/lab1_intersect.py --crack-table`` produces that table); the
extremes tests of the other variants print your kernels' rates (``pytest -s``).
"""

from __future__ import annotations

import functools
import math

import pytest
import torch

from course.core.scenes import load_scene
from course.core.types import Hits, Mesh, Rays
from course.grading.testing import (
    assert_close,
    assert_equal,
    assert_fraction,
    check_tensor,
    expect_error,
    generator,
    replaced,
)
from course.measure.accounting import count_ops, live_values
from course.measure.occupancy import PRESETS, occupancy

LAB_MODULE = "lab1_intersect"
TASKS = {
    1: "Plane + area test",
    2: "Möller–Trumbore",
    3: "Woop's unit-triangle test",
    4: "Watertight test",
    5: "Boxes and spheres",
    6: "Closest hit by brute force",
    7: "Operation counts, registers, occupancy",
}

INF = math.inf
F64 = torch.float64
TRIANGLE_KERNELS = ("intersect_simple", "moller_trumbore", "woop_unit", "watertight")


# ---------------------------------------------------------------------------------------
# Calling the kernels


def intersect(impl, variant, o, d, v0, v1, v2, t_min=0.0, t_max=INF):
    """``(t, u, v)`` of one triangle kernel; Woop's test gets its transform first."""
    if variant == "woop_unit":
        transform = impl.woop_precompute(v0, v1, v2)
        return impl.woop_unit(o, d, transform, t_min, t_max)
    return getattr(impl, variant)(o, d, v0, v1, v2, t_min, t_max)


def checked(result, variant, shape, dtype, device):
    """The (t, u, v) triple, each checked for type, shape, dtype and device."""
    if not isinstance(result, tuple) or len(result) != 3:
        raise AssertionError(
            f"{variant}: expected a tuple (t, u, v), got {type(result).__name__}"
            + (f" of length {len(result)}" if isinstance(result, tuple) else "")
        )
    return tuple(
        check_tensor(
            x, f"{variant}(...)[{i}] ({'tuv'[i]})", shape=tuple(shape), dtype=dtype, device=device
        )
        for i, x in enumerate(result)
    )


def no_nan(variant, case, *tensors):
    for name, x in zip("tuv", tensors):
        bad = torch.isnan(x.cpu())
        if bad.any():
            raise AssertionError(
                f"{variant} ({case}): {int(bad.sum())} NaN values in {name}, first at "
                f"{tuple(bad.nonzero()[0].tolist())}. Misses must return t = inf and u = v = 0: "
                f"mask the outputs with the hit mask (torch.where), never let a NaN out."
            )


def expect_misses(variant, case, t, u, v, what="ray"):
    no_nan(variant, case, t, u, v)
    hit = t.cpu() < INF
    if hit.any():
        i = tuple(hit.nonzero()[0].tolist())
        raise AssertionError(
            f"{variant} ({case}): {int(hit.sum())} of {hit.numel()} {what}s report a hit; they "
            f"must all miss. First at {i}: t={t.cpu()[i].item()!r}, u={u.cpu()[i].item()!r}, "
            f"v={v.cpu()[i].item()!r}."
        )
    assert_equal(u, torch.zeros_like(u), name=f"{variant} ({case}): u of misses", where=what)
    assert_equal(v, torch.zeros_like(v), name=f"{variant} ({case}): v of misses", where=what)


# ---------------------------------------------------------------------------------------
# References (float64, CPU)


def ref_triangle(o, d, v0, v1, v2, t_min=0.0, t_max=INF, margin_eps=None):
    """Cramer's rule on ``[-d, e1, e2] (t, u, v) = o - v0`` in float64.

    Returns ``(t, u, v, hit, judged)``: ``hit`` is the exact decision, ``judged`` marks the
    pairs far enough from every decision boundary for a ``margin_eps``-precise kernel to
    agree (None: judge all).
    """
    o, d, v0, v1, v2 = torch.broadcast_tensors(
        *(x.detach().to("cpu", F64) for x in (o, d, v0, v1, v2))
    )
    t_min = torch.as_tensor(t_min).detach().to("cpu", F64)
    t_max = torch.as_tensor(t_max).detach().to("cpu", F64)
    e1, e2 = v1 - v0, v2 - v0
    s = o - v0
    n = torch.linalg.cross(e1, e2)
    det = -(d * n).sum(-1)
    t = (s * n).sum(-1) / det
    u = -(d * torch.linalg.cross(s, e2)).sum(-1) / det
    v = -(d * torch.linalg.cross(e1, s)).sum(-1) / det
    w = 1 - u - v
    hit = (det != 0) & (u >= 0) & (v >= 0) & (w >= 0) & (t >= t_min) & (t <= t_max)
    if margin_eps is None:
        return t, u, v, hit, torch.ones_like(hit)
    # A float test's errors in u, v, w grow like |s| / (size * sin(angle)), in t like
    # |s| / sin(angle) (units of |d|).
    size = torch.minimum(e1.norm(dim=-1), e2.norm(dim=-1))
    sin = det.abs() / (d.norm(dim=-1) * n.norm(dim=-1))
    reach = s.norm(dim=-1) / size + 1
    margin = torch.minimum(torch.minimum(u, v), w)
    inside_clear = margin.abs() * sin > 64 * margin_eps * reach
    t_err = 64 * margin_eps * (t.abs() + s.norm(dim=-1) / (d.norm(dim=-1) * sin))
    interval_clear = ((t - t_min).abs() > t_err) & ((t - t_max).abs() > t_err)
    judged = inside_clear & ((margin < 0) | interval_clear)
    return t, u, v, hit, judged


def compare_hits(variant, case, got, ref, eps, where="(ray, triangle)"):
    """Decisions must agree on judged pairs; t, u, v must agree on judged hits."""
    t, u, v = (x.detach().to("cpu", F64) for x in got)
    t_ref, u_ref, v_ref, hit_ref, judged = ref
    hit = t < INF
    wrong = (hit != hit_ref) & judged
    if wrong.any():
        i = tuple(wrong.nonzero()[0].tolist())
        if hit_ref[i]:
            detail = (
                f"the float64 reference hits at t={t_ref[i].item():.9g}, "
                f"u={u_ref[i].item():.6g}, v={v_ref[i].item():.6g}, but you report a miss"
            )
        else:
            detail = (
                f"the float64 reference misses (t={t_ref[i].item():.6g}, "
                f"u={u_ref[i].item():.6g}, v={v_ref[i].item():.6g}: outside the triangle "
                f"or the interval), but you report a hit at t={t[i].item():.9g}, "
                f"u={u[i].item():.6g}, v={v[i].item():.6g}"
            )
        raise AssertionError(
            f"{variant} ({case}): {int(wrong.sum())} of {int(judged.sum())} clear-cut "
            f"{where} pairs are decided wrongly. First at {where} {i}: {detail}."
        )
    both = hit & hit_ref & judged
    scale = t_ref.abs().where(both, torch.zeros_like(t_ref)).amax().item() + 1
    tol = 4096 * eps
    assert_close(
        t[both],
        t_ref[both],
        rtol=tol,
        atol=tol * scale,
        name=f"{variant} ({case}): t of clear-cut hits",
        where="hit",
    )
    assert_close(
        u[both], u_ref[both], atol=tol * 16, name=f"{variant} ({case}): u of hits", where="hit"
    )
    assert_close(
        v[both], v_ref[both], atol=tol * 16, name=f"{variant} ({case}): v of hits", where="hit"
    )
    return judged.float().mean().item()


def barycentric_properties(variant, case, t, u, v, o, d, v0, v1, v2, eps):
    """On hits: u, v >= 0, u + v <= 1, and (1-u-v) v0 + u v1 + v v2 == o + t d."""
    t, u, v = (x.detach().to("cpu", F64) for x in (t, u, v))
    hit = t < INF
    tol = 64 * eps
    for name, bad in (("u >= 0", u < -tol), ("v >= 0", v < -tol), ("u + v <= 1", u + v > 1 + tol)):
        bad &= hit
        if bad.any():
            i = tuple(bad.nonzero()[0].tolist())
            raise AssertionError(
                f"{variant} ({case}): {int(bad.sum())} hits violate {name}; "
                f"first at {i}: u={u[i].item()!r}, v={v[i].item()!r}"
            )
    o, d, v0, v1, v2 = (x.detach().to("cpu", F64) for x in (o, d, v0, v1, v2))
    shape = (*t.shape, 3)
    point = (o + t.where(hit, torch.zeros_like(t))[..., None] * d).expand(shape)
    bary = ((1 - u - v)[..., None] * v0 + u[..., None] * v1 + v[..., None] * v2).expand(shape)
    extent = (v0.abs() + v1.abs() + v2.abs() + o.abs()).expand(shape).amax(-1)
    gap = (point - bary).norm(dim=-1)
    bad = hit & (
        gap > 1e3 * eps * extent + 1e3 * eps * (t.abs()[..., None] * d).expand(shape).norm(dim=-1)
    )
    if bad.any():
        i = tuple(bad.nonzero()[0].tolist())
        raise AssertionError(
            f"{variant} ({case}): the hit point from (u, v) differs from o + t d by "
            f"{gap[i].item():.3g} at {i} (t={t[i].item()!r}, u={u[i].item()!r}, "
            f"v={v[i].item()!r}): "
            f"u must weight v1 and v the corner v2, with (1 - u - v) for v0"
        )


# ---------------------------------------------------------------------------------------
# Scenes and rays (built in float64, then rounded once to the dtype under test)


def soup(n: int, seed: int) -> torch.Tensor:
    """(n, 3, 3) float64 corners of the course's random triangle soup in the unit cube."""
    mesh = load_scene("random_soup", device="cpu", dtype=F64, n=n, seed=seed).mesh
    return mesh.vertices[mesh.faces]


def rays_at(tris: torch.Tensor, n: int, seed: int):
    """n rays from outside the unit cube: 2/3 aimed at points on random triangles (some just
    outside them), 1/3 at random points of the cube. float64 (n, 3) each, and (n,) the
    triangle each ray was aimed at."""
    g = generator(seed)
    origins = torch.rand(n, 3, generator=g, dtype=F64) * 4 - 1.5
    pick = torch.randint(0, len(tris), (n,), generator=g)
    b = torch.rand(n, 2, generator=g, dtype=F64) * 1.2 - 0.1
    b = torch.where((b.sum(-1, keepdim=True) > 1.1), 1 - b, b)
    t = tris[pick]
    aim = t[:, 0] + b[:, :1] * (t[:, 1] - t[:, 0]) + b[:, 1:] * (t[:, 2] - t[:, 0])
    anywhere = torch.rand(n, 3, generator=g, dtype=F64)
    aim = torch.where(torch.arange(n)[:, None] % 3 == 2, anywhere, aim)
    return origins, aim - origins, pick


def icosphere(level: int) -> Mesh:
    return load_scene("icosphere", device="cpu", dtype=F64, level=level).mesh


def edge_and_vertex_rays(mesh: Mesh, shift: float, dtype, inside: bool):
    """Rays through the vertices and the points at 1/2 and 1/4 of every edge of a closed
    mesh (after rounding it, translated by ``shift``, to ``dtype``): from outside towards
    the centre, or from the centre outwards. Returns (o, d, corners) in ``dtype`` and
    ``incident`` (R, F) bool: the triangles sharing each ray's aimed vertex or edge."""
    vertices = (mesh.vertices + shift).to(dtype)
    exact = vertices.to(F64)
    faces = mesh.faces
    edges = torch.cat([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    edges = edges.sort(dim=1).values.unique(dim=0)
    targets = [exact] + [exact[edges[:, 0]] * (1 - f) + exact[edges[:, 1]] * f for f in (0.5, 0.25)]
    targets = torch.cat(targets)
    has = (faces[None, :, :] == torch.arange(len(exact))[:, None, None]).any(-1)  # (V, F)
    on_edge = has[edges[:, 0]] & has[edges[:, 1]]
    incident = torch.cat([has, on_edge, on_edge])
    center = torch.full((3,), float(shift), dtype=F64)
    radial = targets - center
    radial = radial / radial.norm(dim=-1, keepdim=True)
    origins = (center.expand_as(targets) if inside else center + 3 * radial).to(dtype)
    directions = (targets - origins.to(F64)).to(dtype)
    return origins, directions, vertices[faces], incident


def crack_rate(impl, variant, mesh, shift, dtype, inside, device):
    """Rays of ``edge_and_vertex_rays`` whose first hit is not a triangle sharing the aimed
    vertex or edge (a miss, or a pass-through to the far side): (R,) bool."""
    o, d, corners, incident = edge_and_vertex_rays(mesh, shift, dtype, inside)
    o, d, corners = o.to(device), d.to(device), corners.to(device)
    tri = corners[None]
    t, u, v = checked(
        intersect(
            impl, variant, o[:, None], d[:, None], tri[..., 0, :], tri[..., 1, :], tri[..., 2, :]
        ),
        variant,
        (len(o), len(corners)),
        dtype,
        device,
    )
    side = "inside" if inside else "outside"
    case = f"closed icosphere translated by {shift:g}, rays from {side}"
    no_nan(variant, case, t, u, v)
    t = t.cpu()
    first = t.amin(dim=1, keepdim=True)
    cracks = ~((t == first) & (first < INF) & incident).any(dim=1)
    return cracks, case, (o.cpu(), d.cpu())


# ---------------------------------------------------------------------------------------
# Checks shared by the four triangle kernels


def check_matches_reference(impl, variant, device):
    eps = torch.finfo(torch.float32).eps
    tris = soup(48, seed=11)
    o64, d64, _ = rays_at(tris, 160, seed=12)
    o, d, tri = (x.to(device, torch.float32) for x in (o64, d64, tris))
    v0, v1, v2 = tri[None, :, 0], tri[None, :, 1], tri[None, :, 2]
    got = checked(
        intersect(impl, variant, o[:, None], d[:, None], v0, v1, v2),
        variant,
        (160, 48),
        torch.float32,
        device,
    )
    ref = ref_triangle(o[:, None], d[:, None], v0, v1, v2, margin_eps=eps)
    assert ref[3].sum() > 60, "test set-up: too few hits in the soup"
    judged = compare_hits(variant, "160 rays x 48 random triangles, float32", got, ref, eps)
    assert judged > 0.9, f"test set-up: only {judged:.1%} of the pairs are clear-cut"
    barycentric_properties(variant, "random soup", *got, o[:, None], d[:, None], v0, v1, v2, eps)

    # Broadcasting: one ray per triangle (K, 3) x (K, 3), and one triangle for all rays.
    k = torch.arange(160) % 48
    pairs = checked(
        intersect(impl, variant, o, d, tri[k, 0], tri[k, 1], tri[k, 2]),
        variant,
        (160,),
        torch.float32,
        device,
    )
    for name, a, b in zip("tuv", pairs, got):
        assert_equal(
            a,
            b[torch.arange(160), k],
            name=f"{variant}: {name} of rays (K, 3) against "
            "triangles (K, 3) vs the same pairs from (N, 1, 3) x (1, M, 3)",
            where="ray",
        )
    single = checked(
        intersect(impl, variant, o, d, tri[5, 0], tri[5, 1], tri[5, 2]),
        variant,
        (160,),
        torch.float32,
        device,
    )
    for name, a, b in zip("tuv", single, got):
        assert_equal(
            a,
            b[:, 5],
            name=f"{variant}: {name} of rays (N, 3) against one triangle (3,)",
            where="ray",
        )

    # float64 in, float64 out, agreeing with the reference much more tightly.
    o, d, tri = (x.to(device) for x in (o64, d64, tris))
    v0, v1, v2 = tri[None, :, 0], tri[None, :, 1], tri[None, :, 2]
    got64 = checked(
        intersect(impl, variant, o[:, None], d[:, None], v0, v1, v2),
        variant,
        (160, 48),
        F64,
        device,
    )
    compare_hits(
        variant,
        "float64",
        got64,
        ref_triangle(o[:, None], d[:, None], v0, v1, v2, margin_eps=torch.finfo(F64).eps),
        torch.finfo(F64).eps,
    )

    # The same answers on the CPU and on the GPU.
    if torch.device(device).type != "cpu":
        cpu = intersect(impl, variant, *(x.cpu() for x in (o[:, None], d[:, None], v0, v1, v2)))
        for name, a, b in zip("tuv", got64, cpu):
            assert_close(
                a,
                b,
                rtol=1e-9,
                atol=1e-9,
                name=f"{variant}: {name} on {device} vs on the CPU (float64)",
                where="pair",
            )

    check_bad_input(impl, variant, device)


def check_bad_input(impl, variant, device):
    o = torch.zeros(4, 3, device=device)
    d = torch.tensor([[0.0, 0.0, 1.0]] * 4, device=device)
    v0 = torch.tensor([[0.0, 0.0, 1.0]] * 4, device=device)
    v1, v2 = (
        v0 + torch.tensor([1.0, 0, 0], device=device),
        v0 + torch.tensor([0, 1.0, 0], device=device),
    )
    if variant == "woop_unit":
        transform = impl.woop_precompute(v0, v1, v2)
        fn = impl.woop_unit
        expect_error("origins", fn, o[:, :2], d, transform, case="origins of shape (4, 2)")
        expect_error("directions", fn, o, d.long(), transform, case="int64 directions")
        expect_error("transform", fn, o, d, transform[..., :3], case="a (4, 3, 3) transform")
        expect_error(
            "directions",
            fn,
            o,
            d.double(),
            transform,
            case="float64 directions with float32 origins",
        )
        expect_error(
            ("origins", "directions", "transform"),
            fn,
            o[:3],
            d[:3],
            transform,
            case="3 rays against 4 transforms (shapes that do not broadcast)",
        )
        expect_error("v1", impl.woop_precompute, v0, v1.long(), v2, case="int64 v1")
        expect_error("v2", impl.woop_precompute, v0, v1, v2[:, :2], case="v2 of shape (4, 2)")
        return
    fn = getattr(impl, variant)
    expect_error("origins", fn, o[:, :2], d, v0, v1, v2, case="origins of shape (4, 2)")
    expect_error("v1", fn, o, d, v0, v1.long(), v2, case="int64 v1")
    expect_error(
        "directions", fn, o, d.double(), v0, v1, v2, case="float64 directions with float32 origins"
    )
    expect_error(
        ("origins", "directions", "v0", "v1", "v2"),
        fn,
        o[:3],
        d[:3],
        v0,
        v1,
        v2,
        case="3 rays against 4 triangles (shapes that do not broadcast)",
    )
    expect_error(
        "t_min",
        fn,
        o,
        d,
        v0,
        v1,
        v2,
        torch.zeros(5, device=device),
        case="t_min of shape (5,) for 4 rays",
    )
    expect_error("v0", fn, o, d, [[0.0, 0.0, 1.0]] * 4, v1, v2, case="a list as v0")
    if torch.device(device).type != "cpu":
        expect_error("v2", fn, o, d, v0, v1, v2.cpu(), case="v2 on the CPU, the rest on the GPU")


# Exactly representable planes and rays, so "parallel" and "in the plane" hold exactly for
# every variant (the plane x = z is mirror-symmetric, so even Woop's rounded transform
# keeps it exact).
PLANE_TRIANGLES = [
    [[0.0, 0.0, 0.0], [1.0, 0.0, 1.0], [0.0, 1.0, 0.0]],
    [[0.5, 0.5, 0.5], [-0.5, 0.25, -0.5], [0.25, -0.5, 0.25]],
]
IN_PLANE_DIRECTIONS = [
    [1.0, 0.0, 1.0],
    [0.0, 1.0, 0.0],
    [0.0, 1.0, -0.0],
    [-0.0, -1.0, 0.0],
    [0.5, -0.25, 0.5],
    [-1.0, 0.75, -1.0],
]
IN_PLANE_POINTS = [
    [0.25, 0.25, 0.25],
    [0.125, 0.5, 0.125],
    [-1.0, 0.25, -1.0],
    [2.0, 0.0, 2.0],
    [0.0, -1.0, 0.0],
]


def check_degenerate_cases(impl, variant, device, dtype=torch.float32):
    def run(o, d, v0, v1, v2, t_min=0.0, t_max=INF):
        o, d, v0, v1, v2 = (torch.as_tensor(x, dtype=dtype).to(device) for x in (o, d, v0, v1, v2))
        shape = torch.broadcast_shapes(o.shape[:-1], d.shape[:-1], v0.shape[:-1])
        return checked(
            intersect(impl, variant, o, d, v0, v1, v2, t_min, t_max), variant, shape, dtype, device
        )

    tris = torch.tensor(PLANE_TRIANGLES, dtype=F64)
    dirs = torch.tensor(IN_PLANE_DIRECTIONS, dtype=F64)
    pts = torch.tensor(IN_PLANE_POINTS, dtype=F64)
    # Rays in the plane x = z (through the triangles and beside them), and parallel to it.
    o = pts[:, None, None, :].expand(-1, len(dirs), len(tris), 3)
    d = dirs[None, :, None, :].expand_as(o)
    tv = tris[None, None].expand(len(pts), len(dirs), -1, -1, -1)
    expect_misses(
        variant,
        "rays lying in the triangle's plane",
        *run(o, d, tv[..., 0, :], tv[..., 1, :], tv[..., 2, :]),
    )
    offset = torch.tensor([0.0, 0.0, 0.5], dtype=F64)
    expect_misses(
        variant,
        "rays parallel to the triangle's plane",
        *run(o + offset, d, tv[..., 0, :], tv[..., 1, :], tv[..., 2, :]),
    )

    # Zero-area triangles: collinear corners, a repeated corner, a point.
    degenerate = torch.tensor(
        [
            [[0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [2.0, 2.0, 2.0]],
            [[0.2, 0.3, 0.0], [0.2, 0.3, 0.0], [1.0, 0.0, 0.0]],
            [[0.2, 0.3, 0.0], [1.0, 0.0, 0.0], [1.0, 0.0, 0.0]],
            [[0.5, 0.5, 0.5], [0.5, 0.5, 0.5], [0.5, 0.5, 0.5]],
        ],
        dtype=F64,
    )
    aims = torch.stack(
        [
            degenerate[:, 0],
            degenerate[:, 1],
            degenerate.mean(dim=1),
            0.3 * degenerate[:, 0] + 0.7 * degenerate[:, 2],
        ],
        dim=1,
    )  # (4, 4, 3)
    starts = torch.tensor([[0.1, -0.7, -2.0], [3.0, 0.2, 0.5], [-0.4, 2.0, 1.5]], dtype=F64)
    o = starts[:, None, None, :].expand(-1, 4, 4, 3)
    d = aims[None] - o
    tv = degenerate[None, :, None].expand(3, -1, 4, -1, -1)
    expect_misses(
        variant,
        "zero-area and repeated-corner triangles",
        *run(o, d, tv[..., 0, :], tv[..., 1, :], tv[..., 2, :]),
    )

    # NaN and infinite origins or directions, and zero directions, at a triangle they would hit.
    tri = torch.tensor([[0.0, 0.0, 1.0], [1.0, 0.0, 1.5], [0.0, 1.0, 2.0]], dtype=F64)
    base_o, base_d = (
        torch.tensor([0.2, 0.3, -1.0], dtype=F64),
        torch.tensor([0.01, 0.02, 1.0], dtype=F64),
    )
    bad_o, bad_d = [], []
    for value in (math.nan, INF, -INF):
        for axis in range(3):
            x = base_o.clone()
            x[axis] = value
            bad_o.append(x)
            bad_d.append(base_d)
            y = base_d.clone()
            y[axis] = value
            bad_o.append(base_o)
            bad_d.append(y)
        bad_o.append(torch.full((3,), value, dtype=F64))
        bad_d.append(torch.full((3,), value, dtype=F64))
    bad_o.append(base_o)
    bad_d.append(torch.zeros(3, dtype=F64))
    bad_o.append(base_o)
    bad_d.append(torch.tensor([0.0, -0.0, 0.0], dtype=F64))
    expect_misses(
        variant,
        "NaN, inf or zero origins and directions",
        *run(torch.stack(bad_o), torch.stack(bad_d), tri[0], tri[1], tri[2]),
    )

    # Axis-parallel rays with +0.0 and -0.0 components hit the triangle x + y + z = 1.
    corner = torch.eye(3, dtype=F64)
    zeros = [(0.0, 0.0), (0.0, -0.0), (-0.0, 0.0), (-0.0, -0.0)]
    o_list, d_list = [], []
    for axis in range(3):
        for sign in (1.0, -1.0):
            for z1, z2 in zeros:
                d = [z1, z2]
                d.insert(axis, sign)
                o = [0.25, 0.25]
                o.insert(axis, 0.5 - 1.5 * sign)
                o_list.append(o)
                d_list.append(d)
    t, u, v = run(o_list, d_list, corner[0], corner[1], corner[2])
    expected_t = torch.full((len(o_list),), 1.5, dtype=dtype)
    tol = 4 * torch.finfo(dtype).eps
    assert_close(
        t,
        expected_t,
        rtol=tol,
        name=f"{variant}: t of axis-parallel rays with +0.0/-0.0 components "
        "(each should hit x + y + z = 1 at t = 1.5)",
        where="ray",
    )
    hit_points = torch.tensor(o_list, dtype=F64) + 1.5 * torch.tensor(d_list, dtype=F64)
    assert_close(
        u,
        hit_points[:, 1],
        atol=tol,
        name=f"{variant}: u of the axis-parallel rays "
        "(the y of the hit point for corners e_x, e_y, e_z)",
        where="ray",
    )
    assert_close(
        v,
        hit_points[:, 2],
        atol=tol,
        name=f"{variant}: v of the axis-parallel rays (the z of the hit point)",
        where="ray",
    )

    # The interval is closed: t == t_min and t == t_max are hits, one ulp beyond is not.
    tri = torch.tensor([[0.0, 0.0, 2.0], [1.0, 0.0, 2.0], [0.0, 1.0, 2.0]], dtype=F64)
    o = torch.tensor([[0.25, 0.25, 0.0]] * 7, dtype=F64)
    d = torch.tensor([[0.0, 0.0, 1.0]] * 6 + [[0.0, 0.0, -1.0]], dtype=F64)
    two = torch.tensor(2.0, dtype=dtype)
    up, down = torch.nextafter(two, two + 1).item(), torch.nextafter(two, two - 1).item()
    t_min = torch.tensor([2.0, up, 0.0, 0.0, 3.0, 1.0, -INF], dtype=dtype, device=device)
    t_max = torch.tensor([INF, INF, 2.0, down, INF, 2.5, INF], dtype=dtype, device=device)
    o_under = torch.tensor([0.25, 0.25, 4.0], dtype=F64)
    o[6] = o_under
    t = run(o, d, tri[0], tri[1], tri[2], t_min, t_max)[0]
    expected = torch.tensor([2.0, INF, 2.0, INF, INF, 2.0, 2.0], dtype=dtype)
    cases = [
        "t == t_min",
        "t one ulp below t_min",
        "t == t_max",
        "t one ulp above t_max",
        "the hit nearer than t_min = 3",
        "t_min=1, t_max=2.5",
        "t_min = -inf, hit at t = 2",
    ]
    for i, case in enumerate(cases):
        assert t[i].item() == expected[i].item(), (
            f"{variant}: ray with a hit at exactly t = 2 and t_min={t_min[i].item()!r}, "
            f"t_max={t_max[i].item()!r} ({case}): expected t = {expected[i].item()}, got "
            f"{t[i].item()!r}. Hits are accepted for t in the closed interval [t_min, t_max]."
        )
    behind = run(o_under, torch.tensor([0.0, 0.0, 1.0]), tri[0], tri[1], tri[2])
    expect_misses(variant, "triangle behind the ray (t = -2, t_min = 0)", *behind)

    # The triangle is closed: rays through its corners and onto its edges hit. Every value
    # here is a short binary fraction, so any test's arithmetic is exact and u, v, 1 - u - v
    # come out exactly 0 (or 1) on the boundary: nothing for rounding to decide.
    aim_uv = torch.tensor(
        [
            [0.0, 0.0],
            [1.0, 0.0],
            [0.0, 1.0],
            [0.5, 0.0],
            [0.0, 0.5],
            [0.5, 0.5],
            [0.25, 0.75],
            [0.25, 0.25],
        ],
        dtype=F64,
    )
    aim = torch.cat([aim_uv, torch.full((len(aim_uv), 1), 2.0, dtype=F64)], dim=-1)
    slopes = torch.tensor(
        [[0.0, 0.0, 1.0], [0.0, 0.0, -1.0], [0.25, -0.5, 1.0], [-0.5, 0.25, -1.0]], dtype=F64
    )
    o_edge = (aim[:, None] - 2 * slopes[None]).reshape(-1, 3)
    d_edge = slopes[None].expand(len(aim), -1, -1).reshape(-1, 3)
    t, u, v = run(o_edge, d_edge, tri[0], tri[1], tri[2])
    no_nan(variant, "rays onto the corners and edges of a triangle", t, u, v)
    missed = t.cpu() == INF
    if missed.any():
        i = int(missed.nonzero()[0, 0])
        raise AssertionError(
            f"{variant}: {int(missed.sum())} of {len(t)} rays aimed exactly at a corner or an "
            f"edge of the triangle (0,0,2), (1,0,2), (0,1,2) miss it. First: ray {i}, origin "
            f"{o_edge[i].tolist()}, direction {d_edge[i].tolist()}, aimed at barycentrics "
            f"u, v = {aim_uv[i // len(slopes)].tolist()}. The triangle is closed: u >= 0, "
            f"v >= 0 and u + v <= 1 (areas or edge functions >= 0) include the boundary."
        )
    want_uv = aim_uv.repeat_interleave(len(slopes), dim=0)
    assert_close(
        t,
        torch.full_like(t, 2.0),
        rtol=tol,
        name=f"{variant}: t of rays onto the triangle's corners and edges",
        where="ray",
    )
    assert_close(
        u,
        want_uv[:, 0],
        atol=tol,
        name=f"{variant}: u of rays onto the triangle's corners and edges",
        where="ray",
    )
    assert_close(
        v,
        want_uv[:, 1],
        atol=tol,
        name=f"{variant}: v of rays onto the triangle's corners and edges",
        where="ray",
    )

    # Default arguments t_min = 0.0, t_max = inf: hits at t = 0 (origin on the triangle),
    # t = 1e-4 and t = 1e6 count, as with the bounds passed explicitly.
    o_def = torch.tensor(
        [
            [0.25, 0.25, 2.0],
            [0.25, 0.25, 2.0 - 2.0**-13],
            [0.25, 0.25, 2.0 - 2.0**20],
            [0.25, 0.25, 4.0],
        ],
        dtype=F64,
    )
    d_def = torch.tensor(
        [[0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [0.0, 0.0, 1.0]], dtype=F64
    )
    args = [x.to(device, dtype) for x in (o_def, d_def, tri[0], tri[1], tri[2])]
    if variant == "woop_unit":
        transform = impl.woop_precompute(*args[2:])
        defaults = impl.woop_unit(args[0], args[1], transform)
    else:
        defaults = getattr(impl, variant)(*args)
    defaults = checked(defaults, variant, (4,), dtype, device)
    explicit = run(o_def, d_def, tri[0], tri[1], tri[2], 0.0, INF)
    for name, a, b in zip("tuv", defaults, explicit):
        assert_equal(
            a,
            b,
            name=f"{variant}: {name} with the default t_min, t_max vs passing "
            "t_min=0.0, t_max=inf (hits at t = 0, 1.2e-4, 1e6 and a triangle behind "
            "the ray); the defaults must be t_min=0.0 and t_max=math.inf",
            where="ray",
        )
    assert (explicit[0].cpu()[:3] < INF).all(), (
        f"{variant}: rays hitting at t = 0 (origin on the triangle), t = 1.2e-4 and t = 1e6 with "
        f"t_min=0, t_max=inf must hit; got t = {explicit[0].cpu().tolist()}"
    )

    # Rays leaving a hit point with t_min = 1e-4 must not find the same triangle again.
    tris = soup(64, seed=21)
    o64, d64, pick = rays_at(tris, 64, seed=22)
    tris = tris[pick]
    hit_t, hit_u, hit_v, hit, _ = ref_triangle(o64, d64, tris[:, 0], tris[:, 1], tris[:, 2])
    good = hit & (hit_u > 0.05) & (hit_v > 0.05) & (1 - hit_u - hit_v > 0.05)
    assert good.sum() > 8, "test set-up: too few clean hits"
    points = (o64 + hit_t[:, None] * d64)[good].to(dtype).to(F64)
    tri = tris[good]
    normal = torch.linalg.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normal = normal / normal.norm(dim=-1, keepdim=True)
    g = generator(23)
    out = torch.randn(len(points), 3, generator=g, dtype=F64)
    out = out / out.norm(dim=-1, keepdim=True)
    out = torch.where(((out * normal).sum(-1, keepdim=True)).abs() < 0.2, normal, out)
    spawn_o = torch.cat([points, points])
    spawn_d = torch.cat([out, -out])
    tv = torch.cat([tri, tri])
    expect_misses(
        variant,
        "rays spawned from a hit point with t_min = 1e-4 (self-hits)",
        *run(spawn_o, spawn_d, tv[:, 0], tv[:, 1], tv[:, 2], 1e-4),
    )


GRAZING_COSINES = (1e-3, 1e-4, 1e-5, 1e-6, 1e-7)
GRAZING_SCENES = {"icosphere": {"level": 2}, "suzanne": {}, "bunny": {}}


@functools.cache
def grazing_case(scene: str, n: int = 1000, faces: int = 1000):
    """Rays nearly parallel to triangles of a built-in mesh, against (up to ``faces`` of) its
    triangles: float32 ``o, d`` (n, 3) and ``v0, v1, v2`` (F, 3), and the float64 reference
    (``ref_triangle`` with float32 margins) of every (ray, triangle) pair.

    Each ray is picked a triangle and an in-plane direction tilted towards the plane so that
    ``d . n_hat`` is one of ``GRAZING_COSINES``: half start beside the triangle (1e-3 to
    1e-1 of the mesh's size off its plane) and cross the plane far away (t up to ~1e7), half
    are aimed at a point of the triangle from one mesh size away."""
    mesh = load_scene(scene, device="cpu", dtype=F64, **GRAZING_SCENES[scene]).mesh
    g = generator(131)
    tris = mesh.vertices[mesh.faces].to(torch.float32).to(F64)  # the corners under test
    if len(tris) > faces:
        tris = tris[torch.randperm(len(tris), generator=g)[:faces]]
    pick = torch.randint(0, len(tris), (n,), generator=g)
    t = tris[pick]
    e1, e2 = t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]
    normal = torch.linalg.cross(e1, e2)
    normal = normal / normal.norm(dim=-1, keepdim=True)
    along = torch.randn(n, 3, generator=g, dtype=F64)
    along = along - (along * normal).sum(-1, keepdim=True) * normal
    along = along / along.norm(dim=-1, keepdim=True)
    cos = torch.tensor(GRAZING_COSINES, dtype=F64)[torch.arange(n) % len(GRAZING_COSINES)]
    side = torch.where(torch.rand(n, generator=g) < 0.5, -1.0, 1.0).to(F64)
    d = (1 - cos * cos).sqrt()[:, None] * along - (side * cos)[:, None] * normal
    b = torch.rand(n, 2, generator=g, dtype=F64)
    b = torch.where(b.sum(-1, keepdim=True) > 1, 1 - b, b)
    point = t[:, 0] + b[:, :1] * e1 + b[:, 1:] * e2
    size = (tris.reshape(-1, 3).amax(0) - tris.reshape(-1, 3).amin(0)).norm()
    height = size * 10 ** (torch.rand(n, generator=g, dtype=F64) * 2 - 3)
    beside = point + (side * height)[:, None] * normal - size * along
    aimed = point - size * d
    o = torch.where((torch.arange(n) // len(GRAZING_COSINES) % 2 == 0)[:, None], beside, aimed)
    o, d, tris = o.float(), d.float(), tris.float()
    v0, v1, v2 = tris[:, 0], tris[:, 1], tris[:, 2]
    ref = ref_triangle(
        o[:, None],
        d[:, None],
        v0[None],
        v1[None],
        v2[None],
        margin_eps=torch.finfo(torch.float32).eps,
    )
    return o, d, v0, v1, v2, ref


def check_grazing(impl, variant, device):
    """Rays at grazing angles past closed meshes: no hit (and no miss) the float64
    reference decides clearly the other way, whatever the angle."""
    eps = torch.finfo(torch.float32).eps
    for scene in GRAZING_SCENES:
        o, d, v0, v1, v2, ref = grazing_case(scene)
        got = checked(
            intersect(
                impl,
                variant,
                o[:, None].to(device),
                d[:, None].to(device),
                v0[None].to(device),
                v1[None].to(device),
                v2[None].to(device),
            ),
            variant,
            (len(o), len(v0)),
            torch.float32,
            device,
        )
        case = (
            f"{len(o)} rays at grazing angles (cos {GRAZING_COSINES[0]:g} .. "
            f"{GRAZING_COSINES[-1]:g} to a triangle's plane) past {len(v0)} triangles of "
            f"{scene}"
        )
        no_nan(variant, case, *got)
        try:
            compare_hits(variant, case, got, ref, eps)
        except AssertionError as error:
            raise AssertionError(
                f"{error} Nearly parallel rays cross a triangle's plane far away (t up to "
                f"~1e7): there the float32 differences v - p of a point test (sub-areas, edge "
                f"functions) round to the same value, the areas to 0, and 0 >= 0 passes. "
                f"Reject a hit where that rounding (about eps |v - p|^2 |n|) reaches the "
                f"triangle's own area, or use a test whose error does not grow with t."
            ) from None


def check_extremes(impl, variant, device):
    eps = torch.finfo(torch.float32).eps
    # A triangle of side 2e-4, hit at its centroid and missed two sides away.
    side = 2e-4
    base = torch.tensor([0.3, -0.2, 0.5], dtype=F64)
    tri = base + side * torch.tensor(
        [[0.0, 0.0, 0.0], [1.0, 0.0, 0.2], [0.5, math.sqrt(3) / 2, -0.1]], dtype=F64
    )
    tri = tri.float().double()
    centroid = tri.mean(dim=0)
    away = centroid + 2 * side * torch.tensor([1.0, 1.0, 0.0], dtype=F64)
    dirs = torch.tensor([[0.3, 0.2, 1.0], [-0.1, 0.05, -1.0], [1.0, 0.1, 0.4]], dtype=F64)
    dirs = dirs / dirs.norm(dim=-1, keepdim=True)
    for distance in (1.0, 10.0):
        o = torch.cat([centroid - distance * dirs, away - distance * dirs]).float()
        d = (torch.cat([centroid.expand_as(dirs), away.expand_as(dirs)]) - o.double()).float()
        t, u, v = checked(
            intersect(
                impl, variant, o.to(device), d.to(device), *(x.float().to(device) for x in tri)
            ),
            variant,
            (6,),
            torch.float32,
            device,
        )
        hit = t.cpu() < INF
        assert hit[:3].all() and not hit[3:].any(), (
            f"{variant}: a triangle of side {side:g} at distance {distance:g}: rays through its "
            f"centroid must hit and rays {2 * side:g} beside it must miss; got hits "
            f"{hit.tolist()}. A parallel test with an absolute epsilon (|det| < 1e-6) throws "
            f"away small triangles: make it relative to |d| |e1| |e2|."
        )
        assert_close(t[:3], torch.ones(3), rtol=1e-4, name=f"{variant}: t of the tiny triangle")
        assert_close(
            u[:3],
            torch.full((3,), 1 / 3),
            atol=5e-2,
            name=f"{variant}: u at the tiny triangle's centroid",
        )

    # The whole scene scaled by 1e-6 and 1e6: hits found, t accurate relative to the scale.
    mesh = icosphere(1)
    g = generator(31)
    n = 96
    start = torch.randn(n, 3, generator=g, dtype=F64)
    start = 4 * start / start.norm(dim=-1, keepdim=True)
    aim = 0.5 * (torch.rand(n, 3, generator=g, dtype=F64) - 0.5)
    for scale in (1e-6, 1e6):
        tri = (mesh.vertices[mesh.faces] * scale).float()
        o = (start * scale).float()
        d = (aim * scale - o.double()).float()
        v0, v1, v2 = (tri[None, :, k].to(device) for k in range(3))
        got = checked(
            intersect(impl, variant, o[:, None].to(device), d[:, None].to(device), v0, v1, v2),
            variant,
            (n, len(tri)),
            torch.float32,
            device,
        )
        case = f"icosphere scaled by {scale:g}"
        no_nan(variant, case, *got)
        t_near = got[0].cpu().double().amin(dim=1)
        ref = ref_triangle(o[:, None], d[:, None], v0, v1, v2)
        t_ref = torch.where(ref[3], ref[0], torch.full_like(ref[0], INF)).amin(dim=1)
        assert_fraction(
            t_near == INF,
            name=f"{variant} ({case}): rays through the sphere's centre region that miss it",
            at_most=0.02,
            where="ray",
        )
        ok = t_near < INF
        assert_close(
            t_near[ok],
            t_ref[ok],
            rtol=1e-4,
            name=f"{variant} ({case}): nearest t against float64",
            where="ray",
        )

    # Every dtype: float16/bfloat16 only for well-shaped triangles, float32/64 tightly.
    g = generator(41)
    k = 64
    corners = torch.tensor([[-1.0, -0.8, 0.1], [1.1, -0.9, -0.2], [0.1, 1.0, 0.15]], dtype=F64)
    b = 0.15 + 0.35 * torch.rand(k, 2, generator=g, dtype=F64)  # u, v in [0.15, 0.5]
    outside = torch.arange(k) % 2 == 1
    b = torch.where(outside[:, None], b - torch.tensor([0.6, 0.0], dtype=F64), b)
    aim = corners[0] + b[:, :1] * (corners[1] - corners[0]) + b[:, 1:] * (corners[2] - corners[0])
    o = torch.randn(k, 3, generator=g, dtype=F64) * 0.3 + torch.tensor([0.0, 0.0, -2.0])
    for dtype, tol in (
        (torch.float16, 2e-2),
        (torch.bfloat16, 6e-2),
        (torch.float32, 1e-5),
        (torch.float64, 1e-12),
    ):
        oo, cc = o.to(dtype), corners.to(dtype)
        dd = (aim - oo.to(F64)).to(dtype)
        t, u, v = checked(
            intersect(
                impl, variant, oo.to(device), dd.to(device), *(cc[j].to(device) for j in range(3))
            ),
            variant,
            (k,),
            dtype,
            device,
        )
        case = f"{dtype} well-shaped triangle"
        no_nan(variant, case, t, u, v)
        hit = t.cpu() < INF
        wrong = hit == outside
        if wrong.any():
            i = int(wrong.nonzero()[0, 0])
            raise AssertionError(
                f"{variant} ({case}): ray {i} aimed at barycentrics {b[i].tolist()} should "
                f"{'miss' if outside[i] else 'hit'}, got {'a hit' if hit[i] else 'a miss'}"
            )
        t_ref = ref_triangle(oo, dd, *(cc[j] for j in range(3)))[0]
        assert_close(
            t[~outside],
            t_ref[~outside],
            rtol=tol,
            name=f"{variant} ({case}): t computed in {dtype}",
            where="ray",
        )
        assert_close(
            u[~outside],
            b[~outside, 0],
            atol=max(tol, 1e-6) * 10,
            name=f"{variant} ({case}): u",
            where="ray",
        )
    del eps


def report_cracks(impl, variant, device):
    """Non-watertight variants: no crash and no NaN on a closed mesh; crack rates printed."""
    mesh = icosphere(2)
    rates = []
    for shift in (0.0, 1e5, 1e6):
        for inside in (False, True):
            cracks, case, _ = crack_rate(impl, variant, mesh, shift, torch.float32, inside, device)
            rates.append(f"{case}: {cracks.float().mean().item():.2%} pass through")
    print(f"{variant}:\n  " + "\n  ".join(rates))


# ---------------------------------------------------------------------------------------
# Task 1: the simple test


@pytest.mark.task(1)
@pytest.mark.points(1)
def test_intersect_simple_matches_float64_reference(impl, device):
    check_matches_reference(impl, "intersect_simple", device)


def check_simple_resolution_rule(impl, device):
    """Step 4's rule ``16 eps R^2 |n|_max <= n . n`` at its boundary, on slivers.

    Slivers of width ``w`` (a power of two times eps) in the plane z = 0, hit straight down
    exactly at a corner: every quantity of the rule is a power of two, so the rule decides
    exactly (equality included), whatever the evaluation order. Corners and edges have no
    positive component in some windings (``|e|_max`` takes absolute values), and one ray
    meets the corner v1, where ``R = |v0 - p|_max + max(|e1|_max, |e2|_max) = 2``."""
    for dtype in (torch.float32, F64):
        eps = torch.finfo(dtype).eps
        cases = []  # (v0, v1, v2, corner hit)
        for w in (16 * eps, 8 * eps):
            cases.append(([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, w, 0.0], 0))
            cases.append(([0.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [-0.5, -w, 0.0], 0))
            cases.append(([0.0, 0.0, 0.0], [-0.5, -w, 0.0], [-1.0, 0.0, 0.0], 0))
        for w in (64 * eps, 8 * eps):
            cases.append(([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, w, 0.0], 1))
        tv = torch.tensor([c[:3] for c in cases], dtype=F64)
        p = tv[torch.arange(len(cases)), torch.tensor([c[3] for c in cases])]
        d = torch.tensor([0.0, 0.0, -1.0], dtype=F64).expand(len(cases), 3)
        o = p - d
        # The rule, exactly (powers of two), in float64.
        e1, e2 = tv[:, 1] - tv[:, 0], tv[:, 2] - tv[:, 0]
        n = torch.linalg.cross(e1, e2)
        reach = (tv[:, 0] - p).abs().amax(-1) + torch.maximum(e1.abs().amax(-1), e2.abs().amax(-1))
        accept = 16 * eps * n.abs().amax(-1) * reach**2 <= (n * n).sum(-1)
        assert accept.any() and not accept.all(), "test set-up: both outcomes expected"
        t, u, v = checked(
            impl.intersect_simple(
                *(x.to(device, dtype) for x in (o, d, tv[:, 0], tv[:, 1], tv[:, 2]))
            ),
            "intersect_simple",
            (len(cases),),
            dtype,
            device,
        )
        no_nan("intersect_simple", "slivers at the resolution limit", t, u, v)
        hit = t.cpu() < INF
        wrong = hit != accept
        if wrong.any():
            i = int(wrong.nonzero()[0, 0])
            lhs = (16 * eps * n[i].abs().amax() * reach[i] ** 2).item()
            raise AssertionError(
                f"intersect_simple ({dtype}): a ray straight down onto the corner "
                f"{p[i].tolist()} of the sliver {tv[i].tolist()} gives R = {reach[i].item()}, "
                f"16 eps R^2 |n|_max = {lhs:.6g} and n . n = {(n[i] * n[i]).sum().item():.6g}: "
                f"step 4 says {'accept (<=, equality included)' if accept[i] else 'reject'}, "
                f"you report {'a hit' if hit[i] else 'a miss'}. R = |v0 - p|_max + "
                f"max(|e1|_max, |e2|_max) with |x|_max = x.abs().amax(-1) (absolute values), "
                f"eps = torch.finfo(dtype).eps, the factor 16 exactly."
            )


@pytest.mark.task(1)
@pytest.mark.points(1)
def test_intersect_simple_degenerate_and_interval_cases(impl, device):
    check_degenerate_cases(impl, "intersect_simple", device)
    check_simple_resolution_rule(impl, device)


@pytest.mark.task(1)
@pytest.mark.points(1)
def test_intersect_simple_extremes(impl, device):
    check_extremes(impl, "intersect_simple", device)
    check_grazing(impl, "intersect_simple", device)
    report_cracks(impl, "intersect_simple", device)


# ---------------------------------------------------------------------------------------
# Task 2: Möller–Trumbore


@pytest.mark.task(2)
@pytest.mark.points(1)
def test_moller_trumbore_matches_float64_reference(impl, device):
    check_matches_reference(impl, "moller_trumbore", device)


def check_relative_parallel_test(impl, device):
    """Möller–Trumbore's parallel test is relative: rays with ``|det|`` far below
    ``eps |d| |e1| |e2|`` miss, rays far above it that cross the triangle hit. The corners
    and directions are short binary fractions, so ``det`` (= the tilt ``dz``) and the rest
    are exact in any evaluation order; e1 has no positive component in one winding."""
    corners = torch.tensor(
        [
            [[1.0, 0.0, 0.0], [0.0, 0.0, 0.0], [1.0, 1.0, 0.0]],
            [[1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 0.0, 0.0]],
        ],
        dtype=F64,
    )
    # |d|_max = 0.5, so a tilt of eps / 2 is exactly at the threshold (parallel: <=) and
    # one of eps just above it; every direction with y = -0.25 and a negative tilt has no
    # positive component.
    eps = torch.finfo(torch.float32).eps
    tilts = [2.0**-40, 2.0**-34, 2.0**-8, eps / 2, eps]
    d = torch.tensor(
        [[-0.5, y, s * tilt] for y in (0.25, -0.25) for s in (1, -1) for tilt in tilts],
        dtype=F64,
    )
    target = torch.tensor([0.75, 0.5, 0.0], dtype=F64)  # inside both, crossed at t = 1
    o = target - d
    o, d = o[:, None].expand(-1, 2, -1), d[:, None].expand(-1, 2, -1)
    tv = corners[None].expand(len(d), -1, -1, -1)
    e1, e2 = tv[..., 1, :] - tv[..., 0, :], tv[..., 2, :] - tv[..., 0, :]
    det = (e1 * torch.linalg.cross(d, e2)).sum(-1)
    relative = det.abs() / (d.abs().amax(-1) * e1.abs().amax(-1) * e2.abs().amax(-1))
    parallel = relative <= eps
    exact = (relative == eps) | (relative == 2 * eps)  # powers of two: decided exactly
    assert bool((exact | (relative < 1e-2 * eps) | (relative > 1e3 * eps)).all()), (
        "test set-up: ambiguous tilt"
    )
    t, u, v = checked(
        impl.moller_trumbore(
            *(
                x.to(device, torch.float32)
                for x in (o, d, tv[..., 0, :], tv[..., 1, :], tv[..., 2, :])
            )
        ),
        "moller_trumbore",
        (len(d), 2),
        torch.float32,
        device,
    )
    no_nan("moller_trumbore", "rays parallel to the plane to within rounding", t, u, v)
    hit = t.cpu() < INF
    wrong = hit == parallel
    if wrong.any():
        i = tuple(wrong.nonzero()[0].tolist())
        raise AssertionError(
            f"moller_trumbore: ray {i} with direction {d[i].tolist()} against the triangle "
            f"{tv[i].tolist()} has |det| = {relative[i].item():.6g} |d| |e1| |e2| (max-norms), "
            f"{'at or below' if parallel[i] else 'above'} eps = {eps:.3g}: it must "
            f"{'miss (parallel to within rounding)' if parallel[i] else 'hit at t = 1'}, got "
            f"{'a hit' if hit[i] else 'a miss'}. Reject |det| <= eps * |d| |e1| |e2| with "
            f"max-norms (equality is parallel), |x|_max = x.abs().amax(-1) (the absolute "
            f"values, whatever the signs)."
        )


@pytest.mark.task(2)
@pytest.mark.points(1)
def test_moller_trumbore_degenerate_and_interval_cases(impl, device):
    check_degenerate_cases(impl, "moller_trumbore", device)
    check_relative_parallel_test(impl, device)


@pytest.mark.task(2)
@pytest.mark.points(1)
def test_moller_trumbore_extremes(impl, device):
    check_extremes(impl, "moller_trumbore", device)
    check_grazing(impl, "moller_trumbore", device)
    report_cracks(impl, "moller_trumbore", device)


# ---------------------------------------------------------------------------------------
# Task 3: Woop's unit-triangle test


@pytest.mark.task(3)
@pytest.mark.points(1)
def test_woop_precompute_maps_to_unit_triangle(impl, device):
    tris = soup(32, seed=51)
    for dtype, tol in ((torch.float32, 1e-5), (F64, 1e-13)):
        tri = tris.to(device, dtype)
        transform = check_tensor(
            impl.woop_precompute(tri[:, 0], tri[:, 1], tri[:, 2]),
            "woop_precompute(v0, v1, v2)",
            shape=(32, 3, 4),
            dtype=dtype,
            device=device,
        )
        m = transform.cpu().double()
        exact = tri.cpu().double()
        corners = torch.cat([exact, torch.ones(32, 3, 1, dtype=F64)], dim=-1)  # homogeneous
        mapped = torch.einsum("fij,fkj->fki", m, corners)
        # Each row rounds like |r_i| |x| + |c_i|.
        scale = (
            m[..., :3].abs().sum(-1, keepdim=True) * exact.abs().amax((1, 2))[:, None, None]
            + m[..., 3:].abs()
        ).transpose(1, 2)
        unit = torch.tensor([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], dtype=F64)
        assert_close(
            (mapped - unit) / scale,
            torch.zeros_like(mapped),
            atol=tol,
            name=f"woop_precompute ({dtype}): the transform applied to (v0, v1, v2) "
            "should give (0,0,0), (1,0,0), (0,1,0) (error relative to the "
            "row's magnitude)",
            where="(triangle, corner, axis)",
        )
        normal = torch.linalg.cross(exact[:, 1] - exact[:, 0], exact[:, 2] - exact[:, 0])
        n_mapped = torch.einsum("fij,fj->fi", m[..., :3], normal)
        row = m[..., :3].abs().sum(-1) * normal.abs().amax(-1, keepdim=True)
        assert_close(
            n_mapped[:, :2] / row[:, :2],
            torch.zeros(32, 2, dtype=F64),
            atol=tol,
            name=f"woop_precompute ({dtype}): the normal must map onto the z axis "
            "(x and y of the mapped normal)",
            where="(triangle, axis)",
        )
        assert (n_mapped[:, 2] > 0).all(), (
            "woop_precompute: the normal e1 x e2 must map to +z (a positive z component), so "
            "that the map keeps orientation"
        )
    # Degenerate triangles get a transform that every ray misses, and no exception.
    flat = torch.tensor(
        [
            [[0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [2.0, 2.0, 2.0]],
            [[0.2, 0.3, 0.0], [0.2, 0.3, 0.0], [1.0, 0.0, 0.0]],
        ],
        device=device,
    )
    transform = check_tensor(
        impl.woop_precompute(flat[:, 0], flat[:, 1], flat[:, 2]),
        "woop_precompute of degenerate triangles",
        shape=(2, 3, 4),
        dtype=torch.float32,
        device=device,
    )
    o = torch.tensor([[0.5, 1.0, -1.0], [0.25, 0.25, -1.0]], device=device)
    d = torch.tensor([[0.5, 0.0, 1.5], [0.0, 0.05, 1.0]], device=device)
    expect_misses(
        "woop_unit",
        "degenerate triangles' transforms",
        *impl.woop_unit(o[:, None], d[:, None], transform[None]),
    )
    # Corners with inf or NaN coordinates: no NaN in the transform either, and every ray
    # misses (e1 x e2 may be inf there, |e1 x e2| > 0, and the rows inf / inf = NaN).
    bad = torch.tensor(
        [
            [[0.0, 0.0, 0.0], [INF, 0.0, 0.0], [1.0, 1.0, 1.0]],
            [[0.0, 0.0, 1.0], [1.0, 0.0, 1.0], [0.0, -INF, 1.0]],
            [[0.0, 0.0, 1.0], [1.0, 0.0, 1.0], [0.0, math.nan, 1.0]],
            [[0.0, 0.0, 1.0], [1.0, 0.0, 1.0], [0.0, 1.0, 1.0]],  # a good one
        ],
        device=device,
    )
    transform = check_tensor(
        impl.woop_precompute(bad[:, 0], bad[:, 1], bad[:, 2]),
        "woop_precompute of triangles with inf/NaN corners",
        shape=(4, 3, 4),
        dtype=torch.float32,
        device=device,
    ).cpu()
    alone = impl.woop_precompute(bad[3:, 0], bad[3:, 1], bad[3:, 2]).cpu()
    assert_close(
        transform[3],
        alone[0],
        rtol=1e-6,
        atol=1e-6,
        name="woop_precompute: a good triangle batched with inf/NaN ones must get the same "
        "transform as alone (each triangle's transform depends on its own corners only)",
        where="(row, column)",
    )
    transform = transform[:3]
    nan = torch.isnan(transform)
    if nan.any():
        k = int(nan.nonzero()[0, 0])
        raise AssertionError(
            f"woop_precompute: the transform of triangle {bad[k].cpu().tolist()} contains "
            f"{int(nan[k].sum())} NaN values: {transform[k].tolist()}. Non-finite input gives "
            f"misses, never NaN outputs: give a triangle whose transform is not finite the "
            f"zero transform too, as a degenerate one."
        )
    o = torch.tensor([[0.25, 0.25, -1.0], [0.3, 0.1, -1.0]], device=device)
    d = torch.tensor([[0.0, 0.0, 1.0], [0.1, 0.05, 1.0]], device=device)
    expect_misses(
        "woop_unit",
        "transforms of triangles with inf/NaN corners",
        *impl.woop_unit(o[:, None], d[:, None], transform.to(device)[None]),
    )
    check_bad_input(impl, "woop_unit", device)


@pytest.mark.task(3)
@pytest.mark.points(1)
def test_woop_unit_matches_float64_reference(impl, device):
    check_matches_reference(impl, "woop_unit", device)


@pytest.mark.task(3)
@pytest.mark.points(0.5)
def test_woop_unit_degenerate_and_interval_cases(impl, device):
    check_degenerate_cases(impl, "woop_unit", device)


@pytest.mark.task(3)
@pytest.mark.points(0.5)
def test_woop_unit_extremes(impl, device):
    check_extremes(impl, "woop_unit", device)
    check_grazing(impl, "woop_unit", device)
    report_cracks(impl, "woop_unit", device)


# ---------------------------------------------------------------------------------------
# Task 4: watertight


@pytest.mark.task(4)
@pytest.mark.points(0.5)
def test_watertight_matches_float64_reference(impl, device):
    check_matches_reference(impl, "watertight", device)


@pytest.mark.task(4)
@pytest.mark.points(0.5)
def test_watertight_degenerate_and_interval_cases(impl, device):
    check_degenerate_cases(impl, "watertight", device)
    check_degenerate_cases(impl, "watertight", device, dtype=F64)


@pytest.mark.task(4)
@pytest.mark.points(0.5)
def test_watertight_extremes(impl, device):
    check_extremes(impl, "watertight", device)
    check_grazing(impl, "watertight", device)


@pytest.mark.task(4)
@pytest.mark.points(1)
@pytest.mark.parametrize("shift", [0.0, 1e5, 1e6])
def test_watertight_has_no_cracks_on_a_closed_mesh(impl, device, shift):
    mesh = icosphere(2)
    for inside in (False, True):
        cracks, case, (o, d) = crack_rate(
            impl, "watertight", mesh, shift, torch.float32, inside, device
        )
        if cracks.any():
            i = int(cracks.nonzero()[0, 0])
            raise AssertionError(
                f"watertight ({case}): {int(cracks.sum())} of {len(cracks)} rays through shared "
                f"edges and vertices pass through a crack: their first hit is not one of the "
                f"triangles sharing the aimed edge or vertex. First: ray {i}, origin "
                f"{o[i].tolist()}, direction {d[i].tolist()}. Compute the edge functions from "
                f"the sheared vertices exactly as the paper does, so a shared edge gives both "
                f"triangles the same value with opposite signs; treat 0 as neither sign."
            )


def axis_rays_near_edges(n: int, seed: int):
    """Triangles and axis-parallel rays that pass within rounding distance of an edge.

    In the sheared frame of an axis-parallel ray the 2D coordinates are the vertices' own,
    so the float64 signs of U, V, W (exact products of floats) decide exactly. The edge BC
    is built to pass through the ray almost exactly (U nearly 0), A lies clearly on one side.
    Returns o, d, v0, v1, v2 (float32, (n, 3)) and the exact decision (bool, (n,)).
    """
    g = generator(seed)
    by = torch.rand(n, generator=g) + 0.5
    cy = -(torch.rand(n, generator=g) + 0.5)
    bx = torch.rand(n, generator=g) * 2 - 1
    cx = (cy.double() * bx.double() / by.double()).float()
    side = torch.where(torch.rand(n, generator=g) < 0.5, -1.0, 1.0)
    normal = torch.stack([by - cy, cx - bx], dim=-1)
    normal = normal / normal.norm(dim=-1, keepdim=True)
    a2 = (
        side[:, None] * (0.5 + torch.rand(n, 1, generator=g)) * normal
        + 0.3 * (torch.rand(n, 2, generator=g) - 0.5)
    ).float()
    flat = [a2, torch.stack([bx, by], -1), torch.stack([cx, cy], -1)]
    A, B, C = (p.double() for p in flat)
    U = C[:, 0] * B[:, 1] - C[:, 1] * B[:, 0]
    V = A[:, 0] * C[:, 1] - A[:, 1] * C[:, 0]
    W = B[:, 0] * A[:, 1] - B[:, 1] * A[:, 0]
    signs = torch.stack([U.sign(), V.sign(), W.sign()], -1)
    inside = ~((signs < 0).any(-1) & (signs > 0).any(-1)) & (signs != 0).any(-1)
    depth = torch.rand(n, 3, generator=g) + 1.0
    # The ray runs along axis k in direction s (with a -0.0 in the other components half the
    # time); the triangle's 2D coordinates go to the two other axes in cyclic order.
    k = torch.arange(n) % 3
    s = torch.where(torch.arange(n) % 6 < 3, 1.0, -1.0)
    zero = torch.where(torch.arange(n) % 4 < 2, 0.0, -0.0)
    o = torch.zeros(n, 3)
    d = zero[:, None].expand(n, 3).clone()
    vs = [torch.zeros(n, 3) for _ in range(3)]
    rows = torch.arange(n)
    d[rows, k] = s
    o[rows, k] = -3.0 * s
    for p, vtx, z in zip(flat, vs, depth.T):
        vtx[rows, (k + 1) % 3] = p[:, 0]
        vtx[rows, (k + 2) % 3] = p[:, 1]
        vtx[rows, k] = z * s
    return o, d, vs[0], vs[1], vs[2], inside, U


@pytest.mark.task(4)
@pytest.mark.points(0.5)
def test_watertight_decides_exactly_near_edges(impl, device):
    o, d, v0, v1, v2, inside, U = axis_rays_near_edges(3000, seed=61)
    products_equal = (v2[:, 0] * v1[:, 1] == v2[:, 1] * v1[:, 0]) & (U != 0)
    # Rotate the corners (v0, v1, v2) -> (v1, v2, v0) or (v2, v0, v1) for a third of the rays
    # each: the edge near the ray becomes the one of W or V, the exact decision is the same.
    turn = (torch.arange(len(o)) // 3) % 3
    corners = torch.stack([v0, v1, v2], 1)
    corners = corners[torch.arange(len(o))[:, None], (torch.arange(3) + turn[:, None]) % 3]
    v0, v1, v2 = corners.unbind(1)
    t, u, v = checked(
        impl.watertight(*(x.to(device) for x in (o, d, v0, v1, v2))),
        "watertight",
        (len(o),),
        torch.float32,
        device,
    )
    no_nan("watertight", "axis-parallel rays grazing an edge", t, u, v)
    hit = t.cpu() < INF
    wrong = hit != inside
    if wrong.any():
        i = int(wrong.nonzero()[0, 0])
        raise AssertionError(
            f"watertight: {int(wrong.sum())} of {len(o)} axis-parallel rays passing within "
            f"rounding distance of an edge are decided wrongly (exact answer from float64 edge "
            f"functions). First: ray {i} should {'hit' if inside[i] else 'miss'}; its edge "
            f"function {'UWV'[int(turn[i])]} is exactly {U[i].item():.3g} in float64 but the two "
            f"float32 products "
            f"{'round to the same value' if products_equal[i] else 'differ'}. When U, V or W "
            f"comes out exactly 0.0, recompute all three in float64 (the double fallback)."
        )
    assert products_equal.sum() > 20, "test set-up: too few rays with equal rounded products"


@pytest.mark.slow
@pytest.mark.task(4)
@pytest.mark.parametrize(
    "dtype,shift",
    [
        (torch.float16, 0.0),
        (torch.bfloat16, 0.0),
        (torch.float32, 0.0),
        (torch.float32, 1e6),
        (F64, 0.0),
        (F64, 1e6),
    ],
)
def test_watertight_has_no_cracks_on_a_finer_mesh(impl, device, dtype, shift):
    """Ungraded: icosphere level 3 in every dtype (bfloat16 only near the origin: at 1e3
    its 8-bit mantissa collapses the sphere onto a handful of grid points)."""
    mesh = icosphere(3)
    for inside in (False, True):
        cracks, case, _ = crack_rate(impl, "watertight", mesh, shift, dtype, inside, device)
        assert not cracks.any(), (
            f"watertight ({case}, {dtype}): {int(cracks.sum())} of "
            f"{len(cracks)} rays through shared edges and vertices crack"
        )


# ---------------------------------------------------------------------------------------
# Task 5: boxes and spheres


def ref_box(o, d, lo, hi, t_min=0.0, t_max=INF):
    """Per-axis slabs in float64 with the zero-direction case spelled out."""
    o, d, lo, hi = (x.detach().to("cpu", F64) for x in (o, d, lo, hi))
    zero = d == 0
    t0, t1 = (lo - o) / d, (hi - o) / d
    near = torch.where(zero, torch.where((lo <= o) & (o <= hi), -INF, INF), torch.minimum(t0, t1))
    far = torch.where(zero, torch.where((lo <= o) & (o <= hi), INF, -INF), torch.maximum(t0, t1))
    near = torch.maximum(torch.as_tensor(t_min, dtype=F64), near.amax(-1))
    far = torch.minimum(torch.as_tensor(t_max, dtype=F64), far.amin(-1))
    return near, far, near <= far


def box_case(n: int, seed: int):
    """Random boxes (some flat along an axis) and rays, some starting exactly on a slab plane
    with a zero (+0.0 or -0.0) direction component along that axis. float32."""
    g = generator(seed)
    lo = torch.rand(n, 3, generator=g) * 2 - 1
    size = torch.rand(n, 3, generator=g)
    size = torch.where(torch.rand(n, 3, generator=g) < 0.1, torch.zeros_like(size), size)
    hi = lo + size
    o = torch.rand(n, 3, generator=g) * 4 - 2
    d = torch.randn(n, 3, generator=g)
    zero = torch.rand(n, 3, generator=g) < 0.3
    sign = torch.where(torch.rand(n, 3, generator=g) < 0.5, 0.0, -0.0)
    d = torch.where(zero, sign, d)
    on_plane = zero & (torch.rand(n, 3, generator=g) < 0.5)
    o = torch.where(on_plane, torch.where(torch.rand(n, 3, generator=g) < 0.5, lo, hi), o)
    # A third of the rays start inside their box.
    inner = lo + size * torch.rand(n, 3, generator=g)
    o = torch.where((torch.arange(n) % 3 == 0)[:, None] & ~on_plane, inner, o)
    return o, d, lo, hi


def box_hint(o, d, lo, hi) -> str:
    """What a wrong ``ray_box`` decision most likely got wrong, for one ray (CPU tensors)."""
    zero = d == 0
    on_plane = zero & ((o == lo) | (o == hi))
    outside = zero & ((o < lo) | (o > hi))
    if outside.any():
        axis = int(outside.nonzero()[0, 0])
        return (
            f"Its direction is 0 on axis {axis}, where the origin lies outside the slab: "
            f"1/d = inf puts that slab at infinity, so t_near = inf (or t_far = -inf). With "
            f"t_max = inf, t_near = t_far = inf passes t_near <= t_far: also require "
            f"t_near < inf."
        )
    if on_plane.any():
        axis = int(on_plane.nonzero()[0, 0])
        return (
            f"It starts on a slab plane of axis {axis} with d = 0 there: 0 * inf = NaN for "
            f"that slab, which must drop out of the max/min (torch.fmax/fmin), not poison "
            f"it."
        )
    return (
        "Intersect the three slabs [min(t0, t1), max(t0, t1)] with [t_min, t_max]; a hit "
        "needs t_near <= t_far."
    )


@pytest.mark.task(5)
@pytest.mark.points(1)
def test_ray_box_matches_slabs(impl, device):
    d = torch.tensor([[0.0, -0.0, 2.0], [-0.0, 0.5, -4.0], [INF, 1.0, -1.0]], device=device)
    inv = check_tensor(
        impl.safe_reciprocal(d),
        "safe_reciprocal(d)",
        shape=(3, 3),
        dtype=torch.float32,
        device=device,
    ).cpu()
    expected = torch.tensor([[INF, -INF, 0.5], [-INF, 2.0, -0.25], [0.0, 1.0, -1.0]])
    assert_equal(
        inv, expected, name="safe_reciprocal: 1/+0 = +inf, 1/-0 = -inf, 1/x", where="(ray, axis)"
    )

    n = 600
    o, d, lo, hi = box_case(n, seed=71)
    inv_d = impl.safe_reciprocal(d.to(device))
    t_min = torch.where(torch.arange(n) % 5 == 0, 0.3, 0.0).to(device)
    t_max = torch.where(torch.arange(n) % 7 == 0, 1.5, INF).to(device)
    result = impl.ray_box(o.to(device), inv_d, lo.to(device), hi.to(device), t_min, t_max)
    assert isinstance(result, tuple) and len(result) == 3, "ray_box: return (t_near, t_far, hit)"
    near = (
        check_tensor(result[0], "ray_box t_near", shape=(n,), dtype=torch.float32, device=device)
        .cpu()
        .double()
    )
    far = (
        check_tensor(result[1], "ray_box t_far", shape=(n,), dtype=torch.float32, device=device)
        .cpu()
        .double()
    )
    hit = check_tensor(result[2], "ray_box hit", shape=(n,), dtype=torch.bool, device=device).cpu()
    r_near, r_far, r_hit = ref_box(o, d, lo, hi, t_min.cpu(), t_max.cpu())
    clear = (r_far - r_near).abs() > 1e-5 * (r_near.abs() + r_far.abs()).nan_to_num(0, 1, 1) + 1e-6
    wrong = (hit != r_hit) & (clear | r_hit)
    if wrong.any():
        i = int(wrong.nonzero()[0, 0])

        def vec(x):
            return "(" + ", ".join(f"{c:.4g}" for c in x.tolist()) + ")"

        raise AssertionError(
            f"ray_box: {int(wrong.sum())} of {n} rays decided wrongly: ray {i} should "
            f"{'hit' if r_hit[i] else 'miss'}, you report {'a hit' if hit[i] else 'a miss'}. "
            f"{box_hint(o[i], d[i], lo[i], hi[i])} Ray {i}: origin {vec(o[i])}, direction "
            f"{vec(d[i])}, box {vec(lo[i])}..{vec(hi[i])}, t in [{t_min[i].item()}, "
            f"{t_max[i].item()}]: the slabs give [{r_near[i].item():.6g}, "
            f"{r_far[i].item():.6g}], you computed [{near[i].item():.6g}, {far[i].item():.6g}]."
        )
    for name, got, want in (("t_near", near, r_near), ("t_far", far, r_far)):
        bad = torch.isnan(got) & hit
        if bad.any():
            i = int(bad.nonzero()[0, 0])
            raise AssertionError(
                f"ray_box: {name} is NaN for {int(bad.sum())} hits; first ray "
                f"{i}, origin {o[i].tolist()}, direction {d[i].tolist()}"
            )
        assert_close(
            got[hit], want[hit], rtol=1e-5, atol=1e-5, name=f"ray_box: {name} of hits", where="hit"
        )
    assert (near[hit] >= t_min.cpu()[hit]).all() and (far[hit] <= t_max.cpu()[hit]).all(), (
        "ray_box: [t_near, t_far] must be clipped to [t_min, t_max]"
    )

    # NaN/inf rays and empty boxes never hit.
    o2 = torch.tensor([[math.nan, 0.0, 0.0], [0.0, 0.0, 0.0], [INF, 0.5, 0.5], [0.5, 0.5, -2.0]])
    d2 = torch.tensor([[1.0, 0.0, 0.0], [math.nan, 1.0, 1.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    box_lo = torch.tensor([[-1.0] * 3] * 3 + [[1.0, 1.0, 1.0]])
    box_hi = torch.tensor([[1.0] * 3] * 3 + [[0.0, 0.0, 0.0]])
    _, _, hit2 = impl.ray_box(
        o2.to(device), impl.safe_reciprocal(d2.to(device)), box_lo.to(device), box_hi.to(device)
    )
    assert not hit2.cpu().any(), (
        f"ray_box: NaN origin, NaN direction, infinite origin and an empty box (min > max) must "
        f"all miss; got hits {hit2.cpu().tolist()}"
    )
    # An infinite direction component (inv_direction 0) from inside the box misses too,
    # and with the default t_min = 0 a ray starting inside the box has t_near = 0.
    o3 = torch.tensor([[0.0, 0.0, 0.0], [0.0, 0.0, 0.0]], device=device)
    d3 = torch.tensor([[INF, 0.5, 0.5], [1.0, 0.5, -0.25]], device=device)
    near3, _, hit3 = impl.ray_box(
        o3, impl.safe_reciprocal(d3), -torch.ones_like(o3), torch.ones_like(o3)
    )
    assert hit3.cpu().tolist() == [False, True], (
        f"ray_box: from the centre of the box [-1, 1]^3, the direction (inf, 0.5, 0.5) "
        f"(inv_directions (0, 2, 2)) must miss (every |inv_direction| > 0) and "
        f"(1, 0.5, -0.25) must hit; got hits {hit3.cpu().tolist()}"
    )
    assert near3.cpu()[1].item() == 0.0, (
        f"ray_box: a ray starting inside the box with the default t_min = 0 has t_near = 0, "
        f"got {near3.cpu()[1].item()!r}"
    )
    expect_error(
        "box_min",
        impl.ray_box,
        o.to(device),
        inv_d,
        lo[:, :2].to(device),
        hi.to(device),
        case="box_min of shape (N, 2)",
    )
    expect_error(
        "inv_directions",
        impl.ray_box,
        o.to(device),
        inv_d.long(),
        lo.to(device),
        hi.to(device),
        case="int64 inv_directions",
    )


@pytest.mark.task(5)
@pytest.mark.points(1)
def test_ray_box_is_conservative(impl, device):
    """Rays aimed exactly at box edges and corners: whenever the exact slab test (float64
    from the same float32 inputs) hits, the float32 test must hit too."""
    g = generator(81)
    n = 2000
    lo = torch.rand(n, 3, generator=g, dtype=F64) * 2 - 1
    hi = lo + 0.05 + torch.rand(n, 3, generator=g, dtype=F64)
    # Points on edges (two coordinates at a bound) and corners (three).
    pick = torch.rand(n, 3, generator=g) < 0.5
    target = lo + (hi - lo) * torch.rand(n, 3, generator=g, dtype=F64)
    bound = torch.where(pick, lo, hi)
    free = torch.randint(0, 4, (n,), generator=g)  # axis 3: a corner
    mask = torch.arange(3)[None, :] != free[:, None]
    target = torch.where(mask, bound, target)
    distance = 10.0 ** (torch.rand(n, 1, generator=g, dtype=F64) * 4 - 1)
    o = target + distance * torch.randn(n, 3, generator=g, dtype=F64)
    lo32, hi32, o32 = lo.float(), hi.float(), o.float()
    d32 = (target - o32.double()).float()
    near, far, hit = impl.ray_box(
        o32.to(device), impl.safe_reciprocal(d32.to(device)), lo32.to(device), hi32.to(device)
    )
    hit = hit.cpu()
    r_near, r_far, r_hit = ref_box(o32, d32, lo32, hi32)
    lost = r_hit & ~hit
    if lost.any():
        i = int(lost.nonzero()[0, 0])
        raise AssertionError(
            f"ray_box: {int(lost.sum())} of {int(r_hit.sum())} rays that touch their box (exact "
            f"slab interval [{r_near[i].item():.9g}, {r_far[i].item():.9g}] for ray {i}) are "
            f"reported as misses (you computed [{near[i].item():.9g}, {far[i].item():.9g}]). "
            f"Rounding can make t_near > t_far by a few ulp: scale t_far by 1 + 2 gamma(3) "
            f"(Ize 2013) so the test is conservative."
        )
    assert r_hit.sum() > n // 4, "test set-up: too few touching rays"


def ref_sphere(o, d, center, radius, t_min=0.0, t_max=INF):
    o, d, center = (x.detach().to("cpu", F64) for x in (o, d, center))
    r = torch.as_tensor(radius).to("cpu", F64)
    f = o - center
    a = (d * d).sum(-1)
    b = (f * d).sum(-1)
    c = (f * f).sum(-1) - r * r
    perp = f - (b / a)[..., None] * d
    disc = a * (r * r - (perp * perp).sum(-1))
    root = disc.clamp(min=0).sqrt()
    t0, t1 = (-b - root) / a, (-b + root) / a
    near_ok = (disc >= 0) & (t0 >= t_min) & (t0 <= t_max)
    far_ok = (disc >= 0) & (t1 >= t_min) & (t1 <= t_max)
    del c
    return torch.where(near_ok, t0, torch.where(far_ok, t1, torch.full_like(t0, INF))), disc


@pytest.mark.task(5)
@pytest.mark.points(1)
def test_ray_sphere_matches_float64(impl, device):
    g = generator(91)
    n = 500
    center = torch.rand(n, 3, generator=g, dtype=F64) * 4 - 2
    radius = 0.1 + torch.rand(n, generator=g, dtype=F64)
    o = torch.rand(n, 3, generator=g, dtype=F64) * 6 - 3
    # Half the rays start inside their sphere; directions not normalised.
    o = torch.where(
        (torch.arange(n) % 2 == 0)[:, None],
        center + 0.5 * radius[:, None] * (torch.rand(n, 3, generator=g, dtype=F64) - 0.5),
        o,
    )
    d = torch.randn(n, 3, generator=g, dtype=F64) * (0.5 + torch.rand(n, 1, generator=g, dtype=F64))
    aim = center + 1.3 * radius[:, None] * (torch.rand(n, 3, generator=g, dtype=F64) - 0.5)
    d = torch.where((torch.arange(n) % 4 == 1)[:, None], aim - o, d)
    o32, d32, c32, r32 = o.float(), d.float(), center.float(), radius.float()
    t_max = torch.where(torch.arange(n) % 6 == 5, 0.5, INF).float()
    t = check_tensor(
        impl.ray_sphere(
            o32.to(device), d32.to(device), c32.to(device), r32.to(device), 0.0, t_max.to(device)
        ),
        "ray_sphere(...)",
        shape=(n,),
        dtype=torch.float32,
        device=device,
    ).cpu()
    t_ref, disc = ref_sphere(o32, d32, c32, r32, 0.0, t_max)
    a = (d32.double() ** 2).sum(-1)
    clear = (
        (disc.abs() > 1e-4 * a * r32.double() ** 2)
        & ((t_ref - t_max).abs() > 1e-4)
        & (t_ref.abs() > 1e-4)
    )
    wrong = (t.isinf() != t_ref.isinf()) & clear
    if wrong.any():
        i = int(wrong.nonzero()[0, 0])
        raise AssertionError(
            f"ray_sphere: {int(wrong.sum())} of {n} rays decided wrongly; first ray {i}: origin "
            f"{o32[i].tolist()}, direction {d32[i].tolist()}, sphere {c32[i].tolist()} r="
            f"{r32[i].item():.6g}, t_max={t_max[i].item()}: expected t={t_ref[i].item():.7g}, "
            f"got {t[i].item():.7g}. Return the nearest root inside [t_min, t_max] (the far root "
            f"when the origin is inside)."
        )
    both = t.isfinite() & t_ref.isfinite() & clear
    assert_close(
        t[both], t_ref[both], rtol=1e-5, atol=1e-6, name="ray_sphere: t of hits", where="hit"
    )
    assert not torch.isnan(t).any(), "ray_sphere: NaN in t (misses must be inf)"

    # Exact roots at t = 4 and 6; the closed interval; one shared sphere (radius a number).
    o1 = torch.zeros(10, 3, device=device)
    d1 = torch.tensor([[0.0, 0.0, 1.0]] * 10, device=device)
    four, six = torch.tensor(4.0), torch.tensor(6.0)
    above4, below6 = torch.nextafter(four, four + 1).item(), torch.nextafter(six, six - 1).item()
    t_lo = torch.tensor(
        [0.0, 4.0, above4, 0.0, 0.0, 7.0, 5.0, 5.0, 6.0, torch.nextafter(six, six + 1).item()],
        device=device,
    )
    t_hi = torch.tensor(
        [INF, INF, INF, 4.0, torch.nextafter(four, four - 1).item(), INF, 6.0, below6, 6.0, INF],
        device=device,
    )
    t1 = impl.ray_sphere(o1, d1, torch.tensor([0.0, 0.0, 5.0], device=device), 1.0, t_lo, t_hi)
    assert_equal(
        t1,
        torch.tensor([4.0, 4.0, 6.0, 4.0, INF, INF, 6.0, INF, 6.0, INF]),
        name="ray_sphere: sphere at z=5, r=1 hit from the origin (roots 4 and 6) with "
        "t_min/t_max [0,inf], [4,inf], [4+ulp,inf], [0,4], [0,4-ulp], [7,inf], "
        "[5,6], [5,6-ulp], [6,6], [6+ulp,inf] (the interval is closed for the far "
        "root too)",
        where="ray",
    )

    # Default arguments t_min = 0.0, t_max = inf: the same as passing them. Origins on the
    # sphere (a root at t = 0: inward and outward) and 2^-11, 2^-13 before it, and 1e6 away.
    o3 = torch.tensor(
        [
            [0.0, 0.0, 4.0],
            [0.0, 0.0, 6.0],
            [0.0, 0.0, 4.0 - 2.0**-11],
            [0.0, 0.0, 4.0 - 2.0**-13],
            [0.0, 0.0, 5.0 - 1e6],
        ],
        device=device,
    )
    d3 = torch.tensor([[0.0, 0.0, 1.0]] * 5, device=device)
    c3 = torch.tensor([0.0, 0.0, 5.0], device=device)
    defaults = check_tensor(
        impl.ray_sphere(o3, d3, c3, 1.0),
        "ray_sphere(o, d, center, 1.0)",
        shape=(5,),
        dtype=torch.float32,
        device=device,
    )
    explicit = impl.ray_sphere(o3, d3, c3, 1.0, 0.0, INF)
    assert_equal(
        defaults,
        explicit,
        name="ray_sphere: t with the default t_min, t_max vs "
        "passing t_min=0.0, t_max=inf (origins on a sphere, 1.2e-4 to 4.9e-4 before it "
        "and 1e6 away); the defaults must be t_min=0.0 and t_max=math.inf",
        where="ray",
    )
    t_ref3, _ = ref_sphere(o3, d3, c3, 1.0)
    assert_close(
        defaults,
        t_ref3,
        rtol=1e-5,
        atol=1e-6,
        name="ray_sphere with the default "
        "t_min = 0: a root at t = 0 (origin on the sphere) or just beyond is the hit",
        where="ray",
    )

    # NaN/inf/zero rays and a sphere behind the ray miss without NaN.
    o2 = torch.tensor(
        [[math.nan, 0, 0], [0, 0, 0], [INF, 0, 0], [0, 0, 0], [0, 0, 10.0]], device=device
    )
    d2 = torch.tensor(
        [[0, 0, 1.0], [0, math.nan, 1], [0, 0, 1], [0, 0, 0], [0, 0, 1]], device=device
    )
    t2 = impl.ray_sphere(o2, d2, torch.tensor([0.0, 0.0, 5.0], device=device), 1.0)
    assert_equal(
        t2,
        torch.full((5,), INF),
        name="ray_sphere: NaN origin, NaN direction, infinite "
        "origin, zero direction and a sphere behind the ray all miss",
        where="ray",
    )
    expect_error(
        "center",
        impl.ray_sphere,
        o1,
        d1,
        torch.zeros(2, device=device),
        1.0,
        case="center of shape (2,)",
    )
    expect_error(
        "radius",
        impl.ray_sphere,
        o1,
        d1,
        torch.zeros(3, device=device),
        torch.ones(6, dtype=torch.int64, device=device),
        case="int64 radius",
    )


@pytest.mark.task(5)
@pytest.mark.points(1)
def test_ray_sphere_small_and_far(impl, device):
    g = generator(101)
    n = 400
    for distance, radius in ((1e3, 1.0), (1e4, 1.0), (10.0, 1e-3)):
        axis = torch.randn(n, 3, generator=g, dtype=F64)
        axis = axis / axis.norm(dim=-1, keepdim=True)
        side = torch.linalg.cross(axis, torch.randn(n, 3, generator=g, dtype=F64))
        side = side / side.norm(dim=-1, keepdim=True)
        offset = 0.95 * radius * torch.rand(n, 1, generator=g, dtype=F64)
        center = (distance * axis).float()
        o = torch.zeros(n, 3)
        d = (center.double() + offset * side).float()
        d = d / d.norm(dim=-1, keepdim=True)
        t = impl.ray_sphere(o.to(device), d.to(device), center.to(device), radius).cpu()
        t_ref, _ = ref_sphere(o, d, center, radius)
        case = f"sphere of radius {radius:g} at distance {distance:g} (float32)"
        assert t_ref.isfinite().all(), "test set-up: every ray should hit"
        assert_fraction(
            ~t.isfinite(),
            name=f"ray_sphere ({case}): rays through the sphere that miss",
            at_most=0.0,
            where="ray",
        )
        assert_close(
            t,
            t_ref,
            rtol=2e-6,
            name=f"ray_sphere ({case}): t against float64. The "
            "discriminant b^2 - ac cancels here; use a (r^2 - |f - (b/a) d|^2)",
            where="ray",
        )

    # Rays spawned on the surface with t_min = 1e-4: outward rays miss, inward rays exit.
    axis = torch.randn(n, 3, generator=g, dtype=F64)
    axis = axis / axis.norm(dim=-1, keepdim=True)
    center = torch.tensor([3.0, -2.0, 1.0], dtype=F64)
    points = (center + 2.0 * axis).float()
    out = axis + 0.5 * torch.randn(n, 3, generator=g, dtype=F64)
    out = torch.where(((out * axis).sum(-1, keepdim=True)) < 0.2, axis, out).float()
    c32 = center.float().to(device)
    t_out = impl.ray_sphere(points.to(device), out.to(device), c32, 2.0, 1e-4).cpu()
    assert_equal(
        t_out,
        torch.full((n,), INF),
        name="ray_sphere: outward rays spawned on the surface with t_min = 1e-4 (self-hits)",
        where="ray",
    )
    t_in = impl.ray_sphere(points.to(device), (-out).to(device), c32, 2.0, 1e-4).cpu()
    t_ref, _ = ref_sphere(points, -out, center.float(), 2.0, 1e-4)
    assert_close(
        t_in,
        t_ref,
        rtol=1e-5,
        name="ray_sphere: inward rays spawned on the surface "
        "with t_min = 1e-4 must find the far side",
        where="ray",
    )


# ---------------------------------------------------------------------------------------
# Task 6: closest hit


def ref_closest(o, d, tris, t_min, t_max, eps):
    """Nearest hit per ray in float64, and which rays are clear-cut: no pair that a float
    test may decide either way competes with the nearest hit, and no two hits tie closely."""
    t, u, v, hit, judged = ref_triangle(
        o[:, None],
        d[:, None],
        tris[None, :, 0],
        tris[None, :, 1],
        tris[None, :, 2],
        t_min[:, None],
        t_max[:, None],
        margin_eps=eps,
    )
    t_hit = torch.where(hit, t, torch.full_like(t, INF))
    best = t_hit.amin(dim=1)
    cols = torch.arange(t.shape[1]).expand_as(t)
    index = torch.where((t_hit == best[:, None]) & hit, cols, t.shape[1]).amin(dim=1)
    index = torch.where(best < INF, index, -1)
    slack = 1e-3 * (1 + t.abs())
    competing = (
        ~judged
        & ~(t > best[:, None] + slack)
        & ~(t < t_min[:, None] - slack)
        & ~(t > t_max[:, None] + slack)
    )
    second = torch.where(cols == index[:, None], INF, t_hit).amin(dim=1)
    duplicate = (second == best) & (best < INF)  # exact copies: the lower index wins
    clear = ~competing.any(dim=1) & (
        ((second - best) > 1e-4 * (1 + best.abs())) | duplicate | (best == INF)
    )
    safe = index.clamp(min=0)[:, None]
    return best, index, u.gather(1, safe)[:, 0], v.gather(1, safe)[:, 0], clear


def given_moller_trumbore(origins, directions, v0, v1, v2, t_min=0.0, t_max=math.inf):
    """Möller–Trumbore with the relative parallel test (task 2), given: in place of the lab's
    own while closest_hit (task 6) is graded, so a mistake in task 2 costs task 2 only.
    Broadcast shapes as the lab's kernels; returns (t, u, v), (inf, 0, 0) for a miss."""
    e1, e2 = v1 - v0, v2 - v0
    p = torch.linalg.cross(
        directions.expand(torch.broadcast_shapes(directions.shape, e2.shape)), e2
    )
    det = (e1 * p).sum(-1)
    scale = directions.abs().amax(-1) * e1.abs().amax(-1) * e2.abs().amax(-1)
    s = origins - v0
    q = torch.linalg.cross(s.expand(torch.broadcast_shapes(s.shape, e1.shape)), e1)
    u, v, t = (s * p).sum(-1) / det, (directions * q).sum(-1) / det, (e2 * q).sum(-1) / det
    hit = (
        (det.abs() > torch.finfo(det.dtype).eps * scale)
        & (u >= 0)
        & (v >= 0)
        & (u + v <= 1)
        & (t >= t_min)
        & (t <= t_max)
    )
    inf, zero = t.new_tensor(INF), t.new_tensor(0.0)
    return torch.where(hit, t, inf), torch.where(hit, u, zero), torch.where(hit, v, zero)


def closest_hit_given_kernel(lab, rays, mesh, *args, **kwargs):
    """``lab.closest_hit`` next to the lab with the given Möller–Trumbore in place of the
    lab's (its default variant, task 2): task 6 is graded on its own."""
    with replaced(lab, {"moller_trumbore": given_moller_trumbore}):
        return lab.closest_hit(rays, mesh, *args, **kwargs)


def closest(impl, rays, mesh, *args, **kwargs):
    """The lab's closest_hit on the given Möller–Trumbore (``closest_hit_given_kernel``)."""
    return impl.probe(closest_hit_given_kernel, rays, mesh, *args, **kwargs)


def implemented_variants(impl) -> list[str]:
    """The other triangle kernels the submission has done: closest_hit's tests run the
    default variant on a given Möller–Trumbore (task 2) and try the lab's other variants only
    where they exist, so task 6 is graded on its own."""
    one = torch.tensor([[0.25, 0.25, -1.0]]), torch.tensor([[0.0, 0.0, 1.0]])
    tri = torch.eye(3)[:, None, :]
    done = []
    for variant in TRIANGLE_KERNELS:
        if variant == "moller_trumbore":
            continue  # the given one, through the default variant
        try:
            intersect(impl, variant, *one, tri[0], tri[1], tri[2])
        except NotImplementedError:
            continue
        done.append(variant)
    return done


def check_hits(hits, n, dtype, device, case):
    assert isinstance(hits, Hits), (
        f"closest_hit ({case}): expected a course.core.types.Hits, got {type(hits).__name__}"
    )
    check_tensor(hits.t, "Hits.t", shape=(n,), dtype=dtype, device=device)
    check_tensor(hits.triangle, "Hits.triangle", shape=(n,), dtype=torch.int64, device=device)
    check_tensor(hits.u, "Hits.u", shape=(n,), dtype=dtype, device=device)
    check_tensor(hits.v, "Hits.v", shape=(n,), dtype=dtype, device=device)


def compare_closest(hits, ref, case, where="ray"):
    best, index, u, v, clear = ref
    got_t, got_i = hits.t.cpu().double(), hits.triangle.cpu()
    wrong = (got_i != index) & clear
    if wrong.any():
        i = int(wrong.nonzero()[0, 0])
        raise AssertionError(
            f"closest_hit ({case}): {int(wrong.sum())} of {int(clear.sum())} clear-cut rays "
            f"report the wrong triangle. First: ray {i} should hit triangle {index[i].item()} at "
            f"t={best[i].item():.7g}, got triangle {got_i[i].item()} at t={got_t[i].item():.7g}. "
            f"Keep the *nearest* hit over all chunks, and add each chunk's offset to its local "
            f"triangle index."
        )
    hit = clear & (index >= 0)
    assert_close(got_t[hit], best[hit], rtol=1e-4, name=f"closest_hit ({case}): t", where=where)
    assert_close(hits.u.cpu()[hit], u[hit], atol=1e-2, name=f"closest_hit ({case}): u", where=where)
    assert_close(hits.v.cpu()[hit], v[hit], atol=1e-2, name=f"closest_hit ({case}): v", where=where)
    miss = clear & (index < 0)
    assert (got_t[miss] == INF).all() and (hits.u.cpu()[miss] == 0).all(), (
        f"closest_hit ({case}): misses must have t = inf, triangle = -1, u = v = 0"
    )


def soup_scene(n_tris, n_rays, seed, device):
    tris = soup(n_tris, seed)
    # Two exact duplicates appended: ties must go to the lower index.
    tris = torch.cat([tris, tris[[3, 7]]])
    o, d, _ = rays_at(tris, n_rays, seed + 1)
    d = torch.cat([d[:-2], tris[[3, 7]].mean(dim=1) - o[-2:]])  # hit the duplicates
    g = generator(seed + 2)
    t_max = torch.where(torch.rand(n_rays, generator=g) < 0.1, 0.8, INF).double()
    t_min = torch.where(torch.rand(n_rays, generator=g) < 0.1, 0.5, 0.0).double()
    mesh = Mesh(
        vertices=tris.reshape(-1, 3).float().to(device),
        faces=torch.arange(3 * len(tris)).reshape(-1, 3).to(device),
    )
    rays = Rays(
        origins=o.float().to(device),
        directions=d.float().to(device),
        t_min=t_min.float().to(device),
        t_max=t_max.float().to(device),
    )
    ref = ref_closest(
        rays.origins.cpu(),
        rays.directions.cpu(),
        mesh.triangles().cpu(),
        rays.t_min.cpu(),
        rays.t_max.cpu(),
        torch.finfo(torch.float32).eps,
    )
    return rays, mesh, ref


@pytest.mark.task(6)
@pytest.mark.points(1)
def test_closest_hit_matches_reference(impl, device):
    rays, mesh, ref = soup_scene(120, 200, seed=111, device=device)
    hits = closest(impl, rays, mesh)
    check_hits(hits, len(rays), torch.float32, device, "default variant")
    compare_closest(hits, ref, "120 random triangles + 2 duplicates, 200 rays")
    assert ref[4].float().mean() > 0.85, "test set-up: too few clear-cut rays"
    tie = hits.triangle.cpu()[-2:].tolist()
    assert tie == [3, 7], (
        f"closest_hit: the last two rays hit triangles 3 and 7, which have exact duplicates at "
        f"the end of the mesh (equal t): ties go to the lowest index, expected [3, 7], got {tie}"
    )
    for variant in implemented_variants(impl):
        hits = impl.closest_hit(rays, mesh, variant)
        check_hits(hits, len(rays), torch.float32, device, variant)
        compare_closest(hits, ref, f"variant={variant!r}")


def probe_largest_tensor(lab, rays, mesh, variant, budget):
    """Run closest_hit (on the given Möller–Trumbore) and report the largest tensor (bytes)
    any op created, and the hits."""
    from torch.utils._python_dispatch import TorchDispatchMode

    class Largest(TorchDispatchMode):
        largest = 0

        def __torch_dispatch__(self, func, types, args=(), kwargs=None):
            out = func(*args, **(kwargs or {}))
            for x in out if isinstance(out, (tuple, list)) else [out]:
                if isinstance(x, torch.Tensor):
                    Largest.largest = max(Largest.largest, x.numel() * x.element_size())
            return out

    with replaced(lab, {"moller_trumbore": given_moller_trumbore}), Largest():
        hits = lab.closest_hit(rays, mesh, variant, budget)
    return Largest.largest, hits


@pytest.mark.task(6)
@pytest.mark.points(1)
def test_closest_hit_respects_memory_budget(impl, device):
    rays, mesh, ref = soup_scene(60, 48, seed=121, device=device)
    full = closest(impl, rays, mesh, "moller_trumbore")
    # 2 KiB: a few triangles at a time for one ray; 128 KiB: all triangles, a few rays.
    for budget in (2**11, 2**17):
        largest, hits = impl.probe(probe_largest_tensor, rays, mesh, "moller_trumbore", budget)
        check_hits(hits, len(rays), torch.float32, device, f"budget {budget}")
        pairs = len(rays) * mesh.num_faces * 4
        per_triangle = 16 * mesh.num_faces * 4  # the mesh's own arrays may be whole
        assert largest <= max(budget, per_triangle), (
            f"closest_hit with memory_budget_bytes={budget}: an op created a tensor of "
            f"{largest} bytes (all {len(rays)} x {mesh.num_faces} pairs take {pairs} bytes per "
            f"float). Work in chunks of rays and triangles sized from the budget."
        )
        for name in ("t", "triangle", "u", "v"):
            assert_equal(
                getattr(hits, name),
                getattr(full, name),
                name=f"closest_hit: Hits.{name} with a {budget}-byte budget vs the "
                "default budget (chunking must not change the answer)",
                where="ray",
            )
        compare_closest(hits, ref, f"budget {budget}")


@pytest.mark.task(6)
@pytest.mark.points(1)
def test_closest_hit_closed_mesh_and_errors(impl, device):
    # From inside a closed sphere every ray hits exactly once.
    mesh64 = icosphere(2)
    mesh = Mesh(vertices=mesh64.vertices.float().to(device), faces=mesh64.faces.to(device))
    g = generator(131)
    d = torch.randn(150, 3, generator=g)
    d = d / d.norm(dim=-1, keepdim=True)
    rays = Rays.create(torch.zeros(3, device=device), d.to(device))
    ref = ref_closest(
        rays.origins.cpu(),
        rays.directions.cpu(),
        mesh.triangles().cpu(),
        rays.t_min.cpu(),
        rays.t_max.cpu(),
        torch.finfo(torch.float32).eps,
    )
    for variant in ["moller_trumbore", *implemented_variants(impl)]:
        hits = (
            closest(impl, rays, mesh)
            if variant == "moller_trumbore"
            else impl.closest_hit(rays, mesh, variant)
        )
        check_hits(hits, 150, torch.float32, device, variant)
        compare_closest(hits, ref, f"rays from the centre of a closed icosphere, {variant}")
    # t_max shorter than the radius: all miss.
    short = Rays.create(torch.zeros(3, device=device), d.to(device), t_max=0.5)
    hits = closest(impl, short, mesh)
    assert_equal(
        hits.triangle,
        torch.full((150,), -1),
        name="closest_hit: rays with t_max = 0.5 inside a unit sphere must miss (triangle -1)",
        where="ray",
    )
    assert_equal(hits.t, torch.full((150,), INF), name="closest_hit: t of misses", where="ray")
    assert_equal(hits.u, torch.zeros(150), name="closest_hit: u of misses", where="ray")
    # Bad input.
    expect_error("variant", impl.closest_hit, rays, mesh, "moller", case="variant='moller'")
    expect_error(
        "mesh",
        impl.closest_hit,
        rays,
        Mesh(vertices=mesh.vertices.double(), faces=mesh.faces),
        case="a float64 mesh with float32 rays",
    )
    expect_error(
        "rays",
        impl.closest_hit,
        (rays.origins, rays.directions),
        mesh,
        case="a tuple instead of Rays",
    )
    expect_error(
        "memory_budget_bytes",
        impl.closest_hit,
        rays,
        mesh,
        "watertight",
        0,
        case="memory_budget_bytes=0",
    )


# ---------------------------------------------------------------------------------------
# Task 7: accounting


def accounting_args(lab, variant):
    """The documented accounting case: one ray against one triangle, float32, CPU."""
    o = torch.tensor([[0.25, 0.2, -1.0]])
    d = torch.tensor([[0.1, 0.05, 1.0]])
    v0, v1, v2 = (
        torch.tensor([[0.0, 0.0, 0.0]]),
        torch.tensor([[1.0, 0.0, 0.0]]),
        torch.tensor([[0.0, 1.0, 0.0]]),
    )
    if variant == "woop_unit":
        return o, d, lab.woop_precompute(v0, v1, v2)
    return o, d, v0, v1, v2


def probe_accounting(lab, variant):
    """course.measure.accounting run on the lab's own kernel, next to it."""
    args = accounting_args(lab, variant)
    counts = count_ops(getattr(lab, variant), *args, lanes=1)
    live = live_values(getattr(lab, variant), *args, lanes=1)
    return {
        **{
            k: getattr(counts, k)
            for k in ("mul", "add", "div", "sqrt", "fma", "compare", "abs", "select", "other")
        },
        "cycles_bound": counts.cycles_bound(),
        "peak_last_use": live.peak_last_use,
    }


LECTURE_MUL = {"intersect_simple": 39, "moller_trumbore": 23, "woop_unit": 20}


@pytest.mark.task(7)
@pytest.mark.points(1)
def test_op_counts(impl):
    counts = {}
    for variant in TRIANGLE_KERNELS:
        got = impl.op_counts(variant)
        assert isinstance(got, dict), f"op_counts({variant!r}): expected a dict, got {type(got)}"
        want = impl.probe(probe_accounting, variant)
        for key in ("mul", "add", "div", "sqrt", "fma", "compare", "cycles_bound"):
            assert key in got, f"op_counts({variant!r}): missing key {key!r} (got {sorted(got)})"
            assert abs(got[key] - want[key]) < 1e-9, (
                f"op_counts({variant!r})[{key!r}] = {got[key]}, but "
                f"course.measure.accounting.count_ops on your {variant} for the documented "
                f"ray and triangle gives {want[key]}"
            )
        counts[variant] = got
    expect_error("variant", impl.op_counts, "nope", case="an unknown variant name")
    for variant, lecture in LECTURE_MUL.items():
        mul = counts[variant]["mul"]
        assert lecture / 3 <= mul <= 3 * lecture, (
            f"op_counts({variant!r}): {mul} multiplies per test, the lecture counts {lecture}: "
            f"more than a factor 3 apart, so the kernel does much more (or less) than the "
            f"algorithm needs"
        )
    assert counts["moller_trumbore"]["mul"] < counts["intersect_simple"]["mul"], (
        "Möller–Trumbore should need fewer multiplies than the plane + area test"
    )
    assert counts["woop_unit"]["mul"] <= counts["moller_trumbore"]["mul"], (
        "Woop's unit test (with the transform precomputed) should need no more multiplies "
        "than Möller–Trumbore"
    )


@pytest.mark.task(7)
@pytest.mark.points(1)
def test_register_estimate_and_occupancy(impl):
    for variant in TRIANGLE_KERNELS:
        got = impl.register_estimate(variant)
        want = math.ceil(impl.probe(probe_accounting, variant)["peak_last_use"])
        assert got == want, (
            f"register_estimate({variant!r}) = {got!r}, but "
            f"course.measure.accounting.live_values on your {variant} gives peak_last_use "
            f"rounded up = {want}"
        )
        assert 8 <= got <= 128, f"register_estimate({variant!r}) = {got}: implausible"
        for arch, block in (("g80", 64), ("hopper_h100", 256)):
            occ = impl.occupancy_for(variant, arch, block)
            expected = occupancy(PRESETS[arch], got, block)
            assert (
                occ.blocks_per_sm == expected.blocks_per_sm
                and occ.occupancy == expected.occupancy
                and occ.regs_per_thread == got
            ), (
                f"occupancy_for({variant!r}, {arch!r}, {block}): expected "
                f"{expected.blocks_per_sm} blocks/SM, occupancy {expected.occupancy:.3f} "
                f"for {got} registers, got {occ.blocks_per_sm} blocks/SM, occupancy "
                f"{occ.occupancy:.3f} ({occ.regs_per_thread} registers)"
            )
        default = impl.occupancy_for(variant)
        expected = occupancy(PRESETS["g80"], got, 64)
        assert (default.blocks_per_sm, default.occupancy) == (
            expected.blocks_per_sm,
            expected.occupancy,
        ), (
            f"occupancy_for({variant!r}) with the defaults (arch 'g80', block_size 64): "
            f"expected {expected.blocks_per_sm} blocks/SM, occupancy {expected.occupancy:.3f}, "
            f"got {default.blocks_per_sm} blocks/SM, occupancy {default.occupancy:.3f}"
        )
    expect_error("variant", impl.register_estimate, "nope", case="an unknown variant name")
    expect_error("variant", impl.occupancy_for, "nope", case="an unknown variant name")
