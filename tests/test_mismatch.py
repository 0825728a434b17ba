"""Model error: the spec (presets, YAML, errors), sampled plants, the randomized envs
(`RandomizedPlant`) and the margins under error (`mismatch_tasks`, `mismatch_report`)."""

import gymnasium as gym
import numpy as np
import pytest

import bound_env
from bound_env.envs.wrappers import RandomizedPlant
from bound_env.model.mismatch import (
    EIGHT,
    NOISE_SCALES,
    PLANT_KEYS,
    PRESETS,
    as_spec,
    sample_plants,
)
from bound_env.model.params import load_gait

gym.register_envs(bound_env)
ENV_IDS = ("PassiveBound-v1", "PassiveBoundStride-v1", "PassiveBoundRescue-v0")


# -- the spec ----------------------------------------------------------------------------------


def test_presets():
    for name in PRESETS:
        assert as_spec(name).name == name
    s = as_spec("pm10")
    assert dict(s.ranges) == {k: 0.10 for k in EIGHT}
    assert dict(as_spec("all20").ranges) == {k: 0.20 for k in PLANT_KEYS}
    both = as_spec("pm5+noise+delay1")
    assert dict(both.ranges) == {k: 0.05 for k in EIGHT}
    assert dict(both.noise) == {k: 0.01 for k in NOISE_SCALES}
    assert both.delay == 1
    assert as_spec("none").is_nominal and not as_spec("pm5").is_nominal


@pytest.mark.parametrize(
    "spec, words",
    [
        ("pm7", "unknown mismatch preset 'pm7'"),
        ({"params": {"mass": 0.1}}, "unknown parameter 'mass'"),
        ({"params": {"kc": -0.1}}, "params.kc: a range must be >= 0"),
        ({"params": {"m1": 1.0}}, "params.m1: a range of 1.0 makes m1 non-positive"),
        ({"params": {"m1": "big"}}, "params.m1 must be a number"),
        ({"noise": {"contact_back": 0.1}}, "unknown observation component 'contact_back'"),
        ({"noise": {"theta1": -1}}, "noise.theta1: a standard deviation must be >= 0"),
        ({"noise": float("nan")}, "noise must be finite"),
        ({"delay": -1}, "delay must lie in [0, 20]"),
        ({"delay": 1.5}, "delay must be a whole number"),
        ({"delays": 1}, "unknown key(s) ['delays']"),
    ],
)
def test_bad_spec_is_one_line(spec, words):
    with pytest.raises(ValueError) as e:
        as_spec(spec)
    assert words in str(e.value) and "\n" not in str(e.value)


def test_yaml_file(tmp_path):
    f = tmp_path / "soft.yaml"
    f.write_text("params: {kb: 0.1, kf: 0.1}\nnoise: 0.02\ndelay: 2\n")
    s = as_spec(str(f))
    assert s.name == "soft" and dict(s.ranges) == {"kb": 0.1, "kf": 0.1} and s.delay == 2
    assert dict(s.noise) == {k: 0.02 for k in NOISE_SCALES}
    bad = tmp_path / "bad.yaml"
    bad.write_text("params: {kb: 2}\n")
    with pytest.raises(ValueError, match=r"mismatch file .*bad.yaml: .*params.kb"):
        as_spec(bad)
    with pytest.raises(ValueError, match="does not exist"):
        as_spec(tmp_path / "missing.yaml")


def test_sample_plants():
    nominal = load_gait("default").params
    a = sample_plants("pm10", 16, seed=3)
    assert a == sample_plants("pm10", 16, seed=3)
    assert a != sample_plants("pm10", 16, seed=4)
    for plant in a:
        assert set(plant) == set(EIGHT)
        for k, v in plant.items():
            assert 0.9 * getattr(nominal, k) <= v <= 1.1 * getattr(nominal, k)
    assert sample_plants("none", 3, seed=1) == [{}, {}, {}]
    # the overrides are a plant the stride map takes
    from bound_env.sim.stride_map import StrideMap

    sm = StrideMap("default", a[0])
    assert sm.params.m1 == pytest.approx(a[0]["m1"])


# -- the randomized envs -----------------------------------------------------------------------


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_check_env_and_seeded_plants(env_id):
    from gymnasium.utils.env_checker import check_env

    env = RandomizedPlant(gym.make(env_id), mismatch="pm10+noise")
    with pytest.warns(UserWarning):  # "different from the unwrapped version": a wrapper
        check_env(env, skip_render_check=True)
    _, i1 = env.reset(seed=5)
    _, i2 = env.reset(seed=5)
    _, i3 = env.reset(seed=6)
    assert i1["plant"] == i2["plant"] and i1["plant"] != i3["plant"]
    assert set(i1["plant_factors"]) == set(EIGHT)
    assert i1["plant"]["zeta"] != load_gait("default").params.zeta
    env.close()


def _rollout(env, seed, n=60):
    obs, info = env.reset(seed=seed)
    rng = np.random.default_rng(0)
    out = [obs]
    for _ in range(n):
        obs, r, term, trunc, info = env.step(env.action_space.sample() * 0 + rng.uniform(-1, 1))
        out.append(np.concatenate([obs.ravel(), [r]]))
        if term or trunc:
            break
    return out


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_no_error_is_the_env_bit_for_bit(env_id):
    plain = gym.make(env_id)
    wrapped = RandomizedPlant(gym.make(env_id), mismatch={"params": {k: 0.0 for k in EIGHT}})
    a, b = _rollout(plain, 11, 20), _rollout(wrapped, 11, 20)
    assert len(a) == len(b)
    for x, y in zip(a, b, strict=True):
        assert np.array_equal(x, y)


def test_noise_is_what_it_says():
    sigma = 0.05
    clean = RandomizedPlant(gym.make("PassiveBound-v1"), mismatch="none")
    noisy = RandomizedPlant(gym.make("PassiveBound-v1"), mismatch={"noise": {"theta1": sigma}})
    names = clean.unwrapped.task.obs_names
    i = names.index("theta1")
    diffs = []
    for seed in range(3):
        clean.reset(seed=seed)
        noisy.reset(seed=seed)
        for _ in range(60):  # zero torque: the same states; only the observation differs
            o1, *_ = clean.step(np.zeros(1, dtype=np.float32))
            o2, *_ = noisy.step(np.zeros(1, dtype=np.float32))
            d = o2 - o1
            assert np.all(np.delete(d, i) == 0)
            diffs.append(d[i])
    sd = np.std(diffs)
    assert 0.8 * sigma * NOISE_SCALES["theta1"] < sd < 1.2 * sigma * NOISE_SCALES["theta1"]


def test_delay_shifts_the_actions():
    plain = gym.make("PassiveBound-v1")
    late = RandomizedPlant(gym.make("PassiveBound-v1"), mismatch="delay2")
    acts = [np.array([a], dtype=np.float32) for a in np.linspace(-1, 1, 30)]
    plain.reset(seed=2)
    late.reset(seed=2)
    zero = np.zeros(1, dtype=np.float32)
    for k, a in enumerate(acts):
        o_late, *_ = late.step(a)
        o_plain, *_ = plain.step(zero if k < 2 else acts[k - 2])
        assert np.array_equal(o_late, o_plain)
    with pytest.raises(ValueError, match="delay"):
        RandomizedPlant(gym.make("PassiveBoundStride-v1"), mismatch="delay1")


def test_plant_changes_the_dynamics():
    env = RandomizedPlant(gym.make("PassiveBound-v1"), mismatch="pm20")
    plain = gym.make("PassiveBound-v1")
    a, b = _rollout(plain, 1, 60), _rollout(env, 1, 60)
    assert any(not np.array_equal(x, y) for x, y in zip(a, b, strict=False))


# -- margins under error -----------------------------------------------------------------------


def _setup(policy, spec="pm5", seed=12345):
    from bound_env.analysis.margins import Setup, as_budget
    from bound_env.analysis.margins.model_error.mismatch_tasks import MISMATCH_BUDGETS
    from bound_env.control import load_controller

    ctrl = load_controller(policy) if policy != "passive" else None
    if ctrl is None:
        from agents.runtime.controllers import ZeroController

        ctrl = ZeroController()
    g = load_gait("default")
    return Setup(
        controller=ctrl,
        gait="default",
        budget=as_budget("test"),
        z_star=g.z0,
        key=f"test-{policy}-{spec}",
        seed=seed,
        mismatch=as_spec(spec),
        mismatch_budget=MISMATCH_BUDGETS["test"],
    )


def test_hold_without_error_needs_no_torque():
    from bound_env.analysis.margins.model_error.mismatch_tasks import task_mm_hold

    r = task_mm_hold(_setup("lqr", "none"))
    assert r["outcomes"] == [1] * 8
    assert max(r["effort"]) < 1e-6  # the nominal cycle needs no torque
    assert max(max(s) for s in r["settle"]) < 1e-6


def test_hold_and_curve_under_error_are_seeded():
    from bound_env.analysis.margins.model_error.mismatch_tasks import plants_of, task_mm_curve

    s1, s2 = _setup("lqr", "pm10"), _setup("lqr", "pm10", seed=777)
    assert [p.m1 for p in plants_of(s1, 4)] != [p.m1 for p in plants_of(s2, 4)]
    a, b = task_mm_curve(s1, 0.05), task_mm_curve(s1, 0.05)
    assert a == b and len(a["outcomes"]) == 8


def test_median_interval():
    from bound_env.analysis.margins.model_error.mismatch_tasks import median_interval

    lo, hi = median_interval(list(range(32)))
    assert lo < 15.5 < hi and (lo, hi) == (9.0, 22.0)
    assert median_interval([3.0]) == [3.0, 3.0]


def _block(name, hold, curve):
    sizes = [0.01, 0.1]
    return {
        "spec": as_spec(name).to_dict(),
        "seeds": {"plants": 1, "noise": 2},
        "budget": {"plants": len(hold)},
        "plants": [{}] * len(hold),
        "hold": {
            "strides": 20,
            "k": sum(hold),
            "n": len(hold),
            "ci": [0.1, 0.9],
            "outcomes": hold,
            "effort_strides": 5,
            "effort_median": 3.0,
            "effort_median_ci": [1.0, 5.0],
        },
        "curve": [{"size": s, "outcomes": o} for s, o in zip(sizes, curve, strict=True)],
        "curve_strides": 20,
        "r50": 0.05,
        "r50_ci": [0.01, 0.1],
        "mfpt": [],
    }


def test_markdown_pairs_shared_plants():
    from bound_env.analysis.margins.model_error.mismatch_report import mismatch_markdown

    a = _block("pm5", [1, 1, 1, 1], [[1, 1, 1, 1], [1, 1, 0, 0]])
    b = _block("pm5", [1, 0, 0, 0], [[1, 1, 0, 0], [0, 0, 0, 0]])
    c = _block("pm10", [0, 0, 0, 0], [[0, 0, 0, 0], [0, 0, 0, 0]])
    md = mismatch_markdown({"passive": [b], "lqr": {"pm5": a, "pm10": c}})
    assert "### pm5" in md and "### pm10" in md and "#### " not in md
    assert "| lqr | 4/4" in md and "3/0, p = 0.25" in md  # McNemar: 3 discordant pairs
    assert "| passive | 1/4" in md


def test_cli_bad_spec(cli):
    code, out, err = cli("margins", "--policy", "lqr", "--budget", "test", "--mismatch", "pm3")
    assert code != 0 and "unknown mismatch preset 'pm3'" in err and "Traceback" not in err


@pytest.mark.slow
def test_cli_margins_mismatch(cli, tmp_path):
    import json

    code, out, err = cli(
        "margins",
        "--policy",
        "lqr",
        "--budget",
        "test",
        "--mismatch",
        "pm5",
        "--out",
        tmp_path,
        "--workers",
        "1",
        "--no-progress",
    )
    assert code == 0, err
    r = json.loads((tmp_path / "margins.json").read_text())
    assert "basin" in r and "mismatch" in r
    mm = r["mismatch"]["pm5"]
    assert mm["hold"]["n"] == 8 and len(mm["curve"]) == 2 and "model error pm5" in out


def test_noise_and_delay_reach_the_controller():
    """The runner's noise and delay change what an LQR does; without them the same runs
    repeat exactly."""
    from bound_env.analysis.margins.closed_loop import loop_for
    from bound_env.analysis.margins.model_error.mismatch_tasks import plant_runs

    setup = _setup("lqr", "none")
    loop = loop_for(setup)
    g = load_gait("default")
    Z0 = g.z0 + 0.05 * np.abs(g.z0) * np.array([1, -1, 1, -1, 1, -1])
    plants = [g.params] * 2
    runs = {
        name: plant_runs(
            loop, np.tile(Z0, (2, 1)), plants, 6, as_spec(name), [1, 2], effort_strides=3
        )
        for name in ("none", "delay1", "noise5")
    }
    again = plant_runs(
        loop, np.tile(Z0, (2, 1)), plants, 6, as_spec("none"), [1, 2], effort_strides=3
    )
    assert again == runs["none"]
    assert runs["none"]["effort"][0] == runs["none"]["effort"][1]  # the same robot twice
    assert runs["delay1"]["effort"] != runs["none"]["effort"]
    assert runs["noise5"]["effort"][0] != runs["noise5"]["effort"][1]  # own noise per robot


def test_compute_margins_refuses_a_spec_twice():
    from agents.runtime.controllers import ZeroController
    from bound_env.analysis.margins import compute_margins

    with pytest.raises(ValueError, match="names a spec twice: 'pm5'"):
        compute_margins(ZeroController(), budget="test", mismatch=["pm5", "pm5"])
