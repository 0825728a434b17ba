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


def test_the_same_trajectories_as_the_former_choice_env(student):
    """Against `agents.finetune.ChoiceStrideEnv` (the private env it replaces), bit for bit."""
    from agents.finetune import ChoiceStrideEnv

    old, new = ChoiceStrideEnv(student), student_env(student)
    rng = np.random.default_rng(2)
    compared = 0
    for seed in range(5):
        o1, _ = old.reset(seed=seed)
        o2, _ = new.reset(seed=seed)
        assert np.array_equal(o1, o2)
        done = False
        while not done:
            a = int(rng.integers(len(student.rows))) if rng.random() < 0.5 else 0
            o1, r1, t1, u1, i1 = old.step(a)
            o2, r2, t2, u2, i2 = new.step(a)
            assert np.array_equal(old.z, new.unwrapped.z) and np.array_equal(o1, o2)
            assert (r1, t1, u1) == (r2, t2, u2)
            compared += 1
            done = t1 or u1
    assert compared > 10
