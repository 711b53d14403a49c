"""Your point on the plot: every lab's knobs measured on your code and on the reference.

``rtcourse bench --lab N`` runs one lab's knobs (``labN.py`` of this package: the lab's
scenes, settings and error in one place, also used by the ``bench/labN_*.py`` scripts) on
an implementation (by default the student's ``labs/``) and on the reference in the same
run, and writes a CSV of every row, a Pareto plot with the student's points marked over the
reference's front, and a table of the student's time and error beside the reference's.

Error is always measured against the lab's exact or converged answer (float64 brute force,
a closed form, a many-sample quadrature, the lab's brute-force reference renderer), never
against the reference at the same setting: a fast but wrong kernel shows as wrong.

Where the reference's rows come from:

* in the course repository, ``solutions/`` is measured in the same process, same run;
* in the student handout there is no ``solutions/``: ``rtcourse release`` measured the
  references with ``--quick`` on the CPU and shipped their rows as
  ``bench/reference/labN.csv``, each with the seconds of a fixed calibration workload
  (:func:`course.measure.bench.calibration_seconds`) on the machine that measured them.
  The student's run times the same workload and scales the shipped times by the ratio of
  the two, so the ratio to the reference compares like with like (approximately: see
  there). ``--quick`` on the CPU runs on one thread on both sides. The table's header and
  the CSV's ``seconds_source`` column say which it was.

On CUDA the fused kernels of ``course.kernels`` add rows of their own (``impl`` "fused")
where a lab has one.

A lab's trade module provides ``MODULE`` (the lab module's name), ``TITLE``, ``ERROR`` and
``ERROR_NAME`` (what its error column measures, in a sentence and in a few words),
``prepare(device, quick) -> ctx`` (scenes and exact answers, course code only),
``knobs(ctx) -> [dict]`` (each with a ``setting`` label), ``measure(lab, ctx, knob) ->
dict`` (``seconds``, ``error`` and any work counters) and optionally ``fused(ctx) ->
[dict]`` (rows of the fused kernels, CUDA).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path

REFERENCE_DIR = Path("bench") / "reference"  # the handout's shipped reference rows


LABS = tuple(range(7))  # every lab has a trade module here: labN.py


class NotWritten(RuntimeError):
    """The implementation measured has not written a function that every row needs."""


def trade_module(number: int):
    """The trade module of lab ``number`` (0 .. 6)."""
    import importlib

    if number not in LABS:
        raise ValueError(f"lab: expected one of {list(LABS)}, got {number!r}")
    return importlib.import_module(f"{__name__}.lab{number}")  # only the lab measured


@dataclass
class TradeResult:
    """What :func:`run` wrote and measured."""

    rows: list[dict]
    csv: Path
    png: Path | None
    table: str
    skipped: list[str] = field(default_factory=list)
    seconds: float = 0.0


def measure_rows(trade, lab, ctx: dict, impl: str, log=print, bar=None) -> tuple[list, list]:
    """Every knob of ``trade`` measured on the lab module ``lab``: ``(rows, skipped)``.
    A knob whose code raises NotImplementedError is skipped (its message in ``skipped``);
    any other exception makes a row with NaN time and error and the exception's name."""
    rows, skipped = [], []
    for knob in trade.knobs(ctx):
        try:
            measured = trade.measure(lab, ctx, knob)
        except NotImplementedError as exc:
            skipped.append(f"{knob['setting']}: {str(exc).splitlines()[0]}")
            measured = None
        except Exception as exc:  # noqa: BLE001  (the student's bug is a result, not a crash)
            log(
                f"  {impl} {knob['setting']}: failed: {type(exc).__name__}: "
                f"{str(exc).splitlines()[0][:120] if str(exc) else ''}"
            )
            measured = {"seconds": math.nan, "error": math.nan, "failed": f"{type(exc).__name__}"}
        if measured is not None:  # dataclass results (Lab 1's hits, for its script) stay out
            rows.append(
                {
                    "impl": impl,
                    **knob,
                    **{k: v for k, v in measured.items() if not hasattr(v, "__dataclass_fields__")},
                }
            )
        if bar is not None:
            bar.update(1)
    return rows, skipped


def _first_task(skipped: list[str]) -> str:
    return skipped[0].split(": ", 1)[1] if skipped else "nothing measured"


def run(
    number: int,
    impl: str | None = None,
    device=None,
    quick: bool = False,
    out=None,
    root=None,
    log=print,
    reference: bool = True,
) -> TradeResult:
    """Measure lab ``number``'s knobs on ``impl`` (default ``labs``: the student's code) and
    on the reference; write ``labN.csv`` and ``labN.png`` into ``out`` (default
    ``out/bench/labN`` of the course) and return what was measured.

    Raises :class:`NotWritten` (one line naming the first unwritten task) when no row of
    ``impl`` could be measured because its functions raise NotImplementedError.
    ``reference``: False measures ``impl`` alone (the release's reference rows).
    """
    import torch

    from course.core.device import default_device, set_cpu_threads
    from course.core.files import repo_root

    started = time.perf_counter()
    trade = trade_module(number)
    root = Path(repo_root() if root is None else root)
    device = default_device(device)
    out = Path(out) if out is not None else root / "out" / "bench" / f"lab{number}"
    # --quick on the CPU runs on one thread, as the shipped reference rows were measured:
    # its batches are too small to gain from more, and one core's speed is what the
    # calibration can compare between machines (a thread count would scale its large
    # batch and not the small ones). Full runs use the free cores.
    threads, previous = None, torch.get_num_threads()
    if device.type == "cpu":
        threads = set_cpu_threads(1 if quick else None)
    try:
        return _run(
            number,
            trade,
            root,
            device,
            quick,
            impl or "labs",
            out,
            log,
            reference,
            threads,
            started,
        )
    finally:
        torch.set_num_threads(previous)  # the caller's (a release, a notebook) as it was


def _run(number, trade, root, device, quick, impl, out, log, reference, threads, started):
    from course.core.labs import implementation_folder, load_lab
    from course.core.progress import progress
    from course.measure.bench import calibration_seconds, device_name, trade_plot, write_rows_csv

    folder = implementation_folder(root, impl)
    solutions = root / "solutions"
    is_reference = solutions.is_dir() and folder.resolve() == solutions.resolve()
    ctx = trade.prepare(device, quick)
    ctx.setdefault("device", device)
    ctx.setdefault("quick", quick)
    before = calibration_seconds(device)
    name = device_name(device)

    live_reference = reference and solutions.is_dir() and not is_reference
    knobs = len(trade.knobs(ctx))
    bar = progress(
        total=knobs * (2 if live_reference else 1), desc=f"lab {number} bench", unit="row"
    )
    try:
        student = load_lab(trade.MODULE, str(folder), root)
        label = "reference" if is_reference else "yours"
        yours, skipped = measure_rows(trade, student, ctx, label, log, bar)
        if not yours and skipped:
            raise NotWritten(
                f"{folder.name}/{trade.MODULE}: {_first_task(skipped)}; write it "
                f"to measure your trade (nothing else of lab {number} was "
                f"measured)"
            )
        # Calibrated before and after the rows: on a shared machine the load moves, and
        # the mean of the two follows it better than either.
        calibration = (before + calibration_seconds(device)) / 2
        common = {
            "lab": number,
            "device": name,
            "calibration_s": calibration,
            "cpu_threads": threads,
        }
        source = "measured in this run"
        ref_rows: list[dict] = []
        if is_reference:
            ref_rows, yours = yours, []
        elif live_reference:
            ref_rows, _ = measure_rows(
                trade, load_lab(trade.MODULE, "solutions", root), ctx, "reference", log, bar
            )
        elif reference:
            ref_rows, source = shipped_reference(root, number, calibration, device)
    finally:
        bar.close()
    fused = []
    if device.type == "cuda" and hasattr(trade, "fused"):
        try:
            fused = trade.fused(ctx)
        except Exception as exc:  # noqa: BLE001  (a Triton that cannot compile a kernel)
            log(
                f"  fused kernels of lab {number}: not measured: {type(exc).__name__}: "
                f"{str(exc).strip().splitlines()[-1][:160] if str(exc).strip() else ''}"
            )
    for row in fused:
        row.setdefault("impl", "fused")
    measured_source = "measured in this run"
    rows = (
        [
            dict(common, **r, implementation=str(folder), seconds_source=measured_source)
            for r in yours
        ]
        + [
            dict(common, **r) if "seconds_source" in r else dict(common, **r, seconds_source=source)
            for r in ref_rows
        ]
        + [dict(common, **r, seconds_source=measured_source) for r in fused]
    )
    for row in rows:
        row["error_metric"] = trade.ERROR_NAME
    csv = write_rows_csv(rows, out / f"lab{number}.csv")
    png = out / f"lab{number}.png"
    title = f"{trade.TITLE}\nerror: {trade.ERROR_NAME}; {name}, {'quick' if quick else 'full'}"
    try:
        trade_plot(
            ref_rows, yours, fused, path=png, title=title, yours_name=f"yours ({folder.name})"
        )
    except ValueError:  # no finite row at all (every row failed): the CSV says why
        png = None
    table = format_table(number, trade, yours, ref_rows, source, skipped, fused)
    return TradeResult(
        rows=rows,
        csv=csv,
        png=png,
        table=table,
        skipped=skipped,
        seconds=time.perf_counter() - started,
    )


def bench_rows(number: int, lab, device, quick: bool, out, log=print) -> list[dict]:
    """The rows of ``rtcourse bench --lab N`` measured on the lab module ``lab`` (a bench
    script's), written as ``trade.csv`` and plotted as ``pareto_trade.png`` into ``out``
    the way a student's plot is drawn, so the lecture's figure and the student's come from
    one measurement. Knobs ``lab`` has not written are skipped with the reason."""
    from course.measure.bench import trade_plot, write_rows_csv

    trade = trade_module(number)
    ctx = trade.prepare(device, quick)
    rows, skipped = measure_rows(trade, lab, ctx, "reference", log)
    for reason in skipped:
        log(f"  trade rows: skipped {reason}")
    if rows:
        out = Path(out)
        write_rows_csv([dict(r, error_metric=trade.ERROR_NAME) for r in rows], out / "trade.csv")
        trade_plot(
            rows,
            [],
            path=out / "pareto_trade.png",
            title=f"{trade.TITLE}\nerror: {trade.ERROR_NAME}",
        )
    return rows


def shipped_reference(
    root: Path, number: int, calibration: float, calibration_device="cpu"
) -> tuple[list, str]:
    """The handout's reference rows of lab ``number`` with their seconds scaled to this
    machine (``calibration``: this machine's calibration seconds), and the sentence saying
    so (``calibration_device``: where ``calibration`` was timed); ``([], why)`` where the
    handout has none."""
    from course.measure.bench import device_name, read_rows_csv

    path = Path(root) / REFERENCE_DIR / f"lab{number}.csv"
    if not path.is_file():
        return [], (
            f"no reference rows: {REFERENCE_DIR / path.name} is not in this handout "
            f"(rtcourse release ships it)"
        )
    rows = read_rows_csv(path)
    theirs = next((r["calibration_s"] for r in rows if r.get("calibration_s")), None)
    scale = calibration / theirs if theirs else 1.0
    where = rows[0].get("device", "?") if rows else "?"
    source = (
        f"shipped ({REFERENCE_DIR / path.name}, measured on {where}), times x{scale:.3g} "
        f"by calibration (this machine {calibration * 1e3:.3g} ms, theirs "
        f"{(theirs or math.nan) * 1e3:.3g} ms)"
    )
    here = device_name(calibration_device)
    if here.split("-")[0] != str(where).split("-")[0]:  # a GPU against CPU rows
        source += f"; you run on {here}, another kind of device: read the ratio as rough"
    scaled = []
    for row in rows:
        seconds = row.get("seconds")
        scaled.append(
            {
                **{
                    k: v
                    for k, v in row.items()
                    if k not in ("lab", "device", "calibration_s", "seconds_source")
                },
                "impl": "reference",
                "seconds_measured": seconds,
                "seconds": seconds * scale if isinstance(seconds, (int, float)) else seconds,
                "time_scale": scale,
                "reference_device": where,
                "reference_calibration_s": theirs,
                "seconds_source": source,
            }
        )
    return scaled, source


def _num(value, fmt: str) -> str:
    """A cell: the number, "nan"/"inf" for one that is not finite (a wrong result says so),
    "-" for none."""
    if not isinstance(value, (int, float)) or isinstance(value, bool):
        return format("-", f">{fmt.split('.')[0]}")
    return format(value, fmt)


def format_table(
    number: int, trade, yours: list, reference: list, source: str, skipped: list, fused: list = ()
) -> str:
    """The terminal table: per setting, your seconds and error beside the reference's, and
    your time as a multiple of the reference's (below 1: faster); the fused kernels' rows
    after them, timed in this run."""
    ref = {r["setting"]: r for r in reference}
    lines = [f"Lab {number}: {trade.TITLE}", f"error: {trade.ERROR}", f"reference times: {source}"]
    width = max([len(r["setting"]) for r in [*(yours or reference), *fused]] + [7])
    head = (
        f"{'setting':<{width}}  {'your s':>10}  {'ref s':>10}  {'ratio':>6}  "
        f"{'your error':>10}  {'ref error':>10}"
    )
    lines += ["", head, "-" * len(head)]
    for row in yours or reference:
        twin = ref.get(row["setting"], {})
        mine = row if yours else {}
        ratio = (
            mine.get("seconds", math.nan) / twin["seconds"]
            if yours and twin.get("seconds")
            else None
        )
        error = f"{'failed':>10}" if mine.get("failed") else _num(mine.get("error"), "10.3g")
        lines.append(
            f"{row['setting']:<{width}}  {_num(mine.get('seconds'), '10.3g')}  "
            f"{_num(twin.get('seconds'), '10.3g')}  {_num(ratio, '6.2f')}  "
            f"{error}  {_num(twin.get('error'), '10.3g')}"
        )
    for row in fused:
        lines.append(
            f"{row['setting']:<{width}}  {'':>10}  {_num(row.get('seconds'), '10.3g')}"
            f"  {'':>6}  {'':>10}  {_num(row.get('error'), '10.3g')}"
        )
    lines.append("ratio: your seconds / the reference's at the same setting (below 1: faster)")
    if skipped:
        lines.append(
            f"not measured ({len(skipped)}): "
            + "; ".join(skipped[:3])
            + (" ..." if len(skipped) > 3 else "")
        )
    return "\n".join(lines)


def write_reference_rows(root, out, labs=LABS, log=print) -> list[Path]:
    """Measure every lab's reference (``root/solutions``) with ``quick`` sizes on the CPU
    and write its rows to ``out/bench/reference/labN.csv`` (the release's step, for a
    handout that has no solutions/). Returns the files written, relative to ``out``."""
    root, out = Path(root), Path(out)
    written = []
    for number in labs:
        result = run(
            number,
            impl="solutions",
            device="cpu",
            quick=True,
            root=root,
            out=out / REFERENCE_DIR,
            log=log,
            reference=False,
        )
        (out / REFERENCE_DIR / f"lab{number}.png").unlink(missing_ok=True)
        written.append(REFERENCE_DIR / result.csv.name)
        log(f"    lab {number}: reference rows in {result.seconds:.1f} s")
    return written


__all__ = [
    "LABS",
    "NotWritten",
    "TradeResult",
    "bench_rows",
    "format_table",
    "measure_rows",
    "run",
    "shipped_reference",
    "trade_module",
    "write_reference_rows",
]
