"""Hidden grader for Lab 0, task 1: packed framebuffers at sizes and layouts the handout's
tests do not use (not in the student handout; shown on Gradescope after the due date).

The reference is the packing formula itself, evaluated in int64 and wrapped to int32 by
hand: independent of the byte-view reference of the visible grader and of the host's byte
order.
"""

from __future__ import annotations

import math

import pytest
import torch

from course.grading.testing import assert_equal, check_tensor, generator, replaced
from course.measure.bench import Timing

LAB_MODULE = "lab0_interop"
TASKS = {1: "Packed framebuffers", 3: "The PBO analogue"}
pytestmark = pytest.mark.visibility("after_due_date")

# One pixel, a single odd row, a single column, odd primes, and a 1080p frame.
SHAPES = [(1, 1), (1, 1023), (517, 1), (37, 53), (1080, 1920)]


def formula_pack(rgba: torch.Tensor) -> torch.Tensor:
    c = rgba.cpu().to(torch.int64)
    word = c[..., 0] + (c[..., 1] << 8) + (c[..., 2] << 16) + (c[..., 3] << 24)
    return (word - (word >= 2**31).to(torch.int64) * 2**32).to(torch.int32)


def random_rgba(shape, seed) -> torch.Tensor:
    rgba = torch.randint(0, 256, (*shape, 4), generator=generator(seed), dtype=torch.uint8)
    every_other = torch.arange(rgba[..., 3].numel()).reshape(shape) % 2 == 0
    rgba[..., 3] |= every_other.to(torch.uint8) << 7  # half the words negative as int32
    return rgba


@pytest.mark.task(1)
@pytest.mark.points(0.5)
@pytest.mark.parametrize("shape", SHAPES, ids=[f"{h}x{w}" for h, w in SHAPES])
def test_pack_rgba8_unpack_rgba8_odd_and_large_sizes(impl, device, shape):
    rgba = random_rgba(shape, seed=shape[0] * 7919 + shape[1])
    packed = check_tensor(
        impl.pack_rgba8(rgba.to(device)),
        f"pack_rgba8 of a {shape} image",
        shape=shape,
        dtype=torch.int32,
        device=device,
    )
    assert_equal(packed, formula_pack(rgba), name=f"pack_rgba8 of a {shape} image", where="pixel")
    back = check_tensor(
        impl.unpack_rgba8(packed),
        f"unpack_rgba8 of a {shape} framebuffer",
        shape=(*shape, 4),
        dtype=torch.uint8,
        device=device,
    )
    assert_equal(
        back, rgba, name=f"unpack_rgba8(pack_rgba8(rgba)) at {shape}", where="(y, x, channel)"
    )


def strided_views(device):
    """Views that are not one contiguous block: a crop, every other column, and a planar
    (4, H, W) image seen channel-last."""
    base = random_rgba((24, 34), seed=5).to(device)
    planar = base.permute(2, 0, 1).contiguous()
    return {
        "a crop": base[3:17, 5:26],
        "every other column": base[:, ::2],
        "a channel-last view of a planar image": planar.permute(1, 2, 0),
    }


def probe_pack_strided(lab, device):
    """Pack the strided views; runs next to the code under test because a view's layout
    does not survive the trip to the sandbox. Returns what it packed: the test compares."""
    results = {}
    for name, view in strided_views(device).items():
        try:
            results[name] = lab.pack_rgba8(view).cpu()
        except Exception as exc:  # noqa: BLE001  (reported by the test, with the view)
            results[name] = f"{type(exc).__name__}: {exc}"
    return results


@pytest.mark.task(1)
@pytest.mark.points(0.5)
def test_pack_rgba8_strided_views(impl, device):
    results = impl.probe(probe_pack_strided, device)
    for name, view in strided_views("cpu").items():  # the grader's own inputs
        result = results.get(name) if isinstance(results, dict) else None
        if isinstance(result, str):
            pytest.fail(
                f"pack_rgba8 of {name} (a valid (H, W, 4) uint8 tensor that is not "
                f"contiguous) raised {result}. Kernels must accept any strided input; "
                f"a byte view of the input needs .contiguous() first.",
                pytrace=False,
            )
        packed = check_tensor(
            result, f"pack_rgba8 of {name}", shape=view.shape[:2], dtype=torch.int32
        )
        assert_equal(packed, formula_pack(view), name=f"pack_rgba8 of {name}", where="pixel")


# ---------------------------------------------------------------- task 3, under a stub clock


def stub_clock(fn, *args, repeats=5, warmup=1, device=None, **kwargs):
    """``time_fn``'s stand-in: calls ``fn`` once and reports a fixed clock, a median of
    0.25 s per call and a best of 0.125 s, so the units and the statistic are seen exactly."""
    fn(*args, **kwargs)
    return Timing(
        median=0.25,
        min=0.125,
        max=0.5,
        mean=0.3,
        repeats=repeats,
        device=str(device),
        method="stub",
    )


def probe_bandwidth_under_a_stub_clock(lab, nbytes, pinned, device):
    with replaced(lab, {"time_fn": stub_clock}) as module:
        return module.measure_copy_bandwidth(nbytes, pinned, device, repeats=3)


@pytest.mark.task(3)
@pytest.mark.points(0.25)
@pytest.mark.parametrize("pinned", [False, True])
def test_measure_copy_bandwidth_under_a_stub_clock(impl, device, pinned):
    nbytes = 3 << 20
    got = impl.probe(probe_bandwidth_under_a_stub_clock, nbytes, pinned, device)
    want = nbytes / 0.25 / 1e9
    why = ""
    if isinstance(got, float) and math.isclose(got, nbytes / 0.25 / 2**30, rel_tol=1e-6):
        why = " That is GiB/s (2**30 bytes); the docstring asks for GB/s (1e9 bytes)."
    elif isinstance(got, float) and math.isclose(got, nbytes / 0.125 / 1e9, rel_tol=1e-6):
        why = " That is the best copy's bandwidth; the docstring asks for the median's."
    assert isinstance(got, float) and math.isclose(got, want, rel_tol=1e-9), (
        f"measure_copy_bandwidth({nbytes}, pinned={pinned}) with the given time_fn stubbed "
        f"to a median of 0.25 s per copy (best 0.125 s): expected nbytes / median / 1e9 = "
        f"{want!r} GB/s, got {got!r}.{why}"
    )
