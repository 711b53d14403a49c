"""Toy lab of the grader's bounds: plain calls, an output argument, a view a probe checks
and bad input. Its hostile submissions (tests/meta/hostile/*/lab8_guard.py) each attack
one bound."""


def scale(x, factor):
    """Task 1. x: (N,) float, factor: float -> x * factor (a new tensor)."""
    return x * factor


def scale_into(x, factor, out):
    """Task 2. Writes x * factor into out ((N,) float, like x) and returns out."""
    out.copy_(x * factor)
    return out


def as_view(x):
    """Task 3. x: (2, N) contiguous float -> (2N,), sharing x's memory (no copy)."""
    return x.view(-1)


def total_positive(x):
    """Task 4. x: (N,) float, every entry > 0 -> sum of x (0-d). ValueError naming x else."""
    if bool((x <= 0).any()):
        raise ValueError("x: every entry must be > 0")
    return x.sum()
