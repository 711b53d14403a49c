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
            "media summed; g weighted by scattering",
            "test_media_at_sums_media",
            "g_not_scattering_weighted",
        ),
    ],
    "voxelize": [
        (
            "samples the froxel points at the given jitter",
            "test_voxelize_samples_froxel_points",
            "voxelize_ignores_jitter",
        ),
    ],
    "henyey_greenstein": [
        (
            "normalised HG phase, forward scattering for g > 0",
            "test_henyey_greenstein_normalised",
            "hg_wrong_sign",
        ),
        ("other g values (hidden)", "test_henyey_greenstein_hidden_g", None),
    ],
    "schlick_phase": [
        ("k clamped: finite for g near 1", "test_schlick_phase_clamped", "schlick_no_clamp"),
    ],
    "cull_lights": [
        (
            "a light is listed in every tile it touches",
            "test_cull_lights_keeps_every_touched_tile",
            "tile_list_drops_border_lights",
        ),
    ],
    "build_shadow_map": [
        (
            "agrees with exact shadow rays",
            "test_shadow_map_matches_exact_shadow_rays",
            None,
        ),
    ],
    "shadow_lookup": [
        (
            "agrees with exact shadow rays",
            "test_shadow_map_matches_exact_shadow_rays",
            None,
        ),
    ],
    "light_froxels": [
        (
            "in-scattered light of the closed form",
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
    ],
    "extinction_volume": [
        ("extinction sampled over the box", "test_transmittance_volume_sun", None),
    ],
    "light_transmittance": [
        (
            "optical depth integrated over length",
            "test_light_transmittance_point_light",
            "light_march_unit_steps",
        ),
    ],
    "transmittance_volume": [
        (
            "sun transmittance with step lengths",
            "test_transmittance_volume_sun",
            "shadow_volume_unit_steps",
        ),
        ("spot lights", "test_transmittance_volume_spot", None),
    ],
    "sample_light_volume": [
        ("trilinear lookup of the light volume", "test_transmittance_volume_sun", None),
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
        ("rejection of outside history", "test_reproject_rejects_history_outside", None),
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
        ("other volumes (hidden)", "test_temporal_blend_hidden_volume", None),
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
        ("other values (hidden)", "test_slice_integral_hidden_values", None),
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
        ("naive: the talk's leak", "test_integrate_froxels_naive_leaks", None),
    ],
    "apply_froxels": [
        (
            "trilinear lookup at the froxel centres",
            "test_apply_froxels_trilinear_lookup",
            "trilinear_half_froxel_off",
        ),
    ],
    "render_froxels": [
        (
            "material and lighting share the jitter",
            "test_render_froxels_temporal",
            "jitter_not_shared",
        ),
        (
            "homogeneous fog of the closed form",
            "test_render_froxels_homogeneous_closed_form",
            None,
        ),
        (
            "extremes and bad input",
            "test_render_froxels_extremes_and_bad_input",
            None,
        ),
    ],
}
