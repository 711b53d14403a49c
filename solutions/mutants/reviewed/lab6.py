"""Lab 6's generated mutants that survive the graders, reviewed (see
``solutions/mutants/reviewed/__init__.py``)."""

EQUIVALENT = {
    "lab6_raster:bounding_boxes:const_int:3": (
        "the bound only caps the floats before the int64 conversion; any cap >= size - 0.5 gives "
        "the same boxes once begin/end are clamped to [0, size]"
    ),
    "lab6_raster:coverage:cmp_Gt_GtE:0": (
        "drawn already requires area != 0 on the line before, so area >= 0 and area > 0 keep the "
        "same triangles"
    ),
    "lab6_raster:clip_triangles:const_int:4": (
        "isfinite(clip).all(-2).all(-1) and .all(-1).all(-1) both reduce the (F, 3, 4) corners and "
        "coordinates to (F,): the same mask"
    ),
    "lab6_raster:shade:cmp_GtE_Gt:0": (
        "torch.where(face > 0, face, 0) and torch.where(face >= 0, face, 0) both give 0 for face =="
        " 0; empty pixels are zeroed by the final torch.where(face >= 0, ...)"
    ),
    "lab6_raster:bounding_boxes:const_int:1": (
        "isfinite(xy).all(-2).all(-1) and .all(-1).all(-1) both reduce the (K, 3, 2) corners and "
        "coordinates to (K,): the same mask"
    ),
    "lab6_raster:bounding_boxes:const_float:0": (
        "a floor of -1.1 instead of -1.0 on x_min: ceil(lo - 0.5) <= 0 either way, and begin is "
        "clamped to 0: the same boxes"
    ),
    "lab6_raster:bounding_boxes:const_float:1": (
        "a floor of -1.1 instead of -1.0 on x_max: floor(hi - 0.5) + 1 <= -1 either way, and end "
        "is clamped to begin >= 0: the same (empty) boxes"
    ),
    "lab6_raster:_top_left:cmp_Lt_LtE:0": (
        "differs only when bx == ax and by == ay, a zero-length edge: its triangle has zero area "
        "and coverage never draws it (area != 0)"
    ),
    "lab6_raster:_top_left:cmp_Lt_LtE:1": (
        "differs only when ax == bx and ay == by, a zero-length edge: its triangle has zero area "
        "and coverage never draws it (area != 0)"
    ),
    "lab6_raster:clip_triangles:cmp_LtE_Lt:0": (
        "a triangle with all three w <= 0 that the weaker test keeps has every clipped corner, a "
        'convex combination of its corners, at w <= 0: step 3 drops it, docstring: "Drop a '
        'triangle whose clipped part has a corner at ``w <= 0``"'
    ),
}
