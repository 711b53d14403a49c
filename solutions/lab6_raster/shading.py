"""Task 4: perspective-correct barycentrics (``perspective_correct``, ``resolve_pixels``),
the whole pipeline (``rasterize_mesh``), attributes at pixels (``interpolate``) and
flat/smooth Lambert shading (``shade``).
"""

from __future__ import annotations

import torch

from course.core.camera import Camera
from course.core.types import Mesh
from course.given.lab6 import (
    EMPTY,
    ID_MASK,
    any_shape,
    check_size,
    check_tensor,
    face_normals,
    normalized,
)

from .clipping import clip_triangles, to_clip_space, to_screen
from .edges import edge_functions
from .visibility import rasterize


def perspective_correct(bary, inv_w):
    """Screen-space barycentrics -> barycentrics on the triangle in 3D.

    bary: (..., 3) float screen-space barycentrics of a point; inv_w: (..., 3) float the
    corners' ``1/w``. Returns (..., 3): ``(b_i / w_i) / sum_j (b_j / w_j)``.

    Why: the projection divides by w, so equal steps on screen are not equal steps on the
    triangle. Attributes divided by w (and 1/w itself) are linear in screen space; dividing
    the interpolated ``a/w`` by the interpolated ``1/w`` recovers the attribute. Plain
    screen-space weights bend textures and normals on surfaces that recede from the eye.

    Hints: three multiplies, a sum over the last axis, one division.
    """
    # BEGIN SOLUTION (task 4)
    q = bary * inv_w
    return q / (q[..., 0] + q[..., 1] + q[..., 2])[..., None]
    # END SOLUTION


def resolve_pixels(keys, screen, source, weights, width: int, height: int):
    """Deferred per-pixel barycentrics from a visibility buffer.

    keys: (H*W,) int64 from ``rasterize``; screen, source, weights: the (K, 3, 4), (K,),
    (K, 3, 3) triangles that were rasterized, their source faces and clip weights
    (``clip_triangles``); width, height: the viewport. Returns ``(face, bary)``: face (H, W)
    int64 the visible source face (-1 where empty), bary (H, W, 3) the perspective-correct
    barycentrics of the pixel centre **in the source face** (0 where empty).

    Per pixel (no fragments are kept: the visibility buffer's id is enough): the triangle
    ``k``, its ``edge_functions`` at the pixel centre normalised by their sum (screen-space
    barycentrics), ``perspective_correct`` with its corners' 1/w, then the clip weights:
    ``bary_source = sum_j mu_j weights[k, j]``.

    Hints: do it for all ``H*W`` pixels at once: gather triangle ``k`` (0 for empty pixels)
    and mask the results with ``torch.where`` at the end; ``pixel % width`` and
    ``pixel // width`` give the column and row.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    check_size(width, height)
    check_tensor(keys, "keys", (width * height,), kind="int64")
    check_tensor(screen, "screen", (None, 3, 4), like=keys)
    check_tensor(source, "source", (screen.shape[0],), kind="int64", like=keys)
    check_tensor(weights, "weights", (screen.shape[0], 3, 3), like=keys)
    # BEGIN SOLUTION (task 4)
    covered = keys != EMPTY
    k = torch.where(covered, keys & ID_MASK, 0)
    if screen.shape[0] == 0:  # nothing was rasterized: no triangle to gather from
        empty = torch.full((height, width), -1, dtype=torch.int64, device=keys.device)
        return empty, torch.zeros(height, width, 3, dtype=screen.dtype, device=keys.device)
    pixel = torch.arange(width * height, device=keys.device)
    px = (pixel % width).to(screen.dtype) + 0.5
    py = (pixel // width).to(screen.dtype) + 0.5
    tri = screen[k]
    e = edge_functions(tri, px, py)
    b = e / (e[:, 0] + e[:, 1] + e[:, 2])[:, None]
    mu = perspective_correct(b, tri[..., 3])
    w = weights[k]
    bary = mu[:, 0, None] * w[:, 0] + mu[:, 1, None] * w[:, 1] + mu[:, 2, None] * w[:, 2]
    bary = torch.where(covered[:, None], bary, torch.zeros_like(bary))
    face = torch.where(covered, source[k], -1)
    return face.reshape(height, width), bary.reshape(height, width, 3)
    # END SOLUTION


def rasterize_mesh(
    mesh: Mesh,
    camera: Camera,
    *,
    depth_bits: int = 32,
    cull_backfaces: bool = False,
    memory_budget_bytes: int = 2**28,
):
    """The whole pipeline: ``(face (H, W) int64, bary (H, W, 3))`` of ``mesh`` seen by
    ``camera`` (``camera.width`` x ``camera.height`` pixels), on the mesh's device and dtype.

    ``to_clip_space`` with ``camera.view_projection()``, ``clip_triangles``, ``to_screen``,
    ``rasterize``, ``resolve_pixels``. face is -1 where nothing is visible; bary are the
    perspective-correct barycentrics of the pixel centre in that face.

    Errors: TypeError naming ``mesh`` unless it is a Mesh, or ``camera`` unless it is a
    Camera; an invalid mesh raises ``Mesh.validate``'s errors.

    Hints: ``camera.view_projection(torch.float64).to(mesh.device)``; ``clip[mesh.faces]``
    gathers the corners of every face.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    if not isinstance(mesh, Mesh):
        raise TypeError(f"mesh: expected course.core.types.Mesh, got {type(mesh).__name__}")
    if not isinstance(camera, Camera):
        raise TypeError(f"camera: expected course.core.camera.Camera, got {type(camera).__name__}")
    mesh.validate()
    # BEGIN SOLUTION (task 4)
    mvp = camera.view_projection(torch.float64).to(mesh.device)
    clip = to_clip_space(mesh.vertices, mvp)
    clipped, source, weights = clip_triangles(clip[mesh.faces])
    screen = to_screen(clipped, camera.width, camera.height)
    keys = rasterize(
        screen,
        camera.width,
        camera.height,
        depth_bits=depth_bits,
        cull_backfaces=cull_backfaces,
        memory_budget_bytes=memory_budget_bytes,
    )
    return resolve_pixels(keys, screen, source, weights, camera.width, camera.height)
    # END SOLUTION


def interpolate(values, faces, face, bary):
    """Per-vertex attributes at pixels: ``sum_i bary_i * values[faces[face, i]]``.

    values: (V, C) float (normals, UVs, colours), faces: (F, 3) int64, face: (...) int64
    face per pixel (-1: empty), bary: (..., 3) float. Returns (..., C) in ``values``' dtype,
    0 where ``face == -1``.

    Hints: ``values[faces[face]]`` is (..., 3, C) (use face 0 for empty pixels, then mask).
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    check_tensor(values, "values", (None, None))
    check_tensor(faces, "faces", (None, 3), kind="int64", like=values)
    check_tensor(face, "face", any_shape(face), kind="int64", like=values)
    check_tensor(bary, "bary", (*face.shape, 3), like=values)
    # BEGIN SOLUTION (task 4)
    hit = face >= 0
    corners = values[faces[torch.where(hit, face, 0)]]  # (..., 3, C)
    b = bary.to(values.dtype)
    result = (
        b[..., 0, None] * corners[..., 0, :]
        + b[..., 1, None] * corners[..., 1, :]
        + b[..., 2, None] * corners[..., 2, :]
    )
    return torch.where(hit[..., None], result, torch.zeros_like(result))
    # END SOLUTION


def shade(mesh: Mesh, face, bary, light_direction, smooth: bool = True):
    """Lambert shading with a directional light: ``max(0, n . l)`` per pixel.

    mesh: the rasterized mesh; face (H, W) int64 and bary (H, W, 3) from ``rasterize_mesh``;
    light_direction: (3,) float toward the light (normalised here); smooth: per-vertex
    normals interpolated with ``bary`` (Gouraud/Phong normals), else the face normal (flat).
    Returns (H, W) in the mesh's dtype, 0 where ``face == -1``. One-sided: the normal of a
    face is ``(v1 - v0) x (v2 - v0)`` as wound, a vertex normal the normalised sum of the
    (area-weighted, i.e. unnormalised) normals of its faces.

    The interpolated normal must be normalised again: a blend of unit vectors is shorter
    than 1 (by up to a few percent on a coarse mesh), which darkens the middle of each face.

    Errors: TypeError naming ``mesh`` unless it is a Mesh; ValueError or TypeError naming
    ``face`` (not an (H, W) int64 tensor), ``bary`` (not (H, W, 3) float) or
    ``light_direction`` (not a (3,) float tensor), any of them off the mesh's device.

    Hints: the provided ``face_normals`` and ``normalized``; ``index_add_`` over
    ``mesh.faces.reshape(-1)`` sums face normals into their vertices; ``interpolate``.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    if not isinstance(mesh, Mesh):
        raise TypeError(f"mesh: expected course.core.types.Mesh, got {type(mesh).__name__}")
    check_tensor(face, "face", (None, None), kind="int64", like=mesh.vertices)
    check_tensor(bary, "bary", (*face.shape, 3), like=mesh.vertices)
    check_tensor(light_direction, "light_direction", (3,), like=mesh.vertices)
    # BEGIN SOLUTION (task 4)
    light = normalized(light_direction.to(mesh.dtype))
    normals = face_normals(mesh)
    if smooth:
        vertex_normals = torch.zeros_like(mesh.vertices).index_add_(
            0, mesh.faces.reshape(-1), normals.repeat_interleave(3, dim=0)
        )
        n = normalized(interpolate(normalized(vertex_normals), mesh.faces, face, bary))
    else:
        n = normalized(normals)[torch.where(face >= 0, face, 0)]
    cosine = (n * light).sum(-1).clamp(min=0)
    return torch.where(face >= 0, cosine, torch.zeros_like(cosine))
    # END SOLUTION
