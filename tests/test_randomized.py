"""`RandomizedPlant` on every registered env id: the robot runs on the drawn plant (one holder
of the plant), sensor noise reaches every input a controller decides on, in each env's own
observation units, and the compositions (`LibraryActions`, delay, double wrapping)."""

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.envs.registration import registry

import bound_env
from bound_env.envs.wrappers import LibraryActions, RandomizedPlant
from bound_env.model.mismatch import NOISE_SCALES, plant_params
from bound_env.sim.stride_map import EVAL_RTOL, StrideMap

gym.register_envs(bound_env)
ENV_IDS = sorted(k for k in registry if k.startswith("PassiveBound"))
U_ACTION = 0.1  # a torque that moves every id's apex (coefficients or normalized torque)


def _map_settings(base) -> dict:
    """gait, dt, max_torque, rtol of the step env an env's strides run on."""
    if hasattr(base, "lqr"):  # the rescue envs
        return dict(gait=base.lqr.gait, dt=base.lqr.dt, max_torque=base.lqr.max_torque,
                    rtol=EVAL_RTOL)  # fmt: skip
    c = base.task.config
    return dict(gait=c.gait, dt=c.dt, max_torque=c.max_torque, rtol=c.rtol)


def _one_stride(env, z0):
    """The true next apex of the wrapped env from its start z0, and the interval actions."""
    base = env.unwrapped
    if hasattr(base, "action_mode") or hasattr(base, "lqr") or hasattr(base, "basis"):
        u = np.full(env.action_space.shape, U_ACTION, dtype=np.float32)
        if hasattr(base, "lqr"):  # a rescue: the LQR's plan (a constant profile may fall)
            u = base.lqr.coefficients(z0).astype(np.float32)
        if hasattr(base, "profile_actions"):
            a = base.profile_actions(u.astype(float))
        else:
            a = base.task.sim.actions(u.astype(float))[0]
        _, _, _, _, info = env.step(u)
        return info.get("true_apex_z", info["apex_z"]), a
    for _ in range(200):  # the step env: a constant torque until the stride completes
        _, _, term, _, info = env.step(np.array([U_ACTION], dtype=np.float32))
        assert not term
        if "apex_z" in info:
            return info.get("true_apex_z", info["apex_z"]), np.array(
                [U_ACTION], dtype=np.float32
            ).astype(float)
    raise AssertionError("no apex")


@pytest.mark.parametrize("spec", ["pm20", {"params": {"alpha_deg": 0.5}}], ids=["pm20", "slope"])
@pytest.mark.parametrize("env_id", ENV_IDS)
def test_every_id_runs_its_robot_on_the_drawn_plant(env_id, spec):
    env = RandomizedPlant(gym.make(env_id), mismatch=spec)
    base = env.unwrapped  # from z* (the literal cycle is unstable), or just past the safe radius
    z = base.z_ref.copy()
    if hasattr(base, "safe"):
        z[0] += 2 * base.safe * base.scales[0]
    _, info = env.reset(seed=2, options={"apex_state": z})
    z0 = info.get("true_start_z", info["start_z"])
    z1, a = _one_stride(env, z0)
    settings = _map_settings(env.unwrapped)
    drawn = {k: info["plant"][k] for k in info["plant_factors"]}
    expected = StrideMap(gait_overrides=drawn, **settings).map(z0, a)
    nominal = StrideMap(**settings).map(z0, a)
    if spec == "pm20":  # the same parameters bit for bit: the same stride
        assert np.array_equal(z1, expected)
    else:  # alpha round-trips through degrees (1 ulp): the same stride to the integrator
        np.testing.assert_allclose(z1, expected, rtol=0, atol=1e-9)
    assert np.max(np.abs(z1 - nominal)) > 1e-5  # and not the nominal robot's
    env.close()


def test_the_stride_envs_rough_terrain_draws_around_the_drawn_slope():
    env = RandomizedPlant(
        gym.make("PassiveBoundStride-v1", slope_noise_deg=0.5), {"params": {"alpha_deg": 0.5}}
    )
    _, info = env.reset(seed=2)
    assert env.unwrapped.alpha_deg == pytest.approx(info["plant"]["alpha_deg"], abs=1e-12)
    assert env.unwrapped.params.alpha == env.unwrapped.plant_task.params.alpha
    env.close()


def test_one_holder_of_the_plant():
    """Each env's robot, start check and strides read one task's plant: the stride map keeps
    no copy, so setting the holder's parameters changes the next stride."""
    from bound_env.model.params import load_gait

    sm = StrideMap()
    z = load_gait("default").z0
    before = sm.map(z, [0.2])
    sm.task.set_params(plant_params(sm.params, {"kc": 1.2}))
    assert not np.array_equal(sm.map(z, [0.2]), before)
    assert not hasattr(sm, "_aux0")
    stride = gym.make("PassiveBoundStride-v1").unwrapped
    assert stride.task.sim.stride_map.task is stride.plant_task is stride.task.step_task
    rescue = gym.make("PassiveBoundRescue-v1").unwrapped
    assert rescue.plant.task is rescue.plant_task


def test_vector_envs():
    """The native vector env is refused in one line; a vector env of wrapped envs draws one
    plant per robot."""
    native = gym.make_vec("PassiveBound-v1", 2, vectorization_mode="vector_entry_point")
    with pytest.raises(ValueError, match='vectorization_mode="sync"') as e:
        RandomizedPlant(native, "pm20")
    assert "\n" not in str(e.value)
    envs = gym.make_vec("PassiveBound-v1", 2, vectorization_mode="sync",
                        wrappers=[lambda e: RandomizedPlant(e, "pm20")])  # fmt: skip
    envs.reset(seed=3)
    p0, p1 = (e.unwrapped.params for e in envs.envs)
    nominal = gym.make("PassiveBound-v1").unwrapped.params
    assert p0 != p1 and nominal not in (p0, p1)
    envs.close()


# -- sensor noise: every input of a controller, in the observation's units ----------------------


def _noise_samples(env_id, noise, n=40, **kw):
    """(observed apex - true apex in SI, observation - the true apex's observation) over n
    resets of the stride or rescue env under ``noise``."""
    env = RandomizedPlant(gym.make(env_id, **kw), {"noise": noise})
    base = env.unwrapped
    # the stride env observes z itself, the rescue envs (z - z*) / obs_scale
    scale, ref = getattr(base, "obs_scale", np.ones(6)), getattr(base, "obs_scale", None)
    ref = np.zeros(6) if ref is None else base.z_ref
    d_si, d_obs = [], []
    for seed in range(n):
        obs, info = env.reset(seed=seed)
        true = base.z  # the state the robot is in
        true_obs = np.clip(((true - ref) / scale).astype(np.float32),
                           base.observation_space.low, base.observation_space.high)  # fmt: skip
        d_si.append(info["start_z"] - true)
        d_obs.append(obs.astype(float) - true_obs)
        assert np.array_equal(info.get("true_start_z"), true)
        assert np.array_equal(obs, base.apex_observation(info["start_z"]))  # one draw
    return np.array(d_si), np.array(d_obs), scale


@pytest.mark.parametrize(
    "env_id", ["PassiveBoundStride-v1", "PassiveBoundRescue-v0", "PassiveBoundRescue-v1"]
)
def test_noise_is_in_each_envs_observation_units(env_id):
    sigma = {"y_g": 1.0, "xdot_g": 1.0}
    d_si, d_obs, scale = _noise_samples(env_id, sigma)
    for j, name in ((0, "y_g"), (3, "xdot_g")):
        sd_si = NOISE_SCALES[name]
        assert 0.7 * sd_si < np.std(d_si[:, j]) < 1.3 * sd_si
        sd_obs = sd_si / scale[j]  # v1: 0.02 / 0.112 on y_g, not 1 (the apex scale's)
        assert 0.7 * sd_obs < np.std(d_obs[:, j]) < 1.3 * sd_obs
    assert np.all(d_si[:, [1, 2, 4, 5]] == 0)


def test_the_step_envs_apex_in_info_is_noisy_too():
    env = RandomizedPlant(gym.make("PassiveBound-v1"), {"noise": {"theta2dot": 1.0}})
    obs, info = env.reset(seed=1)
    diffs = [info["start_z"] - info["true_start_z"]]
    while len(diffs) < 30:
        obs, _, term, trunc, info = env.step(np.zeros(1, dtype=np.float32))
        assert not (term or trunc)
        if "apex_z" in info:
            diffs.append(info["apex_z"] - info["true_apex_z"])
    d = np.array(diffs)
    assert np.all(d[:, :5] == 0)
    assert 0.6 * NOISE_SCALES["theta2dot"] < np.std(d[:, 5]) < 1.4 * NOISE_SCALES["theta2dot"]


def test_a_stride_controller_in_the_plain_loop_reads_the_noisy_apex():
    from bound_env.control import load_controller
    from bound_env.control.plain import PlainPolicy

    ctrl = load_controller("lqr")
    seen = []
    on_apex = ctrl.on_apex
    ctrl.on_apex = lambda z, t: (seen.append(np.array(z)), on_apex(z, t))[1]
    act = PlainPolicy(ctrl)
    env = RandomizedPlant(gym.make("PassiveBound-v1"), {"noise": {"y_g": 0.5}})
    obs, info = env.reset(seed=0)
    truth = [info["true_start_z"]]
    while len(truth) < 4:
        obs, _, term, _, info = env.step(act(obs, info))
        assert not term
        if "apex_z" in info:
            truth.append(info["true_apex_z"])
    act(obs, info)
    assert len(seen) == len(truth)
    for z, t in zip(seen, truth, strict=True):
        assert z[0] != t[0] and np.array_equal(z[1:], t[1:])


def test_lqr_residual_plans_on_the_observed_state():
    env = RandomizedPlant(gym.make("PassiveBoundRescue-v1", action_mode="lqr_residual"),
                          {"noise": {"y_g": 1.0, "theta1": 1.0}})  # fmt: skip
    _, info = env.reset(seed=3)
    lqr = env.unwrapped.lqr
    _, _, _, _, step = env.step(np.zeros(env.action_space.shape, dtype=np.float32))
    assert np.array_equal(step["u"], lqr.coefficients(info["start_z"]))
    assert not np.array_equal(step["u"], lqr.coefficients(info["true_start_z"]))


@pytest.mark.parametrize("order", ["library-outside", "library-inside"])
def test_library_row_0_plans_on_the_observed_state(order):
    noise = {"noise": {"y_g": 1.0, "theta1": 1.0}}
    if order == "library-outside":
        env = LibraryActions(RandomizedPlant(gym.make("PassiveBoundRescue-v1"), noise))
    else:
        env = RandomizedPlant(LibraryActions(gym.make("PassiveBoundRescue-v1")), noise)
    _, info = env.reset(seed=3)
    lqr = env.unwrapped.lqr
    _, _, _, _, step = env.step(0)
    assert np.array_equal(step["u"], lqr.coefficients(info["start_z"]))
    assert not np.array_equal(step["u"], lqr.coefficients(info["true_start_z"]))


# -- compositions (issue 40) --------------------------------------------------------------------


def test_a_randomized_plant_over_a_randomized_plant_is_refused():
    with pytest.raises(ValueError, match="already a RandomizedPlant") as e:
        RandomizedPlant(RandomizedPlant(gym.make("PassiveBound-v1"), "pm10"), "pm20")
    assert "\n" not in str(e.value)


@pytest.mark.parametrize(
    "kind",
    [float, np.float64, np.float32, lambda x: [x], lambda x: np.array([x]), np.array],
    ids=["float", "float64", "float32", "list", "array", "0-d array"],
)
def test_the_delay_line_takes_every_action_the_plain_env_takes(kind):
    plain = gym.make("PassiveBound-v1")
    late = RandomizedPlant(gym.make("PassiveBound-v1"), mismatch="delay1")
    acts = [kind(a) for a in np.linspace(-0.5, 0.5, 12)]
    plain.reset(seed=2)
    late.reset(seed=2)
    for k, a in enumerate(acts):
        o_late, *_ = late.step(a)
        o_plain, *_ = plain.step(np.float32(0.0) if k == 0 else acts[k - 1])
        assert np.array_equal(o_late, o_plain)


@pytest.mark.parametrize("bad", [np.array([np.nan]), float("inf"), [0.1, 0.2], "a"])
def test_the_delay_line_refuses_what_the_plain_env_refuses_when_given(bad):
    late = RandomizedPlant(gym.make("PassiveBound-v1"), mismatch="delay1")
    late.reset(seed=0)
    with pytest.raises(ValueError, match="action") as e:
        late.step(bad)  # at once, not one interval later
    assert "\n" not in str(e.value)


def test_library_actions_over_the_lqr_residual_mode_is_refused():
    env = gym.make("PassiveBoundRescue-v1", action_mode="lqr_residual")
    with pytest.raises(ValueError, match="action_mode='lqr_residual'") as e:
        LibraryActions(env)
    assert "\n" not in str(e.value)


# -- the privileged observation -----------------------------------------------------------------


@pytest.mark.parametrize(
    "env_id", ["PassiveBound-v1", "PassiveBoundStride-v1", "PassiveBoundRescue-v1"]
)
def test_the_privileged_observation_is_the_plants_factors(env_id):
    env = RandomizedPlant(gym.make(env_id), "pm10+noise", privileged_obs=True)
    n = gym.make(env_id).observation_space.shape[0]
    assert env.observation_space.shape == (n + 8,) and len(env.privileged_names) == 8
    for seed in (1, 2):
        obs, info = env.reset(seed=seed)
        want = np.array([info["plant_factors"][k] for k in env.privileged_names], np.float32)
        assert np.array_equal(obs[n:], want) and env.observation_space.contains(obs)
        obs, *_ = env.step(env.action_space.sample() * 0)
        assert np.array_equal(obs[n:], want)  # the same plant all episode, never noised
    plain = RandomizedPlant(gym.make(env_id), "pm10")
    assert plain.observation_space == gym.make(env_id).observation_space  # opt-in only
    for bad, words in (("noise", "varies no plant parameter"), ("pm10", "true or false")):
        with pytest.raises(ValueError, match=words) as e:
            RandomizedPlant(gym.make(env_id), bad, privileged_obs=1 if bad == "pm10" else True)
        assert "\n" not in str(e.value)


@pytest.mark.parametrize("policy", ["ppo-v1-final/s0", "archive/stride-residual/s0"])
def test_the_loader_refuses_a_policy_trained_on_the_privileged_observation(policy, tmp_path):
    import shutil

    import yaml

    from agents.runtime.policy import load_controller

    folder = tmp_path / "privileged"
    shutil.copytree(bound_env_root() / "agents" / "policies" / policy, folder)
    data = yaml.safe_load((folder / "config.yaml").read_text())
    section = data[data["run"]["env_id"]]
    entry = {
        "bound_env.envs.randomized.RandomizedPlant": {"mismatch": "pm10", "privileged_obs": True}
    }
    section["env_wrapper"] = [entry, *section["env_wrapper"]]
    (folder / "config.yaml").write_text(yaml.safe_dump(data))
    with pytest.raises(ValueError, match="trained with a privileged observation") as e:
        load_controller(str(folder))
    assert "\n" not in str(e.value)


def bound_env_root():
    from pathlib import Path

    return Path(__file__).resolve().parent.parent
