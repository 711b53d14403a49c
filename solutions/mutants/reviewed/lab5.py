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
    "lab5_froxel:slice_integral:const_int:2": (
        "the placeholder length where sigma_t = 0 and D = inf only multiplies sigma_t = 0: tau = "
        "0 * 0 or 0 * 1 is 0 either way, and the integral uses length, not the placeholder"
    ),
    "lab5_froxel:slice_integral:cmp_Lt_LtE:1": (
        "a tie only: at tau = 1e-4 exactly, the series 1 - x/2 + x^2/6 and -expm1(-x)/x agree "
        "to ~4e-14 relative (series error x^3/24), far below any test's tolerance; where to "
        "switch formulas is the reference's own choice, not the contract's"
    ),
    "lab5_froxel:slice_integral:const_float:0": (
        "moving the series threshold from 1e-4 to 1.1e-4: both formulas agree there to ~6e-14 "
        "relative (series error x^3/24), far below any tolerance a correct solution must meet; "
        "where to switch is not part of the contract"
    ),
    "lab5_froxel:slice_integral:const_float:1": (
        "safe only replaces tau in the branch torch.where discards (tau < 1e-4); 1.0 or 1.1 "
        "only keeps that unused branch finite, so values and gradients are unchanged"
    ),
}
