"""Task 2: zero-copy sharing: ``framebuffer_to_numpy``, ``numpy_to_framebuffer``,
``share_dlpack``, ``cuda_array_interface``.
"""

from __future__ import annotations

import numpy as np
import torch

from .framebuffer import _check_framebuffer

# Task 2: zero-copy sharing (3 points)
#
# "Register + map" gives CUDA a pointer into memory GL owns: two APIs, one buffer. The
# PyTorch equivalents are views: another library's array over the tensor's memory. A view
# is only possible for a contiguous block of the expected type, so check first.


def framebuffer_to_numpy(fb: torch.Tensor) -> np.ndarray:
    """A numpy view of a CPU framebuffer ``fb: (H, W) int32``: same memory, no copy.

    A write through the array is visible in ``fb`` and vice versa;
    ``arr.__array_interface__['data'][0] == fb.data_ptr()``.

    Errors: ValueError naming ``fb`` for a non-contiguous, non-int32 or non-2-D tensor
    (``_check_framebuffer``) and for a CUDA tensor (numpy cannot address GPU memory: the
    caller must download it explicitly; a hidden copy would break the contract).

    Hint: ``Tensor.numpy()`` shares memory; ``np.array(t)`` and ``.copy()`` do not.
    """
    raise NotImplementedError("not implemented yet: framebuffer_to_numpy (task 2)")


def numpy_to_framebuffer(arr: np.ndarray) -> torch.Tensor:
    """A tensor view of ``arr: (H, W) int32`` C-contiguous numpy array: same memory.

    Errors: TypeError if ``arr`` is not an ndarray; ValueError naming ``arr`` for a wrong
    ndim, a dtype other than int32 or a non-C-contiguous array (``arr.flags.c_contiguous``).

    Hint: ``torch.from_numpy`` shares memory; ``torch.tensor(arr)`` copies.
    """
    raise NotImplementedError("not implemented yet: numpy_to_framebuffer (task 2)")


def share_dlpack(fb: torch.Tensor) -> torch.Tensor:
    """Re-import ``fb: (H, W) int32`` (any device) through its DLPack export.

    DLPack is the common zero-copy exchange format of array libraries (CuPy, JAX, numba,
    TensorFlow, numpy): the producer exports a capsule (pointer, shape, strides, dtype,
    device), the consumer wraps it. Return the tensor that ``torch.from_dlpack`` builds: a
    new tensor object (not ``fb`` itself) over the same memory, on the same device.

    Errors: ValueError naming ``fb`` as in ``_check_framebuffer``.

    Hint: ``torch.from_dlpack(fb)`` calls ``fb.__dlpack__(stream=...)``; on CUDA the
    producer orders the consumer's stream after work already queued on ``fb``.
    """
    raise NotImplementedError("not implemented yet: share_dlpack (task 2)")


def cuda_array_interface(fb: torch.Tensor) -> dict:
    """The CUDA Array Interface (version 3) dict describing a CUDA framebuffer.

    Keys: ``shape`` (H, W) as a tuple, ``typestr`` "<i4" (little-endian 4-byte int),
    ``data`` (fb.data_ptr(), False) — the pointer and a read-only flag, ``strides`` None
    (meaning C-contiguous), ``version`` 3 and ``stream``: the stream a consumer must
    synchronise with (1 means the legacy default stream; 0 is not allowed). numba, CuPy and
    ``torch.as_tensor`` build a view from such a dict alone.

    Errors: ValueError naming ``fb`` as in ``_check_framebuffer``, and for a CPU tensor.

    Hint: ``torch.cuda.current_stream(fb.device).cuda_stream`` is 0 for the default stream.
    """
    raise NotImplementedError("not implemented yet: cuda_array_interface (task 2)")
