"""The demo gallery: each lab's showcase rendered from an implementation.

A lab's showcase lives in ``bench/showcase/labN.py`` as
``render(lab, device, size) -> (image (H, W, 3) float linear RGB, info dict)``;
``lab`` is the lab module (the solutions by default, or a student's labs/).
"""

from __future__ import annotations

import html
import time
from pathlib import Path

import torch

from course.core.files import import_file
from course.core.image import save_png
from course.core.labs import lab_number
from course.core.progress import progress
from course.measure.bench import load_lab


def showcases(root: Path) -> list[tuple[int, Path]]:
    found = []
    for path in sorted((root / "bench" / "showcase").glob("lab*.py")):
        if lab_number(path.stem) is not None:
            found.append((lab_number(path.stem), path))
    return found


def build_gallery(
    root: Path, impl_folder: Path, device: str, out: Path, size: int, log=print
) -> list[dict]:
    """Render every available showcase into ``out`` and write ``out/index.html``."""
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    cases = showcases(root)
    bar = progress(cases, desc="gallery", unit="lab")
    if log is print and not bar.disable:
        log = bar.write  # lines above the bar, not through it
    for step, (number, path) in enumerate(bar, 1):
        bar.set_postfix_str(f"lab {number}")
        log(f"[{step}/{len(cases)}] lab {number}: rendering {path.stem} on {device} ...")
        try:
            lab = load_lab(f"lab{number}", str(impl_folder))
        except FileNotFoundError:
            log(f"    no lab {number} module in {impl_folder}; skipped")
            continue
        start = time.perf_counter()
        try:
            image, info = import_file(path, f"showcase_{path.stem}").render(lab, device, size)
        except NotImplementedError as exc:
            log(f"    not implemented yet: {exc}")
            rows.append({"lab": number, "status": "not implemented yet", "seconds": 0.0})
            continue
        seconds = time.perf_counter() - start
        png = out / f"lab{number}.png"
        save_png(png, image)
        rows.append({"lab": number, "status": "ok", "image": png.name, "seconds": seconds, **info})
        log(f"    done in {seconds:.2f} s -> {png}")
    _write_index(out, rows, device)
    return rows


def _write_index(out: Path, rows: list[dict], device: str):
    name = torch.cuda.get_device_name() if device.startswith("cuda") else "CPU"
    cards = []
    for row in rows:
        facts = "".join(
            f"<tr><th>{html.escape(str(k))}</th><td>{html.escape(_fmt(v))}</td></tr>"
            for k, v in row.items()
            if k not in ("image", "lab")
        )
        img = f'<img src="{row["image"]}" alt="lab {row["lab"]}">' if "image" in row else ""
        cards.append(
            f'<div class="card"><h2>Lab {row["lab"]}</h2>{img}<table>{facts}</table></div>'
        )
    (out / "index.html").write_text(
        "<!doctype html><meta charset=utf-8><title>GPU ray tracing with PyTorch: gallery"
        "</title><style>body{font-family:sans-serif;margin:2em}.card{display:inline-block;"
        "vertical-align:top;margin:1em;padding:1em;border:1px solid #ccc}img{width:320px;"
        "image-rendering:pixelated}th{text-align:left;padding-right:1em}</style>"
        f"<h1>Gallery</h1><p>Rendered on {html.escape(device)} ({html.escape(name)}), "
        f"torch {torch.__version__}.</p>" + "".join(cards)
    )


def _fmt(value) -> str:
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value)
