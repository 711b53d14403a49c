"""Tests of the course framework: devices, types, camera, scenes, images and benchmarking.

CPU only and fast; the device-mismatch checks use torch's "meta" device, which exists
everywhere, so they run without a GPU.
"""

import dataclasses
import json
import math

import numpy as np
import pytest
import torch
import trimesh

from course.core import scenes
from course.core.camera import Camera, look_at, perspective, primary_rays
from course.core.device import available_devices, default_device
from course.core.image import from_srgb8, save_png, show, srgb_decode, srgb_encode, to_srgb8
from course.core.scenes import QuadLight, list_scenes, load_mesh, load_scene
from course.core.types import Hits, Mesh, Rays, closest
from course.measure import bench
from course.measure.bench import (
    ResultTable,
    device_name,
    pareto_front,
    pareto_plot,
    time_fn,
    time_replayed,
)


@pytest.fixture(autouse=True)
def _isolated_env(monkeypatch, tmp_path):
    """No test sees the user's device override or writes into the user's cache."""
    monkeypatch.delenv("RTCOURSE_DEVICE", raising=False)
    monkeypatch.setenv("RTCOURSE_CACHE", str(tmp_path / "cache"))


# ---------------------------------------------------------------------------------------
# device


def test_default_device_prefers_cuda_when_present():
    expected = "cuda" if torch.cuda.is_available() else "cpu"
    assert default_device().type == expected
    assert available_devices()[0] == "cpu"
    assert expected in available_devices()


def test_default_device_argument_overrides_env(monkeypatch):
    monkeypatch.setenv("RTCOURSE_DEVICE", "cpu")
    assert default_device() == torch.device("cpu")
    assert default_device(torch.device("cpu")) == torch.device("cpu")


@pytest.mark.parametrize(
    "spec, match",
    [("gpu0", "prefer.*not a device"), ("meta", "prefer.*cpu' and 'cuda"), ("cuda:99", "prefer")],
)
def test_default_device_rejects_bad_devices(spec, match):
    with pytest.raises(ValueError, match=match):
        default_device(spec)


def test_default_device_rejects_bad_env(monkeypatch):
    monkeypatch.setenv("RTCOURSE_DEVICE", "banana")
    with pytest.raises(ValueError, match="RTCOURSE_DEVICE"):
        default_device()


@pytest.mark.skipif(torch.cuda.is_available(), reason="checks the message without CUDA")
def test_default_device_cuda_missing():
    with pytest.raises(ValueError, match="CUDA is not available"):
        default_device("cuda")


# ---------------------------------------------------------------------------------------
# types


def _rays(n=4, dtype=torch.float32):
    g = torch.Generator().manual_seed(0)
    return Rays.create(
        torch.rand(n, 3, generator=g, dtype=dtype), torch.randn(n, 3, generator=g, dtype=dtype)
    )


def test_rays_create_broadcasts():
    rays = Rays.create([0.0, 1.0, 2.0], torch.ones(5, 3, dtype=torch.float64), t_min=1e-3)
    assert len(rays) == 5 and rays.dtype == torch.float64
    assert rays.origins.shape == (5, 3) and rays.origins[4].tolist() == [0.0, 1.0, 2.0]
    assert rays.t_min.shape == (5,) and torch.all(rays.t_min == 1e-3)
    assert torch.all(torch.isinf(rays.t_max))
    assert torch.equal(
        rays.at(torch.full((5,), 2.0, dtype=torch.float64)), rays.origins + 2 * rays.directions
    )


@pytest.mark.parametrize(
    "field, value, error, match",
    [
        (
            "origins",
            torch.zeros(4, 4),
            ValueError,
            r"origins: expected shape \(N, 3\), got \(4, 4\)",
        ),
        ("directions", torch.zeros(4, 3, dtype=torch.int32), TypeError, "directions.*floating"),
        ("t_min", torch.zeros(4, dtype=torch.float64), TypeError, "t_min.*float32 like origins"),
        ("t_max", torch.zeros(3), ValueError, r"t_max.*N=4 as in origins"),
        ("origins", [[0.0, 0.0, 0.0]] * 4, TypeError, "origins.*torch.Tensor"),
        ("t_max", torch.zeros(4, device="meta"), ValueError, "t_max.*device cpu like origins"),
    ],
)
def test_rays_validation_names_field(field, value, error, match):
    with pytest.raises(error, match=match):
        dataclasses.replace(_rays(), **{field: value})


def test_rays_create_errors():
    with pytest.raises(ValueError, match=r"directions: expected shape \(N, 3\)"):
        Rays.create(torch.zeros(3), torch.zeros(3))
    with pytest.raises(ValueError, match=r"t_min: expected shape \(4,\) or a scalar"):
        Rays.create(torch.zeros(3), torch.ones(4, 3), t_min=torch.zeros(2))
    with pytest.raises(ValueError, match="origins: expected device cpu"):
        Rays.create(torch.zeros(3, device="meta"), torch.ones(4, 3))


def test_degenerate_values_are_allowed():
    rays = Rays.create(torch.tensor([[math.nan, 0, 0]]), torch.zeros(1, 3))
    mesh = Mesh(torch.tensor([[0.0, 0, 0], [1, 1, 1], [2, 2, 2]]), torch.tensor([[0, 1, 1]]))
    assert len(rays) == 1 and mesh.num_faces == 1


def test_types_are_frozen_and_move():
    rays = _rays()
    with pytest.raises(dataclasses.FrozenInstanceError):
        rays.origins = rays.directions
    assert rays.to(torch.float64).dtype == torch.float64
    assert rays.to("cpu", torch.float16).t_max.dtype == torch.float16
    hits = Hits.miss(3).to(torch.float64)
    assert hits.t.dtype == torch.float64 and hits.triangle.dtype == torch.int64


def test_batch_indexing():
    rays = _rays(6)
    assert len(rays[2:5]) == 3 and len(rays[0]) == 1
    mask = torch.tensor([True, False] * 3)
    assert torch.equal(rays[mask].directions, rays.directions[mask])


def test_hits_miss_and_validation():
    hits = Hits.miss(5, torch.float64)
    assert torch.all(torch.isinf(hits.t)) and torch.all(hits.triangle == -1)
    assert not hits.hit.any() and len(hits) == 5 and hits.dtype == torch.float64
    with pytest.raises(TypeError, match="triangle: expected dtype torch.int64"):
        dataclasses.replace(hits, triangle=hits.triangle.int())


def test_closest_takes_nearer_and_keeps_first_on_ties():
    h1 = Hits(
        torch.tensor([1.0, 5.0, math.inf, 2.0]),
        torch.tensor([0, 1, -1, 3]),
        torch.full((4,), 0.1),
        torch.full((4,), 0.2),
    )
    h2 = Hits(
        torch.tensor([3.0, 4.0, 6.0, 2.0]),
        torch.tensor([10, 11, 12, 13]),
        torch.full((4,), 0.3),
        torch.full((4,), 0.4),
    )
    best = closest(h1, h2)
    assert best.t.tolist() == [1.0, 4.0, 6.0, 2.0]
    assert best.triangle.tolist() == [0, 11, 12, 3]
    assert best.u.tolist() == pytest.approx([0.1, 0.3, 0.3, 0.1])
    with pytest.raises(ValueError, match="h2: expected 4 hits"):
        closest(h1, Hits.miss(3))


def test_mesh_triangles_and_validation():
    vertices = torch.tensor([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    mesh = Mesh(vertices, torch.tensor([[0, 1, 2], [0, 2, 3]]))
    assert mesh.num_faces == 2 and mesh.num_vertices == 4
    assert torch.equal(mesh.triangles()[1], vertices[[0, 2, 3]])
    with pytest.raises(ValueError, match="faces.*empty mesh"):
        Mesh(vertices, torch.zeros(0, 3, dtype=torch.int64))
    with pytest.raises(ValueError, match=r"faces: expected indices in \[0, 4\).*\[0, 4\]"):
        Mesh(vertices, torch.tensor([[0, 1, 4]]))
    with pytest.raises(ValueError, match="faces: expected indices"):
        Mesh(vertices, torch.tensor([[-1, 1, 2]]))
    with pytest.raises(TypeError, match="vertices: expected a floating-point"):
        Mesh(vertices.long(), torch.tensor([[0, 1, 2]]))
    with pytest.raises(TypeError, match="faces: expected dtype torch.int64"):
        Mesh(vertices, torch.tensor([[0, 1, 2]], dtype=torch.int32))


# ---------------------------------------------------------------------------------------
# camera


def test_look_at_is_orthonormal_and_maps_eye_to_origin():
    eye, target = (3.0, -2.0, 5.0), (0.5, 1.0, -1.0)
    view = look_at(eye, target, (0.2, 1.0, 0.1))
    rotation = view[:3, :3]
    assert view.dtype == torch.float64
    assert torch.allclose(rotation @ rotation.T, torch.eye(3, dtype=torch.float64), atol=1e-12)
    assert torch.det(rotation).item() == pytest.approx(1.0)  # right-handed
    assert torch.allclose(
        view @ torch.tensor([*eye, 1.0], dtype=torch.float64),
        torch.tensor([0.0, 0, 0, 1], dtype=torch.float64),
        atol=1e-12,
    )
    # The target lies straight ahead, on the camera's -z axis.
    distance = math.dist(eye, target)
    assert torch.allclose(
        view @ torch.tensor([*target, 1.0], dtype=torch.float64),
        torch.tensor([0.0, 0, -distance, 1], dtype=torch.float64),
        atol=1e-12,
    )


def test_look_at_errors():
    with pytest.raises(ValueError, match="target: must differ from eye"):
        look_at((1, 2, 3), (1, 2, 3), (0, 1, 0))
    with pytest.raises(ValueError, match="up: must not be parallel"):
        look_at((0, 0, 0), (0, 5, 0), (0, 1, 0))
    with pytest.raises(ValueError, match="eye: expected 3 coordinates"):
        look_at((0, 0), (0, 0, 1), (0, 1, 0))


def _ndc(matrix, point):
    clip = matrix @ torch.tensor([*point, 1.0], dtype=torch.float64)
    return clip[:3] / clip[3]


def test_perspective_maps_near_and_far_planes():
    proj = perspective(60.0, 1.5, 0.1, 100.0)
    assert _ndc(proj, (0.0, 0.0, -0.1))[2].item() == pytest.approx(-1.0)
    assert _ndc(proj, (0.0, 0.0, -100.0))[2].item() == pytest.approx(1.0)
    # A point on the top edge of the frustum lands on ndc y = 1.
    assert _ndc(proj, (0.0, math.tan(math.radians(30)), -1.0))[1].item() == pytest.approx(1.0)
    infinite = perspective(60.0, 1.5, 0.1, math.inf)
    assert _ndc(infinite, (0.0, 0.0, -0.1))[2].item() == pytest.approx(-1.0)
    assert _ndc(infinite, (0.0, 0.0, -1e12))[2].item() == pytest.approx(1.0)


@pytest.mark.parametrize(
    "args, match",
    [
        ((0.0, 1.0, 0.1, 10.0), "fov_y_deg"),
        ((180.0, 1.0, 0.1, 10.0), "fov_y_deg"),
        ((60.0, 0.0, 0.1, 10.0), "aspect"),
        ((60.0, 1.0, 0.0, 10.0), "near"),
        ((60.0, 1.0, 1.0, 1.0), "far"),
    ],
)
def test_perspective_errors(args, match):
    with pytest.raises(ValueError, match=match):
        perspective(*args)


@pytest.mark.parametrize(
    "changes, match",
    [
        ({"width": 0}, "width"),
        ({"height": -3}, "height"),
        ({"width": 2.5}, "width"),
        ({"fov_y": 180.0}, "fov_y"),
        ({"fov_y": 0.0}, "fov_y"),
        ({"near": -1.0}, "near"),
        ({"target": (1.0, 2.0, 3.0)}, "target"),
    ],
)
def test_camera_validation(changes, match):
    args = {"eye": (1.0, 2.0, 3.0), "target": (0.0, 0.0, 0.0)}
    with pytest.raises(ValueError, match=match):
        Camera(**{**args, **changes})


def _camera(width=7, height=5):
    return Camera(
        eye=(2.0, 1.5, 4.0),
        target=(-0.5, 0.3, 0.2),
        up=(0.1, 1.0, 0.0),
        fov_y=50.0,
        width=width,
        height=height,
    )


def test_primary_rays_layout():
    camera = _camera()
    rays = primary_rays(camera, device="cpu")
    assert len(rays) == 35 and rays.dtype == torch.float32 and rays.device.type == "cpu"
    assert torch.allclose(rays.directions.norm(dim=1), torch.ones(35))
    assert torch.all(rays.t_min == 0) and torch.all(torch.isinf(rays.t_max))
    assert torch.allclose(rays.origins, torch.tensor(camera.eye).expand(35, 3))
    # Row 0 is the top row and column 0 the left column, in camera space.
    view = camera.view(torch.float32)[:3, :3]
    first, last = view @ rays.directions[0], view @ rays.directions[-1]
    assert first[0] < 0 < last[0] and first[1] > 0 > last[1]
    assert primary_rays(camera, dtype=torch.float16, device="cpu").dtype == torch.float16


def test_center_ray_points_at_target():
    camera = _camera()
    rays = primary_rays(camera, dtype=torch.float64, device="cpu")
    center = rays.directions[(camera.height // 2) * camera.width + camera.width // 2]
    to_target = torch.tensor(camera.target, dtype=torch.float64) - torch.tensor(camera.eye)
    assert torch.allclose(center, to_target / to_target.norm(), atol=1e-12)


def test_primary_rays_reproject_to_pixel_centres():
    camera = _camera()
    rays = primary_rays(camera, dtype=torch.float64, device="cpu")
    points = rays.at(torch.full((len(rays),), 3.7, dtype=torch.float64))
    clip = (
        torch.cat([points, torch.ones(len(rays), 1, dtype=torch.float64)], 1)
        @ camera.view_projection().T
    )
    ndc = clip[:, :3] / clip[:, 3:]
    x = (ndc[:, 0] + 1) / 2 * camera.width
    y = (1 - ndc[:, 1]) / 2 * camera.height
    rows, cols = torch.meshgrid(
        torch.arange(camera.height), torch.arange(camera.width), indexing="ij"
    )
    assert torch.allclose(x, cols.flatten().double() + 0.5, atol=1e-9)
    assert torch.allclose(y, rows.flatten().double() + 0.5, atol=1e-9)
    assert torch.all(ndc[:, 2].abs() < 1)  # inside the depth range


# ---------------------------------------------------------------------------------------
# image


def test_srgb_transfer_function():
    x = torch.tensor([0.0, 0.0031308, 0.5, 1.0], dtype=torch.float64)
    expected = [0.0, 0.0031308 * 12.92, 1.055 * 0.5 ** (1 / 2.4) - 0.055, 1.0]
    assert srgb_encode(x).tolist() == pytest.approx(expected, abs=1e-12)
    grid = torch.linspace(0, 1, 1001, dtype=torch.float64)
    assert torch.allclose(srgb_decode(srgb_encode(grid)), grid, atol=1e-12)
    # The two pieces meet: the function is continuous at the threshold (to ~1e-7).
    assert srgb_encode(
        torch.tensor(0.0031308 + 1e-12, dtype=torch.float64)
    ).item() == pytest.approx(0.04045, abs=1e-6)


def test_srgb_clamps_and_zeroes_nan():
    x = torch.tensor([-1.0, 2.0, math.nan, math.inf, -math.inf])
    assert srgb_encode(x).tolist() == [0.0, 1.0, 0.0, 1.0, 0.0]
    assert srgb_decode(x).tolist() == [0.0, 1.0, 0.0, 1.0, 0.0]
    with pytest.raises(TypeError, match="linear: expected a floating-point"):
        srgb_encode(torch.tensor([1, 2]))


def test_to_srgb8_rounds_half_up_and_roundtrips():
    # Linear values whose code value 255 * encode(x) is exactly 0.5, 1.5, 2.5.
    halves = torch.tensor([[[0.5, 1.5, 2.5]]], dtype=torch.float64) / 255 / 12.92
    assert to_srgb8(halves).tolist() == [[[1, 2, 3]]]
    codes = torch.arange(256, dtype=torch.uint8).reshape(16, 16, 1).expand(16, 16, 3)
    assert torch.equal(to_srgb8(from_srgb8(codes, torch.float64)), codes)
    assert torch.equal(to_srgb8(from_srgb8(codes).half()), codes)


def test_image_shape_errors():
    with pytest.raises(ValueError, match=r"img: expected shape \(H, W, 3\), got \(4, 4\)"):
        to_srgb8(torch.zeros(4, 4))
    with pytest.raises(TypeError, match="img8: expected dtype torch.uint8"):
        from_srgb8(torch.zeros(2, 2, 3))
    with pytest.raises(ValueError, match="img"):
        save_png("unused.png", torch.zeros(2, 2, 4))


def test_save_png_roundtrip(tmp_path):
    from PIL import Image

    img = torch.rand(4, 5, 3, generator=torch.Generator().manual_seed(1))
    path = save_png(tmp_path / "sub" / "img.png", img)
    assert np.array_equal(np.asarray(Image.open(path).convert("RGB")), to_srgb8(img).numpy())
    codes = torch.randint(0, 256, (3, 2, 3), dtype=torch.uint8)
    assert np.array_equal(
        np.asarray(Image.open(save_png(tmp_path / "c.png", codes))), codes.numpy()
    )


def test_show_draws_on_axes():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ax = show(torch.zeros(3, 4, 3), title="black")
    assert ax.get_title() == "black" and ax.images[0].get_array().shape == (3, 4, 3)
    plt.close(ax.figure)


# ---------------------------------------------------------------------------------------
# bench


def test_time_fn_on_cpu():
    calls = []
    timing = time_fn(lambda x: calls.append(x.sum()), torch.ones(10), repeats=5, warmup=2)
    assert len(calls) == 7
    assert timing.repeats == 5 and timing.device == "cpu" and timing.method == "perf_counter"
    assert 0 <= timing.min <= timing.median <= timing.max and timing.min <= timing.mean
    assert "median of 5" in str(timing)
    with pytest.raises(ValueError, match="repeats"):
        time_fn(lambda: None, repeats=0)
    with pytest.raises(ValueError, match="warmup"):
        time_fn(lambda: None, warmup=-1)


def test_time_replayed_falls_back_to_time_fn_on_cpu():
    calls = []
    timing = time_replayed(lambda x: calls.append(x.sum()), torch.ones(10), repeats=4, warmup=1)
    assert len(calls) == 5 and timing.method == "perf_counter" and timing.repeats == 4
    with pytest.raises(ValueError, match="calls"):
        time_replayed(lambda: None, calls=0)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")
def test_time_replayed_times_the_kernels_of_a_captured_graph():
    x = torch.randn(2048, 2048, device="cuda")
    calls = []

    def work(a):
        calls.append(1)
        return a @ a

    timing = time_replayed(work, x, calls=4, repeats=5, warmup=2)
    # Python runs for the warm-up and the capture only: replays do not call it.
    assert len(calls) == 2 + 4 and timing.method == "cuda-graph"
    # A 2048^3 matmul is ~17 GFLOP: more than 1 us on any GPU, less than 1 s.
    assert 1e-6 < timing.min <= timing.median <= timing.max < 1.0


def test_time_fn_infers_device_from_dataclass_arguments():
    assert bench._tensor_device([3, _rays()]) == torch.device("cpu")
    assert bench._tensor_device([3, "x"]) is None


def test_device_name_is_filesystem_safe():
    name = device_name("cpu")
    assert name.startswith("cpu-") and name.endswith("cores")
    assert all(c.isalnum() or c == "-" for c in name)


def test_result_table_json_and_markdown(tmp_path):
    table = ResultTable("demo", device="cpu")
    table.add(variant="a", seconds=torch.tensor(0.5), error=np.float64(1e-3), n=3)
    table.add(variant="b", seconds=0.25, error=0.123456789)
    path = table.to_json(tmp_path / "out" / "demo.json")
    data = json.loads(path.read_text())
    assert data["rows"][0] == {"variant": "a", "seconds": 0.5, "error": 1e-3, "n": 3}
    assert {"device", "device_name", "torch", "command", "date"} <= set(data["metadata"])
    assert data["metadata"]["torch"] == torch.__version__
    assert ResultTable.from_json(path).rows == table.rows
    lines = table.to_markdown().splitlines()
    assert lines[0] == "| variant | seconds | error | n |"
    assert lines[3] == "| b | 0.25 | 0.1235 |  |"


def test_pareto_front():
    rows = [
        {"seconds": 1.0, "error": 0.1},
        {"seconds": 2.0, "error": 0.01},
        {"seconds": 3.0, "error": 0.05},
        {"seconds": 0.5, "error": 0.5},
        {"seconds": 2.0, "error": 0.2},
        {"seconds": math.nan, "error": 0.0},
    ]
    assert pareto_front(rows, "seconds", "error") == [3, 0, 1]
    fast = [
        {"rays_per_s": 1e6, "error": 0.1},
        {"rays_per_s": 1e7, "error": 0.2},
        {"rays_per_s": 1e5, "error": 0.3},
    ]
    assert pareto_front(fast, "rays_per_s", "error", maximize_x=True) == [1, 0]


def test_pareto_plot_writes_file(tmp_path):
    rows = [
        {
            "setting": f"s{i}",
            "variant": "ab"[i % 2],
            "rays_per_s": 10.0**i,
            "error": 10.0**-i if i else 0.0,
        }
        for i in range(5)
    ]
    fig = pareto_plot(
        rows,
        x="rays_per_s",
        y="error",
        label="setting",
        group="variant",
        path=tmp_path / "plots" / "p.png",
    )
    assert (tmp_path / "plots" / "p.png").stat().st_size > 0
    assert "higher is better" in fig.axes[0].get_xlabel()
    with pytest.raises(ValueError, match="rows: no row"):
        pareto_plot(rows, x="seconds", y="error")


# ---------------------------------------------------------------------------------------
# scenes


def test_list_scenes():
    assert {
        "triangle",
        "cornell_box",
        "icosphere",
        "random_soup",
        "teapot_in_stadium",
        "suzanne",
        "bunny",
        "bunny_x4",
        "bunny_x16",
    } <= set(list_scenes())
    with pytest.raises(ValueError, match="name: unknown scene 'nope'"):
        load_scene("nope")


@pytest.mark.parametrize(
    "name", ["triangle", "icosphere", "random_soup", "cornell_box", "suzanne", "teapot_in_stadium"]
)
def test_small_scenes_have_mesh_and_camera(name):
    scene = load_scene(name, device="cpu", dtype=torch.float64)
    assert scene.mesh.vertices.dtype == torch.float64 and scene.mesh.device.type == "cpu"
    assert isinstance(scene.camera, Camera) and scene.media is None
    # The default camera looks at the scene: its centre ray starts inside the far plane.
    view = scene.camera.view()
    depth = -(scene.mesh.vertices @ view[:3, :3].T + view[:3, 3])[:, 2]
    assert depth.max() > 0 and depth.min() < scene.camera.far


def test_icosphere_is_watertight():
    mesh = load_scene("icosphere", level=2, device="cpu").mesh
    assert mesh.num_faces == 20 * 4**2
    surface = trimesh.Trimesh(mesh.vertices.numpy(), mesh.faces.numpy(), process=False)
    assert surface.is_watertight and surface.is_winding_consistent and surface.volume > 0
    with pytest.raises(ValueError, match="level"):
        load_scene("icosphere", level=-1)


def test_random_soup_is_deterministic_and_varied():
    a = load_scene("random_soup", n=500, seed=3, device="cpu").mesh
    b = load_scene("random_soup", n=500, seed=3, device="cpu").mesh
    c = load_scene("random_soup", n=500, seed=4, device="cpu").mesh
    assert a.num_faces == 500 and torch.equal(a.vertices, b.vertices)
    assert not torch.equal(a.vertices, c.vertices)
    assert a.vertices.min() >= 0 and a.vertices.max() <= 1
    extent = (a.triangles().amax(1) - a.triangles().amin(1)).amax(1)
    assert extent.max() / extent.min() > 50
    with pytest.raises(ValueError, match="n: expected at least one"):
        load_scene("random_soup", n=0)


def test_cornell_box_is_closed_with_a_ceiling_light():
    scene = load_scene("cornell_box", device="cpu")
    surface = trimesh.Trimesh(scene.mesh.vertices.numpy(), scene.mesh.faces.numpy())
    assert surface.is_watertight
    lo, hi = scene.mesh.vertices.amin(0), scene.mesh.vertices.amax(0)
    eye = torch.tensor(scene.camera.eye)
    assert torch.all(eye > lo) and torch.all(eye < hi)
    (light,) = scene.lights
    assert isinstance(light, QuadLight) and light.normal == pytest.approx((0.0, -1.0, 0.0))
    assert hi[1] - 0.01 < light.center[1] < hi[1] and light.area > 0


def test_teapot_in_stadium_is_dense_inside_sparse():
    mesh = load_scene("teapot_in_stadium", subdivisions=1, device="cpu").mesh
    scene_extent = (mesh.vertices.amax(0) - mesh.vertices.amin(0)).max()
    near_origin = mesh.vertices.norm(dim=1) < 0.2
    assert scene_extent >= 200 and near_origin.float().mean() > 0.99
    assert mesh.num_faces == 968 * 4 + 12


def test_load_mesh_assets_and_formats(tmp_path):
    suzanne = load_mesh("suzanne", device="cpu")
    assert suzanne.num_faces == 968 and suzanne.num_vertices < 3 * 968  # merged seams
    sphere = trimesh.creation.icosphere(subdivisions=1)
    for suffix in ("obj", "ply"):
        sphere.export(tmp_path / f"s.{suffix}")
        mesh = load_mesh(tmp_path / f"s.{suffix}", device="cpu", dtype=torch.float64)
        assert mesh.num_faces == 80
        assert np.allclose(
            np.sort(mesh.triangles().numpy().reshape(-1)),
            np.sort(sphere.triangles.reshape(-1)),
            atol=1e-6,
        )


def test_load_mesh_flattens_gltf_node_transforms(tmp_path):
    tri = trimesh.Trimesh([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])
    scene = trimesh.Scene()
    scene.add_geometry(tri, node_name="a")
    scene.add_geometry(
        tri, node_name="b", transform=trimesh.transformations.translation_matrix([10.0, 0, 0])
    )
    scene.export(tmp_path / "two.glb")
    mesh = load_mesh(tmp_path / "two.glb", device="cpu")
    assert mesh.num_faces == 2
    assert sorted(mesh.triangles()[:, :, 0].min(1).values.tolist()) == [0.0, 10.0]
    loaded = load_scene(str(tmp_path / "two.glb"), device="cpu")
    assert loaded.name == "two" and loaded.camera is not None


def test_load_mesh_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="path_or_name.*suzanne"):
        load_mesh(tmp_path / "missing.obj")
    (tmp_path / "points.obj").write_text("v 0 0 0\nv 1 0 0\n")
    with pytest.raises(ValueError, match="path_or_name.*no triangles"):
        load_mesh(tmp_path / "points.obj")


def test_bunny_x4_is_subdivided_and_cached(tmp_path, monkeypatch):
    bunny = load_scene("bunny", device="cpu").mesh
    x4 = load_scene("bunny_x4", device="cpu").mesh
    assert bunny.num_faces == 69451 and x4.num_faces == 4 * bunny.num_faces
    assert (tmp_path / "cache" / "bunny_loop1.npz").is_file()

    def no_rebuild(*args, **kwargs):
        raise AssertionError("the cached subdivision should have been used")

    monkeypatch.setattr(trimesh.remesh, "subdivide_loop", no_rebuild)
    again = load_scene("bunny_x4", device="cpu").mesh
    assert torch.equal(again.vertices, x4.vertices) and torch.equal(again.faces, x4.faces)


def test_cache_rebuilds_unreadable_files(tmp_path):
    (tmp_path / "cache").mkdir()
    (tmp_path / "cache" / "k.npz").write_bytes(b"truncated")

    def build():
        return np.zeros((3, 3)), np.array([[0, 1, 2]])

    assert scenes._cached("k", build)[1].tolist() == [[0, 1, 2]]
    assert scenes._cached("k", None)[1].tolist() == [[0, 1, 2]]
    assert sorted(p.name for p in (tmp_path / "cache").iterdir()) == ["k.npz"]
