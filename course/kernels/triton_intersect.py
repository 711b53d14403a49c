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
"""

from __future__ import annotations

import contextlib
import math
from dataclasses import dataclass

import torch

try:
    import triton
    import triton.language as tl
except ImportError as _err:  # the rest of the course works without Triton
    triton = tl = None
    _TRITON_IMPORT_ERROR: ImportError | None = _err

    def _jit(fn):
        return fn
else:
    _TRITON_IMPORT_ERROR = None
    _jit = triton.jit

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

# Layouts pad the triangle count to a multiple of this, so an unrolled loop of any
# power-of-two factor up to PAD needs no bounds mask; padding triangles never hit.
PAD = 16

# Launch defaults from bench/lab1_intersect.py's sweep (1M rays x 2K triangles; figures in
# bench/results/nvidia-h200/lab1/): what matters is rays per thread, block_rays / (32
# num_warps). One ray per thread is bound by the triangle loads; 4 rays per thread share
# each load 4 ways (128 registers); 8 gain little more at ~230 registers, close to spilling.
DEFAULT_BLOCK_RAYS = 256
DEFAULT_NUM_WARPS = 2
DEFAULT_UNROLL = 4


# --------------------------------------------------------------------------------------
# Triangle layouts (built once per mesh, like an acceleration structure)
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class TriangleLayout:
    """Per-triangle data in structure-of-arrays form, padded for the kernels.

    data: (R, M_pad) float32 contiguous, one row per coordinate (R = 9 for ``"mt"``:
        v0, e1, e2; R = 12 for ``"unit"``: the 3x4 transform row by row);
    count: M, the number of real triangles (columns ``M..M_pad-1`` are padding);
    kind: ``"mt"`` or ``"unit"``.
    """

    data: torch.Tensor
    count: int
    kind: str

    @property
    def padded_count(self) -> int:
        return self.data.shape[1]


def _check_triangles(triangles: torch.Tensor) -> torch.Tensor:
    if not isinstance(triangles, torch.Tensor):
        raise TypeError(
            f"triangles: expected a (M, 3, 3) float tensor or a TriangleLayout, "
            f"got {type(triangles).__name__}"
        )
    if triangles.ndim != 3 or triangles.shape[1:] != (3, 3):
        raise ValueError(
            f"triangles: expected shape (M, 3, 3) (corners x xyz), got {tuple(triangles.shape)}"
        )
    if not triangles.is_floating_point():
        raise TypeError(f"triangles: expected a floating-point tensor, got {triangles.dtype}")
    return triangles


def _soa(rows: torch.Tensor, count: int, kind: str, pad_row: torch.Tensor) -> TriangleLayout:
    """(M, R) per-triangle rows -> (R, M_pad) float32, padding columns set to ``pad_row``."""
    padded = max(1, -(-count // PAD)) * PAD  # never empty: the epilogue reads column 0
    data = pad_row.to(rows.device, torch.float32)[:, None].repeat(1, padded)
    data[:, :count] = rows.T.to(torch.float32)
    return TriangleLayout(data.contiguous(), count, kind)


def mt_layout(triangles: torch.Tensor) -> TriangleLayout:
    """Möller–Trumbore's precomputed layout: rows ``v0x v0y v0z e1x e1y e1z e2x e2y e2z``.

    triangles: (M, 3, 3) float, corners ``v0, v1, v2`` of each triangle. The edges are
    formed in the input dtype (so a float64 mesh gives correctly rounded fp32 edges).
    Padding triangles have zero edges: ``det = 0``, never a hit.
    """
    tri = _check_triangles(triangles)
    v0, v1, v2 = tri.unbind(1)
    rows = torch.cat([v0, v1 - v0, v2 - v0], dim=1)  # (M, 9)
    return _soa(rows, tri.shape[0], "mt", torch.zeros(9))


def unit_layout(triangles: torch.Tensor) -> TriangleLayout:
    """Woop's unit-triangle layout: the 3x4 affine map ``M`` from world to triangle space.

    triangles: (M, 3, 3) float. ``M`` sends ``v0 -> (0,0,0)``, ``v1 -> (1,0,0)``,
    ``v2 -> (0,1,0)`` and ``n = e1 x e2`` to ``(0,0,1)``, so a ray hits where its
    transformed ``z`` is 0, at barycentrics ``(u, v) = (x, y)``. It is the inverse of
    ``[e1 e2 n | v0]``, in closed form: rows ``(e2 x n, n x e1, n) / |n|^2`` (computed in
    float64, then rounded to fp32). Degenerate triangles (``|n| = 0`` or non-finite) get
    the padding transform, whose ``z`` never reaches 0 and whose ``u`` is -1: never a hit.
    """
    tri = _check_triangles(triangles).to(torch.float64)
    v0, v1, v2 = tri.unbind(1)
    e1, e2 = v1 - v0, v2 - v0
    n = torch.linalg.cross(e1, e2)
    n2 = (n * n).sum(-1, keepdim=True)
    rot = (
        torch.stack([torch.linalg.cross(e2, n), torch.linalg.cross(n, e1), n], dim=1)
        / n2[..., None]
    )
    shift = -(rot @ v0[..., None])  # (M, 3, 1): maps v0 to the origin
    rows = torch.cat([rot, shift], dim=2).reshape(-1, 12)
    never = torch.tensor([0.0, 0, 0, -1, 0, 0, 0, -1, 0, 0, 0, 1], dtype=torch.float64)
    good = (n2[:, 0] > 0) & torch.isfinite(rows).all(dim=1)
    rows = torch.where(good[:, None], rows, never.to(rows.device))
    return _soa(rows, tri.shape[0], "unit", never)


# --------------------------------------------------------------------------------------
# Kernels
# --------------------------------------------------------------------------------------


@_jit
def _load_mt(ptr, stride, idx):
    """Column ``idx`` of the (9, stride) Möller–Trumbore layout: v0, e1, e2.

    ``idx`` is a scalar (one triangle, broadcast to the ray block) in the loop and a
    per-ray vector (each ray's winner: a gather) in the epilogue."""
    return (
        tl.load(ptr + 0 * stride + idx),
        tl.load(ptr + 1 * stride + idx),
        tl.load(ptr + 2 * stride + idx),
        tl.load(ptr + 3 * stride + idx),
        tl.load(ptr + 4 * stride + idx),
        tl.load(ptr + 5 * stride + idx),
        tl.load(ptr + 6 * stride + idx),
        tl.load(ptr + 7 * stride + idx),
        tl.load(ptr + 8 * stride + idx),
    )


@_jit
def _load_unit(ptr, stride, idx):
    """Column ``idx`` of the (12, stride) unit-triangle layout: the 3x4 transform by rows."""
    return (
        tl.load(ptr + 0 * stride + idx),
        tl.load(ptr + 1 * stride + idx),
        tl.load(ptr + 2 * stride + idx),
        tl.load(ptr + 3 * stride + idx),
        tl.load(ptr + 4 * stride + idx),
        tl.load(ptr + 5 * stride + idx),
        tl.load(ptr + 6 * stride + idx),
        tl.load(ptr + 7 * stride + idx),
        tl.load(ptr + 8 * stride + idx),
        tl.load(ptr + 9 * stride + idx),
        tl.load(ptr + 10 * stride + idx),
        tl.load(ptr + 11 * stride + idx),
    )


@_jit
def _mt_terms(ox, oy, oz, dx, dy, dz, v0x, v0y, v0z, e1x, e1y, e1z, e2x, e2y, e2z):
    """Möller–Trumbore by Cramer's rule: ``det`` and the numerators of ``u, v, t``.

    With ``s = o - v0``, ``p = d x e2``, ``q = s x e1``: ``det = e1 . p``,
    ``u = (s . p) / det``, ``v = (d . q) / det``, ``t = (e2 . q) / det``.
    """
    sx = ox - v0x
    sy = oy - v0y
    sz = oz - v0z
    px = dy * e2z - dz * e2y
    py = dz * e2x - dx * e2z
    pz = dx * e2y - dy * e2x
    det = e1x * px + e1y * py + e1z * pz
    u_num = sx * px + sy * py + sz * pz
    qx = sy * e1z - sz * e1y
    qy = sz * e1x - sx * e1z
    qz = sx * e1y - sy * e1x
    v_num = dx * qx + dy * qy + dz * qz
    t_num = e2x * qx + e2y * qy + e2z * qz
    return det, u_num, v_num, t_num


@_jit
def _load_rays(o_ptr, d_ptr, tmin_ptr, tmax_ptr, ray, live):
    """Rays ``ray`` (a block of indices); dead lanes get a zero direction, which misses."""
    ox = tl.load(o_ptr + ray * 3 + 0, mask=live, other=0.0)
    oy = tl.load(o_ptr + ray * 3 + 1, mask=live, other=0.0)
    oz = tl.load(o_ptr + ray * 3 + 2, mask=live, other=0.0)
    dx = tl.load(d_ptr + ray * 3 + 0, mask=live, other=0.0)
    dy = tl.load(d_ptr + ray * 3 + 1, mask=live, other=0.0)
    dz = tl.load(d_ptr + ray * 3 + 2, mask=live, other=0.0)
    t_lo = tl.load(tmin_ptr + ray, mask=live, other=0.0)
    t_hi = tl.load(tmax_ptr + ray, mask=live, other=0.0)
    return ox, oy, oz, dx, dy, dz, t_lo, t_hi


@_jit
def _store_hits(t_ptr, id_ptr, u_ptr, v_ptr, ray, live, best_t, best_id, u, v):
    """Write one block of hits; misses get t = inf, id = -1, u = v = 0 (the Hits contract)."""
    found = best_id >= 0
    tl.store(t_ptr + ray, tl.where(found, best_t, float("inf")), mask=live)
    tl.store(id_ptr + ray, best_id.to(tl.int64), mask=live)
    tl.store(u_ptr + ray, tl.where(found, u, 0.0), mask=live)
    tl.store(v_ptr + ray, tl.where(found, v, 0.0), mask=live)


@_jit
def _mt_closest_kernel(
    o_ptr,
    d_ptr,
    tmin_ptr,
    tmax_ptr,
    tri_ptr,
    t_ptr,
    id_ptr,
    u_ptr,
    v_ptr,
    n_rays,
    m_pad,
    BLOCK_RAYS: tl.constexpr,
    UNROLL: tl.constexpr,
    DIVISION_FREE: tl.constexpr,
):
    ray = tl.program_id(0) * BLOCK_RAYS + tl.arange(0, BLOCK_RAYS)
    live = ray < n_rays
    ox, oy, oz, dx, dy, dz, t_lo, t_hi = _load_rays(o_ptr, d_ptr, tmin_ptr, tmax_ptr, ray, live)

    # The best hit is the fraction best_num / best_den. The reciprocal variant divides
    # every pair and keeps best_den = 1; the division-free one keeps (t' * sign, |det|).
    best_num = t_hi
    best_den = tl.full([BLOCK_RAYS], 1.0, tl.float32)
    best_id = tl.full([BLOCK_RAYS], -1, tl.int32)
    # A while loop rather than `for base in range(0, m_pad, UNROLL)`: the same code
    # compiled (measured), and older Triton interpreters cannot range over a runtime int.
    base = 0
    while base < m_pad:
        # Unrolled so the next triangle's loads are in flight during this one's math.
        for k in tl.static_range(UNROLL):
            j = base + k
            v0x, v0y, v0z, e1x, e1y, e1z, e2x, e2y, e2z = _load_mt(tri_ptr, m_pad, j)
            det, u_num, v_num, t_num = _mt_terms(
                ox, oy, oz, dx, dy, dz, v0x, v0y, v0z, e1x, e1y, e1z, e2x, e2y, e2z
            )
            if DIVISION_FREE:
                # Fold det's sign into the numerators, then test u, v, t scaled by |det|:
                # u >= 0, v >= 0, u + v <= 1, t_min <= t < best become comparisons of
                # products. det = 0 (parallel ray, padding) fails "t_lo*0 <= t < best*0"
                # (or gives NaN = false), so it needs no test of its own.
                flip = det < 0.0
                adet = tl.abs(det)
                su = tl.where(flip, -u_num, u_num)
                sv = tl.where(flip, -v_num, v_num)
                st = tl.where(flip, -t_num, t_num)
                hit = (
                    (su >= 0.0)
                    & (sv >= 0.0)
                    & (su + sv <= adet)
                    & (st >= t_lo * adet)
                    & (st * best_den < best_num * adet)
                )
                best_num = tl.where(hit, st, best_num)
                best_den = tl.where(hit, adet, best_den)
            else:
                # det = 0 makes inv_det infinite and u or v inf or NaN, which fails
                # the interval tests: parallel rays and padding need no branch.
                inv_det = 1.0 / det
                u = u_num * inv_det
                v = v_num * inv_det
                t = t_num * inv_det
                hit = (u >= 0.0) & (v >= 0.0) & (u + v <= 1.0) & (t >= t_lo) & (t < best_num)
                best_num = tl.where(hit, t, best_num)
            best_id = tl.where(hit, j, best_id)
        base += UNROLL

    # Epilogue, once per ray: barycentrics of the winner (a gather by best_id).
    # Misses read column 0 (a layout always has one) and are overwritten by the store.
    winner = tl.maximum(best_id, 0)
    v0x, v0y, v0z, e1x, e1y, e1z, e2x, e2y, e2z = _load_mt(tri_ptr, m_pad, winner)
    det, u_num, v_num, t_num = _mt_terms(
        ox, oy, oz, dx, dy, dz, v0x, v0y, v0z, e1x, e1y, e1z, e2x, e2y, e2z
    )
    inv_det = 1.0 / det
    _store_hits(
        t_ptr,
        id_ptr,
        u_ptr,
        v_ptr,
        ray,
        live,
        best_num / best_den,
        best_id,
        u_num * inv_det,
        v_num * inv_det,
    )


@_jit
def _unit_terms(ox, oy, oz, dx, dy, dz, m00, m01, m02, m03, m10, m11, m12, m13, m20, m21, m22, m23):
    """Woop's unit-triangle test: transform the ray, intersect the plane z = 0.

    ``t = -o'z / d'z``; the hit point's ``(x, y)`` in triangle space are ``(u, v)``.
    """
    oz_ = m20 * ox + m21 * oy + m22 * oz + m23
    dz_ = m20 * dx + m21 * dy + m22 * dz
    t = -oz_ / dz_
    u = (m00 * ox + m01 * oy + m02 * oz + m03) + t * (m00 * dx + m01 * dy + m02 * dz)
    v = (m10 * ox + m11 * oy + m12 * oz + m13) + t * (m10 * dx + m11 * dy + m12 * dz)
    return t, u, v


@_jit
def _unit_closest_kernel(
    o_ptr,
    d_ptr,
    tmin_ptr,
    tmax_ptr,
    tri_ptr,
    t_ptr,
    id_ptr,
    u_ptr,
    v_ptr,
    n_rays,
    m_pad,
    BLOCK_RAYS: tl.constexpr,
    UNROLL: tl.constexpr,
):
    ray = tl.program_id(0) * BLOCK_RAYS + tl.arange(0, BLOCK_RAYS)
    live = ray < n_rays
    ox, oy, oz, dx, dy, dz, t_lo, t_hi = _load_rays(o_ptr, d_ptr, tmin_ptr, tmax_ptr, ray, live)

    best_t = t_hi
    best_id = tl.full([BLOCK_RAYS], -1, tl.int32)
    base = 0
    while base < m_pad:
        for k in tl.static_range(UNROLL):
            j = base + k
            (m00, m01, m02, m03, m10, m11, m12, m13, m20, m21, m22, m23) = _load_unit(
                tri_ptr, m_pad, j
            )
            t, u, v = _unit_terms(
                ox, oy, oz, dx, dy, dz, m00, m01, m02, m03, m10, m11, m12, m13, m20, m21, m22, m23
            )
            # A ray parallel to the plane gives t = +-inf or NaN and u, v = NaN: no hit.
            hit = (u >= 0.0) & (v >= 0.0) & (u + v <= 1.0) & (t >= t_lo) & (t < best_t)
            best_t = tl.where(hit, t, best_t)
            best_id = tl.where(hit, j, best_id)
        base += UNROLL

    winner = tl.maximum(best_id, 0)
    (m00, m01, m02, m03, m10, m11, m12, m13, m20, m21, m22, m23) = _load_unit(
        tri_ptr, m_pad, winner
    )
    t, u, v = _unit_terms(
        ox, oy, oz, dx, dy, dz, m00, m01, m02, m03, m10, m11, m12, m13, m20, m21, m22, m23
    )
    _store_hits(t_ptr, id_ptr, u_ptr, v_ptr, ray, live, best_t, best_id, u, v)


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
