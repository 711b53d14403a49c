"""The course's own building blocks: types, camera, images, scenes, timing, devices."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from course.bench import ResultTable, pareto_front, time_fn
from course.camera import Camera, look_at, perspective, primary_rays
from course.device import default_device
from course.image import from_srgb8, save_png, srgb_decode, srgb_encode, to_srgb8
from course.scenes import list_scenes, load_mesh, load_scene
from course.testing import assert_close, assert_equal
from course.types import Hits, Mesh, Rays, closest

# ----------------------------------------------------------------------------- types


def test_rays_broadcast_and_validate(device):
    d = torch.randn(5, 3, device=device)
    rays = Rays.create([0.0, 1.0, 2.0], d, t_min=1e-3)
    assert rays.origins.shape == (5, 3) and rays.t_max.isinf().all()
    assert rays.origins.device == d.device and rays.t_min.dtype == d.dtype
    assert_close(rays.at(torch.ones(5, device=device)), rays.origins + d, name="at", atol=0)
    with pytest.raises(ValueError, match="directions"):
        Rays.create([0.0, 0.0, 0.0], torch.zeros(5, 2))
    with pytest.raises(ValueError, match="t_min"):
        Rays.create([0.0, 0.0, 0.0], torch.zeros(5, 3), t_min=torch.zeros(4))


def test_mesh_rejects_structural_errors_only():
    v = torch.tensor([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    mesh = Mesh(v, torch.tensor([[0, 1, 2], [0, 0, 0]]))  # a degenerate face is allowed
    assert mesh.num_faces == 2 and mesh.triangles().shape == (2, 3, 3)
    with pytest.raises(ValueError, match="faces"):
        Mesh(v, torch.tensor([[0, 1, 3]]))
    with pytest.raises((ValueError, TypeError), match="faces"):
        Mesh(v, torch.tensor([[0.0, 1.0, 2.0]]))
    with pytest.raises(ValueError):
        Mesh(torch.zeros(0, 3), torch.zeros(0, 3, dtype=torch.int64))


def test_hits_miss_and_closest():
    a = Hits.miss(4)
    assert a.t.isinf().all() and (a.triangle == -1).all()
    b = Hits(t=torch.tensor([1.0, math.inf, 3.0, 2.0]), triangle=torch.tensor([5, -1, 7, 8]),
             u=torch.zeros(4), v=torch.zeros(4))
    c = Hits(t=torch.tensor([2.0, 4.0, 1.0, math.inf]), triangle=torch.tensor([1, 2, 3, -1]),
             u=torch.zeros(4), v=torch.zeros(4))
    best = closest(b, c)
    assert_equal(best.triangle, torch.tensor([5, 2, 3, 8]), name="triangle")
    assert_equal(closest(a, b).triangle, b.triangle, name="triangle")


# ----------------------------------------------------------------------------- camera


def test_view_matrix_is_rigid_and_looks_down_minus_z():
    view = look_at((1.0, 2.0, 3.0), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0))
    rot = view[:3, :3]
    assert_close(rot @ rot.T, torch.eye(3, dtype=rot.dtype), name="R R^T", atol=1e-12)
    target_cam = view @ torch.tensor([0.0, 0.0, 0.0, 1.0], dtype=view.dtype)
    assert target_cam[2] < 0 and abs(target_cam[0]) < 1e-12 and abs(target_cam[1]) < 1e-12


def test_primary_rays_reproject_to_pixel_centres(device):
    cam = Camera(eye=(0.5, 1.0, 4.0), target=(0.0, 0.2, 0.0), fov_y=50.0, width=7, height=5,
                 near=0.1, far=100.0)
    rays = primary_rays(cam, device=device, dtype=torch.float64)
    assert rays.origins.shape == (35, 3) and rays.directions.device.type == device
    assert_close(rays.directions.norm(dim=1), torch.ones(35, dtype=torch.float64),
                 name="|d|", atol=1e-12)
    points = rays.at(torch.full((35,), 3.0, dtype=torch.float64, device=device)).cpu()
    clip = torch.cat([points, torch.ones(35, 1, dtype=torch.float64)], 1) @ cam.view_projection().T
    ndc = clip[:, :3] / clip[:, 3:]
    px = (ndc[:, 0] + 1) / 2 * cam.width          # left to right
    py = (1 - ndc[:, 1]) / 2 * cam.height         # row 0 at the top
    rows, cols = torch.meshgrid(torch.arange(5.0), torch.arange(7.0), indexing="ij")
    assert_close(px, cols.flatten().double() + 0.5, name="pixel x", atol=1e-9, where="ray")
    assert_close(py, rows.flatten().double() + 0.5, name="pixel y", atol=1e-9, where="ray")


def test_camera_rejects_bad_arguments():
    with pytest.raises(ValueError, match="width"):
        Camera(eye=(0, 0, 1), target=(0, 0, 0), width=0)
    with pytest.raises(ValueError, match="fov"):
        Camera(eye=(0, 0, 1), target=(0, 0, 0), fov_y=180.0)
    with pytest.raises(ValueError):
        perspective(45.0, 1.0, near=1.0, far=0.5)


# ----------------------------------------------------------------------------- images


def test_srgb_round_trip_and_extremes():
    x = torch.linspace(0, 1, 1001, dtype=torch.float64)
    assert_close(srgb_decode(srgb_encode(x)), x, name="decode(encode(x))", atol=1e-12)
    odd = torch.tensor([math.nan, -1.0, 2.0, math.inf, 0.0031308, 0.5])
    enc = srgb_encode(odd)
    assert not enc.isnan().any() and enc.min() >= 0 and enc.max() <= 1
    img = torch.tensor([[[0.0, 1.0, math.nan]]])
    assert to_srgb8(img).tolist() == [[[0, 255, 0]]]
    codes = torch.arange(256, dtype=torch.uint8).reshape(16, 16, 1).expand(16, 16, 3)
    assert_equal(to_srgb8(from_srgb8(codes, torch.float64)), codes, name="8-bit round trip")


def test_save_png_writes_the_srgb8_image(tmp_path):
    from PIL import Image

    img = torch.rand(6, 9, 3, generator=torch.Generator().manual_seed(0))
    path = save_png(tmp_path / "x.png", img)
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    back = torch.from_numpy(np.asarray(Image.open(path).convert("RGB")).copy())
    assert_equal(back, to_srgb8(img), name="PNG pixels", where="pixel")
    with pytest.raises(ValueError, match="img"):
        save_png(tmp_path / "y.png", torch.zeros(4, 4))


# ----------------------------------------------------------------------------- scenes


def test_icosphere_is_closed_and_unit():
    import trimesh

    mesh = load_scene("icosphere", level=2).mesh
    assert mesh.num_faces == 320
    tm = trimesh.Trimesh(mesh.vertices.numpy(), mesh.faces.numpy(), process=False)
    assert tm.is_watertight and tm.is_winding_consistent
    assert_close(mesh.vertices.norm(dim=1), torch.ones(mesh.num_vertices), name="radius",
                 atol=1e-6)


def test_random_soup_is_deterministic_and_device_independent(device):
    a = load_scene("random_soup", n=50, seed=3).mesh
    b = load_scene("random_soup", device=device, n=50, seed=3).mesh
    assert_equal(b.vertices.cpu(), a.vertices, name="vertices")
    c = load_scene("random_soup", n=50, seed=4).mesh
    assert not torch.equal(a.vertices, c.vertices)
    assert a.vertices.min() >= 0 and a.vertices.max() <= 1


def test_shipped_assets_load_with_their_transforms():
    suzanne = load_mesh("suzanne")
    assert suzanne.num_faces == 968 and suzanne.faces.dtype == torch.int64
    scene = load_scene("suzanne")
    assert scene.camera is not None and scene.media is None  # only what the scene has
    assert load_mesh("bunny").num_faces == 69451


def test_builtin_scenes_build(device):
    for name in ("triangle", "cornell_box", "teapot_in_stadium"):
        scene = load_scene(name, device=device)
        assert scene.mesh.vertices.device.type == device, name
        assert scene.camera is not None, name
    assert {"suzanne", "bunny", "bunny_x4", "bunny_x16", "icosphere"} <= set(list_scenes())
    with pytest.raises(ValueError, match="name"):
        load_scene("no such scene")


# ----------------------------------------------------------------------------- timing


def test_time_fn_and_result_table(tmp_path):
    timing = time_fn(lambda x: x @ x, torch.ones(32, 32), repeats=5, warmup=1)
    assert timing.min <= timing.median <= timing.max and timing.method == "perf_counter"
    table = ResultTable("t", device="cpu")
    table.add(knob=1, seconds=1.0, error=0.1)
    table.add(knob=2, seconds=2.0, error=0.2)  # slower and worse: not on the front
    table.add(knob=3, seconds=3.0, error=0.01)
    assert sorted(pareto_front(table.rows, "seconds", "error")) == [0, 2]
    path = table.to_json(tmp_path / "t.json")
    assert ResultTable.from_json(path).rows == table.rows
    assert "knob" in table.to_markdown()


def test_default_device_rules(monkeypatch):
    assert default_device("cpu").type == "cpu"
    monkeypatch.setenv("RTCOURSE_DEVICE", "cpu")
    assert default_device().type == "cpu"
    with pytest.raises(ValueError):
        default_device("tpu")
    if not torch.cuda.is_available():
        with pytest.raises(ValueError, match="CUDA"):
            default_device("cuda")
