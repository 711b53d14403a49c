# Right answers, after leaving processes behind: sleepers in their own sessions (double
# forked, so they are nobody's child), and children that each hold memory under the
# worker's address-space cap while together they pass the worker's memory limit.
import os
import subprocess
import sys
import time

MARK = "rtcourse-hostile-child-987654"


def _sleepers(n):
    for _ in range(n):
        subprocess.Popen([sys.executable, "-c", f"import time; time.sleep(600)  # {MARK}"],
                         start_new_session=True, stdout=subprocess.DEVNULL,
                         stderr=subprocess.DEVNULL)
    if os.fork() == 0:  # a grandchild that leaves its session and its parent
        os.setsid()
        if os.fork() == 0:
            os.execv(sys.executable, [sys.executable, "-c",
                                      f"import time; time.sleep(600)  # {MARK}"])
        os._exit(0)


def scale(x, factor):
    _sleepers(3)
    return x * factor


def scale_into(x, factor, out):
    hog = f"x = b'1' * (400 * 2**20); import time; time.sleep(600)  # {MARK}"
    for _ in range(4):  # 1.6 GB together, each under the cap
        subprocess.Popen([sys.executable, "-c", hog], stdout=subprocess.DEVNULL,
                         stderr=subprocess.DEVNULL)
    time.sleep(30)  # the grader stops it for memory long before
    out.copy_(x * factor)
    return out


def as_view(x):
    _sleepers(1)
    return x.view(-1)


def total_positive(x):
    if bool((x <= 0).any()):
        raise ValueError("x: every entry must be > 0")
    return x.sum()
