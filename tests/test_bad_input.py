"""Issue 40: every new surface refuses bad input in one line naming the parameter, file or key.

One test per case of the issue (each fails on main c8aee56): the model-error spec
(`bound_env.model.mismatch`, ``--mismatch``), offset-free names and gains, a controller's gain,
the apex state a stride controller plans from, and the scripts' arguments. The classes
behind the cases are property-tested in tests/test_properties.py.
"""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import bound_env
import bound_env.model.mismatch as mm
from bound_env.model.mismatch import (
    NOISE_SCALES,
    MismatchSpec,
    as_spec,
    from_dict,
    sample_plant_params,
    sample_plants,
)

gym.register_envs(bound_env)
ROOT = Path(__file__).resolve().parents[1]


def one_line(e) -> str:
    text = str(e.value if hasattr(e, "value") else e)
    assert "\n" not in text and text, text
    return text


def script(name: str):
    """scripts/<name>.py as a module (its ``main(argv)`` runs in-process)."""
    spec = importlib.util.spec_from_file_location(f"script_{name}", ROOT / "scripts" / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def usage_error(main, argv, capsys) -> str:
    """``main(argv)`` ends in exit 2 with argparse's usage and ONE error line (returned), or
    with one line of its own; never a traceback or exit 0."""
    try:
        code = main([str(a) for a in argv])
    except SystemExit as e:
        code = e.code
    err = capsys.readouterr().err.strip()
    assert code == 2, (code, err)
    assert "Traceback" not in err, err
    lines = err.splitlines()
    if any(": error: " in ln for ln in lines):  # argparse: usage lines, then the error
        lines = lines[next(i for i, ln in enumerate(lines) if ": error: " in ln) :]
    assert len(lines) == 1, err
    return lines[0]


# -- the mismatch spec -------------------------------------------------------------------------


def test_a_folder_is_not_an_unknown_preset(tmp_path):
    with pytest.raises(ValueError) as e:
        as_spec(tmp_path)
    assert "is a folder" in one_line(e) and str(tmp_path) in str(e.value)
    assert "preset" not in str(e.value)


def test_a_file_name_with_a_comma_is_one_spec(tmp_path):
    f = tmp_path / "soft,stiff.yaml"
    f.write_text("name: soft-stiff\nparams: {kb: 0.1}\n")
    specs = mm.parse_specs(f"{f},pm5")
    assert [s.name for s in specs] == ["soft-stiff", "pm5"]
    assert dict(specs[0].ranges) == {"kb": 0.1}
    # without a name: key, its stem is no name (a comma); the error names the file
    f.write_text("params: {kb: 0.1}\n")
    with pytest.raises(ValueError) as e:
        mm.parse_specs(str(f))
    assert str(f) in one_line(e) and "name:" in str(e.value)


def test_two_files_of_one_stem_are_both_named(tmp_path):
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    for d, k in (("a", "m1"), ("b", "m2")):
        (tmp_path / d / "soft.yaml").write_text(f"params: {{{k}: 0.1}}\n")
    a, b = tmp_path / "a" / "soft.yaml", tmp_path / "b" / "soft.yaml"
    with pytest.raises(ValueError) as e:
        mm.parse_specs(f"{a},{b}")
    assert str(a) in one_line(e) and str(b) in str(e.value) and "'soft'" in str(e.value)
    # the margins' own check names them too
    with pytest.raises(ValueError, match="soft.yaml and .*soft.yaml are both named"):
        mm.check_distinct([as_spec(a), as_spec(b)])
    with pytest.raises(ValueError, match="names a spec twice: 'pm5'"):
        mm.parse_specs("pm5,pm5")


@pytest.mark.parametrize(
    "data, words",
    [
        ({"params": 0}, "params must be a mapping"),
        ({"params": [0.1]}, "params must be a mapping"),
        ({"noise": []}, "noise must be a mapping"),
        ({"noise": "lots"}, "noise must be a mapping"),
        ({"name": None}, "name must be a string"),
        ({"name": 5}, "name must be a string"),
        ({"name": "a\nb"}, "mismatch name 'a\\nb'"),
        ({"name": "a|b"}, "mismatch name 'a|b'"),
        ({"name": ""}, "mismatch name ''"),
        ({"noise": 1e6}, "noise.y_g: sigma 1e+06 is beyond 1"),
        ({"noise": {"theta1": 1.01}}, "noise.theta1: sigma 1.01 is beyond 1"),
        ({"params": {"m1": 10**400}}, "params.m1 must be finite"),
    ],
)
def test_bad_spec_values_are_one_line_naming_the_key(data, words):
    with pytest.raises(ValueError) as e:
        from_dict(data)
    assert words in one_line(e)


def test_a_yaml_key_twice_is_refused_naming_it_and_its_line(tmp_path):
    f = tmp_path / "dup.yaml"
    f.write_text("params: {m1: 0.1}\nparams: {m2: 0.2}\n")
    with pytest.raises(ValueError) as e:
        as_spec(f)
    assert "duplicate key 'params' at line 2" in one_line(e) and str(f) in str(e.value)
    f.write_text("params: {m1: 0.1, m1: 0.2}\n")
    with pytest.raises(ValueError, match="duplicate key 'm1'"):
        as_spec(f)
    # the same reader for gait files and controller specs
    from bound_env.control import load_controller
    from bound_env.model.params import load_gait

    g = tmp_path / "gait.yaml"
    g.write_text("kc: 300\nkc: 200\n")
    with pytest.raises(ValueError, match=r"gait file .*gait.yaml: .*duplicate key 'kc'"):
        load_gait(g)
    c = tmp_path / "ctrl.yaml"
    c.write_text("controller: lqr\nR: 1.0\nR: 0.1\n")
    with pytest.raises(ValueError, match=r"ctrl.yaml: .*duplicate key 'R'"):
        load_controller(c)


def test_noise_at_the_limit_is_accepted():
    s = from_dict({"noise": mm.MAX_NOISE})
    assert dict(s.noise) == {k: mm.MAX_NOISE for k in NOISE_SCALES}
    assert from_dict({"params": None, "noise": None}).is_nominal  # keys with nothing after


@pytest.mark.parametrize("n, word", [(-3, "n must be"), (2.5, "n must be"), (True, "n must be")])
def test_a_bad_plant_count_is_refused(n, word):
    nominal = bound_env.model.params.load_gait("default").params
    for f in (
        lambda: sample_plants("pm5", n, 0),
        lambda: sample_plant_params("pm5", n, 0, nominal),
    ):
        with pytest.raises(ValueError) as e:
            f()
        assert word in one_line(e)
    with pytest.raises(ValueError, match="seed must be"):
        sample_plants("pm5", 2, -1)
    assert sample_plants("pm5", 0, 0) == []  # no plant asked, none drawn


@pytest.mark.parametrize("ranges", [5, "abc", [("m1",)], [(1, 0.1)], {"m1": 0.1, 3: 0.2}])
def test_mismatch_spec_ranges_errors_name_ranges(ranges):
    with pytest.raises(ValueError) as e:
        MismatchSpec(ranges=ranges)
    assert "ranges" in one_line(e)


def test_a_name_given_twice_in_pairs_is_refused():
    with pytest.raises(ValueError, match="'m1' is given twice"):
        MismatchSpec(ranges=(("m1", 0.1), ("m1", 0.2)))
    with pytest.raises(ValueError, match="noise: 'y_g' is given twice"):
        MismatchSpec(noise=[("y_g", 0.1), ("y_g", 0.2)])
    assert MismatchSpec(ranges={"m1": 0.1}) == MismatchSpec(ranges=(("m1", 0.1),))


def test_spaces_around_plus_name_the_preset_join():
    assert as_spec("pm5 + noise").name == "pm5+noise" == as_spec("pm5+noise").name


# -- offset-free names and gains ----------------------------------------------------------------


@pytest.mark.parametrize("name", ["lqr-of+of", "lqr+of+of"])
def test_offset_free_twice_is_refused_saying_why(name):
    from bound_env.control import load_controller

    with pytest.raises(ValueError) as e:
        load_controller(name)
    assert "held offset-free already" in one_line(e) and "not a stride controller" not in str(e)


def test_offset_free_twice_over_a_learned_policy_too():
    from agents.runtime.policy import load_controller

    with pytest.raises(ValueError) as e:
        load_controller("default+of+of")
    assert "'default+of' is held offset-free already" in one_line(e)


def test_an_np_float32_gain_is_a_number():
    from bound_env.control import load_controller
    from bound_env.control.offset_free import OffsetFree

    lqr = load_controller("lqr")
    a = OffsetFree(lqr, gain=np.float32(0.25), deadband=np.float64(1e-7), max_shift=np.int64(1))
    assert type(a.gain) is float and a.gain == 0.25 and a.max_shift == 1.0
    for bad in (True, "0.1", np.float32(np.nan), 1e308):
        with pytest.raises(ValueError, match="offset_free: gain must be a number") as e:
            OffsetFree(lqr, gain=bad)
        one_line(e)


# -- a controller's gain, the apex state of a plan ----------------------------------------------


@pytest.mark.parametrize("env_id", ["PassiveBoundRescue-v0", "PassiveBoundRescue-v1"])
def test_a_huge_gain_is_refused_naming_gain(env_id):
    with pytest.raises(ValueError) as e:
        gym.make(env_id, gain=[[1e308] * 6] * 8)
    assert one_line(e).startswith("gain has entries up to 1e+308")


def test_a_huge_gain_in_a_spec_is_refused_naming_the_field():
    from bound_env.control import ControllerSpec, load_controller

    with pytest.raises(ValueError) as e:
        load_controller(ControllerSpec("lqr", gain=[[1e7] * 6] * 4))
    assert one_line(e).startswith("gain has entries up to")
    fb = load_controller(ControllerSpec("lqr", gain=[[10.0] * 6] * 4))  # large, but a gain
    assert np.all(np.isfinite(fb.design["rho_closed"]))


@pytest.mark.parametrize("key, value", [("start_z", np.nan), ("start_z", np.inf)])
def test_act_refuses_a_non_finite_start_state(key, value):
    from agents.runtime.rollout import load_policy

    make_env, act = load_policy("lqr")
    obs, info = make_env().reset(seed=0)
    info = {**info, key: np.where(np.arange(6) == 2, value, info[key])}
    with pytest.raises(ValueError) as e:
        act(obs, info)
    assert "info['start_z'] must be the apex state" in one_line(e)


def test_notify_apex_refuses_a_mis_shaped_apex_state():
    from bound_env.control import load_controller
    from bound_env.sim.stride_protocol import notify_apex

    obs = np.zeros(16, dtype=np.float32)
    for z in ([0.25] * 5, "zzz", None):
        with pytest.raises(ValueError, match=r"info\['apex_z'\] must be the apex state") as e:
            notify_apex(load_controller("lqr"), obs, {"apex_z": z})
        one_line(e)


# -- scripts/rescue_eval.py --------------------------------------------------------------------


@pytest.fixture(scope="module")
def rescue_eval():
    return script("rescue_eval")


@pytest.mark.parametrize(
    "argv, words",
    [
        (["lqr", "--dirs", "0"], "--dirs: must be >= 1"),
        (["lqr", "--dirs", "-1"], "--dirs: must be >= 1"),
        (["lqr", "--dirs", "x"], "--dirs: not an integer"),
        (["lqr", "--sizes", "nan"], "--sizes: must be finite"),
        (["lqr", "--sizes", "0"], "--sizes: must be > 0"),
        (["lqr", "--sizes", "2"], "--sizes: must be <= 1"),
        (["lqr", "--seed", "-1"], "--seed: must be >= 0"),
        (["lqr", "--seed", "12345"], "test set"),
        (["lqr", "--env-id", "PassiveBound-v1"], "--env-id: invalid choice"),
        ([""], "a policy must be a name or a path"),
        (["nope"], "nope"),
        (["passive"], "not a stride controller"),
        (["ppo-v1"], "archived"),
    ],
)
def test_rescue_eval_bad_arguments_are_one_line(rescue_eval, capsys, argv, words):
    assert words in usage_error(rescue_eval.main, argv, capsys)


def _run_folder(tmp, env_id):
    d = tmp / env_id
    d.mkdir()
    (d / "model.zip").write_bytes(b"not read: refused before the model is loaded")
    (d / "config.yaml").write_text(f"run: {{env_id: {env_id}}}\n{env_id}:\n  env_kwargs: {{}}\n")
    return d


def test_rescue_eval_refuses_a_model_of_another_env(rescue_eval, tmp_path, capsys):
    v1 = _run_folder(tmp_path, "PassiveBoundRescue-v1")
    err = usage_error(rescue_eval.main, [v1, "--env-id", "PassiveBoundRescue-v0"], capsys)
    assert "--env-id PassiveBoundRescue-v0" in err and "trained on PassiveBoundRescue-v1" in err
    step = _run_folder(tmp_path, "PassiveBound-v1")
    err = usage_error(rescue_eval.main, [step], capsys)
    assert "trained on PassiveBound-v1" in err and "not on the rescue task" in err
    err = usage_error(rescue_eval.main, [v1], capsys)  # the same env: the zip is read, and bad
    assert "not a readable PPO model" in err


def test_rescue_eval_gives_a_result(rescue_eval, capsys):
    assert rescue_eval.main(["lqr", "--dirs", "1", "--sizes", "0.001"]) == 0
    assert "lqr: return rate - (0/0)" in capsys.readouterr().out  # no start past safe
    assert rescue_eval.main(["lqr", "--dirs", "2", "--sizes", "0.3", "0.001", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)["lqr"]
    assert [r["r"] for r in out["sizes"]] == [0.3, 0.001]
    assert out["sizes"][1]["n"] == 0 and out["sizes"][1]["rate"] is None  # none past safe
    assert out["sizes"][0]["n"] == 2 and out["seed"] == 777


# -- scripts/control_effort.py, scripts/control_table.py ----------------------------------------


@pytest.mark.parametrize(
    "name, argv, words",
    [
        ("control_effort", ["--policy", ""], "a policy must be a name"),
        ("control_effort", ["--policy", "nope"], "'nope' does not exist"),
        ("control_effort", ["--policy", "ppo-v1"], "archived"),
        ("control_effort", ["--out", "{file}/x"], "exists and is not a folder"),
        ("control_table", ["--workers", "0"], "--workers: must be >= 1"),
        ("control_table", ["--seed", "-1"], "--seed: must be >= 0"),
        ("control_table", ["--seed", "1e3"], "--seed: not an integer"),
        ("control_table", ["--out", "{file}/x"], "exists and is not a folder"),
    ],
)
def test_scripts_bad_arguments_are_one_line(name, argv, words, tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    argv = [a.replace("{file}", str(blocker)) for a in argv]
    assert words in usage_error(script(name).main, argv, capsys)
    assert not (blocker.parent / "x").exists()


# -- the command line: --mismatch, compare --render-only ----------------------------------------


def cli_error(argv, capsys) -> str:
    """``bound-env argv`` in-process: exit 2 and one error line (warnings aside), returned."""
    from bound_env.commands.cli import main

    code = main([str(a) for a in argv])
    err = capsys.readouterr().err.strip()
    assert code == 2, err
    lines = [ln for ln in err.splitlines() if not ln.startswith("warning:")]
    lines = lines[next((i for i, ln in enumerate(lines) if ": error: " in ln), 0) :]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def test_margins_mismatch_names_both_files_of_one_stem(tmp_path, capsys):
    for d in ("a", "b"):
        (tmp_path / d).mkdir()
        (tmp_path / d / "soft.yaml").write_text("params: {kb: 0.1}\n")
    spec = f"{tmp_path / 'a' / 'soft.yaml'},{tmp_path / 'b' / 'soft.yaml'}"
    for cmd in (["margins", "--policy", "lqr"], ["compare", "--entry", "lqr"]):
        err = cli_error([*cmd, "--mismatch", spec, "--out", tmp_path / "o"], capsys)
        assert "a/soft.yaml and " in err and "b/soft.yaml are both named 'soft'" in err
    err = cli_error(
        ["margins", "--policy", "lqr", "--mismatch", tmp_path, "--out", tmp_path], capsys
    )
    assert "is a folder" in err and "preset" not in err
    assert not (tmp_path / "o").exists()


RENDER_DATA = ROOT / "tests" / "data" / "render_only"


def _render_fixture(tmp_path, blocks: dict | None = None, change=None):
    import shutil

    out, docs = tmp_path / "out", tmp_path / "docs"
    shutil.copytree(RENDER_DATA / "out", out)
    docs.mkdir()
    shutil.copyfile(RENDER_DATA / "paired.input.json", docs / "paired.json")
    for f in out.glob("*/margins.json"):
        data = json.loads(f.read_text())
        if blocks is not None:
            data["mismatch"] = blocks
        if change is not None:
            change(data)
        f.write_text(json.dumps(data))
    return ["compare", "--budget", "test", "--render-only", "--no-progress", "--entry", "lqr",
            "--out", out, "--docs", docs]  # fmt: skip


def _block(name):
    """A model-error block as `mismatch_tasks.assemble_mismatch` writes it (the fields the page
    reads)."""
    hold = [1, 1, 0, 1]
    return {
        "spec": as_spec(name).to_dict(),
        "seeds": {"plants": 1, "noise": 2},
        "budget": {"plants": 4},
        "plants": [{}] * 4,
        "hold": {"strides": 20, "k": 3, "n": 4, "ci": [0.3, 0.95], "outcomes": hold,
                 "effort_strides": 5, "effort_median": 3.0, "effort_median_ci": [1.0, 5.0]},
        "curve": [{"size": 0.01, "outcomes": hold}, {"size": 0.1, "outcomes": [0, 0, 1, 0]}],
        "curve_strides": 20,
        "r50": 0.05,
        "r50_ci": [0.01, 0.1],
        "mfpt": [],
    }  # fmt: skip


def test_render_only_shows_the_model_error_it_was_asked_for(tmp_path, capsys):
    from bound_env.commands.cli import main

    argv = _render_fixture(tmp_path, {"pm5": _block("pm5"), "pm10": _block("pm10")})
    err = cli_error([*argv, "--mismatch", "pm20"], capsys)
    assert "margins.json: no model-error block 'pm20' (it holds: pm10, pm5)" in err
    assert main([str(a) for a in argv] + ["--mismatch", "pm5"]) == 0, capsys.readouterr().err
    page = (tmp_path / "docs" / "MARGINS.md").read_text()
    assert "### pm5" in page and "### pm10" not in page
    # a block of that name measured under another spec (a YAML file named pm5) is refused
    other = tmp_path / "pm5.yaml"
    other.write_text("params: {m1: 0.3}\n")
    err = cli_error([*argv, "--mismatch", other], capsys)
    assert "block 'pm5' was measured under another spec" in err


def test_render_only_refuses_a_nan_r50(tmp_path, capsys):
    argv = _render_fixture(tmp_path, change=lambda d: d["basin_curve"].update(r50=float("nan")))
    err = cli_error(argv, capsys)
    assert "margins.json: basin_curve.r50: must be a finite number, got NaN" in err


# -- policy names ------------------------------------------------------------------------------


def test_an_empty_policy_is_one_line(capsys):
    err = cli_error(["rollout", "--policy", "", "--strides", "1"], capsys)
    assert "policy '' is empty" in err


def test_a_bare_archived_entry_says_where_it_went(tmp_path, capsys):
    err = cli_error(["compare", "--entry", "ppo-v1", "--out", tmp_path], capsys)
    assert "was archived" in err and "archive/ppo-v1" in err


def test_a_policy_folder_named_plus_of_is_itself(tmp_path):
    import shutil

    from agents.runtime.policy import load_controller, shipped_policies
    from bound_env.control.offset_free import OffsetFree

    d = tmp_path / "mine+of"
    shutil.copytree(shipped_policies()["default"], d)
    ctrl = load_controller(d)
    assert not isinstance(ctrl, OffsetFree)
    assert isinstance(load_controller("default+of"), OffsetFree)  # a name: still the wrapper
    with pytest.raises(FileNotFoundError) as e:
        load_controller(tmp_path / "gone+of")
    assert "nor " in one_line(e) and "would hold offset-free" in str(e.value)


# -- train -------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "hp, words",
    [
        ({"n_envs": "abc"}, "hyperparameter n_envs must be a whole number"),
        ({"n_envs": [2]}, "hyperparameter n_envs must be a whole number"),
        ({"n_envs": 0}, "hyperparameter n_envs must be a whole number in [1, 1024]"),
        ({"n_timesteps": float("inf")}, "hyperparameter n_timesteps must be a whole number"),
        ({"n_timesteps": True}, "hyperparameter n_timesteps"),
        ({"n_steps": 1.5}, "hyperparameter n_steps"),
        ({"batch_size": "64"}, "hyperparameter batch_size"),
        ({"learning_rate": [1]}, "hyperparameter learning_rate must be a finite number > 0"),
        ({"learning_rate": float("nan")}, "hyperparameter learning_rate"),
        ({"learning_rate": "lin_x"}, "learning_rate: 'lin_<value>' needs a number"),
    ],
)
def test_bad_hyperparameters_are_named(hp, words):
    from agents.common.config import preprocess

    with pytest.raises(ValueError) as e:
        preprocess({"n_timesteps": 1000, "policy": "MlpPolicy", **hp})
    assert words in one_line(e)
    spec = preprocess({"n_timesteps": 1e5, "n_envs": 2.0, "policy": "MlpPolicy"})  # whole floats
    assert (spec.n_timesteps, spec.n_envs) == (100_000, 2)


def test_train_hp_errors_name_the_key_on_the_command_line(tmp_path, capsys):
    for value in ("abc", "[2]", ".inf"):
        err = cli_error(
            ["train", "--name", "x", "--runs-dir", tmp_path, "--hp", f"n_envs={value}"], capsys
        )
        assert "hyperparameter n_envs must be" in err
    assert not (tmp_path / "x").exists()


@pytest.fixture
def old_run(tmp_path):
    """A run folder as `train` leaves it (config.yaml, run.json), without checkpoints: a
    resume that passes its checks stops at the missing checkpoint."""
    from agents.common.run_files import write_config

    d = tmp_path / "r"
    d.mkdir()
    hp = {"n_timesteps": 1000, "policy": "MlpPolicy", "learning_rate": 3e-4,
          "env_kwargs": {"max_torque": 80.0}}  # fmt: skip
    write_config(d / "config.yaml", "PassiveBound-v0", hp, 7)
    (d / "run.json").write_text("{}")
    return ["train", "--name", "r", "--runs-dir", tmp_path, "--resume"]


@pytest.mark.parametrize(
    "extra, words",
    [
        (["--env-id", "PassiveBound-v1"], "trained on PassiveBound-v0, not --env-id"),
        (["--hp", "learning_rate=0.5"], "--hp learning_rate=0.5 differs from the run's"),
        (["--hp", "env_kwargs.max_torque=20"], "env_kwargs.max_torque = 80.0"),
        (["--seed", "3"], "has seed 7, not --seed 3"),
        (["--init-from", "lqr"], "had no warm start, not --init-from lqr"),
    ],
)
def test_resume_refuses_another_setting(old_run, capsys, extra, words):
    err = cli_error([*old_run, *extra], capsys)
    assert "--resume: " in err and words in err


def test_resume_with_the_runs_own_settings_is_accepted(old_run, capsys):
    same = ["--env-id", "PassiveBound-v0", "--seed", "7", "--hp", "learning_rate=3e-4",
            "--hp", "n_timesteps=5000"]  # fmt: skip
    err = cli_error([*old_run, *same], capsys)
    assert "no complete checkpoint" in err  # past the checks: the run has no checkpoint


# -- a policy without its fingerprint ----------------------------------------------------------


@pytest.mark.parametrize(
    "name, unchecked",
    [
        ("step-ppo/s0", "that base 'default' is the controller it was trained over"),
        ("archive/stride-residual/s0", "that base.json is the one it was saved with"),
    ],
)
def test_a_policy_without_its_fingerprint_needs_force(tmp_path, capsys, name, unchecked):
    import shutil

    from agents.runtime.policy import SHIPPED_DIR, load_controller

    d = tmp_path / "p"
    shutil.copytree(SHIPPED_DIR / name, d)
    (d / "fingerprint.json").unlink()
    with pytest.raises(ValueError) as e:
        load_controller(d)
    assert "no fingerprint.json, so it cannot be checked" in one_line(e)
    assert unchecked in str(e.value) and "--force" in str(e.value)
    capsys.readouterr()
    load_controller(d, force=True)
    warn = capsys.readouterr().err
    assert "warning: " in warn and unchecked in warn


# -- compositions of wrappers ------------------------------------------------------------------


def test_library_actions_twice_is_refused():
    from bound_env.envs.wrappers import LibraryActions

    once = LibraryActions(gym.make("PassiveBoundRescue-v0"))
    with pytest.raises(ValueError) as e:
        LibraryActions(once)
    assert "got Discrete(66): wrap the env once" in one_line(e)


def _obs_filter(env):
    from agents.common.wrappers import ObservationFilter

    return ObservationFilter(env)


def _residual(env):
    from agents.runtime.residual import ResidualOver

    return ResidualOver(env)


@pytest.mark.parametrize(
    "outer, inner, words",
    [
        (_obs_filter, _obs_filter, "ObservationFilter needs the env's full observation (16"),
        (_residual, _residual, "ResidualOver needs the env's full observation (16"),
        (_residual, _obs_filter, "got shape (10,): the wrapper below it (ObservationFilter)"),
        (_obs_filter, _residual, "got shape (18,): the wrapper below it (ResidualOver)"),
    ],
)
def test_observation_wrappers_over_a_changed_observation_are_refused(outer, inner, words):
    env = inner(gym.make("PassiveBound-v1"))
    with pytest.raises(ValueError) as e:
        outer(env)
    assert words in one_line(e)


@pytest.mark.parametrize("wrap", [_obs_filter, _residual])
def test_step_env_wrappers_over_a_stride_env_are_refused(wrap):
    with pytest.raises(ValueError) as e:
        wrap(gym.make("PassiveBoundStride-v1"))
    assert "needs a PassiveBound step env" in one_line(e) and "PassiveBoundStride-v1" in str(e)


def test_the_shipped_order_still_composes():
    from agents.common.wrappers import PerturbedStarts

    env = PerturbedStarts(_obs_filter(gym.make("PassiveBound-v1")))  # configs/ppo.yaml's order
    obs, _ = env.reset(seed=0)
    assert obs.shape == (10,) and np.all(np.isfinite(obs))


# -- scripts/hold_eval.py ----------------------------------------------------------------------


@pytest.mark.parametrize(
    "argv, words",
    [
        (["--strides", "0"], "--strides: must be >= 10"),
        (["--robots", "-1"], "--robots: must be >= 1"),
        (["--delta", "1"], "--delta: must be <= 0.99"),
        (["--delta", "nan"], "--delta: must be finite"),
        (["--seed", "-1"], "--seed: must be >= 0"),
        (["--set", "gain=abc"], "--set: gain: not a number"),
        (["--set", "gain=0"], "--set: gain: must be > 0"),
        (["--set", "foo=1"], "KEY one of estimator, gain"),
        (["--set", "estimator=x"], "estimator must be one of"),
        (["--policy", ""], "a policy must be a name or a path"),
        (["--table", "x"], "--table: not an integer"),
        (["--policy", "nope", "--robots", "2", "--strides", "10"], "'nope' does not exist"),
        (["--gait", "nope", "--robots", "2", "--strides", "10"], "no gait file 'nope'"),
    ],
)
def test_hold_eval_bad_arguments_are_one_line(argv, words, capsys):
    assert words in usage_error(script("hold_eval").run, argv, capsys)
