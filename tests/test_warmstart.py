"""Tests of the warm start of step-level PPO by behaviour cloning (agents/training/warmstart.py)."""

import numpy as np
import pytest


@pytest.fixture(scope="module")
def setup():
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    from agents.common.config import DEFAULT_CONFIG
    from agents.runtime.policy import load_controller
    from agents.training.train import make_env, preprocess, resolve_section

    hp = resolve_section(DEFAULT_CONFIG, "PassiveBound-v0", ["n_envs=1"], 1000)
    spec = preprocess(hp)
    venv = VecNormalize(
        DummyVecEnv([lambda: make_env("PassiveBound-v0", spec.env_kwargs, spec, 0)])
    )
    model = PPO(env=venv, seed=0, device="cpu", **spec.algo_kwargs)
    env = make_env("PassiveBound-v0", spec.env_kwargs, spec, 1)
    return model, venv, env, load_controller("lqr")


def test_the_teacher_data_are_the_teachers_torques(setup):
    from agents.training.warmstart import collect

    _, _, env, teacher = setup
    X, A = collect(env, teacher, seed=0, n_steps=600, progress=False)
    assert X.shape == (600, env.observation_space.shape[0]) and A.shape == (600,)
    assert np.all(np.abs(A) <= 1.0) and np.std(A) > 0  # the LQR acts off the cycle
    assert np.all(np.isfinite(X))


def test_the_clone_fits_the_teacher_and_sets_the_statistics(setup):
    import torch as th

    from agents.training.warmstart import clone, collect

    model, venv, env, teacher = setup
    X, A = collect(env, teacher, seed=1, n_steps=1500, progress=False)
    pol = model.policy

    def rmse():
        xn = np.clip((X - venv.obs_rms.mean) / np.sqrt(venv.obs_rms.var + venv.epsilon), -10, 10)
        with th.no_grad():
            f = pol.extract_features(th.as_tensor(xn, dtype=th.float32), pol.pi_features_extractor)
            a = pol.action_net(pol.mlp_extractor.forward_actor(f)).numpy().ravel()
        return float(np.sqrt(np.mean((np.clip(a, -1, 1) - A) ** 2)))

    out = clone(model, venv, X, A, seed=0, epochs=20)
    np.testing.assert_allclose(venv.obs_rms.mean, X.mean(axis=0))
    assert out["bc_rmse"] == pytest.approx(rmse(), rel=1e-4)
    assert out["bc_rmse"] < 0.5 * out["teacher_rms"]  # it learned the torques, not their mean
