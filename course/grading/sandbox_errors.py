"""What the sandbox raises in the grader's process: a worker that crashed, ran out of time,
of the lab's time budget or of memory, a reply too large or not the probe's, and the
student's own exception rebuilt from the worker's report (its type where it is a builtin
one, its message and the worker's traceback as text)."""

from __future__ import annotations


class WorkerCrashed(RuntimeError):
    """The submission ended or broke the worker process."""


class TimeLimitExceeded(TimeoutError):
    """A call ran past the test's time limit; the worker was killed."""


class TimeBudgetExceeded(TimeLimitExceeded):
    """The submission's code used up the lab's time budget."""


class MemoryLimitExceeded(MemoryError):
    """A call used more memory than allowed; the worker was killed."""


class ReplyTooLarge(RuntimeError):
    """A call's result is bigger than a reply may be."""


class ForgedReply(AssertionError):
    """A probe's reply that its process's trusted code did not write."""


def _raise_student_error(err: dict, where: str, redact=None):
    """Re-raise a submission's exception as the closest builtin exception type,
    so ``pytest.raises(ValueError)`` works across the process boundary."""
    __tracebackhide__ = True  # a student's failure report shows their call, not the sandbox
    import builtins

    redact = redact or (lambda t: t)
    if not isinstance(err, dict) or not all(
        isinstance(err.get(k), str) for k in ("type", "message", "traceback")
    ):
        raise WorkerCrashed(f"the worker sent a malformed error during {where}")
    # Cut first: a hostile worker's megabytes of text must not cost the grader time.
    message, trace = redact(err["message"][:4000]), redact(err["traceback"][:4000])
    kind = err["type"][:100]
    text = f"{kind}: {message}" if kind != "NotImplementedError" else message
    kinds = err.get("kinds") if isinstance(err.get("kinds"), list) else []
    for name in kinds:
        cls = getattr(builtins, name, None) if isinstance(name, str) else None
        if isinstance(cls, type) and issubclass(cls, Exception) and cls is not Exception:
            if cls is NotImplementedError:
                raise NotImplementedError(message)
            tail = f"\n(raised in {where}" + (f"; {trace}" if trace else ")")
            raise cls(text + tail)
    raise RuntimeError(f"{text}\n(raised in {where})\n{trace}")
