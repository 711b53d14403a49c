"""The input-mutation check: which arguments a call changed, and whether it was allowed to.

Kernels never modify their inputs; only an argument the reference names ``out`` (or
``..._out``) may be written. :func:`call_checked` copies every tensor and numpy array among
the arguments (nested ones too), runs the call and compares bits; :func:`check_written`
decides from the reference's parameter names. Both sides of the sandbox use it: the
worker (:mod:`course.grading.worker`) around every call of a submission and inside a
probe (``_CheckedLab``), the grader (:mod:`course.grading.sandbox`) on what the worker
reports, and :class:`LocalLab` around the trusted reference, in-process.

Standard library at import (numpy and torch are imported when first needed): the worker's
keeper imports this before it forks.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import inspect

# ------------------------------------------------------------- shared with the grader


def is_output_name(name) -> bool:
    """Arguments a kernel may write into: ``out`` or ``..._out``."""
    return isinstance(name, str) and (name == "out" or name.endswith("_out"))


def input_mutation_message(where: str, names) -> str:
    return (
        f"{where} modified its input argument(s) {', '.join(map(repr, names))}. Kernels "
        f"must leave their inputs untouched (only an `out` argument may be written): a "
        f"caller that reuses the input would silently get wrong results."
    )


def too_large_message(where: str, nbytes: int, limit: int) -> str:
    return (
        f"{where} returned {nbytes / 2**20:.0f} MB of data, more than the "
        f"{limit / 2**20:.0f} MB a result may hold; the test fails"
    )


# ---------------------------------------------------------------- input-mutation check


def _tensor_like(value):
    import numpy as np
    import torch

    if isinstance(value, torch.Tensor):
        return value.layout == torch.strided
    return isinstance(value, np.ndarray)


def _walk(value, path="", depth=0):
    """(path, array) for every tensor or numpy array in ``value``, inside lists, tuples,
    dicts and dataclasses too (a ``Mesh`` or ``Rays`` argument holds tensors)."""
    if _tensor_like(value):
        yield path, value
        return
    if depth >= 4:
        return
    if type(value) in (list, tuple) or isinstance(value, tuple):
        for i, item in enumerate(value):
            yield from _walk(item, f"{path}[{i}]", depth + 1)
    elif type(value) is dict:
        for key, item in list(value.items())[:64]:
            yield from _walk(item, f"{path}[{key!r}]", depth + 1)
    elif dataclasses.is_dataclass(value) and not isinstance(value, type):
        for f in dataclasses.fields(value):
            yield from _walk(getattr(value, f.name, None), f"{path}.{f.name}", depth + 1)


def _copy(a):
    import torch

    return a.detach().clone() if isinstance(a, torch.Tensor) else a.copy()


def _same_bits(a, b) -> bool:
    import numpy as np
    import torch

    if isinstance(a, np.ndarray):
        return (
            a.shape == b.shape
            and a.dtype == b.dtype
            and np.ascontiguousarray(a).tobytes() == np.ascontiguousarray(b).tobytes()
        )
    a = a.detach()
    if a.shape != b.shape or a.dtype != b.dtype:
        return False
    if a.dtype.is_floating_point or a.dtype.is_complex:
        # Bits, not values (NaN == NaN, -0.0 != +0.0); a fresh dense copy first: a strided
        # view (x[..., 0]) cannot be reinterpreted as bytes, nor can an expanded one
        # (contiguous() keeps stride 0 on size-1 dims).
        return torch.equal(_dense_bytes(a), _dense_bytes(b))
    return torch.equal(a, b)


def _dense_bytes(t):
    import torch

    flat = torch.empty(t.numel(), dtype=t.dtype, device=t.device).copy_(t.reshape(-1))
    return flat.view(torch.uint8)


@dataclasses.dataclass
class Changed:
    """An argument (or a tensor inside one) whose bits a call changed."""

    position: int | None  # index of a positional argument, else None
    keyword: str | None  # name of a keyword argument, else None
    path: str  # "" for the argument itself, ".origins" / "[2]" inside it
    value: object  # the array after the call


@contextlib.contextmanager
def _unobserved():
    """The check's own copies and comparisons, hidden from the torch modes a probe may
    have entered (an op counter or a live-value tracker must see the kernel only)."""
    import torch

    try:
        from torch.utils._python_dispatch import _disable_current_modes
    except ImportError:  # an older torch: no modes to hide from
        _disable_current_modes = contextlib.nullcontext
    with _disable_current_modes(), torch._C.DisableTorchFunction():
        yield


def call_checked(fn, args, kwargs):
    """Call ``fn``; return ``(result, changed, exception)``.

    ``changed`` lists every tensor or numpy array among the arguments (nested ones too)
    whose bits differ after the call, whether it returned or raised: a kernel that zeroes
    its inputs and then raises is caught as well. Which of them may be written (outputs)
    is the caller's decision, made from the reference's signature.
    """
    before = []
    with _unobserved():
        for i, arg in enumerate(args):
            before += [(i, None, p, a, _copy(a)) for p, a in _walk(arg)]
        for key, arg in kwargs.items():
            before += [(None, key, p, a, _copy(a)) for p, a in _walk(arg)]
    result, error = None, None
    try:
        result = fn(*args, **kwargs)
    except BaseException as exc:  # a submission may raise anything, SystemExit too
        error = exc
    with _unobserved():
        changed = [
            Changed(pos, key, path, a)
            for pos, key, path, a, old in before
            if not _same_bits(a, old)
        ]
    return result, changed, error


def argument_name(changed: Changed, positional) -> str | None:
    """The parameter a changed argument was passed as, by the reference's positional
    parameter names ``positional`` (None: the reference is not known)."""
    if changed.keyword is not None:
        return changed.keyword
    if positional is not None and changed.position < len(positional):
        return positional[changed.position]
    return None


def check_written(changed, where, positional):
    """Raise AssertionError if a call changed anything but its outputs; return the
    changed outputs as ``(position, keyword, value)``."""
    bad, outputs = [], []
    for c in changed:
        name = argument_name(c, positional)
        if c.path == "" and is_output_name(name):
            outputs.append(c)
        else:
            label = name or f"argument {c.position}"
            bad.append(label + c.path)
    if bad:
        raise AssertionError(input_mutation_message(where, bad))
    return outputs


# ---------------------------------------------------------------- checked lab (probes)


class _CheckedLab:
    """The lab module as a probe sees it: every call goes through the input-mutation
    check, with the outputs named by the reference's signatures."""

    def __init__(self, module, signatures, where):
        self._module, self._signatures, self._where = module, signatures, where

    def __getattr__(self, name):
        value = getattr(self._module, name)
        return _wrap(value, name, self._signatures, f"{self._where}.{name}")


class _CheckedObject:
    def __init__(self, obj, cls_name, signatures):
        self._obj, self._cls, self._signatures = obj, cls_name, signatures

    def __getattr__(self, name):
        value = getattr(self._obj, name)
        return _wrap(value, f"{self._cls}.{name}", self._signatures, f"{self._cls}.{name}")


def _wrap(value, key, signatures, where):
    if not callable(value) or type(value).__name__ == "module":
        return value
    positional = signatures.get(key) if signatures is not None else None

    @functools.wraps(value, updated=())  # a probe may read its signature (accounting does)
    def call(*args, **kwargs):
        result, changed, error = call_checked(value, args, kwargs)
        check_written(changed, where, positional)
        if error is not None:
            raise error
        if isinstance(value, type):
            return _CheckedObject(result, key, signatures)
        return result

    return call


class LocalLab:
    """A trusted lab module, called in-process with the same checks as the sandbox."""

    def __init__(self, name: str, module):
        self._name = name
        self._module = module

    def _start_clock(self, time_limit=None):
        pass

    def __getattr__(self, name):
        if name.startswith("_"):
            raise AttributeError(name)
        value = getattr(self._module, name)
        if callable(value) and not isinstance(value, type):
            return _checked(value, f"{self._name}.{name}")
        return value

    def probe(self, fn, *args, **kwargs):
        return fn(self._module, *args, **kwargs)

    def __repr__(self):
        return f"<lab {self._name} from {self._module.__file__}>"


def _positional_names(fn):
    try:
        return [
            p.name
            for p in inspect.signature(fn).parameters.values()
            if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD)
        ]
    except (TypeError, ValueError):
        return []


def _checked(fn, where):
    def call(*args, **kwargs):
        result, changed, error = call_checked(fn, args, kwargs)
        check_written(changed, where, _positional_names(fn))
        if error is not None:
            raise error
        return result

    call.__name__ = getattr(fn, "__name__", "call")
    call.__doc__ = fn.__doc__
    return call
