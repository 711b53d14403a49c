"""The tracer callable the labs take: :func:`trace_bvh`, closest or any hit in a mesh.

It walks the flat BVH of ``course.kernels.flat_bvh`` (built once per scene and cached) with
the fused Triton kernel of ``course.kernels.triton_tracer`` on CUDA and the torch walk of
``flat_bvh`` elsewhere. It sits above both, so neither module imports the other's walk.
"""

from __future__ import annotations

import math

from course.core.types import Hits
from course.kernels.flat_bvh import check_rays, flat_bvh_for, trace_flat_torch

__all__ = ["trace_bvh"]


def trace_bvh(scene, origins, directions, t_min=0.0, t_max=math.inf, any_hit: bool = False) -> Hits:
    """Closest (or any) hit of each ray in ``scene``: the lab's tracer callable.

    scene: a ``WhittedScene`` (or anything with ``vertices`` (V, 3) float and ``faces``
        (F, 3) int64); its BVH is built on first use and cached (``flat_bvh_for``).
    origins, directions: (N, 3) float (traced in float32; directions need not be unit);
    t_min, t_max: numbers or (N,) tensors, the closed interval of accepted hits.
    any_hit: stop at the first hit found (shadow rays): ``triangle >= 0`` says "occluded".
    Returns float32 ``Hits`` on the rays' device. Runs the Triton kernel on CUDA and the
    torch traversal elsewhere; both follow the contract of
    ``course.kernels.flat_bvh``'s docstring: the hits of a brute-force float32
    Möller–Trumbore over every triangle (the box tests are conservative and lose none), which
    is not watertight: a ray through a shared edge or vertex may miss all the triangles
    around it (about 10% of rays aimed exactly at a mesh's vertices or edges).
    """
    if not isinstance(any_hit, bool):
        raise TypeError(f"any_hit: expected a bool, got {type(any_hit).__name__}")
    check_rays(origins, directions, t_min, t_max)
    bvh = flat_bvh_for(scene)
    if origins.device.type == "cuda":
        from course.kernels import triton_tracer

        if triton_tracer.triton_available() and not triton_tracer.interpreting():
            return triton_tracer.trace_flat_triton(
                bvh.to(origins.device), origins, directions, t_min, t_max, any_hit=any_hit
            )
    return trace_flat_torch(bvh, origins, directions, t_min, t_max, any_hit=any_hit)
