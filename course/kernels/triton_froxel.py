"""Lab 5's froxel pipeline as fused Triton kernels: a frame without a Python loop over lights.

Lab 5 writes the Frostbite pipeline as batched torch code, stage by stage: the V-buffer,
then one pass over the lit froxels per light (a dozen tensor operations each), the
prefix sums of the integration, the trilinear application. Every stage is a round trip
of a 2-million-froxel volume through DRAM, and the reference reads tensor sizes back to
the host several times per frame. The talk's GPU version does the opposite: one thread
per froxel evaluates the media and all the lights of its tile in registers, and the
integration walks each froxel column in the same program. This module is that design,
given (not an exercise) so the lab can measure the gap on the same numbers.

Kernels of one frame (no host synchronisation between them):

1. ``_shadow_map_kernel``: the sun's shadow map (a ray per texel against the occluder
   boxes), for every sun with ``shadows`` when the scene has occluders;
2. ``_extinction_kernel``: the extinction volume over ``volume_bounds(scene, grid)`` (the
   media's bounds in view, reaching the point and spot lights that light it; the media at
   its voxel centres), at ``volume_resolution`` or the one chosen from the media's size;
3. ``_transmittance_kernel``: every sun's and spot light's transmittance volume, a texel
   per lane marching its ray through the extinction volume (4 depth samples per texel
   of resolution, as the lab's ``light_froxels``);
4. ``_froxel_kernel``: a program per tile column (all its slices in one block of lanes):
   the media at each froxel's sample point (constant fog, height fog, fog volumes with
   their density textures), the light culling of the tile (float64, as the lab's
   ``cull_lights``), the lighting (phase function, shadow map, transmittance volume),
   with each point light's path to the froxel marched through the extinction volume
   (``light_steps`` midpoint steps over its part inside the volume's box, as the lab's
   ``light_transmittance``; lanes beyond the light's range skip it),
   and the front-to-back integration of the column as prefix sums over the block
   (``tl.cumsum``), written as the volume of nodes ``(L, T)`` that the application reads;
5. ``_apply_kernel``: a lane per pixel, the trilinear lookup at its view depth.

What it computes is Lab 5's ``render_froxels`` for the non-temporal path (jitter 0.5),
with every numerical convention of the lab (``solutions/lab5_froxel/`` states them):
exponential slices, samples at the tile centre and the middle depth of the slice,
``MIN_LIGHT_DISTANCE`` and the ``range`` cut-off of point and spot lights, the spot's
smoothstep, the shadow map's nearest-texel test with its bias, trilinear transmittance
volumes (1 outside them), the energy-conserving slice integral ``S D phi(sigma_t D)``
with ``phi(x) = (1 - e^-x) / x`` by its series for small ``x`` (finite at 0, no NaN for
huge ``x``), and the application's clamping (depths beyond ``far`` and the sky read the
last slice, depths before ``near`` get no fog). Only tiles with media are lit, only
froxels that scatter, each light only in the tiles of its list.

Accuracy: float32 throughout (float64 images are computed in float32 and returned as
float64); the compiled kernels use the GPU's fast ``exp``/``log``/division, so values
agree with the torch pipeline in float32 to a few 1e-6 relative. A sample point within
rounding of a discontinuity (the edge of a fog volume, a shadow-map texel, a light's
range) may fall on the other side of it; ``tests/meta/test_triton_froxel.py`` bounds how
often.

Speed: the frame's budget is 2 ms for the talk's 1080p frame (240 x 135 x 64 froxels, a
sun with a shadow map, 14 point lights, 6 textured fog volumes, height fog).
``bench/lab5_froxel.py --device cuda --gpu-target`` times that frame against the torch
pipeline, kernel by kernel, and checks the images agree; its figures are in
bench/results/<gpu>/lab5/ (nvidia-h200, nvidia-h100-80gb-hbm3).

The parts: :mod:`course.kernels.triton_froxel_lookups` (the packed tables' layout and the
device functions), :mod:`course.kernels.triton_froxel_kernels` (the five kernels),
:mod:`course.kernels.triton_froxel_plan` (the scene packed into tables); this module
checks the arguments and launches the frame.

Runs compiled on CUDA, or in Triton's CPU interpreter when ``TRITON_INTERPRET=1`` is set
before ``triton`` is first imported (small frames only). Importing this module without
Triton works; calling it then raises ImportError.
"""

from __future__ import annotations

import math

import torch

from course.given.lab5_checks import (
    INTEGRATIONS,
    PHASES,
    check_choice,
    check_scene,
    check_volume,
    check_volume_resolution,
)
from course.given.lab5_grid import SLICES, scene_grid, slice_offset
from course.given.lab5_volumes import LIGHT_STEPS
from course.kernels.triton_froxel_kernels import (
    _apply_kernel,
    _extinction_kernel,
    _froxel_kernel,
    _shadow_map_kernel,
    _transmittance_kernel,
)
from course.kernels.triton_froxel_plan import _plan
from course.kernels.triton_intersect import _ieee_quiet, _require_triton, interpreting, triton

__all__ = ["render_froxels_fused"]

BLOCK_PIXELS = 256  # lanes per program of the application
BLOCK_TEXELS = 128  # lanes per program of the light-space textures and the extinction volume
# Interpreted, every program costs milliseconds of Python: far fewer, larger blocks.
BLOCK_TEXELS_INTERPRETED = 8192


def render_froxels_fused(
    scene,
    camera,
    depth_image,
    opaque_image,
    *,
    tile=None,
    slices=SLICES,
    near=None,
    far=None,
    phase="hg",
    integration="energy",
    volumetric_shadows=True,
    shadow_resolution=128,
    volume_resolution=None,
    light_steps=LIGHT_STEPS,
    counts=True,
    num_warps=None,
):
    """Lab 5's ``render_froxels`` (non-temporal) in five Triton launches: ``(image, report)``.

    scene: a ``course.given.lab5.Scene``; camera: its ``Camera``; depth_image (H, W)
    view depths >= 0 (+inf: sky), opaque_image (H, W, 3), float32 or float64 on one CUDA
    device (or the CPU under ``TRITON_INTERPRET=1``); the keywords as ``render_froxels``.
    Returns the image (H, W, 3) in the images' dtype and a report with the keys of
    ``render_froxels``' (``grid``, ``froxels``, ``froxels_lit``, ``tiles_with_media``,
    ``light_tiles``, ``light_evaluations``, ``jitter`` 0.5, ``history_valid`` 0.0,
    ``history`` None) and ``kernel``, the froxel kernel's compiled handle (``n_regs``,
    ``n_spills``; absent without media), ``volume_bounds`` and ``volume_resolution`` (as the
    lab's). The counts cost one synchronisation at the end of the frame: with
    ``counts=False`` they are None, the kernels skip that bookkeeping and nothing waits
    for the GPU (the frame is only queued).

    ``num_warps``: of the froxel kernel, a power of two up to 32 (default: one warp per 32
    slices, a lane per froxel of the column: the launch the GPU accuracy tests run).

    A scene without media returns a copy of ``opaque_image``, as the lab does. The scene's
    description (not its density textures) is packed into device tables once per scene,
    camera and settings; the shadow maps, the extinction and transmittance volumes, the
    froxels and the image are computed every call.
    """
    _require_triton()
    check_scene(scene)
    grid = scene_grid(scene, camera, tile, slices, near, far)
    # The lab's check_images also scans the depths for NaN and negative values, which
    # waits for the GPU: here only shapes, dtypes and devices are checked (a NaN depth
    # reads as no fog, a negative one as before near).
    h, w = camera.height, camera.width
    check_volume(depth_image, "depth_image", (h, w))
    check_volume(opaque_image, "opaque_image", (h, w, 3), depth_image.dtype, depth_image.device)
    dtype = depth_image.dtype
    check_choice(phase, "phase", PHASES)
    check_choice(integration, "integration", INTEGRATIONS)
    for name, value in (("shadow_resolution", shadow_resolution), ("light_steps", light_steps)):
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise ValueError(f"{name}: expected an int >= 1, got {value!r}")
    check_volume_resolution(volume_resolution)
    # Compiled, Triton rejects a warp count that is not a power of two deep in its compiler
    # (an assertion naming none of these arguments) and cannot launch over 32 warps; the
    # interpreter ignores num_warps, so a bad value would pass every CPU test.
    if num_warps is not None and (
        isinstance(num_warps, bool)
        or not isinstance(num_warps, int)
        or not 1 <= num_warps <= 32
        or num_warps & (num_warps - 1)
    ):
        raise ValueError(f"num_warps: expected None or a power of two <= 32, got {num_warps!r}")
    report = {
        "grid": grid,
        "froxels": math.prod(grid.shape),
        "froxels_lit": 0,
        "tiles_with_media": 0,
        "light_tiles": [0] * len(scene.lights),
        "light_evaluations": 0,
        "volume_bounds": None,
        "volume_resolution": 0,
        "jitter": 0.5,
        "history_valid": 0.0,
        "history": None,
    }
    if not scene.media:
        return opaque_image.clone(), report
    device = depth_image.device
    if not interpreting() and device.type != "cuda":
        raise ValueError(
            f"depth_image: the compiled Triton kernels need CUDA tensors, got "
            f"{device} (for the CPU, set TRITON_INTERPRET=1 before importing "
            "triton)"
        )

    plan = _plan(
        scene, grid, shadow_resolution, volume_resolution, bool(volumetric_shadows), device
    )
    f32 = torch.float32
    if plan["textures"]:
        tex = torch.cat(
            [scene.media[m].density.to(device, f32).reshape(-1) for m in plan["textures"]]
        )
    else:
        tex = torch.zeros(1, dtype=f32, device=device)
    vdata = torch.empty(plan["data_size"], dtype=f32, device=device)
    n_tiles = grid.nx * grid.ny
    n_lights = len(scene.lights)
    nodes = torch.empty(grid.slices + 1, grid.ny, grid.nx, 4, dtype=f32, device=device)
    lit = torch.empty(n_tiles if counts else 1, dtype=torch.int32, device=device)
    media = torch.empty(n_tiles if counts else 1, dtype=torch.int8, device=device)
    listed = torch.empty(
        max(n_lights, 1) * n_tiles if counts else 1, dtype=torch.int8, device=device
    )
    depth = depth_image.to(f32).contiguous()
    opaque = opaque_image.to(f32).contiguous()
    out = torch.empty(opaque.shape, dtype=f32, device=device)
    block_s = max(triton.next_power_of_2(grid.slices), 4)  # >= 4: lanes 0-3 write node 0
    warps = num_warps or max(1, min(8, block_s // 32))
    block = BLOCK_TEXELS_INTERPRETED if interpreting() else BLOCK_TEXELS
    with _ieee_quiet():
        if plan["n_maps"]:
            res = plan["shadow_resolution"]
            _shadow_map_kernel[(plan["n_maps"], triton.cdiv(res * res, block))](
                plan["volf"], plan["voli"], vdata, plan["boxes"], plan["n_boxes"], BLOCK=block
            )
        res = plan["volume_resolution"] if plan["extinction"] else 1
        ext = torch.empty(res**3, dtype=f32, device=device)
        if plan["extinction"]:
            _extinction_kernel[(triton.cdiv(res**3, block),)](
                ext,
                plan["medf"],
                plan["medi"],
                tex,
                len(scene.media),
                res,
                *plan["lo"],
                *plan["size"],
                BLOCK=block,
            )
            if plan["n_volumes"]:
                _transmittance_kernel[(plan["n_volumes"], triton.cdiv(res * res, block))](
                    plan["volf"],
                    plan["voli"],
                    vdata,
                    ext,
                    res,
                    plan["first_volume"],
                    *plan["lo"],
                    *plan["size"],
                    BLOCK=block,
                )
        log_ratio = math.log(grid.far / grid.near)
        report["kernel"] = _froxel_kernel[(n_tiles,)](
            nodes,
            lit,
            media,
            listed,
            plan["camf"],
            plan["camd"],
            plan["dz"],
            plan["medf"],
            plan["medi"],
            tex,
            len(scene.media),
            plan["lightf"],
            plan["lighti"],
            plan["lightd"],
            n_lights,
            plan["volf"],
            plan["voli"],
            vdata,
            ext,
            res,
            *plan["lo"],
            *plan["size"],
            light_steps,
            grid.nx,
            grid.ny,
            grid.slices,
            grid.tile,
            camera.width,
            camera.height,
            grid.near,
            log_ratio / grid.slices,
            slice_offset(grid, 0.5),
            *scene.ambient,
            BLOCK_S=block_s,
            SCHLICK=phase == "schlick",
            NAIVE=integration == "naive",
            COUNTS=bool(counts),
            num_warps=warps,
        )
        n_pixels = camera.width * camera.height
        _apply_kernel[(triton.cdiv(n_pixels, BLOCK_PIXELS),)](
            out,
            nodes,
            depth,
            opaque,
            n_pixels,
            camera.width,
            grid.tile,
            grid.nx,
            grid.ny,
            grid.slices,
            float(grid.nx),
            float(grid.ny),
            float(grid.slices),
            math.log(grid.near),
            grid.slices / log_ratio,
            BLOCK=BLOCK_PIXELS,
        )
    if plan["extinction"]:
        report["volume_bounds"] = plan["bounds"]
        report["volume_resolution"] = plan["volume_resolution"]
    if counts:
        _count(report, lit, media, listed, n_lights, n_tiles)
    else:
        for name in ("froxels_lit", "tiles_with_media", "light_tiles", "light_evaluations"):
            report[name] = None
    return out.to(dtype), report


def _count(report, lit, media, listed, n_lights, n_tiles):
    """The lab's counts from the per-tile numbers the kernel wrote, in one transfer."""
    listed = listed[: n_lights * n_tiles].reshape(n_lights, n_tiles).to(torch.int64)
    lit = lit.to(torch.int64)
    media = media.to(torch.int64)
    totals = torch.cat(
        [lit.sum()[None], media.sum()[None], (listed * lit).sum()[None], (listed * media).sum(1)]
    ).tolist()
    report["froxels_lit"], report["tiles_with_media"] = totals[0], totals[1]
    report["light_evaluations"] = totals[2]
    # Nothing lit: the lab evaluates no light anywhere.
    report["light_tiles"] = totals[3:] if totals[0] else [0] * n_lights
