"""Grader for Lab 6: a compute rasterizer.

References are computed here, never stored: exact integer edge functions with the top-left
rule (written from its geometric definition, not from the lab's formulation) on vertices
placed on a 1/16-pixel grid, where float32 arithmetic is exact too; exact minima by sorting;
and a brute-force float64 closest-hit tracer (Möller–Trumbore) for everything in 3D. The
tracers handed to the lab are module-level functions of this file (``trace_suzanne`` ...),
each building its scene itself, so they also run inside the sandboxed worker.

Each task is graded on its own: ``rasterize`` runs with the given ``coverage`` and
``bounding_boxes`` of this module in place of the lab's (task 2), and the tests of tasks 4
and 5 start from the reference's visibility buffer and clipped triangles (the ``reference``
fixture). Only the last task (``END_TO_END``) runs the lab's whole pipeline.

What each extreme must survive:

=====================================  ==================================================
case                                   asserted
=====================================  ==================================================
edges through pixel centres (grids,    every pixel covered exactly once; each triangle's
fans), a jittered full-screen mesh     pixels equal the exact top-left reference
triangles crossing / behind the near   clipped to z + w >= 0; the union on screen equals
plane                                  the float64 ray/plane reference
huge triangles (1e6 px), sub-pixel     box clamped, no allocation beyond the budget or
ones, NaN/inf, zero area, empty scene  the screen; 0 or 1 pixels; nothing; nothing
coplanar duplicates                    exact depth ties go to the lowest id
triangle order, chunking               bit-identical visibility buffers
perspective-correct barycentrics       within 2e-4 of the exact ray/plane point (screen-
                                       space weights are off by ~0.1 on a slanted plane)
raster vs ray-traced primary           >= 99.5% equal ids, every other pixel explained
visibility (Suzanne, also 1e5 away,    (within 1e-4 of an edge, or a tie); fp32 and fp64
fp32/fp64, 24-bit depth)               rasters agree on >= 99.5%
hybrid shadows                         >= 98% of pixels agree with float64 shadows; the
                                       shadowed fraction matches fully traced shadows
CPU vs CUDA                            bit-identical id buffers
=====================================  ==================================================
"""

from __future__ import annotations

import dataclasses
import functools
import math
from pathlib import Path

import pytest
import torch

from course.core.camera import Camera, primary_rays
from course.core.files import import_file, lab_source
from course.core.scenes import load_scene
from course.core.types import Hits, Mesh
from course.given.lab6 import BYTES_PER_FRAGMENT
from course.grading.testing import (
    assert_close,
    assert_equal,
    assert_fraction,
    assert_image_close,
    check_tensor,
    expect_error,
    generator,
    image_mismatch,
    poisoned,
    replaced,
)

LAB_MODULE = "lab6_raster"
TASKS = {
    1: "MVP transform and near-plane clipping",
    2: "Edge functions and the fill rule",
    3: "Packed depth|id keys and atomic-min visibility",
    4: "Perspective-correct interpolation and shading",
    5: "Raster vs ray-traced visibility, hybrid shadows",
    6: "End to end: your whole pipeline against ray tracing",
}
END_TO_END = 6  # the one task graded on the lab's own chain; every other task on its own

F64 = torch.float64
EMPTY = torch.iinfo(torch.int64).max
MASK = (1 << 32) - 1


# ---------------------------------------------------------------------------------------
# Calling the lab


def fragments(impl, screen, width, height, cull=False, device="cpu"):
    """``coverage`` checked for types and shapes; returns CPU tensors."""
    result = impl.coverage(screen, width, height, cull)
    assert isinstance(result, tuple) and len(result) == 3, (
        "coverage: expected a tuple (triangle, pixel, bary)"
    )
    triangle, pixel, bary = result
    check_tensor(
        triangle, "coverage(...)[0] (triangle)", shape=(None,), dtype=torch.int64, device=device
    )
    n = triangle.shape[0]
    check_tensor(pixel, "coverage(...)[1] (pixel)", shape=(n,), dtype=torch.int64, device=device)
    check_tensor(bary, "coverage(...)[2] (bary)", shape=(n, 3), dtype=screen.dtype, device=device)
    return triangle.cpu(), pixel.cpu(), bary.cpu()


@pytest.fixture
def reference(request, impl):
    """The reference lab module (trusted, run here) for the results of earlier tasks that a
    task builds on (a visibility buffer, a clipped screen), so each task is graded on its
    own. In the student handout, which has no solutions/, it is the lab itself: there an
    early mistake can also show in a later task's tests."""
    path = lab_source(Path(request.config.rootpath) / "solutions", LAB_MODULE)
    return import_file(path, f"reference_{LAB_MODULE}") if path is not None else impl


def reference_raster(reference, mesh: Mesh, camera: Camera):
    """Tasks 1-3 by the reference: (keys, screen, source, weights) on the mesh's device."""
    mvp = camera.view_projection(F64).to(mesh.device)
    clip = reference.to_clip_space(mesh.vertices, mvp)
    clipped, source, weights = reference.clip_triangles(clip[mesh.faces])
    screen = reference.to_screen(clipped, camera.width, camera.height)
    return reference.rasterize(screen, camera.width, camera.height), screen, source, weights


def pipeline(impl, mesh: Mesh, camera: Camera, **kwargs):
    """``rasterize_mesh`` checked: (face (H, W), bary (H, W, 3)) on the CPU."""
    result = impl.rasterize_mesh(mesh, camera, **kwargs)
    assert isinstance(result, tuple) and len(result) == 2, (
        "rasterize_mesh: expected a tuple (face, bary)"
    )
    shape = (camera.height, camera.width)
    face = check_tensor(
        result[0],
        "rasterize_mesh(...)[0] (face)",
        shape=shape,
        dtype=torch.int64,
        device=mesh.device,
    )
    bary = check_tensor(
        result[1],
        "rasterize_mesh(...)[1] (bary)",
        shape=(*shape, 3),
        dtype=mesh.dtype,
        device=mesh.device,
    )
    return face.cpu(), bary.cpu()


def screen_triangles(impl, vertices, faces, camera: Camera, device):
    """Task 1 end to end: (clipped, source, weights, screen) on the CPU."""
    mvp = camera.view_projection(F64).to(device)
    clip = impl.to_clip_space(vertices.to(device), mvp)
    result = impl.clip_triangles(clip[faces.to(device)])
    assert isinstance(result, tuple) and len(result) == 3, (
        "clip_triangles: expected a tuple (clipped, source, weights)"
    )
    clipped, source, weights = result
    check_tensor(
        clipped, "clip_triangles(...)[0]", shape=(None, 3, 4), dtype=vertices.dtype, device=device
    )
    k = clipped.shape[0]
    check_tensor(source, "clip_triangles(...)[1]", shape=(k,), dtype=torch.int64, device=device)
    check_tensor(
        weights, "clip_triangles(...)[2]", shape=(k, 3, 3), dtype=vertices.dtype, device=device
    )
    screen = check_tensor(
        impl.to_screen(clipped, camera.width, camera.height),
        "to_screen(...)",
        shape=(k, 3, 4),
        dtype=vertices.dtype,
        device=device,
    )
    return clipped.cpu(), source.cpu(), weights.cpu(), screen.cpu()


# ---------------------------------------------------------------------------------------
# Exact 2D references


def exact_coverage(tris, width, height):
    """(K, H*W) bool: pixel centres inside each triangle by the top-left rule, exactly.

    tris: (K, 3, 2) float64 on a 1/16-pixel grid (scaled by 16 they are integers, like the
    pixel centres). Edge functions in int64; the rule from its definition: a centre on an
    edge counts when the edge is a *top* edge (horizontal, the triangle below it, y down) or
    a *left* edge (not horizontal, the triangle to its right)."""
    q = torch.round(tris * 16).to(torch.int64)
    assert torch.equal(q.double() / 16, tris), "test set-up: vertices off the 1/16 grid"
    rows, cols = torch.meshgrid(torch.arange(height), torch.arange(width), indexing="ij")
    px, py = (cols.reshape(-1) * 16 + 8), (rows.reshape(-1) * 16 + 8)

    def edge(a, b, x, y):
        return (x - a[..., 0]) * (b[..., 1] - a[..., 1]) - (y - a[..., 1]) * (b[..., 0] - a[..., 0])

    v = [q[:, i, None, :] for i in range(3)]
    area = edge(q[:, 1], q[:, 2], q[:, 0, 0], q[:, 0, 1])
    sign = torch.sign(area)[:, None]
    inside = (area != 0)[:, None].expand(-1, width * height).clone()
    for i in range(3):
        a, b, c = v[(i + 1) % 3], v[(i + 2) % 3], v[i]
        e = edge(a, b, px[None], py[None]) * sign
        flat = a[..., 1] == b[..., 1]
        top = flat & (c[..., 1] > a[..., 1])
        left = ~flat & (edge(a, b, c[..., 0], c[..., 1]) * (b[..., 1] - a[..., 1]) > 0)
        inside &= (e > 0) | ((e == 0) & (top | left))
    return inside


def coverage_matrix(triangle, pixel, k, n_pixels):
    m = torch.zeros(k, n_pixels, dtype=torch.int64)
    m.index_put_((triangle, pixel), torch.ones_like(pixel), accumulate=True)
    return m


def grid_mesh(xs, ys, jitter=None, flip=None):
    """Two triangles per cell of the grid xs x ys (float64); diagonals alternate (or by
    ``flip``); ``jitter`` (len(ys), len(xs), 2) moves the vertices. (K, 3, 2), counter-
    clockwise on screen (positive area)."""
    gx, gy = torch.meshgrid(
        torch.as_tensor(xs, dtype=F64), torch.as_tensor(ys, dtype=F64), indexing="xy"
    )
    points = torch.stack([gx, gy], -1)
    if jitter is not None:
        points = points + jitter
    tris = []
    for j in range(len(ys) - 1):
        for i in range(len(xs) - 1):
            a, b = points[j, i], points[j, i + 1]  # top-left, top-right
            c, d = points[j + 1, i], points[j + 1, i + 1]  # bottom-left, bottom-right
            if (i + j) % 2 if flip is None else flip:
                tris += [torch.stack([a, c, d]), torch.stack([a, d, b])]
            else:
                tris += [torch.stack([a, c, b]), torch.stack([b, c, d])]
    return torch.stack(tris)


def screen4(tris2d, inv_w=1.0, z=0.0):
    """(K, 3, 4) screen triangles (x, y, z_ndc, 1/w) from (K, 3, 2) positions."""
    k = tris2d.shape[0]
    inv_w = torch.as_tensor(inv_w, dtype=tris2d.dtype).expand(k).reshape(k, 1, 1).expand(k, 3, 1)
    z = torch.as_tensor(z, dtype=tris2d.dtype).expand(k).reshape(k, 1, 1).expand(k, 3, 1)
    return torch.cat([tris2d, z, inv_w], -1)


# ---------------------------------------------------------------------------------------
# A brute-force float64 tracer and the scenes it knows


def closest_hits(tris, origins, directions, t_min, t_max, pairs_per_chunk=2**20):
    """Nearest hits by Möller–Trumbore in float64 on the CPU: (t, triangle, u, v), ties to
    the lowest index. tris (M, 3, 3); origins, directions (N, 3); t_min, t_max (N,)."""
    tris = tris.to(F64)
    o, d = origins.detach().to("cpu", F64), directions.detach().to("cpu", F64)
    lo, hi = t_min.detach().to("cpu", F64), t_max.detach().to("cpu", F64)
    n, m = o.shape[0], tris.shape[0]
    v0 = tris[:, 0]
    e1, e2 = tris[:, 1] - v0, tris[:, 2] - v0
    t_best = torch.full((n,), math.inf, dtype=F64)
    tri_best = torch.full((n,), -1, dtype=torch.int64)
    u_best, v_best = torch.zeros(n, dtype=F64), torch.zeros(n, dtype=F64)
    step = max(1, pairs_per_chunk // max(m, 1))
    E1 = [e1[None, :, i] for i in range(3)]
    E2 = [e2[None, :, i] for i in range(3)]
    shared = bool((o == o[:1]).all()) if n else False  # primary rays: one eye for all
    for s in range(0, n, step):
        D = [d[s : s + step, i, None] for i in range(3)]
        S = [(o[:1] if shared else o[s : s + step])[:, i, None] - v0[None, :, i] for i in range(3)]
        p = [D[1] * E2[2] - D[2] * E2[1], D[2] * E2[0] - D[0] * E2[2], D[0] * E2[1] - D[1] * E2[0]]
        det = E1[0] * p[0] + E1[1] * p[1] + E1[2] * p[2]
        q = [S[1] * E1[2] - S[2] * E1[1], S[2] * E1[0] - S[0] * E1[2], S[0] * E1[1] - S[1] * E1[0]]
        u = (S[0] * p[0] + S[1] * p[1] + S[2] * p[2]) / det
        v = (D[0] * q[0] + D[1] * q[1] + D[2] * q[2]) / det
        t = (E2[0] * q[0] + E2[1] * q[1] + E2[2] * q[2]) / det
        ok = (
            (det != 0)
            & (u >= 0)
            & (v >= 0)
            & (u + v <= 1)
            & (t >= lo[s : s + step, None])
            & (t <= hi[s : s + step, None])
        )
        t = torch.where(ok, t, math.inf)
        t_min_row, idx = t.min(dim=1)  # first index among equal minima
        hit = t_min_row < math.inf
        rows = torch.arange(t.shape[0])
        t_best[s : s + step] = t_min_row
        tri_best[s : s + step] = torch.where(hit, idx, -1)
        u_best[s : s + step] = torch.where(hit, u[rows, idx], 0)
        v_best[s : s + step] = torch.where(hit, v[rows, idx], 0)
    return t_best, tri_best, u_best, v_best


def ray_plane_barycentrics(tris, origins, directions):
    """Barycentrics (N, 3) and t (N,) of each ray against the plane of its own triangle
    (N, 3, 3), float64: where the ray meets the plane, not clipped to the triangle."""
    tris, o, d = (x.to(F64) for x in (tris, origins, directions))
    v0, e1, e2 = tris[:, 0], tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]
    s = o - v0
    n = torch.linalg.cross(e1, e2)
    det = -(d * n).sum(-1)
    t = (s * n).sum(-1) / det
    u = -(d * torch.linalg.cross(s, e2)).sum(-1) / det
    v = -(d * torch.linalg.cross(e1, s)).sum(-1) / det
    return torch.stack([1 - u - v, u, v], -1), t


FAR = 1e5  # the translation of the far-from-origin scene


@functools.cache
def scene(name: str) -> tuple[Mesh, Camera]:
    """A test scene as float32 geometry (the rasterized one) on the CPU, and its camera.

    suzanne: the glTF monkey (968 triangles); suzanne_far: the same translated by 1e5 (in
    float64, then rounded: that float32 geometry is the scene) with the camera moved too;
    shadow_scene: Suzanne above a ground quad."""
    base = load_scene("suzanne", device="cpu", dtype=F64)
    camera = dataclasses.replace(base.camera, width=96, height=64)
    vertices, faces = base.mesh.vertices, base.mesh.faces
    if name == "suzanne":
        return Mesh(vertices.float(), faces), camera
    if name == "suzanne_far":

        def move(p):
            return tuple(float(c + FAR) for c in p)

        return (
            Mesh((vertices + FAR).float(), faces),
            dataclasses.replace(camera, eye=move(camera.eye), target=move(camera.target)),
        )
    if name == "shadow_scene":
        z = float(vertices[:, 2].min()) - 0.05
        ground = torch.tensor(
            [[-4.0, -4.0, z], [4.0, -4.0, z], [4.0, 4.0, z], [-4.0, 4.0, z]], dtype=F64
        )
        n = vertices.shape[0]
        quad = torch.tensor([[n, n + 1, n + 2], [n, n + 2, n + 3]])
        mesh = Mesh(torch.cat([vertices, ground]).float(), torch.cat([faces, quad]))
        return mesh, dataclasses.replace(camera, width=48, height=48)
    if name == "plates":
        # Three square plates stacked along y, the middle one first (faces 0 and 1): it is
        # in the top plate's shadow and casts its own onto the ground.
        def plate(x0, x1, z0, z1, y):
            return [[x0, y, z0], [x1, y, z0], [x1, y, z1], [x0, y, z1]]

        vertices = torch.tensor(
            plate(-1.5, 1.5, -1.5, 1.5, 1.0)
            + plate(-0.8, 0.4, -0.4, 0.8, 2.0)
            + plate(-4.0, 4.0, -4.0, 4.0, 0.0),
            dtype=torch.float32,
        )
        quads = [[[i, i + 1, i + 2], [i, i + 2, i + 3]] for i in (0, 4, 8)]
        camera = Camera(
            eye=(2.5, 6.0, 5.0),
            target=(0.0, 0.5, 0.0),
            fov_y=50.0,
            width=48,
            height=40,
            near=0.1,
            far=50.0,
        )
        return Mesh(vertices, torch.tensor(quads).reshape(-1, 3)), camera
    raise ValueError(f"name: unknown test scene {name!r}")


_TRACED: dict = {}


def _trace(name, origins, directions, t_min, t_max):
    mesh, _ = scene(name)
    # Graders and the lab trace the same rays more than once: remember the last few answers.
    inputs = tuple(x.detach().cpu() for x in (origins, directions, t_min, t_max))
    key = (name, *(hash(x.numpy().tobytes()) for x in inputs))
    if key not in _TRACED:
        if len(_TRACED) > 8:
            _TRACED.clear()
        _TRACED[key] = closest_hits(mesh.triangles(), *inputs)
    t, tri, u, v = _TRACED[key]
    dtype, device = origins.dtype, origins.device
    return Hits(
        t=t.to(device, dtype), triangle=tri.to(device), u=u.to(device, dtype), v=v.to(device, dtype)
    )


def trace_suzanne(origins, directions, t_min, t_max):
    """The tracer handed to the lab: brute force in float64 over ``scene("suzanne")``."""
    return _trace("suzanne", origins, directions, t_min, t_max)


def trace_shadow_scene(origins, directions, t_min, t_max):
    """The tracer handed to the lab: brute force in float64 over ``scene("shadow_scene")``."""
    return _trace("shadow_scene", origins, directions, t_min, t_max)


def trace_plates(origins, directions, t_min, t_max):
    """The tracer handed to the lab: brute force in float64 over ``scene("plates")``."""
    return _trace("plates", origins, directions, t_min, t_max)


def reference_visibility(mesh: Mesh, camera: Camera):
    """Float64 primary visibility: (rays (float64), t (N,), triangle (N,))."""
    key = (hash(mesh.vertices.numpy().tobytes()), hash(mesh.faces.numpy().tobytes()), camera)
    if key not in _REFERENCES:
        rays = primary_rays(camera, device="cpu", dtype=F64)
        t, tri, _, _ = closest_hits(
            mesh.triangles(), rays.origins, rays.directions, rays.t_min, rays.t_max
        )
        _REFERENCES[key] = rays, t, tri
    return _REFERENCES[key]


_REFERENCES: dict = {}


def check_visibility(face, mesh: Mesh, camera: Camera, case: str, agree: float, tol: float = 1e-4):
    """Compare a raster id buffer with float64 ray tracing: at least ``agree`` of the pixels
    equal, and every other pixel *explained*: the raster's triangle really lies under the
    pixel centre (barycentrics >= -tol) and is not clearly behind the traced hit, and a
    traced hit the raster lost lies within tol of its triangle's edge (a silhouette)."""
    rays, t_ref, ref = reference_visibility(mesh, camera)
    got = face.reshape(-1)
    differ = got != ref
    rate = differ.double().mean().item()
    tris = mesh.triangles().to(F64)
    idx = differ.nonzero()[:, 0]
    if len(idx):
        a, r = got[idx], ref[idx]
        o, d = rays.origins[idx], rays.directions[idx]
        bary_a, t_a = ray_plane_barycentrics(tris[a.clamp(min=0)], o, d)
        bary_r, _ = ray_plane_barycentrics(tris[r.clamp(min=0)], o, d)
        margin_a, margin_r = bary_a.amin(-1), bary_r.amin(-1)
        claim_ok = (a < 0) | (margin_a >= -tol)
        not_behind = (r < 0) | (margin_r <= tol) | ((a >= 0) & (t_a <= t_ref[idx] * (1 + tol)))
        bad = ~(claim_ok & not_behind)
        if bad.any():
            j = int(bad.nonzero()[0, 0])
            row, col = divmod(int(idx[j]), camera.width)
            raise AssertionError(
                f"{case}: {int(bad.sum())} pixels show a wrong triangle. First at pixel "
                f"(row {row}, col {col}): the raster shows triangle {int(a[j])}, the float64 ray "
                f"through the pixel centre hits triangle {int(r[j])} at "
                f"t={float(t_ref[idx[j]]):.6g}"
                + (
                    f"; the ray meets triangle {int(a[j])}'s plane at barycentrics "
                    f"{[round(x, 5) for x in bary_a[j].tolist()]}, t={float(t_a[j]):.6g}"
                    if a[j] >= 0
                    else ""
                )
                + "."
            )
    if rate > 1 - agree:
        raise image_mismatch(
            f"{case}: {int(differ.sum())} of {got.numel()} pixels ({rate:.2%}) differ from "
            f"float64 ray tracing (all near edges), at most {1 - agree:.2%} expected: is the "
            f"top-left rule evaluated consistently, and are pixel centres at +0.5?",
            got,
            ref,
            differ,
            name=case,
            kind="id",
            image_shape=(camera.height, camera.width),
        )
    return rate


# ---------------------------------------------------------------------------------------
# Task 1: MVP, clipping, viewport


@pytest.mark.task(1)
@pytest.mark.points(1)
def test_to_clip_space_and_to_screen_pixel_convention(impl, device):
    # A non-square camera; points along the float64 primary rays of chosen pixels.
    camera = Camera(
        eye=(0.3, -0.2, 4.0),
        target=(0.1, 0.2, 0.0),
        fov_y=50.0,
        width=7,
        height=5,
        near=0.5,
        far=50.0,
    )
    rays = primary_rays(camera, device="cpu", dtype=F64)
    rows, cols = torch.meshgrid(torch.arange(5), torch.arange(7), indexing="ij")
    depth = torch.linspace(1.0, 20.0, 35, dtype=F64)
    points = rays.origins + depth[:, None] * rays.directions
    mvp = camera.view_projection(F64)
    exact = torch.cat([points, torch.ones(35, 1, dtype=F64)], 1) @ mvp.T
    for dtype, tol in ((torch.float32, 2e-6), (torch.float64, 1e-12)):
        clip = check_tensor(
            impl.to_clip_space(points.to(device, dtype), mvp.to(device)),
            "to_clip_space(...)",
            shape=(35, 4),
            dtype=dtype,
            device=device,
        )
        assert_close(
            clip, exact, atol=tol * 10, rtol=tol, name=f"to_clip_space ({dtype})", where="vertex"
        )
        screen = check_tensor(
            impl.to_screen(exact.to(device, dtype)[:, None].expand(35, 3, 4).contiguous(), 7, 5),
            "to_screen(...)",
            shape=(35, 3, 4),
            dtype=dtype,
            device=device,
        )
        screen = screen[:, 0].cpu()
        want = torch.stack(
            [
                cols.reshape(-1) + 0.5,
                rows.reshape(-1) + 0.5,
                exact[:, 2] / exact[:, 3],
                1 / exact[:, 3],
            ],
            -1,
        ).to(F64)
        assert_close(
            screen[:, :2],
            want[:, :2],
            atol=1e-4,
            name=(
                f"to_screen ({dtype}): (x, y) of points on the primary ray of each pixel (row 0 at "
                f"the top, centres at +0.5, so x = col + 0.5, y = row + 0.5)"
            ),
            where="point",
        )
        assert_close(
            screen[:, 2:],
            want[:, 2:],
            rtol=1e-5,
            atol=1e-6,
            name=f"to_screen ({dtype}): z_ndc = z / w and 1 / w",
            where="point",
        )
    # 1 / w is one over the distance along the view axis.
    forward = torch.tensor(camera.target, dtype=F64) - torch.tensor(camera.eye, dtype=F64)
    along = ((points - rays.origins) * forward / forward.norm()).sum(-1)
    assert_close(exact[:, 3], along, rtol=1e-12, name="test set-up: w is the view depth")
    # Far from the origin: float32 vertices 1e5 away, the camera next to them.
    far = dataclasses.replace(
        camera, eye=(1e5 + 0.3, 1e5 - 0.2, 1e5 + 4.0), target=(1e5 + 0.1, 1e5 + 0.2, 1e5)
    )
    verts = (points + 1e5).float()
    mvp = far.view_projection(F64)
    exact = torch.cat([verts.double(), torch.ones(35, 1, dtype=F64)], 1) @ mvp.T
    clip = impl.to_clip_space(verts.to(device), mvp.to(device)).cpu()
    assert_close(
        clip,
        exact,
        rtol=1e-6,
        atol=1e-5,
        name=(
            "to_clip_space of float32 vertices 1e5 from the origin, camera beside them: a float32 "
            "product cancels five digits here; compute the transform in float64"
        ),
        where="vertex",
    )
    # A 1x1 viewport: the view axis lands on the one pixel's centre.
    one = impl.to_screen(torch.tensor([[[0.0, 0.0, 0.5, 2.0]] * 3], device=device), 1, 1).cpu()
    assert_close(
        one[0, 0, :2],
        torch.tensor([0.5, 0.5]),
        atol=1e-7,
        name="to_screen on a 1x1 viewport: the view axis",
        where="coordinate",
    )
    # Bad input.
    v = points.float().to(device)
    expect_error("vertices", impl.to_clip_space, v.int(), mvp.to(device), case="integer vertices")
    expect_error(
        "vertices", impl.to_clip_space, v[:, :2], mvp.to(device), case="vertices of shape (N, 2)"
    )
    expect_error("mvp", impl.to_clip_space, v, mvp[:3, :3].to(device), case="a (3, 3) mvp")
    expect_error(
        "width",
        impl.to_screen,
        exact[:1, None].expand(1, 3, 4).float().to(device),
        0,
        5,
        case="width=0",
    )
    # A corner at w <= 0 (or NaN) is on or behind the eye: x / w has no screen position
    # (inf or NaN, or mirrored through the eye); clip_triangles never outputs one.
    for w_bad in (0.0, -2.0, math.nan):
        bad = torch.tensor([[[0.0, 0.0, 0.5, 2.0]] * 3], device=device)
        bad[0, 1, 3] = w_bad
        expect_error(
            "clipped",
            impl.to_screen,
            bad,
            4,
            4,
            kinds=(ValueError,),
            case=f"a corner with w = {w_bad} (the perspective divide needs w > 0: "
            f"check the corners and raise ValueError naming `clipped`)",
        )


def near_plane_cases(device, dtype):
    """Clip-space triangles with 3, 2, 1 and 0 corners on the visible side of the near plane
    (and some outside a side plane), plus NaN and fully-rejected ones. (F, 3, 4) float64."""
    g = generator(61)
    f = 240
    w = torch.rand(f, 3, generator=g, dtype=F64) * 4 - 1.5  # some behind the eye
    xy = (torch.rand(f, 3, 2, generator=g, dtype=F64) * 2 - 1) * (w.abs()[..., None] + 0.5)
    z = (torch.rand(f, 3, generator=g, dtype=F64) * 2 - 1) * (w.abs() + 0.5)
    clip = torch.cat([xy, z[..., None], w[..., None]], -1)
    clip[0] = torch.tensor([[0.0, 0.0, 0.0, 1.0], [0.5, 0.0, 0.0, 1.0], [0.0, 0.5, 0.0, 1.0]])
    clip[1, 0, 0] = math.nan  # NaN: dropped
    clip[2, :, 0] = clip[2, :, 3].abs() + 1  # all right of x = w
    clip[3, :, 2] = -clip[3, :, 3].abs() - 1  # all in front of the near plane
    return clip


def exact_clip_fraction(clip):
    """Per triangle: the fraction of its (barycentric) area on the side z + w >= 0, and
    whether it is kept: not rejected by the seven half-spaces (the six planes and w <= 0),
    and no corner of its clipped polygon at w <= 0 (there the divide would give inf/NaN).
    Also the smallest |w| of a polygon corner (how clear that decision is). float64."""
    d = clip[..., 2] + clip[..., 3]
    x, y, z, w = clip.unbind(-1)
    outside = (
        (x < -w).all(-1)
        | (x > w).all(-1)
        | (y < -w).all(-1)
        | (y > w).all(-1)
        | (z < -w).all(-1)
        | (z > w).all(-1)
        | (w <= 0).all(-1)
    )
    keep = torch.isfinite(clip).all(-1).all(-1) & ~outside
    frac = torch.zeros(clip.shape[0], dtype=F64)
    margin = torch.full((clip.shape[0],), math.inf, dtype=F64)
    for i in range(clip.shape[0]):
        di, wi = d[i].tolist(), w[i].tolist()
        inside = [x >= 0 for x in di]
        # The polygon's corners: the inside corners, and where edges cross d = 0.
        corners_w = [wi[k] for k in range(3) if inside[k]]
        for a, b in ((0, 1), (1, 2), (2, 0)):
            if inside[a] != inside[b]:
                corners_w.append(wi[a] + di[a] / (di[a] - di[b]) * (wi[b] - wi[a]))
        if corners_w:
            margin[i] = min(abs(c) for c in corners_w)
            keep[i] &= min(corners_w) > 0
        if all(inside):
            frac[i] = 1.0
        elif any(inside):
            # The region d >= 0 (or d < 0) around the lone corner is a triangle with sides
            # t_ab, t_ac of the edges from it.
            lone = next(k for k in range(3) if inside.count(inside[k]) == 1)
            a, b, c = lone, (lone + 1) % 3, (lone + 2) % 3
            corner = (di[a] / (di[a] - di[b])) * (di[a] / (di[a] - di[c]))
            frac[i] = corner if inside[a] else 1 - corner
    return frac, keep, margin


@pytest.mark.task(1)
@pytest.mark.points(1)
def test_clip_triangles_near_plane(impl, device):
    clip64 = near_plane_cases(device, F64)
    frac, keep, margin = exact_clip_fraction(clip64)
    assert 20 < int(((frac > 0) & (frac < 1) & keep).sum()), "test set-up: too few crossings"
    assert bool((margin > 1e-4).all()), "test set-up: a clipped corner too close to w = 0"
    for dtype, tol in ((torch.float32, 2e-5), (torch.float64, 1e-12)):
        clip = clip64.to(dtype)
        result = impl.clip_triangles(clip.to(device))
        assert isinstance(result, tuple) and len(result) == 3, (
            "clip_triangles: expected a tuple (clipped, source, weights)"
        )
        clipped, source, weights = result
        k = check_tensor(
            clipped, "clip_triangles(...)[0]", shape=(None, 3, 4), dtype=dtype, device=device
        ).shape[0]
        check_tensor(source, "clip_triangles(...)[1]", shape=(k,), dtype=torch.int64, device=device)
        check_tensor(weights, "clip_triangles(...)[2]", shape=(k, 3, 3), dtype=dtype, device=device)
        clipped, source, weights = clipped.cpu().double(), source.cpu(), weights.cpu().double()
        case = f"clip_triangles ({dtype})"
        assert bool((source[1:] >= source[:-1]).all()), f"{case}: source must be increasing"
        d = clipped[..., 2] + clipped[..., 3]
        scale = clipped.abs().amax(-1)
        bad = d < -tol * (scale + 1)
        if bad.any():
            k0, j0 = bad.nonzero()[0].tolist()
            raise AssertionError(
                f"{case}: output triangle {k0} (from input {int(source[k0])}) has corner {j0} "
                f"with z + w = {float(d[k0, j0]):.3g} < 0, behind the near plane: triangles "
                f"crossing it must be clipped (a corner with w < 0 projects to the wrong side "
                f"of the screen)"
            )
        # Weights: each output corner is its weighted sum of the source corners.
        rebuilt = weights @ clip64[source]
        assert_close(
            clipped,
            rebuilt,
            atol=tol * 10,
            rtol=tol,
            name=f"{case}: clipped corners vs weights @ source corners",
            where="corner",
        )
        assert_close(
            weights.sum(-1),
            torch.ones(k, 3, dtype=F64),
            atol=tol,
            name=f"{case}: weights of each corner sum to 1",
            where="corner",
        )
        assert bool((weights >= -tol).all()), f"{case}: negative weights"
        # Area: the outputs of a source tile exactly its part on the visible side, with the
        # winding kept (positive determinant in barycentric space).
        det = torch.linalg.det(weights)
        assert bool((det > -tol).all()), (
            f"{case}: an output triangle reverses its source's winding (corner order): "
            f"rotate corners, never swap two"
        )
        area = torch.zeros(clip64.shape[0], dtype=F64).index_add_(0, source, det)
        want = torch.where(keep, frac, torch.zeros_like(frac))
        assert_close(
            area,
            want,
            atol=1e-4 if dtype == torch.float32 else 1e-9,
            name=(
                f"{case}: the area of each input triangle's outputs, as a fraction of its own "
                f"(expected: the part with z + w >= 0; 0 for rejected, NaN or fully-clipped ones, "
                f"and for those with a clipped corner at w <= 0)"
            ),
            where="input triangle",
        )
        counts = torch.bincount(source, minlength=clip64.shape[0])
        n_in = ((clip64[..., 2] + clip64[..., 3]) >= 0).sum(-1)
        want_counts = torch.where(keep, torch.tensor([0, 1, 2, 1])[n_in], 0)
        assert_equal(
            counts,
            want_counts,
            name=(
                f"{case}: triangles out per triangle in (3 corners inside: 1, two: 2 (a quad), "
                f"one: 1, none or outside one plane or NaN or a clipped corner at w <= 0: 0)"
            ),
            where="input triangle",
        )
    # Every corner exactly on one plane of the view volume: on its boundary, not outside
    # (the half-spaces x < -w, ... are strict), so the triangle is kept, once and whole.
    base = torch.tensor(
        [[0.25, -0.5, 0.0, 1.0], [0.5, 0.25, 0.5, 2.0], [-0.75, 0.5, -1.0, 4.0]], dtype=F64
    )
    planes = {
        "x = -w": (0, -1),
        "x = w": (0, 1),
        "y = -w": (1, -1),
        "y = w": (1, 1),
        "z = -w (the near plane)": (2, -1),
        "z = w (the far plane)": (2, 1),
    }
    on_plane = base.repeat(len(planes), 1, 1)
    for n, (axis, sign) in enumerate(planes.values()):
        on_plane[n, :, axis] = sign * on_plane[n, :, 3]
    for dtype in (torch.float32, F64):
        _, source, _ = impl.clip_triangles(on_plane.to(device, dtype))
        source = source.cpu().tolist()
        wrong = [name for n, name in enumerate(planes) if source.count(n) != 1]
        assert not wrong, (
            f"clip_triangles ({dtype}): triangles with all three corners on the plane "
            f"{', '.join(wrong)} came out {[source.count(n) for n in range(len(planes))]} "
            f"times (one each expected, in the order {list(planes)}): a corner on a plane "
            f"lies on the view volume's boundary, not outside it (reject only x < -w, x > w, "
            f"y < -w, y > w, z < -w, z > w, w <= 0)"
        )
    empty = impl.clip_triangles(torch.zeros(0, 3, 4, device=device))
    assert [tuple(x.shape) for x in empty] == [(0, 3, 4), (0,), (0, 3, 3)], (
        f"clip_triangles of no triangles: got shapes {[tuple(x.shape) for x in empty]}"
    )
    expect_error(
        "clip",
        impl.clip_triangles,
        torch.zeros(4, 3, 3, device=device),
        case="clip of shape (F, 3, 3)",
    )


def ground_scene(device, dtype):
    """A ground quad y = -1 reaching far behind the camera, and a triangle behind the eye."""
    vertices = torch.tensor(
        [
            [-40.0, -1.0, -40.0],
            [40.0, -1.0, -40.0],
            [40.0, -1.0, 40.0],
            [-40.0, -1.0, 40.0],
            [-1.0, -1.0, 5.0],
            [1.0, -1.0, 5.0],
            [0.0, 1.0, 5.0],
        ],
        dtype=dtype,
    )
    faces = torch.tensor([[0, 3, 2], [0, 2, 1], [4, 5, 6]])
    camera = Camera(
        eye=(0.0, 0.0, 0.0),
        target=(0.2, -0.35, -1.0),
        fov_y=70.0,
        width=48,
        height=32,
        near=0.05,
        far=200.0,
    )
    return Mesh(vertices.to(device), faces.to(device)), camera


@pytest.mark.task(1)
@pytest.mark.points(1)
def test_clip_triangles_ground_plane_behind_camera(impl, device):
    mesh, camera = ground_scene(device, torch.float32)
    _, source, _, screen = screen_triangles(impl, mesh.vertices, mesh.faces, camera, device)
    assert not bool((source == 2).any()), (
        "clip_triangles: the triangle entirely behind the eye must be rejected"
    )
    assert bool((screen[..., 3] > 0).all()), "to_screen: 1/w must be positive after clipping"
    # The union of the screen triangles (tested here in float64) must be the ground the
    # float64 primary rays hit in front of the near plane.
    rays = primary_rays(camera, device="cpu", dtype=F64)
    t = (-1.0 - rays.origins[:, 1]) / rays.directions[:, 1]
    hit_point = rays.origins + t[:, None] * rays.directions
    forward = torch.tensor(camera.target, dtype=F64) - torch.tensor(camera.eye, dtype=F64)
    view_depth = (t[:, None] * rays.directions * forward / forward.norm()).sum(-1)
    on_ground = (t > 0) & (hit_point[:, 0].abs() < 40) & (hit_point[:, 2].abs() < 40)
    want = on_ground & (view_depth >= camera.near) & (view_depth <= camera.far)
    rows, cols = torch.meshgrid(
        torch.arange(camera.height), torch.arange(camera.width), indexing="ij"
    )
    px = (cols.reshape(-1) + 0.5).to(F64)
    py = (rows.reshape(-1) + 0.5).to(F64)
    s = screen[..., :2].double()

    def edge(a, b):
        return (px[:, None] - a[None, :, 0]) * (b[None, :, 1] - a[None, :, 1]) - (
            py[:, None] - a[None, :, 1]
        ) * (b[None, :, 0] - a[None, :, 0])

    e = torch.stack([edge(s[:, 1], s[:, 2]), edge(s[:, 2], s[:, 0]), edge(s[:, 0], s[:, 1])], -1)
    inside = ((e >= -1e-3).all(-1) | (e <= 1e-3).all(-1)).any(1)
    clearly = ((e >= 1e-2).all(-1) | (e <= -1e-2).all(-1)).any(1)
    # Judge pixels away from the quad's far edge (the horizon band) and the triangle edges.
    judged = clearly | ~inside
    wrong = judged & (clearly != want)
    assert int(want.sum()) > 300, "test set-up: too little ground in view"
    if wrong.any():
        i = int(wrong.nonzero()[0, 0])
        raise AssertionError(
            f"clip_triangles/to_screen: {int(wrong.sum())} pixel centres are "
            f"{'covered' if bool(clearly[i]) else 'not covered'} by the screen triangles of a "
            f"ground plane that reaches behind the camera, but the float64 ray through pixel "
            f"(row {i // camera.width}, col {i % camera.width}) "
            f"{'hits' if bool(want[i]) else 'misses'} it. Clip at z + w = 0 before dividing "
            f"by w."
        )


W_CASES = {  # clip coordinates (x, y, z, w) no perspective camera makes; a degenerate one can
    "every coordinate 0 (a zero matrix)": [[0.0, 0.0, 0.0, 0.0]] * 3,
    "every w = 0 and z = 0": [[-1.0, 0.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0]],
    "every w = 0, z mixed (a quad after the near clip)": [
        [-1.0, -1.0, 0.0, 0.0],
        [1.0, -1.0, 1.0, 0.0],
        [0.0, 1.0, -1.0, 0.0],
    ],
    "one corner at w < 0 beyond the far plane": [
        [0.0, 0.0, 0.0, 1.0],
        [0.5, 0.0, 0.0, 1.0],
        [0.0, 0.5, 1.0, -0.5],
    ],
    "one corner at w = 0, z = 0": [
        [0.0, 0.0, 0.0, 1.0],
        [0.5, 0.0, 0.0, 1.0],
        [0.3, 0.2, 0.0, 0.0],
    ],
    "a quad whose cut lands at w < 0": [
        [0.0, 0.0, 2.0, -1.5],
        [0.5, 0.0, 2.0, -1.5],
        [0.0, 0.5, -3.0, 1.0],
    ],
}


@pytest.mark.task(1)
@pytest.mark.points(1)
def test_clip_triangles_w_at_or_behind_the_eye(impl, device):
    # Every output corner must have w > 0: the divide by w of a corner at w = 0 gives
    # inf/NaN on screen, and at w < 0 flips it. On the visible side of the near plane such
    # a corner lies at or beyond the far plane, so the triangle is dropped.
    control = [[-0.5, -0.5, 0.0, 1.0], [0.5, -0.5, 0.0, 1.0], [0.0, 0.5, 0.0, 1.0]]
    names = list(W_CASES)
    for dtype in (torch.float32, F64):
        clip = torch.tensor([W_CASES[n] for n in names] + [control], dtype=dtype)
        clipped, source, _ = impl.clip_triangles(clip.to(device))
        source = source.cpu()
        kept = [names[i] for i in source.tolist() if i < len(names)]
        assert not kept, (
            f"clip_triangles ({dtype}): the triangles with {', '.join(sorted(set(kept)))} "
            f"came out: a corner at w <= 0 (at or beyond the far plane here) must never "
            f"reach the divide by w; drop the triangle (reject every w <= 0, and drop outputs "
            f"with a corner at w <= 0)"
        )
        assert source.tolist() == [len(names)], (
            f"clip_triangles ({dtype}): the control triangle in front of the camera must come "
            f"out once, got sources {source.tolist()}"
        )
        screen = impl.to_screen(clipped, 16, 16).cpu()
        assert bool(torch.isfinite(screen).all()) and bool((screen[..., 3] > 0).all()), (
            f"to_screen after clip_triangles ({dtype}): NaN/inf or 1/w <= 0 on screen"
        )
    # A zero view-projection matrix puts every vertex at the origin of clip space.
    mesh, _ = ground_scene(device, torch.float32)
    clip = impl.to_clip_space(mesh.vertices, torch.zeros(4, 4, dtype=F64, device=device))
    clipped, source, _ = impl.clip_triangles(clip[mesh.faces])
    assert clipped.shape[0] == 0, (
        f"clip_triangles of a mesh seen through a zero matrix (every clip coordinate 0): "
        f"{clipped.shape[0]} triangles came out, to be divided by w = 0"
    )


# ---------------------------------------------------------------------------------------
# Task 2: bounding boxes, edge functions, fill rule


def box_reference(tris, width, height):
    """(K, 4) [col_begin, row_begin, col_end, row_end) by trying every pixel centre; empty
    boxes as (0, 0, 0, 0)."""
    finite = torch.isfinite(tris).all(-1).all(-1)
    lo, hi = tris.amin(1), tris.amax(1)
    boxes = torch.zeros(tris.shape[0], 4, dtype=torch.int64)
    for axis, size in ((0, width), (1, height)):
        centres = torch.arange(size, dtype=F64) + 0.5
        ok = (centres[None] >= lo[:, axis, None]) & (centres[None] <= hi[:, axis, None])
        ok &= finite[:, None]
        any_ok = ok.any(1)
        first = torch.where(any_ok, ok.to(torch.int64).argmax(1), 0)
        last = torch.where(any_ok, size - ok.flip(1).to(torch.int64).argmax(1), 0)
        boxes[:, axis], boxes[:, axis + 2] = first, last
    empty = (boxes[:, 2] <= boxes[:, 0]) | (boxes[:, 3] <= boxes[:, 1])
    return torch.where(empty[:, None], 0, boxes), empty


@pytest.mark.task(1)
@pytest.mark.points(1)
def test_clip_triangles_corner_on_near_plane(impl, device):
    # d = z + w = 0 is the visible side (d >= 0): a triangle with one corner exactly on the
    # near plane and the others in front of it has three inside corners and is kept whole.
    tri = [[0.0, 0.0, -1.0, 1.0], [0.5, 0.0, 0.0, 1.0], [0.0, 0.5, 0.0, 1.0]]
    for dtype in (torch.float32, F64):
        clip = torch.tensor([tri], dtype=dtype)
        clipped, source, weights = impl.clip_triangles(clip.to(device))
        case = f"clip_triangles ({dtype}) of {tri} (corner 0 on the near plane, z + w = 0)"
        assert clipped.shape[0] == 1, (
            f"{case}: expected 1 output triangle (the input, all corners have z + w >= 0), "
            f"got {clipped.shape[0]}"
        )
        assert int(source.cpu()[0]) == 0, f"{case}: source must be [0]"
        rebuilt = weights.cpu().double() @ clip.double()[0]
        assert torch.allclose(clipped.cpu().double()[0], rebuilt[0], atol=1e-6), (
            f"{case}: clipped != weights @ clip"
        )
        # The kept triangle covers the input: its corners are the input's (any rotation).
        got = sorted(map(tuple, clipped.cpu().double()[0].tolist()))
        assert got == sorted(map(tuple, clip.double()[0].tolist())), (
            f"{case}: expected the input corners {tri}, got {clipped.cpu().tolist()}"
        )


def clip_to_screen4(clip, width, height):
    """(K, 3, 4) screen triangles (x, y, z_ndc, 1/w) of clip coordinates, in float64: the
    formula of ``to_screen``, written out here (task 1 is graded on its own)."""
    x, y, z, w = clip.to(F64).unbind(-1)
    return torch.stack([(x / w + 1) * (width / 2), (1 - y / w) * (height / 2), z / w, 1 / w], -1)


@pytest.mark.task(2)
@pytest.mark.points(1)
def test_bounding_boxes(impl, device):
    g = generator(71)
    for width, height in ((13, 5), (16, 16), (1, 1), (7, 3), (40, 9)):
        tris = (torch.rand(200, 3, 2, generator=g, dtype=F64) * 1.6 - 0.3) * torch.tensor(
            [width, height], dtype=F64
        )
        special = torch.tensor(
            [
                [[-1e6, -1e6], [1e6, 0.0], [0.0, 1e6]],  # huge: the whole screen
                [[-1e30, -1e30], [1e30, 0.0], [0.0, 1e30]],  # beyond int64: the whole screen
                [[-1e30, -1e30], [-1e29, -1.0], [-3e29, -2e29]],  # far off to the top left
                [[0.4, 0.4], [0.6, 0.4], [0.5, 0.6]],  # sub-pixel, on pixel 0's centre
                [[-5.0, 1.0], [-3.0, 2.0], [-4.0, 3.0]],  # left of the screen
                [[math.nan, 1.0], [2.0, 2.0], [1.0, 3.0]],  # NaN
                [[math.inf, 1.0], [2.0, 2.0], [1.0, 3.0]],  # inf
                [
                    [width - 0.5, height - 0.5],
                    [width + 3.0, height - 0.5],
                    [width - 0.5, height + 3.0],
                ],  # from the last pixel's centre
                [[0.2, 0.2], [2.5, 0.2], [0.2, 2.5]],  # max exactly on pixel 2's centre
                [[1.5, 0.5], [3.5, 0.5], [1.5, 2.5]],  # min and max exactly on centres
                [[2.5, 1.5], [2.5, 1.5], [2.5, 1.5]],  # a point on a pixel centre
                [[0.5, 0.5], [width - 0.5, 0.5], [0.5, height - 0.5]],  # centre to centre
                [[0.51, 0.51], [width - 0.51, 0.51], [0.51, height - 0.51]],  # just inside
                [[0.49, 0.49], [0.49, 0.49], [0.49, 0.49]],  # a point left of centre 0
            ],
            dtype=F64,
        )
        # Screens as to_screen makes them, C = 4 (x, y, z_ndc, 1/w) from clip corners with
        # w != 1: z_ndc and 1/w are no coordinates of the box (z_ndc from -3 to 40 here).
        w = torch.rand(120, 3, 1, generator=g, dtype=F64) * 3.5 + 0.25
        xyz = (torch.rand(120, 3, 3, generator=g, dtype=F64) * 2 - 1) * w * 1.3
        xyz[..., 2:] = (torch.rand(120, 3, 1, generator=g, dtype=F64) * 43 - 3) * w
        screen = clip_to_screen4(torch.cat([xyz, w], -1), width, height)
        screen[:4, :, 2] = math.nan  # NaN z_ndc or 1/w with finite x, y: a box all the same
        screen[4:8, :, 3] = math.inf
        for case, given in (
            ("(K, 3, 2) triangles", torch.cat([tris, special])),
            ("(K, 3, 4) screen triangles (x, y, z_ndc, 1/w)", screen),
        ):
            for dtype in (torch.float32, torch.float64):
                # The reference sees the float32 coordinates too (a centre may move by rounding).
                want, empty = box_reference(given[..., :2].to(dtype).to(F64), width, height)
                got = check_tensor(
                    impl.bounding_boxes(given.to(device, dtype), width, height),
                    "bounding_boxes(...)",
                    shape=(len(given), 4),
                    dtype=torch.int64,
                    device=device,
                ).cpu()
                what = f"bounding_boxes {width}x{height} of {case} ({dtype})"
                got_empty = (got[:, 2] <= got[:, 0]) | (got[:, 3] <= got[:, 1])
                assert_equal(
                    got_empty,
                    empty,
                    name=f"{what}: which boxes are empty (off screen, NaN/inf x or y)",
                    where="triangle",
                )
                assert (
                    bool((got >= 0).all())
                    and bool((got[:, [0, 2]] <= width).all())
                    and bool((got[:, [1, 3]] <= height).all())
                ), f"{what}: boxes must be clamped to the screen"
                assert_equal(
                    torch.where(empty[:, None], 0, got),
                    want,
                    name=(
                        f"{what}: [col_begin, row_begin, col_end, row_end) of the pixels whose "
                        f"centres lie in the triangle's x, y extent (the last row and column "
                        f"included, end = floor(max - 0.5) + 1; only x and y count)"
                    ),
                    where="triangle",
                )
    expect_error(
        "screen",
        impl.bounding_boxes,
        torch.zeros(3, 2, device=device),
        4,
        4,
        case="screen of shape (K, 2)",
    )
    expect_error(
        "height", impl.bounding_boxes, torch.zeros(3, 3, 2, device=device), 4, -1, case="height=-1"
    )


def check_exactly_once(impl, tris, width, height, case, device, exact=True):
    """Every pixel centre covered by exactly one triangle; optionally equal to the exact
    top-left reference per triangle."""
    for dtype in (torch.float32, torch.float64):
        triangle, pixel, bary = fragments(
            impl, tris.to(device, dtype), width, height, device=device
        )
        count = torch.zeros(width * height, dtype=torch.int64).scatter_add_(
            0, pixel, torch.ones_like(pixel)
        )
        bad = count != 1
        if bad.any():
            i = int(bad.nonzero()[0, 0])
            raise AssertionError(
                f"coverage ({case}, {dtype}): {int(bad.sum())} of {width * height} pixels are "
                f"not covered exactly once; pixel (row {i // width}, col {i % width}) is covered "
                f"{int(count[i])} times. A centre on an edge shared by two triangles belongs to "
                f"exactly one of them: the top-left rule (e > 0, or e == 0 on a top or left "
                f"edge), with edge functions computed alike by both triangles."
            )
        if exact:
            want = exact_coverage(tris, width, height)
            got = coverage_matrix(triangle, pixel, len(tris), width * height)
            assert_equal(
                got,
                want.to(torch.int64),
                name=(
                    f"coverage ({case}, {dtype}): pixels of each triangle vs the exact top-left "
                    f"rule (a centre on a top or left edge is in, on a bottom or right edge out)"
                ),
                where="(triangle, pixel)",
            )
        # Barycentrics reproduce the pixel centre.
        col, row = pixel % width, pixel // width
        centre = torch.stack([col + 0.5, row + 0.5], -1).to(F64)
        corners = tris[triangle].to(F64)
        rebuilt = (bary.double()[..., None] * corners).sum(1)
        tol = 1e-3 if dtype == torch.float32 else 1e-9
        assert_close(
            rebuilt,
            centre,
            atol=tol * max(width, height),
            name=(f"coverage ({case}, {dtype}): sum_i bary_i * v_i must be the pixel centre"),
            where="fragment",
        )
        assert bool((bary >= -tol).all()) and bool((bary.sum(-1) - 1).abs().max() < tol), (
            f"coverage ({case}, {dtype}): barycentrics of inside pixels are in [0, 1], sum 1"
        )


@pytest.mark.task(2)
@pytest.mark.points(1)
def test_coverage_fill_rule_exactly_once(impl, device):
    # Grids whose edges and diagonals run through pixel centres, beyond the screen on all sides.
    xs = torch.arange(-2.5, 19.0, 3.0)
    ys = torch.arange(-3.5, 15.0, 3.0)
    for flip in (None, True, False):
        check_exactly_once(
            impl,
            grid_mesh(xs, ys, flip=flip),
            16,
            12,
            f"grid on pixel centres, diagonals {flip}",
            device,
        )
    # Long thin slivers and a fan of 8 triangles around a vertex on a pixel centre.
    ring = torch.tensor(
        [
            [-4.5, -4.5],
            [8.5, -4.5],
            [21.5, -4.5],
            [21.5, 6.5],
            [21.5, 17.5],
            [8.5, 17.5],
            [-4.5, 17.5],
            [-4.5, 6.5],
        ],
        dtype=F64,
    )
    centre = torch.tensor([8.5, 6.5], dtype=F64)
    fan = torch.stack([torch.stack([centre, ring[(i + 1) % 8], ring[i]]) for i in range(8)])
    check_exactly_once(impl, fan, 16, 12, "fan around a pixel centre", device)
    # A jittered mesh: float vertices anywhere, no exact reference, still exactly once.
    xs = torch.linspace(-3.0, 19.0, 9, dtype=F64)
    ys = torch.linspace(-3.0, 15.0, 7, dtype=F64)
    jitter = (torch.rand(7, 9, 2, generator=generator(81), dtype=F64) - 0.5) * 1.5
    jitter[0] = jitter[-1] = 0
    jitter[:, 0] = jitter[:, -1] = 0
    check_exactly_once(
        impl, grid_mesh(xs, ys, jitter), 16, 12, "jittered mesh", device, exact=False
    )
    # A non-square viewport and a 1x1 one.
    xs = torch.arange(-1.5, 23.0, 2.0)
    ys = torch.arange(-0.5, 6.0, 2.0)
    check_exactly_once(impl, grid_mesh(xs, ys), 21, 5, "21x5 grid", device)
    check_exactly_once(
        impl,
        grid_mesh(torch.tensor([-1.0, 0.5, 2.0]), torch.tensor([-1.0, 0.5, 2.0])),
        1,
        1,
        "1x1",
        device,
    )


@pytest.mark.task(2)
@pytest.mark.points(1)
def test_coverage_culling_degenerate_subpixel(impl, device):
    width, height = 16, 12
    # A front face: counter-clockwise as seen, hence positive area on the y-down screen.
    front = torch.tensor([[[2.25, 10.5], [13.75, 9.5], [7.5, 1.25]]], dtype=F64)
    back = front[:, [0, 2, 1]]
    for dtype in (torch.float32, torch.float64):
        both = torch.cat([front, back]).to(device, dtype)
        tri, pix, _ = fragments(impl, both, width, height, False, device)
        assert tri.numel() > 30, "coverage: the test triangle covers many pixels"
        assert_equal(
            pix[tri == 1],
            pix[tri == 0],
            name=(
                f"coverage without culling ({dtype}): a triangle and its reversed copy cover the "
                f"same pixels"
            ),
            where="fragment",
        )
        tri, pix, _ = fragments(impl, both, width, height, True, device)
        assert bool((tri == 0).all()) and tri.numel() > 30, (
            f"coverage with cull_backfaces=True ({dtype}): the counter-clockwise (front, "
            f"positive-area) triangle must stay and its reversed copy go; got fragments of "
            f"triangles {tri.unique().tolist()}"
        )
    # Degenerate triangles cover nothing; a huge one covers everything once.
    degenerate = torch.tensor(
        [
            [[1.5, 1.5], [5.5, 5.5], [9.5, 9.5]],  # collinear through pixel centres
            [[3.5, 3.5], [3.5, 3.5], [8.0, 2.0]],  # repeated corner
            [[2.0, 2.0], [2.0, 2.0], [2.0, 2.0]],  # a point
            [[math.nan, 1.0], [5.0, 5.0], [1.0, 8.0]],  # NaN
            [[-math.inf, 1.0], [5.0, 5.0], [1.0, 8.0]],  # inf
        ],
        dtype=F64,
    )
    huge = torch.tensor([[[-1e6, -1e6], [1e6, -1e6], [0.0, 1e6]]], dtype=F64)
    for dtype in (torch.float32, torch.float64):
        tri, pix, bary = fragments(
            impl, torch.cat([degenerate, huge]).to(device, dtype), width, height, device=device
        )
        assert bool((tri == 5).all()), (
            f"coverage ({dtype}): zero-area and NaN/inf triangles must cover nothing; got "
            f"fragments of triangles {tri.unique().tolist()}"
        )
        assert_equal(
            pix.sort().values,
            torch.arange(width * height),
            name=(f"coverage ({dtype}): a triangle 1e6 pixels across covers every pixel once"),
            where="fragment",
        )
        assert bool(torch.isfinite(bary).all()), "coverage: NaN barycentrics"
    # Sub-pixel triangles: 0 or 1 pixel each, exactly as the rule says.
    g = generator(91)
    corner = torch.randint(0, 16 * width, (300, 1, 2), generator=g).to(F64) / 16
    corner[..., 1] = corner[..., 1] % height
    offsets = torch.randint(-8, 9, (300, 3, 2), generator=g).to(F64) / 16
    tiny = corner + offsets
    want = exact_coverage(tiny, width, height)
    assert 30 < int(want.any(1).sum()) < 290, "test set-up: sub-pixel triangles"
    assert int(want.sum(1).max()) <= 1
    for dtype in (torch.float32, torch.float64):
        tri, pix, _ = fragments(impl, tiny.to(device, dtype), width, height, device=device)
        assert_equal(
            coverage_matrix(tri, pix, 300, width * height),
            want.to(torch.int64),
            name=f"coverage of sub-pixel triangles ({dtype}) vs the exact top-left rule",
            where="(triangle, pixel)",
        )
    # Culling keeps every front face however small (E_12(v0) > 0, twice its area in square
    # pixels, many below 1 here) and drops every back face.
    q = torch.round(tiny * 16).to(torch.int64)
    area = (q[:, 0, 0] - q[:, 1, 0]) * (q[:, 2, 1] - q[:, 1, 1]) - (q[:, 0, 1] - q[:, 1, 1]) * (
        q[:, 2, 0] - q[:, 1, 0]
    )  # E_12(v0), times 256
    front = want & (area > 0)[:, None]
    small = (area > 0) & (area <= 256) & want.any(1)
    assert int(small.sum()) > 10 and int((want & (area < 0)[:, None]).sum()) > 10, (
        "test set-up: small front faces and back faces that cover a pixel centre"
    )
    for dtype in (torch.float32, torch.float64):
        tri, pix, _ = fragments(impl, tiny.to(device, dtype), width, height, True, device)
        assert_equal(
            coverage_matrix(tri, pix, 300, width * height),
            front.to(torch.int64),
            name=(
                f"coverage of sub-pixel triangles with cull_backfaces=True ({dtype}): "
                f"the front faces' pixels (positive area, however small: "
                f"{int(small.sum())} have E_12(v0) <= 1 pixel), no back face's"
            ),
            where="(triangle, pixel)",
        )
    # Half-pixel triangles, E_12(v0) = +1 and -1 exactly, around the centre of pixel (2, 2).
    half = torch.tensor([[[2.25, 2.25], [3.25, 2.25], [2.25, 3.25]]], dtype=F64)
    half = torch.cat([half, half[:, [0, 2, 1]]])
    for cull in (False, True):
        for dtype in (torch.float32, torch.float64):
            tri, pix, _ = fragments(impl, half.to(device, dtype), width, height, cull, device)
            want_tri = [1] if cull else [0, 1]  # triangle 1 is the counter-clockwise one
            assert tri.tolist() == want_tri and pix.tolist() == [2 * width + 2] * len(want_tri), (
                f"coverage ({dtype}, cull_backfaces={cull}) of two half-pixel triangles of "
                f"E_12(v0) = -1 and +1 (twice their area, in pixels), {half.tolist()}: expected "
                f"triangles {want_tri} each on pixel {2 * width + 2} (row 2, col 2), got "
                f"triangles {tri.tolist()} on pixels {pix.tolist()}"
            )
    # (K, 3, 4) screens: only x and y are read; z_ndc and 1/w may even be NaN or inf.
    for dtype in (torch.float32, torch.float64):
        tri, pix, _ = fragments(
            impl,
            screen4(tiny, inv_w=math.inf, z=math.nan).to(device, dtype),
            width,
            height,
            device=device,
        )
        assert_equal(
            coverage_matrix(tri, pix, 300, width * height),
            want.to(torch.int64),
            name=(
                f"coverage of sub-pixel triangles as (K, 3, 4) screens (x, y, z_ndc = NaN, "
                f"1/w = inf) ({dtype}): only x and y decide coverage"
            ),
            where="(triangle, pixel)",
        )
    # No triangles; bad input.
    tri, pix, bary = fragments(
        impl, torch.zeros(0, 3, 4, device=device), width, height, device=device
    )
    assert tri.numel() == 0 and bary.shape == (0, 3), "coverage of no triangles: no fragments"
    expect_error(
        "screen",
        impl.coverage,
        torch.zeros(2, 3, 1, device=device),
        4,
        4,
        case="screen of shape (K, 3, 1)",
    )
    expect_error(
        "screen",
        impl.coverage,
        torch.zeros(2, 3, 2, device=device, dtype=torch.int32),
        4,
        4,
        case="integer screen coordinates",
    )


# ---------------------------------------------------------------------------------------
# Task 3: keys and the atomic-min visibility buffer


def float_bits(x):
    return x.to(torch.float32).view(torch.int32).to(torch.int64)


@pytest.mark.task(3)
@pytest.mark.points(1)
def test_pack_depth_id(impl, device):
    depth = torch.tensor(
        [
            0.0,
            -0.0,
            1e-40,
            1e-30,
            0.25,
            0.5,
            0.5,
            0.5,
            1.0,
            3.0,
            3.0000002,
            1e30,
            math.inf,
            0.0,
            7.5,
        ],
        dtype=F64,
    )
    ids = torch.tensor([5, 4, 0, 9, 3, 2, 7, 2**32 - 1, 1, 0, 0, 2, 6, 0, 123456789])
    for dtype in (torch.float32, torch.float64):
        keys = check_tensor(
            impl.pack_depth_id(depth.to(device, dtype), ids.to(device)),
            "pack_depth_id(...)",
            shape=(len(ids),),
            dtype=torch.int64,
            device=device,
        ).cpu()
        d32 = depth.to(dtype).float().double()
        for i in range(len(ids)):
            for j in range(len(ids)):
                want = (d32[i].item(), int(ids[i])) < (d32[j].item(), int(ids[j]))
                if (int(keys[i]) < int(keys[j])) != want:
                    raise AssertionError(
                        f"pack_depth_id ({dtype}): key of (depth {depth[i].item()!r}, id "
                        f"{int(ids[i])}) = {int(keys[i])} vs key of (depth {depth[j].item()!r}, "
                        f"id {int(ids[j])}) = {int(keys[j])}: keys must order by depth first, "
                        f"then by id (depth in the high bits, -0.0 equal to 0.0)"
                    )
        assert_equal(
            keys & MASK, ids, name="pack_depth_id: the id in the low 32 bits", where="fragment"
        )
        assert_equal(
            keys >> 32,
            float_bits(torch.where(d32 > 0, d32, 0.0)),
            name=(
                "pack_depth_id(depth_bits=32): the float32 bit pattern of the depth in the high "
                "bits"
            ),
            where="fragment",
        )
        ids_back = check_tensor(
            impl.triangle_ids(torch.cat([keys, torch.tensor([EMPTY])]).to(device)),
            "triangle_ids(...)",
            shape=(len(ids) + 1,),
            dtype=torch.int64,
            device=device,
        ).cpu()
        assert_equal(
            ids_back,
            torch.cat([ids, torch.tensor([-1])]),
            name="triangle_ids: the low 32 bits, -1 for EMPTY",
            where="key",
        )
    # 24 bits: unorm24 of the window depth in [0, 1]; depths beyond 1 (and +inf) clamp to 1.
    window = torch.cat(
        [
            torch.tensor(
                [0.0, 1.0, 0.5, 1e-9, 1 - 1e-9, 1.0000001, 1.5, 7.5, 1e30, math.inf], dtype=F64
            ),
            torch.rand(200, generator=generator(101), dtype=F64),
        ]
    )
    ids = torch.arange(len(window))
    for dtype in (torch.float32, torch.float64):
        keys = impl.pack_depth_id(window.to(device, dtype), ids.to(device), 24).cpu()
        want = torch.round(window.to(dtype).double().clamp(0, 1) * (2**24 - 1)).to(torch.int64)
        assert_equal(
            keys >> 32,
            want,
            name=(
                f"pack_depth_id(depth_bits=24, {dtype}): round(clamp(depth, 0, 1) * (2**24 - 1)) "
                f"in "
                f"the high bits"
            ),
            where="fragment",
        )
        assert_equal(
            keys & MASK, ids, name="pack_depth_id(24): the id in the low bits", where="fragment"
        )
    # Bad input.
    d = torch.ones(3, device=device)
    i = torch.arange(3, device=device)
    expect_error("depth_bits", impl.pack_depth_id, d, i, 16, case="depth_bits=16")
    expect_error("depth", impl.pack_depth_id, i, i, case="integer depths")
    expect_error("triangle", impl.pack_depth_id, d, i.int(), case="int32 ids")
    expect_error("triangle", impl.pack_depth_id, d, i - 1, case="a negative id")
    expect_error("triangle", impl.pack_depth_id, d, i + 2**32, case="an id of 2**32")
    expect_error("triangle", impl.pack_depth_id, d, i[:2], case="2 ids for 3 depths")


def min_by_sorting(pixel, key, start):
    """Per pixel: the minimum of ``start`` and all its keys, by sorting (the reference)."""
    out = start.clone()
    order = torch.argsort(key, stable=True)
    order = order[torch.argsort(pixel[order], stable=True)]
    p, k = pixel[order], key[order]
    first = torch.ones_like(p, dtype=torch.bool)
    first[1:] = p[1:] != p[:-1]
    out[p[first]] = torch.minimum(out[p[first]], k[first])
    return out


@pytest.mark.task(3)
@pytest.mark.points(1)
def test_depth_test_atomic_min_order_independent(impl, device):
    g = generator(111)
    n, p = 6000, 400
    pixel = torch.randint(0, p, (n,), generator=g)
    depth = torch.randint(0, 50, (n,), generator=g)  # many equal depths: ties by id
    ids = torch.randint(0, 1000, (n,), generator=g)
    key = (depth << 32) | ids
    start = torch.full((p,), EMPTY, dtype=torch.int64)
    start[::7] = (torch.randint(0, 60, (len(start[::7]),), generator=g) << 32) | 5
    want = min_by_sorting(pixel, key, start)

    def run(order, out=None, split=None):
        out = start.clone().to(device) if out is None else out
        parts = [order] if split is None else [order[:split], order[split:]]
        for part in parts:
            result = impl.depth_test(pixel[part].to(device), key[part].to(device), out)
            check_tensor(result, "depth_test(...)", shape=(p,), dtype=torch.int64, device=device)
        return out.cpu()

    got = run(torch.arange(n))
    assert_equal(
        got,
        want,
        name=(
            "depth_test: out[p] = min(out[p], every key of p) (an atomic minimum: with a plain "
            "read-compare-write the last fragment of a pixel wins, not the nearest)"
        ),
        where="pixel",
    )
    for seed in (1, 2):
        perm = torch.randperm(n, generator=generator(seed))
        assert_equal(
            run(perm),
            want,
            name=f"depth_test with the fragments shuffled (seed {seed})",
            where="pixel",
        )
    assert_equal(
        run(torch.arange(n), split=2500),
        want,
        name="depth_test in two calls (chunks)",
        where="pixel",
    )
    out = poisoned((10,), torch.int64, device)
    expect_error(
        "pixel",
        impl.depth_test,
        torch.tensor([3, 10], device=device),
        torch.tensor([1, 2], device=device),
        out,
        case="a pixel index out of range",
    )
    expect_error(
        "pixel",
        impl.depth_test,
        torch.tensor([3, -1], device=device),
        torch.tensor([1, 2], device=device),
        out,
        case="a negative pixel index",
    )
    # Pixels not starting at 0 are fine.
    got = impl.depth_test(
        torch.tensor([4, 9], device=device),
        torch.tensor([7, 8], device=device),
        torch.full((10,), EMPTY, dtype=torch.int64, device=device),
    ).cpu()
    want = torch.full((10,), EMPTY, dtype=torch.int64)
    want[4], want[9] = 7, 8
    assert_equal(got, want, name="depth_test of fragments on pixels 4 and 9 only", where="pixel")
    expect_error(
        "key",
        impl.depth_test,
        torch.tensor([3, 4], device=device),
        torch.tensor([1, 2], device=device, dtype=torch.int32),
        out,
        case="int32 keys",
    )
    expect_error(
        "out",
        impl.depth_test,
        torch.tensor([3, 4], device=device),
        torch.tensor([1, 2], device=device),
        out.float(),
        case="a float32 out",
    )


def layered_scene(seed: int):
    """Screen triangles on the 1/16 grid, each at its own constant depth (facing the camera):
    several layers, exact duplicates (ties), a triangle beyond the far plane and a huge one
    behind everything. Returns (screen (K, 3, 4) float64, width, height)."""
    width, height = 24, 18
    g = generator(seed)
    k = 60
    centre = torch.randint(0, 16 * width, (k, 1, 2), generator=g).to(F64) / 16
    centre[..., 1] = centre[..., 1] % height
    offsets = torch.randint(-96, 97, (k, 3, 2), generator=g).to(F64) / 16
    tris = centre + offsets
    e1, e2 = tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]
    clockwise = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0] > 0  # seen on the y-down screen
    tris = torch.where(clockwise[:, None, None], tris[:, [0, 2, 1]], tris)  # all front faces
    w = torch.randint(2, 40, (k,), generator=g).to(F64) / 4  # view depths, many equal
    z = 1 - 2 / w  # a z_ndc increasing with w
    z[7] = 1.5  # beyond the far plane
    screen = screen4(tris, inv_w=1 / w, z=z)
    duplicates = screen[[3, 11, 20]]
    huge = screen4(
        torch.tensor([[[-1e6, -1e6], [0.0, 1e6], [1e6, -1e6]]], dtype=F64), 1 / 50.0, 0.99
    )
    return torch.cat([screen, duplicates, huge]), width, height


def reference_keys(screen, width, height, depth_bits=32, dtype=torch.float32):
    """Exact keys of fronto-parallel triangles (constant 1/w and z_ndc per triangle), their
    depths computed in ``dtype`` (as the lab does) and rounded once to float32."""
    inside = exact_coverage(screen[..., :2], width, height)
    inv_w = screen[:, 0, 3].to(dtype)
    z = screen[:, 0, 2].to(dtype)
    if depth_bits == 32:
        quantised = float_bits(1 / inv_w)
    else:
        window = (z * 0.5 + 0.5).double()
        quantised = torch.round(window.clamp(0, 1) * (2**24 - 1)).to(torch.int64)
    key = (quantised << 32) | torch.arange(screen.shape[0])
    key = torch.where(inside & (z <= 1)[:, None], key[:, None], EMPTY)
    return key.amin(0)


def probe_largest_tensor(lab, screen, width, height, budget):
    """Run ``rasterize`` and report the largest tensor (bytes) any op created, and the keys."""
    from torch.utils._python_dispatch import TorchDispatchMode

    class Largest(TorchDispatchMode):
        largest = 0

        def __torch_dispatch__(self, func, types, args=(), kwargs=None):
            out = func(*args, **(kwargs or {}))
            for x in out if isinstance(out, (tuple, list)) else [out]:
                if isinstance(x, torch.Tensor):
                    Largest.largest = max(Largest.largest, x.numel() * x.element_size())
            return out

    with Largest():
        keys = lab.rasterize(screen, width, height, memory_budget_bytes=budget)
    return Largest.largest, keys


def given_bounding_boxes(screen, width: int, height: int):
    """In place of the lab's ``bounding_boxes`` (task 2): the boxes by trying every pixel
    centre (``box_reference``)."""
    return box_reference(screen[..., :2].detach().to("cpu", F64), width, height)[0].to(
        screen.device
    )


def given_coverage(screen, width: int, height: int, cull_backfaces: bool = False):
    """In place of the lab's ``coverage`` (task 2), for vertices on the 1/16-pixel grid:
    the exact top-left coverage, fragments grouped by triangle, float64 barycentrics."""
    xy = screen[..., :2].detach().to("cpu", F64)
    inside = exact_coverage(xy, width, height)
    if cull_backfaces:
        v0, v1, v2 = xy[:, 0], xy[:, 1], xy[:, 2]
        area = (v0[:, 0] - v1[:, 0]) * (v2[:, 1] - v1[:, 1]) - (v0[:, 1] - v1[:, 1]) * (
            v2[:, 0] - v1[:, 0]
        )  # E_12(v0)
        inside &= (area > 0)[:, None]
    triangle, pixel = inside.nonzero(as_tuple=True)
    px, py = (pixel % width).to(F64) + 0.5, (pixel // width).to(F64) + 0.5
    t = xy[triangle]

    def edge(i, j):
        return (px - t[:, i, 0]) * (t[:, j, 1] - t[:, i, 1]) - (py - t[:, i, 1]) * (
            t[:, j, 0] - t[:, i, 0]
        )

    e = torch.stack([edge(1, 2), edge(2, 0), edge(0, 1)], -1)
    bary = e / e.sum(-1, keepdim=True)
    return (
        triangle.to(screen.device),
        pixel.to(screen.device),
        bary.to(screen.device, screen.dtype),
    )


def rasterize_given_coverage(lab, screen, width: int, height: int, **kwargs):
    """``lab.rasterize`` next to the lab, with the given ``coverage`` and ``bounding_boxes``
    in place of the lab's (task 2): task 3 is graded on its own. Returns ``(keys, out)``."""
    with replaced(lab, {"coverage": given_coverage, "bounding_boxes": given_bounding_boxes}):
        keys = lab.rasterize(screen, width, height, **kwargs)
    return keys, kwargs.get("out")


def rasterized(impl, screen, width: int, height: int, **kwargs):
    """The lab's ``rasterize`` with task 2 given (see ``rasterize_given_coverage``)."""
    keys, out = impl.probe(rasterize_given_coverage, screen, width, height, **kwargs)
    if "out" in kwargs:
        kwargs["out"].copy_(out)  # the buffer the lab wrote, next to it
    return keys


_CHUNKS: list = []


def recording_coverage(screen, width: int, height: int, cull_backfaces: bool = False):
    """In place of the lab's ``coverage``: remembers each chunk of triangles ``rasterize``
    hands it (a CPU copy) and returns no fragments."""
    _CHUNKS.append(screen.detach().to("cpu"))
    none = torch.zeros(0, dtype=torch.int64, device=screen.device)
    return none, none.clone(), torch.zeros(0, 3, dtype=screen.dtype, device=screen.device)


def rasterize_chunks(lab, screen, width: int, height: int, **kwargs):
    """``lab.rasterize`` with the given ``bounding_boxes`` and a ``coverage`` that records
    the chunks. Returns the chunks (a list of (k_i, 3, 4) CPU tensors)."""
    _CHUNKS.clear()
    with replaced(lab, {"coverage": recording_coverage, "bounding_boxes": given_bounding_boxes}):
        lab.rasterize(screen, width, height, **kwargs)
    return list(_CHUNKS)


def in_screen_order(chunks: list, screen) -> list:
    """``chunks`` put in the order in which they tile ``screen`` (K, 3, 4) as consecutive
    slices, or as given when no order does (a depth-first search: a chunk equal to one
    already tried at a position is not tried again there)."""
    chunks = [c.cpu() for c in chunks]

    def tile(start: int, left: list):
        if not left:
            return [] if start == screen.shape[0] else None
        tried = []
        for i, chunk in enumerate(left):
            end = start + chunk.shape[0]
            fits = end <= screen.shape[0] and torch.equal(screen[start:end], chunk)
            if fits and not any(torch.equal(chunk, t) for t in tried):
                tried.append(chunk)
                rest = tile(end, left[:i] + left[i + 1 :])
                if rest is not None:
                    return [chunk, *rest]
        return None

    return tile(0, chunks) or chunks


def check_chunks(impl, screen, width, height, budget, case, device):
    """The chunks of ``rasterize``: consecutive slices of the triangles (walked in any
    order: the atomic minimum makes the keys independent of it), each holding at most
    ``budget // BYTES_PER_FRAGMENT`` box pixels (or one triangle), and not needlessly many
    of them."""
    kwargs = {} if budget is None else {"memory_budget_bytes": budget}
    budget = 2**28 if budget is None else budget
    chunks = impl.probe(rasterize_chunks, screen.to(device), width, height, **kwargs)
    what = f"rasterize ({case}, memory_budget_bytes={budget}, {width}x{height})"
    chunks = in_screen_order(chunks, screen.cpu())
    got = torch.cat(chunks) if chunks else screen[:0].cpu()
    assert got.shape == screen.shape and torch.equal(got, screen.cpu()), (
        f"{what}: the chunks handed to coverage must be consecutive slices of the triangles, "
        f"together every triangle once; got chunks of "
        f"{[c.shape[0] for c in chunks]} triangles for {screen.shape[0]}"
    )
    boxes, empty = box_reference(screen[..., :2].cpu().to(F64), width, height)
    pixels = torch.where(empty, 0, (boxes[:, 2] - boxes[:, 0]) * (boxes[:, 3] - boxes[:, 1]))
    per_chunk = max(1, budget // BYTES_PER_FRAGMENT)
    sizes, first = [], 0
    for chunk in chunks:
        k = chunk.shape[0]
        size = int(pixels[first : first + k].sum())
        assert k <= 1 or size <= per_chunk, (
            f"{what}: a chunk of {k} triangles (from triangle {first}) whose boxes hold {size} "
            f"pixels, more than budget // BYTES_PER_FRAGMENT = {per_chunk} (only a single "
            f"triangle may exceed it). A box holds (col_end - col_begin) * (row_end - "
            f"row_begin) pixels."
        )
        sizes.append(size)
        first += k
    total = int(pixels.sum())
    enough = 2 * math.ceil(total / per_chunk) + 1  # adjacent chunks could not be merged
    busy = sum(1 for c in chunks if c.shape[0])
    assert busy <= enough, (
        f"{what}: {busy} chunks for boxes of {total} pixels in all (chunk pixels "
        f"{sizes[:12]}...), where {math.ceil(total / per_chunk)} chunks of at most "
        f"{per_chunk} pixels would do: put as many triangles in a chunk as fit, a Python "
        f"loop over single triangles is slow"
    )


def cells(width, height, cols, rows):
    """(K, 3, 4) screen triangles, one inside each listed pixel (a box of exactly it)."""
    tris = [
        [[c + 0.3, r + 0.3], [c + 0.5, r + 0.7], [c + 0.7, r + 0.3]] for r in rows for c in cols
    ]
    return screen4(torch.tensor(tris, dtype=F64), inv_w=0.5, z=0.2).float()


def check_chunking(impl, device):
    """The chunks ``rasterize`` hands to ``coverage`` (given bounding_boxes, a coverage that
    only records what it is handed)."""
    # 48 one-pixel triangles in the top right of a 24x18 screen.
    small = cells(24, 18, range(12, 24), range(4))
    for budget in (None, 1, 4 * BYTES_PER_FRAGMENT, 5 * BYTES_PER_FRAGMENT - 1, 2**14):
        check_chunks(impl, small, 24, 18, budget, "48 one-pixel triangles", device)
    # Triangles whose boxes (the whole 24x18 screen) each exceed the budget: one per chunk.
    full = screen4(torch.tensor([[[-2.0, -2.0], [4.0, 40.0], [30.0, -2.0]]] * 6, dtype=F64)).float()
    for budget in (100 * BYTES_PER_FRAGMENT, 1000 * BYTES_PER_FRAGMENT):
        check_chunks(impl, full, 24, 18, budget, "6 full-screen triangles", device)
    # The default budget, 2**28 bytes: at most 2**20 pixels a chunk (20 boxes of 256x256).
    many = screen4(
        torch.tensor([[[-1.0, -1.0], [100.0, 600.0], [600.0, -1.0]]] * 20, dtype=F64)
    ).float()
    check_chunks(impl, many, 256, 256, None, "20 triangles over a 256x256 screen", device)
    mixed = torch.cat([small, full, small[:5], full[:1]])
    check_chunks(impl, mixed, 24, 18, 30 * BYTES_PER_FRAGMENT, "small and large", device)


@pytest.mark.task(3)
@pytest.mark.points(1)
def test_rasterize_visibility_buffer(impl, device):
    # With coverage and bounding_boxes given (task 2), except where the memory the lab's own
    # chunking allocates is measured.
    screen, width, height = layered_scene(121)
    for depth_bits in (32, 24):
        for dtype in (torch.float32, torch.float64):
            want = reference_keys(screen.float().double(), width, height, depth_bits, dtype)
            s = screen.float().to(device, dtype)
            out = poisoned((width * height,), torch.int64, device)
            keys = rasterized(impl, s, width, height, depth_bits=depth_bits, out=out)
            check_tensor(
                keys, "rasterize(...)", shape=(width * height,), dtype=torch.int64, device=device
            )
            case = f"rasterize (depth_bits={depth_bits}, {dtype})"
            assert_equal(
                out, keys, name=f"{case}: the returned keys must be `out` itself", where="pixel"
            )
            assert_image_close(
                keys,
                want,
                exact=True,
                kind="id",
                image_shape=(height, width),
                name=(
                    f"{case}: keys of a layered scene (fronto-parallel triangles, exact duplicates "
                    f"at the end: equal depths go to the lower id; one triangle beyond the far "
                    f"plane). EMPTY = {EMPTY} where nothing is drawn"
                ),
                where="pixel",
            )
    # Triangle order and chunking do not matter: the same keys bit for bit.
    perm = torch.randperm(screen.shape[0], generator=generator(122))
    shuffled = screen[perm].float().to(device)
    want = reference_keys(screen[perm].float().double(), width, height)
    assert_equal(
        rasterized(impl, shuffled, width, height),
        want,
        name="rasterize with the triangles shuffled",
        where="pixel",
    )
    full = rasterized(impl, screen.float().to(device), width, height).cpu()
    for budget in (2**10, 2**14):
        keys = rasterized(
            impl, screen.float().to(device), width, height, memory_budget_bytes=budget
        )
        assert_equal(
            keys, full, name=f"rasterize with memory_budget_bytes={budget} (chunks)", where="pixel"
        )
    # Memory: 12 triangles over the whole 8x8 screen (one of them 1e6 pixels across).
    stack = screen4(
        torch.tensor(
            [[[-2.0, -2.0], [4.0, 30.0], [30.0, -2.0]]] * 11
            + [[[-1e6, -1e6], [0.0, 1e6], [1e6, -1e6]]],
            dtype=F64,
        ),
        inv_w=1 / torch.arange(1.0, 13.0, dtype=F64),
    )
    budget = 2**13
    largest, keys = impl.probe(probe_largest_tensor, stack.float().to(device), 8, 8, budget)
    assert_equal(
        keys,
        reference_keys(stack.float().double(), 8, 8),
        name=("rasterize of 12 full-screen triangles with a small memory budget"),
        where="pixel",
    )
    bound = max(budget, 128 * 8 * 8)
    assert largest <= bound, (
        f"rasterize with memory_budget_bytes={budget}: an op created a tensor of {largest} "
        f"bytes for 12 triangles over 8x8 pixels (allowed: the budget, or what one triangle's "
        f"clamped box of at most 8x8 pixels needs). Chunk the triangles by their box sizes."
    )
    # 96 slivers along the bottom row of a 64x64 screen: boxes 64 columns wide, 1 row high
    # (column 0 .. 64, row 63 .. 64): a box's size is its width times its height.
    sliver = torch.tensor([[-2.0, 63.25], [30.0, 63.75], [70.0, 63.25]], dtype=F64)
    slivers = screen4(
        sliver.expand(96, 3, 2).contiguous(), inv_w=1 / torch.arange(1.0, 97.0, dtype=F64)
    )
    budget = 2**15
    largest, keys = impl.probe(probe_largest_tensor, slivers.float().to(device), 64, 64, budget)
    assert_equal(
        keys,
        reference_keys(slivers.float().double(), 64, 64),
        name=("rasterize of 96 slivers along the bottom row with a small memory budget"),
        where="pixel",
    )
    bound = max(budget, 128 * 64, 8 * 64 * 64)
    assert largest <= bound, (
        f"rasterize with memory_budget_bytes={budget}: an op created a tensor of {largest} "
        f"bytes for 96 triangles whose boxes span 64 columns x 1 row of a 64x64 screen "
        f"(allowed: the budget, what one triangle's box of 64 pixels needs, or the (64 * 64,) "
        f"int64 buffer). A box holds (col_end - col_begin) * (row_end - row_begin) pixels."
    )
    # The chunks themselves, by their box sizes.
    check_chunking(impl, device)
    # Culling, an empty scene, bad input.
    reversed_ = screen[:, [0, 2, 1]].float().to(device)
    culled = rasterized(impl, reversed_, width, height, cull_backfaces=True).cpu()
    assert bool((culled == EMPTY).all()), (
        "rasterize(cull_backfaces=True) of clockwise (back-facing) triangles draws nothing"
    )
    empty = rasterized(impl, torch.zeros(0, 3, 4, device=device), 5, 3)
    assert_equal(empty, torch.full((15,), EMPTY), name="rasterize of no triangles", where="pixel")
    expect_error(
        "depth_bits", impl.rasterize, shuffled, width, height, depth_bits=16, case="depth_bits=16"
    )
    expect_error(
        "out",
        impl.rasterize,
        shuffled,
        width,
        height,
        out=torch.zeros(width * height - 1, dtype=torch.int64, device=device),
        case="an out of the wrong size",
    )
    expect_error(
        "memory_budget_bytes",
        impl.rasterize,
        shuffled,
        width,
        height,
        memory_budget_bytes=0,
        case="memory_budget_bytes=0",
    )


# ---------------------------------------------------------------------------------------
# Task 4: perspective-correct interpolation and shading


@pytest.mark.task(4)
@pytest.mark.points(1)
def test_perspective_correct_formula(impl, device):
    g = generator(131)
    b = torch.rand(2, 50, 3, generator=g, dtype=F64)
    b = b / b.sum(-1, keepdim=True)
    inv_w = torch.rand(2, 50, 3, generator=g, dtype=F64) * 10 + 0.01
    q = b * inv_w
    want = q / q.sum(-1, keepdim=True)
    for dtype, tol in ((torch.float32, 1e-6), (torch.float64, 1e-14)):
        got = check_tensor(
            impl.perspective_correct(b.to(device, dtype), inv_w.to(device, dtype)),
            "perspective_correct(...)",
            shape=(2, 50, 3),
            dtype=dtype,
            device=device,
        )
        assert_close(
            got,
            want,
            atol=tol,
            name=(f"perspective_correct ({dtype}): (b_i / w_i) / sum_j (b_j / w_j)"),
            where="point",
        )
    # Equal depths change nothing; corners stay corners.
    same = impl.perspective_correct(b[0].to(device), torch.full((50, 3), 0.25, device=device))
    assert_close(same, b[0], atol=1e-6, name="perspective_correct with equal 1/w", where="point")
    corners = impl.perspective_correct(torch.eye(3, device=device), inv_w[0, :3].float().to(device))
    assert_close(
        corners, torch.eye(3), atol=0, name="perspective_correct at the corners", where="corner"
    )


def slanted_scene(device, dtype):
    """A textured floor receding to the horizon (it crosses the near plane) and a wall at a
    grazing angle: per-vertex UVs are linear in position."""
    vertices = torch.tensor(
        [
            [-6.0, -1.0, 2.0],
            [6.0, -1.0, 2.0],
            [6.0, -1.0, -30.0],
            [-6.0, -1.0, -30.0],
            [2.0, -1.0, -1.0],
            [2.5, 3.0, -1.0],
            [9.0, 3.0, -20.0],
            [8.0, -1.0, -20.0],
        ],
        dtype=F64,
    )
    faces = torch.tensor([[0, 1, 2], [0, 2, 3], [4, 7, 6], [4, 6, 5]])
    uv = torch.stack([vertices[:, 0] * 0.5 + vertices[:, 2] * 0.1, vertices[:, 2] * 0.25 + 1], -1)
    camera = Camera(
        eye=(0.0, 0.2, 0.5),
        target=(0.5, -0.3, -5.0),
        fov_y=60.0,
        width=40,
        height=30,
        near=0.05,
        far=100.0,
    )
    return Mesh(vertices.to(device, dtype), faces.to(device)), uv, camera


@pytest.mark.task(4)
@pytest.mark.points(1)
def test_perspective_correct_exact_surface_point(impl, reference, device):
    # resolve_pixels on the reference's visibility buffer and clipped triangles (tasks 1-3):
    # the barycentrics must be those of the exact point the pixel's ray meets.
    for dtype, tol in ((torch.float32, 2e-4), (torch.float64, 1e-9)):
        mesh, uv, camera = slanted_scene(device, dtype)
        face, bary = resolved(impl, reference, mesh, camera)
        covered = face >= 0
        assert int(covered.sum()) > 600, "test set-up: the slanted planes fill the view"
        rays = primary_rays(camera, device="cpu", dtype=F64)
        tris = mesh.triangles().cpu().to(F64)
        f = face.reshape(-1)[covered.reshape(-1)]
        exact, _ = ray_plane_barycentrics(
            tris[f], rays.origins[covered.reshape(-1)], rays.directions[covered.reshape(-1)]
        )
        got = bary[covered].double()
        case = f"resolve_pixels ({dtype}, on a visibility buffer and clipped triangles given)"
        assert bool((exact.amin(-1) > -1e-3).all()), (
            f"{case}: a pixel shows a face its ray does not pass through"
        )
        assert_close(
            got,
            exact,
            atol=tol,
            name=(
                f"{case}: barycentrics of the visible face at each pixel centre vs the exact point "
                f"where the pixel's ray meets that face (float64). Screen-space weights are wrong "
                f"on a receding plane: divide by w (perspective_correct)"
            ),
            where="covered pixel",
        )
        texcoords = check_tensor(
            impl.interpolate(uv.to(device, dtype), mesh.faces, face.to(device), bary.to(device)),
            "interpolate(...)",
            shape=(camera.height, camera.width, 2),
            dtype=dtype,
            device=device,
        ).cpu()
        want = (exact[..., None] * uv[mesh.faces.cpu()[f]]).sum(1)
        assert_close(
            texcoords[covered],
            want,
            atol=tol * 20,
            name=(f"interpolate ({dtype}): UVs at the visible points vs their exact values"),
            where="covered pixel",
        )
        assert bool((texcoords[~covered] == 0).all()), "interpolate: 0 where face == -1"
        keys, screen, source, _ = reference_raster(reference, mesh, camera)
        k = torch.where(keys == EMPTY, 0, keys & MASK).cpu()
        want_face = torch.where(keys.cpu() == EMPTY, -1, source.cpu()[k]).reshape(face.shape)
        assert_equal(
            face,
            want_face,
            name=f"{case}: face = source[id of the key], -1 where the key is EMPTY",
            where="pixel",
        )
        assert bool((bary[~covered] == 0).all()), f"{case}: bary 0 where face == -1"
        check_one_triangle(impl, device, dtype, tol)


def check_one_triangle(impl, device, dtype, tol):
    """resolve_pixels and interpolate with one triangle (and with none): keys at its corners
    and on its medians, where some sums of edge functions are exactly 0 (only the sum of all
    three is the triangle's area), empty keys elsewhere."""
    width = height = 12
    xy = torch.tensor([[1.5, 1.5], [9.5, 1.5], [1.5, 9.5]], dtype=F64)
    inv_w = torch.tensor([1.0, 0.5, 0.25], dtype=F64)
    screen = torch.cat([xy, torch.full((3, 1), 0.5, dtype=F64), inv_w[:, None]], -1)[None]
    weights = torch.tensor([[[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]]], dtype=F64)
    source = torch.tensor([3])
    # corners, the centroid-ish middle, points on the medians and halfway up
    points = [(1, 1), (1, 9), (9, 1), (5, 3), (5, 1), (1, 5), (3, 5), (5, 5), (3, 3)]
    keys = torch.full((height * width,), EMPTY, dtype=torch.int64)
    for row, col in points:
        keys[row * width + col] = (1 << 32) | 0
    covered = keys != EMPTY
    pixel = torch.arange(height * width)
    px, py = (pixel % width).to(F64) + 0.5, (pixel // width).to(F64) + 0.5
    v = xy

    def edge(i, j):
        return (px - v[i, 0]) * (v[j, 1] - v[i, 1]) - (py - v[i, 1]) * (v[j, 0] - v[i, 0])

    e = torch.stack([edge(1, 2), edge(2, 0), edge(0, 1)], -1)
    q = e / e.sum(-1, keepdim=True) * inv_w
    mu = q / q.sum(-1, keepdim=True)
    want_bary = torch.where(covered[:, None], mu @ weights[0], 0.0).reshape(height, width, 3)
    want_face = torch.where(covered, 3, -1).reshape(height, width)
    case = (
        f"resolve_pixels ({dtype}) of one triangle {xy.tolist()} (1/w = {inv_w.tolist()}), "
        f"keys at its corners and medians"
    )
    result = impl.resolve_pixels(
        keys.to(device),
        screen.to(device, dtype),
        source.to(device),
        weights.to(device, dtype),
        width,
        height,
    )
    face = check_tensor(
        result[0], f"{case}: face", shape=(height, width), dtype=torch.int64, device=device
    ).cpu()
    bary = check_tensor(
        result[1], f"{case}: bary", shape=(height, width, 3), dtype=dtype, device=device
    ).cpu()
    assert_equal(face, want_face, name=f"{case}: face (source, -1 where empty)", where="pixel")
    assert_close(
        bary.double(),
        want_bary,
        atol=tol,
        name=(
            f"{case}: perspective-correct barycentrics (a pixel centre on a corner or a median "
            f"is a pixel like any other; 0 where empty)"
        ),
        where="pixel",
    )
    # interpolate on a one-face mesh: its empty pixels index no other face.
    values = torch.tensor([[1.0, -2.0], [4.0, 0.5], [-3.0, 8.0]], dtype=F64)
    got = check_tensor(
        impl.interpolate(
            values.to(device, dtype),
            torch.tensor([[0, 1, 2]], device=device),
            torch.where(covered, 0, -1).reshape(height, width).to(device),
            want_bary.to(device, dtype),
        ),
        "interpolate(...)",
        shape=(height, width, 2),
        dtype=dtype,
        device=device,
    ).cpu()
    assert_close(
        got.double(),
        want_bary @ values,
        atol=tol * 20,
        name=f"interpolate ({dtype}) on a one-face mesh, 0 where face == -1",
        where="pixel",
    )
    # Nothing rasterized: every pixel empty.
    result = impl.resolve_pixels(
        torch.full((height * width,), EMPTY, dtype=torch.int64, device=device),
        torch.zeros(0, 3, 4, device=device, dtype=dtype),
        torch.zeros(0, dtype=torch.int64, device=device),
        torch.zeros(0, 3, 3, device=device, dtype=dtype),
        width,
        height,
    )
    face = check_tensor(
        result[0],
        "resolve_pixels of no triangles: face",
        shape=(height, width),
        dtype=torch.int64,
        device=device,
    ).cpu()
    bary = check_tensor(
        result[1],
        "resolve_pixels of no triangles: bary",
        shape=(height, width, 3),
        dtype=dtype,
        device=device,
    ).cpu()
    assert bool((face == -1).all()) and bool((bary == 0).all()), (
        f"resolve_pixels ({dtype}) of no triangles (every key EMPTY): face -1 and bary 0 everywhere"
    )


def resolved(impl, reference, mesh: Mesh, camera: Camera):
    """``resolve_pixels`` on the reference's tasks 1-3, checked: (face, bary) on the CPU."""
    keys, screen, source, weights = reference_raster(reference, mesh, camera)
    result = impl.resolve_pixels(keys, screen, source, weights, camera.width, camera.height)
    assert isinstance(result, tuple) and len(result) == 2, (
        "resolve_pixels: expected a tuple (face, bary)"
    )
    shape = (camera.height, camera.width)
    face = check_tensor(
        result[0],
        "resolve_pixels(...)[0] (face)",
        shape=shape,
        dtype=torch.int64,
        device=mesh.device,
    )
    bary = check_tensor(
        result[1],
        "resolve_pixels(...)[1] (bary)",
        shape=(*shape, 3),
        dtype=mesh.dtype,
        device=mesh.device,
    )
    return face.cpu(), bary.cpu()


def sphere_scene(device):
    mesh = load_scene("icosphere", device="cpu", dtype=F64, level=1).mesh
    camera = Camera(
        eye=(0.4, 0.9, 3.2),
        target=(0.0, 0.0, 0.0),
        width=40,
        height=36,
        fov_y=45.0,
        near=0.1,
        far=20.0,
    )
    return Mesh(mesh.vertices.float().to(device), mesh.faces.to(device)), camera


@pytest.mark.task(4)
@pytest.mark.points(1)
def test_shade_flat_smooth(impl, reference, device):
    mesh, camera = sphere_scene(device)
    face, bary = (x.cpu() for x in reference.rasterize_mesh(mesh, camera))  # tasks 1-4 given
    covered = face >= 0
    light = torch.tensor([0.6, 0.8, 0.5])
    l64 = (light / light.norm()).double()
    tris = mesh.triangles().cpu().double()
    normals = torch.linalg.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    fc = face.clamp(min=0)
    flat_want = torch.where(
        covered,
        ((normals / normals.norm(dim=-1, keepdim=True))[fc] * l64).sum(-1).clamp(min=0),
        0.0,
    )
    flat = check_tensor(
        impl.shade(mesh, face.to(device), bary.to(device), light.to(device), False),
        "shade(..., smooth=False)",
        shape=face.shape,
        dtype=torch.float32,
        device=device,
    ).cpu()
    assert_close(
        flat,
        flat_want,
        atol=2e-6,
        name=("shade(smooth=False): max(0, n . l) with the unit face normal (v1 - v0) x (v2 - v0)"),
        where="pixel",
    )
    vn = torch.zeros_like(mesh.vertices.cpu().double()).index_add_(
        0, mesh.faces.cpu().reshape(-1), normals.repeat_interleave(3, 0)
    )
    vn = vn / vn.norm(dim=-1, keepdim=True)
    corners = vn[mesh.faces.cpu()[fc]]
    n = (bary.double()[..., None] * corners).sum(-2)
    n = n / n.norm(dim=-1, keepdim=True)
    smooth_want = torch.where(covered, (n * l64).sum(-1).clamp(min=0), 0.0)
    smooth = impl.shade(mesh, face.to(device), bary.to(device), light.to(device), True).cpu()
    assert_close(
        smooth,
        smooth_want,
        atol=2e-5,
        name=(
            "shade(smooth=True): max(0, n . l) with the interpolated vertex normals (each the "
            "normalised sum of its faces' (v1 - v0) x (v2 - v0)), normalised again after "
            "interpolation"
        ),
        where="pixel",
    )
    # Smooth normals follow the sphere better than flat ones.
    points = (bary.double()[..., None] * tris[fc]).sum(-2)
    sphere = torch.where(
        covered, ((points / points.norm(dim=-1, keepdim=True)) * l64).sum(-1).clamp(min=0), 0.0
    )
    assert (smooth - sphere).abs().mean() < 0.5 * (flat - sphere).abs().mean(), (
        "shade: smooth shading should approximate the sphere much better than flat shading"
    )
    # A one-face mesh: empty pixels index no other face.
    one = Mesh(
        torch.tensor([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], device=device),
        torch.tensor([[0, 1, 2]], device=device),
    )
    one_face = torch.tensor([[0, -1], [-1, 0]], device=device)
    one_bary = torch.tensor([[[0.2, 0.3, 0.5], [0.0] * 3], [[0.0] * 3, [1.0, 0.0, 0.0]]])
    toward = torch.tensor([0.0, 0.6, 0.8], device=device)  # n = +z: n . l = 0.8
    for smooth in (False, True):
        got = impl.shade(one, one_face, one_bary.to(device), toward, smooth).cpu()
        want = torch.tensor([[0.8, 0.0], [0.0, 0.8]])
        assert_close(
            got,
            want,
            atol=1e-6,
            name=f"shade(smooth={smooth}) of a one-face mesh (normal +z), 0 where face == -1",
            where="pixel",
        )
    expect_error(
        "light_direction",
        impl.shade,
        mesh,
        face.to(device),
        bary.to(device),
        light[:2].to(device),
        case="a light direction of shape (2,)",
    )


# ---------------------------------------------------------------------------------------
# Task 5: raster vs ray-traced visibility, hybrid shadows


@pytest.mark.task(5)
@pytest.mark.points(1)
def test_traced_visibility_primary_hits(impl, device):
    _, camera = scene("suzanne")
    traced = check_tensor(
        impl.traced_visibility(trace_suzanne, camera, device),
        "traced_visibility(...)",
        shape=(camera.height, camera.width),
        dtype=torch.int64,
        device=device,
    ).cpu()
    rays = primary_rays(camera, device="cpu", dtype=torch.float32)
    want = trace_suzanne(rays.origins, rays.directions, rays.t_min, rays.t_max).triangle
    assert_image_close(
        traced.reshape(-1),
        want,
        exact=True,
        kind="id",
        image_shape=(camera.height, camera.width),
        name=(
            "traced_visibility: the triangle the tracer returns for each pixel's primary ray "
            "(course.core.camera.primary_rays, row-major)"
        ),
        where="pixel",
    )
    expect_error(
        "trace",
        impl.traced_visibility,
        "not a tracer",
        camera,
        device,
        case="a string as the tracer",
    )


# ---------------------------------------------------------------------------------------
# Task 6: end to end, the lab's whole pipeline


STAGES = ("to_clip_space", "clip_triangles", "to_screen", "rasterize", "resolve_pixels")


def reference_stages(reference, mesh: Mesh, camera: Camera) -> dict:
    """What each stage of ``rasterize_mesh`` returns, by the reference."""
    mvp = camera.view_projection(F64).to(mesh.device)
    clip = reference.to_clip_space(mesh.vertices, mvp)
    clipped, source, weights = reference.clip_triangles(clip[mesh.faces])
    screen = reference.to_screen(clipped, camera.width, camera.height)
    keys = reference.rasterize(screen, camera.width, camera.height)
    return {
        "to_clip_space": clip,
        "clip_triangles": (clipped, source, weights),
        "to_screen": screen,
        "rasterize": keys,
        "resolve_pixels": reference.resolve_pixels(
            keys, screen, source, weights, camera.width, camera.height
        ),
    }


_BUDGETS: list = []


def recording_rasterize(
    screen,
    width: int,
    height: int,
    *,
    depth_bits: int = 32,
    cull_backfaces: bool = False,
    memory_budget_bytes: int = 2**28,
    out=None,
):
    """In place of the lab's ``rasterize``: remembers the memory budget it is given and
    draws nothing."""
    _BUDGETS.append(memory_budget_bytes)
    return torch.full((width * height,), EMPTY, dtype=torch.int64, device=screen.device)


def rasterize_mesh_budgets(lab, mesh: Mesh, camera: Camera, **kwargs):
    """The ``memory_budget_bytes`` that ``lab.rasterize_mesh(mesh, camera, **kwargs)``
    hands to ``rasterize``."""
    _BUDGETS.clear()
    with replaced(lab, {"rasterize": recording_rasterize}):
        lab.rasterize_mesh(mesh, camera, **kwargs)
    return list(_BUDGETS)


def rasterize_mesh_with_stage(lab, stage: str, value, mesh: Mesh, camera: Camera):
    """``lab.rasterize_mesh`` next to the lab, its ``stage`` returning ``value`` (the
    reference's result of that stage) whatever it is given."""
    with replaced(lab, {stage: lambda *args, **kwargs: value}):
        return lab.rasterize_mesh(mesh, camera)


def wrong_stage(impl, reference, mesh: Mesh, camera: Camera, check) -> str:
    """Which stage of the lab's ``rasterize_mesh`` is wrong: swapping a stage for the
    reference's result repairs the image when the mistake is in that stage or before it,
    so the first stage whose swap makes ``check(face, bary)`` pass is the wrong one."""
    stages = reference_stages(reference, mesh, camera)
    for stage in STAGES:
        face, bary = impl.probe(rasterize_mesh_with_stage, stage, stages[stage], mesh, camera)
        try:
            check(face.cpu(), bary.cpu())
        except AssertionError:
            continue
        return (
            f"the step that is wrong: {stage} (with the reference's result of {stage} in "
            f"place of yours the image is right; with that of any step before it, not)"
        )
    return (
        "no single step repairs the image when its result is the reference's: see the "
        "failing tests of each step's task"
    )


def diagnosed(impl, reference, mesh: Mesh, camera: Camera, what: str, check):
    """``check`` the lab's ``rasterize_mesh``; a failure names the step that is wrong."""
    face, bary = pipeline(impl, mesh, camera)
    try:
        return check(face, bary)
    except AssertionError as error:
        hint = wrong_stage(impl, reference, mesh, camera, check)
        raise AssertionError(f"{what}: {hint}.\n{error}") from None


@pytest.mark.task(END_TO_END)
@pytest.mark.points(1)
def test_rasterize_mesh_matches_ray_tracing(impl, reference, device):
    # Your rasterize_mesh: to_clip_space, clip_triangles, to_screen, rasterize (coverage,
    # pack_depth_id, depth_test) and resolve_pixels together; every other task's tests give
    # a task the reference's results of the tasks before it. A failure names the step.
    mesh, camera = scene("suzanne")
    mesh = mesh.to(device)
    rate = diagnosed(
        impl,
        reference,
        mesh,
        camera,
        "rasterize_mesh of Suzanne (96x64)",
        lambda face, _: check_visibility(
            face, mesh.to("cpu"), camera, "rasterize_mesh of Suzanne (96x64)", agree=0.995
        ),
    )
    face24, _ = pipeline(impl, mesh, camera, depth_bits=24)
    check_visibility(
        face24, mesh.to("cpu"), camera, "rasterize_mesh(depth_bits=24) of Suzanne", agree=0.99
    )
    culled, _ = pipeline(impl, mesh, camera, cull_backfaces=True)
    check_visibility(
        culled, mesh.to("cpu"), camera, "rasterize_mesh(cull_backfaces=True) of Suzanne", agree=0.99
    )
    print(f"raster vs float64 ray tracing: {rate:.3%} of pixels differ")
    for kwargs, want in (({}, 2**28), ({"memory_budget_bytes": 3000}, 3000)):
        budgets = impl.probe(rasterize_mesh_budgets, mesh, camera, **kwargs)
        assert budgets == [want], (
            f"rasterize_mesh(..., {kwargs}) handed rasterize memory_budget_bytes {budgets} "
            f"(one call expected, with {want}: the default is 2**28)"
        )
    if device != "cpu":
        face, _ = pipeline(impl, mesh, camera)
        cpu_face, _ = pipeline(impl, mesh.to("cpu"), camera)
        assert_equal(
            face,
            cpu_face,
            name="rasterize_mesh: CUDA vs CPU id buffers (bit-identical)",
            where="pixel",
        )
    # Perspective-correct barycentrics through the whole pipeline, the near plane crossed.
    for dtype, tol in ((torch.float32, 2e-4), (torch.float64, 1e-9)):
        slanted, _, slanted_camera = slanted_scene(device, dtype)
        what = f"rasterize_mesh ({dtype}) of a floor crossing the near plane"
        diagnosed(
            impl,
            reference,
            slanted,
            slanted_camera,
            what,
            exact_barycentrics(slanted, slanted_camera, tol, what),
        )


def exact_barycentrics(mesh: Mesh, camera: Camera, tol: float, what: str):
    """A check of ``(face, bary)``: the barycentrics of the exact point where each pixel's
    ray meets the face shown there, within ``tol``."""
    rays = primary_rays(camera, device="cpu", dtype=F64)
    tris = mesh.triangles().cpu().to(F64)

    def check(face, bary):
        covered = face >= 0
        assert int(covered.sum()) > 600, f"{what}: the slanted planes fill the view"
        f = face.reshape(-1)[covered.reshape(-1)]
        exact, _ = ray_plane_barycentrics(
            tris[f], rays.origins[covered.reshape(-1)], rays.directions[covered.reshape(-1)]
        )
        assert_close(
            bary[covered].double(),
            exact,
            atol=tol,
            name=(f"{what}: barycentrics vs the exact ray/plane point"),
            where="covered pixel",
        )

    return check


@pytest.mark.task(END_TO_END)
@pytest.mark.points(1)
def test_raster_far_from_origin_fp64_and_tiny_viewports(impl, device):
    mesh, camera = scene("suzanne_far")
    face, _ = pipeline(impl, mesh.to(device), camera)
    check_visibility(
        face,
        mesh,
        camera,
        "rasterize_mesh of Suzanne 1e5 from the origin (float32, camera beside it)",
        agree=0.99,
        tol=1e-3,
    )
    near, near_camera = scene("suzanne")
    face32, _ = pipeline(impl, near.to(device), near_camera)
    face64, _ = pipeline(impl, near.to(device, F64), near_camera)
    assert_fraction(
        face32 != face64,
        name="rasterize_mesh: float32 vs float64 id buffers differ",
        at_most=0.005,
        where="pixel",
    )
    # A 1x1 viewport: the one primary ray; a camera looking away: nothing.
    one = dataclasses.replace(near_camera, width=1, height=1)
    face, bary = pipeline(impl, near.to(device), one)
    _, _, ref = reference_visibility(near, one)
    assert int(face.reshape(-1)[0]) == int(ref[0]), (
        f"rasterize_mesh on a 1x1 viewport: expected triangle {int(ref[0])} (the ray through "
        f"the centre), got {int(face.reshape(-1)[0])}"
    )
    away = dataclasses.replace(
        near_camera, target=tuple(2 * e - t for e, t in zip(near_camera.eye, near_camera.target))
    )
    face, bary = pipeline(impl, near.to(device), away)
    assert bool((face == -1).all()) and bool((bary == 0).all()), (
        "rasterize_mesh with the mesh behind the camera: every pixel empty (-1, bary 0)"
    )
    # NaN vertices: their triangles vanish, the rest is unchanged.
    vertices = near.vertices.clone()
    vertices[near.faces[:50].reshape(-1)] = math.nan
    broken = Mesh(vertices, near.faces)
    face_nan, _ = pipeline(impl, broken.to(device), near_camera)
    nan_faces = torch.isnan(vertices[near.faces]).any(-1).any(-1).nonzero()[:, 0]
    assert not bool(torch.isin(face_nan, nan_faces).any()), (
        "rasterize_mesh: triangles with NaN vertices must cover nothing"
    )
    expect_error(
        "mesh",
        impl.rasterize_mesh,
        (near.vertices, near.faces),
        near_camera,
        case="a tuple instead of a Mesh",
    )


def reference_shadows(mesh: Mesh, camera: Camera, light):
    """Float64 shadows from exact primary hits: (triangle (N,), shadowed (N,), the first
    blocker (N,), -1 where none)."""
    rays, t, tri = reference_visibility(mesh, camera)
    hit = tri >= 0
    points = rays.origins[hit] + t[hit, None] * rays.directions[hit]
    d = (light / light.norm()).to(F64).expand_as(points)
    n = points.shape[0]
    _, blocker, _, _ = closest_hits(
        mesh.triangles(),
        points,
        d,
        torch.full((n,), 1e-7, dtype=F64),
        torch.full((n,), math.inf, dtype=F64),
    )
    shadowed = torch.zeros_like(hit)
    shadowed[hit] = blocker >= 0
    first = torch.full_like(tri, -1)
    first[hit] = blocker
    return tri, shadowed, first


@pytest.mark.task(5)
@pytest.mark.points(1)
def test_hybrid_shadows_match_traced(impl, reference, device):
    mesh, camera = scene("shadow_scene")
    light = torch.tensor([0.5, -0.4, 1.0])
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
    ref_tri, ref_shadowed, _ = reference_shadows(mesh, camera, light)
    shadowed_flat = shadowed.reshape(-1)
    assert not bool(shadowed_flat[face.reshape(-1) < 0].any()), (
        "hybrid_shadows: empty pixels are never shadowed"
    )
    frac = ref_shadowed.double().mean().item()
    assert 0.05 < frac < 0.6, f"test set-up: {frac:.1%} of the pixels in shadow"
    disagree = shadowed_flat != ref_shadowed
    assert_fraction(
        disagree,
        name=(
            "hybrid_shadows vs float64 shadow rays from exact hit points: pixels that disagree "
            "(many isolated dark pixels on lit surfaces is shadow acne: start shadow rays at "
            "t_min = shadow_epsilon(mesh))"
        ),
        at_most=0.02,
        where="pixel",
    )
    traced_face, traced = impl.traced_shadows(
        trace_shadow_scene, mesh.to(device), camera, light.to(device)
    )
    check_tensor(
        traced, "traced_shadows(...)[1]", shape=face.shape, dtype=torch.bool, device=device
    )
    assert_equal(
        traced_face.reshape(-1), ref_tri, name="traced_shadows: primary hits", where="pixel"
    )
    gap = abs(traced.double().mean().item() - shadowed.double().mean().item())
    assert gap < 0.01, (
        f"hybrid_shadows shadows {shadowed.double().mean().item():.2%} of the pixels, "
        f"traced_shadows {traced.double().mean().item():.2%}: raster primary visibility "
        f"should change the shadowed fraction by less than 1%"
    )
    # Three stacked plates: face 0 shows in shadow, and face 0 casts shadows.
    plates, plates_camera = scene("plates")
    sun = torch.tensor([-1.0, 1.0, 0.3])
    face, bary = (x.cpu() for x in reference.rasterize_mesh(plates.to(device), plates_camera))
    ref_tri, ref_shadowed, ref_blocker = reference_shadows(plates, plates_camera, sun)
    hybrid = impl.hybrid_shadows(
        trace_plates, plates.to(device), face.to(device), bary.to(device), sun.to(device)
    )
    traced_face, traced = impl.traced_shadows(
        trace_plates, plates.to(device), plates_camera, sun.to(device)
    )
    on_face0 = (ref_tri == 0) & ref_shadowed
    by_face0 = ref_blocker == 0
    assert int(on_face0.sum()) > 20 and int(by_face0.sum()) > 40, "test set-up: plates"
    for what, got in (("hybrid_shadows", hybrid), ("traced_shadows", traced)):
        got = got.cpu().reshape(-1)
        for name, pixels in (
            ("pixels showing face 0 in shadow", on_face0),
            ("pixels whose shadow ray meets face 0 first", by_face0),
        ):
            missed = int((pixels & ~got).sum())
            assert missed <= 0.1 * int(pixels.sum()), (
                f"{what} of three stacked plates, light {sun.tolist()}: {missed} of the "
                f"{int(pixels.sum())} {name} are not shadowed (face and triangle ids start "
                f"at 0: a hit is id >= 0, a miss -1)"
            )
    assert_fraction(
        traced_face.cpu().reshape(-1) != ref_tri,
        name="traced_shadows of three stacked plates: primary hits",
        at_most=0.02,
        where="pixel",
    )
    # The offset follows the scene's scale.
    eps = impl.shadow_epsilon(mesh)
    big = impl.shadow_epsilon(Mesh(mesh.vertices * 1000, mesh.faces))
    assert 0 < eps < 1e-2, f"shadow_epsilon of a scene ~8 across: {eps!r}"
    assert abs(big / eps - 1000) < 1, f"shadow_epsilon must scale with the scene: {eps} -> {big}"
    # Far from the origin the ulps of the coordinates count, on either side of it.
    for shift in (1e3, -1e3):
        moved = Mesh((mesh.vertices.double() + shift).float(), mesh.faces)
        v = moved.vertices.double()
        want = 1e-4 * float((v.amax(0) - v.amin(0)).norm()) + 8 * torch.finfo(
            torch.float32
        ).eps * float(v.abs().max())
        got = impl.shadow_epsilon(moved)
        assert got == pytest.approx(want, rel=1e-6), (
            f"shadow_epsilon of the scene moved by {shift:+g} on every axis: {got!r}, expected "
            f"1e-4 * extent + 8 * eps * max|x| = {want:.6g} (max|x| the largest absolute "
            f"coordinate)"
        )
    # Computed in float64: a float64 scene 1e-3 across, 1e6 from the origin (in float32 its
    # corners would all be the same point).
    tiny = Mesh(
        torch.tensor([[0.0, 0.0, 0.0], [1e-3, 0.0, 0.0], [0.0, 1e-3, 0.0]], dtype=F64) + 1e6,
        torch.tensor([[0, 1, 2]]),
    )
    want = 1e-4 * math.sqrt(2) * 1e-3 + 8 * torch.finfo(F64).eps * (1e6 + 1e-3)
    got = impl.shadow_epsilon(tiny)
    assert got == pytest.approx(want, rel=1e-6), (
        f"shadow_epsilon of a float64 triangle 1e-3 across, 1e6 from the origin: {got!r}, "
        f"expected {want:.6g} (compute in float64: float32 rounds its extent to 0)"
    )
    # No finite vertex: no scale, no offset.
    got = impl.shadow_epsilon(Mesh(torch.full((3, 3), math.nan), torch.tensor([[0, 1, 2]])))
    assert got == 0.0, f"shadow_epsilon of a mesh whose vertices are all NaN: {got!r}, expected 0.0"
    expect_error(
        "light_direction",
        impl.hybrid_shadows,
        trace_shadow_scene,
        mesh.to(device),
        face.to(device),
        bary.to(device),
        light[:2].to(device),
        case="a light direction of shape (2,)",
    )
