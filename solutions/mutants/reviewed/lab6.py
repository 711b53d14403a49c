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
    "lab6_raster:bounding_boxes:drop_clamp:0": (
        "without the float floor of -1 a coordinate below -2**63 (the -1e30 triangles of "
        "test_bounding_boxes) converts to INT64_MIN (x86 cvttsd2si / vcvttpd2qq and CUDA's "
        "saturating cvt alike), which the integer clamp of begin to [0, size] turns into the "
        "same box; only a platform whose out-of-range conversion gives another value could tell"
    ),
    "lab6_raster:bounding_boxes:drop_clamp:1": (
        "without the float floor of -1 an x_max below -2**63 converts to INT64_MIN (x86 and "
        "CUDA alike), and end = max(min(end, size), begin) makes the same empty box; only a "
        "platform whose out-of-range conversion gives another value could tell"
    ),
    "lab6_raster:coverage:const_int:6": (
        "isfinite(xy).all(-2).all(-1) and .all(-1).all(-1) both reduce the (K, 3, 2) corners and "
        "coordinates to (K,): the same mask"
    ),
    "lab6_raster:coverage:cmp_Gt_GtE:1": (
        "positive = area >= 0 differs from area > 0 only for zero-area triangles, which drawn "
        "excludes (area != 0): they get no fragments, so their flag is never read"
    ),
    "lab6_raster:coverage:op_BitAnd_BitOr:0": (
        "NaN/inf corners get empty boxes from bounding_boxes (no fragments) whatever drawn says; "
        "a zero-area triangle, now enumerated, has edge functions summing to 0 at every centre "
        "and edges running both ways, so no centre passes the top-left test; what remains is a "
        "float area that overflows for finite corners (|x| > ~1e19 in float32), which the "
        "docstring leaves open (its non-finite triangles have NaN/inf corners; a float64 "
        "solution would cover the pixels there)"
    ),
    "lab6_raster:coverage:op_BitAnd_BitOr:1": (
        "NaN/inf corners get empty boxes from bounding_boxes (no fragments) whatever drawn says; "
        "what remains is a float area that overflows for finite corners (|x| > ~1e19 in "
        "float32), which the docstring leaves open (its non-finite triangles have NaN/inf "
        "corners; a float64 solution would cover the pixels there)"
    ),
    "lab6_raster:resolve_pixels:op_Div_Mult:0": (
        "e * s instead of e / s (s = e0 + e1 + e2, one number per pixel) scales the three "
        "weights alike, and perspective_correct divides by their weighted sum: the same "
        "barycentrics up to rounding (an overflow would need edge functions beyond 1e19 px^2)"
    ),
    "lab6_raster:shade:const_int:5": (
        "torch.where(face >= 1, face, 0) and torch.where(face >= 0, face, 0) both give 0 for face "
        "== 0 and for -1; empty pixels are zeroed by the final torch.where(face >= 0, ...)"
    ),
    "lab6_raster:traced_shadows:const_int:1": (
        "the t put in for missed primary rays only makes their (unused) points: _shadow_rays "
        "traces points[hit] only, and missed pixels stay unshadowed; 1 instead of 0 changes "
        "nothing"
    ),
    "lab6_raster:rasterize:cmp_Lt_LtE:0": (
        "first <= K runs one more chunk, screen[K:K + 1], which is empty: coverage gives no "
        "fragments and depth_test writes nothing; the keys and the largest allocation are the "
        "same"
    ),
}
