"""Tests of PassiveBound-v0: the passive cycle, API checkers, seeding, robustness, rendering,
arguments, and the vector environments (sync, async, native)."""

import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

import bound_env
from bound_env.envs.render import BACK_BODY, FRONT_BODY
from bound_env.model.hybrid import FAILURES
from bound_env.model.params import load_gait
from bound_env.sim.task import APEX_SCALES, OBS_NAMES

gym.register_envs(bound_env)
ENV_ID = "PassiveBound-v0"
ZERO = np.zeros(1, dtype=np.float32)


def make(**kw):
    return gym.make(ENV_ID, **kw)


def obs_of_z(z):
    """The first 7 observation entries at an apex state z: y_g, th1, th2, xdot, 0, th1d, th2d."""
    return np.array([z[0], z[1], z[2], z[3], 0.0, z[4], z[5]], dtype=np.float32)


def assert_infos_equal(a, b, path=""):
    """Batched infos are equal: same keys, dtypes and values (recursing into dicts)."""
    assert set(a) == set(b), (path, sorted(set(a) ^ set(b)))
    for key in a:
        va, vb = a[key], b[key]
        if isinstance(va, dict):
            assert_infos_equal(va, vb, path + key + ".")
            continue
        assert va.dtype == vb.dtype, (path + key, va.dtype, vb.dtype)
        if va.dtype == object:
            for x, y in zip(va, vb, strict=True):
                if isinstance(x, np.ndarray):
                    np.testing.assert_array_equal(x, y)
                else:
                    assert x == y, (path + key, x, y)
        else:
            np.testing.assert_array_equal(va, vb, err_msg=path + key)


# -- the passive cycle ----------------------------------------------------------------------------


def test_zero_action_stays_on_the_passive_cycle():
    env = make(reset_noise_scale=0.0)
    obs, info = env.reset(seed=0)
    z_star = load_gait("default").z0
    np.testing.assert_array_equal(info["start_z"], z_star)
    np.testing.assert_array_equal(obs[:7], obs_of_z(z_star))
    apexes, rewards = [], []
    for _ in range(1300):  # 13 s, 33 strides
        obs, reward, terminated, truncated, info = env.step(ZERO)
        assert not terminated and not truncated
        assert info["reward_ctrl"] == 0.0 and info["tau"] == 0.0
        rewards.append(reward)
        if "apex_z" in info:
            assert info["apex_count"] == 1
            apexes.append(info["apex_z"])
            assert info["stride"] == len(apexes)
    assert len(apexes) >= 30
    err = np.abs(np.array(apexes) - z_star).max(axis=1)
    assert err[0] <= 1e-9 and err.max() <= 1e-9, err  # from the first stride on
    # the highest possible reward in every step (tracking only numerically above zero)
    np.testing.assert_allclose(rewards, 1.0, atol=1e-12)
    assert info["x_position"] > 30 * 1.0  # ~1.1 m per stride down the slope


def test_stride_timing_and_observation_flags():
    env = make(reset_noise_scale=0.0)
    obs, _ = env.reset(seed=0)
    i = {n: k for k, n in enumerate(OBS_NAMES[1:])}
    p = env.unwrapped.params
    # at the apex both legs are in flight, at rest length and touchdown angle
    assert obs[i["contact_back"]] == 0 and obs[i["contact_front"]] == 0
    assert obs[i["leg_length_back"]] == np.float32(p.lb_bar)
    assert obs[i["leg_angle_back"]] == np.float32(p.gamma_b)
    seen_stance = False
    for k in range(1, 60):
        obs, _, _, _, info = env.step(ZERO)
        assert obs[i["time_since_apex"]] == pytest.approx(0.01 * k, abs=1e-6) or "apex_z" in info
        if obs[i["contact_back"]] == 1:
            seen_stance = True
            assert obs[i["leg_length_back"]] < p.lb_bar
            assert abs(obs[i["leg_angle_back"]]) < np.pi / 2
            assert info["phase"] in ("bs", "ds")
            assert obs[i["touched_back"]] == 1
        if "apex_z" in info:
            assert k == 40  # period 0.3906 s
            assert obs[i["touched_back"]] == 0 and obs[i["touched_front"]] == 0
            assert obs[i["time_since_apex"]] == pytest.approx(0.4 - 0.3906, abs=1e-3)
            break
    assert seen_stance


# -- API checkers ----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "kw",
    [
        {},
        {"render_mode": "rgb_array", "width": 160, "height": 90},
        {"exclude_current_positions_from_observation": False},
    ],
)
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


def test_spaces_and_metadata():
    env = make()
    assert env.action_space == gym.spaces.Box(-1, 1, (1,), np.float32)
    assert env.observation_space.shape == (16,) and env.observation_space.dtype == np.float32
    assert env.spec.max_episode_steps * env.unwrapped.dt / 0.3906 >= 50  # >= 50 strides
    assert env.metadata["render_fps"] == 100
    assert make(dt=0.02).metadata["render_fps"] == 50
    wide = make(exclude_current_positions_from_observation=False)
    obs, info = wide.reset(seed=1)
    assert obs.shape == (17,)
    obs, _, _, _, info = wide.step(ZERO)
    assert obs[0] == np.float32(info["x_position"]) and info["x_position"] > 0


# -- seeding ---------------------------------------------------------------------------------------


def rollout(env, seed, n=400, action_seed=0):
    rng = np.random.default_rng(action_seed)
    out = [env.reset(seed=seed)]
    for _ in range(n):
        step = env.step(rng.uniform(-1, 1, 1).astype(np.float32))
        out.append(step)
        if step[2] or step[3]:
            out.append(env.reset())
    return out


def test_same_seed_gives_bit_identical_trajectories():
    a, b = rollout(make(), seed=7), rollout(make(), seed=7)
    assert len(a) == len(b)
    for x, y in zip(a, b, strict=True):
        assert len(x) == len(y)
        np.testing.assert_array_equal(x[0], y[0])
        assert x[1:-1] == y[1:-1]
        assert x[-1].keys() == y[-1].keys()
        for key in x[-1]:
            np.testing.assert_array_equal(x[-1][key], y[-1][key])
    c = rollout(make(), seed=8, n=1)
    assert not np.array_equal(a[0][0], c[0][0])


def test_start_noise_is_scaled_per_component():
    z_star = load_gait("default").z0
    env = make(reset_noise_scale=0.5)
    starts = np.array([env.reset(seed=s)[1]["start_z"] for s in range(200)])
    dev = (starts - z_star) / APEX_SCALES
    assert np.all(np.abs(dev) <= 0.5)
    assert np.all(np.abs(dev).max(axis=0) > 0.45)  # uniform over the whole range


# -- robustness ------------------------------------------------------------------------------------


@pytest.mark.slow
def test_random_actions_over_100_seeds_never_raise_and_end_with_a_reason():
    env = make(reset_noise_scale=1.0)
    failures = {}
    steps = 0
    for seed in range(100):
        rng = np.random.default_rng(seed)
        obs, info = env.reset(seed=seed)
        actions = rng.uniform(-1.2, 1.2, (1000, 1)).astype(np.float32)
        for a in actions:
            obs, reward, terminated, truncated, info = env.step(a)
            steps += 1
            assert np.all(np.isfinite(obs)) and np.isfinite(reward)
            assert env.observation_space.contains(obs)
            if terminated:
                assert info["failure"] in FAILURES
                assert info["reward_alive"] == 0.0
                failures[info["failure"]] = failures.get(info["failure"], 0) + 1
            else:
                assert info["failure"] is None
            if terminated or truncated:
                obs, info = env.reset()
    assert steps == 100_000
    assert sum(failures.values()) >= 20, failures  # random torques make it fall


def test_action_checks_and_clipping():
    env = make()
    env.reset(seed=0)
    for bad in (np.array([np.nan], np.float32), np.array([np.inf]), [float("-inf")]):
        with pytest.raises(ValueError, match="finite"):
            env.step(bad)
    with pytest.raises(ValueError, match="number"):
        env.step(np.zeros(2))
    e1, e2 = make(), make()
    e1.reset(seed=3)
    e2.reset(seed=3)
    o1, r1, _, _, i1 = e1.step(np.array([5.0], np.float32))
    o2, r2, _, _, i2 = e2.step(np.array([1.0], np.float32))
    np.testing.assert_array_equal(o1, o2)
    assert r1 == r2 and i1["tau"] == i2["tau"] == 40.0
    assert i1["reward_ctrl"] == pytest.approx(-0.1)
    _, _, _, _, i3 = e1.step([-3.0])
    assert i3["tau"] == -40.0


def test_reward_terms_add_up_and_tracking_is_paid_at_the_apex():
    env = make(
        reset_noise_scale=0.5, tracking_cost_weight=2.0, ctrl_cost_weight=0.3, alive_reward=0.5
    )
    z_star = env.unwrapped.z_ref
    env.reset(seed=11)
    n_apex = 0
    for _ in range(200):
        _, reward, terminated, _, info = env.step(np.array([0.25], np.float32))
        terms = info["reward_alive"] + info["reward_tracking"] + info["reward_ctrl"]
        assert reward == terms
        assert info["reward_ctrl"] == pytest.approx(-0.3 * 0.25**2)
        if "apex_z" in info:
            n_apex += 1
            cost = np.sum(((info["apex_z"] - z_star) / APEX_SCALES) ** 2)
            assert info["reward_tracking"] == pytest.approx(-2.0 * cost, rel=1e-12)
        else:
            assert info["reward_tracking"] == 0.0
        assert info["reward_alive"] == (0.0 if terminated else 0.5)
        if terminated:
            break
    assert n_apex >= 3


def test_failures_terminate_with_their_name():
    env = make()
    z = load_gait("default").z0.copy()
    z[3] = -0.5  # running backwards
    _, info = env.reset(options={"apex_state": z})
    assert info["failure"] == "moving_backwards"
    _, reward, terminated, _, info = env.step(ZERO)
    assert terminated and info["failure"] == "moving_backwards" and reward == 0.0
    # nearly no gravity: the robot floats and no stride completes within 2 s
    floating = make(gait_overrides={"g": 0.01}, reset_noise_scale=0.0)
    floating.reset(seed=0)
    for k in range(1, 400):  # noqa: B007 (k after the loop)
        _, _, terminated, _, info = floating.step(ZERO)
        if terminated:
            break
    assert info["failure"] == "no_apex" and k == 200 and info["time"] == pytest.approx(2.0)


# -- arguments -------------------------------------------------------------------------------------


def test_apex_state_option_starts_there():
    env = make()
    z = load_gait("default").z0 + np.array([0.005, 0.02, -0.03, 0.05, 0.3, -0.2])
    obs, info = env.reset(seed=0, options={"apex_state": z})
    np.testing.assert_array_equal(info["start_z"], z)
    np.testing.assert_array_equal(obs[:7], obs_of_z(z))
    np.testing.assert_array_equal(
        env.unwrapped.state, [0.0, z[0], z[1], z[2], z[3], 0.0, z[4], z[5]]
    )
    with pytest.raises(ValueError, match="apex_state"):
        env.reset(options={"apex_state": [1.0, 2.0]})


def test_gaits_and_overrides():
    lit = make(gait="paper-literal", reset_noise_scale=0.0)
    obs, info = lit.reset(seed=0)
    gait = load_gait("paper-literal")
    np.testing.assert_allclose(info["start_z"], gait.z_published)
    assert lit.unwrapped.params.l1 == 0.275
    for _ in range(100):
        _, _, terminated, _, info = lit.step(ZERO)
        if terminated:
            break
    over = make(gait_overrides={"alpha_deg": 2.0, "kc": 300})
    p = over.unwrapped.params
    assert p.kc == 300 and p.alpha == pytest.approx(np.radians(2.0))
    np.testing.assert_array_equal(over.unwrapped.z_ref, load_gait("default").z0)
    over.reset(seed=0)
    over.step(ZERO)
    with pytest.raises(ValueError, match="unknown gait parameter"):
        make(gait_overrides={"spring": 1.0})
    with pytest.raises(FileNotFoundError):
        make(gait="no-such-gait")
    for bad in (
        {"dt": 0.0},
        {"max_torque": -1.0},
        {"reset_noise_scale": np.nan},
        {"apex_scales": [1, 2, 3]},
    ):
        with pytest.raises(ValueError):
            make(**bad)


# -- rendering -------------------------------------------------------------------------------------


def test_rgb_array_frame_shows_the_robot():
    env = make(render_mode="rgb_array", width=320, height=180)
    env.reset(seed=0)
    env.step(ZERO)
    frame = env.render()
    assert frame.shape == (180, 320, 3) and frame.dtype == np.uint8
    for colour in (BACK_BODY, FRONT_BODY):
        near = np.abs(frame.astype(int) - np.array(colour)).max(axis=2) <= 12
        assert near.sum() > 100  # a blank or robot-less frame has none of the body colours
    env.close()


def test_no_render_mode_renders_nothing():
    env = make()
    env.reset(seed=0)
    assert env.unwrapped._renderer is None
    with pytest.warns(UserWarning, match="render_mode"):
        assert env.unwrapped.render() is None


def test_animate_command_writes_a_gif(tmp_path):
    from PIL import Image

    from bound_env.commands.cli import main

    out, png = tmp_path / "bound.gif", tmp_path / "frame.png"
    argv = "animate --gait default --strides 0.5 --width 160 --height 90".split()
    assert main([*argv, "--out", str(out), "--frame", str(png)]) == 0
    with Image.open(out) as im:
        assert im.size == (160, 90) and im.n_frames >= 5
    assert Image.open(png).size == (160, 90)


# -- vector environments ---------------------------------------------------------------------------


def single_env_observations(seed, actions, **kw):
    """Observations of single envs seeded seed + i, stepped with actions[:, i], no resets."""
    obs = []
    for i in range(actions.shape[1]):
        env = make(**kw)
        o = [env.reset(seed=seed + i)[0]]
        for a in actions[:, i]:
            o.append(env.step(a)[0])
        obs.append(o)
    return np.array(obs).swapaxes(0, 1)


@pytest.mark.parametrize("mode", ["sync", "async", "vector_entry_point"])
def test_vector_modes_match_single_envs(mode):
    n, steps, seed = 2, 15, 5
    actions = np.random.default_rng(0).uniform(-1, 1, (steps, n, 1)).astype(np.float32)
    expected = single_env_observations(seed, actions)
    envs = gym.make_vec(ENV_ID, num_envs=n, vectorization_mode=mode)
    try:
        got = [envs.reset(seed=seed)[0]]
        for a in actions:
            got.append(envs.step(a)[0])
    finally:
        envs.close()
    np.testing.assert_array_equal(np.array(got), expected)


@pytest.mark.parametrize("autoreset_mode", [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP])
def test_native_vector_env_matches_sync_through_episode_ends(autoreset_mode):
    n, kw = 4, dict(reset_noise_scale=1.0, max_episode_steps=120)
    sync = gym.make_vec(
        ENV_ID,
        num_envs=n,
        vectorization_mode="sync",
        vector_kwargs={"autoreset_mode": autoreset_mode},
        **kw,
    )
    native = gym.make_vec(
        ENV_ID,
        num_envs=n,
        vectorization_mode="vector_entry_point",
        autoreset_mode=autoreset_mode,
        **kw,
    )
    assert native.metadata["autoreset_mode"] == autoreset_mode
    assert native.observation_space == sync.observation_space
    assert native.action_space == sync.action_space
    (o1, i1), (o2, i2) = sync.reset(seed=2), native.reset(seed=2)
    np.testing.assert_array_equal(o1, o2)
    assert_infos_equal(i1, i2)
    rng = np.random.default_rng(1)
    ends = {"terminated": 0, "truncated": 0}
    for _ in range(400):
        a = rng.uniform(-1.5, 1.5, (n, 1)).astype(np.float32)
        r1, r2 = sync.step(a), native.step(a)
        for x, y in zip(r1[:4], r2[:4], strict=True):
            np.testing.assert_array_equal(x, y)
        assert_infos_equal(r1[4], r2[4])
        ends["terminated"] += r1[2].sum()
        ends["truncated"] += r1[3].sum()
    assert ends["terminated"] > 0 and ends["truncated"] > 0, ends


def test_native_vector_env_options_threads_and_render():
    n = 8
    z = load_gait("default").z0
    kw = dict(num_envs=n, reset_noise_scale=1.0, render_mode="rgb_array", width=64, height=36)
    serial = gym.make_vec(ENV_ID, parallel=False, **kw)
    threads = gym.make_vec(ENV_ID, parallel=True, **kw)
    obs, info = serial.reset(seed=0, options={"apex_state": z})
    np.testing.assert_array_equal(obs[:, :7], np.tile(obs_of_z(z), (n, 1)))
    per_robot = z + np.outer(np.arange(n), [0.001, 0, 0, 0.01, 0, 0])
    obs, info = serial.reset(seed=0, options={"apex_state": per_robot})
    np.testing.assert_array_equal(info["start_z"], per_robot)
    # partial reset, then the threaded kernel gives bit-identical results
    mask = np.zeros(n, dtype=bool)
    mask[3] = True
    obs, info = serial.reset(seed=0, options={"reset_mask": mask})
    assert info["_start_z"].tolist() == mask.tolist()
    serial.reset(seed=0)
    threads.reset(seed=0)
    rng = np.random.default_rng(0)
    for _ in range(150):
        a = rng.uniform(-1, 1, (n, 1))
        for x, y in zip(serial.step(a)[:4], threads.step(a)[:4], strict=True):
            np.testing.assert_array_equal(x, y)
    frames = serial.render()
    assert len(frames) == n and frames[0].shape == (36, 64, 3)
    with pytest.raises(ValueError, match="finite"):
        serial.step(np.full((n, 1), np.nan))
    serial.close()
    threads.close()


def test_kick_changes_only_the_velocities_and_rejects_nan():
    env = gym.make("PassiveBound-v0", reset_noise_scale=0.0).unwrapped
    env.reset(seed=0)
    before = env.state
    env.kick([0.1, 0.0, -0.5, 0.0])
    after = env.state
    assert np.array_equal(after[:4], before[:4])
    assert after[4] == pytest.approx(before[4] + 0.1) and after[6] == pytest.approx(before[6] - 0.5)
    with pytest.raises(ValueError, match="finite"):
        env.kick([np.nan, 0, 0, 0])


# -- one config for both environments ----------------------------------------------------------


def test_task_config_is_what_both_envs_take(make_env):
    import pickle

    from bound_env.envs.vector import PassiveBoundVectorEnv
    from bound_env.sim.task import TASK_SETTINGS, TaskConfig

    cfg = TaskConfig(max_torque=20.0, reset_noise_scale=0.3, apex_scales=[0.03] * 6)
    assert cfg.apex_scales == (0.03,) * 6 and isinstance(cfg.max_torque, float)
    with pytest.raises(Exception, match="cannot assign"):
        cfg.dt = 0.02  # frozen
    # the settings are exactly the env's keyword arguments, minus the rendering ones
    import inspect

    from bound_env.envs.env import PassiveBoundEnv

    env_kwargs = set(inspect.signature(PassiveBoundEnv).parameters)
    assert set(TASK_SETTINGS) == env_kwargs - {"render_mode", "width", "height", "config"}
    by_kwargs = make_env(max_torque=20.0, reset_noise_scale=0.3, apex_scales=[0.03] * 6)
    by_config = make_env(config=cfg)
    assert by_config.unwrapped.task.config == cfg == by_kwargs.unwrapped.task.config
    rng = np.random.default_rng(5)
    a = by_kwargs.reset(seed=11)[0], by_config.reset(seed=11)[0]
    np.testing.assert_array_equal(*a)
    for _ in range(60):
        act = rng.uniform(-1, 1, 1).astype(np.float32)
        o1, r1, *_ = by_kwargs.step(act)
        o2, r2, *_ = by_config.step(act)
        np.testing.assert_array_equal(o1, o2)
        assert r1 == r2
    # keywords not at their default change the config; the env pickles with its config
    changed = make_env(config=cfg, dt=0.02).unwrapped
    assert changed.task.config.dt == 0.02 and changed.task.config.max_torque == 20.0
    clone = pickle.loads(pickle.dumps(changed))
    assert clone.task.config == changed.task.config
    venv = PassiveBoundVectorEnv(num_envs=2, config=cfg, dt=0.02)
    assert venv.task.config == replace_dt(cfg, 0.02)
    venv.close()
    with pytest.raises(ValueError, match="unknown task setting"):
        PassiveBoundVectorEnv(num_envs=2, spring=1.0)
    with pytest.raises(ValueError, match="rtol"):
        TaskConfig(rtol=0.0)
    with pytest.raises(ValueError, match="ctrl_cost_weight"):
        TaskConfig(ctrl_cost_weight=-1.0)


def replace_dt(cfg, dt):
    from dataclasses import replace

    return replace(cfg, dt=dt)


def test_termination_is_decoded_by_the_task(make_env):
    """The task says which robots failed; the env reports it as terminated."""
    env = make_env(gait_overrides={"g": 0.01}, reset_noise_scale=0.0)
    env.reset(seed=0)
    task, b = env.unwrapped.task, env.unwrapped._b
    for _ in range(400):
        _, _, terminated, _, info = env.step(ZERO)
        assert terminated == bool(task.failed(b)[0]) == (info["failure"] is not None)
        if terminated:
            break
    assert terminated
