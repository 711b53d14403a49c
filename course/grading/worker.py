"""The sandboxed worker: imports a submitted lab module and runs calls on it.

Started by :mod:`course.grading.sandbox` as ``python -m course.grading.worker FD
FOLDER MEMORY_BYTES``; ``FD`` is one end of a socket pair. Each request names its lab;
the lab file ``FOLDER/<lab>.py`` is imported on the first request for it. Requests arrive as
pickles from the trusted grader; replies go back as plain data (see
:mod:`course.grading.wire`). Anything the submission prints lands in a file the
grader reads after each request, never on the grader's own output.
"""

from __future__ import annotations

import os
import resource
import sys
import tempfile
import traceback
from multiprocessing.connection import Connection

_OUTPUT_LIMIT = 4000


def _capture_output():
    """Point fds 1 and 2 at a private file; return it for reading back."""
    capture = tempfile.TemporaryFile(mode="w+b")
    os.dup2(capture.fileno(), 1)
    os.dup2(capture.fileno(), 2)
    return capture


def _take_output(capture) -> str:
    sys.stdout.flush()
    sys.stderr.flush()
    capture.seek(0)
    text = capture.read().decode("utf-8", "replace")
    capture.seek(0)
    capture.truncate()
    if len(text) > _OUTPUT_LIMIT:
        text = text[:_OUTPUT_LIMIT] + f"\n... ({len(text) - _OUTPUT_LIMIT} more characters)"
    return text


def _limit_memory(extra_bytes: int):
    """Cap the address space at what is mapped now plus ``extra_bytes``.

    Skipped when CUDA is usable: the driver reserves far more address space than
    it uses. The grader then watches the resident size instead.
    """
    import torch

    if extra_bytes <= 0 or torch.cuda.is_available():
        return
    with open("/proc/self/statm") as f:
        mapped = int(f.read().split()[0]) * os.sysconf("SC_PAGE_SIZE")
    limit = mapped + extra_bytes
    resource.setrlimit(resource.RLIMIT_AS, (limit, limit))


def _error(exc: BaseException) -> dict:
    # Only names and text travel: the grader re-raises a builtin of the same kind.
    kinds = [c.__name__ for c in type(exc).__mro__ if c.__module__ == "builtins"]
    if isinstance(exc, SystemExit):
        message = f"the code called sys.exit({exc.code!r})"
    else:
        message = str(exc)
    tb = traceback.format_exception(type(exc), exc, exc.__traceback__)
    return {"kinds": kinds, "type": type(exc).__name__, "message": message,
            "traceback": "".join(tb[-6:])[-3000:]}


def _same_bits(a, b) -> bool:
    import torch

    if a.shape != b.shape or a.dtype != b.dtype:
        return False
    if a.dtype.is_floating_point or a.dtype.is_complex:
        # Bits, not values (NaN == NaN, -0.0 != +0.0); contiguous first: a strided view
        # (x[..., 0]) cannot be reinterpreted as bytes.
        return torch.equal(a.contiguous().reshape(-1).view(torch.uint8),
                           b.contiguous().reshape(-1).view(torch.uint8))
    return torch.equal(a, b)


def is_output_name(name) -> bool:
    """Arguments a kernel may write into: ``out`` or ``..._out``."""
    return isinstance(name, str) and (name == "out" or name.endswith("_out"))


def call_checked(fn, args, kwargs, param_names):
    """Call ``fn`` and report which tensor arguments it modified.

    Returns ``(result, written)`` where ``written`` maps an argument's name to
    ``(position, tensor after the call)`` for every tensor argument whose bits
    changed; ``position`` is the index of a positional argument, else None.
    """
    import torch

    named = [(name, i, t) for i, (name, t) in enumerate(zip(param_names, args))]
    named += [(name, None, t) for name, t in kwargs.items()]
    before = [(name, pos, t, t.detach().clone()) for name, pos, t in named
              if isinstance(t, torch.Tensor) and t.layout == torch.strided]
    result = fn(*args, **kwargs)
    written = {name: (pos, t) for name, pos, t, old in before
               if not _same_bits(t.detach(), old)}
    return result, written


def parameter_names(fn, count):
    import inspect

    try:
        params = list(inspect.signature(fn).parameters)
    except (TypeError, ValueError):
        params = []
    return [params[i] if i < len(params) else f"argument {i}" for i in range(count)]


def main(argv):
    fd, folder, memory_bytes = int(argv[0]), argv[1], int(argv[2])
    conn = Connection(fd)
    capture = _capture_output()
    os.chdir(tempfile.mkdtemp(prefix="rtcourse-worker-"))
    sys.stdin = open(os.devnull)

    from course.grading import wire  # imports torch

    _limit_memory(memory_bytes)
    labs = _Labs(folder, wire)
    refs: dict[int, object] = {}
    conn.send_bytes(wire.dumps({"ready": True, "output": _take_output(capture)}))

    while True:
        try:
            request = wire.pickle.loads(conn.recv_bytes())
        except EOFError:
            return
        reply = _serve(request, labs, refs, wire)
        reply["output"] = _take_output(capture)
        try:
            data = wire.dumps(reply)
        except BaseException as exc:
            data = wire.dumps({"error": _error(exc), "output": reply["output"]})
        conn.send_bytes(data)


class _Labs:
    """The submission's lab modules, each imported on its first request."""

    def __init__(self, folder, wire):
        self.folder, self.wire = folder, wire
        self.modules: dict[str, tuple] = {}  # name -> (module or None, import error or None)

    def get(self, name):
        if name not in self.modules:
            path = os.path.join(self.folder, f"{name}.py")
            try:
                self.modules[name] = (self.wire.import_file(path, "submission_" + name), None)
            except BaseException as exc:  # a submission may raise anything, SystemExit too
                self.modules[name] = (None, _error(exc))
        return self.modules[name]


def _serve(request, labs, refs, wire):
    op = request["op"]
    module, import_error = labs.get(request["lab"])
    if import_error is not None:
        return {"error": dict(import_error, message="the lab module failed to import: "
                              + import_error["type"] + ": " + import_error["message"])}
    try:
        target = module if request.get("ref") is None else refs[request["ref"]]
        if op == "release":
            refs.pop(request["ref"], None)
            return {"value": None}
        if op == "getattr":
            value = getattr(target, request["name"])
            if callable(value) and not isinstance(value, type(module)):
                return {"value": None, "callable": True}
            return {"value": wire.encode(value, refs)}
        args = wire.decode(request["args"], allow_functions=True, make_ref=refs.__getitem__)
        kwargs = wire.decode(request["kwargs"], allow_functions=True, make_ref=refs.__getitem__)
        if op == "probe":
            fn = wire.load_function(request["probe"])
            return {"value": wire.encode(fn(module, *args, **kwargs), refs)}
        fn = getattr(target, request["name"])
        result, written = call_checked(fn, args, kwargs, parameter_names(fn, len(args)))
        return {"value": wire.encode(result, refs),
                "written": {name: (pos, wire.encode(t)) for name, (pos, t) in written.items()}}
    except BaseException as exc:
        return {"error": _error(exc)}


if __name__ == "__main__":
    main(sys.argv[1:])
