"""The install works on the machines students bring: pip's resolver, in dry-run mode and
with wheels only, resolves the project's dependencies (``dependencies`` plus the ``dev``
extra, read from pyproject.toml) for Linux x86_64 (which is also Windows under WSL), macOS
on Apple silicon and native Windows on amd64. A dependency with no wheel for one of them
fails the test, naming it. Nothing is installed; pip's own cache is the only thing written.

pip's ``--platform`` and ``--python-version`` pick wheels for the target, but pip still
evaluates environment markers (``; platform_system == 'Linux'``) for the machine it runs
on, so a Linux-only dependency would be asked of macOS too. The resolver therefore runs in
a small launcher that hands pip's marker evaluation the target's environment.

An index that serves no separate wheel metadata (PEP 658) makes a dry run download every
wheel it considers: a few hundred MB on macOS and Windows, but gigabytes for torch's
CUDA libraries on Linux. There torch and what it needs are resolved on their own with
pip's ``fast-deps``, which reads just each wheel's metadata with HTTP range requests
(where a pip no longer knows that option, without it), and the rest of the dependencies
in a run of their own. All runs go at once: they mostly wait for the index.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name
from packaging.version import Version

ROOT = Path(__file__).resolve().parents[2]
PYTHON = "3.12"  # the Python a student's laptop most likely has
TIMEOUT = 300  # seconds for the three resolutions together (about 30 s with a near index)


@dataclass(frozen=True)
class Target:
    platforms: tuple[str, ...]  # pip --platform tags (each also accepts older ones on macOS)
    markers: dict  # the PEP 508 marker environment of that machine
    torch_apart: bool = False  # resolve torch in a run of its own, reading only metadata

    def environment(self) -> dict:
        full = f"{PYTHON}.0"
        return {
            "implementation_name": "cpython",
            "implementation_version": full,
            "platform_python_implementation": "CPython",
            "python_version": PYTHON,
            "python_full_version": full,
            "platform_release": "",
            "platform_version": "",
            **self.markers,
        }


# manylinux tags are not widened by pip the way macOS ones are: list glibc 2.17 (CentOS 7)
# up to 2.35 (Ubuntu 22.04, the WSL default).
_MANYLINUX = tuple(f"manylinux_2_{minor}_x86_64" for minor in range(17, 36)) + (
    "manylinux2014_x86_64",
)
TARGETS = {
    "Linux x86_64 (and WSL)": Target(
        _MANYLINUX,
        {
            "sys_platform": "linux",
            "platform_system": "Linux",
            "os_name": "posix",
            "platform_machine": "x86_64",
        },
        torch_apart=True,
    ),
    "macOS arm64": Target(
        ("macosx_14_0_arm64",),
        {
            "sys_platform": "darwin",
            "platform_system": "Darwin",
            "os_name": "posix",
            "platform_machine": "arm64",
        },
    ),
    "Windows amd64": Target(
        ("win_amd64",),
        {
            "sys_platform": "win32",
            "platform_system": "Windows",
            "os_name": "nt",
            "platform_machine": "AMD64",
        },
    ),
}

# Runs pip with the target's marker environment (argv[1], JSON) and pip's arguments.
LAUNCHER = """\
import json, sys
from pip._vendor.packaging import markers
target = dict(markers.default_environment(), **json.loads(sys.argv[1]))
markers.default_environment = lambda: dict(target)
from pip._internal.cli.main import main
sys.exit(main(sys.argv[2:]))
"""

_NETWORK_ERRORS = re.compile(
    r"NewConnectionError|Failed to establish a new connection|Temporary failure in name "
    r"resolution|Name or service not known|Network is unreachable|ConnectTimeout|"
    r"ProxyError|Max retries exceeded|Could not fetch URL|SSLError|No route to host"
)


def project_requirements() -> list[str]:
    try:
        import tomllib
    except ModuleNotFoundError:  # Python 3.10: the copy pip ships
        from pip._vendor import tomli as tomllib
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    extras = project["optional-dependencies"]

    def expand(requirements):  # "gpu-raytracing-course[notebooks]": that extra's own list
        for line in requirements:
            if line.startswith(project["name"] + "["):
                yield from expand(extras[line.split("[", 1)[1].split("]", 1)[0]])
            else:
                yield line

    return list(project["dependencies"]) + list(expand(extras["dev"]))


def _resolve_command(
    target: Target, requirements: list[str], report: Path, scratch: Path, fast: bool
) -> list[str]:
    cmd = [
        sys.executable,
        "-c",
        LAUNCHER,
        json.dumps(target.environment()),
        "install",
        *(["--use-feature=fast-deps"] if fast else []),
        "--dry-run",
        "--ignore-installed",
        "--only-binary=:all:",
        "--python-version",
        PYTHON,
        "--implementation",
        "cp",
        "--target",
        str(scratch),
        "--report",
        str(report),
        "--quiet",
        "--progress-bar",
        "off",
        "--disable-pip-version-check",
        "--timeout",
        "20",
        "--retries",
        "2",
    ]
    for platform in target.platforms:
        cmd += ["--platform", platform]
    return cmd + requirements


def _jobs(target: Target) -> list[tuple[list[str], bool]]:
    """(requirements, fast-deps) of each resolver run for ``target``."""
    reqs = project_requirements()
    if not target.torch_apart:
        return [(reqs, False)]
    is_torch = [canonicalize_name(Requirement(r).name) == "torch" for r in reqs]
    return [
        ([r for r, t in zip(reqs, is_torch) if not t], False),
        ([r for r, t in zip(reqs, is_torch) if t], True),
    ]


def _failure(name: str, output: str) -> str:
    missing = re.findall(r"No matching distribution found for (\S+)", output)
    if missing:
        return (
            f"{name}: no wheel of {', '.join(missing)} for Python {PYTHON} on this "
            f"platform: the install fails there (pip's last words below)\n" + output[-3000:]
        )
    return f"{name}: pip could not resolve the dependencies\n" + output[-3000:]


def _installed(reports: list[Path]) -> dict[str, tuple[Version, str]]:
    found = {}
    for report in reports:
        for item in json.loads(report.read_text())["install"]:
            found[canonicalize_name(item["metadata"]["name"])] = (
                Version(item["metadata"]["version"]),
                item["download_info"]["url"],
            )
    return found


def _start(cmd) -> subprocess.Popen:
    return subprocess.Popen(
        cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, stdin=subprocess.DEVNULL
    )


def _resolve_all(tmp_path) -> dict:
    """Run every target's resolver runs at once; return name -> (target, report paths,
    exit code, output) with the codes and outputs of a target's runs combined."""
    procs = []
    for name, target in TARGETS.items():
        for reqs, fast in _jobs(target):
            i = len(procs)
            report, scratch = tmp_path / f"report-{i}.json", tmp_path / f"target-{i}"
            procs.append(
                [
                    name,
                    target,
                    reqs,
                    fast,
                    report,
                    scratch,
                    _start(_resolve_command(target, reqs, report, scratch, fast)),
                ]
            )
    runs = {}
    try:
        for job in procs:
            name, target, reqs, fast, report, scratch, proc = job
            try:
                output = proc.communicate(timeout=TIMEOUT)[0]
                if proc.returncode and fast and "fast-deps" in output:  # a pip without it
                    job[-1] = proc = _start(_resolve_command(target, reqs, report, scratch, False))
                    output = proc.communicate(timeout=TIMEOUT)[0]
            except subprocess.TimeoutExpired:
                pytest.fail(f"{name}: pip did not resolve the dependencies in {TIMEOUT} s")
            _, reports, code, text = runs.get(name, (target, [], 0, ""))
            runs[name] = (target, [*reports, report], code or proc.returncode, text + output)
    finally:
        for *_, proc in procs:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    return runs


def test_project_dependencies_resolve_to_wheels_everywhere(tmp_path):
    # Checked in a child: importing pip's CLI here would import the standard library's
    # distutils into the test process, and setuptools (which torch.compile's C++ builder
    # imports in later tests) refuses to load beside it.
    check = "import pip._internal.cli.main, pip._vendor.packaging.markers"
    probe = subprocess.run(
        [sys.executable, "-c", check], capture_output=True, text=True, check=False
    )
    if probe.returncode:
        pytest.skip(
            f"pip's resolver is not importable in this environment "
            f"({probe.stderr.strip().splitlines()[-1:]})"
        )
    runs = _resolve_all(tmp_path)
    for name, (_, _, code, output) in runs.items():
        offline = _NETWORK_ERRORS.search(output)
        if code and offline:
            pytest.skip(f"no package index is reachable from here ({name}: {offline.group(0)})")
    problems = []
    for name, (target, reports, code, output) in runs.items():
        if code:
            problems.append(_failure(name, output))
            continue
        installed = _installed(reports)
        environment = target.environment()
        for line in project_requirements():
            req = Requirement(line)
            key = canonicalize_name(req.name)
            wanted = req.marker is None or req.marker.evaluate(environment)
            if wanted and key not in installed:
                problems.append(f"{name}: {req.name} is a dependency but pip did not pick it")
            elif wanted and installed[key][0] not in req.specifier:
                problems.append(
                    f"{name}: {req.name} {installed[key][0]} does not satisfy {req.specifier}"
                )
            elif not wanted and key in installed:
                problems.append(
                    f"{name}: {req.name} is marked '{req.marker}' but pip picked "
                    f"it ({installed[key][1]})"
                )
        for key, (version, url) in installed.items():
            if not url.rsplit("/", 1)[-1].endswith(".whl"):
                problems.append(f"{name}: {key} {version} is not a wheel: {url}")
    assert not problems, "\n\n".join(problems)


def test_triton_is_linux_only_in_the_project():
    """Triton publishes wheels for Linux only: every requirement of it carries the marker."""
    for line in project_requirements():
        req = Requirement(line)
        if canonicalize_name(req.name) == "triton":
            assert req.marker is not None and req.marker.evaluate(
                TARGETS["Linux x86_64 (and WSL)"].environment()
            ), line
            for name in ("macOS arm64", "Windows amd64"):
                assert not req.marker.evaluate(TARGETS[name].environment()), (
                    f"{line!r} would ask for Triton on {name}, where it has no wheel"
                )
