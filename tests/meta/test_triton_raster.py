"""The fused rasterizer (course/kernels/triton_raster.py) against Lab 6's reference ``rasterize``.

Not shipped to students (it compares with ``solutions/``). The same keys are asked for on
scenes that exercise both kernels: Suzanne (small triangles), a jittered mesh covering the
screen (watertight: no pixel left empty), a few screen-filling and off-screen triangles
(the program-per-triangle kernel, clamping), NaN and zero-area triangles (nothing drawn),
with 32-bit and 24-bit depth and with back-face culling. The kernels are compiled without
FMA contraction and divide with correct rounding, so the keys are expected to be the lab's
(the benchmark's end-to-end ids equal the torch pipeline's on every pixel on an H100);
the checks still allow a last-bit difference to resolve an edge or a depth tie the other
way on a few pixels in a thousand (a compiler or interpreter that rounds one operation
differently), and fail beyond that.

The CPU check runs the kernels in Triton's interpreter in a subprocess (``TRITON_INTERPRET``
must be set before Triton is imported); with CUDA they also run compiled, in process.
The fused pipeline (``screen_triangles_triton``: MVP, near-plane clipping and viewport in
one kernel; ``visibility_fused``: that, the raster kernels and the id map) is compared with
the lab's ``to_clip_space``, ``clip_triangles`` and ``to_screen`` (the same pieces, bit for
bit, in another order) and with the lab's visibility, on Suzanne seen from outside and
from inside and on a soup of triangles around the eye (crossings of the near plane with one
and two corners in front, faces behind the eye, NaN and inf vertices). Bad arguments of
the entry points raise an error naming the argument before any launch (in process).

Usage as the subprocess: ``python tests/meta/test_triton_raster.py INPUTS.pt OUTPUTS.pt``.
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest
import torch

REPO = Path(__file__).resolve().parents[2]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

from course.grading.testing import OLD_INTERPRETER_REASON, triton_interpreter_too_old

needs_triton = pytest.mark.skipif(
    importlib.util.find_spec("triton") is None, reason="triton is not installed"
)
RUNS = {
    "32": {"depth_bits": 32},
    "24": {"depth_bits": 24},
    "cull": {"depth_bits": 32, "cull_backfaces": True},
}
# The raster kernels' knobs per run (not the lab's: the keys must not depend on them). The
# 24-bit run sends boxes over 200 pixels to the split path of huge triangles.
KNOBS = {
    "32": {"small_box": 32},
    "24": {"small_box": 32, "huge_box": 200},
    "cull": {"small_box": 32},
}

old_interpreter = pytest.mark.skipif(triton_interpreter_too_old(), reason=OLD_INTERPRETER_REASON)


def cases() -> dict:
    from course.core.scenes import load_scene
    from course.measure.bench import load_lab

    lab = load_lab("lab6_raster", "solutions")
    scene = load_scene("suzanne", device="cpu")
    width, height = 40, 28
    mvp = scene.camera.view_projection(torch.float64)
    clip = lab.to_clip_space(scene.mesh.vertices, mvp)
    clipped, _, _ = lab.clip_triangles(clip[scene.mesh.faces])
    suzanne = lab.to_screen(clipped, width, height).float()
    # A jittered grid of quads covering the screen, then special triangles on top.
    g = torch.Generator().manual_seed(3)
    xs = torch.linspace(-2, width + 2, 8, dtype=torch.float64)
    ys = torch.linspace(-2, height + 2, 6, dtype=torch.float64)
    p = torch.stack(torch.meshgrid(xs, ys, indexing="xy"), -1)
    p[1:-1, 1:-1] += (torch.rand(4, 6, 2, generator=g, dtype=torch.float64) - 0.5) * 3
    a, b, c, d = p[:-1, :-1], p[:-1, 1:], p[1:, 1:], p[1:, :-1]
    quads = torch.cat([torch.stack([a, b, c], -2), torch.stack([a, c, d], -2)]).reshape(-1, 3, 2)
    depth = 0.2 + 0.6 * torch.rand(len(quads), 3, 1, generator=g, dtype=torch.float64)
    grid = torch.cat([quads, depth * 2 - 1, 1 / (1 + 4 * depth)], -1)
    special = torch.tensor(
        [
            [
                [-500, -400, 0.3, 0.5],
                [900, -300, 0.1, 0.6],
                [10, 800, 0.2, 0.7],
            ],  # fills the screen
            [[60, 60, 0.0, 1.0], [80, 60, 0.0, 1.0], [70, 90, 0.0, 1.0]],  # off screen
            [[5, 5, 0.0, 1.0], [15, 5, 0.0, 1.0], [25, 5, 0.0, 1.0]],  # zero area
            [[5, 5, float("nan"), 1.0], [15, 5, 0.0, 1.0], [5, 15, 0.0, 1.0]],  # NaN depth
            [[5, 5, 0.0, 1.0], [float("nan"), 5, 0.0, 1.0], [5, 15, 0.0, 1.0]],  # NaN position
            [[30, 2, -0.9, 0.9], [30, 20, -0.9, 0.9], [2, 11, 1.5, 0.9]],  # past the far plane
        ],
        dtype=torch.float64,
    )
    mixed = torch.cat([grid, special]).float()
    return {"suzanne": (suzanne, width, height), "mixed": (mixed, width, height)}


def run_kernels(data: dict, device: str) -> dict:
    from course.kernels.triton_raster import rasterize_triton

    # Suzanne with the default knobs only: the interpreter runs every lane in Python.
    return {
        (name, run): rasterize_triton(screen.to(device), w, h, **KNOBS[run], **knobs).cpu()
        for name, (screen, w, h) in data.items()
        for run, knobs in RUNS.items()
        if name == "mixed" or run == "32"
    }


def check(data: dict, out: dict, where: str) -> None:
    from course.measure.bench import load_lab

    lab = load_lab("lab6_raster", "solutions")
    for (name, run), keys in out.items():
        screen, w, h = data[name]
        want = lab.rasterize(screen, w, h, **RUNS[run])
        ids, want_ids = lab.triangle_ids(keys), lab.triangle_ids(want)
        differ = (ids != want_ids).double().mean().item()
        assert differ <= 0.004, (
            f"{where}, {name}, depth/cull {run}: the visible triangle "
            f"differs from the reference on {differ:.2%} of the pixels "
            f"(allowed: 0.4%)"
        )
        # Where the same triangle wins, its depth field may differ only by a few last bits
        # (32-bit float depth) or one unorm step (24-bit).
        same = (ids == want_ids) & (ids >= 0)
        steps = ((keys[same] >> 32) - (want[same] >> 32)).abs()
        assert steps.max().item() <= (4 if run != "24" else 1) if len(steps) else True, (
            f"{where}, {name}, {run}: depths differ by up to {steps.max().item()} units"
        )
        if name == "mixed" and run != "cull":
            assert (keys != lab.EMPTY).all(), f"{where}, {name}, {run}: a pixel left empty"


@pytest.fixture(scope="module")
def interpreted(tmp_path_factory):
    """Every kernel of this file run once in Triton's interpreter (one subprocess)."""
    from course.grading.testing import run_in_triton_interpreter

    data = {"raster": cases(), "mesh": mesh_cases()}
    return data, run_in_triton_interpreter(
        __file__, data, tmp_path_factory.mktemp("interp"), timeout=600
    )


@needs_triton
@old_interpreter
def test_interpreted_matches_reference(interpreted):
    data, out = interpreted
    check(data["raster"], out["raster"], "TRITON_INTERPRET=1")


@needs_triton
@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
def test_compiled_matches_reference():
    from course.kernels.triton_intersect import interpreting

    if interpreting():
        pytest.skip("TRITON_INTERPRET=1 is set in this process: nothing is compiled")
    data = cases()
    check(data, run_kernels(data, "cuda"), "compiled")


def test_fast_setup_matches_the_lab_pipeline():
    """screen_triangles_fast (no Triton needed) gives the lab's visibility, also when the
    camera stands inside the mesh and many triangles cross the near plane."""
    import dataclasses

    from course.core.camera import Camera
    from course.core.scenes import load_scene
    from course.kernels.triton_raster import screen_triangles_fast
    from course.measure.bench import load_lab

    lab = load_lab("lab6_raster", "solutions")
    mesh = load_scene("suzanne", device="cpu").mesh
    centre = mesh.vertices.mean(0).tolist()
    inside = Camera(
        eye=tuple(centre),
        target=(centre[0] + 1.0, centre[1], centre[2] + 0.3),
        fov_y=90.0,
        width=48,
        height=40,
        near=0.05,
        far=50.0,
    )
    outside = dataclasses.replace(load_scene("suzanne", device="cpu").camera, width=48, height=40)
    for name, camera in (("inside", inside), ("outside", outside)):
        clip = lab.to_clip_space(mesh.vertices, camera.view_projection(torch.float64))
        screen, source = screen_triangles_fast(
            clip, mesh.faces, 48, 40, lab.clip_triangles, lab.to_screen
        )
        clipped, want_source, _ = lab.clip_triangles(clip[mesh.faces])
        if name == "inside":
            d = clip[mesh.faces][..., 2] + clip[mesh.faces][..., 3]
            crossing = ((d >= 0).any(-1) & (d < 0).any(-1)).sum().item()
            assert crossing > 10, f"only {crossing} triangles cross the near plane"
        got = lab.triangle_ids(lab.rasterize(screen, 48, 40))
        want = lab.triangle_ids(lab.rasterize(lab.to_screen(clipped, 48, 40), 48, 40))
        got = torch.where(got >= 0, source[got.clamp(min=0)], -1)
        want = torch.where(want >= 0, want_source[want.clamp(min=0)], -1)
        assert (got >= 0).any(), f"{name}: nothing visible: the test sees nothing"
        assert torch.equal(got, want), (
            f"{name}: {(got != want).sum().item()} pixels see "
            f"another triangle than the lab's pipeline"
        )


# --------------------------------------------------------------------------------------
# The fused vertex stage and the whole pipeline
# --------------------------------------------------------------------------------------

MESH_RUNS = {"32": {}, "cull": {"cull_backfaces": True}}


def soup_mesh() -> tuple[torch.Tensor, torch.Tensor, int]:
    """Triangles with corners anywhere in a cube around the eye (at the origin, looking
    down -z): many cross the near plane with one or two corners in front, many lie behind
    it; the last faces use NaN and inf vertices. Returns (vertices, faces, special faces)."""
    g = torch.Generator().manual_seed(11)
    n = 80
    vertices = (torch.rand(3 * n, 3, generator=g, dtype=torch.float64) - 0.5) * 4
    vertices[:, 2] -= 0.6  # a little more in front of the eye than behind
    special = torch.tensor(
        [
            [float("nan"), 0.0, -2.0],
            [0.0, float("inf"), -2.0],
            [0.3, 0.3, -1.5],
            [0.0, 0.0, -float("inf")],
        ],
        dtype=torch.float64,
    )
    faces = torch.arange(3 * n).reshape(n, 3)
    base = 3 * n
    extra = torch.tensor(
        [
            [base, base + 2, 1],
            [base + 1, 0, base + 2],
            [base + 3, 2, 4],
            [base + 2, base + 2, base + 2],
        ]
    )  # NaN, inf, -inf, degenerate
    return (torch.cat([vertices, special]).float(), torch.cat([faces, extra]), len(extra))


def mesh_cases() -> dict:
    """name -> (vertices, faces, mvp float64, width, height)."""
    import dataclasses

    from course.core.camera import Camera
    from course.core.scenes import load_scene

    scene = load_scene("suzanne", device="cpu")
    mesh = scene.mesh
    centre = mesh.vertices.mean(0).tolist()
    inside = Camera(
        eye=tuple(centre),
        target=(centre[0] + 1.0, centre[1], centre[2] + 0.3),
        fov_y=90.0,
        width=24,
        height=18,
        near=0.05,
        far=50.0,
    )
    outside = dataclasses.replace(scene.camera, width=40, height=30)
    vertices, faces, _ = soup_mesh()
    eye = Camera(
        eye=(0.0, 0.0, 0.0),
        target=(0.0, 0.0, -1.0),
        fov_y=70.0,
        width=24,
        height=18,
        near=0.3,
        far=10.0,
    )
    return {
        name: (v, f, cam.view_projection(torch.float64), cam.width, cam.height)
        for name, v, f, cam in (
            ("suzanne outside", mesh.vertices, mesh.faces, outside),
            ("suzanne inside", mesh.vertices, mesh.faces, inside),
            ("soup", vertices, faces, eye),
        )
    }


def run_mesh_stages(data: dict, device: str) -> dict:
    from course.kernels.triton_raster import screen_triangles_triton, visibility_fused

    out = {}
    for name, (v, f, mvp, w, h) in data.items():
        v, f = v.to(device), f.to(device)
        out[("screen", name)] = screen_triangles_triton(v, f, mvp, w, h).cpu()
        for run, knobs in MESH_RUNS.items():
            if run == "32" or name == "soup":
                out[("ids", name, run)] = visibility_fused(v, f, mvp, w, h, **knobs).cpu()
    return out


def lab_pieces(lab, vertices, faces, mvp, width, height):
    """The lab's screen triangles and, for each, the slot the fused vertex stage gives it:
    face i's first piece -> i, its second piece -> F + i."""
    clip = lab.to_clip_space(vertices, mvp)
    clipped, source, _ = lab.clip_triangles(clip[faces])
    screen = lab.to_screen(clipped, width, height)
    second = torch.zeros(len(source), dtype=torch.bool)
    second[1:] = source[1:] == source[:-1]
    return screen, source, torch.where(second, source + len(faces), source)


def check_screen(data: dict, out: dict, where: str) -> None:
    from course.measure.bench import load_lab

    lab = load_lab("lab6_raster", "solutions")
    for name, (v, f, mvp, w, h) in data.items():
        got = out[("screen", name)]
        F = len(f)
        assert got.shape == (2 * F, 3, 4) and got.dtype == torch.float32, (
            f"{where}, {name}: screen is {tuple(got.shape)} {got.dtype}, "
            f"expected ({2 * F}, 3, 4) float32"
        )
        want, _, slots = lab_pieces(lab, v, f, mvp, w, h)
        empty = torch.isnan(got).all(-1).all(-1)
        filled = (~empty).nonzero()[:, 0]
        order = slots.argsort()
        missing = sorted(set(slots.tolist()) - set(filled.tolist()))
        extra = sorted(set(filled.tolist()) - set(slots.tolist()))
        assert not missing and not extra, (
            f"{where}, {name}: slots holding a triangle differ from the lab's pieces: "
            f"missing {missing[:8]} ({len(missing)}), unexpected {extra[:8]} ({len(extra)}) "
            f"(slot i: face i, slot {F} + i: the second piece of face i)"
        )
        a, b = got[filled], want[order]
        same = (a == b) | (torch.isnan(a) & torch.isnan(b))
        if not same.all():
            bad = (~same).nonzero()[0].tolist()
            ulps = (a.view(torch.int32).long() - b.view(torch.int32).long()).abs()[~same]
            raise AssertionError(
                f"{where}, {name}: {(~same).sum().item()} screen coordinates differ from "
                f"to_screen(clip_triangles(...)); first: slot {filled[bad[0]].item()}, corner "
                f"{bad[1]}, component {bad[2]}: {a[tuple(bad)].item()!r} vs "
                f"{b[tuple(bad)].item()!r}; up to {ulps.max().item()} float32 ulps"
            )


def test_soup_exercises_every_clipping_case():
    """The soup is worth testing: faces cut into one piece and into two, faces behind the
    near plane, and the special faces (NaN, inf, degenerate) rejected by the lab."""
    from course.measure.bench import load_lab

    lab = load_lab("lab6_raster", "solutions")
    v, f, mvp, w, h = mesh_cases()["soup"]
    special = soup_mesh()[2]
    clip = lab.to_clip_space(v, mvp)[f]
    d = clip[..., 2] + clip[..., 3]
    inside = (d >= 0).sum(-1)
    finite = torch.isfinite(clip).all(-1).all(-1)
    counts = {n: ((inside == n) & finite).sum().item() for n in range(4)}
    assert min(counts.values()) >= 5, f"faces by corners in front of the near plane: {counts}"
    _, source, slots = lab_pieces(lab, v, f, mvp, w, h)
    assert (slots >= len(f)).sum() >= 5, "fewer than 5 faces are cut into two pieces"
    kept = set(range(len(f) - special, len(f) - 1)) & set(source.tolist())
    assert not kept, f"the lab keeps the faces with NaN/inf corners {sorted(kept)}"


def check_ids(data: dict, out: dict, where: str) -> None:
    """visibility_fused against the lab's pipeline (the torch rasterizer). Not bit for bit
    by design: an exact depth tie between a face's second piece and another face goes to
    the other face here (slot order: every first piece before every second piece), to the
    lower face in the lab; ties need coplanar overlapping faces, so they are rare."""
    from course.measure.bench import load_lab

    lab = load_lab("lab6_raster", "solutions")
    for key, ids in out.items():
        if key[0] != "ids":
            continue
        _, name, run = key
        v, f, mvp, w, h = data[name]
        screen, source, _ = lab_pieces(lab, v, f, mvp, w, h)
        k = lab.triangle_ids(lab.rasterize(screen, w, h, **MESH_RUNS[run]))
        want = torch.where(k >= 0, source[k.clamp(min=0)], -1).reshape(h, w)
        assert ids.shape == (h, w) and ids.dtype == torch.int64, (
            f"{where}, {name}, {run}: ids are {tuple(ids.shape)} {ids.dtype}, "
            f"expected ({h}, {w}) int64"
        )
        covered = (want >= 0) | (ids >= 0)
        assert covered.double().mean() > 0.05, f"{where}, {name}, {run}: nothing to compare"
        differ = ((ids != want) & covered).double().sum().item() / covered.sum().item()
        if differ:
            r, c = ((ids != want) & covered).nonzero()[0].tolist()
            first = f"; first at (row {r}, col {c}): {ids[r, c].item()} vs {want[r, c].item()}"
        else:
            first = ""
        assert differ <= 0.004, (
            f"{where}, {name}, {run}: the visible face differs from the "
            f"lab's pipeline on {differ:.2%} of the covered pixels "
            f"(allowed: 0.4%){first}"
        )


@needs_triton
@old_interpreter
def test_interpreted_vertex_stage(interpreted):
    data, out = interpreted
    check_screen(data["mesh"], out["mesh"], "TRITON_INTERPRET=1")


@needs_triton
@old_interpreter
def test_interpreted_visibility_fused(interpreted):
    data, out = interpreted
    check_ids(data["mesh"], out["mesh"], "TRITON_INTERPRET=1")


@needs_triton
@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
def test_compiled_fused_pipeline():
    """The same on CUDA, plus Suzanne at 640x480 (thousands of small and large boxes)."""
    import dataclasses

    from course.core.scenes import load_scene
    from course.kernels.triton_intersect import interpreting

    if interpreting():
        pytest.skip("TRITON_INTERPRET=1 is set in this process: nothing is compiled")
    data = mesh_cases()
    scene = load_scene("suzanne", device="cpu")
    cam = dataclasses.replace(scene.camera, width=640, height=480)
    data["suzanne 640x480"] = (
        scene.mesh.vertices,
        scene.mesh.faces,
        cam.view_projection(torch.float64),
        640,
        480,
    )
    out = run_mesh_stages(data, "cuda")
    check_screen(data, out, "compiled")
    check_ids(data, out, "compiled")


@needs_triton
@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
def test_graph_replay_matches_eager():
    """FusedVisibility (recorded once as a CUDA graph) gives visibility_fused's ids for
    every camera it is called with, each call in a tensor of its own."""
    import dataclasses

    from course.core.scenes import load_scene
    from course.kernels.triton_intersect import interpreting
    from course.kernels.triton_raster import FusedVisibility, visibility_fused

    if interpreting():
        pytest.skip("TRITON_INTERPRET=1 is set in this process: nothing is compiled")
    scene = load_scene("suzanne", device="cuda")
    mesh = scene.mesh
    frame = FusedVisibility(mesh.vertices, mesh.faces, 320, 240)
    results = []
    for turn, up in enumerate((0.0, 0.4, -0.3)):
        eye = tuple(e + up * (i == 1) for i, e in enumerate(scene.camera.eye))
        cam = dataclasses.replace(scene.camera, eye=eye, width=320, height=240)
        mvp = cam.view_projection(torch.float64)
        got = frame(mvp)
        want = visibility_fused(mesh.vertices, mesh.faces, mvp, 320, 240)
        assert (want >= 0).sum() > 1000, f"camera {turn}: too little of Suzanne in view"
        differ = (got != want).sum().item()
        assert differ == 0, f"camera {turn}: the replayed graph differs on {differ} pixels"
        results.append(got)
    assert not torch.equal(results[0], results[1]), "the graph ignored the new matrix"
    assert results[0].data_ptr() != results[1].data_ptr(), "calls share their output"


# --------------------------------------------------------------------------------------
# Argument checks (all before the first launch: no interpreter needed)
# --------------------------------------------------------------------------------------


def _tiny_mesh():
    """A valid call's arguments: one triangle in front of the eye, a float64 matrix, 8 x 6."""
    vertices = torch.tensor([[-0.5, -0.5, 0.5], [0.5, -0.5, 0.5], [0.0, 0.5, 0.5]])
    return vertices, torch.tensor([[0, 1, 2]]), torch.eye(4, dtype=torch.float64), 8, 6


def _mesh_entry(name: str):
    """The mesh entry point ``name`` as ``fn(vertices, faces, mvp, width, height, **knobs)``
    (FusedVisibility: its constructor, which takes no matrix)."""
    import course.kernels.triton_raster as fused

    if name != "FusedVisibility":
        return getattr(fused, name)

    def construct(vertices, faces, mvp, width, height, **knobs):
        return fused.FusedVisibility(vertices, faces, width, height, **knobs)

    construct.__name__ = name
    return construct


MESH_ENTRIES = ("screen_triangles_triton", "visibility_fused", "FusedVisibility")


@needs_triton
@pytest.mark.parametrize("entry", MESH_ENTRIES)
def test_bad_mesh_arguments_are_named(entry):
    """Each bad argument of the mesh entry points raises a ValueError naming it, whatever
    the device: the device is checked last."""
    from course.grading.testing import expect_error

    fn = _mesh_entry(entry)
    v, f, mvp, w, h = _tiny_mesh()
    cases = [  # (name, case, vertices, faces, mvp, width, height)
        ("vertices", "a list of vertices", v.tolist(), f, mvp, w, h),
        ("vertices", "(V, 2) vertices", v[:, :2], f, mvp, w, h),
        ("vertices", "(1, V, 3) vertices", v[None], f, mvp, w, h),
        ("vertices", "int32 vertices", v.int(), f, mvp, w, h),
        ("vertices", "float16 vertices", v.half(), f, mvp, w, h),
        ("faces", "a list of faces", v, f.tolist(), mvp, w, h),
        ("faces", "(F, 2) faces", v, f[:, :2], mvp, w, h),
        ("faces", "(3,) faces", v, f[0], mvp, w, h),
        ("faces", "float32 faces", v, f.float(), mvp, w, h),
        ("faces", "int16 faces", v, f.short(), mvp, w, h),
        ("faces", "faces on another device than vertices", v, f.to("meta"), mvp, w, h),
        ("width", "width = 0", v, f, mvp, 0, h),
        ("width", "width = 2**15", v, f, mvp, 2**15, h),
        ("width", "width = 8.0", v, f, mvp, 8.0, h),
        ("width", "width = True", v, f, mvp, True, h),
        ("height", "height = -1", v, f, mvp, w, -1),
        ("height", "height = None", v, f, mvp, w, None),
    ]
    if entry != "FusedVisibility":  # its matrix comes with each call (next test)
        cases += [
            ("mvp", "a nested list as mvp", v, f, mvp.tolist(), w, h),
            ("mvp", "a (3, 3) mvp", v, f, mvp[:3, :3], w, h),
            ("mvp", "a (1, 4, 4) mvp", v, f, mvp[None], w, h),
            ("mvp", "an int64 mvp", v, f, mvp.long(), w, h),
        ]
    for name, case, *args in cases:
        expect_error(name, fn, *args, kinds=(ValueError,), case=case)
    if entry != "screen_triangles_triton":  # the raster knobs
        for name, value in (
            ("depth_bits", 16),
            ("depth_bits", None),
            ("small_box", -1),
            ("small_box", None),
            ("small_box", 2.5),
            ("small_box", "32"),
            ("small_box", True),
        ):
            expect_error(
                name,
                fn,
                v,
                f,
                mvp,
                w,
                h,
                **{name: value},
                kinds=(ValueError,),
                case=f"{name}={value!r}",
            )


@needs_triton
@pytest.mark.parametrize("entry", MESH_ENTRIES)
def test_cpu_mesh_needs_the_interpreter(entry):
    """Compiled, the kernels need CUDA tensors: a CPU mesh is refused, naming vertices."""
    from course.grading.testing import expect_error
    from course.kernels.triton_intersect import interpreting

    if interpreting():
        pytest.skip("TRITON_INTERPRET=1 is set in this process: CPU tensors are accepted")
    expect_error(
        "vertices",
        _mesh_entry(entry),
        *_tiny_mesh(),
        kinds=(ValueError,),
        case="a CPU mesh without TRITON_INTERPRET=1",
    )


@needs_triton
def test_fused_visibility_call_checks_the_matrix(device, monkeypatch):
    """FusedVisibility(...)(mvp) names a bad matrix: on CUDA before recording its graph,
    elsewhere through visibility_fused. On the CPU, interpreting() is patched to True
    (TRITON_INTERPRET=1 can only be set before triton's import) so that the object can be
    made; the error comes before any launch."""
    import course.kernels.triton_raster as fused
    from course.grading.testing import expect_error

    if device == "cpu":
        monkeypatch.setattr(fused, "interpreting", lambda: True)
    v, f, mvp, w, h = _tiny_mesh()
    frame = fused.FusedVisibility(v.to(device), f.to(device), w, h)
    for bad, case in (
        (mvp.tolist(), "a nested list"),
        (mvp[:3, :3], "a (3, 3) matrix"),
        (mvp.long(), "an int64 matrix"),
    ):
        expect_error("mvp", frame, bad, kinds=(ValueError,), case=case)
    assert frame._graph is None, "a graph was recorded for a bad matrix"


@needs_triton
def test_bad_raster_arguments_are_named():
    """rasterize_triton's checks before the device's (its out buffer is checked after)."""
    from course.grading.testing import expect_error
    from course.kernels.triton_raster import rasterize_triton

    screen = torch.zeros(2, 3, 4)
    for name, case, args, kwargs in (
        ("screen", "a list", (screen.tolist(), 8, 6), {}),
        ("screen", "(K, 3, 3) triangles", (screen[..., :3], 8, 6), {}),
        ("screen", "int32 triangles", (screen.int(), 8, 6), {}),
        ("width", "width = 0", (screen, 0, 6), {}),
        ("height", "height = 2**15", (screen, 8, 2**15), {}),
        ("depth_bits", "depth_bits=16", (screen, 8, 6), {"depth_bits": 16}),
        ("small_box", "small_box=-1", (screen, 8, 6), {"small_box": -1}),
        ("huge_box", "huge_box=-1", (screen, 8, 6), {"huge_box": -1}),
        ("huge_box", "huge_box=2.5", (screen, 8, 6), {"huge_box": 2.5}),
    ):
        expect_error(name, rasterize_triton, *args, **kwargs, kinds=(ValueError,), case=case)


if __name__ == "__main__":
    import course.kernels.triton_raster as fused

    # The interpreter pays per operation and program, not per lane: larger blocks than the
    # GPU's defaults run these cases three times faster (the results must not change).
    fused.BLOCK_TRIANGLES, fused.BLOCK_FACES = 256, 512
    data = torch.load(sys.argv[1], weights_only=False)
    torch.save(
        {
            "raster": run_kernels(data["raster"], "cpu"),
            "mesh": run_mesh_stages(data["mesh"], "cpu"),
        },
        sys.argv[2],
    )
