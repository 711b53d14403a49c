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
}
