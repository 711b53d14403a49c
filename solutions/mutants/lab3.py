"""Lab 3 mutants: typical mistakes in organising a Whitted tracer, each applied to the
reference solution. Every one must lose points on the tests its ``tests`` expression selects.

Only mistakes the grader can see are listed: a wrong image against the float64 reference,
a wrong count of rays, lost work, a graph break under torch.compile, or a wrong layout.
"""

from course.grading.mutants import Mutant

M = "lab3_wavefront"

MUTANTS = [
    Mutant(name="shadow_ray_past_the_light", module=M, function="_light_rays",
           find="t_max = torch.cat((dist - light_offset,",
           replace="t_max = torch.cat((dist + math.inf,", tests="shade_direct",
           why="the shadow ray has no t_max at the point light: it runs on past the lamp and "
               "the ceiling behind it shadows everything"),
    Mutant(name="no_normal_offset", module=M, function="offset_origins",
           find="return points + normals * (offset_scale(points.dtype) * scale)",
           replace="return points", tests="offset_origins",
           why="secondary rays start exactly at the rounded hit point: half of them hit their "
               "own triangle at t ~ 0 (shadow acne)"),
    Mutant(name="offset_not_scaled_with_magnitude", module=M, function="offset_origins",
           find="scale = points.abs().amax(dim=1, keepdim=True).clamp(min=1)",
           replace="scale = 1.0", tests="offset_origins",
           why="a fixed offset vanishes in the rounding of coordinates near 1e5: acne far from "
               "the origin"),
    Mutant(name="normal_faces_away_from_the_ray", module=M, function="surface_at",
           find="normals = torch.where((dot(normals, directions) > 0)[:, None], -normals, normals)",
           replace="normals = torch.where((dot(normals, directions) < 0)[:, None], -normals, "
                   "normals)", tests="surface_at",
           why="the normal points away from the incoming ray: origins are offset *into* the "
               "surface and reflected rays start behind the mirror"),
    Mutant(name="reflect_through_the_normal", module=M, function="reflect",
           find="return normalize(directions - 2 * dot(directions, normals)[:, None] * normals)",
           replace="return normalize(2 * dot(directions, normals)[:, None] * normals - directions)",
           tests="reflect",
           why="reflects about the normal line instead of the surface's plane: the ray goes "
               "back into the mirror"),
    Mutant(name="shadow_rays_below_the_horizon", module=M, function="shade_direct",
           find="row, light = (cos > 0).nonzero(as_tuple=True)",
           replace="row, light = (cos > -2).nonzero(as_tuple=True)", tests="shade_direct",
           why="traces a shadow ray toward every light, also those behind the surface that "
               "cannot contribute: the same image for more work (model only what is needed)"),
    Mutant(name="specular_not_normalised", module=M, function="shade_direct",
           find="lobe = ((s + 8) / (8 * math.pi))[:, None]",
           replace="lobe = (s * 0 + 1)[:, None]", tests="shade_direct",
           why="drops the (s + 8) / (8 pi) normalisation of the Blinn-Phong lobe: highlights "
               "too bright by a factor of 8 pi / (s + 8)"),
    Mutant(name="point_light_without_falloff", module=M, function="_light_rays",
           find="irradiance = torch.cat((scene.point_intensities / (dist**2)[..., None],",
           replace="irradiance = torch.cat((scene.point_intensities * (dist**0)[..., None],",
           tests="shade_direct",
           why="forgets the inverse-square law: E = I / dist^2"),
    Mutant(name="whitted_depth_off_by_one", module=M, function="render_whitted",
           find="for depth in range(max_depth + 1):", replace="for depth in range(max_depth):",
           tests="render_whitted",
           why="one bounce too few: max_depth counts reflections after the primary ray"),
    Mutant(name="whitted_throughput_not_multiplied", module=M, function="render_whitted",
           find="throughput * scene.kr[material.clamp(min=0)], 0.0)",
           replace="scene.kr[material.clamp(min=0)], 0.0)", tests="render_whitted",
           why="the second reflection is weighted by one mirror's kr instead of the product "
               "of both"),
    Mutant(name="wavefront_drops_escaped_rays", module=M, function="render_wavefront",
           find="image.index_add_(0, pixel[~hit], throughput[~hit] * scene.background)",
           replace="pass", tests="render_wavefront",
           why="compaction drops the rays that missed before they add the background: the sky "
               "and its reflections go black"),
    Mutant(name="wavefront_compacts_by_slicing", module=M, function="render_wavefront",
           find="d = reflect(d[mirror], normals[mirror])",
           replace="d = reflect(d, normals)[: int(mirror.sum())]", tests="render_wavefront",
           why="compacts the spawned rays by taking the first k instead of the mirror hits: "
               "reflected rays leave from the wrong pixels' hits"),
    Mutant(name="wavefront_sort_forgets_pixels", module=M, function="render_wavefront",
           find="pixel, d, throughput = pixel[order], d[order], throughput[order]",
           replace="d, throughput = d[order], throughput[order]", tests="render_wavefront",
           why="sorts the shading queue by material but not its pixel indices: every ray's "
               "light lands on another pixel"),
    Mutant(name="wavefront_depth_limit_off_by_one", module=M, function="render_wavefront",
           find="for depth in range(max_depth + 1):", replace="for depth in range(max_depth):",
           tests="render_wavefront",
           why="one bounce too few: bounces 0 .. max_depth are max_depth + 1 trace stages"),
    Mutant(name="uber_normal_not_flipped", module=M, function="_uber_shadow_rays",
           find="normal = torch.where((dot(normal, d) > 0)[:, None], -normal, normal)",
           replace="normal = normal", tests="render_uber",
           why="the uber step keeps the triangle's winding: a ray that meets a back face "
               "(from inside a box) is offset through the surface and lit from outside"),
    Mutant(name="uber_step_compacts", module=M, function="_uber_shadow_rays",
           find="hit = alive & (triangle >= 0)",
           replace="hit = alive & (triangle >= 0)\n    _ = hit.nonzero()", tests="render_uber",
           why="a data-dependent shape (nonzero) inside the uber step: no longer a kernel of "
               "fixed-size buffers"),
    Mutant(name="persistent_loses_queued_work", module=M, function="render_persistent",
           find="queue = {key: torch.cat((queue[key][head:], spawned[key])) for key in queue}",
           replace="queue = {key: spawned[key] for key in queue}", tests="render_persistent",
           why="the new queue keeps only the freshly spawned rays: items that were still "
               "waiting for a free slot are lost"),
    Mutant(name="persistent_depth_off_by_one", module=M, function="render_persistent",
           find="mirror = _is_mirror(scene, material) & (depth[hit] < max_depth)",
           replace="mirror = _is_mirror(scene, material) & (depth[hit] <= max_depth)",
           tests="render_persistent",
           why="spawns a reflection at the depth limit: one bounce too many"),
    Mutant(name="float4_index_by_position", module=M, function="intersect_layout",
           find="index = float_as_index(layout[\"triangles\"][cols, 0, 3])   # the w word",
           replace="index = torch.arange(f, device=like.device)[cols]",
           tests="intersect_layout",
           why="reports the slot instead of the index stored in w: wrong after reordering"),
    Mutant(name="woop_translation_sign", module=M, function="layout_woop",
           find="translation = -(inverse @ c[:, 0, :, None])",
           replace="translation = inverse @ c[:, 0, :, None]", tests="layout",
           why="the affine map's translation must send v0 to the origin: -F^-1 v0"),
]
