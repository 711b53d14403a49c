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
    raise NotImplementedError("not implemented yet: apply_froxels (task 7)")


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
    raise NotImplementedError("not implemented yet: render_froxels (task 8)")
