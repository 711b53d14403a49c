"""course.kernels.triton_tracer: the Triton BVH walk and the Whitted uber kernel.

On the CPU the kernels run in Triton's interpreter (TRITON_INTERPRET=1, which must be set
before triton is imported, hence a subprocess) at tiny sizes; on CUDA the compiled kernels
run at moderate sizes and report their registers and spills. Both are held to
course.kernels.flat_bvh's contract by the float64 rules of tests/test_flat_bvh.py, and the uber
kernel to course.given.lab3.render_reference.
"""

from __future__ import annotations

import importlib.util
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
    check_vertex_hits,
    make_case,
    vertex_case,
)

from course.grading.testing import run_in_triton_interpreter

HAVE_TRITON = importlib.util.find_spec("triton") is not None
needs_triton = pytest.mark.skipif(not HAVE_TRITON, reason="triton is not installed")


def render_cases(size: int) -> dict:
    from course.core.camera import primary_rays
    from course.given.lab3 import whitted_camera

    out = {}
    for name in ("cornell_mirror", "mirror_corridor"):
        rays = primary_rays(whitted_camera(name, size, size), "cpu")
        o, d = rays.origins.clone(), rays.directions.clone()
        o[0, 0] = math.nan  # an invalid primary ray sees the background
        out[name] = (o, d)
    return out


def run_kernels(case: dict, renders: dict, device: str) -> dict:
    """Every kernel on the cases, results on the CPU, plus kernel infos."""
    from course.given.lab3 import whitted_scene
    from course.kernels import triton_tracer as tt
    from course.kernels.flat_bvh import build_flat_bvh

    out: dict = {"interpreting": tt.interpreting(), "info": {}}
    bvh = build_flat_bvh(case["vertices"].to(device), case["faces"].to(device))
    args = [case[k].to(device) for k in ("origins", "directions", "t_min", "t_max")]
    for any_hit in (False, True):
        hits, info = tt.trace_flat_triton(bvh, *args, any_hit=any_hit, return_info=True)
        out["any" if any_hit else "closest"] = hits.to("cpu")
        out["info"][info.name] = info
    # Skipping stages no lane needs must not change a single result.
    out["masked_only"] = tt.trace_flat_triton(bvh, *args, uniform_branches=False).to("cpu")
    # Nor may the stack's place or the triangle tests per step (a deep tree of single
    # triangles: stacks deeper than the four register entries).
    deep = build_flat_bvh(case["vertices"].to(device), case["faces"].to(device), leaf_size=1)
    out["deep"] = tt.trace_flat_triton(deep, *args).to("cpu")
    out["depth"] = deep.depth
    out["variants"] = {
        (regs, tris, spec): tt.trace_flat_triton(
            deep, *args, stack_regs=regs, tris_per_step=tris, speculate=spec
        ).to("cpu")
        for regs, tris, spec in (
            (0, 1, False),
            (4, 1, False),
            (4, 2, False),
            (0, 2, True),
            (4, 2, True),
        )
    }
    for spec in (False, True):
        out["any", spec] = tt.trace_flat_triton(deep, *args, any_hit=True, speculate=spec).to("cpu")
    # Every loop shape and stack place (the local stack compiled only; the interpreter,
    # whose default walk is the while-while loop, runs the if-if loop once more): the
    # same results as the default walk.
    loops = (
        [("if", "global", 4, True)]
        if tt.interpreting()
        else [
            (loop, stack, regs, spec)
            for loop in ("if", "while")
            for stack in ("global", "local")
            for regs in (0, 4)
            for spec in (False, True)
            if not (stack == "local" and regs)
        ]
    )
    out["loops"] = {
        key: tt.trace_flat_triton(
            deep, *args, loop=key[0], stack=key[1], stack_regs=key[2], speculate=key[3]
        ).to("cpu")
        for key in loops
    }
    out["loops_any"] = {
        key: tt.trace_flat_triton(
            deep,
            *args,
            loop=key[0],
            stack=key[1],
            stack_regs=key[2],
            speculate=key[3],
            any_hit=True,
        ).to("cpu")
        for key in loops
    }
    # Persistent programs that take new rays as lanes free up (the default walk): one
    # program, so that every lane is refilled (whole batches, a quarter of the lanes free,
    # any free lane), and none (refill=0: a program per block of rays).
    out["refill"] = {
        (refill, any_hit): tt.trace_flat_triton(
            deep, *args, refill=refill, programs=1 if refill else None, any_hit=any_hit
        ).to("cpu")
        for refill in (32, 8, 1, 0)
        for any_hit in (False, True)
    }
    # Fewer rays than a program's lanes, and one more: the counter runs out at the first
    # take and within the second.
    out["refill_few"] = {
        n: (
            tt.trace_flat_triton(deep, *[a[:n] for a in args], refill=8, programs=1).to("cpu"),
            tt.trace_flat_triton(deep, *[a[:n] for a in args], refill=0).to("cpu"),
        )
        for n in (1, 33)
    }
    v, f, o, d = axis_parallel_case()
    out["axis"] = tt.trace_flat_triton(
        build_flat_bvh(v.to(device), f.to(device), leaf_size=1), o.to(device), d.to(device)
    ).to("cpu")
    out["render"] = {}
    for name, (o, d) in renders.items():
        scene = whitted_scene(name, device=device)
        rgb, info = tt.render_whitted_triton(scene, o.to(device), d.to(device), return_info=True)
        out["render"][name] = rgb.cpu()
        out["info"][info.name] = info
    empty = torch.zeros(0, 3, device=device)
    out["empty"] = len(tt.trace_flat_triton(bvh, empty, empty))
    return out


def check_all(case: dict, renders: dict, out: dict, label: str) -> None:
    from course.given.lab3 import render_reference, whitted_scene

    ref = brute_force64(case)
    check_hits(case, out["closest"], f"{label} closest hit", ref=ref)
    check_hits(case, out["any"], f"{label} any hit", any_hit=True, ref=ref)
    assert torch.equal(out["any"].hit, out["closest"].hit), (
        f"{label}: any hit and closest hit disagree on occlusion for rays "
        f"{(out['any'].hit != out['closest'].hit).nonzero()[:, 0].tolist()}"
    )
    check_axis_parallel(out["axis"], label)
    for field in ("t", "triangle", "u", "v"):
        assert torch.equal(getattr(out["masked_only"], field), getattr(out["closest"], field)), (
            f"{label}: uniform_branches=False changed {field}: the stages must be skipped "
            f"only where no lane needs them"
        )
    assert out["empty"] == 0
    check_hits(case, out["deep"], f"{label} closest hit, leaves of 1", ref=ref)
    assert out["depth"] > 6, "the deep tree must need more than the four register entries"
    for (regs, tris, spec), hits in out["variants"].items():
        for field in ("t", "triangle", "u", "v"):
            assert torch.equal(getattr(hits, field), getattr(out["deep"], field)), (
                f"{label}: stack_regs={regs}, tris_per_step={tris}, speculate={spec} "
                f"changed {field}"
            )
    for spec in (False, True):
        check_hits(
            case, out["any", spec], f"{label} any hit, speculate={spec}", any_hit=True, ref=ref
        )
        assert torch.equal(out["any", spec].hit, out["deep"].hit)
    for (loop, stack, regs, spec), hits in out["loops"].items():
        what = f"{label}: loop={loop!r}, stack={stack!r}, stack_regs={regs}, speculate={spec}"
        for field in ("t", "triangle", "u", "v"):
            assert torch.equal(getattr(hits, field), getattr(out["deep"], field)), (
                f"{what} changed {field} on rays "
                f"{(getattr(hits, field) != getattr(out['deep'], field)).nonzero()[:8, 0]}"
            )
        check_hits(
            case,
            out["loops_any"][loop, stack, regs, spec],
            f"{what} any hit",
            any_hit=True,
            ref=ref,
        )
    for (refill, any_hit), hits in out["refill"].items():
        what = f"{label}: refill={refill}" + (", one program" if refill else "")
        if any_hit:
            check_hits(case, hits, f"{what}, any hit", any_hit=True, ref=ref)
            continue
        for field in ("t", "triangle", "u", "v"):
            assert torch.equal(getattr(hits, field), getattr(out["deep"], field)), (
                f"{what} changed {field} on rays "
                f"{(getattr(hits, field) != getattr(out['deep'], field)).nonzero()[:8, 0]}"
            )
    for n, (got, want) in out["refill_few"].items():
        for field in ("t", "triangle", "u", "v"):
            assert torch.equal(getattr(got, field), getattr(want, field)), (
                f"{label}: refill=8 on {n} ray(s) changed {field}"
            )
    for name, (o, d) in renders.items():
        scene = whitted_scene(name, device="cpu")
        want = render_reference(scene, o, d)
        got = out["render"][name].double()
        assert torch.isfinite(got).all(), f"{label} {name}: non-finite radiance"
        assert torch.equal(got[0], scene.background.double()), (
            f"{label} {name}: a NaN primary ray must see the background, got {got[0].tolist()}"
        )
        err = (got - want).abs().amax(1) / want.abs().amax(1).clamp(min=1e-3)
        # float32 vs float64: pixels may differ where a shadow or a mirror edge falls
        # between the two roundings; everywhere else they agree to ~1e-5.
        bad = (err > 1e-3).float().mean().item()
        assert bad <= 0.02, (
            f"{label} {name}: {bad:.1%} of the pixels differ from render_reference by more "
            f"than 0.1% (worst {err.max().item():.3g} at pixel {int(err.argmax())})"
        )


@needs_triton
def test_interpreted_kernels_follow_the_contract(tmp_path):
    case = make_case(n_tris=80, n_rays=64, seed=5)
    renders = render_cases(5)
    out = run_in_triton_interpreter(__file__, {"case": case, "renders": renders}, tmp_path)
    assert out["interpreting"], "the subprocess did not run Triton's interpreter"
    check_all(case, renders, out, "interpreted")
    for info in out["info"].values():
        assert info.n_regs is None and info.occupancy() is None


def run_vertex_case(case: dict, device: str) -> dict:
    """The closest-hit walk on rays aimed at shared vertices and edges, leaves of 1 and 4,
    and its brute force: the same kernel on one leaf of every triangle (its own
    Möller–Trumbore on each, no box but the root's)."""
    from course.kernels import triton_tracer as tt
    from course.kernels.flat_bvh import build_flat_bvh

    rays = [case[k].to(device) for k in ("origins", "directions")]
    faces = len(case["faces"])
    return {
        leaf: tt.trace_flat_triton(
            build_flat_bvh(case["vertices"].to(device), case["faces"].to(device), leaf_size=leaf),
            *rays,
        ).to("cpu")
        for leaf in (1, 4, faces)
    }


@needs_triton
def test_interpreted_walk_at_shared_vertices_hits_as_brute_force(tmp_path):
    """The kernel's box test is conservative like the torch walk's: rays aimed at a mesh's
    shared vertices and edges hit what brute-force Möller–Trumbore hits (same triangle, same
    t) and miss only where it misses."""
    case = vertex_case(edges=False)
    out = run_in_triton_interpreter(__file__, {"vertex_case": case}, tmp_path)
    brute = out.pop(len(case["faces"]))
    assert brute.hit.any() and not brute.hit.all(), "a mesh's vertices: hits and misses"
    for leaf, hits in out.items():
        check_vertex_hits(case, hits, f"interpreted trace_flat_triton, leaves of {leaf}", ref=brute)


@needs_triton
@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
def test_compiled_walk_at_shared_vertices_hits_as_brute_force():
    _compiled_tracer()  # skips under the interpreter
    case = vertex_case()
    out = run_vertex_case(case, "cuda")
    brute = out.pop(len(case["faces"]))
    for leaf, hits in out.items():
        check_vertex_hits(case, hits, f"compiled trace_flat_triton, leaves of {leaf}", ref=brute)


def _compiled_tracer():
    """course.kernels.triton_tracer, or a skip where this process interprets Triton."""
    from course.kernels import triton_tracer as tt

    if tt.interpreting():
        pytest.skip("TRITON_INTERPRET=1 is set in this process: nothing is compiled")
    return tt


@needs_triton
@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
def test_compiled_kernels_follow_the_contract():
    _compiled_tracer()  # skips under the interpreter
    case = make_case(n_tris=2000, n_rays=3000, seed=7)
    out = run_kernels(case, render_cases(48), "cuda")
    check_all(case, render_cases(48), out, "compiled")
    for info in out["info"].values():
        assert isinstance(info.n_regs, int) and info.n_regs > 0, f"{info.name}: {info.n_regs}"
        assert isinstance(info.n_spills, int) and info.n_spills >= 0
        assert isinstance(info.local_bytes, int) and info.local_bytes >= 4 * info.n_spills
        if info.name in ("closest_hit", "any_hit"):  # the default walk: the local stack
            assert info.local_bytes >= 4 * 64, (
                f"{info.name}: {info.local_bytes} B of local memory, less than its stack"
            )
        occ = info.occupancy()
        print(
            f"{info.name}: {info.n_regs} registers, {info.n_spills} spills, "
            f"{info.local_bytes} B local, "
            f"occupancy {occ.occupancy:.0%} ({occ.limiter})"
        )


@needs_triton
@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
def test_compiled_bunny_matches_torch_traversal():
    from course.core.camera import primary_rays
    from course.given.lab3 import whitted_camera, whitted_scene
    from course.kernels.flat_bvh import flat_bvh_for, trace_flat_torch

    tt = _compiled_tracer()
    scene = whitted_scene("bunny_mirror", device="cpu")
    bvh = flat_bvh_for(scene)
    rays = primary_rays(whitted_camera("bunny_mirror", 96, 96), "cpu")
    want = trace_flat_torch(bvh, rays.origins, rays.directions)
    got = tt.trace_flat_triton(bvh.to("cuda"), rays.origins.cuda(), rays.directions.cuda())
    same = (got.triangle.cpu() == want.triangle).float().mean().item()
    assert same >= 0.999, f"only {same:.2%} of the bunny's rays agree with the torch walk"


@needs_triton
@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
def test_compiled_local_stack_allocates_only_the_outputs():
    from course.kernels.flat_bvh import build_flat_bvh

    tt = _compiled_tracer()
    case = make_case(n_tris=2000, n_rays=3000, seed=7)
    bvh = build_flat_bvh(case["vertices"].cuda(), case["faces"].cuda())
    o, d = case["origins"].cuda(), case["directions"].cuda()
    peaks = {}
    for stack in ("global", "local"):
        tt.trace_flat_triton(bvh, o, d, stack=stack, stack_regs=0)  # compile outside
        torch.cuda.synchronize()
        base = torch.cuda.memory_allocated()
        torch.cuda.reset_peak_memory_stats()
        tt.trace_flat_triton(bvh, o, d, stack=stack, stack_regs=0)
        peaks[stack] = torch.cuda.max_memory_allocated() - base
    outputs = len(o) * (4 + 8 + 4 + 4)  # t, triangle (int64), u, v
    # The allocator rounds every block up to 512 bytes.
    assert peaks["local"] <= outputs + 4 * 512, (
        f"stack='local' allocated {peaks['local']} bytes for {len(o)} rays; the outputs "
        f"need {outputs}: a stack buffer ({peaks['global'] - peaks['local']} more bytes "
        "with stack='global') is allocated that the kernel never reads"
    )


@needs_triton
def test_bad_arguments_raise_clear_errors():
    from course.kernels import triton_tracer as tt
    from course.kernels.flat_bvh import build_flat_bvh

    case = make_case(n_tris=20, n_rays=64, seed=1)
    bvh = build_flat_bvh(case["vertices"], case["faces"])
    o, d = case["origins"], case["directions"]
    for kwargs, word in [
        ({"origins": o[:, :2]}, "origins"),
        ({"directions": d[:2]}, "directions"),
        ({"block": 48}, "block"),
        ({"num_warps": 3}, "num_warps"),
        ({"block": 32, "num_warps": 2}, "block"),
        ({"bvh": "x"}, "bvh"),
        ({"stack_regs": 2}, "stack_regs"),
        ({"tris_per_step": 3}, "tris_per"),
        ({"loop": "do"}, "loop"),
        ({"stack": "shared"}, "stack"),
        ({"stack": "local", "stack_regs": 4}, "stack_regs"),
        ({"refill": -1}, "refill"),
        ({"refill": 33}, "refill"),
        ({"refill": 8, "loop": "if"}, "refill"),
        ({"refill": 0, "programs": 4}, "programs"),
        ({"refill": 8, "programs": 0}, "programs"),
        ({"t_min": torch.zeros(7)}, "t_min"),
    ]:
        args = {"bvh": bvh, "origins": o, "directions": d, **kwargs}
        with pytest.raises((ValueError, TypeError), match=word):
            tt.trace_flat_triton(
                args.pop("bvh"), args.pop("origins"), args.pop("directions"), **args
            )
    if not tt.interpreting():
        with pytest.raises(ValueError, match="CUDA"):
            tt.trace_flat_triton(bvh, o, d)  # CPU tensors, compiled kernels
    with pytest.raises(ValueError, match="max_depth"):
        tt.render_whitted_triton(None, o, d, max_depth=-1)


if __name__ == "__main__":  # the interpreter subprocess: python THIS INPUTS OUTPUTS
    data = torch.load(sys.argv[1], weights_only=False)
    if "vertex_case" in data:
        torch.save(run_vertex_case(data["vertex_case"], "cpu"), sys.argv[2])
    else:
        torch.save(run_kernels(data["case"], data["renders"], "cpu"), sys.argv[2])
