"""Closest-hit brute force as Triton kernels: the lecture's intersection kernel, measurable.

Lab 1 writes ray/triangle tests as batched torch code, which materialises a
``rays x triangles`` tile in memory for every operation. The lecture's CUDA kernel does
the opposite: one thread per ray, a loop over all triangles, and only the running
minimum kept in registers. These kernels are that design in Triton, given (not an
exercise) so the lab can instrument it: registers and spills of the compiled kernel,
occupancy, and throughput against the torch versions.

Design, per program (a block of ``block_rays`` rays, ``num_warps`` warps):

* the ray's origin and direction (6 floats), ``t_min``, the best hit so far
  (``best_t``, ``best_id``) live in registers for the whole kernel;
* the triangle loop is the inner loop; each iteration loads one triangle's data as
  scalars, which every thread of the block shares (uniform loads: they hit L1 after the
  first warp), and tests it against all rays of the block;
* each thread holds ``block_rays / (32 num_warps)`` rays, so each triangle load feeds that
  many tests. This, not occupancy, decides the speed: at one ray per thread the loop is
  bound by its loads; at four, the kernel needs 128 registers and runs at a quarter of the
  warps, and is faster (``bench/lab1_intersect.py`` sweeps it; the figures are in
  bench/results/<gpu>/lab1*/);
* triangles are stored structure-of-arrays (one contiguous row per coordinate) with
  precomputed data: ``v0, e1 = v1 - v0, e2 = v2 - v0`` for Möller–Trumbore (9 floats,
  saving 6 subtractions per test) or Woop's 3x4 world-to-unit-triangle transform
  (12 floats);
* a test does no full-precision division: the reciprocal variant computes ``1/det``
  once per pair with the GPU's fast division (``/`` in Triton is PTX ``div.full.f32``,
  within 2 ulp), the division-free variant compares ``t' / det`` as fractions and
  divides once per ray at the end (for scenes of moderate scale only);
* ``u, v`` of the winner are recomputed once per ray after the loop, so the loop
  carries only ``best_t, best_id`` per ray (the lecture's register budget: ray 6,
  vertices 9, t/u/v 3, triNum 1, loop 1, tid 1, min_t/min_id 2 = 23).

Runs compiled on CUDA, or on the CPU through Triton's interpreter when the environment
variable ``TRITON_INTERPRET=1`` is set before ``triton`` is first imported (slow: only
for small tests). Importing this module without Triton installed works; calling a
kernel then raises ImportError.

Accuracy contract (both kernels, fp32): a hit is reported when ``u >= 0, v >= 0,
u + v <= 1`` and ``t_min <= t <= t_max`` (the closed interval of the lab's kernels), as
evaluated in fp32 with the approximate division (t within ~1e-6 relative of the exact
value for well-conditioned pairs, more for grazing rays); rays through an edge or a
vertex shared by two triangles may miss both (these tests are not watertight); on exact
ties in t the lower triangle index wins. No parallel-ray epsilon: ``det`` that rounds
to exactly 0 misses, a tiny nonzero one is trusted. Degenerate triangles
(zero area, also the padding of the layouts) and rays parallel to a triangle never hit.
NaN coordinates give misses, never NaN outputs.

Its parts: :mod:`~course.kernels.triton_intersect_kernels` (Triton, the device functions
and the kernels) and :mod:`~course.kernels.triton_intersect_layouts` (the triangle layouts);
this module launches them and reports the compiled kernels, and re-exports what the other
Triton kernels import from it (``_jit``, ``tl``, ``triton``, ``_store_hits``).
"""

from __future__ import annotations

import contextlib
import math
from dataclasses import dataclass

import torch

from course.kernels.triton_intersect_kernels import (
    _TRITON_IMPORT_ERROR,
    _mt_closest_kernel,
    _unit_closest_kernel,
    triton,
)
from course.kernels.triton_intersect_kernels import _jit as _jit
from course.kernels.triton_intersect_kernels import _mt_terms as _mt_terms
from course.kernels.triton_intersect_kernels import _store_hits as _store_hits
from course.kernels.triton_intersect_kernels import tl as tl
from course.kernels.triton_intersect_layouts import PAD, TriangleLayout, mt_layout, unit_layout

__all__ = [
    "KernelInfo",
    "TriangleLayout",
    "compiled_kernel_info",
    "interpreting",
    "mt_closest_hit_triton",
    "mt_layout",
    "unit_closest_hit_triton",
    "unit_layout",
]


# Launch defaults from bench/lab1_intersect.py's sweep (1M rays x 2K triangles; figures in
# bench/results/nvidia-h200/lab1/): what matters is rays per thread, block_rays / (32
# num_warps). One ray per thread is bound by the triangle loads; 4 rays per thread share
# each load 4 ways (128 registers); 8 gain little more at ~230 registers, close to spilling.
DEFAULT_BLOCK_RAYS = 256
DEFAULT_NUM_WARPS = 2
DEFAULT_UNROLL = 4


# --------------------------------------------------------------------------------------
# Launchers
# --------------------------------------------------------------------------------------


def _require_triton() -> None:
    if triton is None:
        raise ImportError(
            "the Triton kernels need the `triton` package (pip install triton; "
            "it ships with torch's CUDA wheels on Linux)"
        ) from _TRITON_IMPORT_ERROR


def interpreting() -> bool:
    """True when the kernels run in Triton's CPU interpreter (``TRITON_INTERPRET=1``)."""
    _require_triton()
    return type(_mt_closest_kernel).__name__ == "InterpretedFunction"


def _ieee_quiet():
    """The kernels divide by zero on purpose (inf/NaN then fail the tests); the
    interpreter evaluates them with numpy, which would warn about every such pair."""
    if interpreting():
        import numpy as np

        return np.errstate(divide="ignore", invalid="ignore", over="ignore")
    return contextlib.nullcontext()


def _is_pow2(x: int) -> bool:
    return isinstance(x, int) and x > 0 and x & (x - 1) == 0


def _rays_arg(x, name: str, n: int, device: torch.device) -> torch.Tensor:
    """t_min / t_max: a number or an (N,) tensor -> (N,) float32 contiguous."""
    if isinstance(x, torch.Tensor):
        if x.device != device:
            raise ValueError(f"{name}: expected a tensor on {device} like origins, got {x.device}")
        if x.shape not in (torch.Size([n]), torch.Size([])):
            raise ValueError(f"{name}: expected shape ({n},) or a scalar, got {tuple(x.shape)}")
        return x.to(torch.float32).expand(n).contiguous()
    return torch.full((n,), float(x), dtype=torch.float32, device=device)


def _launch(
    kernel,
    kind: str,
    origins,
    directions,
    triangles,
    t_min,
    t_max,
    block_rays: int,
    num_warps: int,
    unroll: int,
    **constexprs,
):
    """Validate, launch one kernel over all rays; return ((t, id, u, v), compiled handle)."""
    _require_triton()
    for name, x in (("origins", origins), ("directions", directions)):
        if not isinstance(x, torch.Tensor):
            raise TypeError(f"{name}: expected a (N, 3) float tensor, got {type(x).__name__}")
        if x.ndim != 2 or x.shape[1] != 3 or not x.is_floating_point():
            raise ValueError(
                f"{name}: expected a (N, 3) float tensor, got shape {tuple(x.shape)} {x.dtype}"
            )
    if origins.shape != directions.shape:
        raise ValueError(
            f"directions: expected shape {tuple(origins.shape)} like origins, "
            f"got {tuple(directions.shape)}"
        )
    if not _is_pow2(block_rays):
        raise ValueError(f"block_rays: expected a power of two, got {block_rays!r}")
    if not _is_pow2(num_warps) or num_warps > 32:
        raise ValueError(f"num_warps: expected a power of two <= 32, got {num_warps!r}")
    if not _is_pow2(unroll) or PAD % unroll:
        raise ValueError(f"unroll: expected a power of two dividing {PAD}, got {unroll!r}")

    if isinstance(triangles, TriangleLayout):
        if triangles.kind != kind:
            raise ValueError(f"triangles: expected a {kind!r} layout, got a {triangles.kind!r} one")
        layout = triangles
    else:
        layout = (mt_layout if kind == "mt" else unit_layout)(triangles)
    n, device = origins.shape[0], origins.device
    t_lo = _rays_arg(t_min, "t_min", n, device)
    # The kernels keep the best t so far and accept strictly nearer hits (ties keep the
    # lower index); starting from the next float above t_max makes t == t_max a hit.
    t_hi = torch.nextafter(
        _rays_arg(t_max, "t_max", n, device), torch.tensor(math.inf, device=device)
    )
    for name, x in (("directions", directions), ("triangles", layout.data)):
        if x.device != device:
            raise ValueError(f"{name}: expected device {device} like origins, got {x.device}")
    if not interpreting() and device.type != "cuda":
        raise ValueError(
            f"origins: the compiled Triton kernels need CUDA tensors, got {device} "
            "(for the CPU, set TRITON_INTERPRET=1 before importing triton)"
        )
    o = origins.to(torch.float32).contiguous()
    d = directions.to(torch.float32).contiguous()
    t = torch.empty(n, dtype=torch.float32, device=device)
    ids = torch.empty(n, dtype=torch.int64, device=device)
    u = torch.empty(n, dtype=torch.float32, device=device)
    v = torch.empty(n, dtype=torch.float32, device=device)
    handle = None
    if n > 0:
        grid = (triton.cdiv(n, block_rays),)
        with _ieee_quiet():
            handle = kernel[grid](
                o,
                d,
                t_lo,
                t_hi,
                layout.data,
                t,
                ids,
                u,
                v,
                n,
                layout.padded_count,
                BLOCK_RAYS=block_rays,
                UNROLL=unroll,
                num_warps=num_warps,
                **constexprs,
            )
    return (t, ids, u, v), handle


def mt_closest_hit_triton(
    origins: torch.Tensor,
    directions: torch.Tensor,
    triangles,
    t_min=0.0,
    t_max=math.inf,
    *,
    block_rays: int = DEFAULT_BLOCK_RAYS,
    num_warps: int = DEFAULT_NUM_WARPS,
    unroll: int = DEFAULT_UNROLL,
    division_free: bool = False,
):
    """Closest hit of each ray among all triangles, Möller–Trumbore, one Triton program
    per block of rays looping over every triangle.

    origins, directions: (N, 3) float (computed in float32) on CUDA, or on the CPU under
        the interpreter; directions need not be unit length.
    triangles: (M, 3, 3) float corners, or ``mt_layout(triangles)`` (build it once per
        mesh to keep its cost out of the timing).
    t_min, t_max: numbers or (N,) tensors; a hit needs ``t_min <= t <= t_max``.
    block_rays: rays per program (a power of two); num_warps: warps per program;
    unroll: triangles per loop iteration; division_free: compare fractions instead of
    dividing each pair: faster (bench/results/<gpu>/lab1*/), but the products ``t' |det|``
    it compares must stay in fp32's normal range, which (unit directions) holds for scenes
    scaled by about 1e-7 to 1e7; beyond that it reports farther hits than the nearest (it
    does not crash or produce NaN). The reciprocal variant has no such limit.
    Returns ``(t, triangle, u, v)``: (N,) float32 (inf on a miss), (N,) int64 (-1),
    (N,) float32 barycentrics of v1 and v2 (0 on a miss).
    """
    return _launch(
        _mt_closest_kernel,
        "mt",
        origins,
        directions,
        triangles,
        t_min,
        t_max,
        block_rays,
        num_warps,
        unroll,
        DIVISION_FREE=bool(division_free),
    )[0]


def unit_closest_hit_triton(
    origins: torch.Tensor,
    directions: torch.Tensor,
    triangles,
    t_min=0.0,
    t_max=math.inf,
    *,
    block_rays: int = DEFAULT_BLOCK_RAYS,
    num_warps: int = DEFAULT_NUM_WARPS,
    unroll: int = DEFAULT_UNROLL,
):
    """Closest hit by Woop's unit-triangle test with a precomputed 3x4 transform per
    triangle (12 floats), one Triton program per block of rays.

    triangles: (M, 3, 3) float corners, or ``unit_layout(triangles)``. Everything else
    as in ``mt_closest_hit_triton``; one fast division per pair (``t = -o'z / d'z``).
    """
    return _launch(
        _unit_closest_kernel,
        "unit",
        origins,
        directions,
        triangles,
        t_min,
        t_max,
        block_rays,
        num_warps,
        unroll,
    )[0]


# --------------------------------------------------------------------------------------
# What the compiler made of it
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class KernelInfo:
    """Resources of one compiled kernel: the inputs of the occupancy calculation.

    n_regs: registers per thread; n_spills: spilled registers (local memory traffic);
    num_warps, block_rays: the launch configuration; shared_bytes: static shared memory.
    Fields the interpreter or an older Triton cannot tell are None.
    """

    n_regs: int | None
    n_spills: int | None
    num_warps: int
    block_rays: int
    shared_bytes: int | None

    @property
    def threads_per_block(self) -> int:
        return self.num_warps * 32


def _field(obj, name: str):
    """``obj.name`` or ``obj[name]``: Triton's metadata was a dict before it was a namedtuple."""
    if obj is None:
        return None
    if isinstance(obj, dict):
        return obj.get(name)
    return getattr(obj, name, None)


def compiled_kernel_info(
    kernel_fn, origins, directions, triangles, t_min=0.0, t_max=math.inf, **launch
) -> KernelInfo:
    """Launch ``kernel_fn`` (``mt_closest_hit_triton`` or ``unit_closest_hit_triton``) once
    with these arguments and report the compiled kernel's registers and spills.

    ``launch`` takes the kernel's keywords (block_rays, num_warps, unroll, division_free).
    Under the interpreter there is no compiled kernel: n_regs, n_spills, shared_bytes are None.
    """
    launchers = {
        mt_closest_hit_triton: (_mt_closest_kernel, "mt"),
        unit_closest_hit_triton: (_unit_closest_kernel, "unit"),
    }
    if kernel_fn not in launchers:
        raise ValueError(
            "kernel_fn: expected mt_closest_hit_triton or unit_closest_hit_triton, "
            f"got {getattr(kernel_fn, '__name__', kernel_fn)!r}"
        )
    kernel, kind = launchers[kernel_fn]
    block_rays = launch.pop("block_rays", DEFAULT_BLOCK_RAYS)
    num_warps = launch.pop("num_warps", DEFAULT_NUM_WARPS)
    unroll = launch.pop("unroll", DEFAULT_UNROLL)
    constexprs = {"DIVISION_FREE": bool(launch.pop("division_free", False))} if kind == "mt" else {}
    if launch:
        raise TypeError(f"unexpected launch keywords: {sorted(launch)}")
    _, handle = _launch(
        kernel,
        kind,
        origins,
        directions,
        triangles,
        t_min,
        t_max,
        block_rays,
        num_warps,
        unroll,
        **constexprs,
    )
    if handle is not None and _field(handle, "n_regs") is None:
        # Registers are known once the binary is loaded, which recent Tritons do lazily.
        init = getattr(handle, "_init_handles", None)
        if callable(init):
            init()
    metadata = _field(handle, "metadata")
    return KernelInfo(
        n_regs=_field(handle, "n_regs"),
        n_spills=_field(handle, "n_spills"),
        num_warps=num_warps,
        block_rays=block_rays,
        shared_bytes=_field(metadata, "shared"),
    )
