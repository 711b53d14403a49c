"""Pareto plots of the speed/accuracy trade: the front of a table of measured settings, and
a student's points over the reference's (``rtcourse bench``). Object-oriented matplotlib: no
pyplot state, no GUI backend."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path


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


def pareto_plot(
    rows: Sequence[dict],
    x: str = "seconds",
    y: str = "error",
    label: str | None = None,
    path: str | Path | None = None,
    maximize_x: bool | None = None,
    group: str | None = None,
    log: bool = True,
    title: str | None = None,
):
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
        ax.scatter(
            [rows[i][x] for i in members],
            [rows[i][y] for i in members],
            label=None if group is None else f"{group}={value}",
            alpha=0.8,
        )
    front = pareto_front(rows, x, y, maximize_x)
    ax.plot(
        [rows[i][x] for i in front],
        [rows[i][y] for i in front],
        "k--",
        marker="o",
        markerfacecolor="none",
        markersize=11,
        label="Pareto front",
    )
    if label:
        for i in points:
            ax.annotate(
                str(rows[i].get(label, "")),
                (rows[i][x], rows[i][y]),
                textcoords="offset points",
                xytext=(4, 4),
                fontsize=8,
            )
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


def trade_plot(
    reference: Sequence[dict],
    yours: Sequence[dict],
    extra: Sequence[dict] = (),
    x: str = "seconds",
    y: str = "error",
    label: str = "setting",
    path: str | Path | None = None,
    title: str | None = None,
    yours_name: str = "yours",
    reference_name: str = "reference",
    ax=None,
):
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
        ax.scatter(
            [r[x] for r in reference],
            [r[y] for r in reference],
            color="0.55",
            s=30,
            label=reference_name,
            zorder=2,
        )
        front = [reference[i] for i in pareto_front(reference, x, y)]
        ax.plot(
            [r[x] for r in front],
            [r[y] for r in front],
            "--",
            color="0.3",
            lw=1,
            label=f"{reference_name}: Pareto front",
            zorder=1,
        )
    if extra:
        ax.scatter(
            [r[x] for r in extra],
            [r[y] for r in extra],
            marker="^",
            color="0.35",
            s=40,
            label="fused kernels",
            zorder=2,
        )
    if yours:
        by_setting = {r.get(label): r for r in reference}
        for r in yours:
            twin = by_setting.get(r.get(label))
            if twin is not None:
                ax.plot(
                    [twin[x], r[x]],
                    [twin[y], r[y]],
                    "-",
                    color="tab:red",
                    lw=0.6,
                    alpha=0.5,
                    zorder=1,
                )
        ax.scatter(
            [r[x] for r in yours],
            [r[y] for r in yours],
            marker="*",
            s=110,
            color="tab:red",
            label=yours_name,
            zorder=3,
        )
    # Labels on your points where they are few, else on the reference's front only: twenty
    # labels on top of each other are read by nobody.
    named = (
        yours
        if 0 < len(yours) <= 12
        else [reference[i] for i in pareto_front(reference, x, y)]
        if reference
        else yours
    )
    for r in named:
        ax.annotate(
            str(r.get(label, "")),
            (r[x], r[y]),
            textcoords="offset points",
            xytext=(4, 3),
            fontsize=7,
        )
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
