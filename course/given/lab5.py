"""Scenes, lights, the froxel grid and input checks shared by Lab 5's skeleton and reference.

Given code, not exercises: the lab's skeleton, its reference, the brute-force reference
renderer (:mod:`course.given.lab5_reference`), the grader and the benchmarks all describe a
scene with these dataclasses, so there is one copy of them. They are frozen dataclasses of
the ``course`` package: they travel to a sandboxed worker by value.

They live in parts, all imported here (``from course.given.lab5 import ...``):
:mod:`course.given.lab5_scene` (media, lights, boxes, the scene), :mod:`course.given.lab5_grid`
(the froxel grid, its samples, texture sampling and ray-box tests), :mod:`course.given.lab5_volumes`
(light-space textures and their resolution), :mod:`course.given.lab5_checks` (pipeline
constants and input checks).

Units are physical: lengths in metres, extinction and scattering coefficients per metre,
sun irradiance in W/m^2 per colour channel, point/spot intensity in W/sr, radiance in
W/(m^2 sr). Media are summed linearly; extinction is one number per medium (independent of
wavelength, as in Hillaire's talk), scattering is RGB and must not exceed it (albedo <= 1).
"""

from __future__ import annotations

from course.given.lab5_checks import (
    BLEND,
    FLOATS,
    INTEGRATIONS,
    PHASES,
    SCHLICK_K_MAX,
    check_choice,
    check_depths,
    check_dtype,
    check_grid,
    check_images,
    check_jitter,
    check_lights,
    check_phase_inputs,
    check_scene,
    check_volume,
    check_volume_resolution,
)
from course.given.lab5_grid import (
    FAR,
    MAX_TILES,
    NEAR,
    SLICES,
    TILE,
    TILES_PER_VOLUME,
    FroxelGrid,
    frame_jitter,
    froxel_sample_coords,
    halton,
    lights_in_media,
    ray_boxes,
    sample_texture,
    scene_grid,
    slice_offset,
)
from course.given.lab5_scene import (
    LIGHTS,
    MEDIA,
    Box,
    ConstantFog,
    DirectionalLight,
    FogVolume,
    HeightFog,
    PointLight,
    Scene,
    SpotLight,
)
from course.given.lab5_volumes import (
    LIGHT_STEPS,
    MAX_VOLUME_RESOLUTION,
    MIN_LIGHT_DISTANCE,
    VOLUME_RESOLUTION,
    VOXELS_PER_VOLUME,
    LightVolume,
    auto_volume_resolution,
    frustum_bounds,
    light_coords,
    light_frame,
    media_bounds,
    volume_bounds,
)

__all__ = [
    "BLEND",
    "Box",
    "ConstantFog",
    "DirectionalLight",
    "FAR",
    "FLOATS",
    "FogVolume",
    "FroxelGrid",
    "HeightFog",
    "INTEGRATIONS",
    "LIGHTS",
    "LIGHT_STEPS",
    "LightVolume",
    "MAX_TILES",
    "MAX_VOLUME_RESOLUTION",
    "MEDIA",
    "MIN_LIGHT_DISTANCE",
    "NEAR",
    "PHASES",
    "PointLight",
    "SCHLICK_K_MAX",
    "SLICES",
    "Scene",
    "SpotLight",
    "TILE",
    "TILES_PER_VOLUME",
    "VOLUME_RESOLUTION",
    "VOXELS_PER_VOLUME",
    "auto_volume_resolution",
    "check_choice",
    "check_depths",
    "check_dtype",
    "check_grid",
    "check_images",
    "check_jitter",
    "check_lights",
    "check_phase_inputs",
    "check_scene",
    "check_volume",
    "check_volume_resolution",
    "frame_jitter",
    "froxel_sample_coords",
    "frustum_bounds",
    "halton",
    "light_coords",
    "light_frame",
    "lights_in_media",
    "media_bounds",
    "ray_boxes",
    "sample_texture",
    "scene_grid",
    "slice_offset",
    "volume_bounds",
]
