"""Task 7: ``apply_froxels``, the fog over the opaque image; task 8: ``render_froxels``, the
whole frame from the stages of tasks 2, 3, 5, 6 and 7.
"""

from __future__ import annotations

import math

import torch

from course.given.lab5 import (
    INTEGRATIONS,
    LIGHT_STEPS,
    PHASES,
    SLICES,
    check_choice,
    check_grid,
    check_images,
    check_scene,
    check_volume,
    frame_jitter,
    sample_texture,
    scene_grid,
)

from .grid import depth_to_slice
from .integration import integrate_froxels
from .lighting import light_froxels
from .temporal import reproject, temporal_blend
from .vbuffer import voxelize


def apply_froxels(inscatter, transmittance, grid, depth_image, opaque_image, out=None):
    """Fog over the opaque image: ``out = opaque * T(p) + L(p)`` (premultiplied colour/alpha)
    at each pixel's view depth. Returns (H, W, 3), written into ``out`` when given.

    inscatter (S, ny, nx, 3), transmittance (S, ny, nx): :func:`integrate_froxels`'s values
    at the slices' far boundaries; with ``(L, T) = (0, 1)`` at ``near`` they sit on the
    nodes ``z = 0 .. slices`` of the slice coordinate, and across the screen at the tile
    centres. Lookup: trilinear at ``(pixel column + 0.5) / tile, (row + 0.5) / tile`` and
    ``depth_to_slice(depth)`` clamped to ``[0, slices]``: depths beyond ``far`` (and the sky,
    +inf) read the last slice, depths before ``near`` get no fog. depth_image (H, W) view
    depths >= 0 or +inf (NaN or negative depths raise ValueError naming it); opaque_image
    (H, W, 3) of the depths' dtype (else TypeError) and device (``check_images``); NaN/inf
    colours pass through as ``opaque * T + L`` would make them.

    Errors: TypeError naming ``grid`` unless it is a FroxelGrid; TypeError or ValueError
    naming ``depth_image`` (not an (H, W) float32/float64 tensor for the grid's camera;
    ValueError for NaN or negative depths), ``opaque_image`` (not (H, W, 3) of the depths'
    dtype, else TypeError, and device), ``inscatter``, ``transmittance`` or ``out`` (not of
    their shapes, in the depths' dtype and device).
    """
    # BEGIN SOLUTION (task 7)
    check_grid(grid)
    dtype = check_images(grid.camera, depth_image, opaque_image)
    device = depth_image.device
    check_volume(inscatter, "inscatter", (*grid.shape, 3), dtype, device)
    check_volume(transmittance, "transmittance", grid.shape, dtype, device)
    h, w = depth_image.shape
    if out is not None:
        check_volume(out, "out", (h, w, 3), dtype, device)
    nodes = torch.cat(
        [
            torch.cat([torch.zeros(1, grid.ny, grid.nx, 3, dtype=dtype, device=device), inscatter]),
            torch.cat([torch.ones(1, grid.ny, grid.nx, dtype=dtype, device=device), transmittance])[
                ..., None
            ],
        ],
        -1,
    )  # (S + 1, ny, nx, 4)
    z = depth_to_slice(depth_image, grid.near, grid.far, grid.slices)
    z = torch.nan_to_num(z, nan=0.0, posinf=grid.slices, neginf=0.0).clamp(0, grid.slices)
    rows = ((torch.arange(h, dtype=dtype, device=device) + 0.5) / grid.tile)[:, None]
    cols = ((torch.arange(w, dtype=dtype, device=device) + 0.5) / grid.tile)[None, :]
    coords = torch.stack([z + 0.5, rows.expand(h, w), cols.expand(h, w)], -1)
    values = sample_texture(nodes, coords)  # (H, W, 4)
    result = opaque_image * values[..., 3:] + values[..., :3]
    if out is None:
        return result
    out.copy_(result)
    return out
    # END SOLUTION


def render_froxels(
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
    temporal=False,
    frame=0,
    history=None,
):
    """One frame of the pipeline: ``(image (H, W, 3), report)``.

    voxelize -> light_froxels -> (temporal: reproject + temporal_blend of the lit source
    and the extinction) -> integrate_froxels -> apply_froxels, on a
    ``scene_grid(scene, camera, tile, slices, near, far)`` (None: the tile size and depth
    range the scene's media and lights need, see there: 1-pixel tiles when a point or spot
    light sits inside a medium in view, since froxels at tile centres miss its ``1 / d^2``
    peak), in
    the dtype and on the device of the images. With these defaults the frame's mean
    radiance is within 2% of the converged brute-force reference, lit by the sun or by a
    lamp inside the fog (up to ``MAX_TILES`` tiles: larger images keep coarser tiles).
    With ``temporal`` the froxels sample at ``frame_jitter(frame)`` (material and lighting
    alike), and ``history`` (the previous report's ``"history"``, or None) is
    reprojected and blended with weight ``BLEND`` for the new frame.

    The images as :func:`apply_froxels` takes them (checked even without media); bad
    settings (``tile``, ``slices``, ``near``, ``far``, ``phase``, ``integration``,
    ``frame``, ``history``) raise errors naming them.
    A scene without media returns a copy of ``opaque_image`` and does no V-buffer or
    lighting work. ``report``: ``grid``, ``froxels``, ``froxels_lit``, ``tiles_with_media``,
    ``light_tiles``, ``light_evaluations``, ``volume_bounds``, ``volume_resolution`` (as
    :func:`light_froxels`), ``jitter``,
    ``history_valid`` (fraction of froxels that kept history) and ``history`` (a dict
    ``{"grid", "source", "extinction", "frame"}`` for the next frame).

    Errors: TypeError naming ``scene`` unless it is a Scene; ``depth_image`` and
    ``opaque_image`` as in :func:`apply_froxels` (TypeError naming ``depth_image`` for
    float16/bfloat16 images); TypeError or ValueError naming ``tile``, ``slices``, ``near``
    or ``far`` (checked by ``FroxelGrid``); ValueError naming ``phase`` or ``integration``
    (not one of their choices) or ``frame`` (not an int >= 0); with ``temporal``, TypeError
    naming ``history`` unless it is None or the previous report's ``"history"``.
    """
    # BEGIN SOLUTION (task 8)
    check_scene(scene)
    grid = scene_grid(scene, camera, tile, slices, near, far)
    check_images(camera, depth_image, opaque_image)
    check_choice(phase, "phase", PHASES)
    check_choice(integration, "integration", INTEGRATIONS)
    if isinstance(frame, bool) or not isinstance(frame, int) or frame < 0:
        raise ValueError(f"frame: expected an int >= 0, got {frame!r}")
    dtype, device = depth_image.dtype, depth_image.device
    jitter = frame_jitter(frame) if temporal else 0.5
    report = {
        "grid": grid,
        "froxels": math.prod(grid.shape),
        "froxels_lit": 0,
        "tiles_with_media": 0,
        "light_tiles": [0] * len(scene.lights),
        "light_evaluations": 0,
        "volume_bounds": None,
        "volume_resolution": 0,
        "jitter": jitter,
        "history_valid": 0.0,
        "history": None,
    }
    if not scene.media:
        return opaque_image.clone(), report
    vbuffer = voxelize(scene, grid, jitter, dtype, device)
    source, light_report = light_froxels(
        scene,
        grid,
        vbuffer,
        jitter,
        phase=phase,
        volumetric_shadows=volumetric_shadows,
        shadow_resolution=shadow_resolution,
        volume_resolution=volume_resolution,
        light_steps=light_steps,
    )
    report.update(light_report)
    extinction = vbuffer["extinction"]
    if temporal and history is not None:
        if not isinstance(history, dict) or not {"grid", "source", "extinction"} <= set(history):
            raise TypeError("history: expected None or the previous report's 'history' dict")
        prev_source, valid = reproject(history["source"], history["grid"], grid)
        prev_ext, _ = reproject(history["extinction"], history["grid"], grid)
        source = temporal_blend(source, prev_source, valid)
        extinction = temporal_blend(extinction, prev_ext, valid)
        report["history_valid"] = valid.to(torch.float64).mean().item()
    if temporal:
        report["history"] = {
            "grid": grid,
            "source": source,
            "extinction": extinction,
            "frame": frame,
        }
    inscatter, transmittance = integrate_froxels(source, extinction, grid, integration)
    return apply_froxels(inscatter, transmittance, grid, depth_image, opaque_image), report
    # END SOLUTION
