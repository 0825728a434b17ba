"""The learned adaptive controller (agents/adaptive.py): its history, its reset per episode,
its files, and a tiny DAgger run whose history changes its action on two different plants."""

import copy
import json

import numpy as np
import pytest

from agents.experts.adaptive import (
    POLICY_FILE,
    AdaptiveConfig,
    load_adaptive_policy,
    make_controller,
    n_features,
    privileged_teacher,
    save_policy,
    train_adaptive,
    true_map,
)
from bound_env.control import load_controller
from bound_env.model.mismatch import EIGHT, plant_params
from bound_env.sim.stride_protocol import reset_controller


@pytest.fixture(scope="module")
def mpc():
    return load_controller("mpc")


def random_controller(mpc, k=3, seed=0):
    rng = np.random.default_rng(seed)
    D, K = n_features(k, mpc.basis.K), mpc.basis.K
    layers = [
        (rng.normal(0, 0.5, (16, D)), rng.normal(0, 0.1, 16)),
        (rng.normal(0, 0.05, (K + len(EIGHT), 16)), np.zeros(K + len(EIGHT))),
    ]
    return make_controller(mpc, layers, np.zeros(D), np.ones(D), k)


def two_plants(mpc):
    lo = plant_params(mpc.params, dict.fromkeys(EIGHT, 0.97))
    hi = plant_params(mpc.params, dict.fromkeys(EIGHT, 1.03))
    return lo, hi


def run(ctrl, mpc, params, strides, z0=None):
    """Strides of ``ctrl`` on ``params`` from z0 (default z*); the apexes seen."""
    plant = true_map(mpc, params)
    z = mpc.z_ref.copy() if z0 is None else np.asarray(z0, dtype=float)
    seen, plans = [], []
    for _ in range(strides):
        seen.append(z.copy())
        u = ctrl.coefficients(z)  # as on_apex decides: timed, its kind logged
        plans.append(u)
        z = plant.map(z, mpc.profile_actions(u)[0])
        assert z is not None
    return seen, plans


def test_history_slots_fill_then_shift(mpc):
    ctrl = random_controller(mpc, k=2)
    K = mpc.basis.K
    z = mpc.z_ref * 1.02
    f0 = ctrl.features(z)
    assert f0.shape == (n_features(2, K),)
    assert f0[6] == 0.0 and f0[6 + 13 + K] == 0.0  # no stride yet: both slots invalid
    ctrl.plan(z)
    f1 = ctrl.features(z * 1.001)
    assert f1[6] == 1.0 and f1[6 + 13 + K] == 0.0  # one stride: the newest slot only
    u0 = ctrl._last[1]
    np.testing.assert_array_equal(f1[6 + 7 : 6 + 7 + K], np.clip(u0, -10, 10))
    ctrl.plan(z * 1.001)
    ctrl.plan(z * 0.999)
    f3 = ctrl.features(z)
    assert f3[6] == 1.0 and f3[6 + 13 + K] == 1.0
    # the surprise of a stride is its next apex minus the nominal linear map's prediction
    x = ctrl._last[0]
    r = (z - mpc.z_ref - ctrl._A @ (x - mpc.z_ref) - ctrl._B @ ctrl._last[1]) / ctrl.scales
    np.testing.assert_allclose(f3[6 + 7 + K : 6 + 13 + K], np.clip(r, -10, 10))


def test_reset_forgets_the_episode(mpc):
    """After ``reset_controller`` (the stride protocol's reset, called by every loop at an
    episode's start) the controller decides as a fresh one; without it the history carries."""
    lo, hi = two_plants(mpc)
    ctrl = random_controller(mpc)
    fresh = copy.deepcopy(ctrl)  # deepcopy drops the episode too
    _, first = run(ctrl, mpc, lo, 4)
    z = mpc.z_ref + 0.1 * np.abs(mpc.z_ref)
    carried = ctrl.features(z)
    reset_controller(ctrl)
    np.testing.assert_array_equal(ctrl.features(z), fresh.features(z))
    assert not np.array_equal(carried, ctrl.features(z))
    _, again = run(ctrl, mpc, lo, 4)
    np.testing.assert_array_equal(np.array(first), np.array(again))


def test_nominal_cycle_keeps_zero_torque(mpc):
    """On the nominal plant from z* the gate plays the LQR (zero to the cycle's rounding),
    stride after stride (no surprise); a robot off its model opens the gate even near z*."""
    ctrl = random_controller(mpc)
    seen, plans = run(ctrl, mpc, mpc.params, 5)
    for z, u in zip(seen, plans, strict=True):
        np.testing.assert_allclose(z, mpc.z_ref, rtol=0, atol=1e-9)
        np.testing.assert_array_equal(u, mpc.lqr.coefficients(z))  # the gate: the LQR
        assert np.max(np.abs(u)) < 1e-9
    assert ctrl.decision_kinds[-5:] == ["gate"] * 5
    lo, _ = two_plants(mpc)
    reset_controller(ctrl)
    seen, plans = run(ctrl, mpc, lo, 3)
    assert np.max(np.abs(plans[0])) == 0.0  # the start: no history, the gate
    assert ctrl.decision_kinds[-2:] == ["override", "override"]
    assert ctrl.stateful and ctrl.interval_actions is None and ctrl.apex_torques is None


def test_privileged_teacher_plans_on_the_true_plant(mpc):
    lo, _ = two_plants(mpc)
    t = privileged_teacher(mpc, lo)
    z = mpc.z_ref + 0.05 * np.abs(mpc.z_ref)
    a = mpc.profile_actions(np.zeros(mpc.basis.K))
    np.testing.assert_allclose(
        t.model.run(z[None], a).z1[0], true_map(mpc, lo).map(z, a[0]), rtol=0, atol=1e-5
    )
    assert not np.allclose(mpc.model.run(z[None], a).z1[0], t.model.run(z[None], a).z1[0])


def test_files_round_trip_and_tampering(mpc, tmp_path):
    ctrl = random_controller(mpc)
    save_policy(tmp_path / "p", mpc, ctrl, {"adaptive": {}})
    back = load_adaptive_policy(tmp_path / "p")
    z = mpc.z_ref + 0.1 * np.abs(mpc.z_ref)
    np.testing.assert_array_equal(back.plan(z), ctrl.plan(z))
    assert back.fingerprint() == ctrl.fingerprint()
    cfg = json.loads((tmp_path / "p" / "config.json").read_text())
    assert cfg["kind"] == "adaptive" and cfg["factor_keys"] == list(EIGHT)
    with np.load(tmp_path / "p" / POLICY_FILE) as d:
        arrays = dict(d)
    arrays["mu"] = arrays["mu"][:-1]
    np.savez(tmp_path / "p" / POLICY_FILE, **arrays)
    with pytest.raises(ValueError, match="does not match"):
        load_adaptive_policy(tmp_path / "p")
    with pytest.raises(ValueError, match="do not fit"):
        load_adaptive_policy(tmp_path / "p", force=True)


@pytest.mark.slow
def test_tiny_training_history_changes_the_action(mpc, tmp_path):
    """A tiny DAgger run (a few hundred strides on ±10 % plants with sensor noise), then the
    same apex after three strides on two plants that differ: the actions differ, and only
    through the history (reset, both decide alike)."""
    cfg = AdaptiveConfig(
        rounds=1, episodes_first=20, strides=12, epochs=60, val_plants=2, val_strides=5
    )
    summary = train_adaptive(cfg, tmp_path / "run", progress=False)
    assert 150 <= summary["rounds"][0]["states"] <= 240
    ctrl = load_adaptive_policy(tmp_path / "run" / "policy")
    lo, hi = two_plants(mpc)
    z = mpc.z_ref + 0.08 * np.abs(mpc.z_ref)  # past the gate
    acts = []
    for p in (lo, hi):
        reset_controller(ctrl)
        run(ctrl, mpc, p, 3)
        acts.append(ctrl.decide(z, ctrl.features(z)))
    assert np.max(np.abs(acts[0] - acts[1])) > 1e-3
    reset_controller(ctrl)
    a = ctrl.decide(z, ctrl.features(z))
    reset_controller(ctrl)
    np.testing.assert_array_equal(a, ctrl.decide(z, ctrl.features(z)))
    # a resumed run (every round saved) refits the same policy
    train_adaptive(cfg, tmp_path / "run", progress=False)
    assert load_adaptive_policy(tmp_path / "run" / "policy").fingerprint() == ctrl.fingerprint()


@pytest.mark.parametrize(
    "hp, match",
    [
        ({"algo": "adaptive-dagger", "adaptive": {"kk": 3}}, "adaptive.kk: unknown"),
        ({"algo": "adaptive-dagger", "extra": 1}, "unknown key 'extra'"),
        (
            {"algo": "adaptive-dagger", "env_kwargs": {"max_torque": 40.0}},
            "env_kwargs.max_torque = 40.0, but the expert",
        ),
        (
            {"algo": "adaptive-dagger", "env_wrapper": [{"agents.stride.StrideControl": {}}]},
            "RandomizedPlant only",
        ),
        (
            {
                "algo": "adaptive-dagger",
                "env_wrapper": [{"bound_env.wrappers.RandomizedPlant": {"mismatch": "pm99"}}],
            },
            "unknown mismatch preset",
        ),
    ],
)
def test_recipe_section_refuses_bad_keys(hp, match):
    from agents.experts.adaptive_recipe import config_from_section

    with pytest.raises(ValueError, match=match):
        config_from_section(hp, "PassiveBoundStride-v1", 0)
    with pytest.raises(ValueError, match="stride env"):
        config_from_section({"algo": "adaptive-dagger"}, "PassiveBound-v1", 0)


def test_recipe_section_reads_the_shipped_config():
    from agents.common.config import load_hyperparams
    from agents.experts.adaptive_recipe import config_from_section

    cfg = config_from_section(
        load_hyperparams("adaptive", "PassiveBoundStride-v1"), "PassiveBoundStride-v1", 4
    )
    assert cfg.mismatch == "pm10+noise" and cfg.k == 3 and cfg.seed == 4 and cfg.hidden == (64, 64)


@pytest.mark.slow
def test_train_command_runs_the_recipe(tmp_path):
    """``bound-env train --config adaptive`` (tiny settings): a run folder, an exported policy
    with its model card, loadable by path."""
    from agents.runtime.policy import load_controller
    from bound_env.commands.cli import main

    argv = ["train", "--config", "adaptive", "--seed", "3", "--out", str(tmp_path / "runs")]
    for kv in ("rounds=1", "episodes_first=2", "strides=3", "val_plants=1", "val_strides=2"):
        argv += ["--hp", f"adaptive.{kv}"]
    argv += ["--hp", "adaptive.epochs=2", "--export-out", str(tmp_path / "pol"), "--no-progress"]
    assert main(argv) == 0
    assert (tmp_path / "pol" / "MODEL_CARD.md").is_file()
    assert "k = 3" in (tmp_path / "pol" / "MODEL_CARD.md").read_text()
    assert load_controller(tmp_path / "pol").k == 3
