"""What crosses between the grader and the sandboxed worker, and how.

Everything is first turned into plain Python data (dicts, lists, tuples, str,
bytes, numbers, None) and then pickled. The grader unpickles the worker's
replies with an unpickler that refuses *every* class, so a submission cannot
smuggle an object (a tensor subclass that compares equal to anything, a class
with a malicious ``__reduce__``) into the checking process: a tensor arrives as
raw bytes and is rebuilt here as a plain ``torch.Tensor``.

A reply is bounded twice: the grader reads no message longer than its cap (the length comes
first on the socket), and :func:`decode` counts what it builds against the same cap, so a
small pickle that names one big tensor many times cannot make the grader build it many
times. A tensor's bytes must match its shape and dtype.

Tagged values are dicts with the key ``TAG``:
  tensor   {"dtype", "shape", "device", "data"}
  ndarray  {"dtype", "shape", "data"}
  dataclass of the ``course`` package {"cls", "fields"}
  func     a module-level function, by reference {"module" or "file", "qualname"}
  ref      an object that stays in the worker {"id", "type"}
"""

from __future__ import annotations

import dataclasses
import importlib
import inspect
import io
import pickle
import sys
from pathlib import Path

import numpy as np
import torch

from course.core.files import import_file

TAG = "__rtcourse__"
_PLAIN = (str, bytes, int, float, bool, type(None))


class _NoClasses(pickle.Unpickler):
    """An unpickler for plain data only: any class or function is refused."""

    def find_class(self, module, name):
        raise pickle.UnpicklingError(f"refused to load {module}.{name} from the worker")


def dumps(obj) -> bytes:
    return pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)


def loads_plain(data: bytes):
    return _NoClasses(io.BytesIO(data)).load()


# ---------------------------------------------------------------- encoding


def _tensor_bytes(t: torch.Tensor) -> bytes | pickle.PickleBuffer:
    # Strip any subclass behaviour before touching the data.
    with torch._C.DisableTorchFunctionSubclass():
        t = torch.Tensor.detach(t).to("cpu")
        if t.numel() == 0:
            return b""
        # A fresh dense buffer: contiguous() keeps stride 0 on expanded size-1 dims,
        # which cannot be reinterpreted as bytes.
        flat = torch.empty(t.numel(), dtype=t.dtype).copy_(t.reshape(-1))
        # Pickled in place (protocol 5: the buffer's bytes go straight into the stream
        # and come out as a bytearray the tensor can wrap), no intermediate bytes copy.
        return pickle.PickleBuffer(flat.view(torch.uint8).numpy())


def encode(obj, refs=None):
    """Plain-data form of ``obj``. Objects that cannot travel are stored in
    ``refs`` (a dict id -> object, worker side) and sent as references; with
    ``refs=None`` such an object is an error."""
    if isinstance(obj, _PLAIN):
        return obj
    if isinstance(obj, torch.Tensor):
        with torch._C.DisableTorchFunctionSubclass():
            return {
                TAG: "tensor",
                "dtype": str(obj.dtype).removeprefix("torch."),
                "shape": tuple(obj.shape),
                "device": str(obj.device),
                "data": _tensor_bytes(obj),
            }
    if isinstance(obj, np.ndarray) and obj.dtype.kind in "biufc":
        return {
            TAG: "ndarray",
            "dtype": obj.dtype.str,
            "shape": obj.shape,
            "data": np.ascontiguousarray(obj).tobytes(),
        }
    if isinstance(obj, np.generic) and obj.dtype.kind in "biufc":
        return obj.item()
    if isinstance(obj, torch.dtype):
        return {TAG: "dtype", "name": str(obj).removeprefix("torch.")}
    if isinstance(obj, torch.device):
        return {TAG: "device", "name": str(obj)}
    if (
        dataclasses.is_dataclass(obj)
        and not isinstance(obj, type)
        and type(obj).__module__.startswith("course.")
    ):
        return {
            TAG: "dataclass",
            "cls": f"{type(obj).__module__}:{type(obj).__qualname__}",
            "fields": {f.name: encode(getattr(obj, f.name), refs) for f in dataclasses.fields(obj)},
        }
    if type(obj) in (list, tuple) or isinstance(obj, tuple):  # named tuples travel as tuples
        items = [encode(x, refs) for x in obj]
        return items if type(obj) is list else tuple(items)
    if type(obj) is dict:
        return {TAG: "dict", "items": [(encode(k, refs), encode(v, refs)) for k, v in obj.items()]}
    if refs is None:
        if inspect.isfunction(obj) and obj.__qualname__ == obj.__name__:
            return _encode_function(obj)
        raise TypeError(f"cannot send {type(obj).__name__} to the sandboxed worker")
    ref_id = id(obj)
    refs[ref_id] = obj
    return {TAG: "ref", "id": ref_id, "type": type(obj).__name__}


def _encode_function(fn) -> dict:
    """A module-level function travels by reference: the worker imports it."""
    module = sys.modules.get(fn.__module__)
    if fn.__module__.startswith("course.") or fn.__module__ == "course":
        return {TAG: "func", "module": fn.__module__, "qualname": fn.__qualname__}
    path = getattr(module, "__file__", None) or inspect.getfile(fn)
    return {TAG: "func", "file": str(Path(path).resolve()), "qualname": fn.__qualname__}


# ---------------------------------------------------------------- decoding

_ALLOWED_DTYPES = {
    name: getattr(torch, name)
    for name in (
        "float16",
        "bfloat16",
        "float32",
        "float64",
        "uint8",
        "int8",
        "int16",
        "int32",
        "int64",
        "bool",
        "complex64",
        "complex128",
        "uint16",
        "uint32",
        "uint64",
    )
    if hasattr(torch, name)
}


class TooLarge(ValueError):
    """A reply that decodes to more than the cap allows."""


class _Budget:
    """Bytes (and container slots, 8 bytes each) a decode may still build."""

    def __init__(self, limit):
        self.limit = self.left = limit

    def take(self, nbytes):
        self.left -= nbytes
        if self.left < 0:
            raise TooLarge(f"the result decodes to more than {self.limit / 2**20:.0f} MB")


def _shape(d) -> tuple:
    shape = d["shape"]
    if (
        type(shape) not in (tuple, list)
        or len(shape) > 64
        or any(type(s) is not int or s < 0 for s in shape)
    ):
        raise TypeError(f"malformed shape {shape!r}")
    return tuple(shape)


def _decode_tensor(d, device_map, budget=None) -> torch.Tensor:
    dtype = _ALLOWED_DTYPES.get(d["dtype"])
    if dtype is None:
        raise TypeError(f"tensor of unsupported dtype {d['dtype']!r}")
    shape = _shape(d)
    data = d["data"]
    if not isinstance(data, (bytes, bytearray)):
        raise TypeError(f"tensor data of type {type(data).__name__}, expected bytes")
    numel = 1
    for s in shape:
        numel *= s
    if numel * torch.empty((), dtype=dtype).element_size() != len(data):
        raise TypeError(
            f"tensor of shape {shape} and dtype {d['dtype']} with {len(data)} bytes of data"
        )
    if budget is not None:
        budget.take(len(data))
    if len(data) == 0:
        t = torch.empty(shape, dtype=dtype)
    else:
        # A bytearray is this side's own copy (what the unpickler made of the buffer):
        # wrap it without copying again.
        owned = data if isinstance(data, bytearray) else bytearray(data)
        t = torch.frombuffer(owned, dtype=torch.uint8).view(dtype).reshape(shape)
    device = device_map(d["device"])
    return t if device == "cpu" else t.to(device)


def _local_device(name: str) -> str:
    """Results keep the device they were produced on, when this process has it."""
    if name.startswith("cuda") and torch.cuda.is_available():
        return name
    return "cpu"


def load_function(d):
    if "module" in d:
        module = importlib.import_module(d["module"])
    else:
        module = import_file(d["file"])
    obj = module
    for part in d["qualname"].split("."):
        obj = getattr(obj, part)
    return obj


def decode(obj, *, make_ref=None, allow_functions=False, limit=None):
    """Rebuild a value from its plain-data form.

    ``make_ref(id, type)`` turns a worker reference into a local handle (grader
    side). Functions are resolved only when ``allow_functions`` (worker side:
    they come from the trusted grader). ``limit``: the bytes the result may take (the
    grader's cap on replies); more raises :class:`TooLarge`.
    """
    budget = _Budget(limit) if limit is not None else None
    try:
        return _decode(obj, make_ref, allow_functions, budget)
    except RecursionError:
        raise TooLarge("the result is nested too deeply to rebuild") from None


def _decode(obj, make_ref, allow_functions, budget):
    if isinstance(obj, _PLAIN):
        if budget is not None and type(obj) in (str, bytes):
            budget.take(len(obj))
        return obj
    if budget is not None and type(obj) in (list, tuple, dict):
        budget.take(8 * len(obj) + 64)
    if type(obj) is list:
        return [_decode(x, make_ref, allow_functions, budget) for x in obj]
    if type(obj) is tuple:
        return tuple(_decode(x, make_ref, allow_functions, budget) for x in obj)
    if type(obj) is not dict or TAG not in obj:
        raise TypeError(f"malformed value of type {type(obj).__name__} from the other side")
    kind = obj[TAG]

    def sub(value):
        return _decode(value, make_ref, allow_functions, budget)

    if kind == "tensor":
        return _decode_tensor(obj, _local_device, budget)
    if kind == "ndarray":
        dtype = np.dtype(obj["dtype"])
        if dtype.kind not in "biufc":
            raise TypeError(f"array of unsupported dtype {dtype}")
        shape, data = _shape(obj), obj["data"]
        if not isinstance(data, (bytes, bytearray)) or int(np.prod(shape)) * dtype.itemsize != len(
            data
        ):
            raise TypeError(f"array of shape {shape} and dtype {dtype} with malformed data")
        if budget is not None:
            budget.take(len(data))
        return np.frombuffer(bytearray(data), dtype=dtype).reshape(shape)
    if kind == "dtype":
        dtype = _ALLOWED_DTYPES.get(obj["name"])
        if dtype is None:
            raise TypeError(f"unsupported dtype {obj['name']!r}")
        return dtype
    if kind == "device":
        return torch.device(obj["name"])
    if kind == "dict":
        items = obj["items"]
        if budget is not None:
            budget.take(16 * len(items))
        return {sub(k): sub(v) for k, v in items}
    if kind == "dataclass":
        module_name, qualname = obj["cls"].split(":")
        if not module_name.startswith("course."):
            raise TypeError(f"refused class {obj['cls']}")
        cls = getattr(importlib.import_module(module_name), qualname)
        if not dataclasses.is_dataclass(cls):
            raise TypeError(f"refused class {obj['cls']}")
        fields = {k: sub(v) for k, v in obj["fields"].items()}
        return _build_dataclass(cls, fields)
    if kind == "ref" and make_ref is not None:
        return make_ref(obj["id"], obj["type"])
    if kind == "func" and allow_functions:
        return load_function(obj)
    raise TypeError(f"unexpected value kind {kind!r}")


def _build_dataclass(cls, fields):
    # Skip __init__/__post_init__: validation belongs to the checks, which report
    # a malformed result as a wrong answer rather than crashing the decoder.
    obj = object.__new__(cls)
    for name, value in fields.items():
        object.__setattr__(obj, name, value)
    return obj
