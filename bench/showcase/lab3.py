"""Lab 3 showcase: Whitted ray tracing with shadows and two mirror bounces.

Left, the Cornell box whose tall box is a mirror, lit by one point light below the ceiling
(its reflection shows the red wall and the short glossy box); right, the Stanford bunny
(69K triangles) on a mirror floor under a sun and a point light. Rendered by the lab
module passed in (its ``render_wavefront``: separate kernels with compaction, sorted by
material), so a student's labs/ renders too. The tracer is ``course.kernels.trace.trace_bvh``
(a BVH) where it exists; without it only the Cornell box is drawn (brute force over 69K
triangles per ray is too slow for a gallery).
"""

from __future__ import annotations

import time

import torch

from course.core.camera import primary_rays
from course.given.lab3 import trace_brute_force, whitted_camera, whitted_scene

try:
    from course.kernels.trace import trace_bvh
except ImportError:  # pragma: no cover - a checkout without the GPU track's BVH
    trace_bvh = None


def render(lab, device, size: int = 256):
    """``(image (size, 2 size + 2, 3) float linear RGB, info)`` for the gallery (``(size,
    size, 3)``, the Cornell box alone, without the BVH)."""
    device = torch.device(device)
    names = ("cornell_mirror", "bunny_mirror") if trace_bvh is not None else ("cornell_mirror",)
    trace = trace_bvh or trace_brute_force
    images, info = [], {"tracer": trace.__name__, "max_depth": 2}
    for name in names:
        scene = whitted_scene(name, device=device)
        rays = primary_rays(whitted_camera(name, size, size), device=device)
        trace(
            scene,
            rays.origins[:1],
            rays.directions[:1],
            torch.zeros(1, device=device),
            torch.full((1,), float("inf"), device=device),
            False,
        )  # builds the BVH
        start = time.perf_counter()
        image, stats = lab.render_wavefront(
            scene, rays.origins, rays.directions, trace, 2, sort_by_material=True
        )
        if device.type == "cuda":
            torch.cuda.synchronize(device)
        info[f"{name}_seconds"] = time.perf_counter() - start
        info[f"{name}_rays"] = sum(stats["closest_rays"]) + sum(stats["shadow_rays"])
        images.append(image.reshape(size, size, 3).float().cpu())
    gap = torch.ones(size, 2, 3)
    return torch.cat([x for image in images for x in (image, gap)][:-1], dim=1), info
