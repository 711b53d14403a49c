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
from course.measure.plots import (  # re-exported: the benches import them from here
    pareto_front as pareto_front,
)
from course.measure.plots import (
    pareto_plot as pareto_plot,
)
from course.measure.plots import (
    trade_plot as trade_plot,
)


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
        return (
            f"{self.median * 1e3:.3f} ms (median of {self.repeats}, "
            f"min {self.min * 1e3:.3f} ms, {self.method} on {self.device})"
        )


def _tensor_device(args: Sequence) -> torch.device | None:
    """The device of the first tensor among ``args`` or their dataclass fields (Rays, Mesh)."""
    for arg in args:
        values = (
            [getattr(arg, f.name) for f in dataclasses.fields(arg)]
            if dataclasses.is_dataclass(arg)
            else [arg]
        )
        for value in values:
            if isinstance(value, torch.Tensor):
                return value.device
    return None


def time_fn(
    fn: Callable,
    *args,
    repeats: int = 20,
    warmup: int = 3,
    device: str | torch.device | None = None,
    **kwargs,
) -> Timing:
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
    return Timing(
        median=statistics.median(seconds),
        min=min(seconds),
        max=max(seconds),
        mean=statistics.fmean(seconds),
        repeats=repeats,
        device=str(device),
        method=method,
    )


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


def time_replayed(
    fn: Callable, *args, calls: int = 10, repeats: int = 20, warmup: int = 3, **kwargs
) -> Timing:
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
    return Timing(
        median=statistics.median(seconds),
        min=min(seconds),
        max=max(seconds),
        mean=statistics.fmean(seconds),
        repeats=repeats,
        device=str(device),
        method="cuda-graph",
    )


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

    def __init__(
        self,
        name: str = "",
        device: str | torch.device | None = None,
        metadata: dict | None = None,
        rows: list[dict] | None = None,
        total: int | None = None,
    ):
        self.name = name
        self.metadata = metadata if metadata is not None else self._collect_metadata(device)
        self.rows: list[dict] = list(rows or [])
        self.total = total  # rows the benchmark will measure (for its progress bar)
        self._bar = None

    @staticmethod
    def _collect_metadata(device) -> dict:
        device = default_device(device)
        return {
            "device": _device_description(device),
            "device_name": device_name(device),
            "torch": torch.__version__,
            "python": platform.python_version(),
            "command": shlex.join(sys.argv),
            "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        }

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
        path.write_text(
            json.dumps({"name": self.name, "metadata": self.metadata, "rows": self.rows}, indent=2)
            + "\n"
        )
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


def add_impl_option(parser) -> None:
    """The ``--impl`` option of a bench script: which implementation of the labs it measures
    (:func:`load_lab`'s ``impl``; the default, ``RTCOURSE_IMPL`` or else solutions/ where it
    exists and labs/ in the student handout, is what the grader runs too)."""
    parser.add_argument(
        "--impl",
        default=os.environ.get("RTCOURSE_IMPL") or None,
        help="the labs measured: labs (yours), solutions (the references, "
        "in the course repository) or a folder of lab files (default: "
        "solutions where present, else labs)",
    )


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
    v0, e1, e2 = (
        corners[None, :, 0],
        corners[None, :, 1] - corners[None, :, 0],
        corners[None, :, 2] - corners[None, :, 0],
    )
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
        return [
            {k: v for k, v in ((k, _parse_cell(v)) for k, v in row.items()) if v is not None}
            for row in csv.DictReader(f)
        ]
