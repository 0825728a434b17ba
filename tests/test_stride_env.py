"""Tests of PassiveBoundStride-v1: a step is the step env's stride (bit for bit), zero action is
the passive Poincare map, the profile's interval torques match the reference back-end, bases,
rewards, failures, arguments, seeding and both env checkers."""

import warnings
from dataclasses import replace

import gymnasium as gym
import numpy as np
import pytest

import bound_env
from bound_env.model.dynamics import make_aux
from bound_env.model.hybrid import (
    APEX,
    FAILURES,
    N_FLAGS,
    TIME_UP,
    simulate_reference,
    simulate_stride,
    state_from_z,
    z_from_state,
)
from bound_env.model.params import P_TAU, load_gait
from bound_env.sim.stride_task import make_basis
from bound_env.sim.task import APEX_SCALES

gym.register_envs(bound_env)
ENV_ID = "PassiveBoundStride-v1"
GAIT = load_gait("default")
Z_STAR = GAIT.z0


def make(**kw):
    return gym.make(ENV_ID, **kw)


def step_env_stride(z, a, **kw):
    """The stride of a PassiveBound-v0 episode started at the apex z, interval k stepped with
    the action a[min(k, len - 1)]: (apex_z, failure)."""
    env = gym.make("PassiveBound-v0", max_torque=80.0, rtol=1e-10, **kw).unwrapped
    env.reset(options={"apex_state": z})
    for k in range(300):
        _, _, terminated, _, info = env.step(np.array([a[min(k, len(a) - 1)]]))
        if "apex_z" in info:
            return info["apex_z"], None
        if terminated:
            return None, info["failure"]
    return None, "no_apex"


def test_zero_action_is_the_passive_poincare_map():
    env = make(reset_noise_scale=0.0)
    obs, info = env.reset(seed=0)
    np.testing.assert_array_equal(info["start_z"], Z_STAR)
    z = Z_STAR + np.array([0.004, 0.02, -0.03, 0.03, 0.3, -0.2])  # off the cycle
    env.reset(options={"apex_state": z})
    _, reward, terminated, _, info = env.step(np.zeros(4, np.float32))
    ref = simulate_stride(z, GAIT.params, rtol=1e-10, atol=1e-10)
    assert not terminated and ref.failure is None
    # the step env's grid (the integrator stops every 10 ms) and the one-call passive stride:
    # the same map up to the integrator tolerance (rtol = atol = 1e-10; seen: 2e-10 relative,
    # 8e-11 absolute)
    np.testing.assert_allclose(info["apex_z"], ref.z1, rtol=1e-9, atol=1e-9)
    assert info["period"] == pytest.approx(ref.t_end, abs=1e-9)
    assert info["effort"] == 0.0 and info["reward_ctrl"] == 0.0
    # exactly the step env's stride
    np.testing.assert_array_equal(info["apex_z"], step_env_stride(z, [0.0])[0])
    # and through the reference back-end (solve_ivp), to the integrator tolerance
    slow = simulate_stride(z, GAIT.params, backend="reference")
    np.testing.assert_allclose(info["apex_z"], slow.z1, rtol=0, atol=1e-7)


def test_fifty_zero_action_strides_stay_on_the_cycle():
    env = make(reset_noise_scale=0.0)
    env.reset(seed=0)
    worst = 0.0
    for k in range(50):
        obs, reward, terminated, truncated, info = env.step(np.zeros(4, np.float32))
        assert not terminated and not truncated
        err = float(np.max(np.abs(info["apex_z"] - Z_STAR)))
        assert err < 1e-9, (k, err)  # from the first stride on
        worst = max(worst, err)
        assert reward == pytest.approx(1.0, abs=1e-12)
        # the observation is the apex state rounded to float32, nothing else: its distance
        # from z* (up to 1.3e-7 rad/s in theta1dot) is that rounding, not a drift
        np.testing.assert_array_equal(obs, info["apex_z"].astype(np.float32))
    assert worst < 1e-9
    np.testing.assert_array_equal(obs, Z_STAR.astype(np.float32))


def reference_profile(z, dt, taus, params):
    """The same interval torques with the reference back-end (solve_ivp): one call per
    control interval, the last torque held until the apex."""
    y = state_from_z(z)
    aux = make_aux(params.to_array())
    flags = np.zeros(N_FLAGS, dtype=np.bool_)
    t = 0.0
    for j, tau in enumerate(taus):
        aux[P_TAU] = tau
        t_end = (j + 1) * dt if j < len(taus) - 1 else 2.0
        status, t, y, _, _ = simulate_reference(y, aux, flags, t0=t, t_end=t_end)
        if status != TIME_UP:
            break
    assert status == APEX
    return z_from_state(y), t


@pytest.mark.parametrize("basis", ["windows", "phases", "hats"])
def test_a_stride_is_the_step_envs_stride(basis):
    """One step is the step env's stride with the profile's interval averages (bit for bit),
    also on a stride longer than the nominal one (the last window holds past T), and it
    matches the reference back-end on the same interval torques."""
    env = make(basis=basis, K=None if basis == "phases" else 4).unwrapped
    z = Z_STAR + np.array([0.01, 0.0, 0.0, -0.03, 0.0, 0.0])  # higher, slower: a longer stride
    env.reset(options={"apex_state": z})
    u = np.array([0.2, 0.2, -0.3, 0.3, 0.2][: env.task.K], np.float32)
    _, _, terminated, _, info = env.step(u)
    assert not terminated
    assert info["period"] > env.basis.period  # past the nominal period
    np.testing.assert_array_equal(info["tau_windows"], env.basis.torques(u.astype(float), 80.0))
    a = env.task.sim.actions(u.astype(float))[0]  # interval averages, normalized
    np.testing.assert_array_equal(info["apex_z"], step_env_stride(z, a)[0])
    z_ref, t_ref = reference_profile(z, env.task.dt, 80.0 * a, GAIT.params)
    np.testing.assert_allclose(info["apex_z"], z_ref, rtol=0, atol=2e-7)
    assert info["period"] == pytest.approx(t_ref, abs=1e-9)
    # the profile changed the stride: it is not the passive map
    passive = simulate_stride(z, GAIT.params).z1
    assert np.max(np.abs(info["apex_z"] - passive)) > 1e-3
    # effort = time average of |tau| over the stride, interval by interval
    n = int(np.ceil(info["period"] / env.task.dt))
    t = np.minimum(env.task.dt * np.arange(n + 1), info["period"])
    taus = 80.0 * np.abs(a[np.minimum(np.arange(n), len(a) - 1)])
    assert info["effort"] == pytest.approx(np.dot(taus, np.diff(t)) / info["period"], rel=1e-9)


def test_equal_profiles_on_different_grids_give_the_same_stride():
    """[c, c, d, d] on 4 windows is [c, d] on 2 windows; equal hat coefficients are a constant
    torque (a partition of unity), as is a constant on any grid."""
    z = Z_STAR + np.array([0.003, 0.01, 0.0, 0.02, 0.1, 0.0])

    def apex(u, **kw):
        env = make(**kw).unwrapped
        env.reset(options={"apex_state": z})
        return env.step(np.array(u, np.float32))[4]["apex_z"]

    np.testing.assert_allclose(
        apex([0.25, 0.25, -0.5, -0.5], K=4), apex([0.25, -0.5], K=2), rtol=0, atol=1e-8
    )
    const = step_env_stride(z, [0.25])[0]
    # (the interval weights of 3 windows sum to 1 up to round-off: the same map to 1e-9)
    np.testing.assert_allclose(apex([0.25] * 3, K=3), const, rtol=0, atol=1e-9)
    np.testing.assert_allclose(apex([0.25] * 5, basis="hats", K=5), const, rtol=0, atol=1e-8)
    passive = simulate_stride(z, GAIT.params, tau=0.25 * 80.0).z1  # one call, constant torque
    np.testing.assert_allclose(const, passive, rtol=1e-9, atol=1e-9)


def test_bases():
    T = 0.4
    w = make_basis("windows", 4, T)
    np.testing.assert_allclose(w.edges, [0, 0.1, 0.2, 0.3, 0.4])
    taus = np.array([1.0, 2.0, 3.0, 4.0])
    assert w.average(taus, 0.05, 0.15) == pytest.approx(1.5)
    assert w.average(taus, 0.35, 0.55) == pytest.approx(4.0)  # the last window holds
    assert w.average(taus, 0.2, 0.2) == 3.0
    h = make_basis("hats", 3, T)
    np.testing.assert_allclose(h.phi.sum(axis=1), 1.0)  # partition of unity
    assert h.K == 3 and h.phi[0, 0] > h.phi[7, 0] > 0 and h.phi[8, 0] == 0
    p = make_basis("phases", None, T, [0.1, 0.2, 0.1])
    np.testing.assert_allclose(p.edges, [0, 0.1, 0.3, 0.4])
    env = make(basis="phases").unwrapped
    assert env.task.K == len(GAIT.meta["phases"]) == 5
    np.testing.assert_allclose(np.diff(env.basis.edges), GAIT.meta["durations"], atol=1e-8)


def test_bad_arguments_and_actions():
    for bad, msg in (
        ({"basis": "splines"}, "basis"),
        ({"K": 0}, "K"),
        ({"K": 2.5}, "K"),
        ({"basis": "phases", "K": 3}, "phases"),
        ({"basis": "hats", "K": 1}, "hats"),
        ({"max_torque": -1.0}, "max_torque"),
        ({"rtol": 0.0}, "rtol"),
        ({"reset_noise_scale": np.nan}, "reset_noise_scale"),
    ):
        with pytest.raises(ValueError, match=msg):
            make(**bad)
    env = make()
    env.reset(seed=0)
    with pytest.raises(ValueError, match="finite"):
        env.step(np.array([0, np.nan, 0, 0], np.float32))
    with pytest.raises(ValueError, match="K=4"):
        env.step(np.zeros(3))
    with pytest.raises(ValueError, match="apex_state"):
        env.reset(options={"apex_state": [1.0, 2.0]})


def test_rewards_clipping_and_failures():
    env = make(tracking_cost_weight=2.0, ctrl_cost_weight=0.3, alive_reward=0.5)
    env.reset(seed=4)
    u = np.array([0.2, -0.4, 3.0, 0.0], np.float32)  # 3 is clipped to 1
    _, reward, terminated, _, info = env.step(u)
    assert not terminated
    assert reward == info["reward_alive"] + info["reward_tracking"] + info["reward_ctrl"]
    assert info["reward_alive"] == 0.5
    cost = np.sum(((info["apex_z"] - Z_STAR) / APEX_SCALES) ** 2)
    assert info["reward_tracking"] == pytest.approx(-2.0 * cost, rel=1e-12)
    assert info["reward_ctrl"] == pytest.approx(-0.3 * np.mean(np.square([0.2, -0.4, 1.0, 0])))
    assert info["tau_windows"][2] == 80.0
    # a full reverse torque all stride long makes it fall, with a reason
    env.reset(seed=0)
    for _ in range(20):
        obs, reward, terminated, _, info = env.step(-np.ones(4, np.float32))
        if terminated:
            break
    assert terminated and info["failure"] in FAILURES and info["reward_alive"] == 0.0
    assert "apex_z" not in info and env.observation_space.contains(obs)
    z = Z_STAR.copy()
    z[3] = -0.5
    _, info = env.reset(options={"apex_state": z})
    assert info["failure"] == "moving_backwards"
    _, _, terminated, _, info = env.step(np.zeros(4, np.float32))
    assert terminated and info["failure"] == "moving_backwards"


def test_seeding_noise_and_overrides():
    a, b = make(), make()
    za = a.reset(seed=5)[1]["start_z"]
    np.testing.assert_array_equal(za, b.reset(seed=5)[1]["start_z"])
    step = gym.make("PassiveBound-v0")  # the same start as the step env from the same seed
    np.testing.assert_array_equal(za, step.reset(seed=5)[1]["start_z"])
    assert np.all(np.abs((za - Z_STAR) / APEX_SCALES) <= 0.5)
    over = make(gait_overrides={"alpha_deg": 2.0}, reset_noise_scale=0.0).unwrapped
    assert over.params.alpha == pytest.approx(np.radians(2.0))
    np.testing.assert_array_equal(over.z_ref, Z_STAR)
    over.reset(seed=0)
    z1 = over.step(np.zeros(4))[4]["apex_z"]
    step_z1 = step_env_stride(Z_STAR, [0.0], gait_overrides={"alpha_deg": 2.0})[0]
    np.testing.assert_array_equal(z1, step_z1)
    np.testing.assert_allclose(z1, simulate_stride(Z_STAR, over.params).z1, rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("kw", [{}, {"basis": "phases"}, {"basis": "hats", "K": 6}])
def test_gymnasium_and_sb3_env_checkers_pass_without_warnings(kw):
    from gymnasium.utils.env_checker import check_env
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    env = make(**kw)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(env.unwrapped)
        sb3_check_env(env.unwrapped)
        sb3_check_env(env)
    env.close()


def test_one_config_holds_the_stride_tasks_settings():
    from bound_env.sim.stride_task import StrideTask, StrideTaskConfig

    cfg = StrideTaskConfig(K=8, max_torque=80.0, dt=0.02)
    task = StrideTask(cfg, slope_noise_deg=0.1)
    assert task.config == replace(cfg, slope_noise_deg=0.1)
    assert task.K == 8 and task.dt == 0.02 and task.sim.dt == 0.02
    assert task.step_task.config == task.config.plant()  # the plant: the step env's settings
    with pytest.raises(ValueError, match="unknown stride task setting"):
        StrideTask(cfg, basis_name="windows")
    with pytest.raises(ValueError, match="dt"):
        StrideTask(dt=0.0)
