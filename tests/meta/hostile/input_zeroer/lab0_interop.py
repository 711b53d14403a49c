# Lab 0 as the reference computes it, but every call zeroes its input tensors and arrays
# in place (after computing, or before raising). An input that is all zeros already stays
# as it was: the graders' inputs are never all zeros, so no test can pass unnoticed. A call
# with no array to overwrite is not written. Loads the reference from the course folder (a local
# attack only).
import functools
import inspect
import sys
from pathlib import Path

import numpy as np
import torch

import course
from course.core.files import import_file

_ref = import_file(Path(course.__file__).resolve().parent.parent / "solutions" /
                   "lab0_interop", "zeroer_reference")


def _arrays(value):
    if isinstance(value, (torch.Tensor, np.ndarray)):
        return [value]
    if isinstance(value, (list, tuple)):
        return [a for v in value for a in _arrays(v)]
    return []


def _zero(arrays):
    for a in arrays:
        try:
            a.fill_(0) if isinstance(a, torch.Tensor) else a.fill(0)
        except (RuntimeError, ValueError):
            pass


def _zeroing(fn, name, skip_first=False):
    signature = inspect.signature(fn)

    @functools.wraps(fn)
    def call(*args, **kwargs):
        bound = signature.bind(*args, **kwargs)
        items = list(bound.arguments.items())[1 if skip_first else 0:]
        inputs = [a for key, v in items if key != "out" for a in _arrays(v)]
        if not inputs:
            raise NotImplementedError(f"not implemented yet: {name}")
        try:
            result = fn(*args, **kwargs)
        except Exception:
            _zero(inputs)
            raise
        _zero(inputs)
        return result

    return call


for _name, _value in vars(_ref).copy().items():
    if _name.startswith("_") or getattr(_value, "__module__", None) != _ref.__name__:
        continue
    if inspect.isclass(_value):
        _members = {k: _zeroing(v, f"{_name}.{k}", skip_first=True)
                    for k, v in vars(_value).items() if inspect.isfunction(v)}
        setattr(sys.modules[__name__], _name, type(_name, (_value,), _members))
    elif inspect.isfunction(_value):
        setattr(sys.modules[__name__], _name, _zeroing(_value, _name))
