# Replies meant to exhaust the grader's memory: a tensor bigger than a reply may be; a
# message whose header claims 64 GB; a small pickle naming one 4 MB tensor a thousand
# times; a list nested 200000 deep. The last three are written straight onto the worker's
# socket (then the process ends, so its own reply never follows).
import gc
import os
import pickle
import stat
import struct
from multiprocessing.connection import Connection

import torch


def _socket():
    """The worker's connection to the grader (a socket that is still open)."""
    for o in gc.get_objects():
        if isinstance(o, Connection) and not o.closed:
            try:
                if stat.S_ISSOCK(os.fstat(o.fileno()).st_mode):
                    return o
            except OSError:
                pass
    raise RuntimeError("no socket found")


def _send_raw(data):
    _socket().send_bytes(data)
    os._exit(0)


def _memo_bomb():
    tensor = {"__rtcourse__": "tensor", "dtype": "float32", "shape": (2**20,),
              "device": "cpu", "data": bytes(4 * 2**20)}
    return pickle.dumps({"value": [tensor] * 1000, "output": ""}, protocol=5)


def _deep_pickle(depth):
    key = b"X" + struct.pack("<I", 5) + b"value"
    return b"\x80\x02}" + key + b"]" * depth + b"a" * (depth - 1) + b"s."


def scale(x, factor):
    if factor == -1.0:
        _send_raw(_memo_bomb())
    if factor == 0.5:
        _send_raw(_deep_pickle(200000))
    if factor == 3.0:
        os.write(_socket().fileno(), struct.pack("!i", -1) + struct.pack("!Q", 64 * 2**30))
        os._exit(0)
    return torch.zeros(100 * 2**20)  # 400 MB


def scale_into(x, factor, out):
    return [torch.ones(2**20)] * 1000


def as_view(x):
    return [torch.ones(2**20)] * 1000


def total_positive(x):
    nested = []
    for _ in range(200000):
        nested = [nested]
    return nested
