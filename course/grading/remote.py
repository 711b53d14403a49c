"""What of a sandboxed lab stays in the worker: a callable the lab returned (a method of an
object, a closure) and an object of a class the lab defines. Their calls travel like the
lab's own: arguments by value, outputs copied back, the reply checked."""

from __future__ import annotations

import torch

from course.grading import wire
from course.grading.input_check import Changed, check_written
from course.grading.sandbox_errors import WorkerCrashed


def _changed(reply, where) -> list[Changed]:
    try:
        return [
            Changed(pos, key, path, value)
            for pos, key, path, value in reply.get("written", ())
            if (pos is None or type(pos) is int)
            and (key is None or type(key) is str)
            and type(path) is str
        ]
    except (TypeError, ValueError):
        raise WorkerCrashed(f"the worker sent a malformed reply during {where}") from None


class RemoteCallable:
    """A callable that stays in the worker (``lab``: the :class:`SandboxedLab` it came from)."""

    def __init__(self, lab, ref, name, where, key):
        self._lab, self._ref, self._name, self._where = lab, ref, name, where
        self._key = key  # the reference's name for it: "fn", "Class" or "Class.method"

    def __call__(self, *args, **kwargs):
        __tracebackhide__ = True
        lab = self._lab
        reply = lab._request(
            {
                "op": "call",
                "ref": self._ref,
                "name": self._name,
                "args": wire.encode(args),
                "kwargs": wire.encode(kwargs),
            },
            self._where,
        )
        outputs = check_written(
            _changed(reply, self._where), self._where, lab._positional(self._key)
        )
        lab._fail(reply, self._where)
        for c in outputs:
            target = kwargs.get(c.keyword) if c.position is None else args[c.position]
            if isinstance(target, torch.Tensor) and c.value is not None:
                value = lab._decode(c.value, self._where)
                if isinstance(value, torch.Tensor) and value.shape == target.shape:
                    with torch.no_grad():
                        target.copy_(value.to(target.device))
        value = lab._decode(reply.get("value"), self._where)
        if (
            isinstance(value, RemoteObject)
            and lab._signatures is not None
            and self._key in lab._signatures
            and "." not in self._key
        ):
            value._key = self._key  # an instance of the reference's class of that name
        return value


class RemoteObject:
    """An object that stays in the worker (e.g. an instance of a class the lab defines)."""

    def __init__(self, lab, ref_id: int, type_name: str):
        self._lab, self._ref, self._type = lab, ref_id, str(type_name)
        self._key = self._type

    def __getattr__(self, name):
        if name.startswith("_"):
            raise AttributeError(name)
        return self._lab._getattr(self._ref, name, f"{self._type}.{name}", f"{self._key}.{name}")

    def __repr__(self):
        return f"<{self._type} in the sandboxed worker>"
