"""Tests of the rescue task PassiveBoundRescue-v0/-v1 (bound_env/rescue_*.py) and its discrete
wrapper (bound_env.envs.wrappers.LibraryActions): the env checkers, the task's rules, the same
strides as the stride env, bad input, and plain SB3 PPO learning on it."""

import warnings

import gymnasium as gym
import numpy as np
import pytest

import bound_env
from bound_env import RESCUE_ENV_ID, RESCUE_ENV_ID_V1
from bound_env.envs.wrappers import LibraryActions, default_library

gym.register_envs(bound_env)


@pytest.fixture(scope="module")
def student():
    from agents.runtime.policy import load_controller

    return load_controller("default")


def student_env(student, **kw):
    """The rescue env + wrapper on the student's own LQR and library (as `bound-env finetune`)."""
    from agents.experts.finetune import rescue_env_kwargs

    env = gym.make(RESCUE_ENV_ID, **rescue_env_kwargs(student), **kw)
    return LibraryActions(env, student.rows)


IDS = (RESCUE_ENV_ID, RESCUE_ENV_ID_V1)


@pytest.mark.parametrize("env_id", IDS)
def test_a_stride_is_the_stride_envs_stride(env_id):
    """One step from a given apex state under given coefficients lands where
    PassiveBoundStride-v1 (the same basis, K = 8, 80 N m) lands from it: the same plant, bit for
    bit up to the float32 action; the observation is the new apex error in the version's
    scale."""
    env = gym.make(env_id).unwrapped
    ref = gym.make("PassiveBoundStride-v1", K=8, max_torque=80.0)
    rng = np.random.default_rng(3)
    for i in range(4):
        z = env.z_ref + 0.2 * np.abs(env.z_ref) * np.eye(6)[[0, 3, 4, 5][i]] * (-1) ** i
        u = rng.uniform(-0.1, 0.1, 8).astype(np.float32)
        env.reset(options={"apex_state": z})
        ref.reset(options={"apex_state": z})
        obs, _, _, _, info = env.step(u)
        _, _, term, _, rinfo = ref.step(u)
        if term:
            assert info["fell"]
            continue
        np.testing.assert_allclose(info["apex_z"], rinfo["apex_z"], rtol=0, atol=1e-9)
        scale = env.obs_scale if env_id == RESCUE_ENV_ID_V1 else env.scales
        np.testing.assert_allclose(obs, (info["apex_z"] - env.z_ref) / scale, rtol=1e-6)


@pytest.mark.parametrize("env_id", IDS)
def test_starts_are_seeded_past_the_safe_radius_within_r_max(env_id):
    """The same seed gives the same start; every start lies past the safe radius and within
    r_max |z*| of z* in every component (its largest relative component is r <= r_max); v1
    with r_min = 0 draws v0's starts."""
    env = gym.make(env_id, r_max=0.3).unwrapped
    starts = []
    for seed in range(30):
        _, info = env.reset(seed=seed)
        z = info["start_z"]
        assert env.past_safe(z) and info["error"] == env.error(z) > env.safe
        rel = np.abs(z - env.z_ref) / np.abs(env.z_ref)
        assert rel.max() <= 0.3 + 1e-12
        starts.append(z)
    assert np.array_equal(env.reset(seed=7)[1]["start_z"], starts[7])
    other = gym.make(IDS[1 - IDS.index(env_id)], r_max=0.3).unwrapped
    assert np.array_equal(other.reset(seed=7)[1]["start_z"], starts[7])


def test_v1_r_min_and_set_start_radius_move_the_starts():
    env = gym.make(RESCUE_ENV_ID_V1, r_min=0.3, r_max=0.35).unwrapped
    rel = [np.max(np.abs(env.reset(seed=s)[1]["start_z"] - env.z_ref) / np.abs(env.z_ref))
           for s in range(20)]  # fmt: skip
    assert min(rel) >= 0.3 - 1e-12 and max(rel) <= 0.35 + 1e-12
    env.set_start_radius(0.1)
    rel = [np.max(np.abs(env.reset(seed=s)[1]["start_z"] - env.z_ref) / np.abs(env.z_ref))
           for s in range(20)]  # fmt: skip
    assert max(rel) <= 0.1 + 1e-12
    with pytest.raises(ValueError, match="r_min"):
        env.set_start_radius(0.1, r_min=0.2)


def test_v1_pays_a_return_only_and_its_shaping_telescopes():
    """The LQR's plan from a start just past the safe radius returns at once: reward 1
    (v0: 1 + the strides left). With shaping c the rewards of an episode that ends sum to
    1[returned] gamma^(T-1) - Phi(z_0) discounted (Phi(z) = -c log(e(z) / safe)), whatever
    the actions: the shaping cannot change which policy is best."""
    base = gym.make(RESCUE_ENV_ID_V1).unwrapped
    z = base.z_ref + 1.2 * base.safe * base.scales * np.eye(6)[3]
    base.reset(options={"apex_state": z})
    _, r, term, trunc, info = base.step(base.lqr.coefficients(z).astype(np.float32))
    assert info["returned"] and term and not trunc and r == 1.0 == info["reward_return"]
    assert info["reward_shaping"] == 0.0
    c, gamma = 0.3, 0.9
    env = gym.make(RESCUE_ENV_ID_V1, shaping=c, gamma=gamma).unwrapped
    rng = np.random.default_rng(0)
    outcomes = set()
    for seed in range(8):
        _, info = env.reset(seed=seed)
        phi0 = -c * np.log(info["error"] / env.safe)
        total, k, done = 0.0, 0, False
        while not done:
            u = env.lqr.coefficients(env.z) + rng.normal(0, 0.05 * (seed % 3), 8)
            _, r, term, trunc, info = env.step(np.clip(u, -1, 1).astype(np.float32))
            assert r == info["reward_return"] + info["reward_shaping"]
            total += gamma**k * r
            k += 1
            done = term or trunc
        if trunc:  # the potential of the state it was cut at stays in the sum
            phi_t = -c * np.log(info["error"] / env.safe)
            assert total == pytest.approx(gamma**k * phi_t - phi0)
            outcomes.add("truncated")
            continue
        want = (gamma ** (k - 1) if info["returned"] else 0.0) - phi0
        assert total == pytest.approx(want), (seed, info)
        outcomes.add("returned" if info["returned"] else "fell")
    assert {"returned", "fell"} <= outcomes


def test_v1_horizon_is_a_truncation_or_a_termination():
    z_ref = gym.make(RESCUE_ENV_ID_V1).unwrapped.z_ref
    z = z_ref + 0.2 * np.abs(z_ref) * np.eye(6)[4]  # zero action: neither returns nor falls
    for end in (False, True):
        env = gym.make(RESCUE_ENV_ID_V1, horizon=2, shaping=1.0, terminate_at_horizon=end)
        env.reset(options={"apex_state": z})
        phi1 = env.unwrapped.potential(env.step(np.zeros(8, np.float32))[-1]["apex_z"])
        _, r, term, trunc, info = env.step(np.zeros(8, np.float32))
        assert (term, trunc) == (end, not end) and not info["returned"]
        phi2 = 0.0 if end else env.unwrapped.potential(info["apex_z"])
        assert r == pytest.approx(0.99 * phi2 - phi1)


def test_v1_lqr_residual_plays_the_lqr_plus_the_scaled_action():
    env = gym.make(RESCUE_ENV_ID_V1, action_mode="lqr_residual", residual_scale=0.5).unwrapped
    env.reset(seed=2)
    a = np.linspace(-1, 1, 8).astype(np.float32)
    want = np.clip(env.lqr.coefficients(env.z) + 0.5 * a, -1, 1)
    _, _, _, _, info = env.step(a)
    np.testing.assert_array_equal(info["u"], want)
    direct = gym.make(RESCUE_ENV_ID_V1).unwrapped
    direct.reset(seed=2)
    assert np.array_equal(direct.step(a)[-1]["u"], a.astype(float))


@pytest.mark.parametrize("discrete", [False, True])
def test_gymnasium_and_sb3_env_checkers_pass_without_warnings(discrete):
    from gymnasium.utils.env_checker import check_env
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    env = gym.make(RESCUE_ENV_ID)
    if discrete:
        env = LibraryActions(env)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # but v0's own deprecation (the checkers remake it)
        warnings.filterwarnings("ignore", "PassiveBoundRescue-v0 is deprecated", DeprecationWarning)
        if not discrete:
            check_env(env.unwrapped)
            sb3_check_env(env.unwrapped)
        sb3_check_env(env)
    env.close()


def test_v0_is_deprecated_on_make_and_points_to_v1():
    with pytest.warns(DeprecationWarning, match="PassiveBoundRescue-v0 is deprecated.*use Pas"):
        gym.make(RESCUE_ENV_ID)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        gym.make(RESCUE_ENV_ID_V1)  # v1: no warning
    from bound_env.envs.rescue_env import (
        PassiveBoundRescueEnv,
        PassiveBoundRescueV1Env,
        sample_starts,
    )
    from bound_env.envs.rescue_v0 import PassiveBoundRescueEnv as V0
    from bound_env.envs.rescue_v1 import PassiveBoundRescueV1Env as V1

    assert (PassiveBoundRescueEnv, PassiveBoundRescueV1Env) == (V0, V1) and callable(sample_starts)


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


BAD_ARGUMENTS = [
    ({"safe": 0}, "safe"),
    ({"r_max": float("nan")}, "r_max"),
    ({"axis_prob": 1.5}, "axis_prob"),
    ({"horizon": 0}, "horizon"),
    ({"horizon": 2.5}, "horizon"),
    ({"K": 0}, "K"),
    ({"K": "abc"}, "K"),
    ({"controller": "damping"}, "damping"),
    ({"controller": None}, "controller"),
    ({"controller": 3}, "controller"),
    ({"gain": [[1.0] * 6] * 3}, "^gain has shape"),
    ({"gain": [[float("nan")] * 6] * 8}, "^gain must be finite"),
    ({"gain": "abc"}, "^gain must hold real numbers"),
    ({"gain": [1.0] * 6}, "^gain must have shape"),
    ({"max_torque": -1}, "max_torque"),
    # issue 40: an error about the linearization, an AttributeError, a start at 1e300 |z*|
    ({"max_torque": 1e12}, "^max_torque must be in"),
    ({"controller": "lqr-of"}, "^controller 'lqr-of' is held offset-free"),
    ({"r_max": 1e300}, "^r_max must be in"),
    # no start out to r_max can pass the safe radius: refused, not an endless redraw
    ({"safe": 13}, "r_max=0.45 gives no start past the safe radius safe=13"),
    ({"r_max": 1e-9}, "r_max=1e-09 gives no start past the safe radius"),
    ({"r_max": True}, "r_max"),
    # the spec files' dt range: dt=1e-9 built a 25 GB matrix, dt=5.0 (> a stride) was accepted
    ({"dt": 1e-9}, "dt must be a finite number in \\[0.0001, 0.1\\]"),
    ({"dt": 5.0}, "dt must be a finite number in \\[0.0001, 0.1\\]"),
]
BAD_V1_ARGUMENTS = [
    ({"r_min": 0.5}, "r_min must be below r_max"),
    ({"r_min": -0.1}, "r_min"),
    ({"shaping": -1}, "shaping"),
    ({"shaping": 1e308}, "^shaping must be in"),  # issue 40: the first reward was inf
    ({"gamma": 0}, "gamma"),
    ({"gamma": 1.5}, "gamma"),
    ({"action_mode": "residual"}, "action_mode must be one of direct, lqr_residual"),
    ({"residual_scale": 0}, "residual_scale"),
    ({"terminate_at_horizon": "yes"}, "terminate_at_horizon"),
]


@pytest.mark.parametrize("env_id", IDS)
@pytest.mark.parametrize("kw, message", BAD_ARGUMENTS)
def test_bad_arguments_are_refused_in_one_line(env_id, kw, message):
    with pytest.raises(ValueError, match=message) as e:
        gym.make(env_id, **kw)
    assert "\n" not in str(e.value) and ".yaml" not in str(e.value)  # not the spec file's


@pytest.mark.parametrize("kw, message", BAD_V1_ARGUMENTS)
def test_bad_v1_arguments_are_refused_in_one_line(kw, message):
    with pytest.raises(ValueError, match=message) as e:
        gym.make(RESCUE_ENV_ID_V1, **kw)
    assert "\n" not in str(e.value)


@pytest.mark.parametrize("env_id", IDS)
def test_bad_reset_options_and_starts_inside_the_safe_radius_are_refused(env_id):
    env = gym.make(env_id)
    z_ref = env.unwrapped.z_ref
    far = z_ref + 0.3 * np.abs(z_ref) * np.eye(6)[3]
    for options, message in [
        ({"apex_state": [1.0, 2.0]}, "apex_state"),
        ({"apex_state": "abc"}, "apex_state"),
        ({"apex_state": [[1.0, 2.0], [3.0]]}, "apex_state"),
        ({"apex_stat": far}, "unknown reset option 'apex_stat'"),  # a typo: not a random start
        ([1, 2], "options must be a dict"),
        ({"apex_state": z_ref}, "options\\['apex_state'\\] lies inside the safe radius"),
        ({"apex_state": z_ref + 1e6 * np.eye(6)[0]}, "apex_state'\\]: y_g=1000000.2.* outside"),
    ]:
        with pytest.raises(ValueError, match=message) as e:
            env.reset(options=options)
        assert "\n" not in str(e.value)
    obs, info = env.reset(options={"apex_state": far})
    assert np.array_equal(info["start_z"], far)


@pytest.mark.parametrize("env_id", IDS)
def test_a_step_after_a_fall_or_past_truncation_is_refused(env_id):
    """v0 continued from the last apex after a fall, and past the horizon paid -1 and a
    negative bonus: both now raise the stride env's error until reset."""
    env = gym.make(env_id, horizon=2)
    z_ref = env.unwrapped.z_ref
    env.reset(options={"apex_state": z_ref + 0.45 * np.abs(z_ref) * -np.eye(6)[0]})
    _, r, term, _, info = env.step(np.ones(8, dtype=np.float32))
    assert term and info["fell"] and r == 0.0
    with pytest.raises(ValueError, match="step\\(\\) after the episode ended \\(the robot fell\\)"):
        env.step(np.zeros(8, dtype=np.float32))
    env.reset(options={"apex_state": z_ref + 0.2 * np.abs(z_ref) * np.eye(6)[4]})
    done = False
    for _ in range(2):
        _, _, term, trunc, info = env.step(np.zeros(8, dtype=np.float32))
        done = term or trunc
    assert done and trunc and not term, info
    with pytest.raises(ValueError, match="reached its horizon=2"):
        env.step(np.zeros(8, dtype=np.float32))
    env.reset(seed=0)  # a reset starts a new episode
    env.step(np.zeros(8, dtype=np.float32))


def test_train_with_a_bad_rescue_kwarg_leaves_no_run_folder(tmp_path, cli):
    """`train` makes one env before its run folder: a `safe` no start can pass (it hung in
    reset and left the folder behind) is a one-line error, and the CLI exits 2."""
    from agents.training.train import train

    with pytest.raises(ValueError, match="safe=13"):
        train("ppo-rescue", RESCUE_ENV_ID_V1, name="bad", runs_dir=tmp_path,
              sets=["env_kwargs.safe=13"], progress_bar=False)  # fmt: skip
    assert not (tmp_path / "bad").exists()
    code, _, err = cli("train", "--config", "ppo-rescue", "--env-id", RESCUE_ENV_ID,
                       "--hp", "env_kwargs.r_max=1e-9", "--name", "bad", "--out", tmp_path,
                       "--no-progress")  # fmt: skip
    assert code == 2 and "r_max=1e-09" in err, err
    assert len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "bad").exists()


def test_bad_actions_are_refused():
    env = gym.make(RESCUE_ENV_ID)
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


def _returns(model, starts, **kw) -> int:
    """Returns of a model's deterministic policy from the apex states ``starts`` (v1)."""
    env = gym.make(RESCUE_ENV_ID_V1, **kw)
    k = 0
    for z in starts:
        obs, _ = env.reset(options={"apex_state": z})
        done = False
        while not done:
            obs, _, term, trunc, info = env.step(model.predict(obs, deterministic=True)[0])
            done = term or trunc
        k += bool(info["returned"])
    return k


def _fixed_starts(env, sizes=(0.1, 0.15), n_dirs=32, seed=1):
    """z* + r |z*| xi past the safe radius, xi of seed 1 (not the validation set's 777)."""
    from bound_env.analysis.margins import random_directions

    dirs = random_directions(n_dirs, seed)
    zs = [env.z_ref + r * np.abs(env.z_ref) * xi for r in sizes for xi in dirs]
    return [z for z in zs if env.past_safe(z)]


def test_plain_sb3_ppo_runs_on_both_versions():
    """`gymnasium.make` + plain SB3 PPO, a few hundred strides on each version: it runs, and
    its actions are finite coefficients."""
    import torch
    from stable_baselines3 import PPO

    torch.set_num_threads(1)
    for env_id in IDS:
        env = gym.make(env_id)
        model = PPO("MlpPolicy", env, n_steps=128, batch_size=64, n_epochs=2, seed=0,
                    device="cpu")  # fmt: skip
        model.learn(256)
        assert model.num_timesteps >= 256 and len(model.ep_info_buffer) > 0
        act, _ = model.predict(env.reset(seed=1)[0], deterministic=True)
        assert act.shape == (8,) and np.all(np.isfinite(act))


def test_the_shipped_config_section_makes_the_env():
    """configs/ppo-rescue.yaml's section is what `bound-env train --env-id
    PassiveBoundRescue-v0` reads: PPO takes its hyperparameters and its env_kwargs make the
    env with continuous actions."""
    from stable_baselines3 import PPO

    from agents.common.config import preprocess
    from agents.training.train import check_algo_kwargs, check_env_spec, resolve_section

    spec = preprocess(resolve_section("ppo-rescue", RESCUE_ENV_ID, None, None))
    check_algo_kwargs(spec.algo_kwargs, PPO)
    check_env_spec(RESCUE_ENV_ID, spec)
    env = gym.make(RESCUE_ENV_ID, **spec.env_kwargs)
    assert isinstance(env.action_space, gym.spaces.Box) and env.action_space.shape == (8,)
