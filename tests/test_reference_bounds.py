"""The reference back-end is bounded like the fast one: a stiff model (zeta = 1e6 makes the
spine damper's time constant ~1e-7 s) ends as "integration_failed" instead of running on."""

from __future__ import annotations

import time

import pytest

import bound_env.model.hybrid as hybrid
import bound_env.model.reference as reference
from bound_env.model.params import load_gait


@pytest.fixture
def stiff():
    return load_gait("paper", {"zeta": 1e6})


def test_step_budget_gives_integration_failed(stiff, monkeypatch):
    monkeypatch.setattr(reference, "REFERENCE_MAX_STEPS", 300)
    res = hybrid.simulate_stride(stiff.z0, stiff.params, backend="reference")
    assert res.failure == "integration_failed" and res.z1 is None


def test_wall_clock_guard_gives_integration_failed(stiff, monkeypatch):
    monkeypatch.setattr(reference, "REFERENCE_WALL_S", 0.3)
    t0 = time.perf_counter()
    res = hybrid.simulate_stride(stiff.z0, stiff.params, backend="reference")
    assert res.failure == "integration_failed"
    assert time.perf_counter() - t0 < 60  # a bound, not a speed claim: it used to run 15 min


def test_bounds_leave_a_normal_stride_alone():
    g = load_gait("default")
    ref = hybrid.simulate_stride(g.z0, g.params, backend="reference")
    assert ref.failure is None
    assert abs(ref.z1 - g.z0).max() < 1e-6  # on the cycle
