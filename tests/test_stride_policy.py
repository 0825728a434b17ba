"""Learned stride-level control (agents/runtime/stride.py): the residual starts as the LQR exactly,
the NumPy controller matches the trained network, the training wrappers do what they say."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from agents.common.config import load_hyperparams, preprocess
from agents.common.policy_files import write_fingerprint
from agents.runtime.stride import (
    BASE_FILE,
    STRIDE_ENV_ID,
    DirectionStarts,
    StrideControl,
    YardstickReward,
    ZeroActionNet,
)
from agents.runtime.stride_policy import StridePolicyController, load_stride_policy

CONFIG = Path(__file__).resolve().parent.parent / "configs" / "ppo-stride.yaml"
TINY = ["n_envs=2", "n_steps=64", "batch_size=64", "n_epochs=1"]


def _zero_residual_policy(tmp_path) -> Path:
    """A fresh residual policy of configs/ppo-stride.yaml with ZeroActionNet applied, saved as a
    run directory (model.zip, config.yaml, base.json), without any training update."""
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecNormalize

    from agents.common.run_files import write_config
    from agents.runtime.stride_policy import write_base
    from agents.training.train import make_vec, resolve_section

    hp = resolve_section(CONFIG, STRIDE_ENV_ID, TINY, None)
    spec = preprocess(hp)
    venv = make_vec(STRIDE_ENV_ID, spec, 1, 0, "dummy")
    model = PPO(env=venv, seed=0, device="cpu", **spec.algo_kwargs)
    cb = ZeroActionNet()
    cb.init_callback(model)
    cb.on_training_start({}, {})
    run = tmp_path / "run"
    run.mkdir()
    model.save(run / "model.zip")
    VecNormalize(venv, norm_obs=False, norm_reward=True).save(str(run / "vecnormalize.pkl"))
    write_config(run / "config.yaml", STRIDE_ENV_ID, hp, 0)
    write_base(run, venv)
    write_fingerprint(run)  # as training does at its end
    venv.close()
    return run


@pytest.fixture(scope="module")
def zero_run(tmp_path_factory):
    return _zero_residual_policy(tmp_path_factory.mktemp("zero"))


def test_config_parses_and_wraps_the_stride_env():
    hp = load_hyperparams(CONFIG, STRIDE_ENV_ID)
    spec = preprocess(hp)
    assert [c.__name__ for c, _ in spec.wrappers] == [
        "DirectionStarts",
        "StrideControl",
        "YardstickReward",
    ]
    assert [c.__name__ for c, _ in spec.callbacks] == ["ZeroActionNet"]
    assert spec.env_kwargs["K"] == 8 and spec.env_kwargs["basis"] == "windows"


def test_zero_residual_reproduces_the_lqr_exactly(zero_run):
    from bound_env.analysis.margins import ClosedLoop
    from bound_env.control import load_controller as load_classical

    lqr = load_classical("lqr")
    ctrl = load_stride_policy(zero_run)
    assert isinstance(ctrl, StridePolicyController)
    assert json.loads((zero_run / BASE_FILE).read_text())["gain"] == lqr.gain.tolist()
    rng = np.random.default_rng(1)
    z_ref = lqr.z_ref
    for _ in range(20):  # including saturated coefficients
        z = z_ref + 0.3 * np.abs(z_ref) * rng.uniform(-1, 1, 6)
        assert np.all(ctrl.residual(z) == 0.0)
        np.testing.assert_array_equal(ctrl.stride_action(z), lqr.stride_action(z))
    # in the step env (margins' closed loop): the same apex map, bit for bit
    z0 = z_ref + 0.05 * np.abs(z_ref) * np.array([1, -1, 1, -1, 1, -1])
    a, b = ClosedLoop(ctrl), ClosedLoop(lqr)
    za, zb = z0, z0
    for _ in range(3):
        za, zb = a.map(za), b.map(zb)
        assert za is not None
        np.testing.assert_array_equal(za, zb)


def test_numpy_controller_matches_the_network_and_the_wrapper(zero_run, tmp_path):
    """Non-zero last-layer weights: the NumPy controller's coefficients are those the
    training env applies for the network's deterministic action."""
    import gymnasium as gym
    import torch as th
    from stable_baselines3 import PPO

    import bound_env

    model = PPO.load(str(zero_run / "model.zip"), device="cpu")
    with th.no_grad():
        model.policy.action_net.weight.normal_(0.0, 0.5)
        model.policy.action_net.bias.normal_(0.0, 0.1)
    run = tmp_path / "run"
    run.mkdir()
    model.save(run / "model.zip")
    for name in ("config.yaml", BASE_FILE, "vecnormalize.pkl"):
        (run / name).write_bytes((zero_run / name).read_bytes())
    write_fingerprint(run)  # a policy of its own: its fingerprint (issue 40)
    ctrl = load_stride_policy(run)
    gym.register_envs(bound_env)
    env = StrideControl(gym.make(STRIDE_ENV_ID), base_gain=ctrl.base)
    rng = np.random.default_rng(2)
    for _ in range(10):
        z = ctrl.z_ref + 0.2 * np.abs(ctrl.z_ref) * rng.uniform(-1, 1, 6)
        act, _ = model.predict(env.observe(z), deterministic=True)
        want = env.coefficients(z, np.clip(act, -1, 1))
        np.testing.assert_allclose(ctrl.stride_action(z), want, atol=1e-6)
    # and it acts in the step env: a torque within the saturation, a stride to the next apex
    from bound_env.analysis.margins import ClosedLoop

    out = ClosedLoop(ctrl).stride(ctrl.z_ref)
    assert out.failure is None or isinstance(out.failure, str)
    assert 0.0 <= out.effort <= ctrl.max_torque or out.failure is not None


def test_margins_loads_a_stride_policy_by_path(zero_run):
    from agents.runtime.policy import load_controller

    ctrl = load_controller(zero_run)
    assert isinstance(ctrl, StridePolicyController)
    assert ctrl.env_kwargs["max_torque"] == 80.0
    assert len(ctrl.fingerprint()) == 16


def _stride_env():
    import gymnasium as gym

    import bound_env

    gym.register_envs(bound_env)
    return gym.make(STRIDE_ENV_ID)


def test_direction_starts_use_the_yardstick_scale():
    env = DirectionStarts(_stride_env(), r_max=0.2, axis_prob=0.5)
    z_ref = env.z_ref
    for seed in range(30):
        env.reset(seed=seed)
        x = (env.unwrapped.z - z_ref) / np.abs(z_ref)
        assert np.max(np.abs(x)) <= 0.2 + 1e-12
    with pytest.raises(ValueError, match="r_min"):
        DirectionStarts(_stride_env(), r_max=0.1, r_min=0.2)


def test_yardstick_reward_contraction_and_early_falls_cost_more():
    env = YardstickReward(
        StrideControl(_stride_env(), base=None), ctrl_weight=0.0, fall_penalty=10.0, horizon=10
    )
    env.reset(options={"apex_state": env.z_ref})  # on the cycle: e at its floor, no contraction
    _, r, term, _, _ = env.step(np.zeros(env.unwrapped.task.K))
    assert not term and r == pytest.approx(1.0)
    z_low = env.z_ref.copy()
    z_low[0] *= 0.5  # hips far below their touchdown height: falls in the first stride
    env.reset(options={"apex_state": z_low})
    _, r, term, _, info = env.step(np.zeros(env.unwrapped.task.K))
    assert term and info["failure"] is not None and r == pytest.approx(-10.0)
    with pytest.raises(ValueError, match="residual_scale"):
        StrideControl(_stride_env(), base=None, residual_scale=0.0)


@pytest.mark.slow
def test_training_smoke_run_exports_a_policy_that_acts(tmp_path):
    from agents.cli import export_policy
    from agents.training.train import train
    from bound_env.analysis.margins import ClosedLoop

    run = train(
        config=CONFIG,
        env_id=STRIDE_ENV_ID,
        seed=0,
        n_timesteps=256,
        sets=TINY,
        runs_dir=tmp_path,
        vec_env="dummy",
        eval_freq=10_000,
        save_freq=10_000,
        progress_bar=False,
    )
    dest = export_policy(run, tmp_path / "exported")
    assert (dest / BASE_FILE).is_file() and (dest / "model.zip").is_file()
    ctrl = load_stride_policy(dest)
    out = ClosedLoop(ctrl).stride(ctrl.z_ref)
    assert out.z1 is not None  # a quarter-trained residual still completes a stride from z*
    assert json.loads((run / "run.json").read_text())["timesteps_done"] >= 256


def test_anchored_policy_keeps_the_cycle_whatever_the_weights(zero_run, tmp_path):
    """AnchoredMlpPolicy: the residual is zero at z*, so z* stays the closed loop's cycle and
    the coefficients there are the LQR's (zero), for random weights in every layer."""
    import torch as th
    from stable_baselines3 import PPO

    model = PPO.load(str(zero_run / "model.zip"), device="cpu")
    assert type(model.policy).__name__ == "AnchoredMlpPolicy"
    with th.no_grad():
        for p in model.policy.parameters():
            p.normal_(0.0, 0.5)
    act, _ = model.predict(np.zeros(6, dtype=np.float32), deterministic=True)
    assert np.all(act == 0.0)
    run = tmp_path / "run"
    run.mkdir()
    model.save(run / "model.zip")
    for name in ("config.yaml", BASE_FILE, "vecnormalize.pkl"):
        (run / name).write_bytes((zero_run / name).read_bytes())
    write_fingerprint(run)  # a policy of its own: its fingerprint (issue 40)
    ctrl = load_stride_policy(run)
    assert ctrl.anchored and ctrl.gate_scale > 0
    np.testing.assert_array_equal(ctrl.stride_action(ctrl.z_ref), np.zeros(ctrl.phi.shape[1]))
    assert np.any(ctrl.residual(ctrl.z_ref * 1.05) != 0.0)
    # the gate: the residual vanishes faster than linearly, so the closed loop's Jacobian at z*
    # is the LQR's (a linear residual would shrink 10x for a 10x smaller step, this ~1000x)
    d = np.abs(ctrl.z_ref) * np.array([1.0, -0.5, 0.3, 0.8, -1.0, 0.2])
    big, small = (np.max(np.abs(ctrl.residual(ctrl.z_ref + h * d))) for h in (1e-2, 1e-3))
    assert 0 < small < big / 50


@pytest.mark.slow
def test_checkpoint_without_observation_normalization(tmp_path):
    """norm_obs=False (the stride configs): a checkpoint is written and the run resumes."""
    from agents.training.checkpoints import last_checkpoint
    from agents.training.train import train

    run = train(
        config=CONFIG,
        env_id=STRIDE_ENV_ID,
        seed=0,
        n_timesteps=256,
        sets=TINY,
        runs_dir=tmp_path,
        vec_env="dummy",
        eval_freq=10_000,
        save_freq=128,
        progress_bar=False,
    )
    assert last_checkpoint(run) is not None
