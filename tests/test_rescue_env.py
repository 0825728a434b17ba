"""Tests of the rescue task PassiveBoundRescue-v0 (bound_env/rescue_env.py) and its discrete
wrapper (bound_env.wrappers.LibraryActions): the env checkers, the task's rules, the same
strides as the stride map, bad input, and plain SB3 PPO on it."""

import warnings

import gymnasium as gym
import numpy as np
import pytest

import bound_env
from bound_env import RESCUE_ENV_ID
from bound_env.wrappers import LibraryActions, default_library

gym.register_envs(bound_env)


@pytest.fixture(scope="module")
def student():
    from agents.policy import load_controller

    return load_controller("default")


def student_env(student, **kw):
    """The rescue env + wrapper on the student's own LQR and library (as `bound-env finetune`)."""
    from agents.finetune import rescue_env_kwargs

    env = gym.make(RESCUE_ENV_ID, **rescue_env_kwargs(student), **kw)
    return LibraryActions(env, student.rows)


def test_the_same_strides_as_the_stride_map(student):
    """A few seeded episodes and actions: the env + wrapper's starts and apex states after each
    stride are bit for bit those of the student's own plant (`agents.distill.stride_of` on
    `plant_of`, the primitives of fine-tuning's former private env), and so are its rewards."""
    from agents.distill import plant_of, sample_starts, stride_of

    plant = plant_of(student)
    env = student_env(student)
    rng = np.random.default_rng(1)
    strides = falls = returns = 0
    for seed in range(6):
        obs, info = env.reset(seed=seed)
        ref_rng = np.random.default_rng(seed)
        while True:
            z = sample_starts(ref_rng, 1, student.z_ref, 0.45, 0.25)[0]
            if np.max(np.abs(z - student.z_ref) / student.scales) > student.safe:
                break
        assert np.array_equal(info["start_z"], z)
        assert np.array_equal(obs, ((z - student.z_ref) / student.scales).astype(np.float32))
        for k in range(1, 31):
            a = int(rng.integers(len(student.rows))) if k % 2 else 0
            u = student.lqr.coefficients(z) if a == 0 else student.rows[a]
            z1 = stride_of(student, plant, z, u)
            obs, r, term, trunc, info = env.step(a)
            strides += 1
            if z1 is None:
                assert term and info["fell"] and r == 0.0
                falls += 1
                break
            assert np.array_equal(info["apex_z"], z1) and np.array_equal(env.unwrapped.z, z1)
            z = z1
            if np.max(np.abs(z - student.z_ref) / student.scales) <= student.safe:
                assert term and info["returned"] and r == 1.0 + 30 - k
                returns += 1
                break
            assert r == 1.0 and not term and trunc == (k == 30)
    assert strides > 12 and falls > 0, (strides, falls, returns)


@pytest.mark.parametrize("discrete", [False, True])
def test_gymnasium_and_sb3_env_checkers_pass_without_warnings(discrete):
    from gymnasium.utils.env_checker import check_env
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    env = gym.make(RESCUE_ENV_ID)
    if discrete:
        env = LibraryActions(env)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        if not discrete:
            check_env(env.unwrapped)
            sb3_check_env(env.unwrapped)
        sb3_check_env(env)
    env.close()


def test_defaults_are_the_shipped_mpc_spec_and_the_students_library(student):
    """The defaults: the mpc spec's LQR (its stored gain), safe radius and basis; the
    wrapper's default library is the one the shipped `default` chooses from."""
    from bound_env.control import load_controller

    env = gym.make(RESCUE_ENV_ID).unwrapped
    mpc = load_controller("mpc")
    assert env.action_space.shape == (mpc.basis.K,) == (8,)
    assert np.array_equal(env.lqr.gain, mpc.lqr.gain) and env.safe == mpc.safe
    assert np.array_equal(env.lqr.basis.edges, mpc.basis.edges)
    assert (env.r_max, env.axis_prob, env.horizon) == (0.45, 0.25, 30)
    lib = default_library(8)
    assert np.array_equal(lib[1:], student.rows[1:])
    assert LibraryActions(gym.make(RESCUE_ENV_ID)).action_space.n == len(lib) == 4 + 2 * 7 + 48
    # another basis or K: the LQR is designed for it (the stored gain has the wrong shape)
    hats = gym.make(RESCUE_ENV_ID, basis="hats", K=5).unwrapped
    assert hats.lqr.gain.shape == (5, 6) and hats.lqr.design["source"] == "designed"


def test_a_return_ends_the_episode_with_the_strides_left(student):
    """From a start just past the safe radius the LQR's plan returns at once: reward
    1 + (horizon - 1); a start far out under full torque falls: reward 0."""
    env = gym.make(RESCUE_ENV_ID, horizon=12)
    base = env.unwrapped
    z = base.z_ref + 1.2 * base.safe * base.scales * np.eye(6)[3]  # a small xdot error
    obs, info = env.reset(options={"apex_state": z})
    assert base.past_safe(z) and np.array_equal(info["start_z"], z)
    _, r, term, trunc, info = env.step(base.lqr.coefficients(z).astype(np.float32))
    assert info["returned"] and term and not trunc and r == 12.0
    assert info["reward_alive"] + info["reward_bonus"] == r and info["error"] <= base.safe
    env.reset(options={"apex_state": base.z_ref + 0.45 * np.abs(base.z_ref) * -np.eye(6)[0]})
    _, r, term, _, info = env.step(np.ones(8, dtype=np.float32))
    assert term and info["fell"] and r == 0.0 and info["failure"] is not None


def test_starts_lie_past_the_safe_radius_and_episodes_truncate_at_the_horizon():
    env = gym.make(RESCUE_ENV_ID, horizon=3, r_max=0.1)
    base = env.unwrapped
    for seed in range(20):
        _, info = env.reset(seed=seed)
        assert base.past_safe(info["start_z"])
        assert base.error(info["start_z"]) <= 0.1 * np.max(np.abs(base.z_ref) / base.scales)
    # the LQR's plan on tiny starts never falls; those that do not return in 3 are cut
    for seed in range(6):
        env.reset(seed=seed)
        term = trunc = False
        k = 0
        while not (term or trunc):
            _, _, term, trunc, info = env.step(base.lqr.coefficients(base.z))
            k += 1
        assert not info["fell"] and k <= 3 and (term or k == 3)


@pytest.mark.parametrize(
    "kw, message",
    [
        ({"safe": 0}, "safe"),
        ({"r_max": float("nan")}, "r_max"),
        ({"axis_prob": 1.5}, "axis_prob"),
        ({"horizon": 0}, "horizon"),
        ({"horizon": 2.5}, "horizon"),
        ({"K": 0}, "K"),
        ({"controller": "damping"}, "damping"),
        ({"gain": [[1.0] * 6] * 3}, "gain"),
        ({"max_torque": -1}, "max_torque"),
    ],
)
def test_bad_arguments_are_refused(kw, message):
    with pytest.raises(ValueError, match=message):
        gym.make(RESCUE_ENV_ID, **kw)


def test_bad_actions_and_starts_are_refused():
    env = gym.make(RESCUE_ENV_ID)
    with pytest.raises(ValueError, match="apex_state"):
        env.reset(options={"apex_state": [1.0, 2.0]})
    env.reset(seed=0)
    with pytest.raises(ValueError, match="finite"):
        env.step(np.full(8, np.nan))
    with pytest.raises(ValueError, match="K=8"):
        env.step(np.zeros(3))
    lib = LibraryActions(gym.make(RESCUE_ENV_ID))
    lib.reset(seed=0)
    with pytest.raises(ValueError, match="action must be in"):
        lib.step(66)
    with pytest.raises(ValueError, match="rows"):
        LibraryActions(gym.make(RESCUE_ENV_ID), np.full((3, 8), 2.0))
    with pytest.raises(ValueError, match="rows"):
        LibraryActions(gym.make(RESCUE_ENV_ID), np.zeros((3, 4)))


def test_plain_sb3_ppo_learns_on_it():
    """`gymnasium.make` + plain SB3 PPO, a few hundred strides: it runs, and its actions are
    finite coefficients."""
    import torch
    from stable_baselines3 import PPO

    torch.set_num_threads(1)
    env = gym.make(RESCUE_ENV_ID)
    model = PPO("MlpPolicy", env, n_steps=128, batch_size=64, n_epochs=2, seed=0, device="cpu")
    model.learn(384)
    assert model.num_timesteps >= 384 and len(model.ep_info_buffer) > 0
    obs, _ = env.reset(seed=1)
    act, _ = model.predict(obs, deterministic=True)
    assert act.shape == (8,) and np.all(np.isfinite(act))
    assert np.all(np.isfinite([e["r"] for e in model.ep_info_buffer]))


def test_the_shipped_config_section_makes_the_env():
    """configs/ppo-rescue.yaml's section is what `bound-env train --env-id
    PassiveBoundRescue-v0` reads: PPO takes its hyperparameters and its env_kwargs make the
    env with continuous actions."""
    from stable_baselines3 import PPO

    from agents.config import preprocess
    from agents.train import check_algo_kwargs, check_env_spec, resolve_section

    spec = preprocess(resolve_section("ppo-rescue", RESCUE_ENV_ID, None, None))
    check_algo_kwargs(spec.algo_kwargs, PPO)
    check_env_spec(RESCUE_ENV_ID, spec)
    env = gym.make(RESCUE_ENV_ID, **spec.env_kwargs)
    assert isinstance(env.action_space, gym.spaces.Box) and env.action_space.shape == (8,)
