"""Every source file of the labs, the references and the course package fits a reader: at
most 600 lines, with no exemption list (the vendored browser files of ``course/assets/web/``
are not our source). A lab that grows past one readable file becomes a package of modules
(``solutions/lab2_accel/``)."""

from __future__ import annotations

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
LIMIT = 600
FOLDERS = ("labs", "solutions", "course")


def _sources() -> list[Path]:
    return sorted(
        p
        for folder in FOLDERS
        for p in (ROOT / folder).rglob("*.py")
        if "assets" not in p.relative_to(ROOT).parts
    )


@pytest.mark.parametrize("folder", FOLDERS)
def test_no_source_file_over_the_limit(folder):
    long = [
        f"{p.relative_to(ROOT)}: {n} lines"
        for p in _sources()
        if p.relative_to(ROOT).parts[0] == folder and (n := len(p.read_text().splitlines())) > LIMIT
    ]
    assert not long, f"over {LIMIT} lines (split into modules named for what they hold):\n" + (
        "\n".join(long)
    )
