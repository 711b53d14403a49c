"""Operation counts and a live-value (register) estimate for batched torch kernels.

The lecture compares ray/triangle tests by what one GPU thread executes for one test:

    ========================  ===  =======  ===  =====================
    test                      mul  add/sub  div  cycles (G80, 1 warp)
    ========================  ===  =======  ===  =====================
    plane + area              39   53       1    248-404
    Moller-Trumbore           23   24       1    132-224
    Woop unit triangle        20   20       1    116-196
    ========================  ===  =======  ===  =====================

and by the registers that thread needs (the lecture's budget: 23). A torch kernel does the
same work for many *lanes* at once (a lane = one ray-triangle pair = one GPU thread), so
`count_ops` runs it under a dispatch mode, sees every aten op it executes, and divides each
op's work by the number of lanes; `live_values` follows the tensors it allocates and frees
and reports how many values per lane are alive at once.

Both are estimates: they take the torch code op by op as written, without the
common-subexpression elimination and rescheduling a compiler would apply.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import weakref
from collections import Counter
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any

import torch
from torch.utils._python_dispatch import TorchDispatchMode

# G80 issue cost per warp (CUDA C Programming Guide 2.x, "Arithmetic instructions"): add,
# mul and mad 4 cycles; x / y 36; sqrt 32 (a reciprocal of a reciprocal square root).
MAD_CYCLES = 4
DIV_CYCLES = 36
SQRT_CYCLES = 32

Lanes = int | tuple[int, ...] | None


@dataclass(frozen=True)
class OpCounts:
    """Floating-point operations per lane.

    mul, add: every multiply and every add/sub, fused or not, as the lecture's table counts
        them; fma: how many of those (mul, add) pairs the code fused itself (addcmul,
        a + alpha * b, lerp). A mad is one mul plus one add issued as one instruction.
    div: divisions and reciprocals. sqrt: square roots and reciprocal square roots.
    compare: comparisons, min/max, each clamp bound. select: where / masked_fill.
    abs: absolute values. other: any other floating-point op (exp, floor, ...), one per
        output element. Negation is free: GPUs fold a sign flip into the next instruction.
    lanes: how many lanes the totals were divided by (not part of equality).
    """

    mul: float = 0.0
    add: float = 0.0
    div: float = 0.0
    sqrt: float = 0.0
    fma: float = 0.0
    compare: float = 0.0
    abs: float = 0.0
    select: float = 0.0
    other: float = 0.0
    lanes: int = field(default=1, compare=False)

    def cycles_bound(self) -> float:
        """The lecture's lower bound ``4 * (N_mul + |N_add - N_mul|)`` cycles per warp.

        A mad issues a mul and an add in 4 cycles, so the min(N_mul, N_add) pairs fuse and
        the |N_add - N_mul| left over issue alone. (The lecture writes N_mul for the pairs:
        its tests all have N_mul <= N_add.) Division, sqrt and compares are not included.
        """
        return MAD_CYCLES * (min(self.mul, self.add) + abs(self.add - self.mul))

    def cycles_range(self) -> tuple[float, float]:
        """The lecture's G80 cycle range: (every mul/add pair fused, only explicit fmas fused).

        Both ends add 36 cycles per division and 32 per square root:
        plane + area 248-404, Moller-Trumbore 132-224, Woop 116-196.
        """
        slow_ops = DIV_CYCLES * self.div + SQRT_CYCLES * self.sqrt
        unfused = MAD_CYCLES * (self.mul + self.add - self.fma)
        return self.cycles_bound() + slow_ops, unfused + slow_ops

    def as_row(self) -> dict[str, float | str]:
        """Lecture-style columns for a table row."""
        low, high = self.cycles_range()
        return {
            "mul": self.mul,
            "add/sub": self.add,
            "fma": self.fma,
            "div": self.div,
            "sqrt": self.sqrt,
            "compare": self.compare,
            "abs": self.abs,
            "select": self.select,
            "other": self.other,
            "cycles >=": self.cycles_bound(),
            "G80 cycles": f"{_fmt(low)}-{_fmt(high)}",
        }

    @staticmethod
    def table(named: Mapping[str, OpCounts]) -> str:
        """A markdown table with one row per named count (e.g. LECTURE_COUNTS and yours)."""
        rows = {name: counts.as_row() for name, counts in named.items()}
        columns = list(OpCounts().as_row())
        lines = [
            "| variant | " + " | ".join(columns) + " |",
            "|---" * (len(columns) + 1) + "|",
        ]
        for name, row in rows.items():
            cells = [row[c] if isinstance(row[c], str) else _fmt(row[c]) for c in columns]
            lines.append(f"| {name} | " + " | ".join(cells) + " |")
        return "\n".join(lines)


LECTURE_COUNTS: dict[str, OpCounts] = {
    "plane + area": OpCounts(mul=39, add=53, div=1),
    "Moller-Trumbore": OpCounts(mul=23, add=24, div=1),
    "Woop unit triangle": OpCounts(mul=20, add=20, div=1),
}


@dataclass(frozen=True)
class LiveEstimate:
    """How many values per lane a function keeps alive at once: a register-pressure estimate.

    peak: the most values per lane alive at once, as Python keeps them: arguments for the
        whole call, a named intermediate until it is deleted or the function returns. An op's
        result is counted once its operands that die right after it are gone, as a compiler
        writes a result into a dying operand's register. This is also the eager kernel's
        peak memory per lane, in elements.
    peak_after: index into `ops` of the op after which the peak was reached (-1: the inputs).
    peak_last_use: the same count when every value dies at its last use, as a register
        allocator frees it: closer to what a fused kernel needs, and independent of how the
        Python code names or deletes its temporaries.
    inputs: values per lane of the tensor arguments (a ray 6, a triangle 9).
    timeline: values per lane alive after each op (entry 0: before the first; last: after
        the function returned).
    ops: the aten ops run, in order.
    lane_shape: the lanes the values are counted per.

    The lecture's budget for the intersection kernel is 23 registers; a compiler also
    reorders work and keeps constants in instructions, so treat both peaks as estimates.
    """

    peak: float
    peak_after: int
    peak_last_use: float
    inputs: float
    timeline: tuple[float, ...]
    ops: tuple[str, ...]
    lane_shape: tuple[int, ...]


def count_ops(fn: Callable[..., Any], *args: Any, lanes: Lanes = None, **kwargs: Any) -> OpCounts:
    """Floating-point operations per lane of ``fn(*args, **kwargs)``.

    lanes: the number of lanes (ray-triangle pairs), as an int or a shape. Default: the shape
        of the largest tensor fn returns, since a kernel returns one result per lane (t of
        shape (N, M)). Pass it when the result holds several values per lane: a cross
        product of (N, 3) vectors has N lanes.

    Every op adds its total count divided by the number of lanes, so work on smaller tensors
    is amortised: edges computed once per triangle, on (M, 3), cost 3 / N subtractions per
    (N, M) lane. Reductions count k - 1 adds per sum of k values; matmul, einsum and dot
    count k multiplies and k - 1 adds per output; torch.linalg.cross 6 mul and 3 sub per
    vector. Dividing by a Python number counts as a multiply (by its reciprocal). Ops on
    integer or boolean tensors (indices, masks) and data movement (views, indexing, cat,
    stack, copies, dtype casts) cost nothing, except `where`, counted as a select whatever
    its dtype.
    """
    counter = _OpCounter()
    with counter:
        result = fn(*args, **kwargs)
    n = math.prod(_lane_shape(lanes, result))
    return OpCounts(**{name: total / n for name, total in counter.totals.items()}, lanes=n)


def live_values(
    fn: Callable[..., Any], *args: Any, lanes: Lanes = None, **kwargs: Any
) -> LiveEstimate:
    """Values per lane alive at once while ``fn(*args, **kwargs)`` runs (see LiveEstimate).

    lanes: the lane shape, e.g. (N, M) for N rays against M triangles; an int means (lanes,).
        Default: the shape of the largest tensor fn returns.

    A tensor's values per lane are those of its trailing dims: with lanes (N, M), origins
    (N, 3) or (N, 1, 3) hold 3 per lane, vertices (M, 3, 3) hold 9, t (N, M) holds 1. Leading
    dims are matched to lane dims by size, so pick N and M different from each other and
    from the vector sizes (3, 4). A view shares its base's values: slicing out a component
    adds nothing while the base is alive.
    """
    tracker = _LiveTracker(list(_tensors((args, kwargs))))
    with tracker:
        result = fn(*args, **kwargs)
    final = tracker.alive()
    lane_shape = _lane_shape(lanes, result)
    values = [tracker.values_per_lane(key, lane_shape) for key in range(len(tracker.born))]

    def total(keys: Iterable[int]) -> float:
        return float(sum(values[key] for key in keys))

    timeline = tuple(total(keys) for keys in [*tracker.alive_before, final])
    peak = max(timeline)
    returned = {tracker.key(t) for t in _tensors(result)} - {None}
    return LiveEstimate(
        peak=peak,
        peak_after=timeline.index(peak) - 1,
        peak_last_use=max(total(keys) for keys in _live_until_last_use(tracker, returned)),
        inputs=total(key for key, born in enumerate(tracker.born) if born < 0),
        timeline=timeline,
        ops=tuple(tracker.ops),
        lane_shape=lane_shape,
    )


# --- what each aten op costs -------------------------------------------------------------

# Per output element, for elementwise ops.
_ELEMENTWISE: dict[str, dict[str, int]] = {
    "mul": {"mul": 1},
    "add": {"add": 1},
    "sub": {"add": 1},
    "rsub": {"add": 1},
    "div": {"div": 1},
    "reciprocal": {"div": 1},
    "sqrt": {"sqrt": 1},
    "rsqrt": {"sqrt": 1},
    "addcmul": {"mul": 1, "add": 1, "fma": 1},
    "addcdiv": {"div": 1, "add": 1},
    "lerp": {"mul": 1, "add": 2, "fma": 1},  # a + w * (b - a)
    "linalg_cross": {"mul": 2, "add": 1},  # per component: a_y * b_z - a_z * b_y
    "abs": {"abs": 1},
    "neg": {},  # a sign flip rides on the next instruction's operand
    **{
        name: {"compare": 1}
        for name in (
            "lt", "le", "gt", "ge", "eq", "ne", "minimum", "maximum", "fmin", "fmax",
            "clamp_min", "clamp_max", "relu", "isnan", "isinf", "isfinite", "signbit",
        )
    },
}  # fmt: skip

# Ops with a scalar factor (a + alpha * b): a factor other than 1 is one more mul, fused.
_SCALE_ARGUMENT = {"add": "alpha", "sub": "alpha", "rsub": "alpha", "addcmul": "value",
                   "addcdiv": "value"}  # fmt: skip

# pow(x, p) for the exponents a compiler turns into cheaper instructions.
_POWERS: dict[float, dict[str, int]] = {
    1: {}, 2: {"mul": 1}, 0.5: {"sqrt": 1}, -0.5: {"sqrt": 1}, -1: {"div": 1},
}  # fmt: skip

# Per input element reduced away (a sum of k values is k - 1 adds).
_REDUCTIONS = {"sum": "add", "mean": "add", "prod": "mul", "amax": "compare",
               "amin": "compare", "max": "compare", "min": "compare", "argmax": "compare",
               "argmin": "compare"}  # fmt: skip

# Matrix products: (the argument holding the left matrix, whose last dim k is contracted
# with k mul and k - 1 add per output; adds for a bias, as the add* forms add one).
_CONTRACTIONS = {"mm": (0, 0), "bmm": (0, 0), "mv": (0, 0), "dot": (0, 0), "vdot": (0, 0),
                 "addmm": (1, 1), "addmv": (1, 1), "baddbmm": (1, 1)}  # fmt: skip

_SELECTS = {"where", "masked_fill"}

_DATA_MOVEMENT = frozenset({
    "clone", "copy", "_to_copy", "_unsafe_view", "cat", "stack", "index", "index_select",
    "gather", "take", "index_put", "scatter", "masked_select", "masked_scatter", "nonzero",
    "repeat", "flip", "roll", "constant_pad_nd", "lift_fresh", "lift_fresh_copy",
    "_local_scalar_dense", "empty", "empty_like", "empty_strided", "zeros", "zeros_like",
    "ones", "ones_like", "full", "full_like", "fill", "zero", "new_empty", "new_empty_strided",
    "new_zeros", "new_ones", "new_full", "scalar_tensor", "arange", "eye", "linspace",
    "resize", "set", "split_with_sizes_copy", "unbind_copy",
})  # fmt: skip


class _OpCounter(TorchDispatchMode):
    """Sums the operations of every aten op run under it (totals, not per lane)."""

    def __init__(self) -> None:
        super().__init__()
        self.totals: Counter[str] = Counter()

    def __torch_dispatch__(self, func, types, args=(), kwargs=None):
        kwargs = kwargs or {}
        out = func(*args, **kwargs)
        self.totals.update(_op_counts(func, args, kwargs, out))
        return out


def _op_counts(func, args, kwargs, out) -> Counter[str]:
    """Total operations of one aten call, by category."""
    name = _op_name(func)
    outputs = list(_tensors(out))
    if not outputs or func.is_view or name in _DATA_MOVEMENT:
        return Counter()
    n_out = outputs[0].numel()
    if name in _SELECTS:
        return Counter(select=n_out)
    if not any(_is_float(t) for t in [*_tensors((args, kwargs)), *outputs]):
        return Counter()
    per_element = _elementwise_counts(name, func, args, kwargs)
    if per_element is not None:
        return Counter({category: n * n_out for category, n in per_element.items()})
    if name in _REDUCTIONS or name == "linalg_vector_norm":
        return _reduction_counts(name, func, args, kwargs, n_out)
    if name in _CONTRACTIONS:
        matrix, bias = _CONTRACTIONS[name]
        k = args[matrix].shape[-1]
        return Counter(mul=k * n_out, add=(k - 1 + bias) * n_out)
    return Counter(other=n_out)


def _elementwise_counts(name, func, args, kwargs) -> dict[str, int] | None:
    """Operations per output element, or None if `name` is not elementwise."""
    if name == "mul" and any(_is_number(a) and a == 1 for a in args):
        return {}  # torch writes 1 / x as reciprocal(x) * 1
    if name == "div" and _is_number(args[1]):
        return {"mul": 1}  # x / c compiles to x * (1 / c)
    if name in ("max", "min") and func._overloadname == "other":
        return {"compare": 1}
    if name == "clamp":
        bounds = (_argument(func, args, kwargs, "min"), _argument(func, args, kwargs, "max"))
        return {"compare": sum(bound is not None for bound in bounds)}
    if name == "pow":
        exponent = _argument(func, args, kwargs, "exponent")
        return _POWERS.get(exponent, {"other": 1}) if _is_number(exponent) else {"other": 1}
    if name not in _ELEMENTWISE:
        return None
    counts = dict(_ELEMENTWISE[name])
    factor = _argument(func, args, kwargs, _SCALE_ARGUMENT.get(name, ""))
    if _is_number(factor) and factor != 1:
        counts["mul"] = counts.get("mul", 0) + 1
        counts["fma"] = 1
    return counts


def _reduction_counts(name, func, args, kwargs, n_out) -> Counter[str]:
    reduced = args[0].numel() - n_out
    if name == "linalg_vector_norm":
        if _argument(func, args, kwargs, "ord", 2) != 2:
            return Counter(other=n_out)
        return Counter(mul=args[0].numel(), add=reduced, sqrt=n_out)
    counts = Counter({_REDUCTIONS[name]: reduced})
    if name == "mean":
        counts["div"] += n_out
    return counts


# --- which values are alive ----------------------------------------------------------------


class _LiveTracker(TorchDispatchMode):
    """Follows the storages a function allocates, reads and frees.

    A storage (not a tensor) is the unit: views share their base's values, and a base
    stays alive while any view of it does. Each storage gets a key in allocation order;
    a weakref callback marks it dead when torch frees it.
    """

    def __init__(self, inputs: list[torch.Tensor]) -> None:
        super().__init__()
        self.ops: list[str] = []
        self.born: list[int] = []  # by key: the op that allocated it (-1: an input)
        self.layout: list[tuple[torch.Size, tuple[int, ...], int]] = []  # shape, stride, numel
        self.reads: list[set[int]] = []  # by op: the keys it reads
        self.alive_before: list[frozenset[int]] = []  # by op: the keys alive when it starts
        self._dead: set[int] = set()
        self._key_of: dict[int, int] = {}  # id(storage) -> key, while it lives
        self._refs: list[weakref.ref] = []
        for tensor in inputs:
            self._track(tensor)

    def __torch_dispatch__(self, func, types, args=(), kwargs=None):
        kwargs = kwargs or {}
        self.alive_before.append(self.alive())
        self.reads.append({self.key(t) for t in _tensors((args, kwargs))} - {None})
        self.ops.append(func.overloadpacket.__name__)
        out = func(*args, **kwargs)
        for tensor in _tensors(out):
            self._track(tensor)
        return out

    def alive(self) -> frozenset[int]:
        return frozenset(key for key in range(len(self.born)) if key not in self._dead)

    def key(self, tensor: torch.Tensor) -> int | None:
        return self._key_of.get(id(tensor.untyped_storage()))

    def values_per_lane(self, key: int, lane_shape: tuple[int, ...]) -> float:
        """The storage's elements divided by the lanes its first tensor spans."""
        shape, stride, numel = self.layout[key]
        lane_dims = list(zip(shape, stride))[: _lane_dims(shape, lane_shape)]
        # Stride-0 dims are broadcast (expand): they span lanes without holding values.
        return numel / (math.prod(size for size, step in lane_dims if step) or 1)

    def _track(self, tensor: torch.Tensor) -> None:
        storage = tensor.untyped_storage()
        if id(storage) in self._key_of:
            return
        key = len(self.born)
        self._key_of[id(storage)] = key
        self.born.append(len(self.ops) - 1)
        self.layout.append(
            (tensor.shape, tensor.stride(), storage.nbytes() // tensor.element_size())
        )
        self._refs.append(weakref.ref(storage, functools.partial(self._free, key, id(storage))))

    def _free(self, key: int, storage_id: int, _ref: weakref.ref) -> None:
        self._dead.add(key)
        del self._key_of[storage_id]


def _lane_dims(shape: torch.Size, lane_shape: tuple[int, ...]) -> int:
    """How many leading dims of `shape` index lanes: each matches, in order, a lane dim of
    the same size (or is 1, broadcast); the dims after them are one lane's values."""
    remaining = iter(lane_shape)
    matched = 0
    for size in shape:
        if not any(size in (lane, 1) for lane in remaining):
            break
        matched += 1
    return matched


def _live_until_last_use(tracker: _LiveTracker, returned: set[int]) -> Iterator[frozenset[int]]:
    """The keys alive before each op and at the end, if each died right after its last read."""
    last_read = {key: op for op, keys in enumerate(tracker.reads) for key in keys}
    n_ops = len(tracker.ops)
    last_read.update({key: n_ops for key in returned})
    for state in range(n_ops + 1):
        yield frozenset(
            key for key, born in enumerate(tracker.born) if born < state <= last_read.get(key, -1)
        )


# --- helpers ---------------------------------------------------------------------------------


def _tensors(obj: Any) -> Iterator[torch.Tensor]:
    """The tensors in nested tuples, lists, dicts and dataclasses (Rays, Hits, ...)."""
    if isinstance(obj, torch.Tensor):
        yield obj
    elif dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        for f in dataclasses.fields(obj):
            yield from _tensors(getattr(obj, f.name))
    elif isinstance(obj, Mapping):
        for value in obj.values():
            yield from _tensors(value)
    elif isinstance(obj, (list, tuple)):
        for value in obj:
            yield from _tensors(value)


def _lane_shape(lanes: Lanes, result: Any) -> tuple[int, ...]:
    if lanes is None:
        tensors = list(_tensors(result))
        if not tensors:
            raise ValueError(
                "lanes: fn returned no tensor to take the lane shape from; pass lanes="
            )
        shape = tuple(max(tensors, key=torch.Tensor.numel).shape)
    else:
        shape = (lanes,) if isinstance(lanes, int) else tuple(lanes)
    if any(not isinstance(n, int) or n < 1 for n in shape):
        raise ValueError(f"lanes must be a positive int or a shape of positive ints, got {shape}")
    return shape


def _op_name(func) -> str:
    """The aten op's name, in-place variants (mul_) folded into their functional op."""
    name = func.overloadpacket.__name__
    return name[:-1] if name.endswith("_") and not name.endswith("__") else name


def _argument(func, args, kwargs, name: str, default: Any = None) -> Any:
    """An aten call's argument by schema name, wherever the dispatcher put it."""
    if name in kwargs:
        return kwargs[name]
    for index, argument in enumerate(func._schema.arguments):
        if argument.name == name:
            return args[index] if index < len(args) else default
    return default


def _is_float(tensor: torch.Tensor) -> bool:
    return tensor.is_floating_point() or tensor.is_complex()


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _fmt(value: float) -> str:
    return f"{round(value, 2):g}"
