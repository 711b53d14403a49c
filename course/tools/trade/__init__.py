"""Your point on the plot: every lab's knobs measured on your code and on the reference.

``rtcourse bench --lab N`` runs one lab's knobs (``LABS[N]``, a module of this package:
its scenes, its settings and its error, in one place, also used by ``bench/labN_*.py``) on
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
  there). The table's header and the CSV's ``seconds_source`` column say which it was.

On CUDA the fused kernels of ``course.kernels`` add rows of their own (``impl`` "fused")
where a lab has one.

A lab's trade module provides ``MODULE`` (the lab module's name), ``TITLE``, ``ERROR`` (what
its error column measures), ``prepare(device, quick) -> ctx`` (scenes and exact answers,
course code only), ``knobs(ctx) -> [dict]`` (each with a ``setting`` label),
``measure(lab, ctx, knob) -> dict`` (``seconds``, ``error`` and any work counters) and
optionally ``fused(ctx) -> [dict]`` (rows of the fused kernels, CUDA).
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
            log(f"  {impl} {knob['setting']}: failed: {type(exc).__name__}: "
                f"{str(exc).splitlines()[0][:120] if str(exc) else ''}")
            measured = {"seconds": math.nan, "error": math.nan,
                        "failed": f"{type(exc).__name__}"}
        if measured is not None:
            rows.append({"impl": impl, **knob, **measured})
        if bar is not None:
            bar.update(1)
    return rows, skipped


def _first_task(skipped: list[str]) -> str:
    return skipped[0].split(": ", 1)[1] if skipped else "nothing measured"


def run(number: int, impl: str | None = None, device=None, quick: bool = False, out=None,
        root=None, log=print, reference: bool = True) -> TradeResult:
    """Measure lab ``number``'s knobs on ``impl`` (default ``labs``: the student's code) and
    on the reference; write ``labN.csv`` and ``labN.png`` into ``out`` (default
    ``out/bench/labN`` of the course) and return what was measured.

    Raises :class:`NotWritten` (one line naming the first unwritten task) when no row of
    ``impl`` could be measured because its functions raise NotImplementedError.
    ``reference``: False measures ``impl`` alone (the release's reference rows).
    """
    from course.core.device import default_device, set_cpu_threads
    from course.core.files import repo_root
    from course.core.labs import implementation_folder, load_lab
    from course.core.progress import progress
    from course.measure.bench import calibration_seconds, device_name, trade_plot, write_rows_csv

    started = time.perf_counter()
    trade = trade_module(number)
    root = Path(repo_root() if root is None else root)
    device = default_device(device)
    impl = impl or "labs"
    folder = implementation_folder(root, impl)
    solutions = root / "solutions"
    is_reference = solutions.is_dir() and folder.resolve() == solutions.resolve()
    out = Path(out) if out is not None else root / "out" / "bench" / f"lab{number}"
    ctx = trade.prepare(device, quick)
    ctx.setdefault("device", device)
    ctx.setdefault("quick", quick)
    threads = set_cpu_threads() if device.type == "cpu" else None  # the free cores
    calibration = calibration_seconds(device)
    name = device_name(device)
    common = {"lab": number, "device": name, "calibration_s": calibration,
              "cpu_threads": threads}

    live_reference = reference and solutions.is_dir() and not is_reference
    knobs = len(trade.knobs(ctx))
    bar = progress(total=knobs * (2 if live_reference else 1), desc=f"lab {number} bench",
                   unit="row")
    try:
        student = load_lab(trade.MODULE, str(folder), root)
        label = "reference" if is_reference else "yours"
        yours, skipped = measure_rows(trade, student, ctx, label, log, bar)
        if not yours and skipped:
            raise NotWritten(f"{folder.name}/{trade.MODULE}: {_first_task(skipped)}; write it "
                             f"to measure your trade (nothing else of lab {number} was "
                             f"measured)")
        source = "measured in this run"
        ref_rows: list[dict] = []
        if is_reference:
            ref_rows, yours = yours, []
        elif live_reference:
            ref_rows, _ = measure_rows(trade, load_lab(trade.MODULE, "solutions", root), ctx,
                                       "reference", log, bar)
        elif reference:
            ref_rows, source = shipped_reference(root, number, calibration)
    finally:
        bar.close()
    fused = trade.fused(ctx) if device.type == "cuda" and hasattr(trade, "fused") else []
    for row in fused:
        row.setdefault("impl", "fused")
    measured_source = "measured in this run"
    rows = ([dict(common, **r, seconds_source=measured_source) for r in yours]
            + [dict(common, **r) if "seconds_source" in r
               else dict(common, **r, seconds_source=source) for r in ref_rows]
            + [dict(common, **r, seconds_source=measured_source) for r in fused])
    for row in rows:
        row["error_metric"] = trade.ERROR_NAME
    csv = write_rows_csv(rows, out / f"lab{number}.csv")
    png = out / f"lab{number}.png"
    title = f"{trade.TITLE}\nerror: {trade.ERROR_NAME}; {name}, {'quick' if quick else 'full'}"
    try:
        trade_plot(ref_rows, yours, fused, path=png, title=title,
                   yours_name=f"yours ({folder.name})")
    except ValueError:  # no finite row at all (every row failed): the CSV says why
        png = None
    table = format_table(number, trade, yours, ref_rows, source, skipped)
    return TradeResult(rows=rows, csv=csv, png=png, table=table, skipped=skipped,
                       seconds=time.perf_counter() - started)


def shipped_reference(root: Path, number: int, calibration: float) -> tuple[list, str]:
    """The handout's reference rows of lab ``number`` with their seconds scaled to this
    machine (``calibration``: this machine's calibration seconds), and the sentence saying
    so; ``([], why)`` where the handout has none."""
    from course.measure.bench import read_rows_csv

    path = Path(root) / REFERENCE_DIR / f"lab{number}.csv"
    if not path.is_file():
        return [], (f"no reference rows: {REFERENCE_DIR / path.name} is not in this handout "
                    f"(rtcourse release ships it)")
    rows = read_rows_csv(path)
    theirs = next((r["calibration_s"] for r in rows if r.get("calibration_s")), None)
    scale = calibration / theirs if theirs else 1.0
    where = rows[0].get("device", "?") if rows else "?"
    source = (f"shipped ({REFERENCE_DIR / path.name}, measured on {where}), times x{scale:.3g} "
              f"by calibration (this machine {calibration * 1e3:.3g} ms, theirs "
              f"{(theirs or math.nan) * 1e3:.3g} ms)")
    scaled = []
    for row in rows:
        seconds = row.get("seconds")
        scaled.append({**{k: v for k, v in row.items()
                          if k not in ("lab", "device", "calibration_s", "seconds_source")},
                       "impl": "reference", "seconds_measured": seconds,
                       "seconds": seconds * scale if isinstance(seconds, (int, float)) else seconds,
                       "time_scale": scale, "reference_device": where,
                       "reference_calibration_s": theirs, "seconds_source": source})
    return scaled, source


def _num(value, fmt: str) -> str:
    if not isinstance(value, (int, float)) or isinstance(value, bool) or not math.isfinite(value):
        return "-"
    return format(value, fmt)


def format_table(number: int, trade, yours: list, reference: list, source: str,
                 skipped: list) -> str:
    """The terminal table: per setting, your seconds and error beside the reference's, and
    your time as a multiple of the reference's (below 1: faster)."""
    ref = {r["setting"]: r for r in reference}
    lines = [f"Lab {number}: {trade.TITLE}",
             f"error: {trade.ERROR}",
             f"reference times: {source}"]
    width = max([len(r["setting"]) for r in (yours or reference)] + [7])
    head = (f"{'setting':<{width}}  {'your s':>10}  {'ref s':>10}  {'ratio':>6}  "
            f"{'your error':>10}  {'ref error':>10}")
    lines += ["", head, "-" * len(head)]
    for row in (yours or reference):
        twin = ref.get(row["setting"], {})
        mine = row if yours else {}
        ratio = (mine.get("seconds", math.nan) / twin["seconds"]
                 if yours and twin.get("seconds") else math.nan)
        lines.append(f"{row['setting']:<{width}}  {_num(mine.get('seconds'), '10.3g')}  "
                     f"{_num(twin.get('seconds'), '10.3g')}  {_num(ratio, '6.2f')}  "
                     f"{_num(mine.get('error'), '10.3g')}  {_num(twin.get('error'), '10.3g')}")
    lines.append("ratio: your seconds / the reference's at the same setting (below 1: faster)")
    if skipped:
        lines.append(f"not measured ({len(skipped)}): " + "; ".join(skipped[:3])
                     + (" ..." if len(skipped) > 3 else ""))
    return "\n".join(lines)


def write_reference_rows(root, out, labs=LABS, log=print) -> list[Path]:
    """Measure every lab's reference (``root/solutions``) with ``quick`` sizes on the CPU
    and write its rows to ``out/bench/reference/labN.csv`` (the release's step, for a
    handout that has no solutions/). Returns the files written, relative to ``out``."""
    root, out = Path(root), Path(out)
    written = []
    for number in labs:
        result = run(number, impl="solutions", device="cpu", quick=True, root=root,
                     out=out / REFERENCE_DIR, log=log, reference=False)
        (out / REFERENCE_DIR / f"lab{number}.png").unlink(missing_ok=True)
        written.append(REFERENCE_DIR / result.csv.name)
        log(f"    lab {number}: reference rows in {result.seconds:.1f} s")
    return written


__all__ = ["LABS", "NotWritten", "TradeResult", "format_table", "measure_rows", "run",
           "shipped_reference", "trade_module", "write_reference_rows"]
