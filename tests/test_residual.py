"""Step-level residual PPO over a stride controller (agents/runtime/residual.py)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import bound_env
from agents.runtime.controllers import MLPController
from agents.runtime.policy import load_controller
from agents.runtime.residual import ResidualController, ResidualOver, validation_curve
from bound_env.analysis.margins.closed_loop import ClosedLoop
from bound_env.control import notify_apex

gym.register_envs(bound_env)
ENV_KW = dict(
    gait="default",
    max_torque=80.0,
    rtol=1e-8,
    max_episode_steps=800,
    tracking_cost_weight=0.0,
    ctrl_cost_weight=0.0,
)  # fmt: skip  (the ppo-residual task: survival only)


def _net(n_in: int, scale_out: float, seed: int = 0) -> MLPController:
    """A tanh MLP on the residual's features; a zero action layer when scale_out is 0."""
    rng = np.random.default_rng(seed)
    W1, b1 = rng.normal(0, 0.3, (16, n_in)), rng.normal(0, 0.1, 16)
    W2, b2 = scale_out * rng.normal(0, 1, (1, 16)), scale_out * np.ones(1)
    return MLPController(name="net", layers=[(W1, b1), (W2, b2)], activation="Tanh")


@pytest.fixture(scope="module")
def base():
    return load_controller("default")


def _residual(base, scale_out: float) -> ResidualController:
    env = gym.make("PassiveBound-v0", **ENV_KW)
    w = ResidualOver(env, base="default")
    n_in, keep = w.observation_space.shape[0], w.keep
    env.close()
    return ResidualController(
        name="r", base=base, net=_net(n_in, scale_out), scale=0.5, keep=keep,
        env_kwargs={"gait": "default", "max_torque": 80.0, "dt": 0.01},
    )  # fmt: skip


def test_wrapper_passes_gymnasiums_checker():
    from gymnasium.utils.env_checker import check_env

    env = ResidualOver(gym.make("PassiveBound-v0", **ENV_KW))
    check_env(env.unwrapped)
    obs, _ = env.reset(seed=3)
    assert env.observation_space.contains(obs)
    assert env.action_space.shape == (1,)


def test_zero_residual_steps_as_the_base_controller(base):
    """A zero residual gives the env exactly the base's actions (the plain notify_apex loop)."""
    env = ResidualOver(gym.make("PassiveBound-v0", **ENV_KW))
    ref = gym.make("PassiveBound-v0", **ENV_KW)
    ctrl = load_controller("default")
    obs, info = env.reset(seed=11)
    z0 = info["start_z"]
    assert env.gate == 1.0  # training starts are past the safe radius
    robs, rinfo = ref.reset(options={"apex_state": z0})
    notify_apex(ctrl, robs, rinfo)
    n_keep = len(env.keep)
    for _ in range(120):
        a = ctrl(robs)
        assert env.base_action == a
        obs, _, term, trunc, info = env.step(np.zeros(1))
        robs, _, rterm, _, rinfo = ref.step(np.array([a], np.float32))
        notify_apex(ctrl, robs, rinfo)
        assert np.array_equal(obs[:n_keep], robs[env.keep])
        assert term == rterm or info.get("returned")
        if term:
            break


def test_a_return_ends_the_episode_with_the_steps_left_as_bonus():
    env = ResidualOver(gym.make("PassiveBound-v0", **ENV_KW), r_max=0.1)
    returned = 0
    for seed in range(6):
        env.reset(seed=seed)
        k = 0
        while True:
            _, r, term, trunc, info = env.step(np.zeros(1))
            k += 1
            if term or trunc:
                break
        if info.get("returned"):
            returned += 1
            assert r == pytest.approx(1.0 + (800 - k))
    assert returned >= 1


def test_zero_residual_controller_matches_default_on_the_closed_loop(base):
    ctrl = _residual(base, 0.0)
    zs = base.z_ref
    rng = np.random.default_rng(4)
    d = rng.standard_normal((4, 6))
    Z = zs + 0.22 * np.abs(zs) * d / np.abs(d).max(axis=1, keepdims=True)
    a = ClosedLoop(base).run_many(Z, zs, 25)
    b = ClosedLoop(ctrl).run_many(Z, zs, 25)
    assert a == b


def test_the_residual_acts_only_past_the_safe_radius(base):
    """Past the safe radius the network acts: a start there ends elsewhere after one stride
    than under the base alone (and with a zero network exactly where the base ends); on the
    cycle the gate is closed and the action is the base's."""
    ctrl = _residual(base, 1.0)
    z_in = base.z_ref.copy()  # on the cycle: the gate is closed, the action is the base's
    loop = ClosedLoop(ctrl)
    obs, info = loop.env.reset(options={"apex_state": z_in})
    ctrl.on_apex(z_in, 0.0)
    assert ctrl(obs) == base(obs)
    z_out = base.z_ref + 0.15 * np.abs(base.z_ref) * np.array([0, 0, 0, 1, 0, 0])
    assert np.max(np.abs(z_out - base.z_ref) / base.scales) > base.safe  # the gate is open
    after_base = ClosedLoop(base).stride(z_out)
    after_zero = ClosedLoop(_residual(base, 0.0)).stride(z_out)
    after_net = ClosedLoop(ctrl).stride(z_out)
    assert after_base.z1 is not None and np.array_equal(after_zero.z1, after_base.z1)
    if after_net.z1 is not None:  # the outcome changed: another apex state, or a fall
        err = np.max(np.abs(after_net.z1 - after_base.z1) / base.scales)
        assert err > 1e-3, err


def test_decision_kinds_are_recorded_per_apex_decision(base):
    n0 = len(base.decision_kinds)
    base.coefficients(base.z_ref)  # within the safe radius: the gate
    z = base.z_ref + 0.3 * np.abs(base.z_ref) * np.array([0, 0, 0, 1, 0, 0])
    base.coefficients(z)
    kinds = base.decision_kinds[n0:]
    assert kinds[0] == "gate" and kinds[1] in ("lqr", "override")


def test_bad_settings_are_refused():
    env = gym.make("PassiveBound-v0", **ENV_KW)
    with pytest.raises(ValueError, match="scale"):
        ResidualOver(env, scale=0.0)
    with pytest.raises(ValueError, match="max_torque"):
        ResidualOver(gym.make("PassiveBound-v0", **{**ENV_KW, "max_torque": 40.0}))
    with pytest.raises(ValueError, match="no z_ref|stride controller"):
        ResidualOver(env, base="damping")


@pytest.mark.slow
def test_validation_curve_of_default_beats_lqr_at_a_large_size(base):
    """The validation yardstick separates default from its LQR (seed 777, not the test set)."""
    sizes = (0.25,)
    d = validation_curve(base, sizes=sizes, n_dirs=24, strides=30)
    lq = validation_curve(load_controller("lqr"), sizes=sizes, n_dirs=24, strides=30)
    assert d["seed"] == 777 and d["n_dirs"] == 24
    assert d["rates"][0] > lq["rates"][0]


@pytest.mark.slow
def test_train_config_runs_and_loads_as_a_residual_controller(tmp_path):
    """`bound-env train --config ppo-residual` end to end (tiny), then load and act."""
    from agents.training.train import train

    run = train(
        "ppo-residual", "PassiveBound-v0", name="r", n_timesteps=1024, runs_dir=tmp_path,
        vec_env="dummy", eval_freq=1024, n_eval_episodes=1, progress_bar=False,
        sets=["n_envs=2", "n_steps=256", "batch_size=128"],
    )  # fmt: skip
    ctrl = load_controller(run)
    assert isinstance(ctrl, ResidualController)
    zs = ctrl.base.z_ref
    ok, n, _ = ClosedLoop(ctrl).run(zs, zs, 3)
    assert ok or n == 3


def test_the_gate_ramps_from_the_safe_radius(base):
    from agents.runtime.residual import _Gate

    g = _Gate(base, ramp=0.2)
    s = base.scales
    assert g(base.z_ref)[1] == 0.0
    e = base.safe + 0.1  # half the ramp past the safe radius, along y
    z = base.z_ref + np.array([e, 0, 0, 0, 0, 0]) * s
    assert g(z)[1] == pytest.approx(0.5)
    z = base.z_ref + np.array([base.safe + 0.3, 0, 0, 0, 0, 0]) * s
    assert g(z)[1] == 1.0 and _Gate(base)(z)[1] == 1.0  # ramp 0: a step
    with pytest.raises(ValueError, match="ramp"):
        ResidualOver(gym.make("PassiveBound-v0", **ENV_KW), ramp=-1.0)


def test_act_rows_gives_each_copy_its_own_action(base, monkeypatch):
    """`ResidualController.act_rows` (the batched loop's one call for all robots) is each
    copy called alone: exactly the base's action where the gate is closed, the same to
    rounding where the network acts (one forward pass, each row computed alone); and the
    batched closed loop through it ends every robot as the row-by-row loop does."""
    import copy

    ctrl = _residual(base, 1.0)
    zs = base.z_ref
    rng = np.random.default_rng(5)
    d = rng.standard_normal((7, 6))
    Z = np.vstack([zs, zs + 0.2 * np.abs(zs) * d / np.abs(d).max(axis=1, keepdims=True)])
    env = gym.make("PassiveBound-v0", **ENV_KW)
    obs, alone, rows = [], [], []
    for z in Z:
        o, _ = env.reset(options={"apex_state": z})
        for group in (alone, rows):
            c = copy.deepcopy(ctrl)
            c.on_apex(z, 0.0)
            group.append(c)
        obs.append(o)
    env.close()
    obs = np.stack(obs)
    gates = np.array([c._gate for c in rows])
    assert gates[0] == 0.0 and (gates[1:] > 0).sum() >= 4  # closed on the cycle, open past it
    got = ctrl.act_rows(rows, obs)
    want = np.array([c(o) for c, o in zip(alone, obs, strict=True)])
    bases = np.array([float(c.base(o)) for c, o in zip(alone, obs, strict=True)])
    assert got[0] == want[0] == bases[0]
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
    assert np.any(np.abs(want[1:] - bases[1:]) > 1e-3)  # the network acts past the radius
    batched = ClosedLoop(ctrl).run_many(Z[1:], zs, 20)
    monkeypatch.setattr(ResidualController, "act_rows", None)  # row by row
    assert ClosedLoop(ctrl).run_many(Z[1:], zs, 20) == batched
