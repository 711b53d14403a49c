"""Lab 5 mutants: typical mistakes in the froxel pipeline, each applied to the reference
solution. Every one must lose points on the tests its ``tests`` expression selects.
"""

from course.grading.mutants import Mutant

M = "lab5_froxel"

MUTANTS = [
    Mutant(
        name="linear_slicing",
        module=M,
        function="slice_depths",
        find="z = near * torch.exp(k / slices * math.log(far / near))",
        replace="z = near + (far - near) * k / slices",
        tests="slice_depths",
        why="linear depth slices: froxels near the camera are long splinters, far ones "
        "flat plates; the slicing no longer follows perspective",
    ),
    Mutant(
        name="froxel_y_up",
        module=M,
        function="world_to_froxel",
        find="y = (1 - ndc_y) * grid.camera.height",
        replace="y = (1 + ndc_y) * grid.camera.height",
        tests="world_to_froxel",
        why="tile rows counted from the bottom of the screen (OpenGL's window origin) while "
        "images and froxel volumes start at the top",
    ),
    Mutant(
        name="g_not_scattering_weighted",
        module=M,
        function="media_at",
        find="g_weighted = g_weighted + w * (sigma_s.mean() * medium.g)",
        replace="g_weighted = g_weighted + w * medium.g",
        tests="media_at",
        why="phase g averaged by density, not by scattering: a thin strongly-scattering "
        "medium's g loses to a thick absorbing one's",
    ),
    Mutant(
        name="voxelize_ignores_jitter",
        module=M,
        function="voxelize",
        find="coords = froxel_sample_coords(grid, jitter, dtype, device)",
        replace="coords = froxel_sample_coords(grid, 0.5, dtype, device)",
        tests="voxelize",
        why="the V-buffer always samples the slice's middle: temporal jitter has nothing "
        "to average",
    ),
    Mutant(
        name="hg_wrong_sign",
        module=M,
        function="henyey_greenstein",
        find="cos_theta = cos_theta.clamp(-1, 1)\n    # Non-negative",
        replace="cos_theta = -cos_theta.clamp(-1, 1)\n    # Non-negative",
        tests="henyey_greenstein",
        why="cos theta measured between the view ray and the light's travel direction: "
        "forward scattering turns into back scattering",
    ),
    Mutant(
        name="schlick_no_clamp",
        module=M,
        function="schlick_phase",
        find="k = (1.55 * g - 0.55 * g**3).clamp(-SCHLICK_K_MAX, SCHLICK_K_MAX)",
        replace="k = 1.55 * g - 0.55 * g ** 3",
        tests="schlick_phase",
        why="k = 1.55 g - 0.55 g^3 passes 1 near g = 0.999: the phase function blows up",
    ),
    Mutant(
        name="tile_list_drops_border_lights",
        module=M,
        function="cull_lights",
        find="cols = (left >= -r) & (right_d >= -r)\n        rows = (top >= -r) & (bottom >= -r)",
        replace="cols = (left >= 0) & (right_d >= 0)\n        rows = (top >= 0) & (bottom >= 0)",
        tests="cull_lights",
        why="a light is listed only in the tile holding its centre: spheres straddling "
        "tile borders light one tile and leave seams in the next",
    ),
    Mutant(
        name="shadow_volume_unit_steps",
        module=M,
        function="transmittance_volume",
        find="torch.cumsum(sigma * step, -1)",
        replace="torch.cumsum(sigma, -1)",
        tests="transmittance_volume",
        why="optical depth summed per sample without the step length: shadows depend on "
        "the volume's resolution",
    ),
    Mutant(
        name="history_never_rejected",
        module=M,
        function="reproject",
        find="valid = ((prev >= 0) & (prev <= limits)).all(-1)",
        replace="valid = torch.ones(prev.shape[:-1], dtype=torch.bool, device=prev.device)",
        tests="reproject",
        why="history from outside the previous frustum is kept: the clamped border "
        "smears in as ghosts after a camera move",
    ),
    Mutant(
        name="slice_integral_unstable",
        module=M,
        function="slice_integral",
        find="phi = torch.where(small, 1 - tau / 2 + tau * tau / 6, -torch.expm1(-safe) / safe)",
        replace="phi = (1 - torch.exp(-tau)) / tau",
        tests="slice_integral",
        why="(S - S e^(-sigma D)) / sigma as written: 0/0 = NaN in empty froxels and "
        "cancellation for thin ones",
    ),
    Mutant(
        name="transmittance_before_integral",
        module=M,
        function="integrate_froxels",
        find="radiance = torch.cumsum(in_front[..., None] * piece, 0)",
        replace="radiance = torch.cumsum(torch.exp(-behind)[..., None] * piece, 0)",
        tests="integrate_froxels",
        why="transmittance updated before adding the slice: its own medium absorbs the "
        "slice's light twice",
    ),
    Mutant(
        name="naive_integration",
        module=M,
        function="integrate_froxels",
        find="piece, _ = slice_integral(source, extinction, lengths)",
        replace="piece = source * lengths[..., None]",
        tests="integrate_froxels",
        why="the naive S D per slice (the talk's light leak): thick slices emit more than "
        "the medium can, and the result depends on the slice count",
    ),
    Mutant(
        name="trilinear_half_froxel_off",
        module=M,
        function="apply_froxels",
        find="coords = torch.stack([z + 0.5, rows.expand(h, w), cols.expand(h, w)], -1)",
        replace="coords = torch.stack([z, rows.expand(h, w), cols.expand(h, w)], -1)",
        tests="apply_froxels",
        why="slice boundaries treated as voxel centres: the lookup reads half a froxel "
        "too near, so fog in front of a wall thins",
    ),
    Mutant(
        name="point_lights_unattenuated",
        module=M,
        function="light_froxels",
        find="e = e * light_transmittance(extinction, lo, hi, p, light.position,",
        replace="e = e * 1 or light_transmittance(extinction, lo, hi, p, light.position,",
        tests="point_light_in_fog",
        why="point lights shine through the fog unattenuated (only the sun and spots get "
        "volumetric shadows): a lamp inside fog is far too bright",
    ),
    Mutant(
        name="light_march_unit_steps",
        module=M,
        function="light_transmittance",
        find="return torch.exp(-depth * (span * rel.norm(dim=-1) / steps))",
        replace="return torch.exp(-depth * span / steps)",
        tests="light_transmittance or point_light_in_fog",
        why="optical depth summed over the segment's parameter, not its length: the "
        "attenuation depends on the distance's units, not the medium",
    ),
    Mutant(
        name="volumes_over_the_frustum",
        module=M,
        function="light_froxels",
        find="bounds = volume_bounds(scene, grid) if volumetric_shadows and scene.lights else None",
        replace="bounds = frustum_bounds(grid) if volumetric_shadows and scene.lights else None",
        tests="sun_in_fog_box_defaults",
        why="the extinction volume spans the whole frustum: its voxels miss a small fog "
        "box, which then casts no volumetric shadow on itself",
    ),
    Mutant(
        name="jitter_not_shared",
        module=M,
        function="render_froxels",
        find="        vbuffer,\n        jitter,\n        phase=phase,",
        replace="        vbuffer,\n        0.5,\n        phase=phase,",
        tests="render_froxels_temporal",
        why="material sampled at the Halton offset but lighting at the slice's middle: "
        "scattering and light meet at different points",
    ),
    # Fresh mistakes, written from the docstrings
    Mutant(
        name="slice_ends_not_pinned",
        module=M,
        function="slice_depths",
        find="z[0], z[-1] = near, far",
        replace="z = z.clone()",
        tests="slice_depths",
        why="the docstring promises z_0 = near and z_slices = far exactly; exp(log) may "
        "miss far by a rounding step",
    ),
    Mutant(
        name="slices_in_float32",
        module=M,
        function="slice_depths",
        find="k = torch.arange(slices + 1, dtype=torch.float64, device=device)",
        replace="k = torch.arange(slices + 1, dtype=dtype, device=device)",
        tests="slice_depths",
        why="computed in the output dtype instead of float64 rounded once: float32 depths "
        "are off by several ulps",
    ),
    Mutant(
        name="eye_plane_not_nan",
        module=M,
        function="world_to_froxel",
        find="safe = torch.where(depth > 0, depth, math.nan)",
        replace="safe = torch.where(depth >= 0, depth, math.nan)",
        tests="world_to_froxel",
        why="a point on the eye's plane (view depth exactly 0) must give NaN, not inf",
    ),
    Mutant(
        name="froxel_xy_swapped",
        module=M,
        function="froxel_to_world",
        find="_view_dirs(grid, coords[..., 0], coords[..., 1],",
        replace="_view_dirs(grid, coords[..., 1], coords[..., 0],",
        tests="world_to_froxel",
        why="coords are (x, y, z) = (column, row, slice), not (row, column): on a non-square "
        "grid the points land in the wrong tile",
    ),
    Mutant(
        name="slice_length_along_axis",
        module=M,
        function="integrate_froxels",
        find="lengths = ((z[1:] - z[:-1])[:, None, None] * stretch).to(dtype)",
        replace="lengths = ((z[1:] - z[:-1])[:, None, None] * torch.ones_like(stretch)).to(dtype)",
        tests="integrate_froxels",
        why="a slice is (z_{k+1} - z_k) |dir| long along the ray, not its view-depth "
        "thickness: off-centre columns are too thin",
    ),
    Mutant(
        name="stretch_at_tile_corner",
        module=M,
        function="integrate_froxels",
        find='jj, ii = torch.meshgrid(j, i, indexing="ij")',
        replace='jj, ii = torch.meshgrid(j - 0.5, i - 0.5, indexing="ij")',
        tests="integrate_froxels",
        why="the ray goes through the tile centre (i + 0.5, j + 0.5), not its corner",
    ),
    Mutant(
        name="transmittance_in_front_of_slice",
        module=M,
        function="integrate_froxels",
        find="return radiance, torch.exp(-behind)",
        replace="return radiance, in_front",
        tests="integrate_froxels",
        why="the transmittance is to the far boundary of each slice, so it includes the "
        "slice's own medium",
    ),
    Mutant(
        name="reproject_no_slice_offset",
        module=M,
        function="reproject",
        find="[0.0, 0.0, slice_offset(grid, 0.5) - 0.5]",
        replace="[0.0, 0.0, 0.0]",
        tests="reproject",
        why="history voxels sit at z = k + slice_offset, not k + 0.5: reading them as if "
        "they did shifts history by a fraction of a slice",
    ),
    Mutant(
        name="blend_alpha_on_history",
        module=M,
        function="temporal_blend",
        find="history + alpha * (current - history)",
        replace="current + alpha * (history - current)",
        tests="temporal_blend",
        why="alpha is the weight of the current frame, not of the history",
    ),
    Mutant(
        name="blend_alpha_one_rejected",
        module=M,
        function="temporal_blend",
        find="not 0 < alpha <= 1",
        replace="not 0 < alpha < 1",
        tests="temporal_blend",
        why="alpha in (0, 1] includes 1 (no history at all)",
    ),
    Mutant(
        name="zero_length_inf_extinction_nan",
        module=M,
        function="slice_integral",
        find="tau = torch.where(length == 0, 0, extinction * finite)",
        replace="tau = extinction * finite",
        tests="slice_integral",
        why="sigma_t = inf over D = 0 is no optical depth: (0, 1), not NaN",
    ),
    Mutant(
        name="negative_length_accepted",
        module=M,
        function="slice_integral",
        find='for name, x in (("extinction", extinction), ("length", length)):',
        replace='for name, x in (("extinction", extinction),):',
        tests="slice_integral",
        why="a negative length must raise ValueError naming length (it would give a "
        "transmittance above 1)",
    ),
    Mutant(
        name="shadow_plane_at_sphere",
        module=M,
        function="build_shadow_map",
        find="origin = c + (lift + 1.0) * toward",
        replace="origin = c + radius * toward",
        tests="shadow_map",
        why="the shadow map's rays start on the sphere's light-side plane: an occluder "
        "floating above the region (a roof, a cloud of boxes) lies behind them and casts "
        "no shadow",
    ),
    Mutant(
        name="texel_corner_rays",
        module=M,
        function="build_shadow_map",
        find="texel = (torch.arange(resolution, dtype=dtype, device=device) + 0.5) / resolution",
        replace="texel = torch.arange(resolution, dtype=dtype, device=device) / resolution",
        tests="shadow_map",
        why="each texel traces its ray from its corner, not its centre: the whole shadow "
        "shifts by half a texel against the lookup",
    ),
    Mutant(
        name="shadow_bias_one_texel",
        module=M,
        function="shadow_lookup",
        find="bias = 4 * shadow_map.extent / res",
        replace="bias = 2 * shadow_map.extent / res",
        tests="shadow_map",
        why="a texel is 2 extent / R wide: a bias of one texel where two are promised "
        "lets sloped lit faces shadow themselves (acne)",
    ),
    Mutant(
        name="light_volume_default_depth_samples",
        module=M,
        function="light_froxels",
        find="transmittance_volume(extinction, lo, hi, light, resolution, 4 * resolution)",
        replace="transmittance_volume(extinction, lo, hi, light, resolution)",
        tests="light_froxels",
        why="the sun's and spots' transmittance volumes keep the default 2 resolution "
        "depth samples: a fog volume's faces cost up to a full step of optical depth",
    ),
    Mutant(
        name="media_g_nan_without_scattering",
        module=M,
        function="media_at",
        find="g = torch.where(weight > 0, g_weighted / torch.where(weight > 0, weight, 1.0), 0.0)",
        replace="g = g_weighted / weight",
        tests="media_at",
        why="g divided by the scattering weight everywhere: 0 / 0 = NaN where nothing "
        "scatters (no media, absorbing fog), and the NaN spreads through the phase function",
    ),
]
