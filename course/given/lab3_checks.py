"""Lab 3's input checks (the skeleton and the reference call them first): each raises
TypeError/ValueError naming the argument it rejects.

Given code, not exercises (imported through :mod:`course.given.lab3`, whose docstring
states the scene and shading contract).
"""

from __future__ import annotations

import functools

import torch

from course.core.raymath import check_mesh
from course.given.lab3_scene import DTYPES, OFFSET, WhittedScene


def check_scene(scene) -> None:
    """``scene`` must be a valid WhittedScene (TypeError/ValueError naming the problem:
    ``scene``, a field, ``lights`` or ``material``)."""
    if not isinstance(scene, WhittedScene):
        raise TypeError(
            f"scene: expected course.given.lab3.WhittedScene, got {type(scene).__name__}"
        )
    scene.validate()
    if scene.dtype not in DTYPES:
        raise TypeError(
            f"scene: expected float32 or float64 geometry, got {scene.dtype} "
            f"(half precision cannot hold the {OFFSET:g} secondary-ray offset)"
        )


def check_vectors(like: torch.Tensor | None, **vectors) -> int:
    """Each of ``vectors`` (name=tensor) must be an (N, 3) float32/float64 tensor, all with
    one N, dtype and device (those of ``like`` when given). Returns N."""
    n = None
    for name, x in vectors.items():
        if not isinstance(x, torch.Tensor):
            raise TypeError(
                f"{name}: expected a torch.Tensor of shape (N, 3), got {type(x).__name__}"
            )
        if x.dtype not in DTYPES:
            raise TypeError(
                f"{name}: expected float32 or float64, got {x.dtype} (half "
                f"precision cannot hold the {OFFSET:g} secondary-ray offset: "
                f"its spacing near 1 is 1e-3)"
            )
        if x.ndim != 2 or x.shape[1] != 3 or (n is not None and x.shape[0] != n):
            want = "(N, 3)" if n is None else f"({n}, 3)"
            raise ValueError(f"{name}: expected shape {want}, got {tuple(x.shape)}")
        n = x.shape[0]
        if like is not None and x.dtype != like.dtype:
            raise TypeError(f"{name}: expected dtype {like.dtype} like the scene, got {x.dtype}")
        if like is not None and x.device != like.device:
            raise ValueError(
                f"{name}: expected device {like.device} like the scene, got {x.device}"
            )
        like = x
    return n or 0


def check_trace(trace) -> None:
    """``trace`` must be callable as ``trace(scene, origins, directions, t_min, t_max,
    any_hit) -> Hits``."""
    if not callable(trace):
        raise TypeError(
            "trace: expected a callable trace(scene, origins, directions, t_min, "
            f"t_max, any_hit) -> Hits, got {type(trace).__name__}"
        )


def _int_at_least(value, name: str, lo: int) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or value < lo:
        raise ValueError(f"{name}: expected an int >= {lo}, got {value!r}")


def check_max_depth(max_depth) -> None:
    """``max_depth`` must be an int >= 0 (0: primary rays only, no reflections)."""
    _int_at_least(max_depth, "max_depth", 0)


def check_pool_size(pool_size) -> None:
    """``pool_size`` must be an int >= 1."""
    _int_at_least(pool_size, "pool_size", 1)


def check_render_inputs(scene, origins, directions, trace, max_depth) -> int:
    """Provided: validate a renderer's arguments; returns N (the number of rays)."""
    check_scene(scene)
    n = check_vectors(scene.vertices, origins=origins, directions=directions)
    check_trace(trace)
    check_max_depth(max_depth)
    return n


def check_surface_inputs(scene, points, normals, directions, material, trace) -> int:
    """Provided: validate :func:`shade_direct`'s arguments; returns N."""
    check_scene(scene)
    n = check_vectors(scene.vertices, points=points, normals=normals, directions=directions)
    if not isinstance(material, torch.Tensor) or material.dtype != torch.int64:
        raise TypeError(
            f"material: expected an int64 tensor of shape ({n},), got "
            f"{getattr(material, 'dtype', type(material).__name__)}"
        )
    if material.shape != (n,):
        raise ValueError(f"material: expected shape ({n},), got {tuple(material.shape)}")
    if n and (int(material.min()) < 0 or int(material.max()) >= scene.kd.shape[0]):
        raise ValueError(
            f"material: expected indices in [0, {scene.kd.shape[0]}), got values "
            f"in [{int(material.min())}, {int(material.max())}]"
        )
    check_trace(trace)
    return n


check_mesh = functools.partial(check_mesh, dtypes=DTYPES)
"""Provided: ``check_mesh(mesh)``: ``mesh`` must be a valid ``course.core.types.Mesh`` of
float32/float64 vertices (:func:`course.core.raymath.check_mesh` with Lab 3's dtypes)."""
