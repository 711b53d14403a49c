"""Lab 3's contracts: each promise a student function's docstring makes (and the package
docstring's conventions), with the grader test that fails when that promise alone is broken
and, where one is shipped, the mutant (``solutions/mutants/lab3.py``) that breaks just it.
``tests/meta/test_contracts.py`` keeps these lists, the graders and the mutants in step."""

SHADE = "test_shade_direct_matches_reference"


def renderer(name: str, extremes: str) -> list:
    """What every renderer promises (package docstring), with its tests: ``extremes`` is
    the test that feeds it bad rays and bad arguments."""
    return [
        ("the image of render_reference up to rounding", f"test_{name}_matches_reference", None),
        ("NaN/inf rays and zero directions return the background", extremes, None),
        (
            "ValueError / TypeError naming scene, origins, directions, trace or max_depth",
            extremes,
            None,
        ),
    ]


CONTRACTS = {
    "offset_origins": [
        (
            "p + n offset max(1, |p|_inf): lifted along the normal",
            "test_offset_origins",
            "no_normal_offset",
        ),
        (
            "the offset grows with the coordinates' magnitude",
            "test_offset_origins",
            "offset_not_scaled_with_magnitude",
        ),
        ("the infinity norm |p|_inf, not |p|_2", "test_offset_origins", "offset_euclidean_scale"),
        (
            "max(1, .): never below the offset itself near the origin",
            "test_offset_origins",
            "offset_unclamped_scale",
        ),
        (
            "offset_scale(dtype): 1e-4 in float32, ~1.9e-13 in float64",
            "test_offset_origins",
            "offset_fixed_float32_epsilon",
        ),
        (
            "ValueError / TypeError naming points or normals; TypeError for half precision",
            "test_offset_origins",
            None,
        ),
    ],
    "reflect": [
        (
            "r = d - 2 (d . n) n: about the surface's plane",
            "test_reflect",
            "reflect_through_the_normal",
        ),
        ("unit result, independent of the side n faces", "test_reflect", None),
    ],
    "surface_at": [
        (
            "normals flipped to face the ray (n . d <= 0)",
            "test_surface_at",
            "normal_faces_away_from_the_ray",
        ),
        ("misses: points and normals 0, material -1, never NaN", "test_surface_at", None),
    ],
    "shade_direct": [
        (
            "a point light's shadow ray stops short of the light",
            "test_shade_direct_light_on_and_above_a_surface",
            "shadow_ray_reaches_the_light",
        ),
        ("the shadow ray ends at the light, not beyond it", SHADE, "shadow_ray_past_the_light"),
        ("shadow rays only toward lights with n . l > 0", SHADE, "shadow_rays_below_the_horizon"),
        (
            "n . l == 0 exactly (a light in the surface's plane): no shadow ray",
            "test_shade_direct_light_on_and_above_a_surface",
            "shadow_rays_on_the_horizon",
        ),
        ("a single point is shaded like in a batch; no point: 0 shadow rays", SHADE, None),
        ("the lobe's (s + 8) / (8 pi) normalisation", SHADE, "specular_not_normalised"),
        ("a point light's E = I / dist^2", SHADE, "point_light_without_falloff"),
        ("h = normalize(l + v) with v = -d", SHADE, "half_vector_of_d"),
        ("ambient * kd", SHADE, "ambient_from_specular"),
        ("Blinn-Phong: max(0, n . h)^s", SHADE, "phong_instead_of_blinn"),
        ("returns the number of shadow rays traced", SHADE, "shadow_count_only_unblocked"),
        ("ValueError / TypeError naming material, trace or points", SHADE, None),
    ],
    "render_whitted": renderer("render_whitted", "test_render_whitted_extremes")
    + [
        (
            "bounces 0 .. max_depth",
            "test_render_whitted_matches_reference",
            "whitted_depth_off_by_one",
        ),
        (
            "throughput *= kr at every mirror",
            "test_render_whitted_mirror_corridor",
            "whitted_throughput_not_multiplied",
        ),
        (
            "reflected rays start at offset_origins(p, n)",
            "test_render_whitted_matches_reference",
            "whitted_reflected_ray_not_offset",
        ),
    ],
    "render_wavefront": renderer("render_wavefront", "test_render_wavefront_extremes")
    + [
        (
            "misses add throughput * background before they leave the queue",
            "test_render_wavefront_matches_reference",
            "wavefront_drops_escaped_rays",
        ),
        (
            "compaction by the mirror mask, applied to every per-ray tensor",
            "test_render_wavefront_matches_reference",
            "wavefront_compacts_by_slicing",
        ),
        (
            "sorting moves the pixel indices with the rays",
            "test_render_wavefront_matches_reference",
            "wavefront_sort_forgets_pixels",
        ),
        (
            "bounces 0 .. max_depth",
            "test_render_wavefront_matches_reference",
            "wavefront_depth_limit_off_by_one",
        ),
        (
            "closest_rays is the queue's length when traced",
            "test_render_wavefront_stats",
            "wavefront_counts_after_compaction",
        ),
        (
            "material_runs: runs in the queue's order, distinct materials when sorted",
            "test_render_wavefront_material_runs_in_queue_order",
            "wavefront_runs_are_distinct_materials",
        ),
        (
            "a bounce whose rays all miss: hits 0, material_runs 0",
            "test_render_wavefront_extremes",
            None,
        ),
        ("TypeError naming sort_by_material unless a bool", "test_render_wavefront_stats", None),
    ],
    "render_uber": renderer("render_uber", "test_render_uber_matches_reference")
    + [
        (
            "normals face the ray in the step functions too",
            "test_render_uber_matches_reference",
            "uber_normal_not_flipped",
        ),
        (
            "step functions without data-dependent shapes (one graph under torch.compile)",
            "test_render_uber_compiles",
            "uber_step_compacts",
        ),
    ],
    "render_persistent": renderer("render_persistent", "test_render_persistent_stats")
    + [
        (
            "items waiting for a slot stay in the queue",
            "test_render_persistent_matches_reference",
            "persistent_loses_queued_work",
        ),
        (
            "a reflection only while depth < max_depth",
            "test_render_persistent_matches_reference",
            "persistent_depth_off_by_one",
        ),
        (
            "idle_fraction = 1 - sum(active_lanes) / (pool_size steps)",
            "test_render_persistent_stats",
            "persistent_idle_is_busy",
        ),
        (
            "work_generated counts the N primary rays and every reflection",
            "test_render_persistent_stats",
            "persistent_forgets_primaries",
        ),
    ],
    "layout_indexed": [
        (
            "faces int32; bytes per triangle of vertices and indices",
            "test_layout_memory",
            "indexed_faces_int64",
        ),
    ],
    "layout_float4": [
        (
            "w holds order[k] bit for bit (index_as_float)",
            "test_layout_memory",
            "float4_index_by_value",
        ),
        ("slot k holds triangle order[k]", "test_intersect_layout", None),
    ],
    "layout_woop": [
        (
            "translation -F^-1 v0: v0 goes to the origin",
            "test_layout_memory",
            "woop_translation_sign",
        ),
        (
            "a degenerate triangle's rows are NaN",
            "test_layout_memory",
            "woop_layout_degenerate_zero",
        ),
    ],
    "intersect_layout": [
        (
            "float4: the original index read from w",
            "test_intersect_layout",
            "float4_index_by_position",
        ),
        (
            "exact ties go to the lowest original index across tiles and slot orders",
            "test_intersect_layout_exact_ties_and_closed_interval",
            "layout_ties_by_tile",
        ),
        (
            "the interval [t_min, t_max] is closed",
            "test_intersect_layout_exact_ties_and_closed_interval",
            "layout_open_t_max",
        ),
        (
            "a hit iff u, v >= 0 and u + v <= 1: edges and corners included",
            "test_intersect_layout",
            "layout_open_triangle",
        ),
        (
            "u, v of the kept hit (0 for misses)",
            "test_intersect_layout",
            "layout_forgets_uv",
        ),
        (
            "a farther hit never replaces a nearer one, whatever its index or tile",
            "test_intersect_layout",
            None,
        ),
        ("NaN origins and zero directions miss", "test_intersect_layout", None),
        ("ValueError / TypeError naming layout", "test_intersect_layout", None),
    ],
}
