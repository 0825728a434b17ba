"""The step-level residual batched end to end (issue 49): the bases' interval torques of all
robots in one array (`bound_env.sim.stride_protocol.profile_rows`) are each base's own call bit for
bit, the residual's features of all rows are each row's, and the closed loop ends every robot
exactly as the per-robot loop does."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from agents.runtime import residual as residual_mod
from agents.runtime.policy import load_controller
from agents.runtime.residual import residual_features, residual_features_rows
from bound_env.analysis.margins import random_directions
from bound_env.analysis.margins.closed_loop import ClosedLoop
from bound_env.sim.stride_protocol import OBS_TIME, profile_rows
from bound_env.sim.task import OBS_NAMES


def _copies_and_obs(ctrl, n: int, seed: int):
    """n copies of ``ctrl``, each told an apex of its own (past the safe radius: a plan of
    its own) at a float32 time t0, and an observation each at a time along the stride (on
    and between the grid points t0 + k dt, where the snapping rounds half to even)."""
    rng = np.random.default_rng(seed)
    zs = np.asarray(ctrl.z_ref, dtype=float)
    Z = zs + 0.25 * np.abs(zs) * random_directions(n, seed)
    t0 = np.float32(rng.uniform(0, 0.02, n)).astype(float)
    copies = []
    for z, t in zip(Z, t0, strict=True):
        c = copy.deepcopy(ctrl)
        c.on_apex(z, t)
        copies.append(c)
    obs = np.zeros((n, len(OBS_NAMES) - 1), dtype=np.float32)
    k = rng.integers(0, 40, n)
    obs[:, OBS_TIME] = t0 + 0.01 * (k + rng.choice([0.0, 0.5, 0.49, 0.51, 1e-4], n))
    return copies, obs


@pytest.mark.parametrize("name", ["lqr", "default", "deadbeat"])
def test_the_bases_torques_in_one_array_are_each_bases_own_bit_for_bit(name):
    ctrl = load_controller(name)
    copies, obs = _copies_and_obs(ctrl, 400, 7)
    got = profile_rows(copies, obs)
    want = np.array([c(o) for c, o in zip(copies, obs, strict=True)])
    assert got is not None and got.tobytes() == want.tobytes()
    assert np.unique(np.round(want, 6)).size > 20  # the robots' plans differ


def test_a_base_without_a_profile_is_called_row_by_row():
    """A copy that has not been told an apex, and a subclass that overrides ``__call__``
    alone, are not batched (None: the caller calls each)."""
    ctrl = load_controller("lqr")
    copies, obs = _copies_and_obs(ctrl, 4, 1)
    assert profile_rows([copy.deepcopy(ctrl)] + copies[1:], obs) is None

    class Louder(type(ctrl)):
        def __call__(self, obs):
            return 2 * super().__call__(obs)

    loud = [copy.copy(c) for c in copies]
    for c in loud:
        c.__class__ = Louder
    assert profile_rows(loud, obs) is None
    assert profile_rows([], obs[:0]).shape == (0,)


def test_the_features_of_all_rows_are_each_rows():
    ctrl = load_controller("step-ppo/s0")
    rng = np.random.default_rng(3)
    obs = rng.standard_normal((9, len(OBS_NAMES) - 1)).astype(np.float32)
    a0, x, g = rng.standard_normal(9), rng.standard_normal((9, 6)), rng.uniform(0, 1, 9)
    rows = residual_features_rows(obs, ctrl.keep, a0, x, g)
    for k in range(9):
        want = residual_features(obs[k], ctrl.keep, a0[k], x[k], g[k])
        assert rows[k].tobytes() == want.tobytes()


def test_the_batched_loop_ends_every_robot_as_the_per_robot_loop(monkeypatch):
    """step-ppo/s0 from 24 starts past the safe radius, 25 strides: every outcome (held,
    strides, last apex) of the loop batched end to end is the per-robot loop's, bit for bit,
    and the same with the bases' torques batched and not."""
    ctrl = load_controller("step-ppo/s0")
    zs = np.asarray(ctrl.base.z_ref, dtype=float)
    Z = zs + 0.2 * np.abs(zs) * random_directions(24, 3)
    batched = ClosedLoop(ctrl).run_many(Z, zs, 25)
    monkeypatch.setattr(residual_mod, "profile_rows", lambda copies, obs: None)
    bases_alone = ClosedLoop(ctrl).run_many(Z, zs, 25)
    monkeypatch.setattr(type(ctrl), "act_rows", None)  # one call per robot
    alone = ClosedLoop(ctrl).run_many(Z, zs, 25)
    assert repr(batched) == repr(bases_alone) == repr(alone)
    assert 0 < sum(ok for ok, *_ in alone) < len(Z)  # some held, some not: a real test
