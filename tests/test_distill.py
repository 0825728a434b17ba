"""Tests of the distilled stride controller (agents/experts/distill.py): the expert's labels, a
small DAgger run end to end, resuming it, loading the policy by path without torch, the gate that
keeps zero torque on the cycle, and bad input."""

import json
import subprocess
import sys

import numpy as np
import pytest

from agents.experts.distill import DistillConfig, distill, good_rows
from agents.runtime.choice_policy import load_choice_policy
from bound_env.control.mpc import FELL, RETURNED, SURVIVED

SMALL = {"rounds": 2, "starts_first": 40, "starts_round": 20, "epochs": 5, "n_random": 8}


def test_good_rows_follow_the_expert():
    o = np.array([RETURNED, RETURNED, FELL])
    assert good_rows(o, np.array([3, 1, 0]), np.zeros(3)).tolist() == [True, False, False]
    o = np.array([SURVIVED, RETURNED, RETURNED, RETURNED, FELL])
    g = good_rows(o, np.array([12, 2, 3, 5, 0]), np.zeros(5))
    assert g.tolist() == [False, True, True, False, False]  # within one stride of the fastest
    o = np.array([FELL, SURVIVED, SURVIVED, SURVIVED, SURVIVED, FELL])
    s = np.array([0.0, 5.0, 7.0, 6.0, 1.0, 9.0])
    assert good_rows(o, np.full(6, 12), s).tolist() == [False, True, True, True, False, False]
    assert good_rows(np.array([FELL, FELL]), np.zeros(2), np.array([0.5, 0.7])) is None


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("distill")
    summary = distill(DistillConfig(**SMALL), out, progress=False)
    return out, summary


def test_a_small_run_makes_a_policy(run):
    out, summary = run
    assert [r["round"] for r in summary["rounds"]] == [0, 1]
    assert all(r["states"] > 0 for r in summary["rounds"])
    pol = load_choice_policy(out / "policy")
    assert pol.rows.shape == (4 + 2 * 7 + 8, 8)
    # the gate: the LQR (zero torque) on the cycle and near it
    assert np.array_equal(pol.coefficients(pol.z_ref), np.zeros(8))
    z = pol.z_ref + 0.3 * np.abs(pol.z_ref) * np.array([1, -1, 1, -1, 1, -1])
    u = pol.plan(z)
    # past the safe radius the plan is the row the network prefers: a network whose output
    # is a fixed preference for row j (zero last-layer weights, a one-hot bias) plays rows[j],
    # and one that prefers row 0 plays the LQR's plan
    from dataclasses import replace

    W, b = pol.layers[-1]
    for j in (0, 3, len(pol.rows) - 1):
        fixed = replace(pol, layers=[*pol.layers[:-1], (0 * W, 10.0 * np.eye(len(b))[j])])
        want = pol.lqr.coefficients(z) if j == 0 else pol.rows[j]
        assert np.array_equal(fixed.plan(z), want)
        assert np.array_equal(fixed.plan(pol.z_ref), np.zeros(8))  # within safe: the LQR
    # by path, through the loader every command uses
    from agents.runtime.policy import load_controller

    same = load_controller(out / "policy")
    assert same.fingerprint() == pol.fingerprint()
    assert np.array_equal(same.plan(z), u)


def test_a_rerun_resumes_from_the_saved_rounds(run, monkeypatch):
    out, summary = run
    import agents.experts.distill as d

    def no_labels(*a, **k):
        raise AssertionError("a saved round was labelled again")

    monkeypatch.setattr(d.Labeller, "label", no_labels)
    again = distill(DistillConfig(**SMALL), out, progress=False)
    assert again["rounds"] == summary["rounds"]
    with pytest.raises(ValueError, match="other settings"):
        distill(DistillConfig(**{**SMALL, "epochs": 6}), out, progress=False)


def test_the_policy_acts_without_torch(run):
    out, _ = run
    code = (
        "import sys, numpy as np; from agents.runtime.policy import load_controller; "
        f"p = load_controller({str(out / 'policy')!r}); "
        "p.plan(p.z_ref * 1.2); print('torch' in sys.modules)"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert r.stdout.strip() == "False"


def test_the_weights_are_the_fingerprint(run, tmp_path):
    import shutil

    out, _ = run
    pol = load_choice_policy(out / "policy")
    copy = tmp_path / "p"
    shutil.copytree(out / "policy", copy)
    with np.load(copy / "choice.npz") as f:
        arrays = dict(f)
    arrays["b0"] = arrays["b0"] + 1e-3
    np.savez(copy / "choice.npz", **arrays)
    with pytest.raises(ValueError, match="choice.npz does not match"):  # fingerprint.json
        load_choice_policy(copy)
    (copy / "fingerprint.json").unlink()  # a folder saved before fingerprints: not checked
    assert load_choice_policy(copy).fingerprint() != pol.fingerprint()
    (copy / "config.json").write_text(json.dumps({"kind": "choice"}))
    with pytest.raises(ValueError, match="not a readable distilled policy"):
        load_choice_policy(copy)


def test_the_shipped_default_is_a_fingerprinted_choice_policy(tmp_path, capsys):
    """`default` is the learned controller chosen on validation (a distilled choice policy):
    its fingerprint.json binds choice.npz and config.json; a changed file is refused with a
    one-line error unless --force (then a warning)."""
    import shutil

    from agents.runtime.choice_policy import ChoicePolicyController
    from agents.runtime.policy import load_controller, shipped_policies
    from bound_env.commands.cli import main

    src = shipped_policies()["default"]
    fp = json.loads((src / "fingerprint.json").read_text())
    assert set(fp) == {"choice.npz", "config.json"}
    ctrl = load_controller("default")
    assert isinstance(ctrl, ChoicePolicyController)
    assert ctrl.fingerprint() == load_controller(src).fingerprint()
    copy = tmp_path / "pol"
    shutil.copytree(src, copy)
    cfg = json.loads((copy / "config.json").read_text())
    cfg["note"] = "edited"
    (copy / "config.json").write_text(json.dumps(cfg))
    with pytest.raises(ValueError, match="config.json does not match.*--force"):
        load_controller(copy)
    assert main(["rollout", "--policy", str(copy), "--strides", "1"]) == 2
    err = capsys.readouterr().err
    assert "config.json does not match" in err and "--force" in err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    forced = load_controller(copy, force=True)
    assert forced.fingerprint() == ctrl.fingerprint()  # the edit changed nothing it uses
    assert "warning:" in capsys.readouterr().err


def test_a_saved_policy_carries_its_fingerprint(run):
    from agents.runtime.choice_policy import check_choice_fingerprint

    out, _ = run
    fp = json.loads((out / "policy" / "fingerprint.json").read_text())
    assert set(fp) == {"choice.npz", "config.json"}
    assert check_choice_fingerprint(out / "policy") == []


def test_cli_distill_refuses_an_existing_export(tmp_path):
    from bound_env.commands.cli import main

    (tmp_path / "e").mkdir()
    args = ["distill", "--out", str(tmp_path / "r"), "--export", str(tmp_path / "e"), "--quiet"]
    assert main(args) == 2
    assert not (tmp_path / "r").exists()


def test_finetune_env_rewards_survival_and_rescues(run):
    from agents.experts.finetune import rescue_env

    out, _ = run
    pol = load_choice_policy(out / "policy")
    env = rescue_env(pol, horizon=30)
    obs, _ = env.reset(seed=3)
    z = env.unwrapped.z
    assert env.unwrapped.past_safe(z) and obs.shape == (6,)
    assert np.array_equal(obs, ((z - pol.z_ref) / pol.scales).astype(np.float32))
    total, done, k = 0.0, False, 0
    while not done:
        obs, r, term, trunc, info = env.step(0)  # the LQR's plan, stride after stride
        total, done, k = total + r, term or trunc, k + 1
    if info["returned"]:
        assert total == 30.0  # a rescue is worth the whole horizon
    elif info["fell"]:
        assert total == k - 1
    else:
        assert trunc and total == 30.0 and k == 30


def test_finetune_starts_exactly_as_the_student(run, tmp_path):
    """PPO's actor gets the distilled weights: its deterministic choice is the student's."""
    import torch
    from stable_baselines3 import PPO

    from agents.experts.finetune import _actor_layers, _copy_actor, rescue_env

    out, _ = run
    pol = load_choice_policy(out / "policy")
    hidden = [W.shape[0] for W, _ in pol.layers[:-1]]
    model = PPO(
        "MlpPolicy",
        rescue_env(pol),
        policy_kwargs={"net_arch": {"pi": hidden, "vf": [8]}, "activation_fn": torch.nn.Tanh},
        device="cpu",
    )
    _copy_actor(model, pol.layers)
    x = np.random.default_rng(0).normal(size=(200, 6)).astype(np.float32)
    act, _ = model.predict(x, deterministic=True)
    want = np.argmax(pol.logits(pol.z_ref + x * pol.scales), axis=1)
    assert np.mean(act == want) > 0.99  # float32 vs float64 ties aside
    for (a, b), (c, d) in zip(_actor_layers(model), pol.layers, strict=True):
        np.testing.assert_allclose(a, c, atol=1e-6)
        np.testing.assert_allclose(b, d, atol=1e-6)


def test_the_default_controller_runs_in_margins_and_basin_map(tmp_path, capsys):
    """The shipped default (a choice policy) by name through every evaluation command."""
    from bound_env.commands.cli import main

    m = ["margins", "--policy", "default", "--budget", "test", "--workers", "1", "--no-cache"]
    assert main([*m, "--no-progress", "--json", "--out", str(tmp_path / "m")]) == 0
    r = json.loads(capsys.readouterr().out)
    # near the cycle the gate makes it the LQR: its cycle is the LQR's (z*, zero torque) and
    # its multipliers are those of the LQR's design, A - B G (a network that acted on the
    # cycle would move both); what its weights do further out is
    # test_default_returns_from_more_validation_starts_than_the_lqr's
    from bound_env.control import load_controller as load_classical

    lqr = load_classical("lqr")
    assert np.max(np.abs(r["fixed_point_shift"])) < 1e-8
    assert r["emax"] == pytest.approx(lqr.design["rho_closed"], rel=1e-5)
    b = ["basin-map", "--policy", "default", "--grid", "2", "--no-progress"]
    assert main([*b, "--out", str(tmp_path / "b")]) == 0
    assert (tmp_path / "b" / "basin.npz").is_file()


def test_default_returns_from_more_validation_starts_than_the_lqr():
    """The regression test of the shipped learned controller: from 16 validation starts at
    r = 0.22 (directions of seed 777, `agents.common.seeds.VALIDATION_SEED`; never the test set's),
    `default` returns (margins' closed loop, within 100 strides) from more than the LQR, and
    the same library and gate with random network weights return from fewer than `default`:
    its weights are what wins."""
    import dataclasses

    from agents.common.seeds import VALIDATION_SEED
    from agents.runtime.policy import load_controller
    from bound_env.analysis.margins import ClosedLoop, random_directions

    dirs = random_directions(16, VALIDATION_SEED)
    default = load_controller("default")
    rng = np.random.default_rng(0)
    layers = [
        (rng.normal(0, W.shape[1] ** -0.5, W.shape), np.zeros_like(b)) for W, b in default.layers
    ]
    scrambled = dataclasses.replace(default, layers=layers, name="random weights")
    z0 = default.z_ref + 0.22 * np.abs(default.z_ref) * dirs
    wins = {}
    for name, ctrl in (
        ("default", default),
        ("lqr", load_controller("lqr")),
        ("random", scrambled),
    ):
        runs = ClosedLoop(ctrl, "default").run_many(z0, default.z_ref, 100)
        wins[name] = sum(ok for ok, _, _ in runs)
    assert wins["default"] > wins["lqr"] and wins["default"] > wins["random"], wins


def test_the_finetuning_loop_resumes_exports_and_fingerprints(tmp_path, monkeypatch, capsys):
    """`agents.experts.finetune.finetune` with tiny settings from the shipped `default`: killed
    right after its first checkpoint, a rerun continues from that checkpoint (no second warm start)
    to the asked timesteps; the exported policy loads through its fingerprint, keeps the
    student's library and LQR, and a changed weight file is refused."""
    import stable_baselines3.common.callbacks as cbs

    import agents.experts.finetune as ft
    from agents.runtime.policy import resolve_policy

    student_dir = resolve_policy("default")
    student = load_choice_policy(student_dir)
    cfg = ft.FinetuneConfig(
        timesteps=192, n_envs=2, n_steps=32, batch_size=32, n_epochs=1, critic_warmup=1
    )
    killed = []

    class Small(cbs.CheckpointCallback):  # a checkpoint every 64 strides; "killed" after one
        def __init__(self, save_freq, *args, **kwargs):
            super().__init__(32, *args, **kwargs)

        def _on_step(self):
            ok = super()._on_step()
            if self.n_calls % self.save_freq == 0 and not killed:
                killed.append(self.num_timesteps)
                raise KeyboardInterrupt
            return ok

    monkeypatch.setattr(cbs, "CheckpointCallback", Small)
    out = tmp_path / "ft"
    with pytest.raises(KeyboardInterrupt):
        ft.finetune(student_dir, out, cfg, progress=False)
    assert killed == [128] and (out / "ckpt_128_steps.zip").is_file()
    assert not (out / "policy").exists()

    def no_warm_start(*a, **k):
        raise AssertionError("the rerun started from the student again")

    monkeypatch.setattr(ft, "_copy_actor", no_warm_start)
    summary = ft.finetune(student_dir, out, cfg, progress=True)
    assert "resuming from ckpt_128_steps.zip" in capsys.readouterr().err
    assert summary["timesteps"] == 192
    pol = load_choice_policy(out / "policy")
    assert np.array_equal(pol.rows, student.rows)
    assert np.array_equal(pol.lqr.gain, student.lqr.gain) and pol.safe == student.safe
    assert pol.fingerprint() != student.fingerprint()  # PPO moved the weights
    cfg_json = json.loads((out / "policy" / "config.json").read_text())
    assert cfg_json["finetune"]["timesteps"] == 192
    from agents.experts.distill import export_folder  # what `bound-env finetune --export` does

    exported = load_choice_policy(export_folder(out / "policy", tmp_path / "exported"))
    assert exported.fingerprint() == pol.fingerprint()
    with np.load(out / "policy" / "choice.npz") as f:
        arrays = dict(f)
    arrays["W0"] = arrays["W0"] * 1.001
    np.savez(out / "policy" / "choice.npz", **arrays)
    with pytest.raises(ValueError, match="choice.npz does not match"):
        load_choice_policy(out / "policy")
