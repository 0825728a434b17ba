"""Every shipped policy and controller in the plain Gymnasium loop (issue 26, §1).

``obs, info = env.reset(...); while ...: obs, r, term, trunc, info = env.step(act(obs, info))``
with ``env = gym.make("PassiveBound-v1")`` and ``act`` from `agents.runtime.rollout.load_policy`
gives the trajectory of the protocol loop (a bare controller told every apex by ``notify_apex``, as
the margins' closed loop and the CLI ran it before) and of ``bound-env rollout``, bit for bit;
and ``act`` refuses the loops that would silently go wrong.
"""

from __future__ import annotations

from dataclasses import replace

import gymnasium as gym
import numpy as np
import pytest

import bound_env
from agents.runtime.policy import load_controller, policy_names
from agents.runtime.policy_table import ARCHIVE_DIR
from agents.runtime.rollout import load_policy, rollout
from bound_env.control import PlainPolicy, notify_apex

gym.register_envs(bound_env)

# archived policies, loaded by their path (agents/policies/archive/)
PPO_V1 = str(ARCHIVE_DIR / "ppo-v1")
STRIDE_RESIDUAL = str(ARCHIVE_DIR / "stride-residual" / "s0")

STRIDES, SEED, NOISE = 5, 3, 0.5


def _plain_env(env_kwargs: dict):
    """gym.make of the v1 id, with only the settings v1 does not default to the policy's (the
    literal gait has its own id; two families were trained, and are rolled out, at rtol 1e-8;
    the reward weights do not change a trajectory)."""
    literal = env_kwargs.get("gait") == "literal-cycle"
    extra = {"rtol": env_kwargs["rtol"]} if "rtol" in env_kwargs else {}
    return gym.make(bound_env.LITERAL_ENV_ID_V1 if literal else bound_env.ENV_ID_V1, **extra)


def _run(env, policy, strides: int):
    """(actions, apex states) of `strides` strides; ``policy(obs, info) -> action``."""
    obs, info = env.reset(seed=SEED, options=None)
    actions, apexes = [], []
    while len(apexes) < strides:
        a = policy(obs, info)
        actions.append(np.asarray(a, dtype=np.float32).copy())
        obs, _, term, trunc, info = env.step(a)
        if "apex_z" in info:
            apexes.append(np.asarray(info["apex_z"]).copy())
        if term or trunc:
            break
    return np.array(actions), np.array(apexes)


@pytest.mark.parametrize("name", policy_names())
def test_plain_loop_gives_the_rollout_trajectory(name):
    make_env, act = load_policy(name)
    plain_env = _plain_env(make_env.env_kwargs)
    if "max_torque" in make_env.env_kwargs:  # (passive acts with none)
        assert plain_env.unwrapped.task.max_torque == make_env.env_kwargs["max_torque"]
    actions, apexes = _run(plain_env, act, STRIDES)
    assert len(apexes) == STRIDES  # every shipped controller keeps this start up

    # the protocol loop: a fresh controller, notify_apex after reset and every step, on the
    # unwrapped env of the policy's own kwargs (the full observation)
    ctrl = load_controller(name)
    ref_env = gym.make("PassiveBound-v0", **make_env.env_kwargs, reset_noise_scale=NOISE)

    def protocol(obs, info):
        notify_apex(ctrl, obs, info)
        return np.array([ctrl(obs)], dtype=np.float32)

    ref_actions, ref_apexes = _run(ref_env, protocol, STRIDES)
    assert np.array_equal(actions, ref_actions)
    assert np.array_equal(apexes, ref_apexes)

    # and bound-env rollout's summary of the same start
    r = rollout(name, strides=STRIDES, seed=SEED, noise=NOISE)
    task = plain_env.unwrapped.task
    errors = np.max(np.abs((apexes - task.z_ref) / task.apex_scales), axis=1)
    assert r["apex_error"] == errors.tolist()
    plain_env.close()
    ref_env.close()


def test_v1_is_the_published_task_and_v0_is_unchanged():
    v1, v0 = gym.make("PassiveBound-v1").unwrapped, gym.make("PassiveBound-v0").unwrapped
    assert v1.task.max_torque == 80.0 and v0.task.max_torque == 40.0
    assert v1.observation_space == v0.observation_space  # the full observation, as v0
    assert v1.task.config == replace(v0.task.config, max_torque=80.0)  # the only change
    lit = gym.make("PassiveBoundLiteral-v1").unwrapped
    assert lit.task.max_torque == 80.0
    for name in ("lqr", "default", PPO_V1, "damping"):  # every shipped policy's torque
        assert load_policy(name)[0].env_kwargs["max_torque"] == 80.0


def _reset(env_id="PassiveBound-v1", **kw):
    env = gym.make(env_id, **kw)
    obs, info = env.reset(seed=SEED)
    return env, obs, info


@pytest.mark.parametrize("name", ["lqr", "default", STRIDE_RESIDUAL])
def test_a_stride_controller_without_info_fails_loudly(name):
    _, act = load_policy(name)
    env, obs, info = _reset()
    with pytest.raises(TypeError, match=r"act\(obs, info\)"):
        act(obs)
    with pytest.raises(TypeError, match="info must be the dict"):
        act(obs, [info])
    a = act(obs, info)  # and it works with it
    assert a.shape == (1,) and a.dtype == np.float32


@pytest.mark.parametrize("name", [PPO_V1, "damping", "passive"])
def test_feedback_policies_take_obs_alone(name):
    make_env, act = load_policy(name)
    env, obs, info = _reset()
    assert np.array_equal(act(obs), act(obs, info))
    # a PPO policy trained through an ObservationFilter takes its make_env's filtered obs too
    obs_f, _ = make_env().reset(seed=SEED)
    assert np.array_equal(act(obs_f), act(obs))


def test_misused_info_is_refused():
    _, act = load_policy("lqr")
    env, obs, info = _reset()
    step_info = env.step(act(obs, info))[-1]
    fresh = PlainPolicy(act.controller)
    with pytest.raises(ValueError, match="info of env.reset"):
        fresh(obs, step_info)
    # an apex passed while the policy was not asked
    act(obs, info)
    while True:
        obs, *_, info = env.step(np.zeros(1, np.float32))
        if "apex_z" in info:
            break
    obs, *_, info = env.step(np.zeros(1, np.float32))
    with pytest.raises(ValueError, match="apex passed without being announced"):
        act(obs, info)
    # a stale info (the reset's again is a new episode; an older step's is refused)
    obs, info = env.reset(seed=SEED)
    act(obs, info)
    obs2, *_, info2 = env.step(act(obs, info))
    act(obs2, info2)
    act(obs2, info2)  # the same step asked twice: allowed, nothing announced again
    with pytest.raises(ValueError, match="not newer"):
        act(obs, {**info2, "time": 0.0})


@pytest.mark.parametrize(
    "env_id, kw, word",
    [
        ("PassiveBound-v0", {}, "max_torque = 40"),  # a bare v0: half the torque
        ("PassiveBound-v1", {"dt": 0.02}, "dt = 0.01"),
        ("PassiveBound-v1", {"exclude_current_positions_from_observation": False}, "obs"),
    ],
)
@pytest.mark.parametrize("name", ["lqr", PPO_V1])
def test_an_env_of_other_settings_is_refused(env_id, kw, word, name):
    _, act = load_policy(name)
    env, obs, info = _reset(env_id, reset_noise_scale=1.0, **kw)
    with pytest.raises(ValueError, match=word):
        for _ in range(50):
            obs, *_, info = env.step(act(obs, info))


def test_a_failed_episode_is_refused():
    _, act = load_policy("passive")
    env, obs, info = _reset(reset_noise_scale=3.0)
    term = False
    while not term:
        obs, _, term, _, info = env.step(act(obs, info))
    with pytest.raises(ValueError, match="episode has ended"):
        act(obs, info)
