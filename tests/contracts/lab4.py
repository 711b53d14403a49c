"""Lab 4's contracts: each promise a student function's docstring makes
(``solutions/lab4_march/``), with the grader test that fails when that promise alone is
broken and, where one is shipped, the mutant (``solutions/mutants/lab4.py``) that breaks
just it. ``tests/meta/test_contracts.py`` keeps these lists, the graders and the mutants in
step."""

CONTRACTS = {
    "ray_box_interval": [
        (
            "the slab interval of the ray parameter (t of o + t d, not a world distance)",
            "test_ray_box_interval",
            "fresh_box_world_distance",
        ),
        (
            "clipped to t >= 0: a ray starting inside has t_near = 0",
            "test_ray_box_interval",
            "fresh_box_no_clip_at_zero",
        ),
        (
            "the box is closed: hit = t_near <= t_far (edges, flat boxes)",
            "test_ray_box_interval_closed_box",
            "fresh_box_open_interval",
        ),
        (
            "a ray on a slab plane with d = 0 there: NaN slab ignored (fmax/fmin)",
            "test_ray_box_interval",
            "box_nan_poisons_slabs",
        ),
        ("NaN/inf rays and d = 0 miss with t_near = t_far = 0", "test_ray_box_interval", None),
    ],
    "sample_grid": [
        (
            "x indexes the grid's first axis",
            "test_sample_grid_trilinear",
            "trilinear_axes_reversed",
        ),
        (
            "cell-centred values (align_corners=False), clamped at the border",
            "test_sample_grid_trilinear",
            "fresh_grid_node_centred",
        ),
        ("NaN coordinates give 0", "test_sample_grid_trilinear", "fresh_grid_nan_not_zero"),
        ("NaN coordinates give 0 in every channel", "test_sample_grid_trilinear", None),
    ],
    "march_box": [
        (
            "front to back: L += T q w, then T *= T_step",
            "test_march_box_homogeneous_and_layered",
            "march_back_to_front",
        ),
        (
            "each sample is absorbed once, by w, not again by its own T_step",
            "test_march_box_homogeneous_and_layered",
            "march_transmittance_first",
        ),
        (
            "the step's world length is ds = |d| dt",
            "test_march_box_homogeneous_and_layered",
            "fresh_march_ds_not_world",
        ),
        (
            "grids sampled at box coordinates from o - box_min, not absolute points",
            "test_march_box_extremes",
            "march_absolute_points",
        ),
        (
            "jitter: one offset per ray, the same for all its steps, seeded on the CPU",
            "test_march_box_early_termination_and_jitter",
            "fresh_march_jitter_per_step",
        ),
        (
            "a ray stops only once T < min_transmittance",
            "test_march_box_stops_only_below_threshold",
            "fresh_march_stop_at_equal",
        ),
        (
            "misses: radiance 0, transmittance 1, samples 0",
            "test_march_box_early_termination_and_jitter",
            None,
        ),
        (
            "grids at box coordinates: each axis divided by its own side",
            "test_march_box_extremes",
            None,
        ),
        (
            "a flat box: grids read without dividing by its size 0",
            "test_march_box_extremes",
            "fresh_march_flat_axis_nan",
        ),
        ("the default is steps=64", "test_march_box_extremes", None),
    ],
    "segment_integral": [
        (
            '"exact": weight (1 - e^{-sigma D}) / sigma',
            "test_segment_integral_values_and_limits",
            "segment_riemann_called_exact",
        ),
        (
            "sigma = 0 is vacuum: weight D, not 0 / 0",
            "test_segment_integral_values_and_limits",
            "segment_sigma_zero_nan",
        ),
        (
            "no cancellation for small sigma D (expm1)",
            "test_segment_integral_values_and_limits",
            "segment_cancelling_form",
        ),
        (
            "inf * 0 is no step / no medium, not NaN",
            "test_segment_integral_values_and_limits",
            "fresh_segment_inf_times_zero",
        ),
        ('"riemann" is first order', "test_segment_integral_convergence_order", None),
        (
            '"exact" conserves energy: L <= c for q = c sigma',
            "test_segment_integral_conserves_energy",
            None,
        ),
    ],
    "henyey_greenstein": [
        ("g > 0 scatters forward (sign of cos)", "test_henyey_greenstein", "hg_wrong_sign"),
        ("normalised over the sphere: 1 / (4 pi)", "test_henyey_greenstein", "hg_missing_4pi"),
        ("cos outside [-1, 1] is clamped", "test_henyey_greenstein", "hg_cos_unclamped"),
        (
            "the denominator as a sum of non-negative terms for both signs of g",
            "test_henyey_greenstein",
            "fresh_hg_one_denominator",
        ),
    ],
    "shadow_transmittance": [
        (
            "midpoint rule: exact for a homogeneous medium with one step",
            "test_shadow_transmittance",
            "shadow_left_endpoint",
        ),
        (
            "only the part of the light ray inside the box, from t_near",
            "test_shadow_transmittance_only_inside_box",
            "fresh_shadow_from_point_not_box",
        ),
        ("misses, NaN points and steps = 0 give 1", "test_shadow_transmittance", None),
        (
            "grids sampled at (p - box_min) / size; the default is steps=16",
            "test_shadow_transmittance_grid_in_offset_box",
            None,
        ),
        (
            "a flat box: grids read without dividing by its size 0",
            "test_shadow_transmittance_grid_in_offset_box",
            "fresh_shadow_flat_axis_nan",
        ),
    ],
    "march_single_scatter": [
        (
            "S = albedo sigma p E T_light, with the shadow march",
            "test_single_scatter_matches_closed_form",
            "scatter_no_shadow",
        ),
        (
            "an oblique light agrees with quadrature",
            "test_single_scatter_oblique_light_against_quadrature",
            None,
        ),
        (
            "the source reads grids at (x - box_min) / size, in a box away from the origin",
            "test_single_scatter_matches_closed_form",
            "fresh_scatter_grid_absolute_points",
        ),
        (
            "a flat box: grids read without dividing by its size 0",
            "test_single_scatter_matches_closed_form",
            None,
        ),
        (
            "albedo in [0, 1]: both ends allowed, 1 + 1e-12 refused",
            "test_single_scatter_matches_closed_form",
            None,
        ),
        (
            "defaults: light_irradiance=1, g=0, steps=64, shadow_steps=16",
            "test_single_scatter_matches_closed_form",
            None,
        ),
    ],
    "build_occupancy": [
        (
            "True where any voxel of the macro cell has medium or emission",
            "test_voxel_walk_empty_space_skipping",
            "skip_non_empty",
        ),
        ("the default is macro_cell=1", "test_voxel_walk_empty_space_skipping", None),
    ],
    "voxel_walk": [
        (
            "the plane ahead is index + 1 or index, by the direction's sign",
            "test_voxel_walk_optical_depth_exact",
            "dda_off_by_one",
        ),
        (
            "a zero direction component never gives the exit axis",
            "test_voxel_walk_optical_depth_exact",
            "dda_no_axis_guard",
        ),
        ("emission, channels and extremes", "test_voxel_walk_emission_and_extremes", None),
        (
            "samples = steps without occupancy: nothing is read after a ray leaves",
            "test_voxel_walk_optical_depth_exact",
            "fresh_walk_samples_after_exit",
        ),
        (
            "a flat box has voxels of no volume: optical depth 0, no steps",
            "test_voxel_walk_emission_and_extremes",
            None,
        ),
        ("the default is macro_cell=1", "test_voxel_walk_empty_space_skipping", None),
    ],
    "sphere_trace": [
        (
            "running out of steps is UNSURE, never a hit",
            "test_sphere_trace_grazing_and_inside",
            "trace_unsure_as_hit",
        ),
        (
            "a ray starting inside steps by |f|",
            "test_sphere_trace_grazing_and_inside",
            "trace_no_inside_abs",
        ),
        (
            "hit test relative to the distance: |f| <= epsilon t |d|",
            "test_sphere_trace_relative_epsilon",
            "trace_absolute_epsilon",
        ),
        (
            "the tolerance contains |d|: directions of any length find the same points",
            "test_sphere_trace_direction_length",
            "fresh_trace_tolerance_without_d",
        ),
        (
            "over-relaxation falls back when the spheres do not overlap",
            "test_sphere_trace_over_relaxation",
            "trace_no_sor_fallback",
        ),
        ("hits agree with the analytic surfaces", "test_sphere_trace_matches_analytic", None),
        (
            "f = 0 at t = 0 is a hit (<=), at the first evaluation even over-relaxed",
            "test_sphere_trace_exact_boundaries",
            None,
        ),
        (
            "zero directions and NaN rays miss, with no hit test",
            "test_sphere_trace_exact_boundaries",
            "fresh_trace_zero_direction_valid",
        ),
        (
            "t = t_max is not past t_max: a HIT there, UNSURE when out of steps",
            "test_sphere_trace_exact_boundaries",
            None,
        ),
        (
            "a ray past t_max misses even where it lands on a surface",
            "test_sphere_trace_exact_boundaries",
            "fresh_trace_hit_past_t_max",
        ),
        (
            "an sdf returning another shape raises ValueError naming sdf",
            "test_sphere_trace_exact_boundaries",
            None,
        ),
        (
            "the step back is divided by |d|, then omega = 1",
            "test_sphere_trace_exact_boundaries",
            None,
        ),
        (
            "defaults: t_max=100, max_steps=128, epsilon=1e-4, relaxation=1",
            "test_sphere_trace_exact_boundaries",
            None,
        ),
    ],
}
