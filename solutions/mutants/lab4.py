"""Lab 4 mutants: typical mistakes in ray marching, each applied to the reference solution.
Every one must lose points on the tests its ``tests`` expression selects.
"""

from course.grading.mutants import Mutant

M = "lab4_march"

_FRONT_TO_BACK = (
    "        weight, t_seg = segment_integral(sigma, torch.where(active, ds, 0), integrator)\n"
    "        if emission is not None:\n"
    '            q = evaluate(emission, "emission", points, local, channels=True)\n'
    "            if q.ndim == 2:  # colour channels\n"
    "                weight, seen, active_q = weight[:, None], transmittance[:, None], "
    "active[:, None]\n"
    "            else:\n"
    "                seen, active_q = transmittance, active\n"
    "            radiance = radiance + seen * weight * torch.where(active_q, q, 0)\n"
    "        transmittance = transmittance * t_seg\n"
)

MUTANTS = [
    Mutant(
        name="box_nan_poisons_slabs",
        module=M,
        function="ray_box_interval",
        find="t_near = torch.fmax(torch.fmax(torch.fmax(lo[:, 0], lo[:, 1]), lo[:, 2]), zero)\n"
        "    t_far = torch.fmin(torch.fmin(hi[:, 0], hi[:, 1]), hi[:, 2])",
        replace="t_near = torch.maximum(lo.amax(-1), zero)\n    t_far = hi.amin(-1)",
        tests="ray_box_interval",
        why="0 * inf = NaN for a ray starting on a slab plane poisons max/min: it misses the "
        "box it runs along",
    ),
    Mutant(
        name="trilinear_axes_reversed",
        module=M,
        function="sample_grid",
        find="u = torch.nan_to_num(uvw, nan=0.0) * sizes - 0.5",
        replace="u = torch.nan_to_num(uvw.flip(-1), nan=0.0) * sizes - 0.5",
        tests="sample_grid",
        why="grid_sample's (x, y, z) against (D, H, W) order confusion: x read along the "
        "grid's last axis",
    ),
    Mutant(
        name="march_back_to_front",
        module=M,
        function="march_box",
        find="radiance = radiance + seen * weight * torch.where(active_q, q, 0)",
        replace="radiance = radiance * (t_seg[:, None] if q.ndim == 2 else t_seg) "
        "+ weight * torch.where(active_q, q, 0)",
        tests="march_box",
        why="the back-to-front 'over' update in a front-to-back loop: the nearest sample ends "
        "up behind everything else",
    ),
    Mutant(
        name="march_transmittance_first",
        module=M,
        function="march_box",
        find=_FRONT_TO_BACK,
        replace=_FRONT_TO_BACK.replace(
            "        transmittance = transmittance * t_seg\n", ""
        ).replace(
            "        if emission is not None:\n",
            "        transmittance = transmittance * t_seg\n        if emission is not None:\n",
        ),
        tests="march_box",
        why="transmittance updated before accumulating the sample: each step is absorbed "
        "twice by its own medium",
    ),
    Mutant(
        name="march_absolute_points",
        module=M,
        function="march_box",
        find="offset = rel + t[:, None] * d",
        replace="offset = (origins + t[:, None] * d) - box_min",
        tests="march_box",
        why="samples the grid from the absolute point: at 1e5 float32 rounds it to 1/128",
    ),
    Mutant(
        name="segment_riemann_called_exact",
        module=M,
        function="segment_integral",
        find="length * ratio), transmittance",
        replace="length.expand_as(x)), transmittance",
        tests="segment_integral",
        why="the 'exact' step weight is the Riemann sum's length: it misses "
        "(1 - e^{-sigma ds}) / sigma, is first order and not energy-conserving",
    ),
    Mutant(
        name="segment_sigma_zero_nan",
        module=M,
        function="segment_integral",
        find="ratio = torch.where(x > 0, -torch.expm1(-x) / x, 1)",
        replace="ratio = -torch.expm1(-x) / x",
        tests="segment_integral",
        why="(1 - e^{-sigma D}) / sigma at sigma = 0 is 0 / 0: NaN in vacuum",
    ),
    Mutant(
        name="segment_cancelling_form",
        module=M,
        function="segment_integral",
        find="ratio = torch.where(x > 0, -torch.expm1(-x) / x, 1)",
        replace="ratio = torch.where(x > 0, (1 - torch.exp(-x)) / x, 1)",
        tests="segment_integral",
        why="1 - exp(-x) cancels for small x: thin media lose their emission in float32",
    ),
    Mutant(
        name="hg_wrong_sign",
        module=M,
        function="henyey_greenstein",
        find="(1 - g) ** 2 + 2 * g * (1 - cos_theta)",
        replace="(1 - g) ** 2 + 2 * g * (1 + cos_theta)",
        tests="henyey_greenstein",
        why="the wrong sign of cos theta: forward scattering becomes backward scattering",
    ),
    Mutant(
        name="hg_missing_4pi",
        module=M,
        function="henyey_greenstein",
        find="4 * math.pi * base",
        replace="base",
        tests="henyey_greenstein",
        why="without 1 / (4 pi) the phase function integrates to 4 pi, not 1",
    ),
    Mutant(
        name="shadow_left_endpoint",
        module=M,
        function="shadow_transmittance",
        find="(t_near + (k + 0.5) * dt)",
        replace="(t_near + k * dt)",
        tests="shadow_transmittance",
        why="left-endpoint samples: first order, and the sample at the point itself",
    ),
    Mutant(
        name="scatter_no_shadow",
        module=M,
        function="march_single_scatter",
        find="lit = shadow_transmittance(points, light, box_min, box_max, density, shadow_steps)",
        replace="lit = torch.ones_like(sigma)",
        tests="single_scatter",
        why="no shadow march: every sample sees the light unattenuated",
    ),
    Mutant(
        name="dda_off_by_one",
        module=M,
        function="voxel_walk",
        find="ahead = torch.where(step > 0, block_hi + 1, block_lo)",
        replace="ahead = block_hi + 1",
        tests="voxel_walk",
        why="the next boundary is index + 1 whatever the direction: off by one voxel for "
        "negative directions",
    ),
    Mutant(
        name="dda_no_axis_guard",
        module=M,
        function="voxel_walk",
        find="t_axis = torch.where(step != 0, (ahead * voxel - rel) * inv, inf)",
        replace="t_axis = (ahead * voxel - rel) * inv",
        tests="voxel_walk",
        why="a zero direction component gives (plane - o) * inf = -inf or NaN: the walk "
        "steps along an axis the ray never moves on",
    ),
    Mutant(
        name="skip_non_empty",
        module=M,
        function="build_occupancy",
        find="pooled = torch.nn.functional.max_pool3d(\n"
        "        busy[None, None].float(), macro_cell, stride=macro_cell, ceil_mode=True\n"
        "    )",
        replace="pooled = busy[::macro_cell, ::macro_cell, ::macro_cell][None, None].float()",
        tests="empty_space_skipping",
        why="occupancy from one voxel per macro cell: skipping jumps over non-empty voxels",
    ),
    Mutant(
        name="trace_unsure_as_hit",
        module=M,
        function="sphere_trace",
        find="torch.where(t > t_max, MISS, UNSURE)",
        replace="torch.where(t > t_max, MISS, HIT)",
        tests="sphere_trace",
        why="running out of steps counts as a hit: grazing rays that miss report surfaces",
    ),
    Mutant(
        name="trace_absolute_epsilon",
        module=M,
        function="sphere_trace",
        find="radius <= epsilon * t * length",
        replace="radius <= epsilon",
        tests="sphere_trace",
        why="an absolute hit tolerance: unreachable far away (float spacing), too coarse for "
        "small things near the camera",
    ),
    Mutant(
        name="trace_no_sor_fallback",
        module=M,
        function="sphere_trace",
        find="fail = active & (omega > 1) & (radius + prev_radius < prev_step)",
        replace="fail = active & (radius < 0)",
        tests="sphere_trace",
        why="over-relaxation without Keinert's check: steps jump through thin surfaces",
    ),
    Mutant(
        name="hg_cos_unclamped",
        module=M,
        function="henyey_greenstein",
        find="cos_theta = cos_theta.clamp(-1, 1)",
        replace="cos_theta = cos_theta",
        tests="henyey_greenstein",
        why="a cosine a rounding step past 1 makes the denominator negative: NaN phase",
    ),
    Mutant(
        name="trace_no_inside_abs",
        module=M,
        function="sphere_trace",
        find="radius = f.abs()",
        replace="radius = f",
        tests="sphere_trace",
        why="a negative distance (ray starting inside) steps backwards",
    ),
    # Fresh mistakes, written from the docstrings (before reading the tests).
    Mutant(
        name="fresh_box_open_interval",
        module=M,
        function="ray_box_interval",
        find="(t_near <= t_far)",
        replace="(t_near < t_far)",
        tests="ray_box_interval",
        why="the box is closed: a ray grazing an edge or crossing a flat box (t_near = t_far) "
        "still hits it",
    ),
    Mutant(
        name="fresh_box_no_clip_at_zero",
        module=M,
        function="ray_box_interval",
        find="lo[:, 2]), zero)",
        replace="lo[:, 2]), lo[:, 2])",
        tests="ray_box_interval",
        why="the interval is clipped to t >= 0: a ray starting inside has t_near = 0, not a "
        "negative t behind its origin",
    ),
    Mutant(
        name="fresh_box_world_distance",
        module=M,
        function="ray_box_interval",
        find="inv = torch.reciprocal(directions)",
        replace="inv = torch.reciprocal(directions / directions.norm(dim=-1, keepdim=True))",
        tests="ray_box_interval",
        why="t is the ray parameter of o + t d, not a world distance: normalising d gives "
        "wrong t for directions that are not unit",
    ),
    Mutant(
        name="fresh_grid_node_centred",
        module=M,
        function="sample_grid",
        find="u = torch.nan_to_num(uvw, nan=0.0) * sizes - 0.5",
        replace="u = torch.nan_to_num(uvw, nan=0.0) * (sizes - 1)",
        tests="sample_grid",
        why="align_corners=True: values at the box corners instead of the voxel centres",
    ),
    Mutant(
        name="fresh_grid_nan_not_zero",
        module=M,
        function="sample_grid",
        find="return torch.where(finite, terms.sum(-1 - (grid.ndim == 4)), 0)",
        replace="return terms.sum(-1 - (grid.ndim == 4))",
        tests="sample_grid",
        why="NaN coordinates give 0, not the value at the clamped corner",
    ),
    Mutant(
        name="fresh_march_ds_not_world",
        module=M,
        function="march_box",
        find="ds = dt * d.norm(dim=-1)",
        replace="ds = dt",
        tests="march_box",
        why="the segment's world length is |d| dt: with a direction of length 1e-4 or 1e2 "
        "the optical depth comes out wrong",
    ),
    Mutant(
        name="fresh_march_stop_at_equal",
        module=M,
        function="march_box",
        find="active = hit & (transmittance >= min_transmittance)",
        replace="active = hit & (transmittance > min_transmittance)",
        tests="march_box",
        why="a ray stops once T has dropped *below* min_transmittance: with the default 0 an "
        "opaque ray keeps counting its samples",
    ),
    Mutant(
        name="fresh_march_jitter_per_step",
        module=M,
        function="march_box",
        find="t = t_near + (i + xi) * dt",
        replace="t = t_near + (i + (torch.rand(n, generator=generator, dtype=torch.float64)"
        ".to(**like) if jitter else xi)) * dt",
        tests="march_box",
        why="jitter draws one offset per ray, the same for all its steps, not a fresh one per step",
    ),
    Mutant(
        name="fresh_segment_inf_times_zero",
        module=M,
        function="segment_integral",
        find="x = torch.where((length == 0) | (sigma == 0), 0, sigma * length)",
        replace="x = sigma * length",
        tests="segment_integral",
        why="sigma = inf over length 0 (or sigma 0 over an endless step) is 0 * inf = NaN, "
        "not 'no step' / 'no medium'",
    ),
    Mutant(
        name="fresh_hg_one_denominator",
        module=M,
        function="henyey_greenstein",
        find="g >= 0, (1 - g) ** 2",
        replace="g > -2, (1 - g) ** 2",
        tests="henyey_greenstein",
        why="(1 - g)^2 + 2 g (1 - cos) has terms of both signs for g < 0: at g -> -1, "
        "cos = -1 it cancels and loses every digit",
    ),
    Mutant(
        name="fresh_shadow_from_point_not_box",
        module=M,
        function="shadow_transmittance",
        find="offset = rel + (t_near + (k + 0.5) * dt)[:, None] * light",
        replace="offset = rel + ((k + 0.5) * dt)[:, None] * light",
        tests="shadow_transmittance",
        why="a point outside the box is shadowed by the part of the light ray inside the "
        "box, which starts at t_near, not at the point",
    ),
    Mutant(
        name="fresh_trace_tolerance_without_d",
        module=M,
        function="sphere_trace",
        find="radius <= epsilon * t * length",
        replace="radius <= epsilon * t",
        tests="sphere_trace",
        why="t is a ray parameter: the footprint's world size is epsilon t |d|; a direction "
        "of length 1e-4 or 1e2 gets a tolerance 1e4 times too tight or too loose",
    ),
    Mutant(
        name="fresh_march_flat_axis_nan",
        module=M,
        function="march_box",
        find="local = torch.where(size > 0, offset / size, 0.5)",
        replace="local = offset / size",
        tests="march_box_extremes",
        why="a flat box (size 0 on an axis) gives 0 / 0 = NaN box coordinates there, which "
        "sample_grid reads as 0: the medium of a flat box vanishes for rays in its plane",
    ),
    Mutant(
        name="fresh_shadow_flat_axis_nan",
        module=M,
        function="shadow_transmittance",
        find="torch.where(size > 0, offset / size, 0.5)",
        replace="offset / size",
        tests="shadow_transmittance",
        why="0 / 0 = NaN box coordinates on a flat axis read as density 0: no shadow in a flat box",
    ),
    Mutant(
        name="fresh_scatter_grid_absolute_points",
        module=M,
        function="march_single_scatter",
        find="local = torch.where(box_max > box_min, (points - box_min) / size, 0.5)",
        replace="local = torch.where(box_max > box_min, points / size, 0.5)",
        tests="single_scatter",
        why="the source reads a grid at points / size, forgetting box_min: right only for a box "
        "at the origin",
    ),
    Mutant(
        name="fresh_walk_samples_after_exit",
        module=M,
        function="voxel_walk",
        find="sample = active & ~skip",
        replace="sample = ~skip",
        tests="voxel_walk",
        why="rays that have left the grid keep 'reading' a voxel while others still walk: "
        "samples overcounts (and an inf voxel would give inf * 0 = NaN)",
    ),
    Mutant(
        name="fresh_trace_hit_past_t_max",
        module=M,
        function="sphere_trace",
        find="hit = active & ~fail & (radius <= epsilon * t * length)",
        replace="hit = valid & ~fail & (radius <= epsilon * t * length)",
        tests="sphere_trace",
        why="the hit test runs on rays that already went past t_max: one that lands on a "
        "surface beyond t_max becomes a hit",
    ),
    Mutant(
        name="fresh_trace_zero_direction_valid",
        module=M,
        function="sphere_trace",
        find="& (length > 0)\n        & torch.isfinite(length)",
        replace="& torch.isfinite(length)",
        tests="sphere_trace",
        why="a zero direction never moves: starting on a surface, |f| = 0 <= epsilon t |d| = 0 "
        "makes it a hit, though a zero direction is no ray",
    ),
]
