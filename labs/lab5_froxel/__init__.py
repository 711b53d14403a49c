"""Lab 5: the Frostbite froxel pipeline.

Fill in every function that raises ``NotImplementedError`` (the tasks below); the code
imported from ``course.given.lab5`` is given. Run the grader for this lab with
``pytest tests/test_lab5_froxel.py`` (add ``-k slice_depths`` for one function). The tests call
your kernels on the CPU and, where present, on CUDA: write device- and dtype-agnostic
tensor code (loops over slices, lights or frames are fine; no loops over froxels or pixels).

Hillaire, "Physically Based and Unified Volumetric Rendering in Frostbite" (SIGGRAPH 2015),
stage by stage: a clip-space volume of froxels (frustum voxels) aligned with screen tiles,
filled with participating media (the V-buffer), lit once per froxel, accumulated over
frames, integrated front to back and applied to the opaque image. ``course.given.lab5_reference``
renders the same scenes by brute force (per pixel, many samples, exact shadows); the grader
compares the two.

Conventions shared by all kernels
---------------------------------
* A scene (:class:`course.given.lab5.Scene`): media (constant fog, height fog, local fog
  volumes with optional density textures), lights (sun with shadow map, point, spot), an
  ambient radiance and opaque boxes that shadow the sun. Physical units throughout.
* A :class:`FroxelGrid` (camera, tile, slices, near, far): volumes have shape
  ``(slices, ny, nx)`` (``[k, j, i]``: slice, tile row from the top, tile column), colour
  last. Froxel coordinates ``(x, y, z)``: ``x = pixel column / tile``, ``y = pixel row / tile``,
  ``z`` the slice coordinate (slice ``k`` spans ``[k, k + 1)``).
* Froxel ``[k, j, i]`` is sampled at ``froxel_sample_coords(grid, jitter)``: its tile's centre
  and the view depth ``z_k + jitter (z_(k+1) - z_k)``, ``jitter`` in [0, 1) (0.5 without
  temporal integration; the Halton sequence ``frame_jitter(frame)`` with it). Material and
  lighting use the same one.
* The view direction at a point p is ``v = (p - eye) / |p - eye|``; the scattering angle of
  light arriving from unit direction ``l`` (toward the light) has ``cos theta = v . l``
  (``g > 0`` scatters forward: bright looking toward the light).
* Everything works in float32 or float64 on the device of its inputs; float16/bfloat16 raise
  TypeError. Bad input raises ValueError/TypeError naming the argument.

Tasks (points), one file each
-----------------------------
1. ``grid.py``, the grid: ``slice_depths``, ``depth_to_slice``, ``froxel_to_world``,
   ``world_to_froxel``                                                         (2.5)
2. ``vbuffer.py``, the V-buffer: ``media_at``, ``voxelize``                    (2)
3. ``lighting.py``, scattered light per froxel: ``henyey_greenstein``, ``schlick_phase``,
   ``cull_lights``, ``build_shadow_map``, ``shadow_lookup``, ``light_froxels``  (4)
4. ``volumetric_shadows.py``: ``extinction_volume``, ``transmittance_volume``,
   ``sample_light_volume``, ``light_transmittance``                            (2)
5. ``temporal.py``, temporal integration: ``reproject``, ``temporal_blend``     (2.5)
6. ``integration.py``, final integration: ``slice_integral``, ``integrate_froxels`` (3)
7. ``pipeline.py``: ``apply_froxels``, application to the opaque image          (1)
8. ``pipeline.py``: ``render_froxels``, the whole frame, end to end on your own stages
   (3.25; each earlier task is graded on the grader's inputs, so a mistake there costs
   its points once there and again only here)

The lab is this package: the graders load ``lab5_froxel/`` and call the functions this
file imports from its modules. Each module imports what its code uses of
``course.given.lab5`` (input checks, the froxel sample points, texture sampling, light
frames); everything else there is one import away. A module calls another task's function
through its import (``from .grid import froxel_to_world``), so a grader that stands a
given function in for yours is seen there too. Hand in the files you edit (see
``labs/README.md``): a file you leave out is graded as this skeleton's, so it costs only
its own tasks.

Accuracy (asserted by the grader, measured by ``bench/lab5_froxel.py``)
-----------------------------------------------------------------------
* Exact to rounding: the slicing and its inverse, world <-> froxel mapping, the V-buffer at
  its sample points, the lighting at its sample points (without shadows), the per-slice
  integral (any optical depth, 0 to 1e6, with a finite gradient at 0), and the integration
  of a homogeneous medium, independent of the slice count.
* Approximate by design, at the froxel resolution: everything between sample points. A
  tile spans 8 pixels (the phase function, the path length per view depth and the edges
  of fog volumes and shadows are interpolated across it), a slice 43% of its depth at 16
  slices over 0.1 .. 30 m. Against the brute-force reference the grader allows 4-5% of the
  largest radiance (homogeneous fog, height fog), 10% at the silhouette of
  a textured fog volume and 20% at the edges of a sun shadow in fog (a tile of blur).
* Volumetric shadows cover what the scene requires: the media's bounds within the view
  (``volume_bounds``) at a resolution chosen from the media's size
  (``auto_volume_resolution``), and every light's path, point lights' too. The froxel grid
  itself is chosen from the scene (``scene_grid``): a fog volume seen from outside would
  span few fixed 8-pixel tiles and few of 64 slices over 0.1 .. 100 m, and its silhouette,
  interpolated between tile centres, would lose or gain light; by default the tiles shrink
  until every fog volume spans 12 of them, to one pixel when a point or spot light sits
  inside a medium in view (its ``1 / d^2`` peak is narrower than any tile), and the slices cover
  the media's depths only (scenes with unbounded fog lit by the sun keep 8 px and
  0.1 .. 100 m). With these defaults a frame's mean radiance is within 2% of the
  converged brute-force reference, lit by the sun or by a lamp inside the fog.

Errors against the brute-force reference and a float64 quadrature (per tile size, slice
count, volume resolution, with and without volumetric shadows or temporal integration),
measured by ``bench/lab5_froxel.py``: ``bench/results/cpu-2cores/lab5/`` (GPUs:
``bench/results/<gpu>/lab5/``).
"""

from __future__ import annotations

from course.given.lab5 import (
    BLEND,
    INTEGRATIONS,
    LIGHT_STEPS,
    PHASES,
    SLICES,
    FroxelGrid,
    LightVolume,
    Scene,
    auto_volume_resolution,
    frame_jitter,
    froxel_sample_coords,
    frustum_bounds,
    scene_grid,
    volume_bounds,
)

from .grid import depth_to_slice, froxel_to_world, slice_depths, world_to_froxel
from .integration import integrate_froxels, slice_integral
from .lighting import (
    build_shadow_map,
    cull_lights,
    henyey_greenstein,
    light_froxels,
    schlick_phase,
    shadow_lookup,
)
from .pipeline import apply_froxels, render_froxels
from .temporal import reproject, temporal_blend
from .vbuffer import media_at, voxelize
from .volumetric_shadows import (
    extinction_volume,
    light_transmittance,
    sample_light_volume,
    transmittance_volume,
)

__all__ = [
    # task 1
    "slice_depths",
    "depth_to_slice",
    "froxel_to_world",
    "world_to_froxel",
    # task 2
    "media_at",
    "voxelize",
    # task 3
    "henyey_greenstein",
    "schlick_phase",
    "cull_lights",
    "build_shadow_map",
    "shadow_lookup",
    "light_froxels",
    # task 4
    "extinction_volume",
    "transmittance_volume",
    "sample_light_volume",
    "light_transmittance",
    # task 5
    "reproject",
    "temporal_blend",
    # task 6
    "slice_integral",
    "integrate_froxels",
    # task 7
    "apply_froxels",
    # task 8
    "render_froxels",
    # given (course.given.lab5), part of the lab's interface
    "BLEND",
    "INTEGRATIONS",
    "LIGHT_STEPS",
    "PHASES",
    "SLICES",
    "FroxelGrid",
    "LightVolume",
    "Scene",
    "auto_volume_resolution",
    "frame_jitter",
    "froxel_sample_coords",
    "frustum_bounds",
    "scene_grid",
    "volume_bounds",
]
