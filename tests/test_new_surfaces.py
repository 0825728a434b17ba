"""The surfaces of the learned adaptive recipe, ``mpc-adaptive`` and ``mpc-privileged``, the
privileged mark, the scripts and the page's tools, hardened: each unclean input ends in one line
naming the key, file or option (a non-zero exit for a command), never a traceback, lost text or
a silently ignored setting; a privileged controller is marked wherever it appears."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _one_line(capsys) -> str:
    err = capsys.readouterr().err.strip()
    lines = [ln for ln in err.splitlines() if not ln.startswith("warning:")]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


# -- python -m agents.results.prose and agents.results.headline: no text lost -----------------


@pytest.fixture
def prose_on(tmp_path, monkeypatch):
    """``prose.main`` on copies: the page ``name`` of docs/ and the JSON sources, ``change``
    applied to model_error.json."""
    from agents.results import numbers, prose

    sources = numbers.Sources

    def run(name: str, edit=lambda text: text, change=lambda me: None, argv=()):
        docs = tmp_path / "docs"
        shutil.copytree(
            ROOT / "docs", docs, ignore=shutil.ignore_patterns("*.md"), dirs_exist_ok=True
        )
        page = tmp_path / name
        page.write_text(edit((ROOT / "docs" / name).read_text()))
        me = json.loads((docs / "model_error.json").read_text())
        change(me)
        (docs / "model_error.json").write_text(json.dumps(me))
        monkeypatch.setattr(prose, "doc_files", lambda: [page])
        monkeypatch.setattr(numbers, "Sources", lambda: sources(docs))
        before = page.read_text()
        return prose.main(list(argv)), page, before

    return run


def _drop_nth_closing(text: str, n: int = 3) -> str:
    i = -1
    for _ in range(n):
        i = text.index("<!-- /n -->", i + 1)
    return text[:i] + text[i + len("<!-- /n -->") :]


@pytest.mark.parametrize("argv", [(), ("--check",)])
def test_prose_refuses_a_lost_closing_marker_and_writes_nothing(prose_on, capsys, argv):
    code, page, before = prose_on("model-error.md", edit=_drop_nth_closing, argv=argv)
    line = _one_line(capsys)
    assert code == 2 and str(page) in line and "is not closed by <!-- /n -->" in line, line
    assert page.read_text() == before  # the words between two blocks are still there


@pytest.mark.parametrize(
    "edit, words",
    [
        (
            lambda t: t + "\n<!-- n:r50(mpc) -->0.1 <!-- n:r50(lqr) -->0.2<!-- /n -->\n",
            "not closed",
        ),
        (lambda t: t + "\nend <!-- /n -->\n", "without its opening"),
        (lambda t: t + "\n<!-- n:r50(mpc) -->0.1\n", "never closed"),
        (lambda t: t + "\n<!-- table:model-error --> <!-- /table:presets -->\n", "inside"),
    ],
)
def test_prose_refuses_unbalanced_markers(prose_on, capsys, edit, words):
    code, page, before = prose_on("model-error.md", edit=edit)
    line = _one_line(capsys)
    assert code == 2 and words in line and str(page) in line, line
    assert page.read_text() == before


def test_prose_refuses_a_nan_hold_before_writing_anything(prose_on, capsys):
    def nan_hold(me):
        me["specs"][0]["rows"][1]["hold"]["k"] = float("nan")

    def stale(text):  # a block the run would rewrite: nothing may be written all the same
        return text.replace("<!-- /n -->", " stale<!-- /n -->", 1)

    code, page, before = prose_on("model-error.md", edit=stale, change=nan_hold)
    err = capsys.readouterr().err
    assert code == 2 and "not a finite number" in err, err
    assert page.read_text() == before and "nan/32" not in page.read_text()


def test_prose_check_sees_a_stale_block_and_writes_nothing(prose_on, capsys):
    def stale(text):
        return text.replace("<!-- /n -->", " stale<!-- /n -->", 1)

    code, page, before = prose_on("model-error.md", edit=stale, argv=["--check"])
    assert code == 1 and "stale" in capsys.readouterr().out
    assert page.read_text() == before
    code, page, _ = prose_on("model-error.md", edit=stale)
    assert code == 0 and page.read_text() == (ROOT / "docs" / "model-error.md").read_text()


def _readme_case(tmp_path, text):
    readme = tmp_path / "README.md"
    readme.write_text(text)
    return readme


@pytest.mark.parametrize(
    "text",
    [
        # the end marker lost, a second block further down: the rewrite cut the words between
        "a\n<!-- headline:start -->\nold\nwords\n<!-- headline:start -->\nold\n"
        "<!-- headline:end -->\nmore\n",
        # a stale second block: --check said "up to date" while it stayed
        "a\n<!-- headline:start -->\nold\n<!-- headline:end -->\nb\n"
        "<!-- headline:start -->\nold\n<!-- headline:end -->\n",
        "a\n<!-- headline:end -->\nold\n<!-- headline:start -->\n",
    ],
)
@pytest.mark.parametrize("argv", [(), ("--check",)])
def test_headline_refuses_lost_or_doubled_markers(tmp_path, capsys, text, argv):
    from agents.results.headline import main as headline_main

    readme = _readme_case(tmp_path, text)
    code = headline_main(["--readme", str(readme), *argv])
    line = _one_line(capsys)
    assert code == 2 and str(readme) in line and "headline:" in line, line
    assert readme.read_text() == text


# -- a privileged controller is marked wherever it appears -----------------------------------

MARGINS_JSON = ROOT / "tests" / "data" / "render_only" / "out" / "lqr" / "margins.json"


def _privileged_run(label="mpc-privileged") -> dict:
    r = json.loads(MARGINS_JSON.read_text())
    return {**r, "policy": label, "label": label, "privileged": True}


@pytest.mark.parametrize("name", ["mpc-privileged+of"])
def test_offset_free_over_a_privileged_controller_is_refused(name, capsys):
    from agents.runtime.policy import load_controller
    from bound_env.commands.cli import main

    with pytest.raises(ValueError, match="'mpc-privileged' is privileged.*no offset"):
        load_controller(name)
    assert main(["rollout", "--policy", name, "--strides", "1"]) != 0
    assert "is privileged" in _one_line(capsys)


def test_rollout_marks_a_privileged_controller():
    from agents.runtime.rollout import rollout, summary_text

    r = rollout("mpc-privileged", strides=1)
    assert r["privileged"] is True and "(privileged" in summary_text(r)
    r = rollout("lqr", strides=1)
    assert r["privileged"] is False and "privileged" not in summary_text(r)


def test_margins_console_marks_a_privileged_controller():
    from bound_env.analysis.margins import summary_text

    assert "PRIVILEGED" in summary_text(_privileged_run())
    assert "PRIVILEGED" not in summary_text({**_privileged_run(), "privileged": False})


def test_margins_figures_label_a_privileged_column(tmp_path, monkeypatch):
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    from bound_env.analysis.margins.report import plot_margins

    legends = []
    save = Figure.savefig

    def record(fig, *a, **kw):
        for ax in fig.axes:
            if ax.get_legend() is not None:
                legends.append([t.get_text() for t in ax.get_legend().get_texts()])
        return save(fig, *a, **kw)

    monkeypatch.setattr(Figure, "savefig", record)
    lqr = json.loads(MARGINS_JSON.read_text())
    paths = plot_margins([_privileged_run(), {**lqr, "label": "lqr"}], tmp_path)
    assert len(legends) == len(paths) >= 3
    for texts in legends:
        assert "mpc-privileged (privileged)" in texts and "lqr" in texts, texts


def test_headline_row_and_json_mark_a_privileged_column(tmp_path):
    from agents.results.headline import headline_numbers, headline_table, load_headline

    groups = [
        {"label": "mpc", "gait": "default", "policies": ["mpc"], "runs": [_privileged_run("mpc")]}
    ]
    head = headline_numbers(groups, "quick", 12345)
    assert head["rows"][0]["privileged"] is True
    assert "**mpc (privileged: reads the true plant)**" in headline_table(head)
    p = tmp_path / "headline.json"
    m = {"value": 1.0, "low": 0.5, "high": 2.0, "interval": "Poisson-based"}
    head["rows"][0]["mfpt_sigma_100_deg"] = m  # the fixture's run has no MFPT curve
    p.write_text(json.dumps(head))
    assert load_headline(p)["rows"][0]["privileged"] is True
    head["rows"][0]["privileged"] = "yes"
    p.write_text(json.dumps(head))
    with pytest.raises(ValueError, match=r"rows\[0\].privileged must be true or false"):
        load_headline(p)
    groups[0]["runs"][0]["privileged"] = False
    head = headline_numbers(groups, "quick", 12345)
    assert head["rows"][0]["privileged"] is False and "privileged" not in headline_table(head)


# -- a stateful base is reset at each episode ---------------------------------------------------


def _episode_actions(act, env, seed: int, steps: int = 120) -> list:
    obs, info = env.reset(seed=seed)
    out = []
    for _ in range(steps):
        a = act(obs, info)
        out.append(float(a[0]))
        obs, _, terminated, truncated, info = env.step(a)
        if terminated or truncated:
            break
    return out


def _second_equals_fresh(make_controller):
    """The actions of a second episode (after a first one from another start) and those of
    the same episode played by a freshly loaded controller."""
    import gymnasium as gym
    import numpy as np

    import bound_env
    from bound_env.control.plain import PlainPolicy

    gym.register_envs(bound_env)
    used, fresh = make_controller(), make_controller()
    env = gym.make("PassiveBound-v0", reset_noise_scale=2.0, **used.env_kwargs)
    act = PlainPolicy(used)
    _episode_actions(act, env, seed=3)
    second = _episode_actions(act, env, seed=5)
    again = _episode_actions(PlainPolicy(fresh), env, seed=5)
    assert len(second) == len(again) and len(second) > 50
    np.testing.assert_array_equal(second, again)


def test_a_residual_policy_over_an_adaptive_base_resets_it():
    import dataclasses

    from agents.runtime.policy import load_controller
    from agents.runtime.residual import load_base

    def make():  # step-ppo's network over the learned adaptive controller
        return dataclasses.replace(load_controller("step-ppo/s0"), base=load_base("adaptive/s0"))

    assert make().stateful is True and load_controller("step-ppo/s0").stateful is False
    _second_equals_fresh(make)


def test_residual_over_resets_an_adaptive_base():
    import gymnasium as gym
    import numpy as np

    import bound_env
    from agents.runtime.residual import ResidualOver

    gym.register_envs(bound_env)

    def episode(w, seed):
        obs, _ = w.reset(seed=seed)
        out = [obs]
        for _ in range(120):
            obs, _, terminated, truncated, _ = w.step(np.array([0.0], np.float32))
            out.append(obs)
            if terminated or truncated:
                break
        return np.array(out)

    def make():
        env = gym.make("PassiveBound-v0", max_torque=80.0, reset_noise_scale=2.0)
        return ResidualOver(env, base="adaptive/s0", r_max=None, end_on_return=False)

    used = make()
    episode(used, 3)
    second, again = episode(used, 5), episode(make(), 5)
    assert second.shape == again.shape and len(second) > 50
    np.testing.assert_array_equal(second, again)


# -- the learned adaptive recipe: one validator -------------------------------------------------


@pytest.fixture
def train_cli(tmp_path, monkeypatch, capsys):
    """``bound-env train --config adaptive ARGS`` in-process: the one-line error (training
    itself, should the arguments pass, fails the test)."""
    from agents.experts import adaptive_recipe

    def never(*a, **k):
        raise AssertionError("training started: the arguments were accepted")

    monkeypatch.setattr(adaptive_recipe, "train_adaptive", never)

    def run(*args):
        argv = ["train", "--config", "adaptive", "--out", tmp_path / "runs", *args]
        return _cli_line(argv, capsys)

    return run


@pytest.mark.parametrize(
    "setting, key",
    [
        ("k=1e9", "adaptive.k"),
        ("k=1.5", "adaptive.k"),
        ("k=-1", "adaptive.k"),
        ("hidden=[-3]", "adaptive.hidden[0]"),
        ("hidden=[0]", "adaptive.hidden[0]"),
        ("hidden=64", "adaptive.hidden"),
        ("hidden=[]", "adaptive.hidden"),
        ("beta=5", "adaptive.beta"),
        ("nominal_start_prob=2", "adaptive.nominal_start_prob"),
        ("gate_surprise=-1", "adaptive.gate_surprise"),
        ("val_plants=0", "adaptive.val_plants"),
        ("summary=maybe", "adaptive.summary"),
        ("summary=1", "adaptive.summary"),
        ("lr=0", "adaptive.lr"),
        ("lr=.nan", "adaptive.lr"),
        ("aux_weight=-1", "adaptive.aux_weight"),
        ("rounds=0", "adaptive.rounds"),
        ("epochs=2.5", "adaptive.epochs"),
        ("r_max=-0.1", "adaptive.r_max"),
        ("teacher=oracle", "adaptive.teacher"),
        ("val_mismatch=pm10+noise", "adaptive.val_mismatch"),
        ("val_mismatch=pm10+delay1", "adaptive.val_mismatch"),
        ("kk=3", "adaptive.kk: unknown"),
    ],
)
def test_adaptive_recipe_keys_are_typed_and_range_checked(train_cli, setting, key):
    line = train_cli("--hp", f"adaptive.{setting}")
    assert key in line and "configs/adaptive.yaml" in line, line


@pytest.mark.parametrize(
    "args, option",
    [
        (("--n-timesteps", "1000"), "--n-timesteps"),
        (("--eval-freq", "5"), "--eval-freq"),
        (("--n-eval-episodes", "3"), "--n-eval-episodes"),
        (("--save-freq", "10"), "--save-freq"),
        (("--export-from", "best"), "--export-from"),
        (("--vec-env", "dummy"), "--vec-env"),
        (("--set", "kc=300"), "--set kc=300"),
        (("--seeds", "1,2"), "--seeds"),
        (("--init-from", "default"), "--init-from"),
    ],
)
def test_adaptive_recipe_refuses_ppo_options(train_cli, args, option):
    line = train_cli(*args)
    assert option in line and "adaptive-dagger" in line, line


@pytest.mark.parametrize(
    "hp, words",
    [
        (
            "env_wrapper=[{bound_env.envs.wrappers.RandomizedPlant: {mismatch: pm10+delay1}}]",
            "RandomizedPlant mismatch 'pm10+delay1'",
        ),
        ("env_kwargs.gait_overrides.kc=300", "env_kwargs.gait_overrides"),
        ("env_kwargs.dt=0.02", "env_kwargs.dt"),
        ("env_wrapper=RandomizedPlant", "env_wrapper must be a list"),
        ("adaptive=[1]", "adaptive must be a mapping"),
    ],
)
def test_adaptive_recipe_refuses_what_it_would_ignore(train_cli, hp, words):
    line = train_cli("--hp", hp)
    assert words in line, line


def test_adaptive_recipe_resume_needs_a_run(train_cli, tmp_path):
    line = train_cli("--resume", "--name", "nothing")
    assert "--resume" in line and "nothing" in line, line


def test_adaptive_rerun_names_the_changed_settings(tmp_path):
    from dataclasses import asdict

    from agents.experts.adaptive import AdaptiveConfig, train_adaptive

    run = tmp_path / "run"
    run.mkdir()
    old = {**asdict(AdaptiveConfig()), "k": 2, "lr": 0.01}
    (run / "adaptive.json").write_text(json.dumps(old, default=str))
    with pytest.raises(ValueError, match=r"\(k: 2 -> 3; lr: 0.01 -> 0.003\)") as e:
        train_adaptive(AdaptiveConfig(), run, progress=False)
    assert "\n" not in str(e.value)


def test_adaptive_recipe_checks_every_config_field():
    from dataclasses import fields

    from agents.experts.adaptive import AdaptiveConfig
    from agents.experts.adaptive_recipe import RECIPE_KEYS

    assert set(RECIPE_KEYS) == {f.name for f in fields(AdaptiveConfig)} - {"mismatch", "seed"}


def test_adaptive_recipe_without_seed_trains_seed_0(tmp_path, monkeypatch):
    from agents.experts import adaptive_recipe

    seen = []

    class Stop(Exception):
        pass

    def record(cfg, run, progress=True):
        seen.append((cfg.seed, Path(run).name))
        raise Stop

    monkeypatch.setattr(adaptive_recipe, "train_adaptive", record)
    with pytest.raises(Stop):  # was a TypeError: int(None)
        adaptive_recipe.train_from_config(
            "adaptive", "PassiveBoundStride-v1", None, runs_dir=tmp_path
        )
    assert seen == [(0, "adaptive_s0")]


# -- the adaptive spec and the mismatch specs ---------------------------------------------------


@pytest.mark.parametrize(
    "block, words",
    [
        ("adaptive: null", "adaptive is null"),
        ("offset_free: null", "offset_free is null"),
        ("adaptive: {window: 2.5}", "adaptive.window must be an integer"),
        ("adaptive: {identify: 20.5}", "adaptive.identify must be an integer"),
        ("adaptive: {candidates: 12.0}", "adaptive.candidates must be an integer"),
        ("adaptive: {trust_strides: 12}", "adaptive.trust_strides 12 is longer than"),
        ("adaptive: {window: 3, trust_strides: 4}", "adaptive.trust_strides 4 is longer than"),
        ("adaptive: {sigma: 1e-300}", "adaptive.sigma must be a finite number in [1e-06, 10]"),
        ("adaptive: {prior: 1.0e-300}", "adaptive.prior must be a finite number in [1e-06, 10]"),
        ("adaptive: {sigma: 0}", "adaptive.sigma"),
    ],
)
def test_an_adaptive_spec_refuses_what_it_cannot_mean(tmp_path, capsys, block, words):
    from bound_env.commands.cli import main
    from bound_env.control.spec import load_spec

    spec = tmp_path / "spec.yaml"
    spec.write_text(f"controller: mpc\n{block}\n")
    with pytest.raises(ValueError, match="spec.yaml: ") as e:
        load_spec(spec)
    assert words in str(e.value) and "\n" not in str(e.value)
    assert main(["rollout", "--policy", str(spec), "--strides", "1"]) != 0
    line = _one_line(capsys)
    assert words in line and "ZeroDivisionError" not in line, line


@pytest.mark.parametrize("key", ["sigma", "prior"])
def test_adaptive_mpc_refuses_a_tiny_sigma_or_prior(key):
    from bound_env.control.adaptive import AdaptiveMPC

    with pytest.raises(ValueError, match=f"AdaptiveMPC: adaptive.{key} must be"):
        AdaptiveMPC(**{key: 1e-300})


@pytest.mark.parametrize(
    "text, words",
    [
        ("pm10+pm5", "preset pm10 and preset pm5 both set m1"),
        ("pm5+all10", "both set m1"),
        ("noise+noise5", "both set noise"),
        ("delay1+delay2", "both set delay"),
        ("noise5+noise5", "the preset 'noise5' is given twice"),
        ("pm5+noise+pm5", "the preset 'pm5' is given twice"),
    ],
)
def test_mismatch_presets_that_overlap_are_refused(capsys, text, words):
    from bound_env.commands.cli import main
    from bound_env.model.mismatch import as_spec, parse_specs

    with pytest.raises(ValueError, match=r"^mismatch ") as e:
        as_spec(text)
    assert words in str(e.value)
    with pytest.raises(ValueError, match=r"^--mismatch: "):
        parse_specs(text)
    assert main(["margins", "--policy", "lqr", "--mismatch", text, "--budget", "test"]) != 0
    assert words in _one_line(capsys)


def test_mismatch_presets_that_do_not_overlap_combine():
    from bound_env.model.mismatch import as_spec

    s = as_spec("pm10+noise+delay1")
    assert dict(s.ranges)["m1"] == 0.1 and s.has_noise and s.delay == 1


@pytest.mark.parametrize("content", ["", "\n\n", "# nothing\n", "{}\n"])
def test_an_empty_mismatch_file_is_refused(tmp_path, content):
    from bound_env.model.mismatch import as_spec

    p = tmp_path / "mine.yaml"
    p.write_text(content)
    with pytest.raises(ValueError, match=r"mismatch file .*mine.yaml: empty"):
        as_spec(str(p))


# -- compare --render-only: the model-error blocks checked -----------------------------------


def _block(k=30, n=32):
    return {"spec": {"name": "pm5"}, "hold": {"k": k, "n": n, "outcomes": [1] * n}}


@pytest.mark.parametrize(
    "mismatch, words",
    [
        ({"pm5": {"spec": {"name": "pm5"}}}, "mismatch.pm5: hold: missing"),
        ({"pm5": "text"}, "mismatch.pm5: not a JSON object"),
        (
            {"pm5": {**_block(), "hold": {"k": float("nan"), "n": 32}}},
            "mismatch.pm5.hold: k: must be an integer",
        ),
        ({"pm5": _block(99, 8)}, "k 99 of n 8"),
        ({"pm5": {**_block(), "hold": {"k": 3, "n": 8, "outcomes": [1]}}}, "1 outcomes for n 8"),
        ("pm5", "mismatch: must be a JSON object"),
    ],
)
def test_render_only_refuses_a_malformed_mismatch_block(tmp_path, capsys, mismatch, words):
    import sys

    sys.path.insert(0, str(ROOT / "tests"))
    from test_compare_page import _fixture, _render_here

    out, docs = _fixture(tmp_path)
    p = out / "lqr" / "margins.json"
    r = json.loads(p.read_text())
    r["mismatch"] = mismatch
    p.write_text(json.dumps(r))
    res = _render_here(out, docs, capsys)
    lines = [ln for ln in res.stderr.strip().splitlines() if not ln.startswith("warning:")]
    assert res.returncode != 0 and len(lines) == 1, res.stderr
    assert words in lines[0] and "margins.json" in lines[0], lines


# -- the scripts parse their arguments ---------------------------------------------------------


def _script(name: str):
    import importlib.util

    spec = importlib.util.spec_from_file_location(
        f"script48_{name}", ROOT / "scripts" / f"{name}.py"
    )
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _script_error(name, argv, capsys) -> str:
    try:
        code = _script(name).main([str(a) for a in argv])
    except SystemExit as e:
        code = e.code
    err = capsys.readouterr().err.strip()
    assert code not in (0, None) and "Traceback" not in err, err
    return err.splitlines()[-1]


def test_adaptive_tables_help_and_bad_files(tmp_path, capsys):
    with pytest.raises(SystemExit) as e:
        _script("adaptive_tables").main(["--help"])
    assert e.value.code == 0 and "adaptive_hold" in capsys.readouterr().out
    bad = tmp_path / "h.json"
    bad.write_text('{"entries": [1]}')
    assert "entries" in _script_error("adaptive_tables", [bad], capsys)
    assert "h2.json" in _script_error("adaptive_tables", [tmp_path / "h2.json"], capsys)
    hold = ROOT / "docs" / "data" / "adaptive_hold_test.json"
    line = _script_error("adaptive_tables", [hold, "--reference", "nope"], capsys)
    assert "--reference nope" in line, line


@pytest.mark.parametrize(
    "name, argv, words",
    [
        ("adaptive_hold", ["--policy", "lqr", "--mismatch", "pm5", "--seed", "-1"], "--seed"),
        ("adaptive_hold", ["--policy", "nope", "--mismatch", "pm5"], "--policy nope"),
        ("adaptive_hold", ["--policy", "lqr", "--mismatch", "pm99"], "--mismatch pm99"),
        ("adaptive_factors", ["--policy", "lqr", "--plants", "0"], "--plants"),
        ("adaptive_factors", ["--policy", "nope"], "--policy nope"),
        ("hold_vs_delta", ["--policy", "lqr", "--seed", "-1"], "--seed"),
    ],
)
def test_scripts_refuse_bad_arguments_before_running(tmp_path, capsys, name, argv, words):
    line = _script_error(name, [*argv, "--out", tmp_path / "o.json"], capsys)
    assert words in line and ": error: " in line, line
    assert not (tmp_path / "o.json").exists()


def test_hold_vs_delta_refuses_a_garbage_row(tmp_path, capsys):
    (tmp_path / "o.jsonl").write_text('{"policy": "lqr", "delta": 0.05, "seed": 777}\n{garbage\n')
    line = _script_error("hold_vs_delta", ["--policy", "lqr", "--out", tmp_path / "o.json"], capsys)
    assert "o.jsonl:2: not a row" in line, line


def test_hold_eval_set_on_mpc_adaptive_is_a_note_not_a_crash(tmp_path, capsys, monkeypatch):
    mod = _script("hold_eval")
    ran = []

    class Measured(Exception):  # stops the script where it would measure (minutes)
        pass

    def setup_of(*a, **k):
        ran.append(a[0])
        raise Measured

    monkeypatch.setattr(mod, "setup_of", setup_of)
    with pytest.raises(Measured):
        mod.run(
            ["--policy", "mpc-adaptive", "--set", "gain=0.5", "--out", str(tmp_path / "h.jsonl")]
        )
    err = capsys.readouterr().err
    assert "AttributeError" not in err and "mpc-adaptive is not offset-free" in err, err
    assert type(ran[0]).__name__ == "AdaptiveMPC"  # measured as itself, not re-wrapped


# -- property tests: the recipe's keys and the adaptive spec (Hypothesis; the examples per
# test are the profile's: 12 in the fast tier, 150 in CI, tests/conftest.py) ----------------

from hypothesis import given  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

WILD = st.one_of(
    st.integers(-2, 40),  # around the counts' bounds (a trust_strides past the window)
    st.sampled_from([1e-300, 1e-200, 5e-7, 1e-6]),  # a sigma or prior that overflows 1 / x^2
    st.none(),
    st.booleans(),
    st.integers(-(10**12), 10**12),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([1e-300, 1e300, 0, 1, 2, 3, 0.5, -1, 10, 100, "10", "0.5", "maybe", "pm10"]),
    st.text(max_size=6),
    st.lists(st.integers(-5, 5000), max_size=4),
)


def _in_range(v, lo, hi, kind) -> bool:
    import math

    if kind is int:
        return isinstance(v, int) and not isinstance(v, bool) and lo <= v <= hi
    return isinstance(v, float) and math.isfinite(v) and lo <= v <= hi


@given(
    key=st.sampled_from(
        sorted(__import__("agents.experts.adaptive_recipe", fromlist=["x"]).RECIPE_KEYS)
    ),
    value=WILD,
)
def test_every_recipe_key_is_its_type_and_range_or_one_line_naming_it(key, value):
    from agents.experts.adaptive_recipe import check_recipe

    try:
        out = check_recipe({key: value}, "configs/adaptive.yaml")[key]
    except ValueError as e:
        msg = str(e)
        assert msg.startswith(f"configs/adaptive.yaml: adaptive.{key}") and "\n" not in msg, msg
        return
    if key == "hidden":
        assert isinstance(out, tuple) and 1 <= len(out) <= 16
        assert all(_in_range(h, 1, 4096, int) for h in out)
    elif key == "summary":
        assert out is value and isinstance(out, bool)
    elif key in ("teacher", "expert", "val_mismatch"):
        assert isinstance(out, str)
    else:
        assert isinstance(out, (int, float)) and not isinstance(out, bool)
        assert out == out and abs(out) < 1e7  # finite, in its range


@given(
    block=st.dictionaries(
        st.sampled_from(
            sorted(
                __import__("bound_env.control.adaptive_settings", fromlist=["x"]).ADAPTIVE_DEFAULTS
            )
        ),
        WILD,
        max_size=4,
    )
)
def test_an_adaptive_block_is_in_range_or_one_line_naming_the_key(block):
    from bound_env.control.adaptive_settings import ADAPTIVE_INTS, ADAPTIVE_LIMITS, check_adaptive

    try:
        out = check_adaptive(block, "spec.yaml")
    except ValueError as e:
        msg = str(e)
        assert msg.startswith("spec.yaml: adaptive.") and "\n" not in msg, msg
        assert any(f"adaptive.{k}" in msg for k in block), msg
        return
    for k, (lo, hi) in ADAPTIVE_LIMITS.items():
        assert _in_range(
            out[k] if k in ADAPTIVE_INTS else float(out[k]),
            lo,
            hi,
            int if k in ADAPTIVE_INTS else float,
        ), (k, out[k])
    assert out["trust_strides"] <= out["window"]
    assert out["sigma"] >= 1e-6 and out["prior"] >= 1e-6  # 1 / sigma^2 stays finite


# -- tampered learned adaptive policies, another gait ---------------------------------------------


@pytest.fixture
def adaptive_copy(tmp_path):
    """agents/policies/adaptive/s0 copied, its weights x 1.5."""
    import numpy as np

    folder = tmp_path / "adaptive-s0"
    shutil.copytree(ROOT / "agents" / "policies" / "adaptive" / "s0", folder)
    with np.load(folder / "adaptive.npz") as d:
        arrays = {k: d[k] for k in d.files}
    arrays["W0"] = arrays["W0"] * 1.5
    np.savez(folder / "adaptive.npz", **arrays)
    return folder


@pytest.mark.parametrize("fingerprint", [None, "{}", '{"adaptive.npz": "x"}'])
def test_a_tampered_adaptive_policy_without_fingerprint_needs_force(
    adaptive_copy, capsys, fingerprint
):
    from agents.runtime.policy import load_controller
    from bound_env.commands.cli import main

    fp = adaptive_copy / "fingerprint.json"
    fp.unlink()
    if fingerprint is not None:
        fp.write_text(fingerprint)
    with pytest.raises(ValueError, match="fingerprint.json: .*pass --force"):
        load_controller(adaptive_copy)
    assert main(["rollout", "--policy", str(adaptive_copy), "--strides", "1"]) != 0
    assert "fingerprint.json" in _one_line(capsys)
    assert load_controller(adaptive_copy, force=True).k == 3
    assert "warning: " in capsys.readouterr().err


def test_a_learned_adaptive_policy_on_another_gait_needs_force(capsys):
    from agents.runtime.policy import load_controller
    from bound_env.commands.cli import main

    with pytest.raises(ValueError, match="trained on gait 'default', not 'literal-cycle'"):
        load_controller("adaptive/s0", gait="literal-cycle")
    argv = ["rollout", "--policy", "adaptive/s0", "--gait", "literal-cycle", "--strides", "1"]
    assert main(argv) != 0
    assert "--force" in _one_line(capsys)
    assert load_controller("adaptive/s0", gait="literal-cycle", force=True).gait == "literal-cycle"


# -- the cases left from earlier sets ------------------------------------------------------------


def _cli_line(argv, capsys) -> str:
    from bound_env.commands.cli import main

    try:
        code = main([str(a) for a in argv])
    except SystemExit as e:
        code = e.code
    line = _one_line(capsys)
    assert code not in (0, None), line
    return line


def test_train_hp_gamma_beside_the_shaping_discount_is_refused(tmp_path, capsys):
    argv = ["train", "--config", "ppo-rescue", "--hp", "gamma=0.5", "--out", tmp_path]
    line = _cli_line([*argv, "--n-timesteps", "10"], capsys)
    assert "gamma: 0.5" in line and "env_kwargs.gamma" in line, line
    assert not (tmp_path / "PassiveBoundRescue-v1_s0").exists()


def test_train_set_on_the_rescue_env_names_the_key_and_option(tmp_path, capsys):
    argv = ["train", "--config", "ppo-rescue", "--set", "kc=300", "--out", tmp_path]
    line = _cli_line([*argv, "--n-timesteps", "10"], capsys)
    assert "--set kc=300" in line and "takes no gait overrides" in line, line


def test_rescue_eval_says_what_lqr_of_is():
    mod = _script("rescue_eval")
    with pytest.raises(ValueError, match="lqr-of: a stride controller with memory"):
        mod.controller_actor("lqr-of")


@pytest.mark.parametrize("key, value", [("r_max", "0.3"), ("shaping", "0.1"), ("r_max", b"0.3")])
def test_the_rescue_env_refuses_numbers_given_as_text(key, value):
    import gymnasium as gym

    import bound_env

    gym.register_envs(bound_env)
    with pytest.raises(ValueError, match=f"{key} must be a number, got"):
        gym.make("PassiveBoundRescue-v1", **{key: value})


def test_an_archived_folders_own_name_points_to_its_path(capsys):
    from agents.runtime.policy import load_controller

    with pytest.raises(FileNotFoundError, match=r"did you mean .*agents/policies/archive/ppo-v1"):
        load_controller("archive/ppo-v1")
    line = _cli_line(["rollout", "--policy", "archive/ppo-v1", "--strides", "1"], capsys)
    assert "agents/policies/archive/ppo-v1" in line, line


@pytest.mark.parametrize("drop", ["budget", "r50"])
def test_headline_without_budget_or_a_rows_r50_is_one_line(tmp_path, capsys, drop):
    from agents.results.headline import main as headline_main

    head = json.loads((ROOT / "docs" / "headline.json").read_text())
    if drop == "budget":
        del head["budget"]
    else:
        del head["rows"][0]["r50"]
    p = tmp_path / "headline.json"
    p.write_text(json.dumps(head))
    readme = _readme_case(tmp_path, "<!-- headline:start -->\n<!-- headline:end -->\n")
    assert headline_main(["--json", str(p), "--readme", str(readme)]) == 2
    assert f"{drop}: missing" in _one_line(capsys)


def test_a_non_finite_apex_state_is_one_line():
    import gymnasium as gym
    import numpy as np

    import bound_env

    gym.register_envs(bound_env)
    env = gym.make("PassiveBoundRescue-v1")
    with pytest.raises(ValueError, match="apex_state must be finite") as e:
        env.reset(options={"apex_state": [0, 0, 0, 0, 1e8 + 1, np.inf]})
    assert "\n" not in str(e.value)  # found by test_properties' env property (a NumPy repr)
