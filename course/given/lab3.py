"""Lab 3's given code: the Whitted scene, its shading contract, a brute-force tracer and a
slow, obvious reference renderer, and the input checks shared by skeleton and reference.

Given code, not exercises: the lab's skeleton and its reference import these, and so do the
GPU tracers of ``course.kernels.flat_bvh``, ``course.kernels.triton_tracer`` and
``course.kernels.cuda_tracer``, so that every organisation of the tracer renders *the same*
image. They live in parts, all imported here (``from course.given.lab3 import ...``):
:mod:`course.given.lab3_scene` (constants, the scene, its cameras and normals),
:mod:`course.given.lab3_reference` (brute-force tracer, reference renderer),
:mod:`course.given.lab3_checks` (input checks), :mod:`course.given.lab3_layouts` (the
triangle layouts' checks and index word); ``dot`` and ``normalize`` are
:mod:`course.core.raymath`'s. The per-stage clock is here.

The scene (:class:`WhittedScene`, tensors, one float dtype and one device)
--------------------------------------------------------------------------
* ``vertices (V, 3)`` float, ``faces (F, 3)`` int64, ``material (F,)`` int64 into the
  material table;
* materials ``kd (M, 3)`` diffuse albedo, ``ks (M, 3)`` specular colour, ``shininess (M,)``,
  ``kr (M, 3)`` mirror reflectance;
* point lights ``point_positions (P, 3)``, ``point_intensities (P, 3)`` [W/sr];
* directional lights ``dir_directions (D, 3)`` unit, pointing *toward* the light,
  ``dir_irradiance (D, 3)`` [W/m^2];
* ``ambient (3,)``, ``background (3,)``.

P or D may be 0, not both (a scene without lights is a ValueError naming ``lights``); a
material index outside ``[0, M)`` is a ValueError naming ``material``.

The shading contract (every renderer of Lab 3 and every GPU tracer)
-------------------------------------------------------------------
At the closest hit ``p`` of a ray ``(o, d)``, ``d`` unit, on triangle ``f`` of material ``m``:

* ``n``: the unit geometric normal ``cross(v1 - v0, v2 - v0)``, flipped to face the ray
  (``n = -n`` where ``n . d > 0``).
* Robust secondary origin: ``p_off = p + n * offset * max(1, |p|_inf)``, with
  ``offset = OFFSET = 1e-4`` in float32 (see :func:`offset_scale` for float64).
* ``v = -d``; ``L = ambient * kd[m]``.
* Point light ``i``: ``to = P_i - p_off``, ``dist = |to|``, ``l = to / dist``,
  ``E = I_i / dist^2``; shadow ray ``(p_off, l)``, any hit in ``[0, dist - offset *
  max(1, |P_i|_inf)]`` (it stops just short of the light, so a light on a surface is not
  hidden by that surface). Directional light ``j``: ``l = D_j``, ``E = irradiance_j``, the
  shadow ray's ``t_max = inf``.
* Unoccluded and ``n . l > 0``: ``L += E (n . l) (kd / pi + ks (s + 8) / (8 pi)
  max(0, n . h)^s)``, ``h = normalize(l + v)``, ``s = shininess[m]`` (normalised
  Blinn-Phong). A shadow ray is traced only toward lights with ``n . l > 0``: the others
  cannot contribute ("model only what the scene requires").
* Mirror: if ``any(kr[m] > 0)`` and ``depth < max_depth``: ``r = d - 2 (d . n) n``
  (renormalised), ``L += kr[m] * radiance(p_off, r, depth + 1)``. Primary rays have depth 0;
  ``max_depth = 2`` is a primary ray and up to two reflected ones. Shadow rays are cast at
  every hit, primary or reflected.
* A ray that hits nothing returns ``background``. A ray with a NaN/inf origin or direction,
  or a zero direction, hits nothing (it returns ``background``, never NaN).

The tracer callable (how Lab 3 meets Lab 2 without depending on it)
-------------------------------------------------------------------
``trace(scene, origins (N, 3), directions (N, 3), t_min (N,), t_max (N,), any_hit: bool)
-> course.core.types.Hits`` (``t = inf`` and ``triangle = -1`` where missed). With ``any_hit``
it may return any hit in the interval (a shadow ray needs only "blocked or not").
:func:`trace_brute_force` is the given one; ``course.kernels.trace.trace_bvh`` the fast one.

Precision: float32 and float64. Half precision cannot hold a 1e-4 offset next to a
coordinate of 1 (its spacing there is 1e-3), so float16/bfloat16 are rejected with a
TypeError rather than rendered with acne.
"""

from __future__ import annotations

import contextlib
import time

import torch

from course.core.raymath import dot, normalize
from course.given.lab3_checks import (
    check_max_depth,
    check_mesh,
    check_pool_size,
    check_render_inputs,
    check_scene,
    check_surface_inputs,
    check_trace,
    check_vectors,
)
from course.given.lab3_layouts import (
    LAYOUTS,
    check_layout_inputs,
    check_order,
    float_as_index,
    index_as_float,
)
from course.given.lab3_reference import pair_tiles, render_reference, trace_brute_force
from course.given.lab3_scene import (
    BYTES_PER_PAIR,
    DTYPES,
    MAX_DEPTH,
    MEMORY_BUDGET_BYTES,
    OFFSET,
    SCENES,
    WhittedScene,
    face_normals,
    make_scene,
    offset_scale,
    translated,
    whitted_camera,
    whitted_scene,
)

__all__ = [
    "BYTES_PER_PAIR",
    "DTYPES",
    "LAYOUTS",
    "MAX_DEPTH",
    "MEMORY_BUDGET_BYTES",
    "OFFSET",
    "SCENES",
    "StageClock",
    "WhittedScene",
    "check_layout_inputs",
    "check_max_depth",
    "check_mesh",
    "check_order",
    "check_pool_size",
    "check_render_inputs",
    "check_scene",
    "check_surface_inputs",
    "check_trace",
    "check_vectors",
    "dot",
    "face_normals",
    "float_as_index",
    "index_as_float",
    "make_scene",
    "normalize",
    "offset_scale",
    "pair_tiles",
    "render_reference",
    "trace_brute_force",
    "translated",
    "whitted_camera",
    "whitted_scene",
]


class StageClock:
    """Seconds spent per named stage: ``with clock("trace"): ...`` adds to
    ``clock.seconds["trace"]``. On CUDA it synchronises around each stage, so the time is
    the stage's work and not its launch (the price: no overlap between stages)."""

    def __init__(self, device) -> None:
        self.device = torch.device(device)
        self.seconds: dict[str, float] = {}

    @contextlib.contextmanager
    def __call__(self, name: str):
        if self.device.type == "cuda":
            torch.cuda.synchronize(self.device)
        start = time.perf_counter()
        try:
            yield
        finally:
            if self.device.type == "cuda":
                torch.cuda.synchronize(self.device)
            self.seconds[name] = self.seconds.get(name, 0.0) + time.perf_counter() - start
