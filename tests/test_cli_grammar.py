"""The CLI grammar: --version, strict JSON, --no-progress/--quiet, --out folders, and no
tracked file changed by commands run inside a checkout (checked with git status)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from bound_env.commands.cli import main
from bound_env.commands.cli_args import strict_json

ROOT = Path(__file__).resolve().parent.parent
_ANYWHERE = shutil.ignore_patterns(".git", "*.egg-info", ".pytest_cache", ".ruff_cache")
_TOP = {".venv", "out", "runs", "build", "dist", "reproduce"}  # outputs at the top level only


def _SKIP(folder, names):
    """copytree's ignore: output folders only at the top of the checkout."""
    top = {n for n in names if n in _TOP} if Path(folder) == ROOT else set()
    return set(_ANYWHERE(folder, names)) | top


def _no_nan(token):
    raise AssertionError(f"non-strict JSON token {token}")


def test_version(capsys):
    assert main(["--version"]) == 0
    assert capsys.readouterr().out.startswith("bound-env ")


def test_strict_json_has_no_nan_tokens():
    text = strict_json({"a": float("nan"), "b": [1.0, float("inf")], "c": {"d": -float("inf")}})
    data = json.loads(text)  # parses as strict JSON
    assert "NaN" not in text and "Infinity" not in text
    assert data["a"] is None and data["b"] == [1.0, None] and data["c"]["d"] is None
    assert data["nonfinite"] == {"a": "nan", "b[1]": "inf", "c.d": "-inf"}


def test_progress_flag_and_alias_on_long_commands():
    from bound_env.commands.cli import build_parser

    parser = build_parser()
    for cmd in ("train", "margins", "compare", "continue", "sweep", "reproduce", "demo", "animate"):
        sub = parser._subparsers._group_actions[0].choices[cmd]
        flags = set(sub._option_string_actions)
        assert {"--no-progress", "--quiet"} <= flags, cmd


def test_out_that_is_a_file_is_a_one_line_error(tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    assert (
        main(["rollout", "--policy", "passive", "--strides", "1", "--out", str(blocker / "sub")])
        == 2
    )
    err = capsys.readouterr().err
    assert "not a folder" in err and len(err.strip().splitlines()) == 1


def test_stride_repeat_times_after_a_warm_up(capsys):
    assert main(["stride", "--gait", "default", "--repeat", "3", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["repeat"] == 3 and out["seconds_first_stride"] > 0
    assert out["seconds_per_stride"] > 0


@pytest.mark.slow
def test_commands_in_a_checkout_change_no_tracked_file(tmp_path):
    repo = tmp_path / "repo"
    shutil.copytree(ROOT, repo, ignore=_SKIP)
    git = ["git", "-c", "user.name=t", "-c", "user.email=t@t", "-c", "commit.gpgsign=false"]
    subprocess.run(["git", "init", "-q"], cwd=repo, check=True)
    subprocess.run(git + ["add", "-A"], cwd=repo, check=True)
    subprocess.run(git + ["commit", "-q", "-m", "snapshot"], cwd=repo, check=True)
    env = {**os.environ, "PYTHONPATH": str(repo)}
    commands = [
        ["stride", "--gait", "default", "--json"],
        ["fixed-point", "--json"],
        ["demo", "--gif-strides", "1", "--json"],
        [
            "sweep",
            "--param",
            "kc",
            "--from",
            "295",
            "--to",
            "296",
            "--step",
            "1",
            "--refine",
            "0",
            "--out",
            "out/sweep",
            "--json",
        ],
        ["continue", "--param", "kc", "--to", "296", "--step", "0.5", "--out", "out/kc", "--json"],
        ["animate", "--strides", "1", "--out", "out/a.gif", "--json"],
        ["animate", "--strides", "1", "--json"],  # the default --out: out/animate/
        ["margins", "--policy", "passive", "--budget", "test", "--workers", "1", "--json"],
        ["rollout", "--policy", "default", "--strides", "2", "--json"],
        # passive, lqr and a shipped policy with a training curve (copied beside the page);
        # the curated columns at the test budget are test_install's
        [
            "compare",
            "--budget",
            "test",
            "--workers",
            "1",
            "--no-progress",
            "--entry",
            "lqr",
            "--entry",
            "step-ppo=agents/policies/step-ppo/s0",
            "--json",
        ],
        [
            "train",
            "--name",
            "t",
            "--n-timesteps",
            "256",
            "--eval-freq",
            "128",
            "--save-freq",
            "128",
            "--n-eval-episodes",
            "1",
            "--vec-env",
            "dummy",
            "--no-progress",
            "--set",
            "n_envs=1",
            "--set",
            "n_steps=128",
            "--set",
            "batch_size=64",
            "--set",
            "n_epochs=1",
            "--set",
            "callback=[]",
            "--json",
        ],
    ]
    for cmd in commands:
        res = subprocess.run(
            [sys.executable, "-m", "bound_env.commands.cli", *cmd],
            cwd=repo,
            env=env,
            capture_output=True,
            text=True,
            timeout=1200,
        )
        assert res.returncode == 0, (cmd, res.stderr[-2000:])
        json.loads(res.stdout, parse_constant=_no_nan)  # --json everywhere, strict JSON
        status = subprocess.run(
            ["git", "status", "--porcelain"], cwd=repo, check=True, capture_output=True, text=True
        ).stdout
        assert status == "", (cmd, status)
    assert (repo / "out" / "margins" / "MARGINS.md").is_file()  # compare wrote into --out
    assert (repo / "out" / "margins" / "training_step-ppo.png").is_file()


def test_animate_out_is_a_folder_and_a_gif_path_still_works(tmp_path, monkeypatch, cli):
    from PIL import Image

    monkeypatch.chdir(tmp_path)
    small = ["animate", "--strides", "0.3", "--width", "80", "--height", "45"]
    assert cli(*small)[0] == 0  # default: out/animate/bound.gif, never at the top
    assert (tmp_path / "out" / "animate" / "bound.gif").is_file()
    assert not (tmp_path / "bound.gif").exists()
    assert cli(*small, "--out", "figs")[0] == 0
    with Image.open(tmp_path / "figs" / "bound.gif") as im:
        assert im.size == (80, 45)
    code, out, _ = cli(*small, "--out", "old/a.gif", "--json")  # the old spelling
    assert code == 0 and json.loads(out)["gif"] == "old/a.gif"
    assert (tmp_path / "old" / "a.gif").is_file() and not list(tmp_path.rglob("*.tmp.gif"))


def test_train_grammar_hp_set_gait_out_and_old_spellings(capsys):
    from agents.cli import train_sets
    from agents.common.config import DEFAULT_CONFIG
    from agents.training.train import resolve_section
    from bound_env.commands.cli import build_parser

    parser = build_parser()
    new = ["--hp", "n_steps=128", "--set", "kc=300", "--gait", "literal-cycle"]
    args = parser.parse_args(["train", *new, "--out", "R", "--export-out", "E"])
    assert (args.runs_dir, args.export) == ("R", "E")
    old = parser.parse_args(["train", "--runs-dir", "R", "--export", "E", "--set", "n_epochs=3"])
    assert (old.runs_dir, old.export) == ("R", "E")
    hp = resolve_section(DEFAULT_CONFIG, "PassiveBound-v0", train_sets(args), None)
    assert hp["n_steps"] == 128
    assert hp["env_kwargs"]["gait_overrides"] == {"kc": 300.0}
    assert hp["env_kwargs"]["gait"] == "literal-cycle"
    assert "deprecated" not in capsys.readouterr().err
    # the old use of --set (a hyperparameter key) still works, with a one-line notice
    hp = resolve_section(DEFAULT_CONFIG, "PassiveBound-v0", train_sets(old), None)
    assert hp["n_epochs"] == 3 and "gait_overrides" not in hp["env_kwargs"]
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "deprecated" in err[0] and "--hp n_epochs=3" in err[0]


def test_train_export_into_a_folder_with_files_is_refused_before_training(tmp_path, cli):
    shipped = tmp_path / "policy"
    shipped.mkdir()
    (shipped / "model.zip").write_bytes(b"tracked")
    runs = tmp_path / "runs"
    for flag in ("--export", "--export-out"):
        code, _, err = cli(
            "train", "--name", "x", "--out", runs, "--n-timesteps", "64", flag, shipped
        )
        assert code == 2 and "--force" in err and len(err.strip().splitlines()) == 1
    assert not runs.exists() and (shipped / "model.zip").read_bytes() == b"tracked"
    from agents.cli import export_policy

    with pytest.raises(ValueError, match="already holds files"):
        export_policy(tmp_path, shipped)


def test_fixed_point_out_folder_and_the_old_save(tmp_path, cli):
    from bound_env.model.params import load_gait

    code, out, _ = cli("fixed-point", "--out", tmp_path / "fp", "--json")
    assert code == 0 and json.loads(out)["saved"] == str(tmp_path / "fp" / "gait.yaml")
    new = load_gait(tmp_path / "fp" / "gait.yaml")
    assert cli("fixed-point", "--save", tmp_path / "old.yaml")[0] == 0  # the old spelling
    assert (load_gait(tmp_path / "old.yaml").z_star == new.z_star).all()
    code, _, err = cli("fixed-point", "--save", tmp_path / "fp")
    assert code == 2 and "--out" in err


def test_unknown_argument_names_the_sub_command_and_help_gives_defaults(cli, capsys):
    code, _, err = cli("margins", "--set", "kc=1")
    assert code == 2 and "bound-env margins: error: unrecognized arguments: --set kc=1" in err
    for cmd, default in (("margins", "quick"), ("compare", "quick")):  # issue 26: quick
        assert main([cmd, "--help"]) == 0
        text = " ".join(capsys.readouterr().out.split())
        assert f"(default: {default})" in text.split("--budget {test,quick,standard,full}")[-1]
    assert main(["basin-map", "--help"]) == 0
    text = " ".join(capsys.readouterr().out.split()).replace("- ", "-")  # argparse's wrapping
    assert all(name in text for name in ("lqr", "deadbeat", "damping", "step-ppo/s0"))
    assert main(["sweep", "--help"]) == 0
    text = " ".join(capsys.readouterr().out.split())
    assert "gait's own value" in text and "spacing of the values" in text
