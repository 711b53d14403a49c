"""The lecture's own tracer in CUDA C: the speed-of-light reference for the Triton kernels.

One thread per ray, written as a CUDA programmer writes it, with real per-thread branches
and loops where Triton needs masked lock-step steps. It walks course.kernels.flat_bvh's ``pairs``
layout, the packed node of the lecture:

* an interior node is one 64-byte row holding **both children's boxes** and their links
  (four float4 loads test a pair of children; the children's own rows are never read), the
  planes of one axis in one float4, so each ray picks its near and far planes by the signs
  of its direction instead of sorting every slab's two distances;
* **near child first**: both boxes are tested, the nearer hit child is visited next and the
  farther pushed; interior nodes are walked in a tight inner loop, then a leaf's rows;
* **compact triangles**: ``v0`` with the triangle's index in ``w``, the precomputed edges
  ``e1, e2`` (three float4 per triangle), the leaf's end flagged in ``e2.w``, so a stack
  entry is one int (a row of ``pairs``, or ``~first`` for a leaf);
* a **short stack**: ``int stack[32]`` (the tree's interior levels; 64 for deeper trees).
  Registers cannot be indexed dynamically, so the compiler puts it in local memory,
  per-thread device memory cached in L1;
* one launch per call: invalid rays are sorted out in the kernel and numbers for
  ``t_min``/``t_max`` stay numbers (no (N,) tensors, no extra kernels).

Compiled at first use with ``torch.utils.cpp_extension.load_inline`` (nvcc, ~1 minute; the
result is cached on disk by torch). Needs a CUDA device and a CUDA toolkit; without them
every entry point raises ``RuntimeError("needs CUDA and nvcc: ...")`` (see
:func:`unavailable_reason`).

The compiled kernels are read back with ``cudaFuncGetAttributes`` (registers per thread,
local memory per thread, the largest block the kernel can launch with) and
``cudaOccupancyMaxActiveBlocksPerMultiprocessor``, next to ``course.measure.occupancy``'s model of
the same numbers (:func:`cuda_kernel_info`).

Accuracy contract: course.kernels.flat_bvh's (float32, IEEE division, NaN-safe slab test with
Ize's widened exit, closed ``[t_min, t_max]``, ties to the lower original triangle index,
NaN/inf/zero-direction rays miss, not watertight). Any hit returns the first hit found.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass

import torch

from course.core.types import Hits
from course.kernels.flat_bvh import EXIT_SCALE, STACK_DEPTH, FlatBVH, check_ray_bounds

__all__ = ["CudaKernelInfo", "cuda_kernel_info", "trace_flat_cuda", "unavailable_reason"]

DEFAULT_BLOCK = 128
SHORT_STACK = 32
MIN_BLOCKS = 6
"""``capped=True`` compiles the walk for 6 blocks of 256 threads per SM: at most 40
registers (75% occupancy on Hopper) instead of the compiler's 44 (62.5%)."""
"""Stack entries of the walk for trees of up to 33 levels (the bunny's has 18); deeper
trees get STACK_DEPTH. Local memory is reserved per thread for the whole array."""

_KERNEL_SOURCE = r"""
// The walk itself: plain CUDA C, no torch (compiled with nvcc here; the tests also build it
// with a C++ compiler through a few shims, one thread at a time, to check it on a CPU).
#define EXIT_SCALE __EXIT_SCALE__f

// The ray's near (far) plane of an axis is lo (hi) when the direction is positive, hi (lo)
// when negative (sign bit, so -0 counts as negative; either is right for 0). Then
// (plane - o) * (1/d) already comes out as (near, far) in order, and a NaN from 0 * inf
// (a ray lying in a slab plane, parallel to it) drops out of the fmaxf/fminf reductions:
// that slab says "inside", as the contract wants.
__device__ __forceinline__ float pick(bool neg, float lo, float hi) { return neg ? hi : lo; }

// MIN_BLOCKS = 0: registers as the compiler likes (any block up to 1024 threads);
// MIN_BLOCKS > 0: room for that many 256-thread blocks per SM, which caps the registers
// (6 blocks: 40, 75% occupancy) at the price of a few spills (blocks of <= 256 threads).
template <bool ANY_HIT, int STACK, int MIN_BLOCKS>
__global__ void __launch_bounds__(MIN_BLOCKS ? 256 : 1024, MIN_BLOCKS ? MIN_BLOCKS : 1)
trace_kernel(const float4* __restrict__ pairs, const float4* __restrict__ root,
             const float4* __restrict__ tris, int root_ref,
             const float* __restrict__ origins, const float* __restrict__ directions,
             const float* __restrict__ t_min, float t_min_value,
             const float* __restrict__ t_max, float t_max_value,
             float* __restrict__ t_out, long long* __restrict__ id_out,
             float* __restrict__ u_out, float* __restrict__ v_out, int n) {
    const int i = blockIdx.x * blockDim.x + threadIdx.x;
    if (i >= n) return;
    const float ox = origins[3 * i], oy = origins[3 * i + 1], oz = origins[3 * i + 2];
    const float dx = directions[3 * i], dy = directions[3 * i + 1], dz = directions[3 * i + 2];
    const float t_lo = t_min ? t_min[i] : t_min_value;
    float best_t = t_max ? t_max[i] : t_max_value;
    int best_tri = INT_MAX;
    float best_u = 0.0f, best_v = 0.0f;
    // Rays that can hit: finite, a nonzero direction, t_min <= t_max (false for NaN).
    const bool valid = isfinite(ox) && isfinite(oy) && isfinite(oz) && isfinite(dx)
        && isfinite(dy) && isfinite(dz) && (dx != 0.0f || dy != 0.0f || dz != 0.0f)
        && t_lo <= best_t;
    const float ix = __frcp_rn(dx), iy = __frcp_rn(dy), iz = __frcp_rn(dz);
    const bool nx = signbit(ix), ny = signbit(iy), nz = signbit(iz);
    if (valid) {
        // The root's box, from row 0 of the nodes: (lo.xyz, hi.x), (hi.yz, ...).
        const float4 ra = __ldg(root), rb = __ldg(root + 1);
        const float enter = fmaxf(fmaxf(t_lo, (pick(nx, ra.x, ra.w) - ox) * ix),
                                  fmaxf((pick(ny, ra.y, rb.x) - oy) * iy,
                                        (pick(nz, ra.z, rb.y) - oz) * iz));
        const float leave = fminf(best_t, fminf((pick(nx, ra.w, ra.x) - ox) * ix,
                                                fminf((pick(ny, rb.x, ra.y) - oy) * iy,
                                                      (pick(nz, rb.y, ra.z) - oz) * iz))
                                  * EXIT_SCALE);
        int stack[STACK];
        int sp = 0, ref = root_ref;
        bool walking = enter <= leave;
        while (walking) {
            // Interior nodes: one 64-byte row holds both children's boxes and links.
            while (ref >= 0) {
                const float4 px = __ldg(pairs + 4 * ref);
                const float4 py = __ldg(pairs + 4 * ref + 1);
                const float4 pz = __ldg(pairs + 4 * ref + 2);
                const int4 link = __ldg(reinterpret_cast<const int4*>(pairs) + 4 * ref + 3);
                const float ea = fmaxf(fmaxf(t_lo, (pick(nx, px.x, px.y) - ox) * ix),
                                       fmaxf((pick(ny, py.x, py.y) - oy) * iy,
                                             (pick(nz, pz.x, pz.y) - oz) * iz));
                const float la = fminf(best_t, fminf((pick(nx, px.y, px.x) - ox) * ix,
                                                     fminf((pick(ny, py.y, py.x) - oy) * iy,
                                                           (pick(nz, pz.y, pz.x) - oz) * iz))
                                       * EXIT_SCALE);
                const float eb = fmaxf(fmaxf(t_lo, (pick(nx, px.z, px.w) - ox) * ix),
                                       fmaxf((pick(ny, py.z, py.w) - oy) * iy,
                                             (pick(nz, pz.z, pz.w) - oz) * iz));
                const float lb = fminf(best_t, fminf((pick(nx, px.w, px.z) - ox) * ix,
                                                     fminf((pick(ny, py.w, py.z) - oy) * iy,
                                                           (pick(nz, pz.w, pz.z) - oz) * iz))
                                       * EXIT_SCALE);
                const bool ha = ea <= la, hb = eb <= lb;
                if (ha && hb) {  // near child first, the far one on the stack
                    const bool b_first = eb < ea;
                    ref = b_first ? link.y : link.x;
                    stack[sp++] = b_first ? link.x : link.y;
                } else if (ha) {
                    ref = link.x;
                } else if (hb) {
                    ref = link.y;
                } else if (sp > 0) {
                    ref = stack[--sp];
                } else {
                    walking = false;
                    break;
                }
            }
            if (!walking) break;
            // A leaf: its rows from ~ref to the one flagged last (e2.w), Möller–Trumbore.
            for (int row = ~ref;; ++row) {
                const float4 r0 = __ldg(tris + 3 * row);
                const float4 e1 = __ldg(tris + 3 * row + 1);
                const float4 e2 = __ldg(tris + 3 * row + 2);
                const float qx0 = dy * e2.z - dz * e2.y;
                const float qy0 = dz * e2.x - dx * e2.z;
                const float qz0 = dx * e2.y - dy * e2.x;
                const float det = e1.x * qx0 + e1.y * qy0 + e1.z * qz0;
                const float inv = __frcp_rn(det);
                const float sx = ox - r0.x, sy = oy - r0.y, sz = oz - r0.z;
                const float u = (sx * qx0 + sy * qy0 + sz * qz0) * inv;
                const float qx = sy * e1.z - sz * e1.y;
                const float qy = sz * e1.x - sx * e1.z;
                const float qz = sx * e1.y - sy * e1.x;
                const float v = (dx * qx + dy * qy + dz * qz) * inv;
                const float t = (e2.x * qx + e2.y * qy + e2.z * qz) * inv;
                const int tri = __float_as_int(r0.w);
                if (det != 0.0f && u >= 0.0f && v >= 0.0f && u + v <= 1.0f && t >= t_lo
                    && t <= best_t && (t < best_t || tri < best_tri)) {
                    best_t = t; best_tri = tri; best_u = u; best_v = v;
                    if (ANY_HIT) walking = false;
                }
                if (!walking || __float_as_int(e2.w) != 0) break;
            }
            if (!walking || sp == 0) break;
            ref = stack[--sp];
        }
    }
    const bool hit = best_tri != INT_MAX;
    t_out[i] = hit ? best_t : CUDART_INF_F;
    id_out[i] = hit ? (long long)best_tri : -1LL;
    u_out[i] = hit ? best_u : 0.0f;
    v_out[i] = hit ? best_v : 0.0f;
}
"""

_BINDING_SOURCE = r"""
#include <torch/extension.h>
#include <ATen/cuda/CUDAContext.h>
#include <cuda_runtime.h>
#include <math_constants.h>
#include <climits>

__KERNEL__

#define MIN_BLOCKS_CAP __MIN_BLOCKS__

// One of the eight compiled variants: (any hit?, stack entries, register cap?).
template <class T>
static T variant(bool any_hit, int64_t stack, int64_t min_blocks, T a, T b, T c, T d, T e,
                 T f, T g, T h) {
    const T plain[4] = {a, b, c, d}, capped[4] = {e, f, g, h};
    const int k = (any_hit ? 0 : 2) + (stack == 32 ? 0 : 1);
    return min_blocks ? capped[k] : plain[k];
}

template <bool ANY_HIT, int STACK, int MIN_BLOCKS>
static void launch(int grid, int block, cudaStream_t stream, const float4* pairs,
                   const float4* root, const float4* tris, int root_ref, const float* o,
                   const float* d, const float* t_min, float t_min_value, const float* t_max,
                   float t_max_value, float* t, long long* id, float* u, float* v, int n) {
    trace_kernel<ANY_HIT, STACK, MIN_BLOCKS><<<grid, block, 0, stream>>>(
        pairs, root, tris, root_ref, o, d, t_min, t_min_value, t_max, t_max_value, t, id, u,
        v, n);
}

// t_min / t_max: an (N,) float32 tensor, or an empty one and the number in *_value.
std::vector<torch::Tensor> trace(torch::Tensor pairs, torch::Tensor nodes, torch::Tensor tris,
                                 int64_t root_ref, torch::Tensor origins,
                                 torch::Tensor directions, torch::Tensor t_min,
                                 double t_min_value, torch::Tensor t_max, double t_max_value,
                                 bool any_hit, int64_t block, int64_t stack,
                                 int64_t min_blocks) {
    const int n = (int)origins.size(0);
    auto f32 = origins.options();
    auto t = torch::empty({n}, f32), u = torch::empty({n}, f32), v = torch::empty({n}, f32);
    auto id = torch::empty({n}, f32.dtype(torch::kInt64));
    if (n == 0) return {t, id, u, v};
    const int grid = (n + (int)block - 1) / (int)block;
    auto stream = at::cuda::getCurrentCUDAStream();
    const float* lo = t_min.numel() ? t_min.data_ptr<float>() : nullptr;
    const float* hi = t_max.numel() ? t_max.data_ptr<float>() : nullptr;
    auto go = variant<decltype(&launch<true, 32, 0>)>(
        any_hit, stack, min_blocks, launch<true, 32, 0>, launch<true, 64, 0>,
        launch<false, 32, 0>, launch<false, 64, 0>, launch<true, 32, MIN_BLOCKS_CAP>,
        launch<true, 64, MIN_BLOCKS_CAP>, launch<false, 32, MIN_BLOCKS_CAP>,
        launch<false, 64, MIN_BLOCKS_CAP>);
    go(grid, (int)block, stream, (const float4*)pairs.data_ptr<float>(),
       (const float4*)nodes.data_ptr<float>(), (const float4*)tris.data_ptr<float>(),
       (int)root_ref, origins.data_ptr<float>(), directions.data_ptr<float>(), lo,
       (float)t_min_value, hi, (float)t_max_value, t.data_ptr<float>(),
       (long long*)id.data_ptr<int64_t>(), u.data_ptr<float>(), v.data_ptr<float>(), n);
    C10_CUDA_KERNEL_LAUNCH_CHECK();
    return {t, id, u, v};
}

std::vector<int64_t> attributes(bool any_hit, int64_t block, int64_t stack,
                                int64_t min_blocks) {
    cudaFuncAttributes attr;
    int blocks = 0;
    const void* fn = variant<const void*>(
        any_hit, stack, min_blocks, (const void*)trace_kernel<true, 32, 0>,
        (const void*)trace_kernel<true, 64, 0>, (const void*)trace_kernel<false, 32, 0>,
        (const void*)trace_kernel<false, 64, 0>,
        (const void*)trace_kernel<true, 32, MIN_BLOCKS_CAP>,
        (const void*)trace_kernel<true, 64, MIN_BLOCKS_CAP>,
        (const void*)trace_kernel<false, 32, MIN_BLOCKS_CAP>,
        (const void*)trace_kernel<false, 64, MIN_BLOCKS_CAP>);
    C10_CUDA_CHECK(cudaFuncGetAttributes(&attr, fn));
    C10_CUDA_CHECK(cudaOccupancyMaxActiveBlocksPerMultiprocessor(&blocks, fn, (int)block, 0));
    return {attr.numRegs, (int64_t)attr.localSizeBytes, attr.maxThreadsPerBlock,
            (int64_t)attr.sharedSizeBytes, blocks};
}
"""

_CPP_SOURCE = r"""
#include <torch/extension.h>
std::vector<torch::Tensor> trace(torch::Tensor pairs, torch::Tensor nodes, torch::Tensor tris,
                                 int64_t root_ref, torch::Tensor origins,
                                 torch::Tensor directions, torch::Tensor t_min,
                                 double t_min_value, torch::Tensor t_max, double t_max_value,
                                 bool any_hit, int64_t block, int64_t stack,
                                 int64_t min_blocks);
std::vector<int64_t> attributes(bool any_hit, int64_t block, int64_t stack,
                                int64_t min_blocks);
"""

_MODULE = None


def kernel_source() -> str:
    """The walk alone (plain CUDA C, no torch), constants filled in."""
    return _KERNEL_SOURCE.replace("__EXIT_SCALE__", repr(float(EXIT_SCALE)))


def cuda_source() -> str:
    """The CUDA C source as compiled (the walk and its torch binding)."""
    return _BINDING_SOURCE.replace("__KERNEL__", kernel_source()).replace(
        "__MIN_BLOCKS__", str(MIN_BLOCKS)
    )


def stack_entries(bvh: FlatBVH) -> int:
    """The stack the walk of ``bvh`` gets: near-child-first traversal pushes at most one
    entry per interior level (``depth - 1``), so SHORT_STACK unless the tree is deeper."""
    return SHORT_STACK if bvh.depth - 1 <= SHORT_STACK else STACK_DEPTH


def unavailable_reason() -> str | None:
    """Why the CUDA C tracer cannot run here, or None when it can."""
    if not torch.cuda.is_available():
        return "needs CUDA and nvcc: no CUDA device is visible to torch"
    from torch.utils.cpp_extension import CUDA_HOME

    if CUDA_HOME is None:
        return "needs CUDA and nvcc: no CUDA toolkit found (set CUDA_HOME to one with nvcc)"
    return None


def _module():
    """Compile (once per process; torch caches the build on disk) and return the extension."""
    global _MODULE
    if _MODULE is None:
        reason = unavailable_reason()
        if reason is not None:
            raise RuntimeError(reason)
        from torch.utils.cpp_extension import load_inline

        source = cuda_source()
        tag = hashlib.sha1(source.encode()).hexdigest()[:10]
        # sm_90 machine code where the device is a Hopper (torch's default list may hold
        # only older targets plus PTX for the driver to compile at load).
        major, minor = torch.cuda.get_device_capability()
        arch = [f"-gencode=arch=compute_{major}{minor},code=sm_{major}{minor}"]
        _MODULE = load_inline(
            name=f"rtcourse_cuda_tracer_{tag}",
            cpp_sources=_CPP_SOURCE,
            cuda_sources=source,
            functions=["trace", "attributes"],
            extra_cuda_cflags=["-O3", "-lineinfo", *arch],
            verbose=False,
        )
    return _MODULE


def trace_flat_cuda(
    bvh: FlatBVH,
    origins,
    directions,
    t_min=0.0,
    t_max=math.inf,
    *,
    any_hit: bool = False,
    block: int = DEFAULT_BLOCK,
    capped: bool = False,
) -> Hits:
    """Closest (or any) hit of each ray by the CUDA C BVH walk, one thread per ray.

    bvh: ``build_flat_bvh(...)`` on the rays' CUDA device; origins, directions: (N, 3)
    float (traced in float32); t_min, t_max: numbers or (N,) tensors; block: threads per
    block (a multiple of 32, at most 1024; at most 256 with ``capped``); capped: the
    variant with at most 40 registers (see MIN_BLOCKS). Returns float32 ``Hits``.

    One launch and nothing else on the device: the kernel itself sorts out the rays that
    cannot hit (NaN/inf, zero direction, ``t_max < t_min``) and takes numbers for
    ``t_min``/``t_max`` as they are, so no (N,) tensors are made for them.
    """
    module = _module()
    o, d, (lo, lo_value), (hi, hi_value) = check_ray_bounds(origins, directions, t_min, t_max)
    if o.device.type != "cuda":
        raise ValueError(f"origins: expected CUDA tensors, got {o.device}")
    if not isinstance(bvh, FlatBVH) or bvh.nodes.device != o.device:
        raise ValueError("bvh: expected a course.kernels.flat_bvh.FlatBVH on the rays' device")
    if isinstance(block, bool) or not isinstance(block, int) or block % 32 or not 0 < block <= 1024:
        raise ValueError(f"block: expected a multiple of 32 in 32..1024, got {block!r}")
    if capped and block > 256:
        raise ValueError(f"block: the capped variant launches at most 256 threads, got {block}")
    none = o.new_empty(0)
    t, tri, u, v = module.trace(
        bvh.pairs,
        bvh.nodes,
        bvh.triangles,
        bvh.root_ref,
        o,
        d,
        none if lo is None else lo,
        lo_value,
        none if hi is None else hi,
        hi_value,
        bool(any_hit),
        block,
        stack_entries(bvh),
        MIN_BLOCKS if capped else 0,
    )
    return Hits(t=t, triangle=tri, u=u, v=v)


def ptxas_report(arch: str = "sm_90") -> dict:
    """What ptxas says about each variant of the walk: ``{(any_hit, stack, capped): {"regs",
    "stack_frame", "spill_stores", "spill_loads"}}`` (bytes per thread), from ``nvcc
    -Xptxas -v`` on the kernel alone (a few seconds). Needs nvcc, not a GPU."""
    import re
    import subprocess
    import tempfile
    from pathlib import Path

    from torch.utils.cpp_extension import CUDA_HOME

    nvcc = str(Path(CUDA_HOME or "/usr/local/cuda") / "bin" / "nvcc")
    variants = [
        (a, k, m)
        for a in (False, True)
        for k in (SHORT_STACK, STACK_DEPTH)
        for m in (0, MIN_BLOCKS)
    ]
    args = (
        "const float4*, const float4*, const float4*, int, const float*, const float*, "
        "const float*, float, const float*, float, float*, long long*, float*, float*, int"
    )
    lines = [
        f"template __global__ void trace_kernel<{str(a).lower()}, {k}, {m}>({args});"
        for a, k, m in variants
    ]
    with tempfile.TemporaryDirectory() as tmp:
        src = Path(tmp) / "walk.cu"
        src.write_text(
            "#include <climits>\n#include <math_constants.h>\n"
            + kernel_source()
            + "\n".join(lines)
            + "\n"
        )
        out = subprocess.run(
            [
                nvcc,
                "-O3",
                f"-arch={arch}",
                "-Xptxas",
                "-v",
                "-c",
                str(src),
                "-o",
                str(Path(tmp) / "walk.o"),
            ],
            capture_output=True,
            text=True,
            check=True,
        ).stderr
    report = {}
    for block in out.split("Compiling entry function")[1:]:
        name = block.split("'")[1]
        any_hit = "ILb1E" in name
        stack, cap = (int(x) for x in re.search(r"ELi(\d+)ELi(\d+)E", name).groups())
        frame, stores, loads = (
            int(x)
            for x in re.search(
                r"(\d+) bytes stack frame, (\d+) bytes spill stores, (\d+) bytes spill loads", block
            ).groups()
        )
        regs = int(re.search(r"Used (\d+) registers", block).group(1))
        report[any_hit, stack, cap > 0] = {
            "regs": regs,
            "stack_frame": frame,
            "spill_stores": stores,
            "spill_loads": loads,
        }
    return report


@dataclass(frozen=True)
class CudaKernelInfo:
    """What the compiled CUDA kernel uses, and the occupancy it implies, two ways.

    num_regs, local_bytes (per thread: the stack), max_threads_per_block, shared_bytes: from
    cudaFuncGetAttributes; blocks_per_sm_cuda: cudaOccupancyMaxActiveBlocksPerMultiprocessor
    at ``block`` threads; occupancy_cuda: that in warps over the SM's 64 (Hopper);
    blocks_per_sm_model, occupancy_model: course.measure.occupancy for the same inputs.
    """

    name: str
    block: int
    num_regs: int
    local_bytes: int
    max_threads_per_block: int
    shared_bytes: int
    blocks_per_sm_cuda: int
    occupancy_cuda: float
    blocks_per_sm_model: int
    occupancy_model: float


def cuda_kernel_info(
    any_hit: bool = False,
    block: int = DEFAULT_BLOCK,
    arch=None,
    stack: int = SHORT_STACK,
    capped: bool = False,
) -> CudaKernelInfo:
    """Read the compiled kernel's attributes and occupancy (see CudaKernelInfo).

    arch: the course.measure.occupancy preset to model (default: Hopper, the H100/H200 SM);
    stack: the variant's stack entries (SHORT_STACK or STACK_DEPTH, see stack_entries).
    """
    from course.measure.occupancy import HOPPER_H100, occupancy

    arch = arch or HOPPER_H100
    if stack not in (SHORT_STACK, STACK_DEPTH):
        raise ValueError(f"stack: expected {SHORT_STACK} or {STACK_DEPTH}, got {stack!r}")
    regs, local, max_threads, shared, blocks = (
        int(x)
        for x in _module().attributes(bool(any_hit), block, stack, MIN_BLOCKS if capped else 0)
    )
    model = occupancy(arch, regs, block, shared)
    warps = -(-block // 32)
    name = ("cuda_any_hit" if any_hit else "cuda_closest_hit") + ("_capped" if capped else "")
    return CudaKernelInfo(
        name=name,
        block=block,
        num_regs=regs,
        local_bytes=local,
        max_threads_per_block=max_threads,
        shared_bytes=shared,
        blocks_per_sm_cuda=blocks,
        occupancy_cuda=blocks * warps / arch.max_warps_per_sm,
        blocks_per_sm_model=model.blocks_per_sm,
        occupancy_model=model.occupancy,
    )
