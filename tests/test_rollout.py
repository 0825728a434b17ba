"""Running a trained policy: `bound-env rollout`, `load_policy`, and the refusals that keep
evaluation from being silently wrong (missing or foreign statistics, another gait)."""

from __future__ import annotations

import json
import re
import shutil
from collections import OrderedDict
from pathlib import Path

import numpy as np
import pytest
import yaml

from agents.runtime.policy import find_policy_files, load_controller, shipped_policies
from agents.runtime.policy_table import ARCHIVE_DIR
from agents.runtime.rollout import load_policy, rollout
from bound_env.commands.cli import main

ROOT = Path(__file__).resolve().parent.parent

PPO_V1 = ARCHIVE_DIR / "ppo-v1"  # the archived PPO policy, loaded by its path


@pytest.fixture
def policy_copy(tmp_path):
    """A writable copy of the shipped PPO policy (ppo-v1; `default` is a choice policy)."""
    dest = tmp_path / "pol"
    shutil.copytree(PPO_V1, dest)
    return dest


def test_shipped_policies_by_name_and_fingerprinted():
    shipped = shipped_policies()
    assert set(shipped) >= {"default", "literal-cycle", "ppo-v1-final/s0"}
    for folder in shipped.values():
        assert (folder / "fingerprint.json").is_file()
        load_controller(folder)  # passes every check (fingerprint, normalization, config)


@pytest.mark.parametrize("policy", [str(PPO_V1), "default"])
def test_rollout_reports_strides_torque_and_apex_error(tmp_path, capsys, policy):
    """The PPO policy and the shipped default (a distilled stride controller)."""
    out = tmp_path / "r"
    argv = ["rollout", "--policy", policy, "--strides", "3", "--noise", "0.3"]
    assert main([*argv, "--json", "--out", str(out)]) == 0
    r = json.loads(capsys.readouterr().out)
    assert r["strides"] == 3 and r["fell"] is False and r["failure"] is None
    assert len(r["apex_error"]) == 3
    # the policy uses its own max_torque (80 N m, from its config), not the env default (40)
    assert r["max_torque"] == 80.0 and 0 < r["mean_abs_tau"] < 80.0
    assert json.loads((out / "summary.json").read_text()) == r


def test_passive_rollout_applies_no_torque():
    r = rollout("passive", strides=2)
    assert r["strides"] == 2 and r["mean_abs_tau"] == 0.0
    assert max(r["apex_error"]) < 1e-6  # it starts on the passive cycle


def test_rollout_records_a_gif(tmp_path):
    r = rollout("passive", strides=1, video=tmp_path / "v" / "run.gif")
    assert Path(r["video"]).stat().st_size > 1000


def test_load_policy_matches_plain_sb3_and_docs_example_runs():
    from stable_baselines3 import PPO

    text = (ROOT / "docs" / "learned.md").read_text()  # the docs page "Running a trained policy"
    blocks = re.findall(r"```python\n(.*?)```", text, re.S)
    example = next(b for b in blocks if "VecNormalize.load" in b)
    scope: dict = {}
    exec(example.replace("range(400)", "range(60)"), scope)  # noqa: S102 - the docs' code
    assert scope["done"].shape == (1,)
    # the docs' SB3 route and load_policy's act give the same actions
    make_env, act = load_policy(scope["folder"])
    venv = scope["venv"]
    model = PPO.load(scope["folder"] / "model.zip", device="cpu")
    env = make_env()
    obs, _ = env.reset(seed=1)
    for _ in range(30):
        sb3, _ = model.predict(venv.normalize_obs(obs[None]), deterministic=True)
        ours = act(obs)
        assert ours.shape == (1,) and ours.dtype == np.float32
        assert np.allclose(sb3[0], ours, atol=1e-5)
        obs, *_ = env.step(ours)


def test_refuses_missing_statistics(policy_copy, capsys):
    (policy_copy / "vecnormalize.pkl").unlink()
    with pytest.raises(ValueError, match="no vecnormalize.pkl"):
        load_controller(policy_copy)
    assert main(["margins", "--policy", str(policy_copy), "--budget", "test"]) == 2
    assert "vecnormalize.pkl" in capsys.readouterr().err


def test_refuses_statistics_of_another_policy(policy_copy, capsys):
    other = shipped_policies()["literal-cycle"] / "vecnormalize.pkl"
    shutil.copyfile(other, policy_copy / "vecnormalize.pkl")
    with pytest.raises(ValueError, match="different policies"):
        load_controller(policy_copy)
    assert main(["rollout", "--policy", str(policy_copy), "--strides", "1"]) == 2
    err = capsys.readouterr().err
    assert "different policies" in err and "Traceback" not in err


def test_refuses_corrupt_statistics(policy_copy):
    (policy_copy / "fingerprint.json").unlink()
    (policy_copy / "vecnormalize.pkl").write_bytes(b"\x80\x04garbage")
    with pytest.raises(ValueError, match="cannot read"):
        load_controller(policy_copy, force=True)  # no fingerprint: --force (issue 40)


def test_refuses_missing_config(policy_copy):
    (policy_copy / "config.yaml").unlink()
    with pytest.raises(ValueError, match="config.yaml"):
        load_controller(policy_copy)
    with pytest.raises(ValueError, match="config.yaml"):  # no config: the env is unknown
        load_controller(policy_copy, force=True)


def test_refuses_another_gait_unless_forced(capsys):
    with pytest.raises(ValueError, match="trained on gait"):
        load_controller("literal-cycle", gait="default")
    assert (
        main(["rollout", "--policy", "literal-cycle", "--gait", "default", "--strides", "1"]) == 2
    )
    assert "--force" in capsys.readouterr().err
    ctrl = load_controller("literal-cycle", gait="default", force=True)
    assert ctrl.env_kwargs["gait"] == "literal-cycle"
    load_controller(PPO_V1, gait=ROOT / "configs" / "gaits" / "default.yaml")  # same gait


def test_rl_zoo3_run_folder_is_read(tmp_path):
    """rl-zoo3's layout: <run>/<env id>.zip and <run>/<env id>/{config.yml, vecnormalize.pkl},
    the config dumped as an OrderedDict by PyYAML."""
    src = PPO_V1
    run = tmp_path / "PassiveBound-v0_1"
    params = run / "PassiveBound-v0"
    params.mkdir(parents=True)
    shutil.copyfile(src / "model.zip", run / "PassiveBound-v0.zip")
    shutil.copyfile(src / "vecnormalize.pkl", params / "vecnormalize.pkl")
    section = yaml.safe_load((src / "config.yaml").read_text())["PassiveBound-v0"]
    (params / "config.yml").write_text(yaml.dump(OrderedDict(sorted(section.items()))))
    assert "OrderedDict" in (params / "config.yml").read_text()
    files = find_policy_files(run)
    assert files.layout == "rl-zoo3" and files.model.name == "PassiveBound-v0.zip"
    want = load_controller(PPO_V1).fingerprint()
    for given in (run, params, run / "PassiveBound-v0.zip"):
        assert load_controller(given).fingerprint() == want


def test_fingerprint_covers_the_config_and_old_fingerprints_still_load(policy_copy):
    for name, folder in shipped_policies().items():
        fp = json.loads((folder / "fingerprint.json").read_text())
        if (folder / "choice.npz").is_file():  # a distilled choice policy (test_distill)
            assert set(fp) == {"choice.npz", "config.json"}, name
            continue
        if (folder / "adaptive.npz").is_file():  # a learned adaptive policy (test_adaptive)
            assert set(fp) == {"adaptive.npz", "config.json"}, name
            continue
        assert "config.yaml" in fp, name
        assert ("base.json" in fp) == (folder / "base.json").is_file(), name
    # a fingerprint written before it covered the config (model and statistics only) loads
    fp = json.loads((policy_copy / "fingerprint.json").read_text())
    del fp["config.yaml"]
    (policy_copy / "fingerprint.json").write_text(json.dumps(fp))
    assert load_controller(policy_copy).env_kwargs["max_torque"] == 80.0


def test_refuses_a_config_cut_short_unless_forced(policy_copy, capsys):
    """A config.yaml cut at a line boundary before env_kwargs still parses and matches the
    observation shape: without the fingerprint the policy would run at max_torque 40, not 80."""
    cfg = policy_copy / "config.yaml"
    lines = cfg.read_text().splitlines(keepends=True)
    cut = next(i for i, line in enumerate(lines) if line.lstrip().startswith("env_kwargs"))
    cfg.write_text("".join(lines[:cut]))
    with pytest.raises(ValueError, match="config.yaml does not match.*--force"):
        load_controller(policy_copy)
    base = ["--policy", str(policy_copy), "--gait", "default"]
    for argv in (
        ["rollout", *base, "--strides", "1"],
        ["margins", *base, "--budget", "test", "--out", str(policy_copy.parent / "m")],
        ["basin-map", *base, "--grid", "2", "--out", str(policy_copy.parent / "b")],
    ):
        assert main(argv) == 2, argv
        err = capsys.readouterr().err
        assert "config.yaml does not match" in err and "--force" in err, argv
        assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert not (policy_copy.parent / "b").exists()
    ctrl = load_controller(policy_copy, force=True)  # on purpose: as the config now says
    assert "max_torque" not in ctrl.env_kwargs
    assert "does not match" in capsys.readouterr().err  # a warning
