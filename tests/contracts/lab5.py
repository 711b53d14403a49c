"""Lab 5's contracts: each promise a student function's docstring makes, with the grader
test that fails when that promise alone is broken and, where one is shipped, the mutant
(``solutions/mutants/lab5.py``) that breaks just it.
``tests/meta/test_contracts.py`` keeps these lists, the graders and the mutants in step."""

CONTRACTS = {
    "slice_depths": [
        (
            "exponential slicing z_k = near (far / near)^(k / slices)",
            "test_slice_depths_exponential",
            "linear_slicing",
        ),
        (
            "z_0 = near and z_slices = far exactly",
            "test_slice_depths_exponential",
            "slice_ends_not_pinned",
        ),
        (
            "computed in float64, rounded once to dtype",
            "test_slice_depths_exponential",
            "slices_in_float32",
        ),
        (
            "ValueError / TypeError naming near, far, slices or dtype",
            "test_slice_depths_exponential",
            None,
        ),
    ],
    "depth_to_slice": [
        (
            "the exact inverse of slice_depths, float32 and float64, tiny near",
            "test_depth_to_slice_exact_inverse",
            None,
        ),
        (
            "-inf at 0, < 0 before near, > slices beyond far, +inf at +inf",
            "test_depth_to_slice_exact_inverse",
            None,
        ),
        (
            "other slicings (hidden)",
            "test_slice_depths_depth_to_slice_hidden_slicings",
            None,
        ),
    ],
    "froxel_to_world": [
        (
            "the point at slice depth z on the ray through pixel (x, y) * tile",
            "test_world_to_froxel_roundtrip",
            "froxel_xy_swapped",
        ),
    ],
    "world_to_froxel": [
        (
            "the inverse of froxel_to_world, row 0 at the top",
            "test_world_to_froxel_roundtrip",
            "froxel_y_up",
        ),
        (
            "view depth <= 0 (the eye's plane included) gives NaN",
            "test_world_to_froxel_roundtrip",
            "eye_plane_not_nan",
        ),
    ],
    "media_at": [
        (
            "every medium's coefficients times its density at the point, summed linearly",
            "test_media_at_sums_media",
            None,
        ),
        (
            "g is the scattering-weighted mean of the media's g (weight: mean scattering over RGB)",
            "test_media_at_sums_media",
            "g_not_scattering_weighted",
        ),
        (
            "g = 0 where nothing scatters (no media; a purely absorbing fog with g = 0.7)",
            "test_media_at_sums_media",
            "media_g_nan_without_scattering",
        ),
        (
            "height fog: density exp(-falloff (y - base))",
            "test_media_at_sums_media",
            None,
        ),
        (
            "fog volumes: 1 inside the rotated box or ellipsoid times the trilinear density "
            "texture, 0 outside",
            "test_media_at_sums_media",
            None,
        ),
        (
            "scattering (N, 3), extinction (N,), emissive (N, 3), g (N,) in the points' dtype"
            " (float32 and float64) and device",
            "test_media_at_sums_media",
            None,
        ),
        (
            "TypeError naming scene (a list); TypeError or ValueError naming points ((N, 2))",
            "test_media_at_sums_media",
            None,
        ),
    ],
    "voxelize": [
        (
            "media_at at froxel_sample_coords(grid, jitter): the tile's centre, the fraction "
            "jitter through the slice in view depth",
            "test_voxelize_samples_froxel_points",
            "voxelize_ignores_jitter",
        ),
        (
            "volumes indexed [k, j, i]: scattering/emissive (S, ny, nx, 3), extinction/g (S, "
            "ny, nx), of dtype on device",
            "test_voxelize_samples_froxel_points",
            None,
        ),
        (
            "defaults: jitter 0.5 and float32",
            "test_voxelize_samples_froxel_points",
            None,
        ),
        (
            "TypeError or ValueError naming jitter (1.0: not in [0, 1)); TypeError naming "
            "dtype (bfloat16)",
            "test_voxelize_samples_froxel_points",
            None,
        ),
    ],
    "henyey_greenstein": [
        (
            "(1 - g^2) / (4 pi (1 + g^2 - 2 g cos)^(3/2)), forward scattering for g > 0",
            "test_henyey_greenstein_normalised",
            "hg_wrong_sign",
        ),
        (
            "normalised over the sphere with mean cosine g, g in -0.99 .. 0.99",
            "test_henyey_greenstein_normalised",
            None,
        ),
        (
            "g a number or a tensor broadcasting with cos_theta",
            "test_henyey_greenstein_normalised",
            None,
        ),
        (
            "cos_theta past +-1 is clamped to [-1, 1]: finite, the value at +-1",
            "test_henyey_greenstein_normalised",
            None,
        ),
        (
            "finite and accurate at the peak as |g| -> 1 (no cancellation), float32 too",
            "test_henyey_greenstein_normalised",
            None,
        ),
        (
            "ValueError naming g (g = 1); TypeError naming cos_theta (int64)",
            "test_henyey_greenstein_normalised",
            None,
        ),
        (
            "other g values (hidden)",
            "test_henyey_greenstein_hidden_g",
            None,
        ),
    ],
    "schlick_phase": [
        (
            "k clamped to |k| <= SCHLICK_K_MAX: finite and normalised for g near 1",
            "test_schlick_phase_clamped",
            "schlick_no_clamp",
        ),
        (
            "(1 - k^2) / (4 pi (1 - k cos)^2) with k = 1.55 g - 0.55 g^3",
            "test_schlick_phase_clamped",
            None,
        ),
        (
            "normalised over the sphere and positive for every g; mean cosine near g for |g| "
            "<= 0.5",
            "test_schlick_phase_clamped",
            None,
        ),
        (
            "cos_theta clamped to [-1, 1] like henyey_greenstein's",
            "test_schlick_phase_clamped",
            None,
        ),
    ],
    "cull_lights": [
        (
            "a light is listed in every tile its sphere touches (distance >= -range, conservative)",
            "test_cull_lights_keeps_every_touched_tile",
            "tile_list_drops_border_lights",
        ),
        (
            "listed exactly where no tile plane has the sphere entirely outside, for spheres "
            "beside, above, below, behind the eye and beyond far",
            "test_cull_lights_keeps_every_touched_tile",
            None,
        ),
        (
            "side planes through each tile's own pixel edges, signed distances normalised by "
            "the normal's length",
            "test_cull_lights_keeps_every_touched_tile",
            None,
        ),
        (
            "a light beyond far + range reaches no tile; one before near - range neither",
            "test_cull_lights_keeps_every_touched_tile",
            None,
        ),
        (
            "rounding only near a tangent: 15 km from the origin, spheres 0.02 .. 0.3 mm from"
            " tangent decided right (not float32 positions)",
            "test_cull_lights_keeps_every_touched_tile",
            None,
        ),
        (
            "directional lights listed in every tile",
            "test_cull_lights_keeps_every_touched_tile",
            None,
        ),
        (
            "(L, ny, nx) bool on device",
            "test_cull_lights_keeps_every_touched_tile",
            None,
        ),
        (
            "TypeError naming lights for an item that is not a light",
            "test_cull_lights_keeps_every_touched_tile",
            None,
        ),
    ],
    "build_shadow_map": [
        (
            "an 'ortho' LightVolume with (R, R) data of dtype on device; extent = radius, w ="
            " -light.direction (unit)",
            "test_shadow_map_matches_exact_shadow_rays",
            None,
        ),
        (
            "the frame's plane lies beyond every occluder, not only the sphere (a slab 25 m "
            "above it, 470 m from the origin, still casts its shadow)",
            "test_shadow_map_matches_exact_shadow_rays",
            "shadow_plane_at_sphere",
        ),
        (
            "texel (i, j) traces one ray from its centre; data: depth of the first occluder "
            "along w, inf where none",
            "test_shadow_map_matches_exact_shadow_rays",
            "texel_corner_rays",
        ),
        (
            "agrees with exact shadow rays up to the texels' blur",
            "test_shadow_map_matches_exact_shadow_rays",
            None,
        ),
        (
            "resolution 1 works; ValueError naming resolution (0, 1.5) or radius (0)",
            "test_shadow_map_matches_exact_shadow_rays",
            None,
        ),
    ],
    "shadow_lookup": [
        (
            "0 where the nearest texel's occluder lies in front of the point by more than two"
            " texels (4 extent / R), 1 otherwise",
            "test_shadow_map_matches_exact_shadow_rays",
            "shadow_bias_one_texel",
        ),
        (
            "agrees with exact shadow rays (texels blur the edge; a map inside the shadow is "
            "dark to its border texels)",
            "test_shadow_map_matches_exact_shadow_rays",
            None,
        ),
        (
            "1 outside the map, a 1 x 1 map too (no index past the map)",
            "test_shadow_map_matches_exact_shadow_rays",
            None,
        ),
        (
            "(N,) in the points' dtype and device",
            "test_shadow_map_matches_exact_shadow_rays",
            None,
        ),
        (
            "TypeError naming shadow_map for a transmittance volume's (R, R, K) data",
            "test_shadow_map_matches_exact_shadow_rays",
            None,
        ),
    ],
    "light_froxels": [
        (
            "sigma_s (ambient + sum phase(v . l, g) E) at the voxelize sample points of this "
            "jitter (default 0.5)",
            "test_light_froxels_matches_closed_form",
            None,
        ),
        (
            "E: the sun's irradiance, I / d^2 cut at range for point lights, times the cone's"
            " smoothstep for spots",
            "test_light_froxels_matches_closed_form",
            None,
        ),
        (
            "the output in the V-buffer's dtype and device, (S, ny, nx, 3)",
            "test_light_froxels_matches_closed_form",
            None,
        ),
        (
            "only froxels with sigma_s > 0 in tiles with media are lit; emission added everywhere",
            "test_light_froxels_matches_closed_form",
            None,
        ),
        (
            "a single scattering froxel is lit by every light listed for it",
            "test_light_froxels_matches_closed_form",
            None,
        ),
        (
            "report: froxels_lit, tiles_with_media (emission counts as medium), light_tiles "
            "(the sun: the tiles with media), light_evaluations",
            "test_light_froxels_matches_closed_form",
            None,
        ),
        (
            "nothing to light (emission only): light_tiles zeros, no volume",
            "test_light_froxels_matches_closed_form",
            None,
        ),
        (
            "no volume without volumetric_shadows: volume_bounds None, volume_resolution 0",
            "test_light_froxels_matches_closed_form",
            None,
        ),
        (
            "finite with a point light on a froxel's sample point (d >= MIN_LIGHT_DISTANCE)",
            "test_light_froxels_matches_closed_form",
            None,
        ),
        (
            "the sun's shadow map over the bounding sphere of frustum_bounds(grid), 40 m from"
            " the origin",
            "test_light_froxels_matches_closed_form",
            None,
        ),
        (
            "point lights attenuated by the medium",
            "test_render_froxels_point_light_in_fog_against_quadrature",
            "point_lights_unattenuated",
        ),
        (
            "the extinction volume spans the media, not the frustum",
            "test_render_froxels_sun_in_fog_box_defaults_against_quadrature",
            "volumes_over_the_frustum",
        ),
        (
            "shadow map at shadow_resolution (default 128); one extinction volume over "
            "volume_bounds at volume_resolution (reported); sun and spots through "
            "transmittance_volume with 4 resolution depth samples and sample_light_volume; "
            "point lights through light_transmittance with light_steps; each term times its "
            "transmittance",
            "test_light_froxels_shadows_follow_the_recipe",
            "light_volume_default_depth_samples",
        ),
        (
            "errors naming phase, vbuffer (incomplete; only its scattering) and light_steps "
            "(0, 2.0); extra V-buffer keys accepted",
            "test_light_froxels_matches_closed_form",
            None,
        ),
    ],
    "extinction_volume": [
        (
            "media_at at the voxel centres lo + (index + 0.5) / R (hi - lo), x the first axis"
            " (height fog and fog volumes)",
            "test_transmittance_volume_sun",
            None,
        ),
        (
            "constant fog gives its extinction exactly",
            "test_transmittance_volume_sun",
            None,
        ),
        (
            "(R, R, R) of dtype on device",
            "test_transmittance_volume_sun",
            None,
        ),
        (
            "resolution 2 is the smallest (1/4, 3/4 centres); ValueError naming resolution "
            "(1, 2.0) or hi (lo = hi on an axis, hi < lo)",
            "test_transmittance_volume_sun",
            None,
        ),
    ],
    "light_transmittance": [
        (
            "optical depth integrated over length",
            "test_light_transmittance_point_light",
            "light_march_unit_steps",
        ),
        (
            "only the part of the segment inside the box is marched (slab test): exp(-sigma "
            "length inside)",
            "test_light_transmittance_point_light",
            None,
        ),
        (
            "midpoint rule on the trilinear extinction (voxel centres): exact for a medium "
            "linear in space, 1 and 3 steps",
            "test_light_transmittance_point_light",
            None,
        ),
        (
            "1 on the light (zero length) and where the segment misses the box, no NaN",
            "test_light_transmittance_point_light",
            None,
        ),
        (
            "ValueError naming steps (0); TypeError or ValueError naming extinction (2-D)",
            "test_light_transmittance_point_light",
            None,
        ),
    ],
    "transmittance_volume": [
        (
            "sun transmittance with step lengths",
            "test_transmittance_volume_sun",
            "shadow_volume_unit_steps",
        ),
        (
            "spot lights: a 'persp' volume, exp(-sigma length toward the light) in the cone",
            "test_transmittance_volume_spot",
            None,
        ),
        (
            "sun frame: w = -direction, extent = the radius of the box's bounding sphere, far"
            " - near its diameter, the sphere's centre on the axis at depth near + radius",
            "test_transmittance_volume_spot",
            None,
        ),
        (
            "spot frame: origin at the light, w its direction, extent tan(outer_deg), depths "
            "0 .. range",
            "test_transmittance_volume_spot",
            None,
        ),
        (
            "data[i, j, k] = exp(-sum_{m<k} sigma_t(mid_m) step): texel centres, K - 1 equal "
            "midpoint steps, trilinear extinction 0 outside",
            "test_transmittance_volume_spot",
            None,
        ),
        (
            "defaults: resolution 32, K = 2 resolution; steps = 1 gives one depth sample, all"
            " 1; resolution 1 traces the sphere's centre",
            "test_transmittance_volume_sun",
            None,
        ),
        (
            "no NaN in media too dense for float32's exp: T = 0",
            "test_transmittance_volume_sun",
            None,
        ),
        (
            "TypeError naming light (a point light); ValueError naming resolution (0); "
            "TypeError or ValueError naming extinction (2-D)",
            "test_transmittance_volume_sun",
            None,
        ),
    ],
    "sample_light_volume": [
        (
            "trilinear lookup of the light volume",
            "test_transmittance_volume_sun",
            None,
        ),
        (
            "trilinear in the texels and the depth samples (sample k at near + k (far - near)"
            " / (K - 1)), clamped at the ends, ortho and persp",
            "test_transmittance_volume_spot",
            None,
        ),
        (
            "1 outside the map laterally and behind a spot light",
            "test_transmittance_volume_spot",
            None,
        ),
        (
            "TypeError naming volume for a shadow map's (R, R) data",
            "test_transmittance_volume_spot",
            None,
        ),
    ],
    "reproject": [
        (
            "history sampled at the previous froxel centres (slice offset)",
            "test_reproject_follows_the_camera",
            "reproject_no_slice_offset",
        ),
        (
            "history from outside the previous frustum is invalid",
            "test_reproject_follows_the_camera",
            "history_never_rejected",
        ),
        (
            "rejection of outside history",
            "test_reproject_rejects_history_outside",
            None,
        ),
    ],
    "temporal_blend": [
        (
            "history + alpha (current - history) where valid, current elsewhere",
            "test_temporal_blend_exponential",
            "blend_alpha_on_history",
        ),
        (
            "alpha in (0, 1]: 1 allowed, 0 raises ValueError",
            "test_temporal_blend_exponential",
            "blend_alpha_one_rejected",
        ),
        (
            "other volumes (hidden)",
            "test_temporal_blend_hidden_volume",
            None,
        ),
    ],
    "slice_integral": [
        (
            "S D phi(sigma_t D), stable as sigma_t -> 0 and huge",
            "test_slice_integral_limits",
            "slice_integral_unstable",
        ),
        (
            "zero length or no medium is (0, 1) even with an inf factor",
            "test_slice_integral_limits",
            "zero_length_inf_extinction_nan",
        ),
        (
            "a negative extinction or length raises ValueError naming it",
            "test_slice_integral_limits",
            "negative_length_accepted",
        ),
        (
            "other values (hidden)",
            "test_slice_integral_hidden_values",
            None,
        ),
    ],
    "integrate_froxels": [
        (
            "energy: L += T * slice_integral, then T *= e^(-sigma_t D)",
            "test_integrate_froxels_homogeneous_and_energy",
            "transmittance_before_integral",
        ),
        (
            "energy method is the default (not the naive S D)",
            "test_integrate_froxels_homogeneous_and_energy",
            "naive_integration",
        ),
        (
            "slice k is (z_{k+1} - z_k) |dir| long along the ray",
            "test_integrate_froxels_homogeneous_and_energy",
            "slice_length_along_axis",
        ),
        (
            "the ray goes through the tile centre",
            "test_integrate_froxels_homogeneous_and_energy",
            "stretch_at_tile_corner",
        ),
        (
            "transmittance to the far boundary of each slice",
            "test_integrate_froxels_homogeneous_and_energy",
            "transmittance_in_front_of_slice",
        ),
        (
            "naive: the talk's leak",
            "test_integrate_froxels_naive_leaks",
            None,
        ),
    ],
    "apply_froxels": [
        (
            "trilinear lookup at the froxel centres",
            "test_apply_froxels_trilinear_lookup",
            "trilinear_half_froxel_off",
        ),
        (
            "out = opaque T + L, nodes at z = 0 .. slices with (L, T) = (0, 1) at near; tile "
            "centres across the screen",
            "test_apply_froxels_trilinear_lookup",
            None,
        ),
        (
            "depth_to_slice clamped to [0, slices]: beyond far and the sky read the last "
            "slice, before near no fog",
            "test_apply_froxels_trilinear_lookup",
            None,
        ),
        (
            "written into out when given (a NaN-poisoned out comes back clean)",
            "test_apply_froxels_trilinear_lookup",
            None,
        ),
        (
            "float32 as well as float64",
            "test_apply_froxels_trilinear_lookup",
            None,
        ),
        (
            "errors naming depth_image (wrong size, NaN, negative), opaque_image "
            "(float32 with float64 depths), inscatter, transmittance and out (shapes)",
            "test_apply_froxels_trilinear_lookup",
            None,
        ),
    ],
    "render_froxels": [
        (
            "material and lighting share the jitter frame_jitter(frame) with temporal",
            "test_render_froxels_temporal",
            "jitter_not_shared",
        ),
        (
            "the stages voxelize -> light_froxels -> integrate_froxels -> apply_froxels (the "
            "wrong one named)",
            "test_render_froxels_whole_frame_names_the_wrong_step",
            None,
        ),
        (
            "homogeneous fog of the closed form",
            "test_render_froxels_homogeneous_closed_form",
            None,
        ),
        (
            "height fog against the brute-force reference",
            "test_render_froxels_height_fog_against_reference",
            None,
        ),
        (
            "a fog box lit by a point light against the reference",
            "test_render_froxels_fog_box_point_light_against_reference",
            None,
        ),
        (
            "a point light inside fog against quadrature",
            "test_render_froxels_point_light_in_fog_against_quadrature",
            None,
        ),
        (
            "defaults (scene_grid's tile and depths): the sun in a fog box, a fog box in "
            "view, within 2% of the converged reference",
            "test_render_froxels_defaults_against_converged_reference",
            None,
        ),
        (
            "the sun in a fog box with the default grid against quadrature",
            "test_render_froxels_sun_in_fog_box_defaults_against_quadrature",
            None,
        ),
        (
            "a fog box in view with the default grid against quadrature",
            "test_render_froxels_fog_box_in_view_defaults_against_quadrature",
            None,
        ),
        (
            "opaque shadows into fog against the reference",
            "test_render_froxels_shadow_into_fog_against_reference",
            None,
        ),
        (
            "the frame's energy independent of the slice count",
            "test_render_froxels_energy_independent_of_slices",
            None,
        ),
        (
            "without media: a copy of the opaque image, a report of no work (zeros, no "
            "volume); lights culled from tiles they cannot reach",
            "test_render_froxels_models_only_what_is_needed",
            None,
        ),
        (
            "shadow_resolution defaults to 128; history_valid a fraction of whole froxels; "
            "ValueError naming frame (-1); TypeError naming history (a dict without its "
            "volumes)",
            "test_render_froxels_models_only_what_is_needed",
            None,
        ),
        (
            "temporal: history reprojected and blended, kept for a static camera, dropped "
            "after turning around",
            "test_render_froxels_temporal",
            None,
        ),
        (
            "extremes and bad input (sigma_t = 1e6, near 1e-4, float16, bad settings, inf colours)",
            "test_render_froxels_extremes_and_bad_input",
            None,
        ),
    ],
}
