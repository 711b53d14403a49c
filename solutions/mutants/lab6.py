"""Lab 6 mutants: typical mistakes in a compute rasterizer, each applied to the reference
solution. Every one must lose points on the tests its ``tests`` expression selects.
"""

from course.grading.mutants import Mutant

M = "lab6_raster"

MUTANTS = [
    Mutant(
        name="depth_test_race",
        module=M,
        function="depth_test",
        find='out.scatter_reduce_(0, pixel, key, reduce="amin")',
        replace="out.index_put_((pixel,), torch.minimum(out[pixel], key))",
        tests="depth_test",
        why="a read-compare-write instead of an atomic minimum: among the fragments of one "
        "pixel the last writer wins, not the nearest",
    ),
    Mutant(
        name="key_id_in_high_bits",
        module=M,
        function="pack_depth_id",
        find="return (quantised << ID_BITS) | triangle",
        replace="return (triangle << ID_BITS) | quantised",
        tests="pack_depth_id",
        why="the id in the high bits and the depth in the low ones: keys sort by id, so "
        "the lowest triangle id wins whatever its depth",
    ),
    Mutant(
        name="key_negative_zero",
        module=M,
        function="pack_depth_id",
        find="depth = torch.where(depth > 0, depth, torch.zeros_like(depth))",
        replace="depth = depth.clamp(min=0)",
        tests="pack_depth_id",
        why="-0.0 keeps its sign bit: its key is negative and beats every other depth",
    ),
    Mutant(
        name="no_fill_rule",
        module=M,
        function="coverage",
        find="inside = ((e > 0) | ((e == 0) & top_left)).all(-1)",
        replace="inside = (e >= 0).all(-1)",
        tests="coverage",
        why="without the top-left rule a pixel centre on a shared edge is covered twice",
    ),
    Mutant(
        name="cull_front_faces",
        module=M,
        function="coverage",
        find="drawn &= area > 0",
        replace="drawn &= area < 0",
        tests="coverage",
        why="the wrong winding sign: the y flip makes front faces positive on screen, so "
        "this culls the front faces and keeps the back ones",
    ),
    Mutant(
        name="pixel_corners_not_centres",
        module=M,
        function="coverage",
        find="px = cols.to(xy.dtype) + 0.5",
        replace="px = cols.to(xy.dtype)",
        tests="coverage",
        why="samples x at the pixel's corner instead of its centre: coverage shifts by half "
        "a pixel",
    ),
    Mutant(
        name="bbox_misses_last_column",
        module=M,
        function="bounding_boxes",
        find="end = torch.maximum(torch.minimum(end, size), begin)",
        replace="end = torch.maximum(torch.minimum(end, size - 1), begin)",
        tests="bounding_boxes",
        why="clamps the half-open end to size - 1: the last row and column are never drawn",
    ),
    Mutant(
        name="viewport_y_not_flipped",
        module=M,
        function="to_screen",
        find="sy = (1 - y / w) * (height / 2)",
        replace="sy = (1 + y / w) * (height / 2)",
        tests="to_screen",
        why="row 0 is the top of the image, NDC y points up: without the flip the image is "
        "upside down",
    ),
    Mutant(
        name="no_near_plane_clipping",
        module=M,
        function="clip_triangles",
        find="inside = d >= 0",
        replace="inside = torch.ones_like(d, dtype=torch.bool)",
        tests="clip_triangles",
        why="keeps triangles crossing the near plane whole: corners behind the eye (w < 0) "
        "project to the other side of the screen",
    ),
    Mutant(
        name="screen_space_interpolation",
        module=M,
        function="perspective_correct",
        find="q = bary * inv_w",
        replace="q = bary * 1.0",
        tests="perspective_correct",
        why="screen-space (affine) interpolation: textures and normals swim on surfaces "
        "that recede from the eye",
    ),
    Mutant(
        name="smooth_normal_not_renormalised",
        module=M,
        function="shade",
        find="n = normalized(interpolate(normalized(vertex_normals), mesh.faces, face, bary))",
        replace="n = interpolate(normalized(vertex_normals), mesh.faces, face, bary)",
        tests="shade",
        why="a blend of unit normals is shorter than 1: the middle of every face too dark",
    ),
    Mutant(
        name="shadow_rays_without_offset",
        module=M,
        function="_shadow_rays",
        find="(n,), shadow_epsilon(mesh),",
        replace="(n,), 0.0,",
        tests="hybrid_shadows",
        why="shadow rays from t_min = 0 hit their own triangle half the time: shadow acne",
    ),
]
