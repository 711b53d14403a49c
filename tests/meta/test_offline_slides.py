"""``rtcourse slides`` pages work without a network, and ``rtcourse slides NOTEBOOK...``
renders only the notebooks named."""

from __future__ import annotations

import base64
import os
import re
import shutil
import subprocess
import sys
from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import urlsplit

import nbformat
import pytest
from nbformat.v4 import new_code_cell, new_markdown_cell, new_notebook, new_output

# A 1x1 PNG: the saved figure of the toy notebook's code cell.
PNG = base64.b64encode(
    bytes.fromhex(
        "89504e470d0a1a0a0000000d4948445200000001000000010806000000"
        "1f15c4890000000d49444154789c63f8cfc0f01f0005000201a5b1c0a10000000049454e44ae426082"
    )
).decode()

# Loaded before the command: any connection to a host other than this machine fails.
NO_NETWORK = """
import socket
_connect = socket.socket.connect
def _local_only(self, address):
    host = address[0] if isinstance(address, tuple) else address
    if isinstance(host, str) and host not in ("127.0.0.1", "::1", "localhost") \\
            and self.family != getattr(socket, "AF_UNIX", None):
        raise OSError(f"network blocked in this test: {address!r}")
    return _connect(self, address)
socket.socket.connect = _local_only
socket.create_connection = lambda address, *a, **k: (_ for _ in ()).throw(
    OSError(f"network blocked in this test: {address!r}"))
"""


def _course(root: Path):
    (root / "tests").mkdir(parents=True)
    (root / "pyproject.toml").write_text("")
    (root / "slides").mkdir()
    figure = new_code_cell(
        "plot()",
        outputs=[new_output("display_data", data={"image/png": PNG, "text/plain": "<Figure>"})],
    )
    nbformat.write(
        new_notebook(
            cells=[
                new_markdown_cell(
                    "# Formulas\nThe ray $o + t\\,d$ meets the plane where\n\n"
                    "$$t = \\frac{(p - o) \\cdot n}{d \\cdot n}.$$"
                ),
                figure,
                new_markdown_cell("## A second slide"),
            ]
        ),
        root / "slides" / "01_maths.ipynb",
    )
    nbformat.write(
        new_notebook(cells=[new_markdown_cell("# Other")]), root / "slides" / "02_other.ipynb"
    )


def _slides(root: Path, *args):
    (root / "no_network").mkdir(exist_ok=True)
    (root / "no_network" / "sitecustomize.py").write_text(NO_NETWORK)
    env = dict(os.environ, PYTHONPATH=str(root / "no_network"))
    return subprocess.run(
        [sys.executable, "-m", "course.tools.cli", "slides", "--out", "out", *args],
        cwd=root,
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
        env=env,
    )


class _References(HTMLParser):
    """Every address a page loads: <script src>, <link href>, <img src>, ES module
    imports and CSS @import inside the page."""

    def __init__(self):
        super().__init__()
        self.urls, self._in = [], None

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        if tag == "script" and attrs.get("src"):
            self.urls.append(attrs["src"])
        elif tag == "link" and attrs.get("href"):
            self.urls.append(attrs["href"])
        elif tag == "img" and attrs.get("src") and not attrs["src"].startswith("data:"):
            self.urls.append(attrs["src"])
        self._in = tag

    def handle_data(self, data):
        if self._in == "script":
            self.urls += re.findall(r"""\bimport\b[^'"]*?\bfrom\s*['"]([^'"]+)['"]""", data)
            self.urls += re.findall(r"""\bimport\s*\(\s*['"]([^'"]+)['"]""", data)
        elif self._in == "style":
            self.urls += re.findall(r"""@import\s+(?:url\()?\s*['"]?([^'")\s;]+)""", data)


def _remote(url: str) -> bool:
    parts = urlsplit(url)
    return bool(parts.scheme in ("http", "https") or parts.netloc)


def _local_file(page_dir: Path, url: str) -> Path:
    return (page_dir / urlsplit(url).path).resolve()


def _check_css(css: Path, seen: set):
    """A stylesheet's own url(...) and @import references: local and present."""
    if css in seen:
        return
    seen.add(css)
    for url in re.findall(r"""url\(\s*['"]?([^'")]+)['"]?\s*\)""", css.read_text()):
        if url.startswith("data:"):
            continue
        assert not _remote(url), f"{css.name} loads {url} from the network"
        target = _local_file(css.parent, url)
        assert target.is_file(), f"{css.name} refers to {url}, which is not there"
        if target.suffix == ".css":
            _check_css(target, seen)


@pytest.fixture(scope="module")
def rendered(tmp_path_factory) -> Path:
    """The toy course's pages, rendered with the network blocked."""
    root = tmp_path_factory.mktemp("offline")
    _course(root)
    proc = _slides(root, "--no-execute")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return root / "out"


def test_pages_load_nothing_from_the_network(rendered):
    out = rendered
    pages = sorted(out.glob("*.html"))
    assert {p.name for p in pages} >= {"index.html", "01_maths.html", "01_maths.slides.html"}
    css_seen: set = set()
    for page in pages:
        text = page.read_text()
        parser = _References()
        parser.feed(text)
        for url in parser.urls:
            if url.startswith("#"):
                continue
            assert not _remote(url), f"{page.name} loads {url} from the network"
            target = _local_file(out, url)
            assert target.is_file(), f"{page.name} refers to {url}, which is not there"
            if target.suffix == ".css":
                _check_css(target, css_seen)
        if page.name.endswith(".slides.html"):
            # reveal.js and its notes plugin come through require.js, by path.
            required = re.search(r"require\(\s*\{[^}]*\}\s*,\s*\[([^\]]*)\]", text)
            assert required, f"{page.name}: no require([...]) of reveal.js"
            modules = re.findall(r'"([^"]+)"', required.group(1))
            assert any(m.endswith("reveal.js") for m in modules), modules
            for module in modules:
                assert not _remote(module) and _local_file(out, module).is_file(), (
                    f"{page.name}: reveal.js module {module} is not beside the page"
                )
    notes = (out / "01_maths.html").read_text()
    assert "MathJax.js?config=TeX-AMS_CHTML-full" in notes
    assert (out / "_static" / "mathjax" / "config" / "TeX-AMS_CHTML-full.js").is_file(), (
        "MathJax's combined configuration must be beside the page: it loads it by name"
    )
    assert "data:image/png;base64," in notes, "the saved figure is embedded in the notes"
    assert "\\frac" in notes, "the formula is left for MathJax to typeset"
    assert {"reveal.css", "white.css"} <= {p.name for p in css_seen}


def test_slides_renders_only_the_notebooks_named(tmp_path, monkeypatch, capsys):
    from course.tools.cli import main

    _course(tmp_path)
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("RTCOURSE_PROGRESS", "0")  # the lines a log gets, even on a terminal
    out = tmp_path / "out"
    assert main(["slides", "--no-execute", "--out", "out", "02_other"]) == 0
    assert (out / "02_other.slides.html").is_file() and not (out / "01_maths.html").exists()
    assert "[1/1] 02_other.ipynb" in capsys.readouterr().out, "one progress line per notebook"
    assert main(["slides", "--no-execute", "--out", "out", "slides/01_maths.ipynb"]) == 0
    index = (out / "index.html").read_text()
    assert 'href="01_maths.html"' in index and 'href="02_other.html"' in index, (
        "the index keeps the notebook rendered by the earlier run"
    )
    assert "rendered by an earlier run" in index
    with pytest.raises(SystemExit) as stop:
        main(["slides", "--no-execute", "--out", "out", "03_missing"])
    assert "03_missing" in str(stop.value) and "01_maths" in str(stop.value), (
        "an unknown notebook is named, with the ones there are"
    )


BROWSER = next(
    (
        shutil.which(name)
        for name in ("chromium", "chromium-browser", "google-chrome")
        if shutil.which(name)
    ),
    None,
)


@pytest.mark.skipif(
    BROWSER is None, reason="no headless Chromium on this machine to open the pages with"
)
@pytest.mark.parametrize("page", ["01_maths.html", "01_maths.slides.html"])
def test_a_browser_without_network_typesets_the_formulas(rendered, page):
    # A proxy that refuses every connection: only the files beside the page can load.
    proc = subprocess.run(
        [
            BROWSER,
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--proxy-server=127.0.0.1:9",
            "--virtual-time-budget=15000",
            "--dump-dom",
            (rendered / page).as_uri(),
        ],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    dom = proc.stdout
    assert proc.returncode == 0 and dom, proc.stderr[-2000:]
    typeset = re.findall(r'id="MathJax-Element-\d+-Frame"', dom)
    assert len(typeset) >= 2, f"{page}: MathJax typeset {len(typeset)} of the 2 formulas offline"
    assert "Math Processing Error" not in dom
    if page.endswith(".slides.html"):
        assert re.search(r'class="reveal [^"]*\bready\b', dom), (
            f"{page}: reveal.js did not start offline"
        )


def test_a_terminal_gets_a_progress_bar_per_notebook(tmp_path, capfd, monkeypatch):
    from course.tools.slides import render_slides

    _course(tmp_path)
    monkeypatch.setenv("RTCOURSE_PROGRESS", "1")  # as on a terminal
    rows = render_slides(tmp_path, tmp_path / "out", execute=False)
    captured = capfd.readouterr()
    assert len(rows) == 2 and "2/2" in captured.err and "notebook" in captured.err, captured.err[
        -500:
    ]
    assert "01_maths.ipynb done" in captured.out, "each notebook's line goes above the bar"
    assert "[1/2]" not in captured.out, "no plain progress lines beside the bar"
