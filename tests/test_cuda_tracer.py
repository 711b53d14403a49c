"""course.kernels.cuda_tracer: the CUDA C BVH tracer, compiled at run time with nvcc.

Without a CUDA device and toolkit only the "clear reason" behaviour is tested; on a GPU the
kernels are held to course.kernels.flat_bvh's contract by the float64 rules of
tests/test_flat_bvh.py and their attributes are read back.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import pytest
import torch

REPO = Path(__file__).resolve().parents[1]
for path in (REPO, REPO / "tests"):
    if str(path) not in sys.path:
        sys.path.insert(0, str(path))

from test_flat_bvh import (
    axis_parallel_case,
    brute_force64,
    check_axis_parallel,
    check_hits,
    make_case,
)

from course.kernels import cuda_tracer as ct
from course.kernels.flat_bvh import build_flat_bvh

REASON = ct.unavailable_reason()
needs_nvcc = pytest.mark.skipif(REASON is not None, reason=REASON or "")


def test_unavailable_reason_is_clear():
    if REASON is None:
        assert ct.unavailable_reason() is None
        return
    assert REASON.startswith("needs CUDA and nvcc: ")
    case = make_case(n_tris=20, n_rays=64, seed=1)
    bvh = build_flat_bvh(case["vertices"], case["faces"])
    with pytest.raises(RuntimeError, match="needs CUDA and nvcc"):
        ct.trace_flat_cuda(bvh, case["origins"], case["directions"])
    with pytest.raises(RuntimeError, match="needs CUDA and nvcc"):
        ct.cuda_kernel_info()


def test_source_fills_in_the_shared_constants():
    source = ct.cuda_source()
    for placeholder in ("__KERNEL__", "__EXIT_SCALE__", "__MIN_BLOCKS__"):
        assert placeholder not in source, f"{placeholder} was not filled in"
    assert "trace_kernel<ANY_HIT, STACK, MIN_BLOCKS>" in source and ct.kernel_source() in source
    assert f"#define MIN_BLOCKS_CAP {ct.MIN_BLOCKS}" in source


# The walk is plain CUDA C: with these shims a C++ compiler builds it for the CPU, one
# thread at a time, so its logic is checked where there is no GPU.
CPU_SHIMS = r"""
#include <climits>
#include <cmath>
#include <cstring>
struct float4 { float x, y, z, w; };
struct int4 { int x, y, z, w; };
struct Index { int x; };
static Index blockIdx = {0}, blockDim = {1}, threadIdx = {0};
#define __global__
#define __device__
#define __forceinline__ inline
#define __launch_bounds__(...)
#define __restrict__
#define CUDART_INF_F INFINITY
template <class T> static inline T __ldg(const T* p) { return *p; }
static inline float __frcp_rn(float x) { return 1.0f / x; }
static inline int __float_as_int(float f) { int i; std::memcpy(&i, &f, 4); return i; }
using std::isfinite;
using std::signbit;
"""

CPU_ENTRY = r"""
extern "C" void trace_cpu(const float* pairs, const float* nodes, const float* tris,
                          int root_ref, const float* o, const float* d, const float* t_min,
                          const float* t_max, float* t, long long* id, float* u, float* v,
                          int n, int any_hit) {
    blockDim.x = n;
    for (int i = 0; i < n; ++i) {
        threadIdx.x = i;
        auto kernel = any_hit ? trace_kernel<true, 64, 0> : trace_kernel<false, 64, 0>;
        kernel((const float4*)pairs, (const float4*)nodes, (const float4*)tris, root_ref,
               o, d, t_min, 0.0f, t_max, 0.0f, t, id, u, v, n);
    }
}
"""


def cpu_build(tmp_path):
    """The kernel built for the CPU with the shims (ctypes), or skip without g++."""
    import ctypes
    import shutil
    import subprocess

    cxx = shutil.which("g++") or shutil.which("c++")
    if cxx is None:
        pytest.skip("no C++ compiler to build the CUDA C walk for the CPU")
    src, lib = tmp_path / "walk.cpp", tmp_path / "walk.so"
    src.write_text(CPU_SHIMS + ct.kernel_source() + CPU_ENTRY)
    subprocess.run(
        [cxx, "-O1", "-ffp-contract=off", "-shared", "-fPIC", str(src), "-o", str(lib)],
        check=True,
        capture_output=True,
    )
    walk = ctypes.CDLL(str(lib))
    pointer, number = ctypes.c_void_p, ctypes.c_int
    walk.trace_cpu.argtypes = [pointer] * 3 + [number] + [pointer] * 8 + [number, number]
    return walk


def trace_cpu(walk, bvh, case, any_hit=False):
    from course.core.types import Hits

    n = case["origins"].shape[0]
    out = Hits(
        t=torch.full((n,), -1.0),
        triangle=torch.full((n,), -7, dtype=torch.int64),
        u=torch.full((n,), -1.0),
        v=torch.full((n,), -1.0),
    )  # poisoned
    args = [
        bvh.pairs,
        bvh.nodes,
        bvh.triangles,
        bvh.root_ref,
        *(case[k].contiguous() for k in ("origins", "directions", "t_min", "t_max")),
        out.t,
        out.triangle,
        out.u,
        out.v,
        n,
        int(any_hit),
    ]
    walk.trace_cpu(*(x.data_ptr() if isinstance(x, torch.Tensor) else x for x in args))
    return out


@pytest.mark.parametrize("shift", [0.0, 1e5], ids=["unit", "far1e5"])
def test_cuda_walk_built_for_the_cpu_matches_float64_brute_force(tmp_path, shift):
    walk = cpu_build(tmp_path)
    case = make_case(n_tris=300, n_rays=400, seed=13, shift=shift)
    bvh = build_flat_bvh(case["vertices"], case["faces"])
    ref = brute_force64(case)
    closest = trace_cpu(walk, bvh, case)
    check_hits(case, closest, f"CUDA C walk on the CPU, shift {shift}", ref=ref)
    occluded = trace_cpu(walk, bvh, case, any_hit=True)
    check_hits(
        case, occluded, f"CUDA C walk on the CPU, any hit, shift {shift}", any_hit=True, ref=ref
    )
    assert torch.equal(occluded.hit, closest.hit)
    v, f, o, d = axis_parallel_case()
    axis = {
        "origins": o,
        "directions": d,
        "t_min": torch.zeros(len(o)),
        "t_max": torch.full((len(o),), math.inf),
    }
    check_axis_parallel(
        trace_cpu(walk, build_flat_bvh(v, f, leaf_size=1), axis), "CUDA C walk on the CPU"
    )
    single = build_flat_bvh(case["vertices"], case["faces"][:1])  # the root is a leaf
    assert single.root_ref == -1
    one = trace_cpu(walk, single, case)
    want = brute_force64({**case, "faces": case["faces"][:1]})
    check_hits({**case, "faces": case["faces"][:1]}, one, "CUDA C walk, one leaf", ref=want)


@needs_nvcc
@pytest.mark.parametrize("shift", [0.0, 1e5], ids=["unit", "far1e5"])
def test_cuda_matches_float64_brute_force(shift):
    case = make_case(n_tris=2000, n_rays=3000, seed=11, shift=shift)
    bvh = build_flat_bvh(case["vertices"].cuda(), case["faces"].cuda())
    args = [case[k].cuda() for k in ("origins", "directions", "t_min", "t_max")]
    ref = brute_force64(case)
    closest = ct.trace_flat_cuda(bvh, *args).to("cpu")
    check_hits(case, closest, f"CUDA closest hit, shift {shift}", ref=ref)
    occluded = ct.trace_flat_cuda(bvh, *args, any_hit=True).to("cpu")
    check_hits(case, occluded, f"CUDA any hit, shift {shift}", any_hit=True, ref=ref)
    assert torch.equal(occluded.hit, closest.hit)
    v, f, o, d = axis_parallel_case()
    axis = ct.trace_flat_cuda(
        build_flat_bvh(v.cuda(), f.cuda(), leaf_size=1), o.cuda(), d.cuda()
    ).to("cpu")
    check_axis_parallel(axis, "CUDA")


@needs_nvcc
def test_cuda_agrees_with_triton_on_the_bunny():
    from course.core.camera import primary_rays
    from course.given.lab3 import whitted_camera, whitted_scene
    from course.kernels.flat_bvh import flat_bvh_for
    from course.kernels.triton_tracer import trace_flat_triton

    scene = whitted_scene("bunny_mirror", device="cuda")
    bvh = flat_bvh_for(scene)
    rays = primary_rays(whitted_camera("bunny_mirror", 256, 256), "cuda")
    a = ct.trace_flat_cuda(bvh, rays.origins, rays.directions)
    b = trace_flat_triton(bvh, rays.origins, rays.directions)
    same = (a.triangle == b.triangle).float().mean().item()
    assert same >= 0.999, f"CUDA and Triton agree on only {same:.2%} of the bunny's rays"
    assert torch.allclose(a.t[a.hit], b.t[a.hit], rtol=1e-6) or same == 1.0


@needs_nvcc
def test_attributes_are_read_back():
    for any_hit in (False, True):
        info = ct.cuda_kernel_info(any_hit=any_hit, block=128)
        assert 0 < info.num_regs <= 255
        assert info.local_bytes >= 4 * ct.SHORT_STACK, "the stack lives in local memory"
        assert info.max_threads_per_block >= 128
        assert info.blocks_per_sm_cuda >= 1 and 0 < info.occupancy_cuda <= 1
        assert 0 < info.occupancy_model <= 1
        print(info)


@needs_nvcc
def test_bad_arguments_raise_clear_errors():
    case = make_case(n_tris=20, n_rays=64, seed=1)
    bvh = build_flat_bvh(case["vertices"].cuda(), case["faces"].cuda())
    o, d = case["origins"].cuda(), case["directions"].cuda()
    with pytest.raises(ValueError, match="origins"):
        ct.trace_flat_cuda(bvh, o.cpu(), d.cpu())
    with pytest.raises(ValueError, match="block"):
        ct.trace_flat_cuda(bvh, o, d, block=48)
    with pytest.raises(ValueError, match="bvh"):
        ct.trace_flat_cuda(bvh.to("cpu"), o, d)
    with pytest.raises(ValueError, match="directions"):
        ct.trace_flat_cuda(bvh, o, d[:3])
    assert math.isinf(float(ct.trace_flat_cuda(bvh, o[:1], torch.zeros_like(d[:1])).t[0]))
