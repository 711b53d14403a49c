"""Lab 4's generated mutants that survive the graders, reviewed (see
``solutions/mutants/reviewed/__init__.py``)."""

EQUIVALENT = {
    "lab4_march:march_box:const_int:3": (
        "the placeholder point of a missed ray moves from box_min to box_min + 1: its density and "
        "emission are masked by active before use and its step length is 0"
    ),
    "lab4_march:march_box:const_int:8": (
        "sigma of inactive lanes 1 instead of 0: their step length is where(active, ds, 0) = 0, so "
        "segment_integral gives weight 0 and transmittance 1"
    ),
    "lab4_march:march_box:const_int:9": (
        "the step length of inactive lanes 1 instead of 0: their sigma is already masked to 0, so "
        "segment_integral gives transmittance 1, and the weight (1 for the exact integrator) "
        "multiplies where(active_q, q, 0) = 0"
    ),
    "lab4_march:march_box:const_int:11": (
        "the emission of inactive lanes 1 instead of 0: it is multiplied by their weight, which "
        "is 0 (sigma 0 over a step of length 0)"
    ),
    "lab4_march:march_box:const_int:4": (
        "the placeholder direction of a missed ray 1 instead of 0: a missed ray has t_near = "
        "t_far = 0, so every sample is at t = 0 (offset rel + 0 * d = 0) and ds = 0 * |d| = 0"
    ),
    "lab4_march:march_box:narrow_dtype:0": (
        "jitter drawn as float32 instead of float64: another stream of offsets; the docstring "
        "fixes only 'one offset xi in [0, 1] per ray, the same for all its steps, drawn on the "
        "CPU from a generator seeded with seed', not the dtype of the draw"
    ),
    "lab4_march:march_box:const_float:3": (
        "the point at which the emission is evaluated when no step ran is used only for the "
        "shape of its values (the channels of the zero radiance); the values are discarded, and "
        "a field's shape is (N,) or (N, C) at any point (field_values checks it)"
    ),
    "lab4_march:march_box:op_Add_Sub:5": (
        "as march_box:const_float:3: only the shape of that evaluation is used"
    ),
    "lab4_march:march_box:op_Mult_Div:6": (
        "as march_box:const_float:3: only the shape of that evaluation is used"
    ),
    "lab4_march:sample_grid:const_float:0": (
        "the coordinate that replaces NaN before indexing is 0.001 instead of 0: still a valid "
        "(clamped) index, and torch.where(finite, ..., 0) then selects 0 for those points "
        "whatever was read"
    ),
    "lab4_march:sample_grid:cmp_Eq_NotEq:0": (
        "flipping the corner bits swaps i0 with i1 and 1 - f with f together: the same 8 "
        "(index, weight) pairs, summed in another order (differences of an ulp)"
    ),
    "lab4_march:sphere_trace:const_int:5": (
        "the placeholder origin of an invalid ray 1 instead of 0: invalid rays are never active, "
        "so what sdf returns there is never used"
    ),
    "lab4_march:sphere_trace:const_int:6": (
        "the placeholder direction of an invalid ray 1 instead of 0: as sphere_trace:const_int:5"
    ),
    "lab4_march:sphere_trace:op_BitAnd_BitOr:6": (
        "fail set on inactive lanes too: it only changes their t (where(active, ...)), hit "
        "(active & ...), prev_step, prev_radius and omega, none of which is read again for a "
        "lane that is inactive (inactive lanes never become active)"
    ),
    "lab4_march:sphere_trace:cmp_Gt_GtE:1": (
        "the overlap check also with omega = 1: there the last step is exactly prev_radius "
        "(1 * |f|), so |f| + prev_radius < prev_radius never holds for |f| >= 0 (NaN compares "
        "False), and fail stays False"
    ),
    "lab4_march:voxel_walk:const_int:3": (
        "rel of a missed ray 1 instead of 0: missed rays (t = t_end = 0) are never active"
    ),
    "lab4_march:voxel_walk:const_int:4": (
        "the placeholder direction of a missed ray 2 instead of 1: missed rays are never active"
    ),
    "lab4_march:voxel_walk:cmp_Lt_LtE:0": (
        "rays touching the box at one t (t = t_end) start active, but the loop's first line "
        "ands active with t < t_end again before anything is read or counted"
    ),
    "lab4_march:voxel_walk:const_int:11": (
        "X + Y + Z + 2 iterations instead of + 1: X + Y + Z + 1 already finish every ray (see "
        "op_Add_Sub:1), and the loop breaks once no ray is active"
    ),
    "lab4_march:voxel_walk:cmp_Lt_LtE:2": (
        "a ray keeps going at t = t_end only where its cell is still inside the grid, i.e. "
        "where it crossed an interior plane at the very exit point (an edge on the box face): "
        "one more zero-length segment (0 optical depth, one more step). The docstring lets "
        "ties step 'one axis at a time with zero-length segments in between', and the graders "
        "count steps only on rays crossing no edge (rounding decides those either way)"
    ),
    "lab4_march:voxel_walk:cmp_Gt_GtE:1": (
        "on an axis with step 0 the plane ahead is block_hi + 1 instead of block_lo, but its t "
        "is replaced by inf (where(step != 0, ..., inf)) either way"
    ),
    "lab4_march:voxel_walk:const_int:28": (
        "the segment of inactive lanes 1 instead of 0: their sigma and emission are masked to 0 "
        "(sample = active & ~skip), so they add 0 optical depth, transmittance factor 1 and "
        "0 radiance"
    ),
    "lab4_march:voxel_walk:cmp_Gt_GtE:2": (
        "max(located, index) instead of index on an axis with step 0: the direction component "
        "is exactly 0 there, so located (clamped into the block) equals index (as "
        "voxel_walk:cmp_Lt_LtE:3)"
    ),
    "lab4_march:voxel_walk:const_int:37": (
        "min(located, index) on an axis with step 0 as well: located equals index there (as "
        "voxel_walk:cmp_Lt_LtE:3)"
    ),
    "lab4_march:voxel_walk:cmp_Gt_GtE:3": (
        "across on an axis with step 0 is block_hi + 1 instead of block_lo - 1, but it is used "
        "only on the exit axis (argmin of t_axis), and an axis with step 0 has t_axis = inf: "
        "it is the argmin only when every t_axis is inf, and then t_exit = t_end ends the ray, "
        "so its cell is never read again"
    ),
    "lab4_march:voxel_walk:op_Add_Sub:1": (
        "every active iteration moves one index at least 1 toward the exit, so at most X+Y+Z-2 "
        "iterations are active and X+Y+Z-1 still finish every ray (checked on 300 random grids of "
        "1..5 per axis, with and without occupancy, corner-aligned and axis-parallel rays: "
        "identical outputs)"
    ),
    "lab4_march:voxel_walk:cmp_Lt_LtE:3": (
        "on an axis with step 0 the direction component is exactly 0, so the located index, clamped"
        " into the block, equals the current one: min(located, index) = index (checked on 300 "
        "random grids, float32/float64, macro cells 1..3, rays in voxel planes and through corners:"
        " identical outputs)"
    ),
    "lab4_march:voxel_walk:drop_clamp:1": (
        "active lanes have every cell index in [0, size) already; an inactive lane has at most one "
        "index at -1, a valid negative index, and what it reads is masked (same 300-grid check: "
        "identical outputs)"
    ),
    "lab4_march:henyey_greenstein:cmp_GtE_Gt:0": (
        "g = 0 picks the other denominator: (1 + g)^2 - 2 g (1 + cos) and "
        "(1 - g)^2 + 2 g (1 - cos) are both exactly 1 at g = 0, "
        "so the value is the same for every cos"
    ),
    "lab4_march:segment_integral:const_int:6": (
        "the 1 of the inner where is the divisor of the finite steps' lanes, whose result "
        "the outer where(endless, ...) discards: only the lanes with length = inf read 1 / sigma"
    ),
    "lab4_march:shadow_transmittance:const_int:1": (
        "rel of a point whose light ray misses the box moves from 0 to 1: its density is masked by "
        "where(hit, sigma, 0) and its dt is (t_far - t_near) / steps = 0"
    ),
    "lab4_march:shadow_transmittance:const_int:4": (
        "the masked density of a missed point becomes 1: it is multiplied by dt = 0 (t_near = "
        "t_far = 0 where hit is False), so it adds 0 to the depth"
    ),
    "lab4_march:sample_grid:op_Sub_Add:2": (
        "i0 no longer clamped to n - 2 differs only at u = n - 1 exactly (the last centre or "
        "past it): i0 = i1 = n - 1 with f = 0 reads grid[n - 1] at weight 1 and again at "
        "weight 0, which adds nothing (a weight-0 corner is masked, even +inf): the same value"
    ),
    "lab4_march:sample_grid:const_int:5": (
        "the clamp of n - 2 at 1 instead of 0 differs only for n = 2 at u = 1 exactly: i0 = "
        "i1 = 1 with f = 0 reads grid[1] at weight 1, as i0 = 0, f = 1 does (grid[0] at weight "
        "0 is masked, even +inf): the same value"
    ),
    "lab4_march:march_single_scatter:cmp_Gt_GtE:0": (
        "size only divides where box_max > box_min: on a flat axis the local coordinate is the "
        "0.5 of the torch.where that follows, whatever size holds there"
    ),
    "lab4_march:march_single_scatter:const_int:4": (
        "the stand-in size 1 (or 2) of a flat axis is never used: the local coordinate there "
        "is the 0.5 of the torch.where that follows"
    ),
}
