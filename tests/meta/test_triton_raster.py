"""The fused rasterizer (course/triton_raster.py) against Lab 6's reference ``rasterize``.

Not shipped to students (it compares with ``solutions/``). The same keys are asked for on
scenes that exercise both kernels: Suzanne (small triangles), a jittered mesh covering the
screen (watertight: no pixel left empty), a few screen-filling and off-screen triangles
(the program-per-triangle kernel, clamping), NaN and zero-area triangles (nothing drawn),
with 32-bit and 24-bit depth and with back-face culling. Keys may differ only where an FMA
changes a last bit: at most a few pixels in a thousand.

The CPU check runs the kernels in Triton's interpreter in a subprocess (``TRITON_INTERPRET``
must be set before Triton is imported); with CUDA they also run compiled, in process.
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

needs_triton = pytest.mark.skipif(importlib.util.find_spec("triton") is None,
                                  reason="triton is not installed")
RUNS = {"32": {"depth_bits": 32}, "24": {"depth_bits": 24},
        "cull": {"depth_bits": 32, "cull_backfaces": True}}

def _triton_version() -> tuple[int, int]:
    import triton

    return tuple(int(x) for x in triton.__version__.split(".")[:2])


# Triton's interpreter before 3.9 runs loops only to plain-integer bounds and rounds some
# element-wise operations differently from the compiled kernels; the compiled kernels
# are what counts and are tested on CUDA whatever the version.
old_interpreter = pytest.mark.skipif(
    importlib.util.find_spec("triton") is not None and _triton_version() < (3, 9),
    reason="Triton's interpreter before 3.9 cannot run these kernels (loop bounds from "
           "tensors); the compiled kernels are tested on CUDA")



def cases() -> dict:
    from course.bench import load_lab
    from course.scenes import load_scene

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
    special = torch.tensor([
        [[-500, -400, 0.3, 0.5], [900, -300, 0.1, 0.6], [10, 800, 0.2, 0.7]],  # fills the screen
        [[60, 60, 0.0, 1.0], [80, 60, 0.0, 1.0], [70, 90, 0.0, 1.0]],          # off screen
        [[5, 5, 0.0, 1.0], [15, 5, 0.0, 1.0], [25, 5, 0.0, 1.0]],              # zero area
        [[5, 5, float("nan"), 1.0], [15, 5, 0.0, 1.0], [5, 15, 0.0, 1.0]],     # NaN depth
        [[5, 5, 0.0, 1.0], [float("nan"), 5, 0.0, 1.0], [5, 15, 0.0, 1.0]],    # NaN position
        [[30, 2, -0.9, 0.9], [30, 20, -0.9, 0.9], [2, 11, 1.5, 0.9]],          # past the far plane
    ], dtype=torch.float64)
    mixed = torch.cat([grid, special]).float()
    return {"suzanne": (suzanne, width, height), "mixed": (mixed, width, height)}


def run_kernels(data: dict, device: str) -> dict:
    from course.triton_raster import rasterize_triton

    # Suzanne with the default knobs only: the interpreter runs every lane in Python.
    return {(name, run): rasterize_triton(screen.to(device), w, h, small_box=32, **knobs).cpu()
            for name, (screen, w, h) in data.items() for run, knobs in RUNS.items()
            if name == "mixed" or run == "32"}


def check(data: dict, out: dict, where: str) -> None:
    from course.bench import load_lab

    lab = load_lab("lab6_raster", "solutions")
    for (name, run), keys in out.items():
        screen, w, h = data[name]
        want = lab.rasterize(screen, w, h, **RUNS[run])
        ids, want_ids = lab.triangle_ids(keys), lab.triangle_ids(want)
        differ = (ids != want_ids).double().mean().item()
        assert differ <= 0.004, (f"{where}, {name}, depth/cull {run}: the visible triangle "
                                 f"differs from the reference on {differ:.2%} of the pixels "
                                 f"(allowed: 0.4%)")
        # Where the same triangle wins, its depth field may differ only by the last bits
        # an FMA contraction changes (32-bit float depth) or one unorm step (24-bit).
        same = (ids == want_ids) & (ids >= 0)
        steps = ((keys[same] >> 32) - (want[same] >> 32)).abs()
        assert steps.max().item() <= (4 if run != "24" else 1) if len(steps) else True, \
            f"{where}, {name}, {run}: depths differ by up to {steps.max().item()} units"
        if name == "mixed" and run != "cull":
            assert (keys != lab.EMPTY).all(), f"{where}, {name}, {run}: a pixel left empty"


@needs_triton
@old_interpreter
def test_interpreted_matches_reference(tmp_path):
    from course.testing import run_in_triton_interpreter

    data = cases()
    check(data, run_in_triton_interpreter(__file__, data, tmp_path, timeout=600),
          "TRITON_INTERPRET=1")


@needs_triton
@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
def test_compiled_matches_reference():
    from course.triton_intersect import interpreting

    if interpreting():
        pytest.skip("TRITON_INTERPRET=1 is set in this process: nothing is compiled")
    data = cases()
    check(data, run_kernels(data, "cuda"), "compiled")


if __name__ == "__main__":
    torch.save(run_kernels(torch.load(sys.argv[1], weights_only=False), "cpu"), sys.argv[2])


def test_fast_setup_matches_the_lab_pipeline():
    """screen_triangles_fast (no Triton needed) gives the lab's visibility, also when the
    camera stands inside the mesh and many triangles cross the near plane."""
    import dataclasses

    from course.bench import load_lab
    from course.camera import Camera
    from course.scenes import load_scene
    from course.triton_raster import screen_triangles_fast

    lab = load_lab("lab6_raster", "solutions")
    mesh = load_scene("suzanne", device="cpu").mesh
    centre = mesh.vertices.mean(0).tolist()
    inside = Camera(eye=tuple(centre), target=(centre[0] + 1.0, centre[1], centre[2] + 0.3),
                    fov_y=90.0, width=48, height=40, near=0.05, far=50.0)
    outside = dataclasses.replace(load_scene("suzanne", device="cpu").camera, width=48,
                                  height=40)
    for name, camera in (("inside", inside), ("outside", outside)):
        clip = lab.to_clip_space(mesh.vertices, camera.view_projection(torch.float64))
        screen, source = screen_triangles_fast(clip, mesh.faces, 48, 40, lab.clip_triangles,
                                               lab.to_screen)
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
        assert torch.equal(got, want), (f"{name}: {(got != want).sum().item()} pixels see "
                                        f"another triangle than the lab's pipeline")
