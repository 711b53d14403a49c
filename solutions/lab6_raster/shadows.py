"""Task 5: raster against ray-traced primary visibility (``traced_visibility``) and
hybrid shadows: ``world_positions`` from the visibility buffer, ``shadow_epsilon``,
shadow rays by ray tracing (``hybrid_shadows``) and the fully traced frame
(``traced_shadows``).
"""

from __future__ import annotations

import math

import torch

from course.core.camera import Camera, primary_rays
from course.core.types import Mesh
from course.given.lab6 import sun_direction, traced_hits

from .shading import interpolate


def traced_visibility(trace, camera: Camera, device=None, dtype=torch.float32):
    """Ray-traced primary visibility: (H, W) int64, the triangle each pixel's primary ray
    hits first (-1 where it misses), for the same pixel centres as the rasterizer.

    trace: ``trace(origins, directions, t_min, t_max) -> hits`` (see the lab's docstring);
    camera: the view; device, dtype: of the rays (``course.core.camera.primary_rays``).

    Errors: TypeError naming ``trace`` unless it is callable, or ``camera`` unless it is a
    Camera.

    Hints: ``course.core.camera.primary_rays(camera, device, dtype)``; the provided ``traced_hits``
    calls the tracer and checks its answer.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    if not callable(trace):
        raise TypeError(f"trace: expected a callable, got {type(trace).__name__}")
    if not isinstance(camera, Camera):
        raise TypeError(f"camera: expected course.core.camera.Camera, got {type(camera).__name__}")
    # BEGIN SOLUTION (task 5)
    rays = primary_rays(camera, device=device, dtype=dtype)
    _, triangle = traced_hits(trace, rays.origins, rays.directions, rays.t_min, rays.t_max)
    return triangle.reshape(camera.height, camera.width)
    # END SOLUTION


def world_positions(mesh: Mesh, face, bary):
    """(H, W, 3) world-space points ``sum_i bary_i * v_i`` of the visible faces (0 where
    ``face == -1``): the G-buffer's positions, reconstructed from the visibility buffer.

    Hints: ``interpolate``.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    if not isinstance(mesh, Mesh):
        raise TypeError(f"mesh: expected course.core.types.Mesh, got {type(mesh).__name__}")
    # BEGIN SOLUTION (task 5)
    return interpolate(mesh.vertices, mesh.faces, face, bary)
    # END SOLUTION


def shadow_epsilon(mesh: Mesh) -> float:
    """The ``t_min`` of shadow rays (with unit directions), relative to the scene.

    ``1e-4 * extent + 8 * eps * max|x|``: extent is the diagonal of the mesh's bounding box
    (the scene's scale), ``max|x|`` its largest absolute coordinate and eps the machine
    epsilon of its dtype. A reconstructed point is off the true surface by a few ulps of its
    coordinates; a shadow ray starting there must not hit its own triangle (shadow acne),
    and far from the origin the ulps grow with the coordinates. Too large an offset lets
    light leak through thin occluders in contact: scale, not a constant.

    Returns 0.0 when no vertex is finite.

    Hints: compute in float64; ``torch.finfo(mesh.dtype).eps``; ignore non-finite vertices.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    if not isinstance(mesh, Mesh):
        raise TypeError(f"mesh: expected course.core.types.Mesh, got {type(mesh).__name__}")
    # BEGIN SOLUTION (task 5)
    v = mesh.vertices.to(torch.float64)
    v = v[torch.isfinite(v).all(-1)]
    if v.numel() == 0:
        return 0.0
    extent = float((v.amax(0) - v.amin(0)).norm())
    return 1e-4 * extent + 8 * torch.finfo(mesh.dtype).eps * float(v.abs().max())
    # END SOLUTION


def _shadow_rays(trace, mesh: Mesh, points, hit, light):
    """(N,) bool: which of the points (N, 3) marked ``hit`` see something toward ``light``.

    Write this function for ``hybrid_shadows`` and ``traced_shadows``: shadow rays from the
    points with ``hit``, ``t_min = shadow_epsilon(mesh)``, ``t_max = inf``, through
    ``traced_hits``.
    """
    # BEGIN SOLUTION (task 5)
    origins = points[hit]
    directions = light.expand_as(origins).contiguous()
    n = origins.shape[0]
    t_min = torch.full((n,), shadow_epsilon(mesh), dtype=origins.dtype, device=origins.device)
    t_max = torch.full((n,), math.inf, dtype=origins.dtype, device=origins.device)
    _, blocker = traced_hits(trace, origins, directions, t_min, t_max)
    shadowed = torch.zeros(hit.shape, dtype=torch.bool, device=points.device)
    shadowed[hit] = blocker >= 0
    return shadowed
    # END SOLUTION


def hybrid_shadows(trace, mesh: Mesh, face, bary, light_direction):
    """Shadows of a rasterized frame by ray tracing: (H, W) bool, True where the visible
    point's shadow ray toward the directional light hits any triangle (False where
    ``face == -1``).

    trace: the tracer (the lab's docstring); mesh: the scene; face, bary: ``rasterize_mesh``'s
    output; light_direction: (3,) toward the light. Primary visibility costs one raster pass
    instead of one ray per pixel; positions come from ``world_positions``; shadow rays start
    at ``t_min = shadow_epsilon(mesh)`` (unit directions) with ``t_max = inf``.

    Errors: TypeError naming ``trace`` unless it is callable; ValueError or TypeError naming
    ``light_direction`` (not a (3,) float tensor on the mesh's device), or ``face`` /
    ``bary`` as in ``shade``.

    Hints: ``world_positions``, then ``_shadow_rays`` on the flattened pixels.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    if not callable(trace):
        raise TypeError(f"trace: expected a callable, got {type(trace).__name__}")
    light = sun_direction(light_direction, mesh.vertices)  # unit, toward the light
    # BEGIN SOLUTION (task 5)
    points = world_positions(mesh, face, bary)
    return _shadow_rays(trace, mesh, points.reshape(-1, 3), face.reshape(-1) >= 0, light).reshape(
        face.shape
    )
    # END SOLUTION


def traced_shadows(trace, mesh: Mesh, camera: Camera, light_direction):
    """The fully ray-traced counterpart of ``hybrid_shadows``: ``(face (H, W) int64,
    shadowed (H, W) bool)``, the primary rays of ``camera`` traced too (hit points
    ``o + t d``), shadow rays as in ``hybrid_shadows``. Rays in the mesh's dtype and device.

    Hints: ``primary_rays``, ``traced_hits``, hit points ``o + t d`` (use t = 0 for misses to
    avoid ``inf * 0``), then ``_shadow_rays``.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    if not callable(trace):
        raise TypeError(f"trace: expected a callable, got {type(trace).__name__}")
    if not isinstance(mesh, Mesh):
        raise TypeError(f"mesh: expected course.core.types.Mesh, got {type(mesh).__name__}")
    light = sun_direction(light_direction, mesh.vertices)  # unit, toward the light
    # BEGIN SOLUTION (task 5)
    rays = primary_rays(camera, device=mesh.device, dtype=mesh.dtype)
    t, triangle = traced_hits(trace, rays.origins, rays.directions, rays.t_min, rays.t_max)
    hit = triangle >= 0
    points = rays.origins + torch.where(hit, t, 0)[:, None] * rays.directions
    shadowed = _shadow_rays(trace, mesh, points, hit, light)
    shape = (camera.height, camera.width)
    return triangle.reshape(shape), shadowed.reshape(shape)
    # END SOLUTION
