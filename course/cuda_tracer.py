"""The lecture's own tracer in CUDA C: the speed-of-light reference for the Triton kernels.

One thread per ray, the BVH stack in a local array (``int stack[64]``: registers cannot be
indexed dynamically, so the compiler puts it in local memory, per-thread device memory
cached in L1), near child first, Möller–Trumbore on float4 triangles with the triangle's
index in ``w``. It walks the same flat BVH (course.flat_bvh) with the same contract as
course.triton_tracer, in the form a CUDA programmer writes it: real per-thread branches
and loops where Triton needs masked lock-step steps.

Compiled at first use with ``torch.utils.cpp_extension.load_inline`` (nvcc, ~1 minute; the
result is cached on disk by torch). Needs a CUDA device and a CUDA toolkit; without them
every entry point raises ``RuntimeError("needs CUDA and nvcc: ...")`` (see
:func:`unavailable_reason`).

The compiled kernels are read back with ``cudaFuncGetAttributes`` (registers per thread,
local memory per thread, the largest block the kernel can launch with) and
``cudaOccupancyMaxActiveBlocksPerMultiprocessor``, next to ``course.occupancy``'s model of
the same numbers (:func:`cuda_kernel_info`).

Accuracy contract: course.flat_bvh's (float32, IEEE division, NaN-safe slab test with
Ize's widened exit, closed ``[t_min, t_max]``, ties to the lower original triangle index,
NaN/inf/zero-direction rays miss, not watertight). Any hit returns the first hit found.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass

import torch

from course.flat_bvh import EXIT_SCALE, STACK_DEPTH, FlatBVH, check_rays, valid_rays
from course.types import Hits

__all__ = ["CudaKernelInfo", "cuda_kernel_info", "trace_flat_cuda", "unavailable_reason"]

DEFAULT_BLOCK = 128

_CUDA_SOURCE = r"""
#include <torch/extension.h>
#include <ATen/cuda/CUDAContext.h>
#include <cuda_runtime.h>
#include <math_constants.h>
#include <climits>

#define STACK_DEPTH __STACK_DEPTH__
#define EXIT_SCALE __EXIT_SCALE__f

// Slab test of one node's box: nodes are two float4, (lo.xyz, hi.x) and (hi.yz, ints).
// A NaN from 0 * inf (ray parallel to and inside a slab plane) counts as inside.
__device__ __forceinline__ bool box_hit(const float4* __restrict__ nodes, int node,
                                        float ox, float oy, float oz,
                                        float ix, float iy, float iz,
                                        float t_lo, float t_hi, float& enter) {
    const float4 a = __ldg(nodes + 2 * node);
    const float4 b = __ldg(nodes + 2 * node + 1);
    float t0 = (a.x - ox) * ix, t1 = (a.w - ox) * ix;
    float nx = fminf(t0, t1), fx = fmaxf(t0, t1);
    if (t0 != t0 || t1 != t1) { nx = -CUDART_INF_F; fx = CUDART_INF_F; }
    t0 = (a.y - oy) * iy; t1 = (b.x - oy) * iy;
    float ny = fminf(t0, t1), fy = fmaxf(t0, t1);
    if (t0 != t0 || t1 != t1) { ny = -CUDART_INF_F; fy = CUDART_INF_F; }
    t0 = (a.z - oz) * iz; t1 = (b.y - oz) * iz;
    float nz = fminf(t0, t1), fz = fmaxf(t0, t1);
    if (t0 != t0 || t1 != t1) { nz = -CUDART_INF_F; fz = CUDART_INF_F; }
    enter = fmaxf(fmaxf(t_lo, nx), fmaxf(ny, nz));
    const float leave = fminf(t_hi, fminf(fx, fminf(fy, fz)) * EXIT_SCALE);
    return enter <= leave;
}

template <bool ANY_HIT>
__global__ void trace_kernel(const float4* __restrict__ nodes, const float4* __restrict__ tris,
                             const float* __restrict__ origins,
                             const float* __restrict__ directions,
                             const float* __restrict__ t_min, const float* __restrict__ t_max,
                             float* __restrict__ t_out, long long* __restrict__ id_out,
                             float* __restrict__ u_out, float* __restrict__ v_out, int n) {
    const int i = blockIdx.x * blockDim.x + threadIdx.x;
    if (i >= n) return;
    const float ox = origins[3 * i], oy = origins[3 * i + 1], oz = origins[3 * i + 2];
    const float dx = directions[3 * i], dy = directions[3 * i + 1], dz = directions[3 * i + 2];
    const float t_lo = t_min[i];
    float best_t = t_max[i];
    int best_row = -1, best_tri = INT_MAX;
    float best_u = 0.0f, best_v = 0.0f;
    // The launcher gives rays that cannot hit the empty interval [inf, -inf].
    const float ix = __frcp_rn(dx), iy = __frcp_rn(dy), iz = __frcp_rn(dz);
    float enter;
    if (t_lo <= best_t && box_hit(nodes, 0, ox, oy, oz, ix, iy, iz, t_lo, best_t, enter)) {
        int stack[STACK_DEPTH];
        int sp = 0, node = 0;
        while (true) {
            const float4 meta = __ldg(nodes + 2 * node + 1);
            const int word6 = __float_as_int(meta.z), count = __float_as_int(meta.w);
            if (count == 0) {  // interior: both children, nearer first
                const int a = node + 1, b = word6;
                float ta, tb;
                const bool ha = box_hit(nodes, a, ox, oy, oz, ix, iy, iz, t_lo, best_t, ta);
                const bool hb = box_hit(nodes, b, ox, oy, oz, ix, iy, iz, t_lo, best_t, tb);
                if (ha && hb) {
                    const bool b_first = tb < ta;
                    node = b_first ? b : a;
                    stack[sp++] = b_first ? a : b;
                    continue;
                }
                if (ha || hb) {
                    node = ha ? a : b;
                    continue;
                }
            } else {  // leaf: Möller–Trumbore against each triangle
                bool done = false;
                for (int row = word6; row < word6 + count; ++row) {
                    const float4 r0 = __ldg(tris + 3 * row);
                    const float4 e1 = __ldg(tris + 3 * row + 1);
                    const float4 e2 = __ldg(tris + 3 * row + 2);
                    const float px = dy * e2.z - dz * e2.y;
                    const float py = dz * e2.x - dx * e2.z;
                    const float pz = dx * e2.y - dy * e2.x;
                    const float det = e1.x * px + e1.y * py + e1.z * pz;
                    const float inv = __frcp_rn(det);
                    const float sx = ox - r0.x, sy = oy - r0.y, sz = oz - r0.z;
                    const float u = (sx * px + sy * py + sz * pz) * inv;
                    const float qx = sy * e1.z - sz * e1.y;
                    const float qy = sz * e1.x - sx * e1.z;
                    const float qz = sx * e1.y - sy * e1.x;
                    const float v = (dx * qx + dy * qy + dz * qz) * inv;
                    const float t = (e2.x * qx + e2.y * qy + e2.z * qz) * inv;
                    const int tri = __float_as_int(r0.w);
                    if (det != 0.0f && u >= 0.0f && v >= 0.0f && u + v <= 1.0f && t >= t_lo
                        && t <= best_t && (t < best_t || tri < best_tri)) {
                        best_t = t; best_row = row; best_tri = tri; best_u = u; best_v = v;
                        if (ANY_HIT) { done = true; break; }
                    }
                }
                if (done) break;
            }
            if (sp == 0) break;
            node = stack[--sp];
        }
    }
    const bool hit = best_row >= 0;
    t_out[i] = hit ? best_t : CUDART_INF_F;
    id_out[i] = hit ? (long long)best_tri : -1LL;
    u_out[i] = hit ? best_u : 0.0f;
    v_out[i] = hit ? best_v : 0.0f;
}

void trace(torch::Tensor nodes, torch::Tensor tris, torch::Tensor origins,
           torch::Tensor directions, torch::Tensor t_min, torch::Tensor t_max,
           torch::Tensor t_out, torch::Tensor id_out, torch::Tensor u_out, torch::Tensor v_out,
           bool any_hit, int64_t block) {
    const int n = (int)origins.size(0);
    if (n == 0) return;
    const int grid = (n + (int)block - 1) / (int)block;
    auto stream = at::cuda::getCurrentCUDAStream();
    const float4* nd = (const float4*)nodes.data_ptr<float>();
    const float4* tr = (const float4*)tris.data_ptr<float>();
    long long* ids = (long long*)id_out.data_ptr<int64_t>();
    if (any_hit) {
        trace_kernel<true><<<grid, (int)block, 0, stream>>>(
            nd, tr, origins.data_ptr<float>(), directions.data_ptr<float>(),
            t_min.data_ptr<float>(), t_max.data_ptr<float>(), t_out.data_ptr<float>(), ids,
            u_out.data_ptr<float>(), v_out.data_ptr<float>(), n);
    } else {
        trace_kernel<false><<<grid, (int)block, 0, stream>>>(
            nd, tr, origins.data_ptr<float>(), directions.data_ptr<float>(),
            t_min.data_ptr<float>(), t_max.data_ptr<float>(), t_out.data_ptr<float>(), ids,
            u_out.data_ptr<float>(), v_out.data_ptr<float>(), n);
    }
    C10_CUDA_KERNEL_LAUNCH_CHECK();
}

std::vector<int64_t> attributes(bool any_hit, int64_t block) {
    cudaFuncAttributes attr;
    int blocks = 0;
    const void* fn = any_hit ? (const void*)trace_kernel<true> : (const void*)trace_kernel<false>;
    C10_CUDA_CHECK(cudaFuncGetAttributes(&attr, fn));
    C10_CUDA_CHECK(cudaOccupancyMaxActiveBlocksPerMultiprocessor(&blocks, fn, (int)block, 0));
    return {attr.numRegs, (int64_t)attr.localSizeBytes, attr.maxThreadsPerBlock,
            (int64_t)attr.sharedSizeBytes, blocks};
}
"""

_CPP_SOURCE = r"""
#include <torch/extension.h>
void trace(torch::Tensor nodes, torch::Tensor tris, torch::Tensor origins,
           torch::Tensor directions, torch::Tensor t_min, torch::Tensor t_max,
           torch::Tensor t_out, torch::Tensor id_out, torch::Tensor u_out, torch::Tensor v_out,
           bool any_hit, int64_t block);
std::vector<int64_t> attributes(bool any_hit, int64_t block);
"""

_MODULE = None


def cuda_source() -> str:
    """The CUDA C source as compiled (constants filled in)."""
    return (_CUDA_SOURCE.replace("__STACK_DEPTH__", str(STACK_DEPTH))
            .replace("__EXIT_SCALE__", repr(float(EXIT_SCALE))))


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
        _MODULE = load_inline(name=f"rtcourse_cuda_tracer_{tag}", cpp_sources=_CPP_SOURCE,
                              cuda_sources=source, functions=["trace", "attributes"],
                              extra_cuda_cflags=["-O3", "-lineinfo"], verbose=False)
    return _MODULE


def trace_flat_cuda(bvh: FlatBVH, origins, directions, t_min=0.0, t_max=math.inf, *,
                    any_hit: bool = False, block: int = DEFAULT_BLOCK) -> Hits:
    """Closest (or any) hit of each ray by the CUDA C BVH walk, one thread per ray.

    bvh: ``build_flat_bvh(...)`` on the rays' CUDA device; origins, directions: (N, 3)
    float (traced in float32); t_min, t_max: numbers or (N,) tensors; block: threads per
    block (a multiple of 32, at most 1024). Returns float32 ``Hits``.
    """
    module = _module()
    o, d, t_lo, t_hi = check_rays(origins, directions, t_min, t_max)
    if o.device.type != "cuda":
        raise ValueError(f"origins: expected CUDA tensors, got {o.device}")
    if not isinstance(bvh, FlatBVH) or bvh.nodes.device != o.device:
        raise ValueError("bvh: expected a course.flat_bvh.FlatBVH on the rays' device")
    if isinstance(block, bool) or not isinstance(block, int) or block % 32 or not \
            0 < block <= 1024:
        raise ValueError(f"block: expected a multiple of 32 in 32..1024, got {block!r}")
    ok = valid_rays(o, d, t_lo, t_hi)
    t_lo = torch.where(ok, t_lo, math.inf)
    t_hi = torch.where(ok, t_hi, -math.inf)
    n = o.shape[0]
    hits = Hits(t=torch.empty(n, device=o.device), triangle=torch.empty(n, dtype=torch.int64,
                                                                        device=o.device),
                u=torch.empty(n, device=o.device), v=torch.empty(n, device=o.device))
    module.trace(bvh.nodes, bvh.triangles, o, d, t_lo, t_hi, hits.t, hits.triangle, hits.u,
                 hits.v, bool(any_hit), block)
    return hits


@dataclass(frozen=True)
class CudaKernelInfo:
    """What the compiled CUDA kernel uses, and the occupancy it implies, two ways.

    num_regs, local_bytes (per thread: the stack), max_threads_per_block, shared_bytes: from
    cudaFuncGetAttributes; blocks_per_sm_cuda: cudaOccupancyMaxActiveBlocksPerMultiprocessor
    at ``block`` threads; occupancy_cuda: that in warps over the SM's 64 (Hopper);
    blocks_per_sm_model, occupancy_model: course.occupancy for the same inputs.
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


def cuda_kernel_info(any_hit: bool = False, block: int = DEFAULT_BLOCK, arch=None) -> CudaKernelInfo:
    """Read the compiled kernel's attributes and occupancy (see CudaKernelInfo).

    arch: the course.occupancy preset to model (default: Hopper, the H100/H200 SM).
    """
    from course.occupancy import HOPPER_H100, occupancy

    arch = arch or HOPPER_H100
    regs, local, max_threads, shared, blocks = (int(x) for x in _module().attributes(
        bool(any_hit), block))
    model = occupancy(arch, regs, block, shared)
    warps = -(-block // 32)
    return CudaKernelInfo(name="cuda_any_hit" if any_hit else "cuda_closest_hit", block=block,
                          num_regs=regs, local_bytes=local, max_threads_per_block=max_threads,
                          shared_bytes=shared, blocks_per_sm_cuda=blocks,
                          occupancy_cuda=blocks * warps / arch.max_warps_per_sm,
                          blocks_per_sm_model=model.blocks_per_sm,
                          occupancy_model=model.occupancy)
