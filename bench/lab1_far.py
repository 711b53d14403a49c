"""Lab 1's triangle tests far from the origin: the scale at which each stops hitting.

A small icosphere (level 1, radius 1) is scaled by ``S`` in float32, and a ray from outside
is aimed at the centroid of every triangle (the ray must hit). Two cases per scale:

* ``unit``: unit directions (``t`` is a distance, of order ``S``);
* ``scaled``: directions ``target - origin``, of length of order ``S`` (``t`` is of order 1).

The table gives the fraction of the rays that hit (``1`` = every ray). With unit
directions the simple, Möller–Trumbore and watertight tests form products of three
coordinates (``e2 . (s x e1)``, ``U Az``): of order ``S^3``, they overflow float32 (3.4e38)
past ``S`` about 7e12, and the tests miss. Directions that scale with the scene move the
overflow to ``det ~ S^3`` too, but the quotient ``t = T / det`` stays finite until the
products themselves reach inf. Woop's test works on the unit triangle (its transform, made
in float64, absorbs ``1/S``) and keeps hitting up to float32's range.

Usage: ``python bench/lab1_far.py [--impl solutions] [--json PATH]``; the table printed is
the one quoted in Lab 1's docstring, ``solutions/lab1_intersect/__init__.py``
(``tests/meta/test_lab1_crack_table.py`` re-runs it).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from course.core.labs import load_lab  # noqa: E402
from course.core.scenes import load_scene  # noqa: E402

SCALES = (1.0, 1e6, 1e12, 1e13, 1e16, 1e19, 1e22, 1e25, 1e30)
VARIANTS = ("intersect_simple", "moller_trumbore", "woop_unit", "watertight")


def hit_rates(lab, scale: float, mode: str) -> dict:
    """{variant: fraction of the rays aimed at triangle centroids that hit}."""
    mesh = load_scene("icosphere", device="cpu", dtype=torch.float64, level=1).mesh
    corners = mesh.vertices[mesh.faces] * scale
    target = corners.mean(1)
    g = torch.Generator().manual_seed(1)
    out = torch.randn(len(target), 3, generator=g, dtype=torch.float64)
    origins = 3 * scale * out / out.norm(dim=1, keepdim=True)
    d = target - origins
    if mode == "unit":
        d = d / d.norm(dim=1, keepdim=True)
    o, d, c = origins.float(), d.float(), corners.float()
    v0, v1, v2 = c[:, 0], c[:, 1], c[:, 2]
    rates = {}
    with torch.no_grad():
        for name in VARIANTS:
            if name == "woop_unit":
                t, _, _ = lab.woop_unit(o, d, lab.woop_precompute(v0, v1, v2))
            else:
                t, _, _ = getattr(lab, name)(o, d, v0, v1, v2)
            rates[name] = float((t < math.inf).double().mean())
    return rates


def measure(lab) -> dict:
    return {
        mode: {f"{s:g}": hit_rates(lab, s, mode) for s in SCALES} for mode in ("unit", "scaled")
    }


def _rate(x: float) -> str:
    return "1" if x == 1 else ("0" if x == 0 else f"{x:.2g}")


def table(results: dict) -> str:
    """The rST table quoted in Lab 1's docstring."""
    rule = "========  " + "  ".join(["=================="] * len(VARIANTS))
    head = "scale S   " + "  ".join(f"{v:<18}" for v in VARIANTS)
    lines = [
        "Far field (fp32, icosphere level 1 scaled by S: 80 rays aimed at its triangles'",
        "centroids from 3 S away; hit rate with unit directions / with directions of",
        "length ~S):",
        "",
        rule,
        head.rstrip(),
        rule,
    ]
    for s in SCALES:
        key = f"{s:g}"
        cells = [
            f"{_rate(results['unit'][key][v])} / {_rate(results['scaled'][key][v])}"
            for v in VARIANTS
        ]
        lines.append((f"{key:<8}  " + "  ".join(f"{c:<18}" for c in cells)).rstrip())
    lines.append(rule)
    return "\n".join(lines)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--impl", default="solutions")
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args(argv)
    torch.manual_seed(0)
    lab = load_lab("lab1_intersect", args.impl, ROOT)
    results = measure(lab)
    print(table(results))
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(
            json.dumps(
                {
                    "command": "python bench/lab1_far.py --json " + str(args.json),
                    "scales": list(SCALES),
                    "hit_rate": results,
                },
                indent=1,
            )
            + "\n"
        )


if __name__ == "__main__":
    main()
