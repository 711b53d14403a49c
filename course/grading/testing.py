"""Assertions for graders: failures say what, where and how far off.

Every helper raises ``AssertionError`` with a message written for a student:
the quantity's name, what was expected, what came back, the first offending
index and the size of the error.
"""

from __future__ import annotations

import contextlib
import math
import os
import re
import sys
import time
from pathlib import Path

import numpy as np
import torch

# Values that no correct kernel writes: an element still holding one was never written.
_POISON_INT = -0x5A5A5A5A


def poisoned(shape, dtype=torch.float32, device="cpu") -> torch.Tensor:
    """An output buffer pre-filled with a value that exposes unwritten elements.

    Floats get NaN, integers a large negative sentinel, bools True.
    """
    if dtype.is_floating_point:
        return torch.full(shape, float("nan"), dtype=dtype, device=device)
    if dtype == torch.bool:
        return torch.ones(shape, dtype=dtype, device=device)
    info = torch.iinfo(dtype)
    return torch.full(shape, max(info.min, _POISON_INT), dtype=dtype, device=device)


def generator(seed: int, device="cpu") -> torch.Generator:
    """A seeded generator, so a failing case can be replayed."""
    return torch.Generator(device=device).manual_seed(seed)


def _as_tensor(x, name: str) -> torch.Tensor:
    if isinstance(x, torch.Tensor):
        return x
    if isinstance(x, np.ndarray):
        return torch.from_numpy(x)
    raise AssertionError(f"{name}: expected a tensor, got {type(x).__name__}")


def check_tensor(x, name: str, *, shape=None, dtype=None, device=None) -> torch.Tensor:
    """Assert that ``x`` is a tensor of the given shape, dtype and device.

    ``shape`` entries may be ``None`` for "any size".
    """
    if type(x) is not torch.Tensor:
        kind = "a tensor subclass" if isinstance(x, torch.Tensor) else type(x).__name__
        raise AssertionError(f"{name}: expected a torch.Tensor, got {kind}")
    if shape is not None:
        ok = x.dim() == len(shape) and all(s is None or s == d for s, d in zip(shape, x.shape))
        if not ok:
            want = "(" + ", ".join("*" if s is None else str(s) for s in shape) + ")"
            raise AssertionError(f"{name}: expected shape {want}, got {tuple(x.shape)}")
    if dtype is not None and x.dtype != dtype:
        raise AssertionError(f"{name}: expected dtype {dtype}, got {x.dtype}")
    if device is not None and x.device.type != torch.device(device).type:
        raise AssertionError(
            f"{name}: expected a tensor on {torch.device(device).type}, got one on "
            f"{x.device.type} (kernels must work on their inputs' device)"
        )
    return x


def _index(flat: int, shape) -> tuple:
    return tuple(int(i) for i in np.unravel_index(flat, tuple(shape))) if shape else ()


def _fmt(v) -> str:
    if isinstance(v, float):
        return repr(v) if math.isfinite(v) else str(v)
    return str(v)


def assert_close(
    actual,
    expected,
    *,
    name: str,
    atol: float = 0.0,
    rtol: float = 0.0,
    equal_nan: bool = True,
    where: str = "element",
    mask=None,
) -> None:
    """Assert ``|actual - expected| <= atol + rtol * |expected|`` elementwise.

    Compared in float64 on the CPU. Infinities must match exactly; NaN matches NaN
    when ``equal_nan``. ``mask`` (bool, same shape) restricts the comparison.
    ``where`` names the index for the message ("ray", "pixel", ...).
    """
    actual = _as_tensor(actual, name)
    expected = _as_tensor(expected, f"expected {name}")
    if tuple(actual.shape) != tuple(expected.shape):
        raise AssertionError(
            f"{name}: expected shape {tuple(expected.shape)}, got {tuple(actual.shape)}"
        )
    a = actual.detach().to("cpu", torch.float64)
    e = expected.detach().to("cpu", torch.float64)
    both_nan = torch.isnan(a) & torch.isnan(e)
    diff = (a - e).abs()
    diff = torch.where(a == e, torch.zeros_like(diff), diff)  # inf == inf has no NaN diff
    bad = ~(diff <= atol + rtol * e.abs())
    if equal_nan:
        bad &= ~both_nan
    if mask is not None:
        bad &= _as_tensor(mask, "mask").to("cpu", torch.bool)
    count = int(bad.sum())
    if count == 0:
        return
    flat = bad.flatten().nonzero()[0, 0].item()
    first = _index(flat, a.shape)
    d = diff.flatten()
    d = torch.where(bad.flatten(), d.nan_to_num(nan=math.inf), torch.zeros_like(d))
    worst = _index(int(d.argmax()), a.shape)
    av, ev = a.flatten(), e.flatten()
    wflat = int(d.argmax())
    raise AssertionError(
        f"{name}: {count} of {a.numel()} values are off (tolerance atol={atol:g}, "
        f"rtol={rtol:g}).\n"
        f"  first at {where} {first}: expected {_fmt(ev[flat].item())}, "
        f"got {_fmt(av[flat].item())} (off by {_fmt(diff.flatten()[flat].item())})\n"
        f"  worst at {where} {worst}: expected {_fmt(ev[wflat].item())}, "
        f"got {_fmt(av[wflat].item())}"
    )


def assert_equal(actual, expected, *, name: str, where: str = "element") -> None:
    """Exact equality for integer, boolean or bit-exact float results."""
    actual = _as_tensor(actual, name)
    expected = _as_tensor(expected, f"expected {name}")
    if tuple(actual.shape) != tuple(expected.shape):
        raise AssertionError(
            f"{name}: expected shape {tuple(expected.shape)}, got {tuple(actual.shape)}"
        )
    a, e = actual.detach().cpu(), expected.detach().cpu()
    if a.dtype.is_floating_point or e.dtype.is_floating_point:
        bad = ~((a == e) | (torch.isnan(a.double()) & torch.isnan(e.double())))
    else:
        bad = a != e
    count = int(bad.sum())
    if count == 0:
        return
    flat = bad.flatten().nonzero()[0, 0].item()
    raise AssertionError(
        f"{name}: {count} of {a.numel()} values differ; first at {where} "
        f"{_index(flat, a.shape)}: expected {_fmt(e.flatten()[flat].item())}, "
        f"got {_fmt(a.flatten()[flat].item())}"
    )


def assert_fraction(bad: torch.Tensor, *, name: str, at_most: float, where: str = "element"):
    """Assert that the fraction of True in ``bad`` is at most ``at_most``."""
    bad = _as_tensor(bad, name).to("cpu", torch.bool)
    frac = bad.float().mean().item() if bad.numel() else 0.0
    if frac > at_most:
        flat = bad.flatten().nonzero()[0, 0].item()
        raise AssertionError(
            f"{name}: {int(bad.sum())} of {bad.numel()} ({frac:.2%}) fail, at most "
            f"{at_most:.2%} allowed; first at {where} {_index(flat, bad.shape)}"
        )


def first_line(exc: BaseException) -> str:
    """The first line of an exception's message.

    Errors from a sandboxed submission carry its traceback after the first line, and a
    traceback mentions argument names even when the message does not.
    """
    return str(exc).splitlines()[0] if str(exc) else ""


# Builtin errors a submission's own line raises by accident (an index past the end, a shape
# torch refuses, a missing attribute): where a check was expected, they are a wrong answer
# with a message, not a crash of the test.
_ACCIDENTS = (LookupError, RuntimeError, TypeError, ValueError, ArithmeticError, AttributeError)
_LIBRARY = ("site-packages", "dist-packages", "lib/python")


def _raising_line(exc: BaseException) -> str:
    """Where ``exc`` was raised, as ``file:line in function: source``: the last frame of the
    submission's traceback (the worker's, carried in the message, else the local one) that
    lies outside installed libraries and the course package."""
    import traceback

    from course.grading.feedback import text_frames

    course = Path(__file__).resolve().parents[1]
    frames = text_frames(str(exc)) or [
        (f.filename, f.lineno, f.name, f.line or "")
        for f in traceback.extract_tb(exc.__traceback__)
    ]
    found = ""
    for file, line, name, source in frames:
        path = Path(file)
        if any(part in file for part in _LIBRARY) or course in path.resolve().parents:
            continue
        found = f"{path.name}:{line} in {name}" + (f": {source.strip()}" if source else "")
    return found


def expect_error(names, fn, *args, kinds=(ValueError, TypeError), case: str = "", **kwargs):
    """``fn(*args, **kwargs)`` must raise one of ``kinds`` whose message names one of the
    arguments ``names`` (a name or a sequence of names). ``case`` describes the bad input.

    Another builtin error (an ``IndexError`` from an index past the end, a ``RuntimeError``
    from torch, a ``TypeError`` where a ``ValueError`` was asked for) fails the test with
    what was expected, what came and the line that raised it, never as a bare crash."""
    names = (names,) if isinstance(names, str) else tuple(names)
    what = getattr(fn, "__name__", None) or getattr(fn, "_name", "the call")
    case = case or "bad input"
    named = " or ".join(f"`{n}`" for n in names)
    expected = f"{' or '.join(k.__name__ for k in kinds)} naming {named}"
    try:
        fn(*args, **kwargs)
    except kinds as exc:
        assert any(n in first_line(exc) for n in names), (
            f"{what} with {case} raised {type(exc).__name__}({first_line(exc)!r}); the message "
            f"should name the argument {' or '.join(map(repr, names))} and say what was expected"
        )
        return
    except _ACCIDENTS as exc:
        text = first_line(exc)
        if (
            isinstance(exc, NotImplementedError)
            or type(exc).__module__ != "builtins"
            or text.startswith("not implemented yet")
            or "failed to import" in text
        ):
            raise  # an unwritten function or a sandbox failure keeps its own message
        kind = type(exc).__name__
        text = text if text.startswith(kind) else f"{kind}: {text}"
        line = _raising_line(exc)
        raise AssertionError(
            f"{what}: expected {expected} ({case}), got {text}"
            + (f" at {line}" if line else "")
            + "; check the argument first and raise with a message that names it"
        ) from None
    raise AssertionError(f"{what} accepted {case} without complaint: expected {expected}")


@contextlib.contextmanager
def replaced(lab, functions: dict):
    """Inside the block, the lab module's functions named in ``functions`` (name ->
    callable) are the given ones, then the lab's own again. A probe (``impl.probe``) grades
    one task's function this way with given stand-ins for the other tasks' functions it
    calls, so a mistake there does not cost this task's points. ``lab`` is what a probe
    receives: the module, or a wrapper that checks each call (the module's own code calls
    its globals, so they are replaced in the module itself). Yields the module.

    A lab kept as a package calls another module's function through the name it imported
    (``from .grid import build_grid`` in ``two_level.py``): each of the package's modules
    holds its own global of that name. So the name is replaced in the package and in every
    module of it whose global of that name is the lab's function (the same object; a
    module's own different function of that name is left alone), and all are restored."""
    module = sys.modules.get(getattr(lab, "__name__", None), lab)
    prefix = getattr(module, "__name__", "") + "."
    modules = [
        module,
        *(m for key, m in list(sys.modules.items()) if key.startswith(prefix) and m is not None),
    ]
    saved = []  # (module, name, its own value), to put back
    try:
        for name, fn in functions.items():
            own = getattr(module, name)
            for m in modules:
                if m is module or getattr(m, name, None) is own:
                    saved.append((m, name, getattr(m, name)))
                    setattr(m, name, fn)
        yield module
    finally:
        for m, name, value in reversed(saved):
            setattr(m, name, value)


OLD_INTERPRETER_REASON = (
    "Triton's interpreter before 3.9 cannot run these kernels (loop "
    "bounds from tensors); the compiled kernels are tested on CUDA"
)


def triton_interpreter_too_old() -> bool:
    """True where Triton is installed but older than 3.9, whose interpreter runs loops only
    to plain-integer bounds: the interpreted kernel tests skip there with
    ``OLD_INTERPRETER_REASON``."""
    import importlib.util

    if importlib.util.find_spec("triton") is None:
        return False
    import triton

    return tuple(int(x) for x in triton.__version__.split(".")[:2]) < (3, 9)


def run_in_triton_interpreter(script, inputs, tmp_path, timeout: float = 300):
    """Run ``python script IN.pt OUT.pt`` with ``TRITON_INTERPRET=1`` and return OUT.pt.

    Triton chooses between compiling and interpreting when it is first imported, so a
    CPU check of Triton kernels runs in a fresh process with the variable set, whatever
    the calling process imported. ``inputs`` is saved with ``torch.save``; ``script``
    (usually the test file itself, run as ``__main__``) loads it, runs the kernels and
    saves its results. Fails the test with the subprocess's output if it fails.
    """
    import os
    import subprocess
    import sys
    from pathlib import Path

    import pytest

    repo = Path(__file__).resolve().parents[2]
    source, target = Path(tmp_path) / "inputs.pt", Path(tmp_path) / "outputs.pt"
    torch.save(inputs, source)
    env = dict(
        os.environ,
        TRITON_INTERPRET="1",
        PYTHONPATH=os.pathsep.join(filter(None, [str(repo), os.environ.get("PYTHONPATH")])),
    )
    proc = subprocess.run(
        [sys.executable, str(script), str(source), str(target)],
        env=env,
        capture_output=True,
        text=True,
        timeout=timeout,
        check=False,
    )
    if proc.returncode != 0:
        pytest.fail(
            f"the interpreter subprocess failed (exit {proc.returncode}):\n"
            f"{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}"
        )
    return torch.load(target, weights_only=False)


# ------------------------------------------------------------------ images that differ


class ImageMismatch(AssertionError):
    """An image (or depth/id buffer) comparison failed; ``pictures`` are the PNGs written
    (expected, got, difference) for the student to look at."""

    def __init__(self, message: str, pictures=()):
        super().__init__(message)
        self.pictures = [str(p) for p in pictures]


_RUN = f"run-{time.strftime('%Y%m%d-%H%M%S')}-{os.getpid()}"  # this process's run folder


def failure_dir() -> Path:
    """Where failing image tests of this run write their pictures: a folder of its own per
    run (``run-<date>-<time>-<pid>``), so pictures of earlier runs never mix in, under
    ``$RTCOURSE_FAILURE_DIR``, else ``out/failures`` of the course folder the tests run in,
    else ``rtcourse-failures`` in the system's temporary folder."""
    import tempfile

    base = os.environ.get("RTCOURSE_FAILURE_DIR")
    if not base:
        here = Path.cwd()
        course = next(
            (
                f
                for f in (here, *here.parents)
                if (f / "tests").is_dir() and (f / "pyproject.toml").is_file()
            ),
            None,
        )
        base = (
            course / "out" / "failures"
            if course
            else Path(tempfile.gettempdir()) / "rtcourse-failures"
        )
    return Path(base) / _RUN


def _folder_name(text: str, fallback: str) -> str:
    """``text`` as one folder name: whole where it fits, else its start and a hash (file
    systems take 255 bytes)."""
    import hashlib

    name = re.sub(r"[^A-Za-z0-9_.\[\]-]+", "_", text).strip("_") or fallback
    if len(name) > 200:
        name = f"{name[:180]}-{hashlib.sha1(name.encode()).hexdigest()[:12]}"
    return name


def _shown(path: Path) -> str:
    """``path`` as a student types it: relative to the folder the tests run in, if inside."""
    try:
        return str(Path(path).resolve().relative_to(Path.cwd().resolve()))
    except ValueError:
        return str(path)


def _current_test() -> str:
    """The running test's id (pytest sets PYTEST_CURRENT_TEST), as a folder name."""
    test = os.environ.get("PYTEST_CURRENT_TEST", "image").rsplit(" (", 1)[0]
    return _folder_name(test.split("::", 1)[-1], "image")


def _grid(x: torch.Tensor, image_shape) -> torch.Tensor:
    """(H, W) or (H, W, C) on the CPU. Per-pixel rows (N[, C]) take ``image_shape``, or
    form a square when N is a square number (a size x size camera), else one row."""
    x = x.detach().cpu()
    if image_shape is None and x.dim() in (1, 2) and x.shape[0] > 1:
        side = math.isqrt(x.shape[0])
        if side * side == x.shape[0] and (x.dim() == 1 or x.shape[1] <= 4):
            image_shape = (side, side)
    if image_shape is not None:
        x = (
            x.reshape(*image_shape, *x.shape[1:])
            if x.dim() in (1, 2) and x.shape[0] == math.prod(image_shape)
            else x.reshape(*image_shape, -1)
        )
    if x.dim() == 1:
        x = x[None]
    if x.dim() == 3 and x.shape[-1] == 1:
        x = x[..., 0]
    return x


def _ids_to_rgb(ids: torch.Tensor) -> np.ndarray:
    """Distinct colours per id (a hash), black for negative ids (nothing there)."""
    v = ids.to(torch.int64).numpy()
    h = (v * 2654435761) & 0xFFFFFF
    rgb = np.stack([(h >> 16) & 255, (h >> 8) & 255, h & 255], axis=-1).astype(np.uint8)
    rgb = rgb // 2 + 96
    rgb[v < 0] = 0
    return rgb


def _to_rgb(x: torch.Tensor, kind: str, lo: float, hi: float) -> np.ndarray:
    """(H, W[, C]) -> (H, W, 3) uint8 for a PNG: colours through sRGB, scalars (depth)
    as grey from ``lo`` (black) to ``hi`` (white), ids hashed; NaN is magenta."""
    from course.core.image import to_srgb8

    if kind == "id":
        return _ids_to_rgb(x if x.dim() == 2 else x[..., 0])
    v = x.to(torch.float64)
    bad = torch.isnan(v) if v.dim() == 2 else torch.isnan(v).any(-1)
    if kind == "color" and v.dim() == 3 and v.shape[-1] in (3, 4):
        rgb = to_srgb8(v[..., :3].nan_to_num(0.0).clamp(0, 1).float()).numpy()
    else:
        v = v if v.dim() == 2 else v.abs().amax(-1)
        span = hi - lo if hi > lo else 1.0
        grey = ((v.nan_to_num(nan=lo, posinf=hi, neginf=lo) - lo) / span).clamp(0, 1)
        rgb = (grey * 255).round().to(torch.uint8)[..., None].expand(*v.shape, 3).numpy()
    rgb = np.array(rgb, dtype=np.uint8)
    rgb[bad.numpy()] = (255, 0, 255)
    return rgb


def write_pictures(
    actual, expected, bad, *, folder, kind: str = "color", image_shape=None
) -> list[Path]:
    """Write ``expected.png``, ``got.png`` and ``difference.png`` (the pixels out of
    tolerance in red over the expected picture, darkened) into ``folder``."""
    from PIL import Image

    e, a = (
        _grid(_as_tensor(expected, "expected"), image_shape),
        _grid(_as_tensor(actual, "actual"), image_shape),
    )
    finite = e.to(torch.float64)
    finite = finite[torch.isfinite(finite)]
    lo, hi = (float(finite.min()), float(finite.max())) if finite.numel() else (0.0, 1.0)
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    pictures = {"expected": _to_rgb(e, kind, lo, hi), "got": _to_rgb(a, kind, lo, hi)}
    b = _grid(_as_tensor(bad, "bad").to(torch.bool), image_shape)
    b = b if b.dim() == 2 else b.any(-1)
    diff = pictures["expected"] // 3
    diff[b.numpy()] = (255, 32, 32)
    pictures["difference"] = diff
    legends = {
        "expected": "expected",
        "got": "got (your result)",
        "difference": "red: out of tolerance",
    }
    paths = []
    for title, rgb in pictures.items():
        path = folder / f"{title}.png"
        _legible(Image.fromarray(np.ascontiguousarray(rgb)), legends[title]).save(
            path, format="PNG"
        )
        paths.append(path)
    return paths


PICTURE_SIDE = 256  # pixels: the shortest a failure picture's longer side is drawn


def _legible(image, legend: str):
    """``image`` scaled by a whole factor (nearest: every pixel stays a sharp square) until
    its longer side is at least :data:`PICTURE_SIDE`, over a strip naming what it shows."""
    from PIL import Image, ImageDraw

    scale = max(1, -(-PICTURE_SIDE // max(image.size)))
    big = image.resize((image.width * scale, image.height * scale), Image.NEAREST)
    strip = 18
    out = Image.new("RGB", (big.width, big.height + strip), (255, 255, 255))
    out.paste(big, (0, 0))
    ImageDraw.Draw(out).text((4, big.height + 3), legend, fill=(0, 0, 0))
    return out


def assert_image_close(
    actual,
    expected,
    *,
    name: str,
    atol: float = 0.0,
    rtol: float = 0.0,
    kind: str = "color",
    image_shape=None,
    where: str = "pixel",
    mask=None,
    exact: bool = False,
    folder=None,
) -> None:
    """Compare an image, depth buffer or id buffer like :func:`assert_close` (or, with
    ``exact``, :func:`assert_equal`); on a failure also write the expected, the submitted
    and a difference picture and name their folder in the message.

    actual, expected: (H, W), (H, W, C), or (N[, C]) with ``image_shape=(H, W)`` for
    per-ray results of an H x W camera. ``kind``: "color" (linear RGB), "depth" (a
    scalar shown in grey) or "id" (integers, one colour each, negative = nothing).
    ``folder``: where the pictures go (default: one per test under :func:`failure_dir`).
    """
    if kind not in ("color", "depth", "id"):
        raise ValueError(f"kind: expected 'color', 'depth' or 'id', got {kind!r}")
    actual, expected = _as_tensor(actual, name), _as_tensor(expected, f"expected {name}")
    try:
        if exact:
            assert_equal(actual, expected, name=name, where=where)
        else:
            assert_close(actual, expected, name=name, atol=atol, rtol=rtol, where=where, mask=mask)
    except AssertionError as exc:
        a = _as_tensor(actual, name).detach().cpu()
        e = _as_tensor(expected, f"expected {name}").detach().cpu()
        if tuple(a.shape) != tuple(e.shape):
            raise  # nothing to draw side by side
        if exact:
            bad = a != e
        else:
            ad, ed = a.to(torch.float64), e.to(torch.float64)
            diff = torch.where(ad == ed, torch.zeros_like(ad), (ad - ed).abs())
            bad = ~(diff <= atol + rtol * ed.abs()) & ~(torch.isnan(ad) & torch.isnan(ed))
            if mask is not None:
                bad &= _as_tensor(mask, "mask").cpu().to(torch.bool)
        raise image_mismatch(
            str(exc), a, e, bad, name=name, kind=kind, image_shape=image_shape, folder=folder
        ) from None


def image_mismatch(
    message: str,
    actual,
    expected,
    bad,
    *,
    name: str,
    kind: str = "color",
    image_shape=None,
    folder=None,
) -> ImageMismatch:
    """The :class:`ImageMismatch` to raise for a comparison a grader makes itself: writes
    the three pictures (``bad``: the pixels to mark, same leading shape) and names their
    folder after ``message``."""
    target = (
        Path(folder)
        if folder is not None
        else failure_dir() / _current_test() / _folder_name(name, "image")
    )
    try:
        paths = write_pictures(
            actual, expected, bad, folder=target, kind=kind, image_shape=image_shape
        )
    except (OSError, ValueError, RuntimeError) as why:  # the message matters more
        return ImageMismatch(f"{message}\n  (could not write the pictures: {why})")
    return ImageMismatch(
        f"{message}\n  pictures: expected.png, got.png, difference.png in {_shown(target)}", paths
    )
