"""Lab 6's contracts: each promise a student function's docstring makes, with the grader
test that fails when that promise alone is broken and, where one is shipped, the mutant
(``solutions/mutants/lab6.py``) that breaks just it.
``tests/meta/test_contracts.py`` keeps these lists, the graders and the mutants in step."""

CONTRACTS = {
    "to_clip_space": [
        (
            "mvp @ (x, y, z, 1) computed in float64 inside, returned in the input dtype",
            "test_to_clip_space_and_to_screen_pixel_convention",
            "clip_space_in_float32",
        ),
    ],
    "clip_triangles": [
        (
            "triangles crossing the near plane are clipped: every output corner has z + w >= 0",
            "test_clip_triangles_near_plane",
            "no_near_plane_clipping",
        ),
        (
            "d = z + w >= 0 is inside: a corner on the near plane keeps the triangle whole",
            "test_clip_triangles_corner_on_near_plane",
            "near_plane_open",
        ),
        (
            "weights rebuild each output corner; source increasing",
            "test_clip_triangles_near_plane",
            None,
        ),
        (
            "trivial rejection by the seven homogeneous half-spaces, behind the camera too",
            "test_clip_triangles_ground_plane_behind_camera",
            None,
        ),
        (
            "every output corner has w > 0 (degenerate clip coordinates dropped)",
            "test_clip_triangles_w_at_or_behind_the_eye",
            None,
        ),
    ],
    "to_screen": [
        (
            "row 0 at the top: NDC y = 1 maps to screen y = 0",
            "test_to_clip_space_and_to_screen_pixel_convention",
            "viewport_y_not_flipped",
        ),
        (
            "NDC [-1, 1] maps to [0, width]: x = 1 is the image's right edge",
            "test_to_clip_space_and_to_screen_pixel_convention",
            "viewport_width_minus_one",
        ),
    ],
    "edge_functions": [
        (
            "the same value for an edge whatever its direction (shared edges agree exactly)",
            "test_coverage_fill_rule_exactly_once",
            None,
        ),
    ],
    "bounding_boxes": [
        (
            "half-open boxes clamped to [0, size]: the last row and column included",
            "test_bounding_boxes",
            "bbox_misses_last_column",
        ),
        (
            "end = floor(max - 0.5) + 1: a centre exactly on the max edge is included",
            "test_bounding_boxes",
            "bbox_end_ceil",
        ),
        (
            "off screen, NaN or inf: an empty box",
            "test_bounding_boxes",
            None,
        ),
        (
            "only x and y are read: (K, 3, 4) screens with w != 1, NaN z_ndc or 1/w",
            "test_bounding_boxes",
            None,
        ),
        (
            "extents ending exactly on pixel centres, beyond int64 (1e30), several sizes",
            "test_bounding_boxes",
            None,
        ),
    ],
    "coverage": [
        (
            "top and left edges own their pixel centres, the others do not",
            "test_coverage_fill_rule_exactly_once",
            "bottom_right_rule",
        ),
        (
            "the top-left rule: a centre on a shared edge covered exactly once",
            "test_coverage_fill_rule_exactly_once",
            "no_fill_rule",
        ),
        (
            "samples at pixel centres (col + 0.5, row + 0.5)",
            "test_coverage_fill_rule_exactly_once",
            "pixel_corners_not_centres",
        ),
        (
            "cull_backfaces drops the back faces (screen area <= 0), keeps the front ones",
            "test_coverage_culling_degenerate_subpixel",
            "cull_front_faces",
        ),
        (
            "zero-area and NaN/inf triangles cover nothing",
            "test_coverage_culling_degenerate_subpixel",
            None,
        ),
        (
            "a triangle of area exactly +-1/2 pixel covers its centre (culled when back-facing)",
            "test_coverage_culling_degenerate_subpixel",
            None,
        ),
        (
            "only x and y are read: NaN z_ndc and infinite 1/w change nothing",
            "test_coverage_culling_degenerate_subpixel",
            None,
        ),
    ],
    "pack_depth_id": [
        (
            "depth in the high bits, id in the low 32: keys order by depth, then id",
            "test_pack_depth_id",
            "key_id_in_high_bits",
        ),
        (
            "-0.0 and negative depths pack as +0.0",
            "test_pack_depth_id",
            "key_negative_zero",
        ),
        (
            "ids in [0, 2**32): the largest, 2**32 - 1, is accepted",
            "test_pack_depth_id",
            "id_bound_off_by_one",
        ),
        (
            "24 bits: round(depth * (2**24 - 1)) to nearest",
            "test_pack_depth_id",
            "depth24_truncated",
        ),
        (
            "24 bits: the product computed in float64",
            "test_pack_depth_id",
            "depth24_in_float32",
        ),
    ],
    "triangle_ids": [
        (
            "the low 32 bits of a key, -1 for EMPTY",
            "test_pack_depth_id",
            "empty_pixel_not_minus_one",
        ),
    ],
    "depth_test": [
        (
            "an atomic minimum: the nearest key wins whatever the fragment order",
            "test_depth_test_atomic_min_order_independent",
            "depth_test_race",
        ),
        (
            "ValueError for a pixel index outside [0, len(out))",
            "test_depth_test_atomic_min_order_independent",
            "pixel_bound_off_by_one",
        ),
        (
            "ValueError naming pixel for a negative index; pixels need not start at 0",
            "test_depth_test_atomic_min_order_independent",
            None,
        ),
    ],
    "rasterize": [
        (
            "the visibility buffer of the nearest fragment per pixel, chunked or not",
            "test_rasterize_visibility_buffer",
            None,
        ),
        (
            "chunks: consecutive, at most budget // BYTES_PER_FRAGMENT box pixels (or one "
            "triangle), as many as fit; the default budget is 2**28; a budget of 1 is valid",
            "test_rasterize_visibility_buffer",
            None,
        ),
    ],
    "perspective_correct": [
        (
            "bary * (1/w) renormalised to sum 1",
            "test_perspective_correct_formula",
            "screen_space_interpolation",
        ),
        (
            "the normaliser is the sum of bary * (1/w)",
            "test_perspective_correct_formula",
            "perspective_wrong_normaliser",
        ),
    ],
    "resolve_pixels": [
        (
            "object-space barycentrics of the exact surface point at each pixel centre",
            "test_perspective_correct_exact_surface_point",
            None,
        ),
        (
            "face = source[id of the key], -1 and bary 0 where EMPTY; no triangles: all empty",
            "test_perspective_correct_exact_surface_point",
            None,
        ),
        (
            "pixel centres on a corner or a median of a one-triangle buffer",
            "test_perspective_correct_exact_surface_point",
            None,
        ),
    ],
    "rasterize_mesh": [
        (
            "the same face per pixel as ray tracing the primary rays",
            "test_rasterize_mesh_matches_ray_tracing",
            None,
        ),
        (
            "far from the origin and on tiny viewports",
            "test_raster_far_from_origin_fp64_and_tiny_viewports",
            None,
        ),
        (
            "memory_budget_bytes handed to rasterize, default 2**28",
            "test_rasterize_mesh_matches_ray_tracing",
            None,
        ),
    ],
    "interpolate": [
        (
            "sum_i bary_i * values[faces[face, i]], zero where face < 0",
            "test_shade_flat_smooth",
            None,
        ),
        (
            "on a one-face mesh too (empty pixels index no other face)",
            "test_perspective_correct_exact_surface_point",
            None,
        ),
    ],
    "shade": [
        (
            "smooth shading renormalises the interpolated normal",
            "test_shade_flat_smooth",
            "smooth_normal_not_renormalised",
        ),
        (
            "0 where face == -1, on a one-face mesh too",
            "test_shade_flat_smooth",
            None,
        ),
    ],
    "traced_visibility": [
        (
            "face and barycentrics of the primary hits, -1 for a miss",
            "test_traced_visibility_primary_hits",
            None,
        ),
    ],
    "world_positions": [
        (
            "the surface point of each pixel's face and barycentrics",
            "test_hybrid_shadows_match_traced",
            None,
        ),
    ],
    "shadow_epsilon": [
        (
            "a bias scaled to the mesh: no acne, no light leaks",
            "test_hybrid_shadows_match_traced",
            None,
        ),
        (
            "computed in float64; 0.0 when no vertex is finite",
            "test_hybrid_shadows_match_traced",
            None,
        ),
    ],
    "hybrid_shadows": [
        (
            "shadow rays start past t_min = shadow_epsilon: no self-shadowing",
            "test_hybrid_shadows_match_traced",
            "shadow_rays_without_offset",
        ),
        (
            "the same shadows as tracing primary and shadow rays",
            "test_hybrid_shadows_match_traced",
            None,
        ),
        (
            "face 0 is a surface and triangle 0 a blocker like any other",
            "test_hybrid_shadows_match_traced",
            None,
        ),
    ],
    "traced_shadows": [
        (
            "the shadows of traced primary hits",
            "test_hybrid_shadows_match_traced",
            None,
        ),
        (
            "triangle 0 is a primary hit and a blocker like any other",
            "test_hybrid_shadows_match_traced",
            None,
        ),
    ],
}
