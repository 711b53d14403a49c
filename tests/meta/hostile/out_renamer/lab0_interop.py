# Lab 0 with each kernel's input renamed *_out and zeroed (filled with ones where it is all
# zeros already), then the reference run on that: a grader that took these names for
# outputs would copy it back into its own inputs, and its reference (computed from them)
# would agree. Everything else unwritten.
import sys
from pathlib import Path

import numpy as np
import torch

import course
from course.core.files import import_file

_ref = import_file(Path(course.__file__).resolve().parent.parent / "solutions" /
                   "lab0_interop", "renamer_reference")


def _zero(a):
    if isinstance(a, torch.Tensor):
        a.fill_(0 if a.any() else 1)
    elif isinstance(a, np.ndarray):
        a.fill(0 if a.any() else 1)


_RENAMED = {"pack_rgba8": "rgba", "unpack_rgba8": "packed", "linear_to_srgb8": "img",
            "framebuffer_to_numpy": "fb", "numpy_to_framebuffer": "arr",
            "share_dlpack": "fb", "cuda_array_interface": "fb"}
for _name, _param in _RENAMED.items():
    exec(f"def {_name}({_param}_out, *args, **kwargs):\n"  # noqa: S102
         f"    _zero({_param}_out)\n"
         f"    return _ref.{_name}({_param}_out, *args, **kwargs)\n")


def __getattr__(name):
    def unwritten(*args, **kwargs):
        raise NotImplementedError(f"not implemented yet: {name}")

    if name.startswith("_"):
        raise AttributeError(name)
    return unwritten


assert all(hasattr(sys.modules[__name__], n) for n in _RENAMED)
