"""Generated mutants that survive the graders, reviewed: each is equivalent to the reference
for every input the contract allows, or changes only what the contract leaves free (the
docstring then says so). ``rtcourse mutants --generated`` counts these as neither killed
nor survived. Ids are ``module:function:kind:n`` (see course.grading.mutate)."""

EQUIVALENT = {
    # Lab 2
    "lab2_accel:build_lbvh:const_int:34": (
        "an inner node's 'first' is never read (only leaves hold triangles[first:first + count], "
        "and count is 0 for inner nodes), so 1 instead of 0 there changes nothing"
    ),
    "lab2_accel:kd_pack:const_int:10": (
        "packed - 2**33 instead of packed - 2**32 before .to(torch.int32): the conversion keeps the"
        " low 32 bits, the same for both"
    ),
    "lab2_accel:bvh_closest_hit_fast:bool_And_Or:4": (
        "compacting the rays at every look instead of only when few run changes only the order in "
        "which unfinished rays are stepped, not their hits or counters"
    ),
    # Lab 3
    "lab3_wavefront:render_persistent:const_int:5": (
        "fill_(-2) instead of fill_(-1): any negative pixel marks an empty slot (free = pixel < 0, "
        "lane = pixel >= 0)"
    ),
    "lab3_wavefront:render_whitted:drop_clamp:1": (
        "kr[material] with material -1 (a miss) picks the last material's kr, but those lanes are "
        "not alive and torch.where gives 0"
    ),
    "lab3_wavefront:render_whitted:drop_neg:0": (
        "dead lanes traced on [0, inf] instead of an empty interval: their hits are masked by alive"
        " (hit = hits.hit & alive) and o, d, throughput change only where alive; only wasted work"
    ),
    "lab3_wavefront:surface_at:drop_clamp:0": (
        "triangle -1 of a miss indexes the last face (valid negative indexing); the normals and "
        "material of misses are replaced by torch.where(hit, ...)"
    ),
    # Lab 4
    "lab4_march:march_box:const_int:3": (
        "the placeholder point of a missed ray moves from box_min to box_min + 1: its density and "
        "emission are masked by active before use and its step length is 0"
    ),
    "lab4_march:march_box:const_int:7": (
        "sigma of inactive lanes 1 instead of 0: their step length is where(active, ds, 0) = 0, so "
        "segment_integral gives weight 0 and transmittance 1"
    ),
    "lab4_march:voxel_walk:op_Add_Sub:1": (
        "every active iteration moves one index at least 1 toward the exit, so at most X+Y+Z-2 "
        "iterations are active and X+Y+Z-1 still finish every ray (checked on 300 random grids of "
        "1..5 per axis, with and without occupancy, corner-aligned and axis-parallel rays: "
        "identical outputs)"
    ),
    # Lab 0
    "lab0_interop:linear_to_srgb8:const_float:1": (
        "posinf=1.1 is clamped to 1 by the next clamp(0, 1) (and srgb_encode clamps again): +inf "
        "still gives 255"
    ),
    "lab0_interop:linear_to_srgb8:const_float:4": (
        "srgb_encode clamps its input to [0, 1] itself, so clamp(0, 1.1) encodes the same values"
    ),
    "lab0_interop:measure_copy_bandwidth:const_int:3": (
        "warmup=2 instead of 1 only changes how long the measurement runs"
    ),
    "lab0_interop:pack_rgba8:const_int:10": (
        "3**31 never matches, but the int64 -> int32 cast wraps modulo 2**32 on CPU and CUDA, "
        "giving the same two's-complement word"
    ),
    "lab0_interop:pack_rgba8:op_Sub_Add:0": (
        "word + 2**32 equals word - 2**32 modulo 2**32, and the int64 -> int32 cast wraps modulo "
        "2**32: the same int32"
    ),
    "lab0_interop:render_rotating_triangle:cmp_GtE_Gt:0": (
        "only pixel centres whose barycentric rounds to exactly 0 change, within 1e-4 pixel of an "
        "edge, which the contract lets go either way (the docstring says so)"
    ),
    "lab0_interop:render_rotating_triangle:const_int:9": (
        "inside pixels have barycentrics >= 0 summing to 1, so none exceeds 1 beyond rounding (far "
        "below 0.5/255); outside pixels take the background: the upper clamp never changes a code"
    ),
    "lab0_interop:run_frame_loop:const_int:2": (
        "a third device framebuffer is allocated but never used (only indices i % 2 and 0 are read)"
    ),
    # Lab 1
    "lab1_intersect:ray_box:const_int:5": (
        "a t_far margin of 3 gamma(3) instead of 2 stays conservative and differs by about gamma(3)"
        " relative: only rays missing the box by that much change, which the contract lets go "
        "either way (the docstring says so)"
    ),
    # Lab 5
    "lab5_froxel:cull_lights:cmp_GtE_Gt:3": (
        "a tie only: a bottom distance of exactly -range is a sphere tangent to the plane, decided "
        "by rounding, and the light gives nothing at exactly its range; the docstring says ties may"
        " go either way"
    ),
    "lab5_froxel:cull_lights:cmp_GtE_Gt:4": (
        "a tie only: a view depth of exactly near - range is a sphere tangent to the near plane, "
        "and the light gives nothing at exactly its range (docstring: either way)"
    ),
    "lab5_froxel:light_transmittance:drop_nan_to_num:0": (
        "the NaN (0 * inf) arises only for a segment parallel to an axis lying exactly in a face "
        "plane of the box: a tie between inside and outside (docstring: either)"
    ),
    "lab5_froxel:apply_froxels:drop_nan_to_num:0": (
        "depth_to_slice is NaN only for NaN depths, which check_images rejects; the clamp(0, "
        "slices) after it maps -inf/+inf exactly as nan_to_num does"
    ),
    "lab5_froxel:apply_froxels:const_float:0": (
        "the nan= replacement is never used: NaN depths are rejected by check_images"
    ),
    # Lab 6
    "lab6_raster:bounding_boxes:const_int:3": (
        "the bound only caps the floats before the int64 conversion; any cap >= size - 0.5 gives "
        "the same boxes once begin/end are clamped to [0, size]"
    ),
    "lab6_raster:coverage:cmp_Gt_GtE:0": (
        "drawn already requires area != 0 on the line before, so area >= 0 and area > 0 keep the "
        "same triangles"
    ),
    # Lab 0, the second sample
    "lab0_interop:FrameDownloader:op_Add_Sub:0": (
        "(slot - 1) % n walks the ring backwards: any cyclic order reuses a slot only n submits "
        "later, while at most n - 1 others are pending (FIFO through pending), so the frames "
        "received and the buffers reused are the same; for n = 1, 2 identical"
    ),
    "lab0_interop:measure_copy_bandwidth:const_int:0": (
        "a default of 6 repeats instead of 5 only changes how long the measurement runs"
    ),
    "lab0_interop:pack_rgba8:const_int:11": (
        "word >= 2**32 never matches (words < 2**32), but the int64 -> int32 cast wraps modulo "
        "2**32 on CPU and CUDA, giving the same two's-complement word"
    ),
    "lab0_interop:run_frame_loop:const_int:4": (
        "without overlap the loop renders into framebuffers[1] instead of framebuffers[0]: both are"
        " allocated alike (shape, dtype, device) and the other is never used"
    ),
    # Lab 1, the second sample
    "lab1_intersect:closest_hit:drop_clamp:0": (
        "the lab's kernels return t = inf, never NaN, for misses (masked_result), so some column "
        "always equals the row minimum (column 0 when all are inf): the clamp never binds"
    ),
    "lab1_intersect:woop_precompute:cmp_Gt_GtE:0": (
        "area2 == 0 makes n / area2 NaN (0/0) or inf, so the transform is not finite and the "
        "isfinite check zeroes it anyway"
    ),
    # Lab 3, the second sample
    "lab3_wavefront:render_persistent:cmp_Lt_LtE:0": (
        "every slot is emptied (pixel -1) at the end of each step, so at the refill no slot holds a"
        " pixel, 0 or otherwise: free is every slot with < 0 and with <= 0"
    ),
    "lab3_wavefront:render_whitted:cmp_Lt_LtE:0": (
        "depth <= max_depth differs only at depth == max_depth, the last iteration, where alive "
        "only feeds throughput, o and d, never read after the loop"
    ),
    "lab3_wavefront:surface_at:bool_Or_And:0": (
        "only a hits that is not the Hits of the N rays is treated differently; the provided checks"
        " do not validate hits, so that input is outside the contract (the docstring says so)"
    ),
    # Lab 4, the second sample
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
    # Lab 5, the second sample
    "lab5_froxel:cull_lights:narrow_dtype:1": (
        "float32 tile-edge NDC changes the plane distances by ~1e-7 of the light's distance: only "
        "spheres within rounding of tangent go the other way (docstring: either way)"
    ),
    "lab5_froxel:build_shadow_map:const_float:0": (
        "the plane's margin beyond the occluders is free: the data are depths from the map's own "
        "origin and shadow_lookup measures from that origin, so visibility is unchanged"
    ),
    "lab5_froxel:light_transmittance:cmp_Gt_GtE:0": (
        "where span == 0 the optical depth is multiplied by span = 0 whatever points are sampled: T"
        " = 1 both ways"
    ),
    "lab5_froxel:transmittance_volume:const_int:4": (
        "the fallback shape only feeds check_volume for a non-3-D extinction, which is rejected "
        "with (1, 1, 1) or (1, 1, 2) alike"
    ),
    # Lab 6, the second sample
    "lab6_raster:clip_triangles:const_int:4": (
        "isfinite(clip).all(-2).all(-1) and .all(-1).all(-1) both reduce the (F, 3, 4) corners and "
        "coordinates to (F,): the same mask"
    ),
    "lab6_raster:shade:cmp_GtE_Gt:0": (
        "torch.where(face > 0, face, 0) and torch.where(face >= 0, face, 0) both give 0 for face =="
        " 0; empty pixels are zeroed by the final torch.where(face >= 0, ...)"
    ),
    # Lab 2, the second sample
    "lab2_accel:build_lbvh:op_Sub_Add:7": (
        "before is read only at a node's start and at its right child's start, both the start of "
        "exactly one leaf: '+' adds 2 to both and their difference (left_size) is unchanged; leaf "
        "rows are masked"
    ),
    "lab2_accel:build_two_level_grid:drop_clamp:0": (
        "a sub-grid exists only for a cell with n_small > min_triangles >= 0, so n_sub >= 1 for "
        "every sub-grid: the clamp never binds"
    ),
    "lab2_accel:bvh_closest_hit_fast:const_int:0": (
        "the default check_every only sets how many steps run between host looks; extra steps of "
        "finished rays change nothing (a timing knob)"
    ),
    "lab2_accel:bvh_closest_hit_fast:const_int:8": (
        "the loop bound m + F + 1 already covers a ray's box tests and slots; a looser bound only "
        "allows more looks, and the loop breaks when no ray runs"
    ),
    "lab2_accel:bvh_closest_hit_fast:const_int:10": (
        "replays a cached graph twice per look (CUDA graphs only): extra steps of finished rays "
        "change nothing, unfinished ones only get further before the next look"
    ),
    # bvh_closest_hit_fast's knobs and bookkeeping (rtcourse mutants --generated --only
    # bvh_closest_hit_fast: every survivor of that function reviewed here but four that
    # only the CUDA-graph path shows, which the CPU graders do not run: bool_And_Or:0,
    # cmp_Eq_NotEq:0, bool_And_Or:3, cmp_Lt_LtE:1)
    "lab2_accel:bvh_closest_hit_fast:op_BitOr_BitAnd:0": (
        "dict | None is an annotation, never evaluated (from __future__ import annotations)"
    ),
    "lab2_accel:bvh_closest_hit_fast:const_int:1": (
        "the default fuse_steps matters only when compiled, and how many steps one call runs never "
        "changes hits or counters (a timing knob)"
    ),
    "lab2_accel:bvh_closest_hit_fast:const_int:3": (
        "the largest check_every accepted (1024 or 1025): a sanity limit the docstring does not "
        "promise; every accepted value gives the same hits"
    ),
    "lab2_accel:bvh_closest_hit_fast:const_int:5": (
        "the largest fuse_steps accepted (64 or 65): a sanity limit, a timing knob"
    ),
    "lab2_accel:bvh_closest_hit_fast:bool_And_Or:2": (
        "copies the gathered rows into tensors of their own on the eager path too: the same values,"
        " one copy more"
    ),
    "lab2_accel:bvh_closest_hit_fast:const_int:7": (
        "range(1, m + F + 1, k) runs at least m + F steps, as many as a ray can need (one per node "
        "box and one per leaf slot)"
    ),
    "lab2_accel:bvh_closest_hit_fast:const_int:9": (
        "a graph of two calls per replay (CUDA graphs only): extra steps of finished rays change "
        "nothing, unfinished ones only get further before the next look"
    ),
    "lab2_accel:bvh_closest_hit_fast:cmp_Lt_LtE:0": (
        "counts finished rays as running: the walk never compacts or stops early and runs to the "
        "loop bound, whose steps change nothing for finished rays (host time only)"
    ),
    "lab2_accel:bvh_closest_hit_fast:cmp_LtE_Lt:0": (
        "compacts at one ray fewer: when to compact changes only the order in which unfinished rays"
        " are stepped, not their hits or counters"
    ),
    "lab2_accel:bvh_closest_hit_fast:cmp_LtE_GtE:0": (
        "compacts when many rays run instead of few: when to compact changes only the order in "
        "which unfinished rays are stepped, not their hits or counters"
    ),
    "lab2_accel:bvh_closest_hit_fast:cmp_GtE_Gt:0": (
        "compacts only from one ray more than the floor: when to compact changes only the order in "
        "which unfinished rays are stepped, not their hits or counters"
    ),
    "lab2_accel:bvh_closest_hit_fast:cmp_GtE_LtE:0": (
        "compacts only below the floor (on the CPU: never): when to compact changes only the order "
        "in which unfinished rays are stepped, not their hits or counters "
        "(tests/meta/test_lab2_graph_emulated.py checks the floor itself)"
    ),
    "lab2_accel:bvh_closest_hit_fast:const_int:13": (
        "compacts at a ninth instead of an eighth (CUDA graphs): when to compact changes only the "
        "order in which unfinished rays are stepped, not their hits or counters"
    ),
    "lab2_accel:bvh_closest_hit_fast:const_int:14": (
        "compacts at a third instead of half: when to compact changes only the order in which "
        "unfinished rays are stepped, not their hits or counters"
    ),
    "lab2_accel:grid_closest_hit:cmp_Gt_GtE:0": (
        "differs only where step == 0, where t_next is replaced by inf through torch.where: the "
        "boundary computed there is never used"
    ),
}
