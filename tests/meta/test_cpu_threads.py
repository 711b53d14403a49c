"""course.core.device's CPU thread count: the free cores of this process, never the machine's."""

from __future__ import annotations

import os

import pytest
import torch

from course.core import device


def test_free_cpus_follows_affinity_and_load(monkeypatch):
    allowed = device.allowed_cpus()
    assert 1 <= device.free_cpus() <= allowed
    monkeypatch.setattr(os, "cpu_count", lambda: allowed)
    monkeypatch.setattr(os, "getloadavg", lambda: (0.0, 0.0, 0.0))
    assert device.free_cpus() == allowed, "an idle machine: every allowed core is free"
    monkeypatch.setattr(os, "getloadavg", lambda: (50.0 * allowed, 0.0, 0.0))
    assert device.free_cpus() == 1, "an overloaded machine: one thread, never zero"
    if hasattr(os, "sched_getaffinity"):
        monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0})
        monkeypatch.setattr(os, "getloadavg", lambda: (0.0, 0.0, 0.0))
        assert device.allowed_cpus() == 1 and device.free_cpus() == 1, (
            "pinned to one core: one thread, whatever os.cpu_count() says"
        )


def test_set_cpu_threads():
    before = torch.get_num_threads()
    try:
        assert device.set_cpu_threads(1) == 1 and torch.get_num_threads() == 1
        assert 1 <= device.set_cpu_threads() <= device.allowed_cpus()
        for bad in (0, -1, 1.5, True):
            with pytest.raises(ValueError, match="threads"):
                device.set_cpu_threads(bad)
    finally:
        torch.set_num_threads(before)
