"""Assertions for graders: failures say what, where and how far off.

Every helper raises ``AssertionError`` with a message written for a student:
the quantity's name, what was expected, what came back, the first offending
index and the size of the error.
"""

from __future__ import annotations

import math

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


def assert_close(actual, expected, *, name: str, atol: float = 0.0, rtol: float = 0.0,
                 equal_nan: bool = True, where: str = "element", mask=None) -> None:
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


def expect_error(names, fn, *args, kinds=(ValueError, TypeError), case: str = "", **kwargs):
    """``fn(*args, **kwargs)`` must raise one of ``kinds`` whose message names one of the
    arguments ``names`` (a name or a sequence of names). ``case`` describes the bad input."""
    names = (names,) if isinstance(names, str) else tuple(names)
    what = getattr(fn, "__name__", None) or getattr(fn, "_name", "the call")
    case = case or "bad input"
    try:
        fn(*args, **kwargs)
    except kinds as exc:
        assert any(n in first_line(exc) for n in names), (
            f"{what} with {case} raised {type(exc).__name__}({first_line(exc)!r}); the message "
            f"should name the argument {' or '.join(map(repr, names))} and say what was expected")
        return
    raise AssertionError(f"{what} accepted {case} without complaint: expected "
                         f"{' or '.join(k.__name__ for k in kinds)} naming "
                         f"{' or '.join(map(repr, names))}")


OLD_INTERPRETER_REASON = ("Triton's interpreter before 3.9 cannot run these kernels (loop "
                          "bounds from tensors); the compiled kernels are tested on CUDA")


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

    repo = Path(__file__).resolve().parents[1]
    source, target = Path(tmp_path) / "inputs.pt", Path(tmp_path) / "outputs.pt"
    torch.save(inputs, source)
    env = dict(os.environ, TRITON_INTERPRET="1",
               PYTHONPATH=os.pathsep.join(filter(None, [str(repo), os.environ.get("PYTHONPATH")])))
    proc = subprocess.run([sys.executable, str(script), str(source), str(target)], env=env,
                          capture_output=True, text=True, timeout=timeout, check=False)
    if proc.returncode != 0:
        pytest.fail(f"the interpreter subprocess failed (exit {proc.returncode}):\n"
                    f"{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}")
    return torch.load(target, weights_only=False)
