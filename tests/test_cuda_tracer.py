"""course.cuda_tracer: the CUDA C BVH tracer, compiled at run time with nvcc.

Without a CUDA device and toolkit only the "clear reason" behaviour is tested; on a GPU the
kernels are held to course.flat_bvh's contract by the float64 rules of tests/test_flat_bvh.py
and their attributes are read back.
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

from course import cuda_tracer as ct
from course.flat_bvh import build_flat_bvh

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
    assert "__STACK_DEPTH__" not in source and "__EXIT_SCALE__" not in source
    assert "#define STACK_DEPTH 64" in source


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
    axis = ct.trace_flat_cuda(build_flat_bvh(v.cuda(), f.cuda(), leaf_size=1), o.cuda(),
                              d.cuda()).to("cpu")
    check_axis_parallel(axis, "CUDA")


@needs_nvcc
def test_cuda_agrees_with_triton_on_the_bunny():
    from course.camera import primary_rays
    from course.flat_bvh import flat_bvh_for
    from course.triton_tracer import trace_flat_triton
    from course.whitted_support import whitted_camera, whitted_scene

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
        assert info.local_bytes >= 4 * 64, "the 64-entry stack lives in local memory"
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
