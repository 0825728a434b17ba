"""Agents: config loading, training smoke run, margins schema, numerics on known answers."""

from __future__ import annotations

import inspect
import json
import math
from pathlib import Path

import numpy as np
import pytest

from agents.common.config import DEFAULT_CONFIG, apply_sets, load_hyperparams, parse_set, preprocess
from agents.results.margins import compute_margins
from agents.runtime.controllers import MLPController, ZeroController
from agents.runtime.policy import load_controller
from bound_env.analysis.margins import BUDGETS, random_directions
from bound_env.model.numerics import (
    bisect_threshold,
    fd_jacobian,
    map_fixed_point,
    sorted_eigenvalues,
)

# the shipped PPO policy (the `default` controller is a distilled choice policy: test_distill)
SHIPPED = Path(__file__).resolve().parent.parent / "agents" / "policies" / "archive" / "ppo-v1"
MARGIN_KEYS = (
    "basin",
    "basin_min",
    "emax",
    "eigenvalues",
    "slope_window_deg",
    "kc_window",
    "push",
    "effort",
)


# -- config --------------------------------------------------------------------------------------


@pytest.mark.slow
def test_config_file_parses_in_rl_zoo3_format():
    from stable_baselines3 import PPO

    hp = load_hyperparams(DEFAULT_CONFIG, "PassiveBound-v0")
    for key in (
        "n_envs",
        "n_timesteps",
        "policy",
        "normalize",
        "n_steps",
        "batch_size",
        "gamma",
        "learning_rate",
        "policy_kwargs",
        "env_kwargs",
    ):
        assert key in hp, key
    assert isinstance(hp["policy_kwargs"], str)  # rl-zoo3 keeps it a string
    spec = preprocess(hp)
    assert spec.n_envs >= 1 and spec.n_timesteps >= 1e5
    assert spec.normalize_kwargs["gamma"] == hp["gamma"]
    allowed = set(inspect.signature(PPO.__init__).parameters)
    assert set(spec.algo_kwargs) <= allowed, set(spec.algo_kwargs) - allowed
    assert callable(spec.algo_kwargs["learning_rate"])
    assert spec.algo_kwargs["learning_rate"](1.0) == pytest.approx(3e-4)
    assert "net_arch" in spec.algo_kwargs["policy_kwargs"]
    assert [c.__name__ for c, _ in spec.wrappers] == ["ObservationFilter", "PerturbedStarts"]
    assert [c.__name__ for c, _ in spec.callbacks] == [
        "NoiseCurriculumCallback",
        "BasinValidationCallback",
    ]
    literal = preprocess(load_hyperparams(DEFAULT_CONFIG, "PassiveBoundLiteral-v0"))
    assert literal.env_kwargs["gait"] == "literal-cycle"
    assert literal.algo_kwargs["n_steps"] == spec.algo_kwargs["n_steps"]


def test_config_errors_and_overrides(tmp_path):
    with pytest.raises(ValueError, match="no hyperparameters for 'Nope-v0'"):
        load_hyperparams(DEFAULT_CONFIG, "Nope-v0")
    with pytest.raises(FileNotFoundError):
        load_hyperparams(tmp_path / "missing.yaml", "PassiveBound-v0")
    hp = apply_sets(
        {"env_kwargs": {"gait": "default"}},
        ["env_kwargs.max_torque=20", "n_timesteps=1e5", "learning_rate=lin_1e-3"],
    )
    assert hp == {
        "env_kwargs": {"gait": "default", "max_torque": 20},
        "n_timesteps": 1e5,
        "learning_rate": "lin_1e-3",
    }
    assert parse_set("normalize=true") == (["normalize"], True)
    with pytest.raises(ValueError, match="KEY=VALUE"):
        parse_set("n_envs")
    with pytest.raises(ValueError, match="not a mapping"):
        apply_sets({"callback": [1]}, ["callback.x=2"])


# -- numerics on known answers -------------------------------------------------------------------


@pytest.mark.parametrize("threshold", [0.0123, 0.2, 0.77])
def test_bisection_finds_a_synthetic_threshold(threshold):
    calls = []

    def ok(s):
        calls.append(s)
        return s < threshold

    s, capped = bisect_threshold(ok, 1e-3, 1.0, iters=12)
    assert not capped
    assert s < threshold and s > threshold * (1000 ** (-1 / 2**12)) ** 1.01
    assert len(calls) == 14
    lin, _ = bisect_threshold(ok, 0.0, 1.0, iters=20, log=False)
    assert abs(lin - threshold) < 2e-6
    assert bisect_threshold(lambda s: True, 1e-3, 1.0, 5) == (1.0, True)
    assert bisect_threshold(lambda s: False, 1e-3, 1.0, 5) == (0.0, False)


def test_multipliers_of_a_linear_map():
    rng = np.random.default_rng(0)
    # A with eigenvalues 0.9 e^{+-0.7i}, 0.5, -0.3, 0.1, 0.05 in a random basis
    blocks = np.zeros((6, 6))
    r, w = 0.9, 0.7
    blocks[:2, :2] = [[r * math.cos(w), -r * math.sin(w)], [r * math.sin(w), r * math.cos(w)]]
    blocks[2:, 2:] = np.diag([0.5, -0.3, 0.1, 0.05])
    Q = rng.standard_normal((6, 6))
    A = Q @ blocks @ np.linalg.inv(Q)
    b = rng.standard_normal(6)
    z_fix = np.linalg.solve(np.eye(6) - A, b)

    def f(z):
        return A @ z + b

    z, res, jac = map_fixed_point(f, z_fix + 0.3, np.full(6, 1e-4), settle=3, newton_iters=5)
    assert res < 1e-10
    assert np.allclose(z, z_fix, atol=1e-9)
    assert np.allclose(fd_jacobian(f, z, np.full(6, 1e-3), one_sided=False), A, atol=1e-9)
    lam = sorted_eigenvalues(jac)
    want = np.array([0.9 * np.exp(0.7j), 0.9 * np.exp(-0.7j), 0.5, -0.3, 0.1, 0.05])
    assert np.allclose(lam, want, atol=1e-8)
    assert abs(lam[0]) == pytest.approx(0.9)


def test_random_directions_are_reproducible_and_scaled():
    u = random_directions(10)
    assert np.allclose(np.max(np.abs(u), axis=1), 1.0)
    assert np.array_equal(u, random_directions(10))


# -- training ------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def smoke_run(tmp_path_factory):
    from agents.training.train import train

    runs = tmp_path_factory.mktemp("runs")
    sets = [
        "n_envs=2",
        "n_steps=256",
        "batch_size=128",
        "n_epochs=2",
        "policy_kwargs=dict(net_arch=dict(pi=[16], vf=[16]))",
        "callback=[{agents.training.train.BasinValidationCallback: {eval_freq: 1024, iters: 2}}]",
    ]
    run = train(
        name="smoke",
        seed=3,
        n_timesteps=2048,
        sets=sets,
        runs_dir=runs,
        eval_freq=1024,
        n_eval_episodes=1,
        save_freq=1024,
        progress_bar=False,
    )
    return run


@pytest.mark.slow
def test_training_smoke_run_writes_a_model_that_loads_and_acts(smoke_run):
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecNormalize

    run = smoke_run
    for name in (
        "model.zip",
        "vecnormalize.pkl",
        "config.yaml",
        "run.json",
        "eval.csv",
        "eval.png",
        "basin_validation.csv",
        "best/model.zip",
        "best/vecnormalize.pkl",
    ):
        assert (run / name).is_file(), name
    assert list((run / "checkpoints").glob("rl_model_*_steps.zip"))
    assert list((run / "tb").iterdir())
    info = json.loads((run / "run.json").read_text())
    assert info["seed"] == 3 and info["timesteps_done"] >= 2048
    model = PPO.load(run / "model.zip", device="cpu")
    ctrl = load_controller(run)
    assert isinstance(ctrl, MLPController) and ctrl.seed == 3

    import gymnasium as gym

    import bound_env

    gym.register_envs(bound_env)
    env = gym.make("PassiveBound-v0")
    obs, _ = env.reset(seed=1)
    vn = VecNormalize.load(str(run / "vecnormalize.pkl"), _dummy_venv(model.observation_space))
    index = ctrl.obs_index if ctrl.obs_index is not None else slice(None)
    for _ in range(30):
        a_torch, _ = model.predict(vn.normalize_obs(obs[index][None]), deterministic=True)
        a_np = ctrl(obs)
        assert a_np == pytest.approx(float(np.clip(a_torch[0, 0], -1, 1)), abs=1e-5)
        obs, *_ = env.step(np.array([a_np]))


@pytest.mark.slow
def test_export_ships_the_final_model_unless_told(smoke_run, tmp_path):
    from agents.cli import export_policy

    dest = export_policy(smoke_run, tmp_path / "final")
    assert (dest / "model.zip").read_bytes() == (smoke_run / "model.zip").read_bytes()
    info = json.loads((dest / "exported.json").read_text())
    assert info["selection"].startswith("none") and "basin_validation" not in info
    dest = export_policy(smoke_run, tmp_path / "policy", source="best")
    assert (dest / "model.zip").read_bytes() == (smoke_run / "best" / "model.zip").read_bytes()
    info = json.loads((dest / "exported.json").read_text())
    assert info["exported_from"].endswith("best") and "basin_validation" in info
    assert isinstance(load_controller(dest), MLPController)
    with pytest.raises(FileNotFoundError):
        export_policy(tmp_path / "nope", tmp_path / "x")


def _dummy_venv(obs_space):
    import gymnasium as gym
    from stable_baselines3.common.vec_env import DummyVecEnv

    from agents.common.wrappers import ObservationFilter

    def make():
        env = gym.make("PassiveBound-v0")
        return (
            ObservationFilter(env) if obs_space.shape[0] < env.observation_space.shape[0] else env
        )

    return DummyVecEnv([make])


@pytest.mark.slow
def test_resume_continues_from_the_last_checkpoint(smoke_run, tmp_path):
    import shutil

    from agents.training.checkpoints import last_checkpoint
    from agents.training.train import train

    run = tmp_path / "runs" / "smoke"
    shutil.copytree(smoke_run, run)
    (run / "model.zip").unlink()
    ckpt = last_checkpoint(run)
    assert ckpt is not None and ckpt[1] is not None
    train(
        name="smoke",
        resume=True,
        n_timesteps=ckpt[2] + 1024,
        runs_dir=tmp_path / "runs",
        eval_freq=10**9,
        save_freq=10**9,
        progress_bar=False,
        vec_env="dummy",
    )
    info = json.loads((run / "run.json").read_text())
    assert info["timesteps_done"] >= ckpt[2] + 1024
    assert info["sessions"][-1]["from"] == ckpt[2]
    with pytest.raises(ValueError, match="exists"):
        train(name="smoke", n_timesteps=512, runs_dir=tmp_path / "runs", progress_bar=False)


def test_observation_filter_drops_the_flags():
    import gymnasium as gym

    import bound_env
    from agents.common.wrappers import ObservationFilter, observation_index

    gym.register_envs(bound_env)
    base = gym.make("PassiveBound-v0")
    env = ObservationFilter(base)
    obs, _ = env.reset(seed=0)
    names = list(base.unwrapped.task.obs_names)
    assert obs.shape == (len(names) - 6,) == env.observation_space.shape
    assert not {"contact_back", "touched_front", "leg_angle_back"} & set(env.names)
    idx = observation_index([{"agents.common.wrappers.ObservationFilter": {}}], names)
    assert np.array_equal(idx, env.index)
    assert observation_index(["agents.common.wrappers.PerturbedStarts"], names) is None
    with pytest.raises(ValueError, match="unknown observation"):
        ObservationFilter(base, drop=("nope",))


def test_configs_name_the_callbacks_through_agents_train():
    """configs/ppo.yaml and the saved runs' config.yaml name the callbacks
    ``agents.training.train.<name>``: still the classes of `agents.training.train_callbacks`."""
    import agents.training.train_callbacks as callbacks
    from agents.common.config import get_class_by_name

    for name in ("NoiseCurriculumCallback", "BasinValidationCallback"):
        assert get_class_by_name(f"agents.training.train.{name}") is getattr(callbacks, name)


def test_curriculum_raises_the_start_noise():
    import gymnasium as gym

    import bound_env
    from agents.common.wrappers import PerturbedStarts
    from agents.training.train_callbacks import NoiseCurriculumCallback

    gym.register_envs(bound_env)
    env = PerturbedStarts(gym.make("PassiveBound-v0"), noise_scale=0.0)
    _, info = env.reset(seed=0)
    assert np.allclose(info["start_z"], env.z_ref)
    env.get_wrapper_attr("set_noise_scale")(2.0)
    starts = np.array([env.reset()[1]["start_z"] for _ in range(50)])
    dev = np.abs(starts - env.z_ref) / env.apex_scales
    assert dev.max() <= 2.0 + 1e-9 and dev.max() > 0.5
    cb = NoiseCurriculumCallback(start=0.5, end=3.0, ramp=0.5)
    assert cb.value_at(0, 100) == 0.5
    assert cb.value_at(25, 100) == pytest.approx(1.75)
    assert cb.value_at(90, 100) == 3.0


# -- margins -------------------------------------------------------------------------------------


def _check_schema(r):
    for key in MARGIN_KEYS:
        assert key in r, key
    assert set(r["basin"]) == {"y_g", "theta1", "theta2", "xdot_g", "theta1dot", "theta2dot"}
    for e in r["basin"].values():
        for s in ("+", "-"):
            assert 0.0 <= e[s]["rel"] <= e[s]["cap"] and e[s]["abs"] >= 0
            assert e[s]["abs"] == pytest.approx(e[s]["rel"] * abs(e["z_star"]))
    for key in (
        "basin_scale",
        "basin_ceiling",
        "basin_min_cycle",
        "basin_share_min",
        "terrain",
        "terrain_sigma50_deg",
    ):
        assert key in r, key
    assert set(r["basin_ceiling"]) == set(r["basin"])
    c = r["basin_curve"]
    assert len(c["ci_low"]) == len(c["sizes"]) and c["r50_ci"][0] <= c["r50"] <= c["r50_ci"][1]
    assert all(
        lo <= p <= hi for lo, p, hi in zip(c["ci_low"], c["success"], c["ci_high"], strict=True)
    )
    assert r["basin_min"] == min(e[s]["rel"] for e in r["basin"].values() for s in "+-")
    assert len(r["eigenvalues"]) == 6 and all(len(v) == 2 for v in r["eigenvalues"])
    assert r["emax"] == pytest.approx(math.hypot(*r["eigenvalues"][0]))
    assert len(r["slope_window_deg"]) == 2 and len(r["kc_window"]) == 2
    assert set(r["push"]) == {"xdot", "th1dot"}
    for e in r["push"].values():
        assert len(e["sizes"]) == len(e["success"])
    assert r["effort"] >= 0
    json.dumps(r)


@pytest.mark.slow
def test_margins_passive_test_budget(tmp_path):
    r = compute_margins("passive", budget="test", workers=1, out=tmp_path)
    _check_schema(r)
    assert r["emax"] == pytest.approx(0.878, abs=2e-3)  # the passive gait's e_max
    assert r["effort"] == 0.0
    assert np.max(np.abs(r["fixed_point_shift"])) < 1e-6
    assert r["slope_window_deg"][0] < 1.9343 < r["slope_window_deg"][1]
    assert r["kc_window"][0] < 295.0 < r["kc_window"][1]
    for name in ("margins.json", "basin.csv", "curve.csv", "push.csv", "basin.png"):
        assert (tmp_path / name).is_file()
    # the cache makes a second run instant and identical
    r2 = compute_margins("passive", budget="test", workers=1, out=tmp_path)
    assert r2["basin"] == r["basin"] and r2["seconds"] < r["seconds"]


@pytest.mark.slow
@pytest.mark.skipif(not (SHIPPED / "model.zip").is_file(), reason="no shipped policy")
def test_margins_shipped_policy_test_budget(tmp_path):
    r = compute_margins(str(SHIPPED), budget="test", workers=2, out=tmp_path)
    _check_schema(r)
    assert r["emax"] < 0.878
    assert r["effort_frac"] < 0.25


def test_shipped_policy_files_are_small():
    if not (SHIPPED / "model.zip").is_file():
        pytest.skip("no shipped policy")
    total = sum(p.stat().st_size for p in SHIPPED.iterdir() if p.is_file())
    assert total < 2 * 1024**2
    for name in ("model.zip", "vecnormalize.pkl", "config.yaml", "eval.csv", "eval.png"):
        assert (SHIPPED / name).is_file(), name


def test_missing_policy_and_wrong_observation_space(tmp_path, capsys):
    from stable_baselines3 import PPO

    from bound_env.commands.cli import main

    with pytest.raises(FileNotFoundError, match="does not exist"):
        load_controller(tmp_path / "nope")
    assert main(["margins", "--policy", str(tmp_path / "nope"), "--budget", "test"]) == 2
    assert "does not exist" in capsys.readouterr().err
    model = PPO("MlpPolicy", "Pendulum-v1", n_steps=64, device="cpu")
    (tmp_path / "pendulum").mkdir()
    model.save(tmp_path / "pendulum" / "model.zip")
    with pytest.raises(ValueError, match="observation space"):
        load_controller(tmp_path / "pendulum")
    assert main(["margins", "--policy", str(tmp_path / "pendulum"), "--budget", "test"]) == 2
    assert "observation space" in capsys.readouterr().err
    with pytest.raises(ValueError, match="budget"):
        compute_margins(ZeroController(), budget="huge")


def test_budgets_are_ordered():
    q, f = BUDGETS["quick"], BUDGETS["full"]
    assert f.basin_iters > q.basin_iters and f.basin_strides > q.basin_strides
    assert f.curve_dirs > q.curve_dirs and f.push_samples > q.push_samples


@pytest.mark.slow
def test_cli_margins_json_and_compare(tmp_path, capsys):
    from bound_env.commands.cli import main

    assert (
        main(
            [
                "margins",
                "--policy",
                "passive",
                "--budget",
                "test",
                "--json",
                "--workers",
                "1",
                "--out",
                str(tmp_path / "m"),
            ]
        )
        == 0
    )
    r = json.loads(capsys.readouterr().out)
    _check_schema(r)
    docs = tmp_path / "docs"
    assert (
        main(
            [
                "compare",
                "--budget",
                "test",
                "--entry",  # passive and lqr: the curated columns are test_install's
                "lqr",
                "--workers",
                "1",
                "--out",
                str(tmp_path / "c"),
                "--docs",
                str(docs),
            ]
        )
        == 0
    )
    page = (docs / "MARGINS.md").read_text()
    assert "basin_min" in page and "passive" in page and "lqr" in page
    assert (docs / "margins_basin.png").is_file()
