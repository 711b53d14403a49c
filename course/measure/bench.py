"""Measuring the speed/accuracy trade: timing, result tables and Pareto plots.

On CUDA, kernels run asynchronously: wall-clock timing around a launch measures the launch,
not the work. ``time_fn`` therefore uses CUDA events recorded on the stream after a warm-up
and a synchronize, and ``time.perf_counter`` on the CPU. Report the median: it ignores the
occasional slow run caused by another process, a page fault or a cold cache.
"""

from __future__ import annotations

import dataclasses
import datetime
import json
import math
import os
import platform
import re
import shlex
import statistics
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import torch

from course.core.device import default_device


@dataclass(frozen=True)
class Timing:
    """Seconds per call of one timed function, over ``repeats`` calls after a warm-up."""

    median: float
    min: float
    max: float
    mean: float
    repeats: int
    device: str
    method: str  # "cuda-events", "cuda-graph" or "perf_counter"

    def __str__(self) -> str:
        return (f"{self.median * 1e3:.3f} ms (median of {self.repeats}, "
                f"min {self.min * 1e3:.3f} ms, {self.method} on {self.device})")


def _tensor_device(args: Sequence) -> torch.device | None:
    """The device of the first tensor among ``args`` or their dataclass fields (Rays, Mesh)."""
    for arg in args:
        values = ([getattr(arg, f.name) for f in dataclasses.fields(arg)]
                  if dataclasses.is_dataclass(arg) else [arg])
        for value in values:
            if isinstance(value, torch.Tensor):
                return value.device
    return None


def time_fn(fn: Callable, *args, repeats: int = 20, warmup: int = 3,
            device: str | torch.device | None = None, **kwargs) -> Timing:
    """Time ``fn(*args, **kwargs)``; returns its per-call ``Timing`` in seconds.

    device: where ``fn`` runs; by default the device of the first tensor argument (looking
    inside dataclasses such as Rays), else ``default_device()``. Warm-up calls absorb
    one-time costs (allocator growth, autotuning, ``torch.compile``).
    """
    if repeats < 1:
        raise ValueError(f"repeats: expected at least 1, got {repeats}")
    if warmup < 0:
        raise ValueError(f"warmup: expected 0 or more, got {warmup}")
    if device is None:
        device = _tensor_device([*args, *kwargs.values()])
    device = default_device(device)
    for _ in range(warmup):
        fn(*args, **kwargs)
    if device.type == "cuda":
        seconds, method = _time_cuda(fn, args, kwargs, repeats, device), "cuda-events"
    else:
        seconds, method = _time_cpu(fn, args, kwargs, repeats), "perf_counter"
    return Timing(median=statistics.median(seconds), min=min(seconds), max=max(seconds),
                  mean=statistics.fmean(seconds), repeats=repeats, device=str(device),
                  method=method)


def _time_cuda(fn, args, kwargs, repeats: int, device: torch.device) -> list[float]:
    starts = [torch.cuda.Event(enable_timing=True) for _ in range(repeats)]
    ends = [torch.cuda.Event(enable_timing=True) for _ in range(repeats)]
    torch.cuda.synchronize(device)  # the warm-up's queued work must not land in the first run
    with torch.cuda.device(device):
        for start, end in zip(starts, ends):
            start.record()
            fn(*args, **kwargs)
            end.record()
    torch.cuda.synchronize(device)
    return [start.elapsed_time(end) / 1e3 for start, end in zip(starts, ends)]


def time_replayed(fn: Callable, *args, calls: int = 10, repeats: int = 20, warmup: int = 3,
                  **kwargs) -> Timing:
    """The device time of ``fn(*args, **kwargs)`` alone: on CUDA, ``calls`` calls captured
    in one CUDA graph, replayed ``repeats`` times between events (seconds per call, method
    ``"cuda-graph"``); on the CPU, :func:`time_fn`.

    :func:`time_fn` times a call from the host's side: when its Python (argument checks, a
    launcher binding arguments) takes longer than the device's work, the events measure
    the host. A replayed graph runs the same kernels with no host in between, so this is
    what the kernels cost, the figure to compare kernels by; both together say how much a
    call's host time adds. ``fn`` must be capturable: no host sync, no CPU tensors read
    (its warm-up calls, on a side stream, compile what it compiles).
    """
    if calls < 1 or repeats < 1:
        raise ValueError(f"calls, repeats: expected at least 1 each, got {calls}, {repeats}")
    device = default_device(_tensor_device([*args, *kwargs.values()]))
    if device.type != "cuda":
        return time_fn(fn, *args, repeats=repeats, warmup=warmup, device=device, **kwargs)
    with torch.cuda.device(device):
        side = torch.cuda.Stream()
        side.wait_stream(torch.cuda.current_stream())
        with torch.cuda.stream(side):
            for _ in range(max(1, warmup)):
                fn(*args, **kwargs)
        torch.cuda.current_stream().wait_stream(side)
        graph = torch.cuda.CUDAGraph()
        with torch.cuda.graph(graph):
            for _ in range(calls):
                fn(*args, **kwargs)
        graph.replay()  # the first replay uploads the graph
        torch.cuda.synchronize(device)
        seconds = []
        for _ in range(repeats):
            start, end = torch.cuda.Event(enable_timing=True), torch.cuda.Event(enable_timing=True)
            start.record()
            graph.replay()
            end.record()
            end.synchronize()
            seconds.append(start.elapsed_time(end) / 1e3 / calls)
    return Timing(median=statistics.median(seconds), min=min(seconds), max=max(seconds),
                  mean=statistics.fmean(seconds), repeats=repeats, device=str(device),
                  method="cuda-graph")


def _time_cpu(fn, args, kwargs, repeats: int) -> list[float]:
    seconds = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn(*args, **kwargs)
        seconds.append(time.perf_counter() - start)
    return seconds


def device_name(device: str | torch.device | None = None) -> str:
    """A filesystem-safe name for ``device``: ``"nvidia-h100-80gb-hbm3"``, ``"cpu-8cores"``.

    Used as the folder of recorded results (``bench/results/<device_name>/``).
    """
    device = default_device(device)
    if device.type == "cuda":
        return re.sub(r"[^a-z0-9]+", "-", torch.cuda.get_device_name(device).lower()).strip("-")
    return f"cpu-{os.cpu_count()}cores"


def _device_description(device: torch.device) -> str:
    if device.type == "cuda":
        return torch.cuda.get_device_name(device)
    return f"{platform.processor() or platform.machine()} ({os.cpu_count()} cores)"


def _plain(value):
    """A JSON-ready version of a cell: tensors and numpy scalars become Python numbers."""
    if hasattr(value, "tolist"):  # tensors, numpy arrays and numpy scalars
        return value.tolist()
    if isinstance(value, (torch.dtype, torch.device, Path)):
        return str(value)
    return value


class ResultTable:
    """Rows of one benchmark: each a dict of knob settings, seconds, throughput and errors.

    >>> table = ResultTable("lab1 intersection")
    >>> table.add(variant="moller_trumbore", dtype="float32", seconds=0.01, max_error=1e-6)
    >>> table.to_json("bench/results/cpu-8cores/lab1.json")
    """

    def __init__(self, name: str = "", device: str | torch.device | None = None,
                 metadata: dict | None = None, rows: list[dict] | None = None,
                 total: int | None = None):
        self.name = name
        self.metadata = metadata if metadata is not None else self._collect_metadata(device)
        self.rows: list[dict] = list(rows or [])
        self.total = total  # rows the benchmark will measure (for its progress bar)
        self._bar = None

    @staticmethod
    def _collect_metadata(device) -> dict:
        device = default_device(device)
        return {"device": _device_description(device), "device_name": device_name(device),
                "torch": torch.__version__, "python": platform.python_version(),
                "command": shlex.join(sys.argv),
                "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")}

    def add(self, **row) -> dict:
        """Append one row, e.g. ``add(variant="woop", seconds=t.median, max_error=e)``."""
        row = {key: _plain(value) for key, value in row.items()}
        self.rows.append(row)
        self._progress()
        return row

    def _progress(self):
        """Count measured rows on a progress bar (only on a terminal; see course.core.progress):
        a sweep shows it is alive, and with ``total`` how far it has come."""
        from course.core.progress import progress, progress_enabled

        if not progress_enabled():
            return
        if self._bar is None:
            self._bar = progress(total=self.total, desc=self.name or "bench", unit="row")
        self._bar.update(1)
        if self.total is not None and self._bar.n >= self.total:
            self._bar.close()

    def columns(self) -> list[str]:
        """Every key used by any row, in order of first appearance."""
        return list(dict.fromkeys(key for row in self.rows for key in row))

    def to_json(self, path: str | Path) -> Path:
        """Write ``{"name", "metadata", "rows"}`` to ``path`` (folders are created)."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps({"name": self.name, "metadata": self.metadata,
                                    "rows": self.rows}, indent=2) + "\n")
        return path

    @classmethod
    def from_json(cls, path: str | Path) -> ResultTable:
        data = json.loads(Path(path).read_text())
        return cls(data["name"], metadata=data["metadata"], rows=data["rows"])

    def to_markdown(self) -> str:
        """A GitHub-flavoured Markdown table; floats with 4 significant digits."""
        columns = self.columns()
        lines = ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
        lines += ["| " + " | ".join(_cell(row.get(c)) for c in columns) + " |" for row in self.rows]
        return "\n".join(lines)


def _cell(value) -> str:
    if value is None:
        return ""
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value)


def pareto_front(rows: Sequence[dict], x: str, y: str, maximize_x: bool = False) -> list[int]:
    """Indices of the rows no other row beats on both ``x`` and ``y`` (lower ``y`` is better).

    Rows lacking a finite ``x`` or ``y`` are ignored. Returned in order of improving x.
    """
    usable = [i for i, row in enumerate(rows) if _finite(row.get(x)) and _finite(row.get(y))]
    sign = -1.0 if maximize_x else 1.0
    # Sweep from the best x to the worst: a row is on the front iff its y beats all before it.
    order = sorted(usable, key=lambda i: (sign * rows[i][x], rows[i][y]))
    front, best_y = [], math.inf
    for i in order:
        if rows[i][y] < best_y:
            front.append(i)
            best_y = rows[i][y]
    return front


def _finite(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _is_throughput(key: str) -> bool:
    return any(part in key for part in ("per_s", "/s", "throughput"))


def pareto_plot(rows: Sequence[dict], x: str = "seconds", y: str = "error",
                label: str | None = None, path: str | Path | None = None,
                maximize_x: bool | None = None, group: str | None = None,
                log: bool = True, title: str | None = None):
    """Scatter ``y`` (an error, lower is better) against ``x`` (cost or throughput) and mark
    the Pareto front: the settings worth choosing. Returns the matplotlib Figure.

    label: key whose value annotates each point (e.g. ``"setting"``);
    group: key whose values get one colour each (e.g. ``"variant"``);
    maximize_x: whether higher ``x`` is better; by default True for keys that look like a
    throughput (``"rays_per_s"``, ``"throughput"``) and False for times;
    log: log axes (symmetric-log where a column holds zeros, e.g. an exact setting's error);
    path: where to save the figure (PNG, SVG or PDF by suffix).
    """
    from matplotlib.figure import Figure  # object-oriented: no pyplot state, no GUI backend

    maximize_x = _is_throughput(x) if maximize_x is None else maximize_x
    points = [i for i, row in enumerate(rows) if _finite(row.get(x)) and _finite(row.get(y))]
    if not points:
        raise ValueError(f"rows: no row has finite values for both x={x!r} and y={y!r}")
    fig = Figure(figsize=(6.4, 4.8), layout="constrained")
    ax = fig.add_subplot()
    groups = dict.fromkeys(rows[i].get(group) for i in points) if group else {None: None}
    for value in groups:
        members = [i for i in points if group is None or rows[i].get(group) == value]
        ax.scatter([rows[i][x] for i in members], [rows[i][y] for i in members],
                   label=None if group is None else f"{group}={value}", alpha=0.8)
    front = pareto_front(rows, x, y, maximize_x)
    ax.plot([rows[i][x] for i in front], [rows[i][y] for i in front], "k--", marker="o",
            markerfacecolor="none", markersize=11, label="Pareto front")
    if label:
        for i in points:
            ax.annotate(str(rows[i].get(label, "")), (rows[i][x], rows[i][y]),
                        textcoords="offset points", xytext=(4, 4), fontsize=8)
    if log:
        _log_scale(ax.set_xscale, [rows[i][x] for i in points])
        _log_scale(ax.set_yscale, [rows[i][y] for i in points])
    ax.set_xlabel(f"{x} ({'higher' if maximize_x else 'lower'} is better)")
    ax.set_ylabel(f"{y} (lower is better)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    if title:
        ax.set_title(title)
    if path is not None:
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(path, dpi=150)
    return fig


def _log_scale(set_scale, values: list[float]) -> None:
    """Log scale, or symmetric log when some values are <= 0 (a log axis would drop them)."""
    positive = [abs(v) for v in values if v != 0]
    if all(v > 0 for v in values):
        set_scale("log")
    elif positive:
        set_scale("symlog", linthresh=min(positive))


def add_impl_option(parser) -> None:
    """The ``--impl`` option of a bench script: which implementation of the labs it measures
    (:func:`load_lab`'s ``impl``; the default, ``RTCOURSE_IMPL`` or else solutions/ where it
    exists and labs/ in the student handout, is what the grader runs too)."""
    parser.add_argument("--impl", default=os.environ.get("RTCOURSE_IMPL") or None,
                        help="the labs measured: labs (yours), solutions (the references, "
                             "in the course repository) or a folder of lab files (default: "
                             "solutions where present, else labs)")


def load_lab(name: str, impl: str | None = None, root=None):
    """A lab module for benchmarks, demos and notebooks.

    ``name`` is a module name (``"lab1_intersect"``) or a lab prefix (``"lab1"``);
    ``impl`` is ``solutions`` (the default where it exists), ``labs`` (the default in
    the student handout) or a folder holding lab files (see
    :func:`course.core.labs.implementation_folder`); ``root``: the course folder (default:
    the one the current folder lies in; a bench script passes its own). Trusted code only:
    this imports the module into the calling process. FileNotFoundError names a missing
    folder or lab.
    """
    from course.core.labs import load_lab as load

    return load(name, impl, root)


# ------------------------------------------------------------------ your point on the plot

CALIBRATION = "float32 Möller–Trumbore brute force, 2048 rays x 256 triangles (torch)"


def _calibration_batch(device: torch.device):
    """The fixed workload of :func:`calibration_seconds`: rays from a sphere of radius 2
    aimed into a random soup of small triangles in the unit cube, seeded (every machine
    does the same arithmetic)."""
    g = torch.Generator().manual_seed(7)
    centre = torch.rand(256, 1, 3, generator=g)
    corners = (centre + 0.2 * (torch.rand(256, 3, 3, generator=g) - 0.5)).to(device)
    out = torch.randn(2048, 3, generator=g)
    origins = 0.5 + 2.0 * out / out.norm(dim=1, keepdim=True)
    directions = torch.rand(2048, 3, generator=g) - origins
    return origins.to(device), directions.to(device), corners


def _calibration_work(origins, directions, corners) -> torch.Tensor:
    from course.core.raymath import cross, dot

    o, d = origins[:, None], directions[:, None]
    v0, e1, e2 = corners[None, :, 0], corners[None, :, 1] - corners[None, :, 0], \
        corners[None, :, 2] - corners[None, :, 0]
    p = cross(d, e2)
    det = dot(e1, p)
    inv = 1.0 / det
    s = o - v0
    u = dot(s, p) * inv
    q = cross(s, e1)
    v = dot(d, q) * inv
    t = dot(e2, q) * inv
    hit = (det.abs() > 1e-12) & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)
    return torch.where(hit, t, torch.inf).amin(1)


def calibration_seconds(device: str | torch.device | None = None, repeats: int = 7) -> float:
    """Seconds per call of a fixed workload (:data:`CALIBRATION`) on ``device``, timed as
    every row of a bench is (:func:`time_fn`, median).

    What it is for: reference times measured on another machine (the rows the student
    handout ships in ``bench/reference/``) are scaled by the ratio of this machine's
    calibration to theirs, so a ratio to the reference compares like with like. The scale
    is approximate: it holds for work limited by the same arithmetic and memory as the
    workload (batched tensor kernels), less for work dominated by Python or launches.
    """
    device = default_device(device)
    batch = _calibration_batch(device)
    return time_fn(_calibration_work, *batch, repeats=repeats, warmup=2, device=device).median


def write_rows_csv(rows: Sequence[dict], path: str | Path) -> Path:
    """Every row as one line of a CSV with the union of the rows' keys as its header (a key
    a row lacks is an empty cell; floats keep their full precision)."""
    import csv

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    columns = list(dict.fromkeys(key for row in rows for key in row))
    with path.open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=columns)
        writer.writeheader()
        for row in rows:
            writer.writerow({k: "" if row.get(k) is None else _plain(row[k]) for k in columns})
    return path


def _parse_cell(text: str):
    if text == "":
        return None
    if text in ("True", "False"):
        return text == "True"
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def read_rows_csv(path: str | Path) -> list[dict]:
    """The rows :func:`write_rows_csv` wrote: numbers and booleans parsed, empty cells
    left out of their row."""
    import csv

    with Path(path).open(newline="") as f:
        return [{k: v for k, v in ((k, _parse_cell(v)) for k, v in row.items()) if v is not None}
                for row in csv.DictReader(f)]


def trade_plot(reference: Sequence[dict], yours: Sequence[dict], extra: Sequence[dict] = (),
               x: str = "seconds", y: str = "error", label: str = "setting",
               path: str | Path | None = None, title: str | None = None,
               yours_name: str = "yours", reference_name: str = "reference", ax=None):
    """Your points over the reference's: the reference's rows in grey with their Pareto front
    (dashed), ``extra`` rows (fused kernels) as grey triangles, and yours as red stars,
    each labelled with its ``label`` and joined to the reference's point of the same
    setting by a thin line (where the two differ, the line shows by how much and which
    way). Log axes (symmetric-log where a column holds zeros: exact settings). Draws into
    ``ax`` (a matplotlib Axes) when given, else into a new Figure; returns the Figure,
    saved to ``path`` when given."""
    from matplotlib.figure import Figure

    def usable(rows):
        return [r for r in rows if _finite(r.get(x)) and _finite(r.get(y))]

    reference, yours, extra = usable(reference), usable(yours), usable(extra)
    everything = reference + yours + extra
    if not everything:
        raise ValueError(f"rows: no row has finite values for both x={x!r} and y={y!r}")
    if ax is None:
        fig = Figure(figsize=(7.2, 5.0), layout="constrained")
        ax = fig.add_subplot()
    fig = ax.figure
    if reference:
        ax.scatter([r[x] for r in reference], [r[y] for r in reference], color="0.55", s=30,
                   label=reference_name, zorder=2)
        front = [reference[i] for i in pareto_front(reference, x, y)]
        ax.plot([r[x] for r in front], [r[y] for r in front], "--", color="0.3", lw=1,
                label=f"{reference_name}: Pareto front", zorder=1)
    if extra:
        ax.scatter([r[x] for r in extra], [r[y] for r in extra], marker="^", color="0.35",
                   s=40, label="fused kernels", zorder=2)
    if yours:
        by_setting = {r.get(label): r for r in reference}
        for r in yours:
            twin = by_setting.get(r.get(label))
            if twin is not None:
                ax.plot([twin[x], r[x]], [twin[y], r[y]], "-", color="tab:red", lw=0.6,
                        alpha=0.5, zorder=1)
        ax.scatter([r[x] for r in yours], [r[y] for r in yours], marker="*", s=110,
                   color="tab:red", label=yours_name, zorder=3)
    # Labels on your points where they are few, else on the reference's front only: twenty
    # labels on top of each other are read by nobody.
    named = yours if 0 < len(yours) <= 12 else \
        [reference[i] for i in pareto_front(reference, x, y)] if reference else yours
    for r in named:
        ax.annotate(str(r.get(label, "")), (r[x], r[y]), textcoords="offset points",
                    xytext=(4, 3), fontsize=7)
    _log_scale(ax.set_xscale, [r[x] for r in everything])
    _log_scale(ax.set_yscale, [r[y] for r in everything])
    if min(r[y] for r in everything) >= 0:  # errors: a symlog axis need not show negatives
        ax.set_ylim(bottom=0 if ax.get_yscale() == "symlog" else None)
    ax.set_xlabel(f"{x} (lower is better)")
    ax.set_ylabel(f"{y} (lower is better)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    if title:
        ax.set_title(title, fontsize=10)
    if path is not None:
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(path, dpi=120)
    return fig
