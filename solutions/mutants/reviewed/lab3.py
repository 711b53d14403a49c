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
}
