# Right answers, each after sleeping just under the per-test time limit: without a budget a
# lab would take (tests x limit).
import os
import time

NAP = float(os.environ.get("RTCOURSE_TIME_LIMIT", "120")) - 0.4


def scale(x, factor):
    time.sleep(NAP)
    return x * factor


def scale_into(x, factor, out):
    time.sleep(NAP)
    out.copy_(x * factor)
    return out


def as_view(x):
    time.sleep(NAP)
    return x.view(-1)


def total_positive(x):
    time.sleep(NAP)
    if bool((x <= 0).any()):
        raise ValueError("x: every entry must be > 0")
    return x.sum()
