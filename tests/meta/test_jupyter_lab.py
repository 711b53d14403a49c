"""``make lab`` opens the lecture notebooks: JupyterLab starts on ``slides/``, answers on its
REST API, lists the notebooks, runs code in a Python kernel of the course's environment (as a
notebook does, over the kernel's websocket) and shuts down when asked.

The server runs headless on a free port of 127.0.0.1 with a random token, started with the
command ``make lab`` runs (read from ``make -n``; where ``make`` is missing, the same command
directly). Every wait is bounded.
"""

from __future__ import annotations

import json
import os
import secrets
import shlex
import shutil
import socket
import subprocess
import sys
import time
import urllib.error
import urllib.request
import uuid
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
START_TIMEOUT = 120  # seconds for the server to answer (about 10 s on a busy 2-core machine)
KERNEL_TIMEOUT = 60


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def lab_command(lab_args: list[str]) -> list[str]:
    """The command ``make lab LAB_ARGS=...`` runs, with this environment's Jupyter."""
    if shutil.which("make") is None:
        return [
            sys.executable,
            "-m",
            "jupyterlab",
            *lab_args,
            *(["--allow-root"] if os.geteuid() == 0 else []),
            "slides",
        ]
    out = subprocess.run(
        ["make", "-s", "-n", "lab", f"VENV={sys.prefix}", "LAB_ARGS=" + shlex.join(lab_args)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=True,
        timeout=60,
    ).stdout
    return shlex.split(out.strip().splitlines()[-1])


def test_make_lab_runs_jupyter_lab_on_the_slides():
    if shutil.which("make") is None:
        pytest.skip("make is not installed")
    cmd = lab_command(["--no-browser"])
    assert Path(cmd[0]) == Path(sys.prefix) / "bin" / "jupyter" and cmd[1] == "lab", cmd
    assert cmd[-1] == "slides" and "--no-browser" in cmd, cmd


def _get(url: str, token: str, method="GET", body=None, timeout=10):
    request = urllib.request.Request(
        url, method=method, data=body, headers={"Authorization": f"token {token}"}
    )
    with urllib.request.urlopen(request, timeout=timeout) as response:
        text = response.read().decode()
    return json.loads(text) if text else None


def _stop(proc: subprocess.Popen, base: str, token: str) -> str:
    try:
        _get(f"{base}/api/shutdown", token, method="POST", body=b"")
    except (urllib.error.URLError, OSError):
        pass
    try:
        out, _ = proc.communicate(timeout=30)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, _ = proc.communicate()
    return out


def _run_in_kernel(port: int, token: str, kernel_id: str, code: str) -> str:
    """Run ``code`` in the kernel over its websocket, as a notebook does; return its stdout."""
    import websocket  # websocket-client, a dependency of jupyter_server

    ws = websocket.create_connection(
        f"ws://127.0.0.1:{port}/api/kernels/{kernel_id}/channels?token={token}",
        timeout=KERNEL_TIMEOUT,
    )
    try:
        msg_id = uuid.uuid4().hex
        ws.send(
            json.dumps(
                {
                    "header": {
                        "msg_id": msg_id,
                        "msg_type": "execute_request",
                        "username": "test",
                        "session": uuid.uuid4().hex,
                        "version": "5.3",
                    },
                    "parent_header": {},
                    "metadata": {},
                    "channel": "shell",
                    "content": {
                        "code": code,
                        "silent": False,
                        "store_history": False,
                        "user_expressions": {},
                        "allow_stdin": False,
                    },
                }
            )
        )
        printed, deadline = [], time.monotonic() + KERNEL_TIMEOUT
        while time.monotonic() < deadline:
            msg = json.loads(ws.recv())
            if msg.get("parent_header", {}).get("msg_id") != msg_id:
                continue
            kind = msg["header"]["msg_type"]
            if kind == "stream":
                printed.append(msg["content"]["text"])
            elif kind == "error":
                raise AssertionError("the kernel raised: " + "\n".join(msg["content"]["traceback"]))
            elif kind == "status" and msg["content"]["execution_state"] == "idle":
                return "".join(printed)
        raise AssertionError(f"the kernel did not run {code!r} in {KERNEL_TIMEOUT} s")
    finally:
        ws.close()


def test_jupyter_lab_serves_the_slides_and_starts_a_kernel(tmp_path):
    port, token = _free_port(), secrets.token_hex(16)
    args = [
        "--no-browser",
        "--ServerApp.ip=127.0.0.1",
        f"--ServerApp.port={port}",
        "--ServerApp.port_retries=0",
        f"--IdentityProvider.token={token}",
    ]
    env = dict(
        os.environ,
        JUPYTER_RUNTIME_DIR=str(tmp_path / "runtime"),
        JUPYTER_CONFIG_DIR=str(tmp_path / "config"),
    )
    proc = subprocess.Popen(
        lab_command(args),
        cwd=ROOT,
        env=env,
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    base = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + START_TIMEOUT
        while True:
            try:
                version = _get(f"{base}/api", token)
                break
            except (urllib.error.URLError, OSError):
                if proc.poll() is not None or time.monotonic() > deadline:
                    break
                time.sleep(0.5)
        assert proc.poll() is None, "JupyterLab exited before it answered"
        assert time.monotonic() <= deadline, f"JupyterLab did not answer in {START_TIMEOUT} s"
        assert "version" in version, version

        listed = {item["name"] for item in _get(f"{base}/api/contents", token)["content"]}
        notebooks = {path.name for path in (ROOT / "slides").glob("*.ipynb")}
        assert notebooks and notebooks <= listed, (
            f"the server's root is not slides/: it lists {sorted(listed)}"
        )

        kernel = _get(
            f"{base}/api/kernels",
            token,
            method="POST",
            body=json.dumps({"name": "python3"}).encode(),
            timeout=60,
        )
        printed = _run_in_kernel(port, token, kernel["id"], "import sys, course; print(sys.prefix)")
        assert printed.strip() == sys.prefix, (
            f"the notebooks' kernel runs in {printed.strip()!r}, not in the course's "
            f"environment {sys.prefix!r}"
        )
    finally:
        print(_stop(proc, base, token)[-5000:])  # the server's log, shown on a failure
    assert proc.returncode is not None
