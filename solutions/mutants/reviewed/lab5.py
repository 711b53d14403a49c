"""Lab 5's generated mutants that survive the graders, reviewed (see
``solutions/mutants/reviewed/__init__.py``)."""

EQUIVALENT = {
    "lab5_froxel:cull_lights:cmp_GtE_Gt:3": (
        "a tie only: a bottom distance of exactly -range is a sphere tangent to the plane, "
        "decided by rounding, and the light gives nothing at exactly its range; the docstring "
        "says ties may go either way"
    ),
    "lab5_froxel:cull_lights:cmp_GtE_Gt:4": (
        "a tie only: a view depth of exactly near - range is a sphere tangent to the near "
        "plane, and the light gives nothing at exactly its range (docstring: either way)"
    ),
    "lab5_froxel:light_transmittance:drop_nan_to_num:0": (
        "the NaN (0 * inf) arises only for a segment parallel to an axis lying exactly in a "
        "face plane of the box: a tie between inside and outside (docstring: either)"
    ),
    "lab5_froxel:apply_froxels:drop_nan_to_num:0": (
        "depth_to_slice is NaN only for NaN depths, which check_images rejects; the clamp(0, "
        "slices) after it maps -inf/+inf exactly as nan_to_num does"
    ),
    "lab5_froxel:apply_froxels:const_float:0": (
        "the nan= replacement is never used: NaN depths are rejected by check_images"
    ),
    "lab5_froxel:cull_lights:narrow_dtype:1": (
        "float32 tile-edge NDC changes the plane distances by ~1e-7 of the light's distance: "
        "only spheres within rounding of tangent go the other way (docstring: either way)"
    ),
    "lab5_froxel:build_shadow_map:const_float:0": (
        "the plane's margin beyond the occluders is free: the data are depths from the map's "
        "own origin and shadow_lookup measures from that origin, so visibility is unchanged"
    ),
    "lab5_froxel:light_transmittance:cmp_Gt_GtE:0": (
        "where span == 0 the optical depth is multiplied by span = 0 whatever points are "
        "sampled: T = 1 both ways"
    ),
    "lab5_froxel:transmittance_volume:const_int:4": (
        "the fallback shape only feeds check_volume for a non-3-D extinction, which is rejected"
        " with (1, 1, 1) or (1, 1, 2) alike"
    ),
    "lab5_froxel:slice_integral:const_int:2": (
        "the placeholder length where sigma_t = 0 and D = inf only multiplies sigma_t = 0: tau "
        "= 0 * 0 or 0 * 1 is 0 either way, and the integral uses length, not the placeholder"
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
        "a tie only: a left distance of exactly -range is a sphere tangent to the plane; the "
        "docstring: 'A sphere exactly tangent to a plane (distance exactly -range) ... may go "
        "either way: the light gives nothing at its range'"
    ),
    "lab5_froxel:cull_lights:cmp_GtE_Gt:1": (
        "a tie only: a right distance of exactly -range is a tangent sphere, which the "
        "docstring lets go either way"
    ),
    "lab5_froxel:cull_lights:cmp_GtE_Gt:2": (
        "a tie only: a top distance of exactly -range is a tangent sphere, which the docstring "
        "lets go either way"
    ),
    "lab5_froxel:cull_lights:cmp_LtE_Lt:0": (
        "a tie only: a view depth of exactly far + range is a sphere tangent to the far plane "
        "(docstring: either way)"
    ),
    "lab5_froxel:cull_lights:narrow_dtype:2": (
        "float32 tile-edge NDC (exact small integers times t / w, rounded once: ~6e-8) moves "
        "the side planes by ~1e-7 of the light's distance from the eye; the docstring: 'the "
        "planes may be computed in float32: about 1e-7 of the light's distance from the eye ..."
        " may go either way'"
    ),
    "lab5_froxel:cull_lights:narrow_dtype:3": (
        "as narrow_dtype:2, for the right tile edges: ~1e-7 of the distance from the eye, which"
        " the docstring allows"
    ),
    "lab5_froxel:cull_lights:narrow_dtype:4": (
        "as narrow_dtype:2, for the top tile edges: ~1e-7 of the distance from the eye, which "
        "the docstring allows"
    ),
    "lab5_froxel:build_shadow_map:narrow_dtype:0": (
        "the centre in float32 only moves the map's origin (stored in the LightVolume and read "
        "back by shadow_lookup, so depths stay consistent) by ~1e-7 of |centre|: the covered "
        "disc shifts by that much, a tie at its rim; the plane's margin is free (see "
        "const_float:0)"
    ),
    "lab5_froxel:build_shadow_map:narrow_dtype:2": (
        "the occluder corners in float32 only feed the lift (how far beyond every occluder the "
        "plane lies, with 1 m to spare): ~1e-7 of a corner's coordinates changes the plane's "
        "position, which is free (depths are measured from the map's own origin)"
    ),
    "lab5_froxel:build_shadow_map:const_float:2": (
        "a shadow map's near field is never read: shadow_lookup compares depths from the origin"
        " with the (R, R) data, and LightVolume documents near/far only for (R, R, K) "
        "transmittance volumes"
    ),
    "lab5_froxel:shadow_lookup:const_int:2": (
        "data.shape[1] equals data.shape[0]: a shadow map's data is square, (R, R) "
        "(build_shadow_map's docstring)"
    ),
    "lab5_froxel:shadow_lookup:cmp_LtE_Lt:0": (
        "a tie only: a point exactly two texels behind its texel's occluder depth (depth == "
        "occluder + bias) is at the bias's edge, which the docstring ('by more than a bias of "
        "two texels') decides by a real-valued comparison no float computation pins"
    ),
    "lab5_froxel:light_transmittance:const_int:1": (
        "the fallback shape only feeds check_volume for an extinction that is not a 3-D tensor,"
        " which is rejected against (1, 1, 1) or (2, 1, 1) alike (TypeError for a non-tensor, "
        "ValueError for another shape)"
    ),
    "lab5_froxel:light_transmittance:const_int:2": (
        "as const_int:1: the fallback (1, 2, 1) or (1, 1, 1) only serves to reject a non-3-D "
        "extinction, which both do"
    ),
    "lab5_froxel:light_transmittance:const_int:3": (
        "as const_int:1: the fallback (1, 1, 2) or (1, 1, 1) only serves to reject a non-3-D "
        "extinction, which both do"
    ),
    "lab5_froxel:light_transmittance:drop_neg:0": (
        "min(a, b) is NaN only for 0 * inf: a segment parallel to an axis (rel_k = 0) with the "
        "point exactly on that face plane (lo_k = p_k or hi_k = p_k); the docstring: 'A segment"
        " lying in the plane of one of the box's faces (a tie between inside and outside) may "
        "count as either'"
    ),
    "lab5_froxel:light_transmittance:drop_nan_to_num:1": (
        "as drop_neg:0: max(a, b) is NaN only for a segment lying in a face plane of the box, a"
        " tie the docstring lets count as either"
    ),
    "lab5_froxel:light_transmittance:drop_clamp:2": (
        "a negative span (t1 < t0 after clamping to [0, 1]) happens only when the segment "
        "misses the box: the line misses it, or its part of the line [A, B] lies behind the "
        "point (B < 0) or beyond the light (A > 1); t0 is then reset to 0 and the midpoints p +"
        " t rel, t between span and 0, lie on the line outside [A, B], where the trilinear "
        "extinction is exactly 0 (0 outside the box): depth 0, T = 1 either way"
    ),
    "lab5_froxel:light_transmittance:drop_nan_to_num:2": (
        "t1 - t0 cannot be NaN: after the nan_to_num and clamps t0 is in [0, inf] and t1 in "
        "[-inf, 1], so inf - inf never occurs (t0 = +inf only with t1 <= 1); the nan_to_num is "
        "a no-op"
    ),
    "lab5_froxel:light_transmittance:const_float:0": (
        "the nan= value of a nan_to_num that never sees a NaN (see drop_nan_to_num:2)"
    ),
    "lab5_froxel:light_transmittance:const_int:12": (
        "where span == 0, t0 only moves the (finite) sample points; the optical depth is "
        "multiplied by span = 0, so T = exp(-0) = 1 whatever is sampled"
    ),
    "lab5_froxel:transmittance_volume:const_int:2": (
        "the fallback shape only feeds check_volume for an extinction that is not a 3-D tensor,"
        " rejected against (2, 1, 1) or (1, 1, 1) alike"
    ),
    "lab5_froxel:transmittance_volume:const_int:3": (
        "as const_int:2: the fallback (1, 2, 1) or (1, 1, 1) only serves to reject a non-3-D "
        "extinction"
    ),
    "lab5_froxel:transmittance_volume:narrow_dtype:0": (
        "the box's centre in float32 moves the sun's frame (origin stored in the LightVolume) "
        "by ~1e-7 of the centre's coordinates; the data are computed from and read in that "
        "stored frame (sample_light_volume uses volume.origin), so only the covered disc's rim "
        "moves by that much: the sphere still bounds the box to rounding"
    ),
    "lab5_froxel:transmittance_volume:narrow_dtype:1": (
        "the sun's direction in float32 moves the frame's origin by ~1e-7 of the radius; the "
        "data are computed from and read in the stored frame, so only the rim of the covered "
        "disc moves by that much"
    ),
    "lab5_froxel:transmittance_volume:narrow_dtype:2": (
        "the spot's position in float32 moves the frame's origin by ~1e-7 of the position (the "
        "test's frame check allows 1e-6); the data are computed from and read in that stored "
        "origin, and the transmittance toward a light moved by 1e-7 m changes by ~sigma_t 1e-7"
    ),
    "lab5_froxel:transmittance_volume:op_Sub_Add:1": (
        "near is 0.0 for both kinds (the sun's rays start on the frame's plane, a spot's at the"
        " light: 'depths 0 .. range'), so far + near == far - near"
    ),
    "lab5_froxel:transmittance_volume:const_float:4": (
        "the step for K == 1 multiplies nothing: one depth sample means no steps (mids and "
        "sigma are empty, their cumsum too), and the data are all 1 whatever the step"
    ),
    "lab5_froxel:sample_light_volume:cmp_LtE_Lt:0": (
        "a tie only: |a| == 1 exactly is the map's lateral rim (a point whose projection lands "
        "exactly on the frame's edge, decided by rounding in light_coords); inside it the "
        "lookup is clamped to the border texels, so the transmittance there equals the inside "
        "limit and differs from 1 only at that exact rim"
    ),
    "lab5_froxel:sample_light_volume:cmp_LtE_Lt:1": (
        "a tie only: |b| == 1 exactly is the map's lateral rim (a point whose projection lands "
        "exactly on the frame's edge, decided by rounding in light_coords); inside it the "
        "lookup is clamped to the border texels, so the transmittance there equals the inside "
        "limit and differs from 1 only at that exact rim"
    ),
    "lab5_froxel:sample_light_volume:const_int:10": (
        "the coordinates of points outside the map (0 or 1 in place of possibly inf) only keep "
        "sample_texture's lookup finite; its result there is discarded by the final "
        "where(inside, t, 1.0)"
    ),
    "lab5_froxel:apply_froxels:drop_clamp:0": (
        "sample_texture already clamps each coordinate to its border voxel centres: the slice "
        "coordinate z + 0.5 is clamped to [0.5, slices + 0.5] over the slices + 1 nodes, "
        "exactly what clamp(0, slices) does (depths before near read node 0, beyond far the "
        "last node)"
    ),
    "lab5_froxel:render_froxels:cmp_LtE_Lt:0": (
        "differs only for a dict with exactly the keys grid, source and extinction, which is "
        "not 'the previous report's \"history\"' (that one also holds 'frame', and is accepted "
        "both ways); the docstring: 'TypeError naming history unless it is None or the previous"
        " report's \"history\"'"
    ),
    "lab5_froxel:reproject:cmp_GtE_Gt:0": (
        "a tie only: a current froxel centre landing exactly on the previous volume's boundary "
        "(x, y or z exactly 0) after the world round trip (froxel_to_world, world_to_froxel) is"
        " decided by rounding; no geometry puts it there exactly"
    ),
    "lab5_froxel:reproject:cmp_LtE_Lt:0": (
        "a tie only: a current froxel centre landing exactly on the previous volume's far "
        "boundary (x = nx, y = ny or z = slices) after the world round trip, decided by "
        "rounding"
    ),
    "lab5_froxel:reproject:const_int:6": (
        "changes values only where valid is False; the docstring: 'where valid is False, values"
        " are finite but unspecified: they are not used' (coordinate 0 or 1 both read finite "
        "history)"
    ),
    "lab5_froxel:media_at:cmp_Gt_GtE:0": (
        "where the scattering weight is 0 every medium's w * mean(sigma_s) is 0 (densities and "
        "scattering are >= 0), so g_weighted is 0 too, and g_weighted / 1.0 = 0 is what the "
        "docstring's '0 where nothing scatters' asks"
    ),
    "lab5_froxel:media_at:cmp_Gt_GtE:1": (
        "the inner where only guards the division in the branch that the outer where(weight > "
        "0, ..., 0.0) discards: a 0 / 0 there is replaced by 0 either way (media_at promises "
        "values, not gradients)"
    ),
    "lab5_froxel:media_at:const_float:0": (
        "the placeholder divisor 1.0 or 1.1 is used only where the weight is 0, whose quotient "
        "the outer where replaces by 0"
    ),
    "lab5_froxel:henyey_greenstein:cmp_GtE_Gt:0": (
        "g = 0 picks the other denominator: (1 + g)^2 - 2 g (1 + cos) and "
        "(1 - g)^2 + 2 g (1 - cos) are both exactly 1 at g = 0, so the value is the same for "
        "every cos"
    ),
}
