"""The fused froxel pipeline (course/kernels/triton_froxel.py) against Lab 5's ``render_froxels``.

Not shipped to students (it compares with ``solutions/``). Small seeded scenes that
exercise every branch of the kernels, each compared image for image with the lab's torch
pipeline (non-temporal) and count for count with its report:

* ``street``: height fog, a thin constant fog, a rotated textured box and a textured
  ellipsoid, the sun with a shadow-casting occluder, a spot light and a point light
  inside the ellipsoid; a partial tile column and row; random depths from before
  ``near`` to beyond ``far``, plus depth 0 and the sky (+inf);
* the same with Schlick's phase, the naive integral, no volumetric shadows and a slice
  count that is not a power of two (padding lanes);
* ``dense``: extinction 1e4 per metre (transmittance 0 after the first slice: no NaN);
* ``emissive``: sigma_t = 0 everywhere, emission only (the slice integral's series at 0;
  nothing lit, lights listed but never evaluated);
* ``lamp in fog`` and ``sun in a fog box``: Lab 5's quadrature scenes (a point light inside a
  homogeneous box of fog, its light attenuated on the way to each froxel; the sun through
  a box of fog, the extinction volume over the box at the resolution chosen from its size),
  with the defaults, also within 1% and 2% of the grader's single-scattering quadrature;
* a scene without media: a copy of the opaque image;
* bad arguments (wrong kind, shape, dtype, device or value): an error naming the argument,
  raised before any launch (in process, no interpreter needed).

The CPU check runs the kernels in Triton's interpreter in a subprocess (``TRITON_INTERPRET``
must be set before Triton is imported); with CUDA they also run compiled, in process, and
on the bench's full 1080p frame. Usage as the subprocess:
``python tests/meta/test_triton_froxel.py INPUTS.pt OUTPUTS.pt``.
"""

from __future__ import annotations

import importlib.util
import math
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
COUNTS = ("froxels_lit", "tiles_with_media", "light_tiles", "light_evaluations")
# Interpreted, the kernels round like the torch pipeline in float32 (measured: 6e-8 at
# radiance 0.27); compiled, the GPU's fast exp/log/division add a few 1e-7 relative per
# operation. Tolerance per value: RTOL |reference| + ATOL max |reference|.
RTOL, ATOL = 2e-5, 2e-5


old_interpreter = pytest.mark.skipif(triton_interpreter_too_old(), reason=OLD_INTERPRETER_REASON)


def _texture(n: int, g: torch.Generator) -> torch.Tensor:
    return torch.rand(n, n + 1, n - 1, generator=g) * 2


def _images(camera, g: torch.Generator, near: float, far: float):
    """Random view depths from half of ``near`` to twice ``far`` (log-uniform), a few at
    0 and +inf, and random opaque colours."""
    h, w = camera.height, camera.width
    u = torch.rand(h, w, generator=g, dtype=torch.float64)
    depth = torch.exp(math.log(near / 2) + u * math.log(4 * far / near))
    depth[0, :3] = 0.0
    depth[1, :5] = math.inf
    depth[2, :4] = 2 * far
    return depth.float(), torch.rand(h, w, 3, generator=g)


def cases() -> dict:
    """name -> (scene, camera, depth, opaque, keyword arguments)."""
    from course.core.camera import Camera
    from course.given.lab5 import (
        Box,
        ConstantFog,
        DirectionalLight,
        FogVolume,
        HeightFog,
        PointLight,
        Scene,
        SpotLight,
    )

    g = torch.Generator().manual_seed(11)
    angle = 0.6
    ca, sa = math.cos(angle), math.sin(angle)
    street = Scene(
        media=(
            HeightFog(
                scattering=(0.03, 0.035, 0.04), extinction=0.05, g=0.3, base=0.0, falloff=0.3
            ),
            ConstantFog(
                scattering=(0.004, 0.005, 0.006),
                extinction=0.008,
                emissive=(0.001, 0.0, 0.002),
                g=-0.2,
            ),
            FogVolume(
                center=(-1.5, 1.2, -6.0),
                half_size=(1.5, 1.0, 2.0),
                scattering=(0.3, 0.25, 0.2),
                extinction=0.35,
                g=0.5,
                shape="box",
                rotation=((ca, 0.0, -sa), (0.0, 1.0, 0.0), (sa, 0.0, ca)),
                density=_texture(6, g),
            ),
            FogVolume(
                center=(1.8, 1.5, -9.0),
                half_size=(2.0, 1.5, 2.5),
                scattering=(0.2, 0.2, 0.25),
                extinction=0.3,
                g=0.7,
                shape="ellipsoid",
                density=_texture(5, g),
            ),
        ),
        lights=(
            DirectionalLight(direction=(0.4, 0.8, -0.45), irradiance=(3.0, 2.8, 2.5)),
            PointLight(position=(1.6, 1.4, -8.5), intensity=(4.0, 3.0, 2.0), range=5.0),
            SpotLight(
                position=(-2.0, 4.0, -5.0),
                direction=(0.3, -1.0, -0.2),
                intensity=(20.0, 18.0, 15.0),
                range=9.0,
                inner_deg=12.0,
                outer_deg=30.0,
            ),
            PointLight(position=(30.0, 2.0, 5.0), intensity=(9.0, 9.0, 9.0), range=3.0),
        ),
        ambient=(0.05, 0.06, 0.08),
        occluders=(Box((-4.0, 3.0, -9.0), (0.0, 3.5, -5.0)),),
    )
    camera = Camera(eye=(0.0, 1.6, 2.0), target=(0.0, 1.7, -20.0), fov_y=55.0, width=36, height=20)
    base = {"tile": 8, "near": 0.1, "far": 20.0, "shadow_resolution": 16, "volume_resolution": 8}
    depth, opaque = _images(camera, g, 0.1, 20.0)
    dense = Scene(
        media=(ConstantFog(scattering=(500.0, 400.0, 300.0), extinction=1e4, g=0.4),),
        lights=(
            DirectionalLight(direction=(0.2, 1.0, 0.1)),
            PointLight(position=(0.0, 1.6, 1.0), intensity=(5.0, 5.0, 5.0)),
        ),
        ambient=(0.1, 0.1, 0.1),
    )
    emissive = Scene(
        media=(
            ConstantFog(scattering=(0.0, 0.0, 0.0), extinction=0.0, emissive=(0.02, 0.01, 0.005)),
            FogVolume(
                center=(0.0, 1.5, -6.0),
                half_size=(2.0, 2.0, 2.0),
                scattering=(0.0, 0.0, 0.0),
                extinction=0.0,
                emissive=(0.1, 0.2, 0.3),
                shape="ellipsoid",
            ),
        ),
        lights=street.lights,
        ambient=(0.2, 0.2, 0.2),
    )
    small = Camera(eye=(0.0, 1.6, 2.0), target=(0.0, 1.7, -20.0), fov_y=55.0, width=24, height=16)
    d_small, o_small = _images(small, g, 0.1, 20.0)
    lab5 = _lab5_grader()
    fog = {}
    for name, box, light, cam in (
        ("lamp in fog", lab5.LAMP_BOX, lab5.LAMP, lab5.LAMP_CAMERA),
        ("sun in a fog box", lab5.SUN_BOX, lab5.FOG_SUN, lab5.SUN_CAMERA),
    ):
        fog[name] = (
            Scene(media=(lab5.fog_box(*box),), lights=(light,)),
            cam,
            *lab5.sky_images(cam),
            {},
        )
    return {
        "street": (street, camera, depth, opaque, {**base, "slices": 16}),
        "street, schlick, naive, no volumetric shadows, 12 slices": (
            street,
            camera,
            depth,
            opaque,
            {
                **base,
                "slices": 12,
                "phase": "schlick",
                "integration": "naive",
                "volumetric_shadows": False,
            },
        ),
        "dense": (dense, small, d_small, o_small, {**base, "slices": 16}),
        "emissive": (emissive, small, d_small, o_small, {**base, "slices": 16}),
        **fog,
    }


def _lab5_grader():
    """Lab 5's grader module (its fog box scenes and quadrature)."""
    spec = importlib.util.spec_from_file_location(
        "lab5_grader", REPO / "tests" / "test_lab5_froxel.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def run_kernels(data: dict, device: str) -> dict:
    from course.kernels.triton_froxel import render_froxels_fused

    out = {}
    for name, (scene, camera, depth, opaque, kwargs) in data.items():
        image, report = render_froxels_fused(
            scene, camera, depth.to(device), opaque.to(device), **kwargs
        )
        out[name] = (image.cpu(), {k: report[k] for k in COUNTS})
    return out


def compare_images(got, want, where: str, outliers: float = 0.0, worst: float = 0.0):
    """Every value within RTOL |want| + ATOL max |want|, except a fraction ``outliers``
    of the pixels (froxels next to a discontinuity), which must stay within ``worst`` of
    the largest radiance."""
    got, want = got.detach().to("cpu", torch.float64), want.detach().to("cpu", torch.float64)
    assert got.shape == want.shape, (
        f"{where}: image shape {tuple(got.shape)}, expected {tuple(want.shape)}"
    )
    finite = torch.isfinite(want)
    assert torch.equal(torch.isfinite(got), finite), (
        f"{where}: {int((torch.isfinite(got) != finite).sum())} values are non-finite "
        "where the torch pipeline's are finite (or the other way round)"
    )
    scale = want[finite].abs().max().item()
    diff = torch.where(finite, (got - want).abs(), 0.0)
    bad = (diff > RTOL * want.abs() + ATOL * scale).any(-1)
    h, w = bad.shape
    if bad.float().mean().item() > outliers:
        i = int(bad.flatten().nonzero()[0, 0])
        j = int(diff.amax(-1).flatten().argmax())
        raise AssertionError(
            f"{where}: {int(bad.sum())} of {h * w} pixels differ from the torch pipeline by "
            f"more than {RTOL:g} x value + {ATOL:g} x max radiance ({scale:.4g}); "
            f"{outliers:.2%} allowed. First at pixel (row, col) {divmod(i, w)}: got "
            f"{got.reshape(-1, 3)[i].tolist()}, expected {want.reshape(-1, 3)[i].tolist()}; "
            f"worst at {divmod(j, w)}: off by {diff.max().item():.3g}"
        )
    assert diff.max().item() <= max(worst, ATOL) * scale + RTOL * want.abs().max().item(), (
        f"{where}: the worst pixel is off by {diff.max().item():.4g} = "
        f"{diff.max().item() / scale:.3%} of the largest radiance (allowed {worst:.1%})"
    )


def check(data: dict, out: dict, where: str) -> None:
    from course.measure.bench import load_lab

    lab = load_lab("lab5_froxel", "solutions")
    for name, (scene, camera, depth, opaque, kwargs) in data.items():
        want, report = lab.render_froxels(scene, camera, depth, opaque, **kwargs)
        got, counts = out[name]
        compare_images(got, want, f"{where}, {name}")
        for key in COUNTS:
            assert counts[key] == report[key], (
                f"{where}, {name}: report[{key!r}] is {counts[key]}, the lab's {report[key]}"
            )
        if name == "dense":
            inside = (depth > kwargs["near"]).unsqueeze(-1)
            assert torch.equal(
                got[inside.expand_as(got)].isfinite(),
                torch.ones_like(got[inside.expand_as(got)], dtype=torch.bool),
            ), f"{where}, {name}: non-finite radiance in a fully opaque medium"
            assert (got - want).abs().max() <= ATOL * want.abs().max(), (
                f"{where}, {name}: the dense medium differs"
            )
        if name == "emissive":
            assert counts["froxels_lit"] == 0, f"{where}, {name}: lit froxels without scattering"
        if name in ("lamp in fog", "sun in a fog box"):
            lab5 = _lab5_grader()
            box = lab5.LAMP_BOX if name == "lamp in fog" else lab5.SUN_BOX
            quad = lab5.fog_box_quadrature(camera, *box, scene.lights[0], 0.1)
            err, allowed = lab5.mean_error(got, quad), 0.01 if name == "lamp in fog" else 0.02
            assert abs(err) <= allowed, (
                f"{where}, {name}: mean radiance {err:+.2%} off the "
                f"quadrature (allowed {allowed:.0%})"
            )


@needs_triton
@old_interpreter
def test_interpreted_matches_the_lab(tmp_path):
    from course.grading.testing import run_in_triton_interpreter

    data = cases()
    check(
        data, run_in_triton_interpreter(__file__, data, tmp_path, timeout=600), "TRITON_INTERPRET=1"
    )


@needs_triton
def test_scene_without_media_returns_a_copy():
    from course.given.lab5 import PointLight, Scene
    from course.kernels.triton_froxel import render_froxels_fused

    _, camera, depth, opaque, kwargs = cases()["emissive"]
    image, report = render_froxels_fused(
        Scene(lights=(PointLight(),)), camera, depth, opaque, **kwargs
    )
    assert torch.equal(image, opaque), "a scene without media must return the opaque image"
    assert image.data_ptr() != opaque.data_ptr(), "expected a copy, got the input itself"
    assert report["froxels_lit"] == 0 and report["light_tiles"] == [0], report


@needs_triton
@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
def test_compiled_matches_the_lab():
    from course.kernels.triton_intersect import interpreting

    if interpreting():
        pytest.skip("TRITON_INTERPRET=1 is set in this process: nothing is compiled")
    data = cases()
    check(data, run_kernels(data, "cuda"), "compiled")


@needs_triton
@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
def test_compiled_1080p_frame_matches_the_lab():
    """The bench's talk scene at 1080p (240 x 135 x 64 froxels), on the GPU: a froxel
    sample within rounding of a fog volume's edge, a shadow-map texel or a light's range
    may land on the other side (fast exp/division) and move a tile's pixels by up to that
    froxel's light: at most 0.1% of the pixels may differ by more than the tight
    tolerance, none by more than 10% of the largest radiance."""
    from course.kernels.triton_froxel import render_froxels_fused
    from course.kernels.triton_intersect import interpreting
    from course.measure.bench import load_lab

    if interpreting():
        pytest.skip("TRITON_INTERPRET=1 is set in this process: nothing is compiled")
    spec = importlib.util.spec_from_file_location("bench_lab5", REPO / "bench" / "lab5_froxel.py")
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    lab = load_lab("lab5_froxel", "solutions")
    scene = bench.talk_scene("cuda")
    camera = bench.camera_at(1920, 1080)
    depth, opaque = bench.scene_images(camera, "cuda")
    kwargs = {"tile": 8, "slices": 64, "near": bench.NEAR, "far": bench.FAR}
    want, report = lab.render_froxels(scene, camera, depth, opaque, **kwargs)
    got, counts = render_froxels_fused(scene, camera, depth, opaque, **kwargs)
    compare_images(got, want, "compiled, 1080p", outliers=1e-3, worst=0.1)
    for key in ("froxels_lit", "tiles_with_media", "light_evaluations"):
        assert abs(counts[key] - report[key]) <= 1e-4 * report[key], (
            f"1080p: report[{key!r}] is {counts[key]}, the lab's {report[key]}"
        )


def _tiny_frame():
    """A valid call's arguments: a 12 x 8 frame of a scene with media (without media the
    call returns before the device check), float32 CPU images."""
    from course.core.camera import Camera
    from course.given.lab5 import ConstantFog, PointLight, Scene

    camera = Camera(eye=(0.0, 1.0, 2.0), target=(0.0, 1.0, -5.0), width=12, height=8)
    scene = Scene(media=(ConstantFog(),), lights=(PointLight(),))
    return scene, camera, torch.ones(8, 12), torch.zeros(8, 12, 3)


@needs_triton
def test_bad_arguments_are_named():
    """render_froxels_fused checks every argument before its first launch (no interpreter
    needed): each bad one raises a TypeError (wrong kind) or ValueError (wrong shape,
    device or value) naming it, with or without media in the scene."""
    from course.given.lab5 import ConstantFog, Scene
    from course.grading.testing import expect_error
    from course.kernels.triton_froxel import render_froxels_fused

    scene, camera, depth, opaque = _tiny_frame()
    positional = [  # (name, kind, case, scene, camera, depth_image, opaque_image)
        ("camera", TypeError, "a string as the camera", "camera", depth, opaque),
        ("depth_image", TypeError, "a numpy depth image", camera, depth.numpy(), opaque),
        ("depth_image", TypeError, "int64 depths", camera, depth.long(), opaque),
        ("depth_image", TypeError, "float16 images", camera, depth.half(), opaque.half()),
        ("depth_image", ValueError, "depths of shape (W, H)", camera, depth.T, opaque),
        ("depth_image", ValueError, "depths with a channel axis", camera, depth[..., None], opaque),
        ("opaque_image", TypeError, "None as the opaque image", camera, depth, None),
        (
            "opaque_image",
            TypeError,
            "a float64 opaque image with float32 depths",
            camera,
            depth,
            opaque.double(),
        ),
        ("opaque_image", ValueError, "an RGBA opaque image", camera, depth, torch.zeros(8, 12, 4)),
        ("opaque_image", ValueError, "an (H, W) opaque image", camera, depth, depth),
        (
            "opaque_image",
            ValueError,
            "the opaque image on another device than the depths",
            camera,
            depth,
            opaque.to("meta"),
        ),
    ]
    keywords = [  # (name, kind, case, keyword arguments)
        ("tile", ValueError, "tile = 0", {"tile": 0}),
        ("slices", ValueError, "slices = 0", {"slices": 0}),
        ("slices", ValueError, "slices = True", {"slices": True}),
        ("slices", ValueError, "slices = 16.0", {"slices": 16.0}),
        ("near", ValueError, "near = 0", {"near": 0.0}),
        ("near", ValueError, "near = NaN", {"near": math.nan}),
        ("near", TypeError, "near as a string", {"near": "0.1"}),
        ("far", ValueError, "far == near", {"near": 1.0, "far": 1.0}),
        ("far", ValueError, "far = inf", {"far": math.inf}),
        ("phase", ValueError, "an unknown phase function", {"phase": "rayleigh"}),
        ("integration", ValueError, "an unknown integration", {"integration": "trapezoid"}),
        ("shadow_resolution", ValueError, "shadow_resolution = 0", {"shadow_resolution": 0}),
        ("shadow_resolution", ValueError, "shadow_resolution = True", {"shadow_resolution": True}),
        ("shadow_resolution", ValueError, "shadow_resolution = 16.0", {"shadow_resolution": 16.0}),
        (
            "volume_resolution",
            ValueError,
            "volume_resolution = 1 (one depth sample)",
            {"volume_resolution": 1},
        ),
        ("num_warps", ValueError, "num_warps = 3", {"num_warps": 3}),
        ("num_warps", ValueError, "num_warps = 64", {"num_warps": 64}),
        ("num_warps", ValueError, "num_warps = 0", {"num_warps": 0}),
        ("num_warps", ValueError, "num_warps = 2.0", {"num_warps": 2.0}),
    ]
    expect_error(
        "scene",
        render_froxels_fused,
        [ConstantFog()],
        camera,
        depth,
        opaque,
        kinds=(TypeError,),
        case="a list of media as the scene",
    )
    for media, sc in (("with media", scene), ("without media", Scene())):
        for name, kind, case, *args in positional:
            expect_error(
                name, render_froxels_fused, sc, *args, kinds=(kind,), case=f"{case} ({media})"
            )
        for name, kind, case, kwargs in keywords:
            expect_error(
                name,
                render_froxels_fused,
                sc,
                camera,
                depth,
                opaque,
                **kwargs,
                kinds=(kind,),
                case=f"{case} ({media})",
            )


@needs_triton
def test_cpu_images_need_the_interpreter():
    """Compiled, the kernels need CUDA tensors: CPU images are refused, naming depth_image,
    before anything is packed or launched."""
    from course.grading.testing import expect_error
    from course.kernels.triton_froxel import render_froxels_fused
    from course.kernels.triton_intersect import interpreting

    if interpreting():
        pytest.skip("TRITON_INTERPRET=1 is set in this process: CPU tensors are accepted")
    expect_error(
        "depth_image",
        render_froxels_fused,
        *_tiny_frame(),
        kinds=(ValueError,),
        case="CPU images without TRITON_INTERPRET=1",
    )


if __name__ == "__main__":
    torch.save(run_kernels(torch.load(sys.argv[1], weights_only=False), "cpu"), sys.argv[2])
