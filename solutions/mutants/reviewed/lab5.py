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
    "lab5_froxel:slice_integral:const_int:9": (
        "the 1 only stands in for sigma_t where tau is finite, whose 1 / (...) the outer "
        "where(endless, ...) discards; finite and nonzero either way, so no inf or NaN reaches "
        "the values or the gradients"
    ),
    "lab5_froxel:slice_integral:const_int:10": (
        "the 0 stands in for D where tau = inf, whose D phi the outer where(endless, ...) "
        "discards; it only keeps that branch free of inf * 0 (0 or 1 times phi = 0 alike)"
    ),
    "lab5_froxel:cull_lights:cmp_GtE_Gt:0": (
        "a tie only: a left distance of exactly -range is a sphere tangent to the plane; the docstring: 'A sphere exactly tangent to a plane (distance exactly -range) ... may go either way: the light gives nothing at its range'"
    ),
    "lab5_froxel:cull_lights:cmp_GtE_Gt:1": (
        "a tie only: a right distance of exactly -range is a tangent sphere, which the docstring lets go either way"
    ),
    "lab5_froxel:cull_lights:cmp_GtE_Gt:2": (
        "a tie only: a top distance of exactly -range is a tangent sphere, which the docstring lets go either way"
    ),
    "lab5_froxel:cull_lights:cmp_LtE_Lt:0": (
        "a tie only: a view depth of exactly far + range is a sphere tangent to the far plane (docstring: either way)"
    ),
    "lab5_froxel:cull_lights:narrow_dtype:2": (
        "float32 tile-edge NDC (exact small integers times t / w, rounded once: ~6e-8) moves the side planes by ~1e-7 of the light's distance from the eye; the docstring: 'the planes may be computed in float32: about 1e-7 of the light's distance from the eye ... may go either way'"
    ),
    "lab5_froxel:cull_lights:narrow_dtype:3": (
        "as narrow_dtype:2, for the right tile edges: ~1e-7 of the distance from the eye, which the docstring allows"
    ),
    "lab5_froxel:cull_lights:narrow_dtype:4": (
        "as narrow_dtype:2, for the top tile edges: ~1e-7 of the distance from the eye, which the docstring allows"
    ),
    "lab5_froxel:build_shadow_map:narrow_dtype:0": (
        "the centre in float32 only moves the map's origin (stored in the LightVolume and read back by shadow_lookup, so depths stay consistent) by ~1e-7 of |centre|: the covered disc shifts by that much, a tie at its rim; the plane's margin is free (see const_float:0)"
    ),
    "lab5_froxel:build_shadow_map:narrow_dtype:2": (
        "the occluder corners in float32 only feed the lift (how far beyond every occluder the plane lies, with 1 m to spare): ~1e-7 of a corner's coordinates changes the plane's position, which is free (depths are measured from the map's own origin)"
    ),
    "lab5_froxel:build_shadow_map:const_float:2": (
        "a shadow map's near field is never read: shadow_lookup compares depths from the origin with the (R, R) data, and LightVolume documents near/far only for (R, R, K) transmittance volumes"
    ),
    "lab5_froxel:shadow_lookup:const_int:2": (
        "data.shape[1] equals data.shape[0]: a shadow map's data is square, (R, R) (build_shadow_map's docstring)"
    ),
    "lab5_froxel:shadow_lookup:cmp_LtE_Lt:0": (
        "a tie only: a point exactly two texels behind its texel's occluder depth (depth == occluder + bias) is at the bias's edge, which the docstring ('by more than a bias of two texels') decides by a real-valued comparison no float computation pins"
    ),
}
