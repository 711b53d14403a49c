"""Lab 5's generated mutants that survive the graders, reviewed (see
``solutions/mutants/reviewed/__init__.py``)."""

EQUIVALENT = {
    "lab5_froxel:cull_lights:cmp_GtE_Gt:3": (
        "a tie only: a bottom distance of exactly -range is a sphere tangent to the plane, decided "
        "by rounding, and the light gives nothing at exactly its range; the docstring says ties may"
        " go either way"
    ),
    "lab5_froxel:cull_lights:cmp_GtE_Gt:4": (
        "a tie only: a view depth of exactly near - range is a sphere tangent to the near plane, "
        "and the light gives nothing at exactly its range (docstring: either way)"
    ),
    "lab5_froxel:light_transmittance:drop_nan_to_num:0": (
        "the NaN (0 * inf) arises only for a segment parallel to an axis lying exactly in a face "
        "plane of the box: a tie between inside and outside (docstring: either)"
    ),
    "lab5_froxel:apply_froxels:drop_nan_to_num:0": (
        "depth_to_slice is NaN only for NaN depths, which check_images rejects; the clamp(0, "
        "slices) after it maps -inf/+inf exactly as nan_to_num does"
    ),
    "lab5_froxel:apply_froxels:const_float:0": (
        "the nan= replacement is never used: NaN depths are rejected by check_images"
    ),
    "lab5_froxel:cull_lights:narrow_dtype:1": (
        "float32 tile-edge NDC changes the plane distances by ~1e-7 of the light's distance: only "
        "spheres within rounding of tangent go the other way (docstring: either way)"
    ),
    "lab5_froxel:build_shadow_map:const_float:0": (
        "the plane's margin beyond the occluders is free: the data are depths from the map's own "
        "origin and shadow_lookup measures from that origin, so visibility is unchanged"
    ),
    "lab5_froxel:light_transmittance:cmp_Gt_GtE:0": (
        "where span == 0 the optical depth is multiplied by span = 0 whatever points are sampled: T"
        " = 1 both ways"
    ),
    "lab5_froxel:transmittance_volume:const_int:4": (
        "the fallback shape only feeds check_volume for a non-3-D extinction, which is rejected "
        "with (1, 1, 1) or (1, 1, 2) alike"
    ),
}
