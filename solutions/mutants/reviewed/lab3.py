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
}
