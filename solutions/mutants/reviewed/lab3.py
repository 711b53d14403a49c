"""Lab 3's generated mutants that survive the graders, reviewed (see
``solutions/mutants/reviewed/__init__.py``)."""

EQUIVALENT = {
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
    "lab3_wavefront:layout_float4:op_BitOr_BitAnd:0": (
        "the mutated text is a parameter annotation and the module has `from __future__ import"
        " annotations`, so it is never evaluated: no input tells it apart"
    ),
    "lab3_wavefront:surface_at:const_float:0": (
        "t of a missed ray (0 -> 0.001) only enters that ray's point, which the next line "
        "replaces by 0 (torch.where(hit, ..., 0.0)); o + 0.001 d is finite, so nothing else "
        "changes"
    ),
    "lab3_wavefront:surface_at:cmp_Gt_GtE:0": (
        "only n . d == 0 exactly differs (n flipped or not), and both n and -n then satisfy "
        'the docstring: "flipped to face the ray (``n . d <= 0``)"'
    ),
    "lab3_wavefront:render_whitted:drop_clamp:0": (
        "the clamp only changes the material -1 of missed rays, which then index the last "
        "material (a valid index); alive = hit & ..., and hit is False for exactly those rays,"
        " so alive is unchanged"
    ),
    "lab3_wavefront:render_whitted:const_float:1": (
        "the throughput of dead lanes (0 -> 0.001) is never read again: the image only adds "
        "throughput where alive (background) or where hit = hits.hit & alive, and a dead lane "
        "never revives"
    ),
    "lab3_wavefront:render_whitted:const_int:1": (
        "range(max_depth + 2) adds an iteration after depth == max_depth, but alive includes "
        "(depth < max_depth), so after that bounce no lane is alive and the loop breaks before"
        " the extra iteration"
    ),
    "lab3_wavefront:render_uber:const_int:1": (
        "range(max_depth + 2) adds one bounce after the last, where every lane is dead (alive "
        "= hit & ... & more, more False at depth == max_depth): shade_step then adds "
        "throughput * where(hit, ., where(alive, ., 0)) = 0 to every pixel, so the image is "
        "unchanged"
    ),
    "lab3_wavefront:render_uber:drop_neg:0": (
        "dead lanes get [0, inf] instead of an empty interval: shadow_step masks hit = alive &"
        " (triangle >= 0) and shade_step adds 0 where not alive and keeps alive False, so only"
        " the wasted work on dead lanes changes, never the image"
    ),
    "lab3_wavefront:render_uber:cmp_Lt_LtE:0": (
        "more = depth <= max_depth only differs on the last bounce (depth == max_depth), after"
        " which the loop ends: the alive/throughput it spawns are never used and the image of "
        "that bounce is accumulated before (independent of more)"
    ),
    "lab3_wavefront:render_wavefront:const_int:2": (
        "range(max_depth + 2) adds an iteration after depth == max_depth, but mirror includes "
        "(depth < max_depth), so after that bounce no ray is left and the extra iteration "
        "breaks at its start (len(pixel) == 0) before tracing or recording any stats"
    ),
    "lab3_wavefront:intersect_layout:op_BitAnd_BitOr:0": (
        "valid is only a safety net: a NaN/inf origin or direction makes u non-finite in every "
        "layout (MT: an inf times a nonzero is inf, times 0 is NaN, so dot(s, p) or det is inf"
        " or NaN and u = inf or NaN; woop: the transformed coordinates or t are, and u = o'_x +"
        " t d'_x follows), and u >= 0 & u + v <= 1 rejects every non-finite u"
    ),
    "lab3_wavefront:intersect_layout:op_BitAnd_BitOr:6": (
        "ok (det != 0, d'_z != 0) is redundant with the inside test: det == 0 makes u = dot(s,"
        " p) / 0 = inf or NaN, d'_z == 0 makes t = inf or NaN and u = o'_x + t d'_x inf or "
        "NaN (0 * inf), and a non-finite u fails u >= 0 & u + v <= 1; valid is likewise "
        "redundant (see op_BitAnd_BitOr:0)"
    ),
    "lab3_wavefront:intersect_layout:const_int:9": (
        "reads the index from the w of corner 1 instead of corner 0; layout_float4's docstring:"
        ' "every ``triangles[k, j, 3]`` holds ``order[k]`` bit for bit", so every corner\'s w '
        "is the same index"
    ),
    "lab3_wavefront:intersect_layout:cmp_Lt_LtE:1": (
        "tb <= inf differs only for a tile without a hit (tb = inf) meeting a best with t = inf"
        ", i.e. a ray with no hit so far, whose triangle is -1; ib is a triangle index >= 0, "
        "never < -1, so better stays False"
    ),
    "lab3_wavefront:intersect_layout:cmp_Lt_LtE:2": (
        "ib <= best.triangle differs only at ib == best.triangle with tb == best.t: the same "
        "triangle at the same t (each triangle is in exactly one tile of a ray), so replacing "
        "it writes the same t, index, u and v"
    ),
    "lab3_wavefront:render_persistent:const_int:9": (
        "free = pixel < 1 also takes slots holding pixel 0, but every slot is emptied (pixel "
        "-1) at the end of each step, so at the refill no slot holds a pixel (as "
        "render_persistent:cmp_Lt_LtE:0)"
    ),
    "lab3_wavefront:render_persistent:op_Sub_Add:0": (
        "head is 0 whenever take is computed (it starts at 0 and is reset to 0 when the queue "
        "is rebuilt at the end of every step), so len - head == len + head"
    ),
    "lab3_wavefront:render_persistent:cmp_Gt_GtE:0": (
        "take >= 0 also enters the refill with take == 0, which assigns empty slices and adds 0"
        " to head: a no-op"
    ),
    "lab3_wavefront:render_persistent:const_int:20": (
        "-2 instead of -1 marks a finished slot: any negative pixel marks an empty slot (free ="
        " pixel < 0, lane = pixel >= 0), as render_persistent:const_int:5"
    ),
    "lab3_wavefront:render_persistent:const_float:0": (
        "only with no step at all (N = 0 rays), where the docstring's idle_fraction = 1 - "
        "sum(active_lanes) / (pool_size * steps) is 0 / 0 and promises no value"
    ),
}
