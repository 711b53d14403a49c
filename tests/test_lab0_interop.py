"""Grader for Lab 0: interop (packed framebuffers, zero-copy sharing, staging, frame loop).

References are computed here, never stored: byte reinterpretation for packing, float64
``course.core.image.srgb_encode`` for the 8-bit encoding and an analytic point-in-triangle test
for the rasterised frames. Every device is checked against the same CPU reference, so a
passing run also means CPU and CUDA agree. Zero-copy properties can only be observed next
to the code under test, so those tests run a ``probe_*`` function there and check what it
reports.
"""

from __future__ import annotations

import math
import time

import numpy as np
import pytest
import torch

from course.core.image import srgb_decode, srgb_encode
from course.grading.testing import (
    assert_close,
    assert_equal,
    check_tensor,
    expect_error,
    first_line,
    generator,
    poisoned,
    replaced,
)

LAB_MODULE = "lab0_interop"
TASKS = {1: "Packed framebuffers", 2: "Zero-copy sharing", 3: "The PBO analogue", 4: "Frame loop"}

BACKGROUND = (16, 16, 24, 255)  # the documented clear colour of render_rotating_triangle
POISON = int(poisoned((1,), torch.int32)[0])


# ----------------------------------------------------------------------- shared checks


def ref_pack(rgba: torch.Tensor) -> torch.Tensor:
    """RGBA bytes read as one little-endian 32-bit word per pixel, whatever the host."""
    data = np.ascontiguousarray(rgba.cpu().numpy())
    return torch.from_numpy(data.view("<i4")[..., 0].astype(np.int32))


def ref_unpack(packed: torch.Tensor) -> torch.Tensor:
    data = packed.cpu().numpy().astype("<i4")
    return torch.from_numpy(data.view(np.uint8).reshape(*packed.shape, 4).copy())


def check_reported_error(report, name: str, case: str, fn_name: str):
    """Check an error a probe caught: ``report`` is (kind, first line) or None."""
    assert report is not None, (
        f"{fn_name} accepted {case} without complaint: it must raise ValueError naming "
        f"{name!r} (a view of such a buffer would not be what a display expects)"
    )
    kind, message = report
    assert kind in ("ValueError", "TypeError"), (
        f"{fn_name} with {case} raised {kind}: expected ValueError naming {name!r}"
    )
    assert name in message, (
        f"{fn_name} with {case} raised {kind}({message!r}): the message should name "
        f"the argument {name!r} and say what was expected"
    )


def check_srgb_codes(got: torch.Tensor, x: torch.Tensor, name: str, near: float = 5e-4):
    """Compare 8-bit codes with floor(255 * srgb_encode(x) + 0.5) evaluated in float64.

    Inputs whose float64 value of 255 * srgb + 0.5 lies within ``near`` of an integer sit
    on a decision boundary and are not judged (float32 arithmetic may land either side).
    """
    check_tensor(got, name, shape=tuple(x.shape), dtype=torch.uint8, device=x.device.type)
    value = srgb_encode(x.detach().cpu().double()) * 255 + 0.5
    expected = torch.floor(value)
    judged = (value - torch.round(value)).abs() >= near
    bad = (got.cpu().double() != expected) & judged
    if bad.any():
        i = tuple(int(v) for v in bad.nonzero()[0])
        raise AssertionError(
            f"{name}: {int(bad.sum())} of {bad.numel()} codes are wrong; first at {i}: input "
            f"{x[i].item()!r} ({x.dtype}) has 255*srgb = {value[i].item() - 0.5:.6f}, so the code "
            f"is floor(255*srgb + 0.5) = {int(expected[i])}, got {int(got[i])}. Clamp to [0, 1] "
            f"(NaN -> 0), encode in float32 or wider, then round half up."
        )


def reference_triangle(frame_index: int, height: int, width: int, period: int):
    """Analytic barycentrics (H, W, 3) float64 of every pixel centre, and each centre's
    distance to the nearest edge line."""
    theta = 2 * math.pi * (frame_index % period) / period
    r = 0.4 * min(width, height)
    angles = theta + 2 * math.pi * torch.arange(3, dtype=torch.float64) / 3
    vx = width / 2 + r * torch.cos(angles)
    vy = height / 2 - r * torch.sin(angles)
    px = torch.arange(width, dtype=torch.float64).view(1, -1) + 0.5
    py = torch.arange(height, dtype=torch.float64).view(-1, 1) + 0.5
    weights, distances = [], []
    for a, b in ((1, 2), (2, 0), (0, 1)):  # edge opposite vertex 0, 1, 2
        e = (vx[b] - vx[a]) * (py - vy[a]) - (vy[b] - vy[a]) * (px - vx[a])
        weights.append(e)
        distances.append(e.abs() / torch.hypot(vx[b] - vx[a], vy[b] - vy[a]))
    w = torch.stack(weights, dim=-1)
    return w / w.sum(dim=-1, keepdim=True), torch.stack(distances, dim=-1).amin(dim=-1)


def check_triangle_frame(frame: torch.Tensor, frame_index: int, name: str, period: int = 120):
    """Every pixel written; coverage, colour and background as documented."""
    height, width = frame.shape
    frame = frame.cpu()
    unwritten = frame == POISON
    if unwritten.any():
        y, x = (int(v) for v in unwritten.nonzero()[0])
        raise AssertionError(
            f"{name}: {int(unwritten.sum())} of {frame.numel()} pixels were "
            f"never written (first at y={y}, x={x}); clear the background too"
        )
    bary, distance = reference_triangle(frame_index, height, width, period)
    judged = distance >= 1e-4  # pixel centres on an edge may go either way
    inside = (bary >= 0).all(dim=-1)
    rgba = ref_unpack(frame).long()
    covered = (rgba != torch.tensor(BACKGROUND)).any(dim=-1)
    wrong = (covered != inside) & judged
    if wrong.any():
        y, x = (int(v) for v in wrong.nonzero()[0])
        want = "inside" if inside[y, x] else "outside"
        raise AssertionError(
            f"{name} (frame {frame_index}, period {period}): {int(wrong.sum())} pixels have "
            f"the wrong coverage; first at y={y}, x={x}: its centre ({x + 0.5}, {y + 0.5}) "
            f"lies {want} the triangle (barycentrics {bary[y, x].tolist()}), but the pixel is "
            f"{'covered' if covered[y, x] else 'background'}. Sample pixel centres (+0.5) and "
            f"check the vertex formula (y grows downwards, angle grows counter-clockwise)."
        )
    background = torch.tensor(BACKGROUND).expand(height, width, 4)
    outside = ~inside & judged
    assert_equal(
        rgba[outside],
        background[outside],
        name=f"{name} background pixels (RGBA)",
        where="background pixel",
    )
    # Colours are exact, except where 255*b + 0.5 lies within float32 rounding of an integer
    # (1e-3 of a code is about the 1e-4 pixel the coverage contract leaves free).
    value = bary * 255 + 0.5
    expected = torch.cat([torch.floor(value), torch.full_like(bary[..., :1], 255)], dim=-1)
    decided = torch.cat(
        [(value - torch.round(value)).abs() >= 1e-3, torch.ones_like(inside[..., None])], dim=-1
    )
    assert_close(
        rgba,
        expected,
        mask=(inside & judged)[..., None] & decided,
        name=f"{name} (frame {frame_index}, period {period}) triangle colours (RGBA: "
        "floor(255*b + 0.5) exactly, rounding half up, alpha 255)",
        where="covered pixel (y, x, channel)",
    )


# ---------------------------------------------------------------- task 1: packing


KNOWN_WORDS = [
    ((0x12, 0x34, 0x56, 0x78), 0x78563412),
    ((255, 0, 0, 255), 0xFF0000FF),
    ((0, 255, 0, 255), 0xFF00FF00),
    ((0, 0, 255, 255), 0xFFFF0000),
    ((0, 0, 0, 128), 0x80000000),
    ((255, 255, 255, 255), 0xFFFFFFFF),
    ((1, 0, 0, 0), 0x00000001),
    ((0, 0, 0, 127), 0x7F000000),
]


def _hex(word: int) -> str:
    return f"0x{word & 0xFFFFFFFF:08X}"


@pytest.mark.task(1)
@pytest.mark.points(0.5)
def test_pack_rgba8_known_words(impl, device):
    rgba = torch.tensor([[c for c, _ in KNOWN_WORDS]], dtype=torch.uint8, device=device)
    packed = check_tensor(
        impl.pack_rgba8(rgba),
        "pack_rgba8(rgba)",
        shape=(1, len(KNOWN_WORDS)),
        dtype=torch.int32,
        device=device,
    )
    for j, (channels, word) in enumerate(KNOWN_WORDS):
        signed = word - 2**32 if word >= 2**31 else word
        got = int(packed[0, j])
        assert got == signed, (
            f"pack_rgba8: RGBA ({', '.join(f'0x{c:02X}' for c in channels)}) should pack to "
            f"{_hex(word)} "
            f"(int32 {signed}), got {_hex(got)} (int32 {got}). R goes in bits 0-7, G 8-15, "
            f"B 16-23, A 24-31; a word with A >= 128 is a negative int32 (two's complement)."
        )
    back = check_tensor(
        impl.unpack_rgba8(packed),
        "unpack_rgba8(packed)",
        shape=(1, len(KNOWN_WORDS), 4),
        dtype=torch.uint8,
        device=device,
    )
    assert_equal(back, rgba, name="unpack_rgba8 of the known words", where="(row, pixel, channel)")


@pytest.mark.task(1)
@pytest.mark.points(0.75)
def test_pack_rgba8_unpack_rgba8_roundtrip(impl, device):
    gen = generator(0)
    rgba = torch.randint(0, 256, (13, 17, 4), generator=gen, dtype=torch.uint8)
    rgba[::2, :, 3] = torch.randint(128, 256, (7, 17), generator=gen, dtype=torch.uint8)
    packed = check_tensor(
        impl.pack_rgba8(rgba.to(device)),
        "pack_rgba8(rgba)",
        shape=(13, 17),
        dtype=torch.int32,
        device=device,
    )
    assert_equal(packed, ref_pack(rgba), name="pack_rgba8 of random bytes", where="pixel")
    back = check_tensor(
        impl.unpack_rgba8(packed),
        "unpack_rgba8(pack_rgba8(rgba))",
        shape=(13, 17, 4),
        dtype=torch.uint8,
        device=device,
    )
    assert_equal(back, rgba, name="unpack_rgba8(pack_rgba8(rgba))", where="(y, x, channel)")

    # Every bit pattern must survive, the sign bit included.
    words = torch.randint(-(2**31), 2**31, (11, 9), generator=gen, dtype=torch.int64)
    words[0, :4] = torch.tensor([-(2**31), -1, 2**31 - 1, 0])
    words = words.to(torch.int32)
    unpacked = check_tensor(
        impl.unpack_rgba8(words.to(device)),
        "unpack_rgba8(words)",
        shape=(11, 9, 4),
        dtype=torch.uint8,
        device=device,
    )
    assert_equal(
        unpacked,
        ref_unpack(words),
        name="unpack_rgba8 of random words (incl. negative)",
        where="(y, x, channel)",
    )
    assert_equal(
        impl.pack_rgba8(unpacked), words, name="pack_rgba8(unpack_rgba8(words))", where="pixel"
    )


def srgb_boundary_inputs(dtype) -> tuple[torch.Tensor, torch.Tensor]:
    """Linear values just below and above each code's decision boundary, and each level's
    centre; with the codes they must map to (judged against float64 again later)."""
    target = (torch.arange(1, 256, dtype=torch.float64) - 0.5) / 255  # srgb where code k starts
    lo, hi = torch.zeros_like(target), torch.ones_like(target)
    for _ in range(64):  # bisection: the smallest linear value that encodes to >= target
        mid = (lo + hi) / 2
        above = srgb_encode(mid) >= target
        lo, hi = torch.where(above, lo, mid), torch.where(above, mid, hi)
    levels = torch.arange(256, dtype=torch.float64)
    x = torch.cat([hi * (1 - 2e-5), hi * (1 + 2e-5), srgb_decode(levels / 255)])
    codes = torch.cat([levels[:-1], levels[1:], levels])
    return x.to(dtype), codes


@pytest.mark.task(1)
@pytest.mark.points(0.75)
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_linear_to_srgb8_every_level_boundary(impl, device, dtype):
    x, codes = srgb_boundary_inputs(dtype)
    # the test's own premise: the float64 reference puts each input on the intended side
    assert_equal(
        torch.floor(srgb_encode(x.double()) * 255 + 0.5),
        codes,
        name="reference codes of the boundary inputs",
    )
    img = torch.cat([x, x[:2]]).view(16, 16, 3)  # 766 values padded to 768
    got = impl.linear_to_srgb8(img.to(device))
    check_srgb_codes(
        got,
        img.to(device),
        "linear_to_srgb8 at the 255 code boundaries and 256 level centres",
        near=1e-6,
    )


@pytest.mark.task(1)
@pytest.mark.points(0.25)
@pytest.mark.parametrize("dtype", [torch.float16, torch.bfloat16])
def test_linear_to_srgb8_every_half_precision_value(impl, device, dtype):
    one = torch.tensor(1.0, dtype=dtype).view(torch.int16).item()
    x = torch.arange(0, one + 1, dtype=torch.int16).view(dtype)  # every value in [0, 1]
    x = torch.cat([x, torch.zeros(-len(x) % 3, dtype=dtype)]).view(1, -1, 3)
    got = impl.linear_to_srgb8(x.to(device))
    check_srgb_codes(got, x.to(device), f"linear_to_srgb8 of every {dtype} value in [0, 1]")


@pytest.mark.task(1)
@pytest.mark.points(0.5)
@pytest.mark.parametrize("dtype", [torch.float16, torch.bfloat16, torch.float32, torch.float64])
def test_linear_to_srgb8_extremes(impl, device, dtype):
    cases = [
        (math.nan, 0),
        (math.inf, 255),
        (-math.inf, 0),
        (-1.0, 0),
        (-0.0, 0),
        (2.0, 255),
        (1e4, 255),
        (1.0, 255),
        (0.0, 0),
        (-1e-30, 0),
        (1e-30, 0),
        (0.5, 188),
    ]
    x = torch.tensor([[v for v, _ in cases]], dtype=torch.float64).to(dtype).view(1, 4, 3)
    got = check_tensor(
        impl.linear_to_srgb8(x.to(device)),
        "linear_to_srgb8(img)",
        shape=(1, 4, 3),
        dtype=torch.uint8,
        device=device,
    )
    for j, (v, code) in enumerate(cases):
        g = int(got.view(-1)[j])
        assert g == code, (
            f"linear_to_srgb8: input {v!r} ({dtype}) should give code {code}, got {g}. NaN and "
            f"values <= 0 give 0, values >= 1 and +inf give 255; 0.5 is 255*0.7354 + 0.5 -> 188."
        )


def nonzero(shape, dtype=torch.float32):
    """A bad input that is not all zeros: a submission zeroing its inputs in place shows."""
    return (torch.arange(math.prod(shape)) % 7 + 1).to(dtype).reshape(shape)


@pytest.mark.task(1)
@pytest.mark.points(0.25)
def test_pack_rgba8_unpack_rgba8_linear_to_srgb8_bad_input(impl):
    expect_error("rgba", impl.pack_rgba8, nonzero((4, 4, 4), torch.int32))
    expect_error("rgba", impl.pack_rgba8, nonzero((4, 4, 3), torch.uint8))
    expect_error("rgba", impl.pack_rgba8, nonzero((16, 4), torch.uint8))
    expect_error("rgba", impl.pack_rgba8, nonzero((4, 4, 4), torch.uint8).numpy())
    expect_error("packed", impl.unpack_rgba8, nonzero((4, 4), torch.int64))
    expect_error("packed", impl.unpack_rgba8, nonzero((4, 4, 1), torch.int32))
    expect_error("img", impl.linear_to_srgb8, nonzero((4, 4, 3), torch.uint8))
    expect_error("img", impl.linear_to_srgb8, nonzero((4, 4, 4)))
    expect_error("img", impl.linear_to_srgb8, nonzero((12, 3)))


# ---------------------------------------------------------------- task 2: zero-copy


def probe_framebuffer_to_numpy(lab, height, width):
    fb = torch.arange(height * width, dtype=torch.int32).view(height, width)
    arr = lab.framebuffer_to_numpy(fb)
    if not isinstance(arr, np.ndarray):
        return {"type": type(arr).__name__}
    report = {
        "type": "ndarray",
        "dtype": str(arr.dtype),
        "shape": arr.shape,
        "addresses": (arr.__array_interface__["data"][0], fb.data_ptr()),
    }
    if arr.shape == (height, width) and arr.flags.writeable:
        arr[1, 2] = 12345
        fb[0, 1] = -77
        report["tensor_sees_numpy_write"] = int(fb[1, 2])  # the test wants 12345
        report["numpy_sees_tensor_write"] = int(arr[0, 1])  # and -77
    return report


def probe_numpy_to_framebuffer(lab, height, width):
    arr = np.arange(height * width, dtype=np.int32).reshape(height, width)
    fb = lab.numpy_to_framebuffer(arr)
    if not isinstance(fb, torch.Tensor):
        return {"type": type(fb).__name__}
    report = {
        "type": "Tensor",
        "dtype": str(fb.dtype),
        "shape": tuple(fb.shape),
        "device": fb.device.type,
        "addresses": (arr.__array_interface__["data"][0], fb.data_ptr()),
    }
    if tuple(fb.shape) == (height, width):
        fb[1, 2] = 12345
        arr[0, 1] = -77
        report["numpy_sees_tensor_write"] = int(arr[1, 2])  # the test wants 12345
        report["tensor_sees_numpy_write"] = int(fb[0, 1])  # and -77
    return report


def probe_share_dlpack(lab, height, width, device):
    fb = torch.arange(height * width, dtype=torch.int32, device=device).view(height, width)
    shared = lab.share_dlpack(fb)
    if not isinstance(shared, torch.Tensor):
        return {"type": type(shared).__name__}
    report = {
        "type": "Tensor",
        "ids": (id(shared), id(fb)),
        "dtype": str(shared.dtype),
        "shape": tuple(shared.shape),
        "device": shared.device.type,
        "addresses": (shared.data_ptr(), fb.data_ptr()),
    }
    if tuple(shared.shape) == (height, width):
        shared[1, 2] = 12345
        report["fb_sees_write"] = int(fb[1, 2])  # the test wants 12345
    return report


def probe_cuda_array_interface(lab, height, width):
    import types

    fb = torch.arange(height * width, dtype=torch.int32, device="cuda").view(height, width)
    info = lab.cuda_array_interface(fb)
    if not isinstance(info, dict):
        return {"type": type(info).__name__}
    data = info.get("data")
    report = {
        "type": "dict",
        "shape": info.get("shape"),
        "typestr": info.get("typestr"),
        "strides": info.get("strides"),
        "version": info.get("version"),
        "pointers": (
            data[0]
            if isinstance(data, tuple) and len(data) == 2 and isinstance(data[0], int)
            else None,
            fb.data_ptr(),
        ),
        "read_only": data[1] if isinstance(data, tuple) and len(data) == 2 else None,
    }
    report["stream"] = info.get("stream")
    side = torch.cuda.Stream()
    with torch.cuda.stream(side):
        on_side = lab.cuda_array_interface(fb)
    report["side_stream"] = on_side.get("stream") if isinstance(on_side, dict) else None
    report["side_stream_handle"] = side.cuda_stream
    if report["pointers"][0] == report["pointers"][1]:  # a consumer builds a view from it
        view = torch.as_tensor(types.SimpleNamespace(__cuda_array_interface__=info), device="cuda")
        view[1, 2] = 12345
        torch.cuda.synchronize()
        report["fb_sees_consumer_write"] = int(fb[1, 2])  # the test wants 12345
    return report


def _caught(fn, *args):
    try:
        fn(*args)
    except (ValueError, TypeError) as exc:
        return type(exc).__name__, first_line(exc)
    return None


def probe_bad_framebuffers(lab, fn_name, device):
    fn = getattr(lab, fn_name)
    if fn_name == "numpy_to_framebuffer":
        base = np.arange(1, 25, dtype=np.int32).reshape(6, 4)  # not zeros: see nonzero
        cases = {
            "a transposed (non-contiguous) array": base.T,
            "an int64 array": base.astype(np.int64),
            "a 3-D array": base.reshape(6, 4, 1),
        }
    else:
        base = torch.arange(1, 25, dtype=torch.int32, device=device).view(6, 4)
        cases = {
            "a transposed (non-contiguous) framebuffer": base.t(),
            "an int64 framebuffer": base.long(),
            "a 3-D framebuffer": base.view(6, 4, 1),
        }
    return {case: _caught(fn, value) for case, value in cases.items()}


# What each probe writes through one side of a view, read back through the other.
WRITTEN = {
    "tensor_sees_numpy_write": {"framebuffer_to_numpy": 12345, "numpy_to_framebuffer": -77},
    "numpy_sees_tensor_write": {"framebuffer_to_numpy": -77, "numpy_to_framebuffer": 12345},
    "fb_sees_write": {"share_dlpack": 12345},
}


def _check_view_report(report, fn_name, expect_dtype, shape):
    assert report["type"] in ("ndarray", "Tensor"), f"{fn_name} returned a {report['type']}"
    assert report["dtype"] == expect_dtype and tuple(report["shape"]) == shape, (
        f"{fn_name}: expected dtype {expect_dtype} and shape {shape}, got {report['dtype']} "
        f"and {tuple(report['shape'])}"
    )
    mine, theirs = report["addresses"]
    assert type(mine) is int and mine == theirs, (
        f"{fn_name} returned a copy: its data lives at another address. A view shares the "
        f"memory (tensor.numpy() / torch.from_numpy); no bytes should move."
    )
    for key, value in report.items():
        if key.endswith("_write"):
            assert value == WRITTEN[key][fn_name], (
                f"{fn_name}: {key.replace('_', ' ')} failed: the two do not share memory"
            )


@pytest.mark.task(2)
@pytest.mark.points(0.75)
def test_framebuffer_to_numpy_is_a_view(impl, device):
    if device == "cpu":
        report = impl.probe(probe_framebuffer_to_numpy, 5, 7)
        _check_view_report(report, "framebuffer_to_numpy", "int32", (5, 7))
    else:  # numpy cannot address GPU memory: no silent download
        expect_error(
            "fb", impl.framebuffer_to_numpy, torch.zeros(5, 7, dtype=torch.int32, device=device)
        )


@pytest.mark.task(2)
@pytest.mark.points(0.5)
def test_numpy_to_framebuffer_is_a_view(impl):
    report = impl.probe(probe_numpy_to_framebuffer, 5, 7)
    _check_view_report(report, "numpy_to_framebuffer", "torch.int32", (5, 7))
    assert report["device"] == "cpu", "numpy_to_framebuffer must return a CPU tensor (a view)"


@pytest.mark.task(2)
@pytest.mark.points(0.75)
def test_share_dlpack_same_memory(impl, device):
    report = impl.probe(probe_share_dlpack, 5, 7, device)
    assert report["type"] == "Tensor", f"share_dlpack returned a {report['type']}, not a tensor"
    assert report["ids"][0] != report["ids"][1], (
        "share_dlpack returned fb itself: import the DLPack export with torch.from_dlpack to "
        "get the consumer's tensor"
    )
    assert report["device"] == device, (
        f"share_dlpack: the shared tensor is on {report['device']}, fb on {device}"
    )
    _check_view_report(report, "share_dlpack", "torch.int32", (5, 7))


@pytest.mark.task(2)
@pytest.mark.points(0.5)
def test_cuda_array_interface(impl, device):
    if device == "cpu":
        expect_error("fb", impl.cuda_array_interface, nonzero((5, 7), torch.int32))
        return
    report = impl.probe(probe_cuda_array_interface, 5, 7)
    assert report["type"] == "dict", f"cuda_array_interface returned a {report['type']}"
    expected = {"shape": (5, 7), "typestr": "<i4", "strides": None, "version": 3}
    for key, want in expected.items():
        got = report[key]
        got = tuple(got) if isinstance(got, list) else got
        assert got == want, f"cuda_array_interface: {key!r} should be {want!r}, got {got!r}"
    assert report["pointers"][0] == report["pointers"][1], (
        "cuda_array_interface: 'data' must be (fb.data_ptr(), False): the device pointer and "
        "a read-only flag"
    )
    assert report["read_only"] is False, "cuda_array_interface: the framebuffer is writable"
    assert report["stream"] == 1, (
        f"cuda_array_interface on the default stream: 'stream' should be 1 (the legacy default "
        f"stream; 0 is not allowed in version 3), got {report['stream']!r}"
    )
    assert report["side_stream"] == report["side_stream_handle"], (
        f"cuda_array_interface under torch.cuda.stream(s): 'stream' should be the current "
        f"stream's handle s.cuda_stream = {report['side_stream_handle']}, got "
        f"{report['side_stream']!r}: a consumer synchronises with the producer's stream"
    )
    assert report.get("fb_sees_consumer_write") == 12345, (
        "cuda_array_interface: a consumer's write through the described memory did not reach fb"
    )


@pytest.mark.task(2)
@pytest.mark.points(0.5)
@pytest.mark.parametrize(
    "fn_name",
    ["framebuffer_to_numpy", "numpy_to_framebuffer", "share_dlpack", "cuda_array_interface"],
)
def test_framebuffer_to_numpy_numpy_to_framebuffer_share_dlpack_cuda_array_interface_bad_input(
    impl, device, fn_name
):
    name = "arr" if fn_name == "numpy_to_framebuffer" else "fb"
    for case, report in impl.probe(probe_bad_framebuffers, fn_name, device).items():
        check_reported_error(report, name, case, fn_name)


# ---------------------------------------------------------------- task 3: staging


def make_frame(frame_index: int, shape, device) -> torch.Tensor:
    """A frame whose every word depends on its index (negative words included)."""
    gen = generator(1000 + frame_index)
    return (
        torch.randint(-(2**31), 2**31, tuple(shape), generator=gen, dtype=torch.int64)
        .to(torch.int32)
        .to(device)
    )


def render_test_frame(frame_index, out):
    out.copy_(make_frame(frame_index, out.shape, out.device))


def display_checksum(frame_index, frame):
    return (
        frame_index,
        int(frame.to(torch.int64).sum()),
        tuple(frame.shape),
        frame.device.type,
        str(frame.dtype),
    )


def display_address(frame_index, frame):
    return frame.data_ptr()


@pytest.mark.task(3)
@pytest.mark.points(1.0)
@pytest.mark.parametrize("num_buffers", [2, 3])
def test_FrameDownloader_fifo_order_and_content(impl, device, num_buffers):
    shape = (9, 14)
    downloader = impl.FrameDownloader(shape, device, num_buffers=num_buffers)
    submitted = received = 0
    # fill the ring, then alternate receive/submit, drain half way, refill, drain at the end
    plan = (
        ["s"] * num_buffers
        + ["r", "s"] * 5
        + ["r"] * num_buffers
        + ["s"] * num_buffers
        + ["r"] * num_buffers
    )
    for op in plan:
        if op == "s":
            downloader.submit(make_frame(submitted, shape, device))
            submitted += 1
            continue
        got = check_tensor(
            downloader.receive(),
            f"receive() #{received}",
            shape=shape,
            dtype=torch.int32,
            device="cpu",
        )
        assert_equal(
            got,
            make_frame(received, shape, "cpu"),
            where="pixel",
            name=f"receive() #{received} with {num_buffers} buffers (must return "
            f"frame {received}: the oldest submitted, first in first out)",
        )
        received += 1


def probe_downloader_buffers(lab, device, num_buffers, n_frames):
    shape = (8, 16)
    downloader = lab.FrameDownloader(shape, device, num_buffers=num_buffers)
    kept, report = [], {"pointers": [], "pinned": [], "device": [], "frames": []}
    for i in range(n_frames):
        frame = make_frame(i, shape, device)
        downloader.submit(frame)
        if i >= num_buffers - 1:
            host = downloader.receive()
            kept.append(host)  # alive, so a fresh allocation could not reuse its address
            report["pointers"].append(host.data_ptr())
            report["pinned"].append(host.is_pinned() if device == "cuda" else None)
            report["device"].append(host.device.type)
            report["frames"].append(host.detach().cpu().clone())  # the test compares
    return report


@pytest.mark.task(3)
@pytest.mark.points(0.5)
@pytest.mark.parametrize("num_buffers", [2, 3])
def test_FrameDownloader_reuses_pinned_staging_buffers(impl, device, num_buffers):
    report = impl.probe(probe_downloader_buffers, device, num_buffers, 10)
    assert all(d == "cpu" for d in report["device"]), (
        f"receive() must return a host (CPU) staging buffer, got devices {report['device']}"
    )
    wrong = [
        j
        for j, host in enumerate(report["frames"])
        if not (
            isinstance(host, torch.Tensor)
            and host.shape == (8, 16)
            and torch.equal(host, make_frame(j, (8, 16), "cpu"))
        )
    ]
    assert len(report["frames"]) == 10 - num_buffers + 1 and not wrong, (
        f"receive() returned the wrong content for frames {wrong}"
    )
    distinct = len(set(report["pointers"]))
    assert distinct <= num_buffers, (
        f"receive() returned {distinct} different host buffers over "
        f"{len(report['pointers'])} frames with num_buffers={num_buffers}: the staging "
        f"buffers must be allocated once in __init__ and reused (like a PBO), not per frame"
    )
    if device == "cuda":
        assert all(report["pinned"]), (
            "the staging buffers are not pinned: allocate them with pin_memory=True so the "
            "device-to-host copy can run asynchronously (non_blocking=True)"
        )


@pytest.mark.task(3)
@pytest.mark.points(0.5)
def test_FrameDownloader_refuses_overflow(impl, device):
    shape = (4, 6)
    downloader = impl.FrameDownloader(shape, device, num_buffers=2)
    with pytest.raises(RuntimeError):
        downloader.receive()  # nothing submitted yet
    downloader.submit(make_frame(0, shape, device))
    downloader.submit(make_frame(1, shape, device))
    try:
        downloader.submit(make_frame(2, shape, device))
    except RuntimeError:
        pass
    else:
        raise AssertionError(
            "FrameDownloader(num_buffers=2) accepted a third frame while two were in flight: "
            "it would overwrite a staging buffer whose frame was never received. Raise "
            "RuntimeError instead."
        )
    assert_equal(
        downloader.receive(),
        make_frame(0, shape, "cpu"),
        name="first frame after a refused submit",
        where="pixel",
    )
    downloader.submit(make_frame(2, shape, device))  # a buffer is free again
    assert_equal(
        downloader.receive(), make_frame(1, shape, "cpu"), name="second frame", where="pixel"
    )
    assert_equal(
        downloader.receive(), make_frame(2, shape, "cpu"), name="third frame", where="pixel"
    )
    with pytest.raises(RuntimeError):
        downloader.receive()

    # One staging buffer is a valid ring (num_buffers >= 1): one frame in flight at a time.
    single = impl.FrameDownloader(shape, device, num_buffers=1)
    for i in range(3):
        single.submit(make_frame(10 + i, shape, device))
        try:
            single.submit(make_frame(20 + i, shape, device))
        except RuntimeError:
            pass
        else:
            raise AssertionError(
                "FrameDownloader(num_buffers=1) accepted a second frame while one was in "
                "flight: it would overwrite the only staging buffer. Raise RuntimeError."
            )
        assert_equal(
            single.receive(),
            make_frame(10 + i, shape, "cpu"),
            where="pixel",
            name=f"FrameDownloader(num_buffers=1): frame {i} received after its submit",
        )


@pytest.mark.task(3)
@pytest.mark.points(0.25)
def test_FrameDownloader_bad_input(impl, device):
    expect_error("shape", impl.FrameDownloader, (0, 4), device)
    expect_error("shape", impl.FrameDownloader, (4, 4, 4), device)
    expect_error("num_buffers", impl.FrameDownloader, (4, 4), device, num_buffers=0)
    downloader = impl.FrameDownloader((4, 6), device)
    expect_error("frame", downloader.submit, torch.zeros(6, 4, dtype=torch.int32, device=device))
    expect_error("frame", downloader.submit, torch.zeros(4, 6, device=device))
    # A side of 1 is a positive int, so (1, 1) is valid; the default ring (num_buffers=2,
    # the signature's default) holds two frames in flight and refuses a third.
    tiny = impl.FrameDownloader((1, 1), device)
    tiny.submit(make_frame(0, (1, 1), device))
    tiny.submit(make_frame(1, (1, 1), device))
    try:
        tiny.submit(make_frame(2, (1, 1), device))
    except RuntimeError:
        pass
    else:
        raise AssertionError(
            "FrameDownloader((1, 1), device) accepted a third frame while two were in flight: "
            "its default num_buffers is 2, so the third submit should raise RuntimeError"
        )
    assert_equal(tiny.receive(), make_frame(0, (1, 1), "cpu"), name="FrameDownloader((1, 1))")


@pytest.mark.task(3)
@pytest.mark.points(0.25)
@pytest.mark.parametrize("pinned", [False, True])
def test_measure_copy_bandwidth(impl, device, pinned):
    gbps = impl.measure_copy_bandwidth(1 << 16, pinned, device, repeats=2)
    assert isinstance(gbps, float) and math.isfinite(gbps) and gbps > 0, (
        f"measure_copy_bandwidth should return a positive float (GB/s), got {gbps!r}"
    )
    # 64 KiB in 0.65 s .. 6.5 ns: far wider than any machine or load, yet a bandwidth in the
    # wrong units (bytes/s, seconds/byte, bytes x seconds) lands outside by many decades.
    assert 1e-4 <= gbps <= 1e4, (
        f"measure_copy_bandwidth(65536, pinned={pinned}, {device!r}) = {gbps!r} GB/s: outside "
        f"any plausible range [1e-4, 1e4] GB/s (64 KiB copied in 0.65 s .. 6.5 ns). The "
        f"bandwidth is nbytes / seconds per copy / 1e9."
    )
    one = impl.measure_copy_bandwidth(1, pinned, device, repeats=1)  # the smallest block
    assert isinstance(one, float) and math.isfinite(one) and one > 0, (
        f"measure_copy_bandwidth(1, pinned={pinned}, {device!r}, repeats=1) should return a "
        f"positive float (GB/s): nbytes may be any positive int, 1 included; got {one!r}"
    )
    expect_error("nbytes", impl.measure_copy_bandwidth, 0, pinned, device)
    expect_error(
        "repeats",
        impl.measure_copy_bandwidth,
        1,
        pinned,
        device,
        repeats=0,
        case="repeats=0 (nothing would be timed)",
    )
    expect_error(
        "repeats",
        impl.measure_copy_bandwidth,
        1,
        pinned,
        device,
        repeats=2.0,
        case="repeats=2.0 (a float, not an int)",
    )


@pytest.mark.task(3)
@pytest.mark.points(0.5)
@pytest.mark.parametrize("overlap", [True, False])
def test_run_frame_loop_displays_every_frame_in_order(impl, device, overlap):
    shape, n = (6, 10), 7
    expect_error(
        "n_frames",
        impl.run_frame_loop,
        render_test_frame,
        0,
        shape,
        device,
        overlap=overlap,
        case="n_frames=0 (documented: an int >= 1)",
    )
    wall = time.perf_counter()
    result = impl.run_frame_loop(
        render_test_frame, n, shape, device, overlap=overlap, display=display_checksum
    )
    wall = time.perf_counter() - wall
    assert isinstance(result, dict), f"run_frame_loop should return a dict, got {type(result)}"
    seconds = result.get("seconds")
    assert isinstance(seconds, float) and 0 < seconds <= wall, (
        f"run_frame_loop: 'seconds' should be the loop's wall time, in (0, {wall:.4g}] (the "
        f"whole call took {wall:.4g} s), got {seconds!r}"
    )
    assert result.get("frames") == n, (
        f"run_frame_loop: 'frames' should be {n}, got {result.get('frames')!r}"
    )
    fps = result.get("frames_per_second")
    assert isinstance(fps, float) and math.isfinite(fps) and fps > 0, (
        f"run_frame_loop: 'frames_per_second' should be a positive float, got {fps!r}"
    )
    assert math.isclose(fps, n / seconds, rel_tol=1e-6), (
        f"run_frame_loop: 'frames_per_second' should be frames / seconds = {n} / {seconds:.4g} "
        f"= {n / seconds:.4g}, got {fps!r}"
    )
    one = impl.run_frame_loop(
        render_test_frame, 1, shape, device, overlap=overlap, display=display_checksum
    )
    assert [row[0] for row in one.get("displayed", [])] == [0], (
        f"run_frame_loop(n_frames=1, overlap={overlap}) displayed frames "
        f"{[row[0] for row in one.get('displayed', [])]}: expected [0] (n_frames >= 1 is valid)"
    )
    shown = [
        tuple(tuple(v) if isinstance(v, list) else v for v in row)
        for row in result.get("displayed", [])
    ]
    expected = [display_checksum(i, make_frame(i, shape, "cpu")) for i in range(n)]
    assert [row[0] for row in shown] == list(range(n)), (
        f"run_frame_loop(overlap={overlap}) displayed frames {[row[0] for row in shown]}: "
        f"expected each of 0..{n - 1} once, in order"
    )
    for got, want in zip(shown, expected):
        assert got == want, (
            f"run_frame_loop(overlap={overlap}): frame {want[0]} was displayed with (index, "
            f"checksum, shape, device, dtype) {got}, expected {want}: the host frame shown is "
            f"not the frame rendered with that index"
        )
    # The frames shown are the two staging buffers, reused (like two PBOs), never more.
    result = impl.run_frame_loop(
        render_test_frame, 9, shape, device, overlap=overlap, display=display_address
    )
    buffers = len(set(result.get("displayed", [])))
    assert 1 <= buffers <= 2, (
        f"run_frame_loop(overlap={overlap}) showed frames in {buffers} different host buffers "
        f"over 9 frames: it downloads into two staging buffers (a FrameDownloader with "
        f"num_buffers=2) and displays those, reused every other frame"
    )


# ---------------------------------------------------------------- task 4: frame loop
# render_rotating_triangle packs its pixels with pack_rgba8 (task 1): it runs here with the
# given packing below in place of the lab's, so task 4 is graded on its own.


def given_pack_rgba8(rgba: torch.Tensor) -> torch.Tensor:
    """In place of the lab's ``pack_rgba8``: the little-endian word of each pixel."""
    return ref_pack(rgba).to(rgba.device)


def probe_render(lab, frame_index, out, **kwargs):
    """``render_rotating_triangle`` next to the lab, with the given packing; (result, out)."""
    with replaced(lab, {"pack_rgba8": given_pack_rgba8}):
        result = lab.render_rotating_triangle(frame_index, out, **kwargs)
    return result, out


def render(impl, frame_index, out, **kwargs):
    """The lab's render_rotating_triangle (task 1 given); ``out`` gets what it wrote."""
    result, written = impl.probe(probe_render, frame_index, out, **kwargs)
    out.copy_(written)
    return result


@pytest.mark.task(4)
@pytest.mark.points(0.75)
@pytest.mark.parametrize("frame_index", [0, 7, 38, 101])
def test_render_rotating_triangle_coverage(impl, device, frame_index):
    out = poisoned((40, 56), torch.int32, device)
    result = render(impl, frame_index, out)
    check_tensor(
        result, "render_rotating_triangle(...)", shape=(40, 56), dtype=torch.int32, device=device
    )
    assert_equal(
        result, out, name="the returned framebuffer vs out (it must return out)", where="pixel"
    )
    check_triangle_frame(out, frame_index, "render_rotating_triangle")


@pytest.mark.task(4)
@pytest.mark.points(0.25)
def test_render_rotating_triangle_period(impl, device):
    def frame(i, **kw):
        return render(impl, i, poisoned((24, 32), torch.int32, device), **kw)

    check_triangle_frame(
        frame(3, period=10), 3, "render_rotating_triangle(3, period=10)", period=10
    )
    assert_equal(
        frame(13, period=10),
        frame(3, period=10),
        where="pixel",
        name="frame 13 vs frame 3 with period=10 (the rotation repeats every period)",
    )
    assert_equal(
        frame(120), frame(0), where="pixel", name="frame 120 vs frame 0 with the default period 120"
    )
    assert not torch.equal(frame(1), frame(0)), "frames 0 and 1 are identical: no rotation"
    # period=1 is valid (an int >= 1): every frame is frame 0.
    check_triangle_frame(frame(5, period=1), 5, "render_rotating_triangle(5, period=1)", period=1)
    assert_equal(
        frame(5, period=1),
        frame(0),
        where="pixel",
        name="frame 5 with period=1 vs frame 0 (period 1: the triangle never turns)",
    )


def probe_render_in_place(lab, device):
    fb = torch.full((12, 20), -1, dtype=torch.int32, device=device)
    with replaced(lab, {"pack_rgba8": given_pack_rgba8}):
        result = lab.render_rotating_triangle(2, fb)
    return {
        "pointers": (
            result.data_ptr() if isinstance(result, torch.Tensor) else None,
            fb.data_ptr(),
        ),
        "frame": fb.cpu(),
    }


@pytest.mark.task(4)
@pytest.mark.points(0.25)
def test_render_rotating_triangle_writes_in_place(impl, device):
    report = impl.probe(probe_render_in_place, device)
    assert report["pointers"][0] == report["pointers"][1], (
        "render_rotating_triangle must return out itself, not a copy"
    )
    frame = report["frame"]
    unwritten = (frame == -1).nonzero()
    assert not len(unwritten), (
        f"render_rotating_triangle left {len(unwritten)} pixels of out "
        f"unwritten, the first at (row, col) {unwritten[0].tolist()}"
    )
    # Writing in place earns its point only with the right frame in place.
    check_triangle_frame(frame, 2, "render_rotating_triangle(2, out): the frame in out")


def probe_frame_loop(lab, device, width, height, steps, keep=None):
    """Step a FrameLoop ``steps`` times: every step's framebuffer address, and a copy of the
    frames whose index is in ``keep`` (all by default)."""
    kept, pointers, frames = [], [], {}
    with replaced(lab, {"pack_rgba8": given_pack_rgba8}):
        loop = lab.FrameLoop(width, height, device)
        for k in range(steps):
            fb = loop.step()
            kept.append(fb)  # alive, so a per-frame allocation could not reuse its address
            pointers.append(fb.data_ptr())
            if keep is None or k in keep:
                frames[k] = fb.detach().clone().cpu()
    return {"pointers": pointers, "frames": frames}


@pytest.mark.task(4)
@pytest.mark.points(0.5)
def test_FrameLoop_reuses_one_framebuffer(impl, device):
    report = impl.probe(probe_frame_loop, device, 30, 22, 4)
    assert len(set(report["pointers"])) == 1, (
        f"FrameLoop.step() returned {len(set(report['pointers']))} different buffers over 4 "
        f"frames: allocate the framebuffer once in __init__ and render into it every step "
        f"(a registered PBO is never reallocated)"
    )
    for k, frame in report["frames"].items():
        check_tensor(frame, f"FrameLoop.step() #{k}", shape=(22, 30), dtype=torch.int32)
        check_triangle_frame(frame, k, f"FrameLoop.step() #{k}")

    # The default period is 120, as in render_rotating_triangle: step #120 repeats step #0.
    frames = impl.probe(probe_frame_loop, device, 30, 22, 121, keep=(0, 119, 120))["frames"]
    check_triangle_frame(frames[119], 119, "FrameLoop.step() #119 (default period 120)")
    assert_equal(
        frames[120],
        frames[0],
        where="pixel",
        name="FrameLoop.step() #120 vs #0 (the "
        "default period is 120, as in render_rotating_triangle)",
    )

    # A framebuffer one pixel wide or one pixel high is valid (width, height >= 1).
    for width, height in ((1, 9), (9, 1)):
        report = impl.probe(probe_frame_loop, device, width, height, 2)
        for k, frame in report["frames"].items():
            where = f"FrameLoop({width}, {height}).step() #{k}"
            check_tensor(frame, where, shape=(height, width), dtype=torch.int32)
            check_triangle_frame(frame, k, where)


@pytest.mark.task(4)
@pytest.mark.points(0.25)
def test_render_rotating_triangle_FrameLoop_bad_input(impl, device):
    fb = torch.zeros(8, 8, dtype=torch.int32, device=device)
    expect_error("out", impl.render_rotating_triangle, 0, torch.zeros(8, 8, device=device))
    expect_error("out", impl.render_rotating_triangle, 0, fb.view(8, 8, 1))
    expect_error("period", impl.render_rotating_triangle, 0, fb, period=0)
    expect_error("frame_index", impl.render_rotating_triangle, 1.5, fb)
    expect_error("width", impl.FrameLoop, 0, 8, device)
    expect_error("height", impl.FrameLoop, 8, -1, device)
