"""Lab 4's generated mutants that survive the graders, reviewed (see
``solutions/mutants/reviewed/__init__.py``)."""

EQUIVALENT = {
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
}
