"""Grader for Lab 3: organising the tracer.

Every organisation of the Whitted tracer is compared with ``render_reference`` (given in
``course.given.lab3``): the shading contract written out plainly and evaluated in
float64 with the secondary-ray offset of the scene's dtype, so what may differ is rounding.
In float64 the images must agree to 1e-9; in float32 to 1e-4 (relative), except for a
small fraction of pixels where a shadow or edge decision flips (a ray that meets a corner
exactly, a shadow ray that starts on the edge of two walls).

The lab receives ``trace_brute_force`` (given) as its tracer, so it is graded without Lab 2.
Each task is graded on its own: the renderers run with given building blocks (this module's
``offset_origins``, ``reflect``, ``surface_at`` and ``shade_direct`` in place of the lab's,
``with_blocks``), so a mistake in a block costs that block's points; only the last task
(``END_TO_END``) renders with the lab's own blocks, and names the block that is wrong.

Scenes: the Cornell box with a mirror box (closed: a magenta background shows a leak), a
courtyard open to the sky (sun and point light, a mirror wall, rays that escape), the same
courtyard with its lamp standing on the floor or 1e-3 above it (grazing shadow rays), and
two facing mirrors, where the radiance of a ray is the analytic series
``ambient kd (1 + kr + ... + kr^max_depth)``. Extremes: NaN/inf/zero rays, axis-parallel
rays with +0.0/-0.0 components, a scene translated by 1e5 (float64), half precision
(rejected with a TypeError), and bad arguments (a ValueError/TypeError naming them).
"""

from __future__ import annotations

import dataclasses
import functools
import math

import pytest
import torch

from course.core.camera import primary_rays
from course.core.types import Hits, Mesh
from course.given.lab3 import (
    WhittedScene,
    face_normals,
    float_as_index,
    make_scene,
    offset_scale,
    render_reference,
    trace_brute_force,
    translated,
    whitted_camera,
    whitted_scene,
)
from course.grading.testing import (
    assert_close,
    assert_equal,
    check_tensor,
    expect_error,
    generator,
    replaced,
)

LAB_MODULE = "lab3_wavefront"
TASKS = {
    1: "Whitted backward tracing: offsets, reflection, shading with shadow rays",
    2: "Separate kernels (wavefront) with compaction and material sorting",
    3: "The uber kernel: fixed-size buffers under torch.compile",
    4: "Persistent workers: a pool of ray slots fed from a global queue",
    5: "Geometry layouts: indexed, float4 triangles, Woop transforms",
    6: "End to end: your tracer with your own building blocks",
}
END_TO_END = 6  # the one task graded on the lab's own chain; every other task on its own

F32, F64 = torch.float32, torch.float64
INF = math.inf
SIZE = 24  # image side of the renders: 576 rays
TOL = {F64: (1e-9, 1e-12), F32: (1e-4, 1e-5)}  # (rtol, atol) per dtype
FAR_TOL = (1e-5, 1e-8)  # float64 at 1e5: coordinates carry 1e5 * 1e-16 of rounding
FLIPS = 0.01  # the fraction of pixels that may differ (shadow/edge decisions)


# ---------------------------------------------------------------------------------------
# Scenes (built once on the CPU in float64, cast and moved per test)


def unchecked(scene: WhittedScene, **fields) -> WhittedScene:
    """A copy of ``scene`` with ``fields`` replaced and *no* validation (a malformed scene
    a lab must reject, built the way the grader's transport builds dataclasses)."""
    bad = object.__new__(WhittedScene)
    for f in dataclasses.fields(WhittedScene):
        object.__setattr__(bad, f.name, fields.get(f.name, getattr(scene, f.name)))
    return bad


@functools.cache
def _courtyard(lamp: str) -> WhittedScene:
    """A floor 4 x 4, a glossy cube on it, a mirror wall behind, open to a sky background.

    lamp: "both" (sun + point light), "sun" (sun only), "floor" (a point light standing on
    the floor, nothing else) or "grazing" (that light 1e-3 above the floor).
    """
    import trimesh

    cube = trimesh.creation.box(extents=(0.8, 0.8, 0.8))
    cube.apply_translation((0.1, 0.4, 0.0))
    corners = torch.tensor(
        [
            [-2.0, 0.0, -2.0],
            [2.0, 0.0, -2.0],
            [2.0, 0.0, 2.0],
            [-2.0, 0.0, 2.0],
            [-2.0, 0.0, -1.5],
            [2.0, 0.0, -1.5],
            [2.0, 2.0, -1.5],
            [-2.0, 2.0, -1.5],
        ],
        dtype=F64,
    )
    vertices = torch.cat((corners, torch.as_tensor(cube.vertices, dtype=F64)))
    faces = torch.cat(
        (
            torch.tensor([[0, 2, 1], [0, 3, 2], [4, 5, 6], [4, 6, 7]]),
            torch.as_tensor(cube.faces, dtype=torch.int64) + 8,
        )
    )
    material = [0, 0, 1, 1] + [2] * 12
    materials = {
        "kd": [[0.6, 0.6, 0.55], [0.05, 0.05, 0.05], [0.7, 0.3, 0.2]],
        "ks": [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.4, 0.4, 0.4]],
        "shininess": [1.0, 1.0, 30.0],
        "kr": [[0, 0, 0], [0.8, 0.8, 0.8], [0, 0, 0]],
    }
    sun = [((0.4, 0.8, 0.45), (1.2, 1.1, 1.0))]
    point = {
        "both": [((-1.2, 1.5, 1.0), (3.0, 3.0, 3.0))],
        "sun": [],
        "floor": [((1.3, 0.0, 1.1), (2.0, 2.0, 2.0))],
        "grazing": [((1.3, 1e-3, 1.1), (2.0, 2.0, 2.0))],
    }[lamp]
    return make_scene(
        Mesh(vertices, faces),
        material,
        materials,
        point_lights=point,
        dir_lights=sun if lamp in ("both", "sun") else [],
        ambient=(0.05, 0.05, 0.05),
        background=(0.3, 0.5, 0.9),
    )


COURTYARD_CAMERA = dataclasses.replace(
    whitted_camera("cornell_mirror"), eye=(0.4, 1.6, 3.4), target=(0.0, 0.4, 0.0)
)


@functools.cache
def _scene(name: str) -> WhittedScene:
    if name.startswith("courtyard"):
        return _courtyard(name.split("_")[1])
    scene = whitted_scene(name, device="cpu", dtype=F64)
    if name == "cornell_mirror":  # a leak through the closed room shows magenta
        scene = dataclasses.replace(scene, background=torch.tensor([1.0, 0.0, 1.0], dtype=F64))
    return scene


def scene_on(name: str, dtype, device) -> WhittedScene:
    return _scene(name).to(device, dtype)


def camera_rays(name: str, dtype, device, size: int = SIZE):
    """Primary rays (origins, directions) of the scene's camera, size x size."""
    camera = COURTYARD_CAMERA if name.startswith("courtyard") else whitted_camera(name)
    rays = primary_rays(
        dataclasses.replace(camera, width=size, height=size), device="cpu", dtype=F64
    )
    return rays.origins.to(device, dtype), rays.directions.to(device, dtype)


def corridor_rays(n: int, seed: int, dtype, device):
    """Rays between the two mirrors of "mirror_corridor", heading for one of them."""
    g = generator(seed)
    o = torch.rand(n, 3, generator=g, dtype=F64) * torch.tensor([2.0, 2.0, 1.0]) - torch.tensor(
        [1.0, 1.0, 0.5]
    )
    # Tilted by at most 0.6 sideways per unit of z: 5 crossings of the corridor drift at most
    # 6 units from |x|, |y| <= 1, inside the mirrors' 10-unit half-width.
    d = (torch.randn(n, 3, generator=g, dtype=F64) * 0.25).clamp(-0.6, 0.6)
    d[:, 2] = torch.where(torch.rand(n, generator=g) < 0.5, -1.0, 1.0)
    d = d / d.norm(dim=1, keepdim=True)
    return o.to(device, dtype), d.to(device, dtype)


def corridor_expected(max_depth: int, dtype) -> torch.Tensor:
    """(3,) float64: ``ambient kd sum_{k=0}^{max_depth} kr^k``, every ray's radiance."""
    scene = _scene("mirror_corridor")
    kr = scene.kr[0].to(dtype).double()
    series = sum(kr**k for k in range(max_depth + 1))
    return (scene.ambient.to(dtype).double() * scene.kd[0].to(dtype).double()) * series


def axis_rays(n_per_axis: int, seed: int, dtype, device):
    """Rays inside the Cornell box parallel to the axes, both ways, with +0.0 and -0.0
    in their zero components."""
    g = generator(seed)
    origins, directions = [], []
    for axis in range(3):
        for sign in (1.0, -1.0):
            o = torch.rand(n_per_axis, 3, generator=g, dtype=F64) * torch.tensor(
                [1.8, 1.8, 3.6]
            ) + torch.tensor([-0.9, 0.1, -0.9])
            d = torch.zeros(n_per_axis, 3, dtype=F64)
            d[:, axis] = sign
            negative_zero = torch.rand(n_per_axis, 3, generator=g) < 0.5
            d = torch.where(negative_zero & (d == 0), torch.tensor(-0.0, dtype=F64), d)
            origins.append(o)
            directions.append(d)
    return torch.cat(origins).to(device, dtype), torch.cat(directions).to(device, dtype)


def bad_rays(dtype, device):
    """NaN/inf origins and directions and a zero direction: each must return background."""
    nan = math.nan
    o = [
        [nan, 1.0, 0.0],
        [0.0, INF, 0.0],
        [0.0, 1.0, 2.0],
        [0.0, 1.0, 2.0],
        [0.0, 1.0, 2.0],
        [-INF, 1.0, 0.0],
    ]
    d = [
        [0.0, 0.0, -1.0],
        [0.0, 0.0, -1.0],
        [nan, 0.0, -1.0],
        [0.0, INF, -1.0],
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
    ]
    return (
        torch.tensor(o, dtype=F64).to(device, dtype),
        torch.tensor(d, dtype=F64).to(device, dtype),
    )


@functools.cache
def _reference(name: str, dtype, max_depth: int, rays: str, size: int = SIZE) -> torch.Tensor:
    """The reference image (CPU float64) of the named ray set."""
    scene = scene_on(name, dtype, "cpu")
    o, d = ray_set(rays, name, dtype, "cpu", size)
    return render_reference(scene, o, d, max_depth)


def ray_set(rays: str, name: str, dtype, device, size: int = SIZE):
    if rays == "camera":
        return camera_rays(name, dtype, device, size)
    if rays == "axis":
        return axis_rays(8, 5, dtype, device)
    if rays == "corridor":
        return corridor_rays(64, 3, dtype, device)
    raise KeyError(rays)


# ---------------------------------------------------------------------------------------
# Comparisons


def image_of(result, what: str, with_stats: bool):
    if with_stats:
        if not (isinstance(result, tuple) and len(result) == 2 and isinstance(result[1], dict)):
            raise AssertionError(
                f"{what}: expected a tuple (image, stats dict), got {type(result).__name__}"
            )
        return result
    return result, None


def compare_images(
    got, expected: torch.Tensor, what: str, dtype, device, flips: float = FLIPS, tol=None
) -> torch.Tensor:
    """``got`` (N, 3) must match the float64 ``expected`` within ``tol = (rtol, atol)`` (by
    default the dtype's) on all but a fraction ``flips`` of the pixels; never NaN/inf."""
    n = expected.shape[0]
    check_tensor(got, f"{what}: the image", shape=(n, 3), dtype=dtype, device=device)
    got = got.detach().to("cpu", F64)
    finite = torch.isfinite(got).all(1)
    if not finite.all():
        i = int((~finite).nonzero()[0, 0])
        raise AssertionError(
            f"{what}: pixel {i} is {got[i].tolist()}: NaN/inf must never "
            f"reach the image (expected {expected[i].tolist()})"
        )
    rtol, atol = tol or TOL[dtype]
    off = ~((got - expected).abs() <= atol + rtol * expected.abs()).all(1)
    if off.double().mean() > flips:
        from course.grading.testing import assert_image_close  # writes expected/got/difference PNGs

        assert_image_close(
            got,
            expected,
            rtol=rtol,
            atol=atol,
            where="(pixel, channel)",
            name=f"{what}: radiance against the float64 reference renderer "
            f"({int(off.sum())} of {n} pixels off; at most {flips:.0%} "
            f"may differ, where a shadow or edge decision flips in "
            f"{dtype})",
        )
    return got


def check_background(image, scene: WhittedScene, what: str) -> None:
    """Every pixel of ``image`` must be exactly the background."""
    bg = scene.background.to("cpu", F64).expand(image.shape[0], 3)
    assert_close(
        image.detach().to("cpu", F64),
        bg,
        name=f"{what}: rays with NaN/inf "
        "components or a zero direction hit nothing and must return the background",
        where="(ray, channel)",
    )


def check_corridor(render, dtype, device, what: str) -> None:
    """Between two facing mirrors every ray bounces to the depth limit: its radiance is the
    series ambient kd (1 + kr + ... + kr^max_depth), exactly max_depth + 1 terms."""
    scene = scene_on("mirror_corridor", dtype, device)
    o, d = corridor_rays(48, 11, dtype, device)
    for max_depth in range(4):
        image = render(scene, o, d, max_depth)
        expected = corridor_expected(max_depth, dtype).expand(len(o), 3)
        check_tensor(image, f"{what}: the image", shape=(len(o), 3), dtype=dtype, device=device)
        assert_close(
            image.detach().cpu(),
            expected,
            rtol=1e-5 if dtype == F32 else 1e-12,
            where="(ray, channel)",
            name=f"{what}: two facing mirrors, max_depth={max_depth}: radiance "
            f"ambient*kd*(1 + kr + ... + kr^{max_depth}) (a primary ray and "
            f"{max_depth} reflections; one term more or less is an off-by-one "
            f"depth limit)",
        )


def reordered_materials(scene: WhittedScene, order) -> WhittedScene:
    """The same scene with its material table reordered: old material ``order[k]`` is
    material ``k`` (the image does not change)."""
    order = torch.as_tensor(order, device=scene.device)
    inverse = torch.empty_like(order)
    inverse[order] = torch.arange(len(order), device=scene.device)
    return dataclasses.replace(
        scene,
        material=inverse[scene.material],
        kd=scene.kd[order],
        ks=scene.ks[order],
        shininess=scene.shininess[order],
        kr=scene.kr[order],
    )


def without_cube(scene: WhittedScene) -> WhittedScene:
    """The courtyard without its cube (its last 12 triangles): the other indices stay."""
    return dataclasses.replace(scene, faces=scene.faces[:-12], material=scene.material[:-12])


def trace_without_cube(scene, origins, directions, t_min, t_max, any_hit=False):
    """A tracer for which the courtyard's cube does not exist (module level: it travels to
    the sandbox by reference)."""
    return trace_brute_force(without_cube(scene), origins, directions, t_min, t_max, any_hit)


def check_uses_trace(render, device, what: str) -> None:
    """A renderer must find every hit through the ``trace`` it is given: with a tracer that
    does not see the courtyard's cube, the image is the courtyard without the cube."""
    scene = scene_on("courtyard_both", F32, device)
    o, d = camera_rays("courtyard_both", F32, device, 16)
    image = render(scene, o, d, trace_without_cube)
    expected = render_reference(without_cube(scene).to("cpu"), o.cpu(), d.cpu(), 2)
    compare_images(
        image,
        expected,
        f"{what} with a tracer that does not see the cube (every "
        f"closest hit and every shadow ray must go through the trace argument)",
        F32,
        device,
    )


def expect_render_errors(render, device, **extra) -> None:
    """Bad arguments of a renderer: ValueError/TypeError naming them."""
    scene = scene_on("cornell_mirror", F32, device)
    o, d = camera_rays("cornell_mirror", F32, device, 4)
    expect_error(
        "origins",
        render,
        scene,
        o[:, :2],
        d,
        trace_brute_force,
        **extra,
        case="origins of shape (16, 2)",
    )
    expect_error(
        "directions",
        render,
        scene,
        o,
        d[:5],
        trace_brute_force,
        **extra,
        case="5 directions for 16 origins",
    )
    expect_error(
        "origins",
        render,
        scene,
        o.half(),
        d.half(),
        trace_brute_force,
        **extra,
        kinds=(TypeError,),
        case="float16 rays (half precision cannot hold the 1e-4 secondary-ray offset: rejected)",
    )
    expect_error(
        ("origins", "directions"),
        render,
        scene,
        o.bfloat16(),
        d.bfloat16(),
        trace_brute_force,
        **extra,
        kinds=(TypeError,),
        case="bfloat16 rays",
    )
    expect_error(
        "origins",
        render,
        scene,
        o.double(),
        d.double(),
        trace_brute_force,
        **extra,
        kinds=(TypeError,),
        case="float64 rays for a float32 scene",
    )
    if torch.device(device).type != "cpu":
        expect_error(
            "origins",
            render,
            scene,
            o.cpu(),
            d.cpu(),
            trace_brute_force,
            **extra,
            case=f"rays on the CPU for a scene on {device}",
        )
    expect_error("trace", render, scene, o, d, "brute force", **extra, case="a string as trace")
    expect_error(
        "max_depth", render, scene, o, d, trace_brute_force, -1, **extra, case="max_depth=-1"
    )
    expect_error(
        "scene",
        render,
        scene.mesh,
        o,
        d,
        trace_brute_force,
        **extra,
        case="a Mesh instead of a WhittedScene",
    )
    no_lights = unchecked(
        scene,
        point_positions=scene.point_positions[:0],
        point_intensities=scene.point_intensities[:0],
    )
    expect_error(
        "lights",
        render,
        no_lights,
        o,
        d,
        trace_brute_force,
        **extra,
        case="a scene without any light",
    )
    bad_material = unchecked(scene, material=scene.material + 3)
    expect_error(
        "material",
        render,
        bad_material,
        o,
        d,
        trace_brute_force,
        **extra,
        case="material indices beyond the material table",
    )


# ---------------------------------------------------------------------------------------
# Given building blocks: stand-ins for the lab's own task-1 functions. The renderers of
# tasks 1, 2 and 4 are graded with these in place of the lab's offset_origins, reflect,
# surface_at and shade_direct (``with_blocks``), so a mistake in a building block costs
# that block's points only; the end-to-end task runs the lab's own blocks.


def given_offset_origins(points, normals):
    """``p + n * offset * max(1, |p|_inf)``."""
    scale = points.abs().amax(dim=1, keepdim=True).clamp(min=1)
    return points + normals * (offset_scale(points.dtype) * scale)


def given_reflect(directions, normals):
    """``d - 2 (d . n) n``, renormalised."""
    r = directions - 2 * (directions * normals).sum(1, keepdim=True) * normals
    return r / r.norm(dim=1, keepdim=True)


def given_surface_at(scene, origins, directions, hits):
    """Hit points, face normals turned towards the ray, materials; 0 / -1 on a miss."""
    hit = hits.triangle >= 0
    tri = hits.triangle.clamp(min=0)
    t = torch.where(hit, hits.t, 0.0)
    points = torch.where(hit[:, None], origins + t[:, None] * directions, 0.0)
    n = face_normals(scene)[tri]
    n = torch.where(((n * directions).sum(1) > 0)[:, None], -n, n)
    return (points, torch.where(hit[:, None], n, 0.0), torch.where(hit, scene.material[tri], -1))


def given_shade_direct(scene, points, normals, directions, material, trace):
    """The shading contract one light at a time (as ``render_reference`` has it), in the
    scene's dtype: ambient, then each light above the surface with its shadow ray."""
    kd, ks, s = scene.kd[material], scene.ks[material], scene.shininess[material]
    radiance = scene.ambient * kd
    p_off = given_offset_origins(points, normals)
    eps = offset_scale(scene.dtype)
    lights = [
        (pos - p_off, power, eps * max(1.0, pos.abs().max().item()))
        for pos, power in zip(scene.point_positions, scene.point_intensities)
    ]
    lights += [
        (direction.expand_as(p_off), power, None)
        for direction, power in zip(scene.dir_directions, scene.dir_irradiance)
    ]
    traced = 0
    for to, power, light_offset in lights:
        if light_offset is None:
            l, irradiance = to, power.expand_as(p_off)
            t_max = torch.full_like(p_off[:, 0], INF)
        else:
            dist = to.norm(dim=1)
            l, irradiance, t_max = (
                to / dist[:, None],
                power / (dist**2)[:, None],
                dist - light_offset,
            )
        cos = (normals * l).sum(1)
        up = cos > 0
        blocked = torch.zeros_like(up)
        if bool(up.any()):
            blocked[up] = trace(
                scene, p_off[up], l[up], torch.zeros_like(t_max[up]), t_max[up], True
            ).hit
        traced += int(up.sum())
        half = l - directions
        half = half / half.norm(dim=1, keepdim=True)
        lobe = (s + 8) / (8 * math.pi) * (normals * half).sum(1).clamp(min=0) ** s
        brdf = kd / math.pi + ks * lobe[:, None]
        radiance = radiance + torch.where(
            (up & ~blocked)[:, None], irradiance * cos[:, None] * brdf, 0.0
        )
    return radiance, traced


BLOCKS = {
    "offset_origins": "given_offset_origins",
    "reflect": "given_reflect",
    "surface_at": "given_surface_at",
    "shade_direct": "given_shade_direct",
}


def render_with_blocks(lab, render: str, blocks, *args, **kwargs):
    """``lab.<render>(*args, **kwargs)`` run next to the lab with the lab's building blocks
    named in ``blocks`` replaced by the given ones above."""
    with replaced(lab, {name: globals()[BLOCKS[name]] for name in blocks}):
        return getattr(lab, render)(*args, **kwargs)


def with_blocks(impl, render: str, *args, **kwargs):
    """The lab's renderer ``render`` with every building block given."""
    return impl.probe(render_with_blocks, render, tuple(BLOCKS), *args, **kwargs)


# =======================================================================================
# Task 1: Whitted building blocks and backward tracing


def random_frames(n: int, seed: int, dtype):
    """Points of every magnitude (1e-3 .. 1e5, some exactly 0 or with -0.0) and unit normals."""
    g = generator(seed)
    scale = 10 ** (torch.rand(n, 1, generator=g, dtype=F64) * 8 - 3)
    points = torch.randn(n, 3, generator=g, dtype=F64) * scale
    points[:4] = torch.tensor(
        [[0.0, 0.0, 0.0], [-0.0, 1.0, -0.0], [1e5, -3.0, 2.0], [0.5, -1e5, 0.25]], dtype=F64
    )
    normals = torch.randn(n, 3, generator=g, dtype=F64)
    normals[:3] = torch.tensor([[0.0, 1.0, 0.0], [-0.0, -0.0, -1.0], [1.0, 0.0, -0.0]])
    normals = normals / normals.norm(dim=1, keepdim=True)
    return points.to(dtype), normals.to(dtype)


@pytest.mark.task(1)
@pytest.mark.points(1)
@pytest.mark.parametrize("dtype", [F32, F64], ids=["f32", "f64"])
def test_offset_origins(impl, device, dtype):
    points, normals = random_frames(200, 1, dtype)
    got = impl.offset_origins(points.to(device), normals.to(device))
    check_tensor(got, "offset_origins", shape=(200, 3), dtype=dtype, device=device)
    p, n = points.double(), normals.double()
    expected = p + n * offset_scale(dtype) * p.abs().amax(1, keepdim=True).clamp(min=1)
    assert_close(
        got.cpu(),
        expected.to(dtype),
        rtol=4 * torch.finfo(dtype).eps,
        atol=torch.finfo(dtype).tiny,
        where="(ray, axis)",
        name=f"offset_origins ({dtype}): p + n * {offset_scale(dtype):.3g} * "
        "max(1, |p|_inf) (an offset that does not grow with |p| is lost in "
        "rounding far from the origin: acne)",
    )
    lifted = ((got.cpu().double() - p) * n).sum(1)
    assert (lifted > 0).all(), (
        f"offset_origins: ray {int((lifted <= 0).nonzero()[0, 0])} is not lifted off the "
        "surface along its normal"
    )
    expect_error(
        "points",
        impl.offset_origins,
        points[:, :2].to(device),
        normals.to(device),
        case="points of shape (200, 2)",
    )
    expect_error(
        ("points", "normals"),
        impl.offset_origins,
        points.half().to(device),
        normals.half().to(device),
        kinds=(TypeError,),
        case="float16 points",
    )


@pytest.mark.task(1)
@pytest.mark.points(1)
@pytest.mark.parametrize("dtype", [F32, F64], ids=["f32", "f64"])
def test_reflect(impl, device, dtype):
    _, normals = random_frames(300, 2, dtype)
    g = generator(3)
    d = torch.randn(300, 3, generator=g, dtype=F64)
    d[:3] = torch.tensor([[1.0, -0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])  # grazing
    d = (d / d.norm(dim=1, keepdim=True)).to(dtype)
    got = impl.reflect(d.to(device), normals.to(device))
    check_tensor(got, "reflect", shape=(300, 3), dtype=dtype, device=device)
    dd, n = d.double(), normals.double()
    expected = dd - 2 * (dd * n).sum(1, keepdim=True) * n
    tol = 8 * torch.finfo(dtype).eps
    assert_close(
        got.cpu(),
        expected,
        rtol=tol,
        atol=tol,
        where="(ray, axis)",
        name="reflect: d - 2 (d . n) n (the mirror image of d in the surface's plane: "
        "the normal component flips, the tangential one stays)",
    )
    assert_close(
        got.cpu().double().norm(dim=1),
        torch.ones(300, dtype=F64),
        atol=tol,
        name="reflect: |r| (reflected directions are unit)",
        where="ray",
    )
    expect_error(
        "normals",
        impl.reflect,
        d.to(device),
        normals[:7].to(device),
        case="7 normals for 300 directions",
    )


@pytest.mark.task(1)
@pytest.mark.points(1)
@pytest.mark.parametrize("dtype", [F32, F64], ids=["f32", "f64"])
def test_surface_at(impl, device, dtype):
    scene = scene_on("courtyard_both", dtype, device)
    o, d = camera_rays("courtyard_both", dtype, device, 16)
    n = len(o)
    zeros = torch.zeros(n, dtype=dtype, device=device)
    hits = trace_brute_force(scene, o, d, zeros, zeros + INF)
    points, normals, material = impl.surface_at(scene, o, d, hits)
    check_tensor(points, "surface_at: points", shape=(n, 3), dtype=dtype, device=device)
    check_tensor(normals, "surface_at: normals", shape=(n, 3), dtype=dtype, device=device)
    check_tensor(material, "surface_at: material", shape=(n,), dtype=torch.int64, device=device)
    hit = hits.hit.cpu()
    assert 0 < int(hit.sum()) < n, "grader bug: the view should mix hits and sky"
    p64 = (o.double() + hits.t.double().nan_to_num(posinf=0)[:, None] * d.double()).cpu()
    tol = 16 * torch.finfo(dtype).eps
    assert_close(
        points.cpu()[hit],
        p64[hit],
        rtol=tol,
        atol=tol,
        where="(hit, axis)",
        name="surface_at: points o + t d of the hits",
    )
    tri = hits.triangle.cpu()[hit]
    face_n = face_normals(scene.to("cpu", F64))[tri]
    facing = -torch.sign((face_n * d.cpu().double()[hit]).sum(1, keepdim=True)) * face_n
    assert_close(
        normals.cpu()[hit].double(),
        facing,
        atol=tol,
        where="(hit, axis)",
        name="surface_at: normals: the unit geometric normal cross(v1 - v0, v2 - v0), "
        "flipped to face the incoming ray (n . d < 0)",
    )
    assert_equal(
        material.cpu()[hit],
        scene.material.cpu()[tri],
        name="surface_at: material (the hit triangle's entry of scene.material)",
        where="hit",
    )
    assert_equal(
        material.cpu()[~hit],
        torch.full((int((~hit).sum()),), -1),
        name="surface_at: material of rays that missed (-1)",
        where="miss",
    )
    assert_equal(
        normals.cpu()[~hit],
        torch.zeros(int((~hit).sum()), 3, dtype=dtype),
        name="surface_at: normals of rays that missed (0)",
        where="(miss, axis)",
    )
    assert_equal(
        points.cpu()[~hit],
        torch.zeros(int((~hit).sum()), 3, dtype=dtype),
        name="surface_at: points of rays that missed (0)",
        where="(miss, axis)",
    )


def _hits_and_frames(name, dtype, device, size=SIZE):
    """Rays of the scene's camera that hit, with float64-exact hit frames (the inputs of
    shade_direct), on ``device``."""
    scene = scene_on(name, dtype, device)
    o, d = camera_rays(name, dtype, device, size)
    zeros = torch.zeros(len(o), dtype=dtype, device=device)
    hits = trace_brute_force(scene, o, d, zeros, zeros + INF)
    h = hits.hit
    o, d, t, tri = o[h], d[h], hits.t[h], hits.triangle[h]
    p = o + t[:, None] * d
    n = face_normals(scene)[tri]
    n = torch.where(((n * d).sum(1) > 0)[:, None], -n, n)
    return scene, o, d, p, n, scene.material[tri]


def expected_shadow_rays(scene: WhittedScene, p, n) -> int:
    """(hit, light) pairs with n . l > 0 (float64): the shadow rays the contract traces."""
    p, n, s = p.cpu().double(), n.cpu().double(), scene.to("cpu", F64)
    p_off = p + n * offset_scale(scene.dtype) * p.abs().amax(1, keepdim=True).clamp(min=1)
    count = int(((n * s.dir_directions[:, None]).sum(-1) > 0).sum())
    return count + int((((s.point_positions[:, None] - p_off) * n).sum(-1) > 0).sum())


def check_shadow_count(got, expected: int, what: str) -> None:
    assert isinstance(got, int) and not isinstance(got, bool), (
        f"{what}: expected the number of shadow rays traced as an int, got {type(got).__name__}"
    )
    if abs(got - expected) > max(2, 0.005 * expected):
        raise AssertionError(
            f"{what}: traced {got} shadow rays, expected {expected}: one per (hit, light) "
            f"pair with the light above the surface (n . l > 0); lights below the horizon "
            f"cannot contribute and get none (model only what the scene requires)"
        )


@pytest.mark.task(1)
@pytest.mark.points(1)
@pytest.mark.parametrize("name", ["cornell_mirror", "courtyard_both", "courtyard_sun"])
def test_shade_direct_matches_reference(impl, device, name):
    for dtype in (F32, F64):
        scene, o, d, p, n, m = _hits_and_frames(name, dtype, device)
        got = impl.shade_direct(scene, p, n, d, m, trace_brute_force)
        if not (isinstance(got, tuple) and len(got) == 2):
            raise AssertionError(
                f"shade_direct: expected a tuple (radiance, shadow rays), got {type(got).__name__}"
            )
        radiance, shadow_rays = got
        # With max_depth=0 the reference is exactly ambient + direct light at the hits.
        expected = render_reference(scene.to("cpu"), o.cpu(), d.cpu(), 0)
        compare_images(radiance, expected, f"shade_direct on {name} ({dtype})", dtype, device)
        check_shadow_count(
            shadow_rays, expected_shadow_rays(scene, p, n), f"shade_direct on {name} ({dtype})"
        )
        # One point (a lit one) shades as in the batch; no point gives no shadow ray.
        ambient = scene.ambient * scene.kd[m]
        i = int(((radiance - ambient).abs().amax(1) > 1e-3).nonzero()[0, 0])
        one, one_count = impl.shade_direct(
            scene, p[i : i + 1], n[i : i + 1], d[i : i + 1], m[i : i + 1], trace_brute_force
        )
        compare_images(
            one,
            expected[i : i + 1],
            f"shade_direct on {name} ({dtype}) with a single point (its lights count too)",
            dtype,
            device,
        )
        want = expected_shadow_rays(scene, p[i : i + 1], n[i : i + 1])
        assert one_count == want, (
            f"shade_direct on {name} ({dtype}) with a single point: {one_count} shadow rays, "
            f"expected {want} (one per light with n . l > 0)"
        )
        none, none_count = impl.shade_direct(scene, p[:0], n[:0], d[:0], m[:0], trace_brute_force)
        check_tensor(none, "shade_direct of no points: radiance", shape=(0, 3), dtype=dtype)
        assert none_count == 0, (
            f"shade_direct of no points traces no shadow ray: expected 0, got {none_count!r}"
        )
    if name == "courtyard_both":  # shadow rays through the given tracer: the cube casts none
        keep = m != 2  # the points not on the cube (their primary hit is the same without it)
        radiance, _ = impl.shade_direct(
            scene, p[keep], n[keep], d[keep], m[keep], trace_without_cube
        )
        unshadowed = render_reference(
            without_cube(scene).to("cpu"), o[keep].cpu(), d[keep].cpu(), 0
        )
        compare_images(
            radiance,
            unshadowed,
            "shade_direct with a tracer that does not see the "
            "cube (shadow rays must go through the trace argument)",
            dtype,
            device,
        )
    expect_error(
        "material",
        impl.shade_direct,
        scene,
        p,
        n,
        d,
        m + 3,
        trace_brute_force,
        case="material indices beyond the material table",
    )
    expect_error(
        "material",
        impl.shade_direct,
        scene,
        p,
        n,
        d,
        m.int(),
        trace_brute_force,
        case="int32 material indices",
    )
    expect_error("trace", impl.shade_direct, scene, p, n, d, m, None, case="trace=None")
    expect_error(
        "points",
        impl.shade_direct,
        scene,
        p.float(),
        n.float(),
        d.float(),
        m,
        trace_brute_force,
        kinds=(TypeError,),
        case="float32 points, float64 scene",
    )


@pytest.mark.task(1)
@pytest.mark.points(1)
@pytest.mark.parametrize("lamp", ["floor", "grazing"])
def test_shade_direct_light_on_and_above_a_surface(impl, device, lamp):
    """A lamp standing on the floor lights the cube and the wall but not the floor it stands
    on (n . l <= 0 there); 1e-3 above the floor it lights the floor at grazing angles, and
    the shadow rays that skim the floor must neither hit it (acne) nor pass through the cube."""
    name = f"courtyard_{lamp}"
    for dtype in (F32, F64):
        scene, o, d, p, n, m = _hits_and_frames(name, dtype, device, 32)
        radiance, shadow_rays = impl.shade_direct(scene, p, n, d, m, trace_brute_force)
        expected = render_reference(scene.to("cpu"), o.cpu(), d.cpu(), 0)
        got = compare_images(
            radiance, expected, f"shade_direct, lamp {lamp} ({dtype})", dtype, device
        )
        check_shadow_count(
            shadow_rays, expected_shadow_rays(scene, p, n), f"shade_direct, lamp {lamp} ({dtype})"
        )
        floor = (n[:, 1] > 0.5).cpu() & (p[:, 1].abs() < 1e-6).cpu()
        ambient = (scene.ambient * scene.kd[m]).cpu().double()
        lit = (got > ambient + 1e-6).any(1)
        if lamp == "floor":
            assert_close(
                got[floor],
                ambient[floor],
                rtol=1e-6,
                where="(floor pixel, channel)",
                name="shade_direct: the floor under a lamp standing on it gets ambient "
                "light only (n . l = 0: the light lies in its plane)",
            )
            # A sun exactly in the floor's plane: n . l = 0 exactly, so no shadow ray.
            sun = dataclasses.replace(
                scene_on("courtyard_sun", dtype, device),
                dir_directions=torch.tensor([[1.0, 0.0, 0.0]], dtype=dtype, device=device),
            )
            up = torch.tensor([0.0, 1.0, 0.0], dtype=dtype, device=device).expand(len(p), 3)
            keep = floor.to(device)
            flat, flat_count = impl.shade_direct(
                sun, p[keep], up[keep], d[keep], m[keep], trace_brute_force
            )
            assert flat_count == 0, (
                f"shade_direct ({dtype}): {int(keep.sum())} floor points with n = (0, 1, 0) "
                f"under a directional light l = (1, 0, 0) have n . l = 0 exactly: that light "
                f"cannot contribute and gets no shadow ray (only n . l > 0 does); got "
                f"{flat_count!r} shadow rays"
            )
            assert_close(
                flat.cpu().double(),
                (sun.ambient * sun.kd[m[keep]]).cpu().double(),
                rtol=1e-6,
                where="(floor point, channel)",
                name="shade_direct: floor points under a sun in their plane get ambient light only",
            )
            assert lit[~floor].double().mean() > 0.2, (
                "shade_direct: a lamp standing on the floor must light the cube and the wall: "
                "its shadow ray ends just short of the light, so the floor it stands on does "
                "not block it"
            )
        else:
            assert lit[floor].double().mean() > 0.3, (
                f"shade_direct: a lamp 1e-3 above the floor lights only "
                f"{lit[floor].double().mean():.0%} of the floor: grazing shadow rays must "
                f"leave the surface (offset the origin along the normal)"
            )


@pytest.mark.task(1)
@pytest.mark.points(1)
@pytest.mark.parametrize("name", ["cornell_mirror", "courtyard_both"])
def test_render_whitted_matches_reference(impl, device, name):
    for dtype in (F32, F64):
        scene = scene_on(name, dtype, device)
        o, d = camera_rays(name, dtype, device)
        for max_depth in (0, 2):
            image = with_blocks(impl, "render_whitted", scene, o, d, trace_brute_force, max_depth)
            compare_images(
                image,
                _reference(name, dtype, max_depth, "camera"),
                f"render_whitted on {name}, max_depth={max_depth} ({dtype})",
                dtype,
                device,
            )
    check_uses_trace(
        lambda s, o, d, t: with_blocks(impl, "render_whitted", s, o, d, t), device, "render_whitted"
    )


@pytest.mark.task(1)
@pytest.mark.points(1)
def test_render_whitted_mirror_corridor(impl, device):
    for dtype in (F32, F64):
        check_corridor(
            lambda s, o, d, k: with_blocks(impl, "render_whitted", s, o, d, trace_brute_force, k),
            dtype,
            device,
            f"render_whitted ({dtype})",
        )


@pytest.mark.task(1)
@pytest.mark.points(1)
def test_render_whitted_extremes(impl, device):
    for dtype in (F32, F64):
        scene = scene_on("cornell_mirror", dtype, device)
        o, d = axis_rays(8, 5, dtype, device)
        image = with_blocks(impl, "render_whitted", scene, o, d, trace_brute_force)
        compare_images(
            image,
            _reference("cornell_mirror", dtype, 2, "axis"),
            f"render_whitted: axis-parallel rays with +0.0/-0.0 components ({dtype})",
            dtype,
            device,
        )
        o, d = bad_rays(dtype, device)
        check_background(
            with_blocks(impl, "render_whitted", scene, o, d, trace_brute_force),
            scene,
            f"render_whitted ({dtype})",
        )
        # Rays that escape the courtyard into the sky return the background, exactly: also
        # when material 0 is the mirror (a miss has no material; it never reflects).
        sky = reordered_materials(scene_on("courtyard_both", dtype, device), [1, 0, 2])
        o, d = camera_rays("courtyard_both", dtype, device, 16)
        zeros = torch.zeros(len(o), dtype=dtype, device=device)
        escaped = ~trace_brute_force(sky, o, d, zeros, zeros + INF).hit
        image = with_blocks(impl, "render_whitted", sky, o, d, trace_brute_force)
        check_tensor(
            image, "render_whitted: the image", shape=(len(o), 3), dtype=dtype, device=device
        )
        assert_close(
            image.cpu()[escaped.cpu()],
            sky.background.cpu().expand(int(escaped.sum()), 3),
            name=f"render_whitted ({dtype}): primary rays that escape into the sky "
            f"(the background, exactly; the mirror is material 0 here, and a "
            f"ray that missed spawns no reflection)",
            where="(escaped ray, channel)",
        )
    expect_render_errors(impl.render_whitted, device)


@pytest.mark.task(1)
@pytest.mark.points(1)
def test_render_whitted_far_from_origin(impl, device):
    """The Cornell box moved by 1e5 (float64): the same image, no acne, no leaks."""
    for offset in (1e5, (-3e4, 1e5, 7e4)):
        scene = translated(scene_on("cornell_mirror", F64, device), offset)
        o, d = camera_rays("cornell_mirror", F64, device)
        o = o + torch.as_tensor(offset, dtype=F64, device=device)
        image = with_blocks(impl, "render_whitted", scene, o, d, trace_brute_force)
        got = compare_images(
            image,
            _reference("cornell_mirror", F64, 2, "camera"),
            f"render_whitted, the Cornell box moved by {offset}",
            F64,
            device,
            tol=FAR_TOL,
        )
        magenta = (got[:, 0] > 0.9) & (got[:, 1] < 0.1) & (got[:, 2] > 0.9)
        assert not magenta.any(), (
            f"render_whitted: pixel {int(magenta.nonzero()[0, 0])} shows the background "
            "through the closed box moved by 1e5: a leak"
        )


# =======================================================================================
# Task 2: separate kernels (wavefront)


STAT_LISTS = ("closest_rays", "hits", "shadow_rays", "reflected_rays", "material_runs")


def wavefront_stats(stats, max_depth: int, what: str) -> dict:
    """The stats dict, lists padded with zeros to max_depth + 1 entries."""
    out = {}
    for key in STAT_LISTS:
        value = stats.get(key)
        if not isinstance(value, list) or not all(isinstance(x, int) and x >= 0 for x in value):
            raise AssertionError(
                f"{what}: stats[{key!r}] must be a list of non-negative ints "
                f"(one per bounce), got {value!r}"
            )
        if len(value) > max_depth + 1:
            raise AssertionError(
                f"{what}: stats[{key!r}] has {len(value)} entries: more "
                f"bounces than max_depth={max_depth} allows"
            )
        out[key] = value + [0] * (max_depth + 1 - len(value))
    seconds = stats.get("seconds")
    stages = ("generate", "trace", "shade", "spawn")
    if not isinstance(seconds, dict) or not all(
        isinstance(seconds.get(s), float) and seconds[s] >= 0 for s in stages
    ):
        raise AssertionError(
            f"{what}: stats['seconds'] must map each stage {stages} to the "
            f"seconds spent in it, got {seconds!r}"
        )
    return out


@pytest.mark.task(2)
@pytest.mark.points(1)
@pytest.mark.parametrize("sort", [False, True], ids=["unsorted", "sorted"])
def test_render_wavefront_matches_reference(impl, device, sort):
    for name in ("cornell_mirror", "courtyard_both"):
        for dtype in (F32, F64):
            scene = scene_on(name, dtype, device)
            o, d = camera_rays(name, dtype, device)
            image, _ = image_of(
                with_blocks(impl, "render_wavefront", scene, o, d, trace_brute_force, 2, sort),
                "render_wavefront",
                True,
            )
            compare_images(
                image,
                _reference(name, dtype, 2, "camera"),
                f"render_wavefront on {name}, sort_by_material={sort} ({dtype})",
                dtype,
                device,
            )
    check_corridor(
        lambda s, o, d, k: with_blocks(
            impl, "render_wavefront", s, o, d, trace_brute_force, k, sort
        )[0],
        F32,
        device,
        f"render_wavefront (sort_by_material={sort})",
    )
    check_uses_trace(
        lambda s, o, d, t: with_blocks(impl, "render_wavefront", s, o, d, t, 2, sort)[0],
        device,
        "render_wavefront",
    )


@pytest.mark.task(2)
@pytest.mark.points(1)
def test_render_wavefront_stats(impl, device):
    """Rays per stage and bounce, checked where they are known exactly: every corridor ray
    bounces to the limit and needs no shadow ray; in the Cornell box only mirror hits spawn."""
    scene = scene_on("mirror_corridor", F64, device)
    o, d = corridor_rays(40, 2, F64, device)
    n = len(o)
    for max_depth in (0, 3):
        _, stats = image_of(
            with_blocks(impl, "render_wavefront", scene, o, d, trace_brute_force, max_depth),
            "render_wavefront",
            True,
        )
        s = wavefront_stats(stats, max_depth, f"render_wavefront (corridor, max_depth={max_depth})")
        expected = {
            "closest_rays": [n] * (max_depth + 1),
            "hits": [n] * (max_depth + 1),
            "shadow_rays": [0] * (max_depth + 1),
            "reflected_rays": [n] * max_depth + [0],
        }
        for key, value in expected.items():
            assert s[key] == value, (
                f"render_wavefront between two facing mirrors, max_depth={max_depth}: "
                f"stats[{key!r}] = {s[key]}, expected {value} (every ray hits a mirror at "
                f"every bounce; the only light lies in the mirrors' plane, so no shadow ray)"
            )
    for sort in (False, True):
        scene = scene_on("cornell_mirror", F64, device)
        o, d = camera_rays("cornell_mirror", F64, device)
        _, stats = with_blocks(impl, "render_wavefront", scene, o, d, trace_brute_force, 2, sort)
        s = wavefront_stats(stats, 2, "render_wavefront (Cornell box)")
        zeros = torch.zeros(len(o), dtype=F64, device=device)
        hits = trace_brute_force(scene, o, d, zeros, zeros + INF)
        material = scene.material[hits.triangle]
        mirror_hits = int(scene.mirror_faces()[hits.triangle].sum())
        assert s["closest_rays"][0] == len(o) and s["hits"][0] == len(o), (
            f"render_wavefront: depth 0 should trace {len(o)} primary rays and hit with all "
            f"(a closed box), got closest_rays {s['closest_rays']}, hits {s['hits']}"
        )
        assert s["reflected_rays"][0] == mirror_hits == s["closest_rays"][1], (
            f"render_wavefront: {mirror_hits} primary rays hit the mirror, so as many "
            f"reflected rays must be spawned and traced at depth 1 (and no others: diffuse "
            f"hits spawn nothing); got reflected_rays {s['reflected_rays']}, closest_rays "
            f"{s['closest_rays']}"
        )
        for depth in range(3):
            assert s["closest_rays"][depth] >= s["hits"][depth] >= s["reflected_rays"][depth]
        _, _, _, p, nrm, _ = _hits_and_frames("cornell_mirror", F64, device)
        check_shadow_count(
            s["shadow_rays"][0], expected_shadow_rays(scene, p, nrm), "render_wavefront, depth 0"
        )
        runs = s["material_runs"][0]
        distinct = len(material.unique())
        if sort:
            assert runs == distinct, (
                f"render_wavefront(sort_by_material=True): the shading queue at depth 0 holds "
                f"{distinct} materials, so sorted it has {distinct} runs of equal material; "
                f"stats['material_runs'][0] = {runs}"
            )
        else:
            assert runs >= distinct, f"material_runs {runs} < {distinct} distinct materials"
    expect_error(
        "sort_by_material",
        impl.render_wavefront,
        scene,
        o,
        d,
        trace_brute_force,
        2,
        "yes",
        kinds=(TypeError,),
        case="sort_by_material='yes'",
    )


@pytest.mark.task(2)
@pytest.mark.points(1)
def test_render_wavefront_extremes(impl, device):
    for dtype in (F32, F64):
        scene = scene_on("cornell_mirror", dtype, device)
        o, d = axis_rays(8, 5, dtype, device)
        image, _ = with_blocks(impl, "render_wavefront", scene, o, d, trace_brute_force)
        compare_images(
            image,
            _reference("cornell_mirror", dtype, 2, "axis"),
            f"render_wavefront: axis-parallel rays ({dtype})",
            dtype,
            device,
        )
        o, d = bad_rays(dtype, device)
        image, stats = with_blocks(impl, "render_wavefront", scene, o, d, trace_brute_force)
        check_background(image, scene, f"render_wavefront ({dtype})")
        s = wavefront_stats(stats, 2, f"render_wavefront, rays that all miss ({dtype})")
        want = {"closest_rays": [len(o), 0, 0], "hits": [0, 0, 0], "material_runs": [0, 0, 0]}
        got = {key: s[key] for key in want}
        assert got == want, (
            f"render_wavefront ({dtype}): {len(o)} NaN/inf/zero rays all miss: one bounce "
            f"traces them, none hits, so the shading queue is empty (0 runs of equal material)"
            f"; expected {want} (padded to max_depth + 1), got {got}"
        )
    scene = translated(scene_on("cornell_mirror", F64, device), 1e5)
    o, d = camera_rays("cornell_mirror", F64, device)
    image, _ = with_blocks(impl, "render_wavefront", scene, o + 1e5, d, trace_brute_force)
    compare_images(
        image,
        _reference("cornell_mirror", F64, 2, "camera"),
        "render_wavefront, the Cornell box moved by 1e5",
        F64,
        device,
        tol=FAR_TOL,
    )
    expect_render_errors(impl.render_wavefront, device)


# =======================================================================================
# Task 3: the uber kernel


@pytest.mark.task(3)
@pytest.mark.points(1)
def test_render_uber_matches_reference(impl, device):
    for name in ("cornell_mirror", "courtyard_both"):
        for dtype in (F32, F64):
            scene = scene_on(name, dtype, device)
            o, d = camera_rays(name, dtype, device)
            image = impl.render_uber(scene, o, d, trace_brute_force, 2)
            compare_images(
                image,
                _reference(name, dtype, 2, "camera"),
                f"render_uber on {name} ({dtype})",
                dtype,
                device,
            )
    check_corridor(
        lambda s, o, d, k: impl.render_uber(s, o, d, trace_brute_force, k),
        F32,
        device,
        "render_uber",
    )
    check_uses_trace(lambda s, o, d, t: impl.render_uber(s, o, d, t), device, "render_uber")
    scene = scene_on("cornell_mirror", F32, device)
    o, d = bad_rays(F32, device)
    check_background(impl.render_uber(scene, o, d, trace_brute_force), scene, "render_uber")
    o, d = axis_rays(8, 5, F32, device)
    compare_images(
        impl.render_uber(scene, o, d, trace_brute_force),
        _reference("cornell_mirror", F32, 2, "axis"),
        "render_uber: axis-parallel rays",
        F32,
        device,
    )
    expect_render_errors(impl.render_uber, device)


def probe_uber_compiled(lab, scene, origins, directions):
    """Run render_uber with a recording torch.compile backend (it captures graphs, then runs
    them eagerly): ``(image, graph breaks, graphs captured, data-dependent ops)``, the last
    a list of the graph nodes whose sizes depend on tensor values."""
    import torch._dynamo
    from torch._dynamo.utils import counters
    from torch.fx.experimental.symbolic_shapes import free_unbacked_symbols

    torch._dynamo.reset()
    counters.clear()
    graphs, dynamic = [], []

    def recording_backend(gm, example_inputs):
        graphs.append(len(gm.graph.nodes))
        for node in gm.graph.nodes:
            value = node.meta.get("example_value")
            if value is not None and free_unbacked_symbols(value):
                dynamic.append(str(node.target))
        return gm.forward

    image = lab.render_uber(
        scene, origins, directions, trace_brute_force, 2, compile=recording_backend
    )
    return image, sum(counters["graph_break"].values()), len(graphs), dynamic


@pytest.mark.task(3)
@pytest.mark.points(1)
def test_render_uber_compiles(impl, device):
    """Under torch.compile every step of the uber loop is one graph of fixed-size tensors:
    no data-dependent shapes (boolean indexing, nonzero), no .item(), no Python branches on
    tensor values."""
    scene = scene_on("courtyard_both", F32, device)
    o, d = camera_rays("courtyard_both", F32, device, 12)
    image, breaks, graphs, dynamic = impl.probe(probe_uber_compiled, scene, o, d)
    compare_images(
        image,
        _reference("courtyard_both", F32, 2, "camera", 12),
        "render_uber(compile=backend)",
        F32,
        device,
    )
    assert graphs >= 1, (
        "render_uber(compile=backend): torch.compile captured no graph: compile "
        "the shading/spawning steps with torch.compile(step, backend=compile)"
    )
    assert breaks == 0, (
        f"render_uber(compile=backend): {breaks} graph breaks: an uber step "
        "must not call .item() or branch on tensor values"
    )
    assert not dynamic, (
        f"render_uber(compile=backend): the captured steps contain operations whose output "
        f"size depends on the data ({', '.join(sorted(set(dynamic))[:4])}): an uber kernel "
        f"works on fixed-size buffers (torch.where instead of x[mask] or nonzero)"
    )
    expect_error(
        "compile",
        impl.render_uber,
        scene,
        o,
        d,
        trace_brute_force,
        2,
        3.5,
        kinds=(TypeError,),
        case="compile=3.5",
    )


# =======================================================================================
# Task 4: persistent workers


def persistent_stats(stats, pool_size: int, what: str) -> dict:
    for key in ("steps", "work_generated", "work_processed", "shadow_rays"):
        assert isinstance(stats.get(key), int), (
            f"{what}: stats[{key!r}] must be an int, got {stats.get(key)!r}"
        )
    assert stats.get("pool_size") == pool_size, (
        f"{what}: stats['pool_size'] = {stats.get('pool_size')!r}, expected the pool's "
        f"{pool_size} slots"
    )
    active = stats.get("active_lanes")
    if not isinstance(active, list) or len(active) != stats["steps"]:
        raise AssertionError(
            f"{what}: stats['active_lanes'] must list the busy slots of each "
            f"of the {stats['steps']} steps, got {active!r}"
        )
    if any(not 1 <= a <= pool_size for a in active):
        raise AssertionError(
            f"{what}: a step had {min(active)}..{max(active)} active lanes: "
            f"expected 1..pool_size={pool_size} (a step with no work ends "
            f"the loop)"
        )
    idle = 1 - sum(active) / (pool_size * len(active)) if active else 0.0
    fraction = stats.get("idle_fraction")
    if not isinstance(fraction, float) or abs(fraction - idle) > 1e-9:
        raise AssertionError(
            f"{what}: stats['idle_fraction'] = {stats.get('idle_fraction')!r}, "
            f"expected 1 - sum(active_lanes) / (pool_size * steps) = {idle}"
        )
    return stats


@pytest.mark.task(4)
@pytest.mark.points(1)
@pytest.mark.parametrize("pool_size", [1, 100, 4096])
def test_render_persistent_matches_reference(impl, device, pool_size):
    names = ("cornell_mirror",) if pool_size == 1 else ("cornell_mirror", "courtyard_both")
    for name in names:
        for dtype in (F32, F64):
            size = 8 if pool_size == 1 else SIZE
            scene = scene_on(name, dtype, device)
            o, d = camera_rays(name, dtype, device, size)
            image, _ = image_of(
                with_blocks(
                    impl, "render_persistent", scene, o, d, trace_brute_force, 2, pool_size
                ),
                "render_persistent",
                True,
            )
            compare_images(
                image,
                _reference(name, dtype, 2, "camera", size),
                f"render_persistent on {name}, pool_size={pool_size} ({dtype})",
                dtype,
                device,
            )
    check_corridor(
        lambda s, o, d, k: with_blocks(
            impl, "render_persistent", s, o, d, trace_brute_force, k, pool_size
        )[0],
        F32,
        device,
        f"render_persistent (pool_size={pool_size})",
    )
    if pool_size > 1:
        check_uses_trace(
            lambda s, o, d, t: with_blocks(impl, "render_persistent", s, o, d, t, 2, pool_size)[0],
            device,
            "render_persistent",
        )


@pytest.mark.task(4)
@pytest.mark.points(1)
def test_render_persistent_stats(impl, device):
    """Every work item generated is processed exactly once; lanes idle only for lack of work."""
    scene = scene_on("mirror_corridor", F64, device)
    o, d = corridor_rays(40, 2, F64, device)
    n, max_depth = len(o), 3
    for pool_size in (16, 40, 1000):
        what = f"render_persistent (two mirrors, {n} rays, pool_size={pool_size})"
        _, stats = with_blocks(
            impl, "render_persistent", scene, o, d, trace_brute_force, max_depth, pool_size
        )
        s = persistent_stats(stats, pool_size, what)
        work = n * (max_depth + 1)
        assert s["work_generated"] == work and s["work_processed"] == work, (
            f"{what}: {n} primary rays each reflected {max_depth} times are {work} work items; "
            f"got work_generated={s['work_generated']}, work_processed={s['work_processed']} "
            f"(lost or duplicated work)"
        )
        assert sum(s["active_lanes"]) == work, (
            f"{what}: the active lanes of all steps add up to {sum(s['active_lanes'])}, but "
            f"{work} items were processed"
        )
        assert s["steps"] >= math.ceil(work / pool_size) and s["shadow_rays"] == 0
        if pool_size >= n:
            assert s["steps"] == max_depth + 1, (
                f"{what}: with a slot for every ray the pool needs one step per bounce "
                f"({max_depth + 1}), took {s['steps']}"
            )
    # The default pool: pool_size=4096 slots (the signature's default).
    _, stats = with_blocks(impl, "render_persistent", scene, o, d, trace_brute_force, max_depth)
    s = persistent_stats(
        stats, 4096, f"render_persistent (two mirrors, {n} rays, the default pool_size=4096)"
    )
    assert s["steps"] == max_depth + 1 and s["active_lanes"] == [n] * (max_depth + 1), (
        f"render_persistent with the default pool of 4096 slots: {n} rays need one step per "
        f"bounce with {n} busy slots each; got active_lanes {s['active_lanes']}"
    )
    # No rays: an empty image and a pool that never steps (idle_fraction 0.0, no 0 / 0).
    image, stats = with_blocks(
        impl, "render_persistent", scene, o[:0], d[:0], trace_brute_force, max_depth, 16
    )
    s = persistent_stats(stats, 16, "render_persistent (no rays, pool_size=16)")
    assert tuple(image.shape) == (0, 3) and s["steps"] == 0 and s["work_generated"] == 0, (
        f"render_persistent of no rays: expected an image of shape (0, 3), 0 steps and no "
        f"work; got shape {tuple(image.shape)}, steps {s['steps']}, work_generated "
        f"{s['work_generated']}"
    )
    scene = scene_on("cornell_mirror", F64, device)
    o, d = camera_rays("cornell_mirror", F64, device)
    _, stats = with_blocks(impl, "render_persistent", scene, o, d, trace_brute_force, 2, 64)
    s = persistent_stats(stats, 64, "render_persistent (Cornell box, pool_size=64)")
    # The mirror box is convex: its reflections never meet it again, one bounce at most.
    zeros = torch.zeros(len(o), dtype=F64, device=device)
    hits = trace_brute_force(scene, o, d, zeros, zeros + INF)
    mirror_hits = int(scene.mirror_faces()[hits.triangle].sum())
    work = len(o) + mirror_hits
    assert s["work_generated"] == s["work_processed"] == work, (
        f"render_persistent (Cornell box): {len(o)} primary rays, {mirror_hits} of them hit "
        f"the mirror and spawn a reflection: {work} work items; got work_generated="
        f"{s['work_generated']}, work_processed={s['work_processed']}"
    )
    expect_error(
        "pool_size",
        impl.render_persistent,
        scene,
        o,
        d,
        trace_brute_force,
        2,
        0,
        case="pool_size=0",
    )
    expect_error(
        "pool_size",
        impl.render_persistent,
        scene,
        o,
        d,
        trace_brute_force,
        2,
        2.5,
        case="pool_size=2.5",
    )
    o, d = bad_rays(F64, device)
    check_background(
        with_blocks(impl, "render_persistent", scene, o, d, trace_brute_force, 2, 4)[0],
        scene,
        "render_persistent",
    )
    expect_render_errors(impl.render_persistent, device)


# =======================================================================================
# Task 5: geometry layouts


@functools.cache
def _soup(dtype) -> Mesh:
    """120 random triangles in the unit cube, a degenerate one, and two sharing an edge."""
    from course.core.scenes import load_scene

    soup = load_scene("random_soup", device="cpu", dtype=F64, n=120, seed=9).mesh
    corners = soup.vertices[soup.faces]
    extra = torch.tensor(
        [
            [[0.2, 0.2, 0.5], [0.2, 0.2, 0.5], [0.6, 0.3, 0.5]],  # a line
            [[0.1, 0.1, 0.95], [0.9, 0.1, 0.95], [0.1, 0.9, 0.95]],
            [[0.9, 0.1, 0.95], [0.9, 0.9, 0.95], [0.1, 0.9, 0.95]],
        ],
        dtype=F64,
    )
    corners = torch.cat((corners, extra))
    return Mesh(corners.reshape(-1, 3).to(dtype), torch.arange(3 * len(corners)).reshape(-1, 3))


def soup_rays(dtype, device, n: int = 300, seed: int = 4):
    g = generator(seed)
    out = torch.randn(n, 3, generator=g, dtype=F64)
    o = 0.5 + 1.5 * out / out.norm(dim=1, keepdim=True)
    d = torch.rand(n, 3, generator=g, dtype=F64) - o
    o[:6] = torch.tensor(
        [
            [0.3, 0.3, 2.0],
            [0.3, 0.3, -1.0],
            [2.0, 0.5, 0.5],
            [0.5, -1.0, 0.5],
            [math.nan, 0.5, 0.5],
            [0.5, 0.5, 2.0],
        ],
        dtype=F64,
    )
    d[:6] = torch.tensor(
        [
            [0.0, -0.0, -1.0],
            [-0.0, 0.0, 1.0],
            [-1.0, 0.0, -0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, -1.0],
            [0.0, 0.0, 0.0],
        ],
        dtype=F64,
    )
    t_max = torch.where(torch.arange(n) % 7 == 3, 1.0, INF).to(F64)
    return tuple(x.to(device, dtype) for x in (o, d, torch.zeros(n, dtype=F64), t_max))


def check_layout_hits(hits, expected: Hits, what: str, dtype) -> None:
    n = len(expected)
    assert isinstance(hits, Hits), (
        f"{what}: expected course.core.types.Hits, got {type(hits).__name__}"
    )
    check_tensor(hits.t, f"{what}: t", shape=(n,), dtype=dtype)
    tri, ref = hits.triangle.cpu(), expected.triangle.cpu()
    # Another algorithm may decide a ray through an edge or a tie differently: a few rays.
    differ = tri != ref
    if differ.double().mean() > 0.02:
        i = int(differ.nonzero()[0, 0])
        raise AssertionError(
            f"{what}: {int(differ.sum())} of {n} rays report another triangle "
            f"than brute force; first: ray {i}, expected {int(ref[i])} at "
            f"t={expected.t[i].item():.7g}, got {int(tri[i])} at "
            f"t={hits.t[i].item():.7g}"
        )
    # A tie or a shared edge: the other triangle is hit at the same distance, never farther.
    both = differ & (ref >= 0) & (tri >= 0)
    far = (hits.t.cpu() - expected.t.cpu()).abs() > 1e-4 * expected.t.cpu().abs()
    if (both & far).any():
        i = int((both & far).nonzero()[0, 0])
        raise AssertionError(
            f"{what}: ray {i} reports triangle {int(tri[i])} at t={hits.t[i].item():.7g}, but "
            f"triangle {int(ref[i])} is hit nearer, at t={expected.t[i].item():.7g}: keep the "
            f"nearest hit over all tiles (a farther hit never replaces a nearer one, whatever "
            f"its index)"
        )
    same = (~differ) & (ref >= 0)
    assert_close(
        hits.t.cpu()[same],
        expected.t.cpu()[same],
        rtol=1e-4,
        where="hit",
        name=f"{what}: t of the hits",
    )
    atol = 1e-4 if dtype == F32 else 1e-9
    for name in ("u", "v"):
        assert_close(
            getattr(hits, name).cpu()[same],
            getattr(expected, name).cpu()[same],
            atol=atol,
            where="hit",
            name=f"{what}: {name} of the hits (the barycentrics of the kept hit)",
        )
    missed = (tri < 0) & ~differ
    assert_equal(
        hits.t.cpu()[missed],
        torch.full((int(missed.sum()),), INF, dtype=dtype),
        name=f"{what}: t of misses (inf)",
        where="miss",
    )
    for name in ("u", "v"):
        assert_equal(
            getattr(hits, name).cpu()[tri < 0],
            torch.zeros(int((tri < 0).sum()), dtype=dtype),
            name=f"{what}: {name} of misses (0)",
            where="miss",
        )


@pytest.mark.task(5)
@pytest.mark.points(1)
@pytest.mark.parametrize("dtype", [F32, F64], ids=["f32", "f64"])
def test_layout_memory(impl, device, dtype):
    mesh = _soup(dtype)
    mesh = Mesh(mesh.vertices.to(device), mesh.faces.to(device))
    f, size = mesh.num_faces, torch.finfo(dtype).bits // 8
    corners = mesh.triangles().cpu()

    indexed = impl.layout_indexed(mesh)
    check_tensor(
        indexed.get("vertices"),
        "layout_indexed: vertices",
        shape=(mesh.num_vertices, 3),
        dtype=dtype,
        device=device,
    )
    check_tensor(
        indexed.get("faces"),
        "layout_indexed: faces",
        shape=(f, 3),
        dtype=torch.int32,
        device=device,
    )
    assert_equal(
        indexed["vertices"][indexed["faces"].long()].cpu(),
        corners,
        name="layout_indexed: vertices[faces] (the triangles' corners)",
        where="corner",
    )
    want = (mesh.num_vertices * 3 * size + f * 3 * 4) / f
    assert indexed.get("bytes_per_triangle") == pytest.approx(want), (
        f"layout_indexed: bytes_per_triangle = {indexed.get('bytes_per_triangle')!r}, expected "
        f"{want:g} (V * 3 coordinates of {size} bytes + F * 3 int32 indices, per triangle)"
    )

    order = torch.randperm(f, generator=generator(5)).to(device)
    for perm in (None, order):
        float4 = impl.layout_float4(mesh) if perm is None else impl.layout_float4(mesh, perm)
        tri = check_tensor(
            float4.get("triangles"),
            "layout_float4: triangles",
            shape=(f, 3, 4),
            dtype=dtype,
            device=device,
        ).cpu()
        index = torch.arange(f) if perm is None else order.cpu()
        assert_equal(
            tri[..., :3],
            corners[index],
            where="(slot, corner, axis)",
            name="layout_float4: xyz of the three float4 (the corners, in order)",
        )
        assert_equal(
            float_as_index(tri[:, 0, 3]),
            index,
            where="slot",
            name="layout_float4: w of the first float4 (the triangle's index, bit for "
            "bit: index_as_float)",
        )
        assert float4.get("bytes_per_triangle") == pytest.approx(12 * size), (
            f"layout_float4: bytes_per_triangle should be 3 float4 = {12 * size}"
        )

    woop = impl.layout_woop(mesh)
    m = (
        check_tensor(
            woop.get("transforms"),
            "layout_woop: transforms",
            shape=(f, 3, 4),
            dtype=dtype,
            device=device,
        )
        .cpu()
        .double()
    )
    unit = torch.tensor([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], dtype=F64)
    ok = torch.isfinite(m).all(2).all(1)
    assert not ok[120], "layout_woop: the degenerate triangle 120 (a line) has no unit-triangle map"
    mapped = corners.double() @ m[:, :, :3].transpose(1, 2) + m[:, None, :, 3]
    # Rounding the map to the dtype moves M v + t by a few ulps of its terms' magnitudes.
    scale = corners.double().abs() @ m[:, :, :3].abs().transpose(1, 2) + m[:, None, :, 3].abs()
    off = (mapped - unit).abs() > 8 * torch.finfo(dtype).eps * scale + 1e-12
    assert_close(
        torch.where(off, mapped, unit)[ok],
        unit.expand(int(ok.sum()), 3, 3),
        where="(triangle, corner, axis)",
        name="layout_woop: M [v, 1] for the corners v0, v1, v2 (Woop's unit triangle: "
        "(0,0,0), (1,0,0), (0,1,0))",
    )
    # The third column of the frame is the unit normal normalize(e1 x e2) (right-handed):
    # M [n, 0] = (0, 0, 1), so z' is the signed distance from the plane along n.
    c64 = corners.double()
    normal = torch.linalg.cross(c64[:, 1] - c64[:, 0], c64[:, 2] - c64[:, 0], dim=-1)
    normal = normal / normal.norm(dim=1, keepdim=True)
    lifted = (m[:, :, :3] @ normal[:, :, None])[..., 0]
    e_z = torch.tensor([0.0, 0.0, 1.0], dtype=F64)
    scale = (m[:, :, :3].abs() @ normal.abs()[:, :, None])[..., 0]
    off = (lifted - e_z).abs() > 8 * torch.finfo(dtype).eps * scale + 1e-12
    assert_close(
        torch.where(off, lifted, e_z)[ok],
        e_z.expand(int(ok.sum()), 3),
        where="(triangle, axis)",
        name="layout_woop: M [n, 0] for the unit normal n = normalize(e1 x e2) (the "
        "frame's third column, in that order: (0, 0, 1); e2 x e1 gives -1)",
    )
    assert woop.get("bytes_per_triangle") == pytest.approx(12 * size)
    expect_error("mesh", impl.layout_woop, mesh.vertices, case="a tensor instead of a Mesh")
    expect_error("order", impl.layout_float4, mesh, order[:-1], case="order of F - 1 entries")


def intersect_in_small_tiles(lab, pairs: int, *args):
    """``lab.intersect_layout(*args)`` with the memory budget of ``pair_tiles`` cut to
    ``pairs`` (ray, triangle) pairs, so that each ray meets the triangles in several tiles
    (run next to the lab; the budget is restored after)."""
    import sys

    import course.given.lab3 as given
    import course.given.lab3_reference as tiles  # pair_tiles reads the budget here

    module = sys.modules.get(getattr(lab, "__name__", None), lab)
    owners = [m for m in (given, tiles, module) if hasattr(m, "MEMORY_BUDGET_BYTES")]
    saved = [(m, m.MEMORY_BUDGET_BYTES) for m in owners]
    try:
        for m in owners:
            m.MEMORY_BUDGET_BYTES = pairs * given.BYTES_PER_PAIR
        return lab.intersect_layout(*args)
    finally:
        for m, budget in saved:
            m.MEMORY_BUDGET_BYTES = budget


def check_layout_edges_and_ties(impl, device, dtype) -> None:
    """Rays straight down onto the corners, edges and inside of the unit triangle, which the
    mesh holds three times (1, 2, 3) above a farther copy (0). Every corner, ray and
    transform is exact, so u, v and t are exact: u = 0, v = 0 and u + v = 1 on the edges
    are hits, and the exact tie goes to triangle 1, also with one pair per tile in a float4
    layout that stores the triangles in the order 3, 2, 1, 0 (the farther triangle 0, of a
    lower index, comes last and must not replace the nearer hit)."""
    unit = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]
    below = [[0.0, 0.0, -1.0], [1.0, 0.0, -1.0], [0.0, 1.0, -1.0]]
    corners = torch.tensor([below, unit, unit, unit], dtype=dtype)
    mesh = Mesh(corners.reshape(-1, 3).to(device), torch.arange(12, device=device).reshape(4, 3))
    uv = torch.tensor(
        [[0, 0], [1, 0], [0, 1], [0.5, 0], [0, 0.5], [0.5, 0.5], [0.25, 0.25]], dtype=dtype
    )
    n = len(uv)
    o = torch.cat((uv, torch.ones(n, 1, dtype=dtype)), 1).to(device)
    d = torch.tensor([0.0, 0.0, -1.0], dtype=dtype).expand(n, 3).contiguous().to(device)
    t_min = torch.zeros(n, dtype=dtype, device=device)
    t_max = torch.full((n,), INF, dtype=dtype, device=device)
    order = torch.tensor([3, 2, 1, 0], device=device)
    cases = {
        "indexed": (impl.layout_indexed(mesh), None),
        "float4": (impl.layout_float4(mesh), None),
        "woop": (impl.layout_woop(mesh), None),
        "float4 in the order 3, 2, 1, 0, one pair per tile": (impl.layout_float4(mesh, order), 1),
        "woop, one pair per tile": (impl.layout_woop(mesh), 1),
    }
    for what, (layout, pairs) in cases.items():
        if pairs is None:
            hits = impl.intersect_layout(layout, o, d, t_min, t_max)
        else:
            hits = impl.probe(intersect_in_small_tiles, pairs, layout, o, d, t_min, t_max)
        got = {k: getattr(hits, k).cpu() for k in ("triangle", "t", "u", "v")}
        for i in range(n):
            want = (1, 1.0, uv[i, 0].item(), uv[i, 1].item())
            have = tuple(x[i].item() for x in got.values())
            assert have == want, (
                f"intersect_layout ({what}, {dtype}): the ray straight down onto the point "
                f"(u, v) = {tuple(uv[i].tolist())} of the unit triangle (on an edge or corner: "
                f"u, v >= 0 and u + v <= 1 include it) must hit triangle 1 at t = 1 with that "
                f"u, v exactly (every number here is exact; triangles 2 and 3 are copies of 1, "
                f"an exact tie that the lowest index wins, in any tile order; triangle 0 is "
                f"hit farther, at t = 2); got (triangle, "
                f"t, u, v) = {have}"
            )


@pytest.mark.task(5)
@pytest.mark.points(1)
@pytest.mark.parametrize("dtype", [F32, F64], ids=["f32", "f64"])
def test_intersect_layout(impl, device, dtype):
    mesh = _soup(dtype)
    mesh = Mesh(mesh.vertices.to(device), mesh.faces.to(device))
    scene = make_scene(
        mesh,
        torch.zeros(mesh.num_faces, dtype=torch.int64),
        {"kd": [[1, 1, 1]], "ks": [[0, 0, 0]], "shininess": [1], "kr": [[0, 0, 0]]},
        dir_lights=[((0, 1, 0), (1, 1, 1))],
    )
    o, d, t_min, t_max = soup_rays(dtype, device)
    expected = trace_brute_force(scene, o, d, t_min, t_max)
    assert 50 < int(expected.hit.sum()) < 280, "grader bug: mix hits and misses"
    order = torch.randperm(mesh.num_faces, generator=generator(6)).to(device)
    layouts = {
        "indexed": impl.layout_indexed(mesh),
        "float4": impl.layout_float4(mesh),
        "float4 in a shuffled order": impl.layout_float4(mesh, order),
        "woop": impl.layout_woop(mesh),
    }
    for what, layout in layouts.items():
        hits = impl.intersect_layout(layout, o, d, t_min, t_max)
        check_layout_hits(hits, expected, f"intersect_layout ({what}, {dtype})", dtype)
        for k in (4, 5):  # a NaN origin, a zero direction
            assert int(hits.triangle[k]) == -1, (
                f"intersect_layout ({what}): ray {k} (NaN origin or zero direction) must miss"
            )
    # A memory budget of 40 pairs: pair_tiles hands each ray the triangles in 4 tiles; the
    # hit kept over all tiles is the nearest (among equal t the lowest index), whatever
    # order the tiles' indices come in (the shuffled float4 layout).
    rays = tuple(x[:90] for x in (o, d, t_min, t_max))
    expected = trace_brute_force(scene, *rays)
    for what in ("indexed", "float4 in a shuffled order", "woop"):
        hits = impl.probe(intersect_in_small_tiles, 40, layouts[what], *rays)
        check_layout_hits(
            hits,
            expected,
            f"intersect_layout ({what}, {dtype}) with a memory "
            f"budget of 40 (ray, triangle) pairs: the closest hit over several "
            f"tiles of triangles",
            dtype,
        )
    check_layout_edges_and_ties(impl, device, dtype)
    expect_error(
        "layout",
        impl.intersect_layout,
        {"kind": "bvh"},
        o,
        d,
        t_min,
        t_max,
        case="a dict of kind 'bvh'",
    )


# =======================================================================================
# Task 6: end to end, with the lab's own building blocks


def _repairs(impl, block: str, scene, o, d, expected) -> bool:
    """Whether render_whitted matches the reference with only ``block`` given."""
    image = impl.probe(
        render_with_blocks, "render_whitted", (block,), scene, o, d, trace_brute_force, 2
    )
    try:
        compare_images(image, expected, "", F32, scene.device)
    except AssertionError:
        return False
    return True


@pytest.mark.task(END_TO_END)
@pytest.mark.points(1)
def test_whole_tracer_end_to_end(impl, device):
    """render_whitted with the lab's own offset_origins, reflect, surface_at and shade_direct
    (every other renderer test gives it those). When the image is wrong, each block is
    swapped for the given one in turn: a swap that repairs the image names the wrong step."""
    for name in ("cornell_mirror", "courtyard_both"):
        scene = scene_on(name, F32, device)
        o, d = camera_rays(name, F32, device)
        expected = _reference(name, F32, 2, "camera")
        what = f"render_whitted on {name} with your own building blocks (float32)"
        try:
            compare_images(
                impl.render_whitted(scene, o, d, trace_brute_force, 2), expected, what, F32, device
            )
        except AssertionError as error:
            wrong = [block for block in BLOCKS if _repairs(impl, block, scene, o, d, expected)]
            hint = (
                f"the step that is wrong: {', '.join(wrong)} (with the given "
                f"{' or '.join(wrong)} in place of yours the image is right)"
                if wrong
                else "no single building block repairs the image when swapped for a given "
                "one: see the failing tests of each block and of render_whitted"
            )
            raise AssertionError(f"{what}: {hint}.\n{error}") from None
