"""Bad input, every sub-command: a one-line error and a non-zero exit, never a traceback.

The CLI table runs in-process (`bound_env.commands.cli.main`): an exception escaping ``main`` is
what a user would see as a traceback, and fails the test. The env table does the same for the
Gymnasium API: a clear ``ValueError``, never another exception or a silent coercion.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from agents.runtime.policy_table import ARCHIVE_DIR
from bound_env.commands.cli import main

BAD_GAITS = {
    "list": "- 1\n- 2\n",
    "truncated": "kc: [1, 2\n",
    "unparsable": "kc: : :\n  - ]\n",
    "tag": "kc: !!python/object/apply:os.system ['echo hi']\n",
    "binary": b"\x89PNG\r\n\x1a\n\x00\x00\xff\xfe",
    "z_star_short": "kc: 295\nz_star: [0.25, 0.5]\n",
    "z_star_text": "kc: 295\nz_star: [a, b, c, d, e, f]\n",
    "bad_value": "kc: stiff\n",
}


@pytest.fixture
def files(tmp_path):
    out = {}
    for name, text in BAD_GAITS.items():
        p = tmp_path / f"{name}.yaml"
        if isinstance(text, bytes):
            p.write_bytes(text)
        else:
            p.write_text(text)
        out[name] = str(p)
    blocker = tmp_path / "a_file"
    blocker.write_text("x")
    out["file"] = str(blocker)
    out["dir"] = str(tmp_path)
    # a PPO policy whose config.yaml was cut at a line boundary before env_kwargs: it parses
    # and matches the observation shape, but would run at the env's default max_torque
    from agents.runtime.policy import shipped_policies

    cut = tmp_path / "cut-policy"
    shutil.copytree(ARCHIVE_DIR / "ppo-v1", cut)
    lines = (cut / "config.yaml").read_text().splitlines(keepends=True)
    end = next(i for i, line in enumerate(lines) if line.lstrip().startswith("env_kwargs"))
    (cut / "config.yaml").write_text("".join(lines[:end]))
    out["cut_policy"] = str(cut)
    # the shipped default (a distilled choice policy) with its config.json cut short: its
    # fingerprint.json holds the sha256
    cut = tmp_path / "cut-choice"
    shutil.copytree(shipped_policies()["default"], cut)
    text = (cut / "config.json").read_text()
    (cut / "config.json").write_text(text[: len(text) // 2])
    out["cut_choice"] = str(cut)
    # the shipped default with dt 1e-7 (ran until killed) and its fingerprint rewritten
    import json

    from agents.runtime.choice_policy import write_choice_fingerprint

    slow = tmp_path / "dt-choice"
    shutil.copytree(shipped_policies()["default"], slow)
    cfg = json.loads((slow / "config.json").read_text())
    cfg["expert"]["dt"] = 1e-7
    (slow / "config.json").write_text(json.dumps(cfg))
    write_choice_fingerprint(slow)
    out["dt_choice"] = str(slow)
    # a PPO folder with a choice.npz dropped in
    both = tmp_path / "both"
    shutil.copytree(ARCHIVE_DIR / "ppo-v1", both)
    shutil.copy(shipped_policies()["default"] / "choice.npz", both)
    out["both"] = str(both)
    return out


def _cases(f):
    """(argv, a word the error must contain, or None)."""
    cases = []
    for name in BAD_GAITS:
        g = f[name]
        cases += [
            (["stride", "--gait", g], "gait file"),
            (["fixed-point", "--gait", g], "gait file"),
            (["animate", "--gait", g, "--out", f["dir"] + "/x.gif"], "gait file"),
            (
                [
                    "sweep",
                    "--gait",
                    g,
                    "--param",
                    "kc",
                    "--from",
                    "290",
                    "--to",
                    "291",
                    "--step",
                    "1",
                    "--out",
                    f["dir"] + "/s",
                ],
                "gait file",
            ),
            (["rollout", "--policy", "passive", "--gait", g, "--strides", "1"], "gait file"),
        ]
    cases += [
        (["stride", "--gait", f["dir"]], "folder"),
        (["stride", "--repeat", "0"], "--repeat"),
        (["stride", "--repeat", "inf"], "--repeat"),
        (["stride", "--z", "1,2,3"], "--z"),
        (["stride", "--set", "kc=abc"], "kc"),
        (["stride", "--set", "nope=1"], "nope"),
        (["stride", "--backend", "gpu"], "--backend"),
        (["fixed-point", "--tol", "-1"], "--tol"),
        (["fixed-point", "--tol", "nan"], "--tol"),
        (["fixed-point", "--max-iter", "-1"], "--max-iter"),
        (["continue", "--param", "kc", "--to", "inf", "--out", f["dir"] + "/c"], "--to"),
        (["continue", "--param", "kc", "--to", "300", "--step", "0", "--out", f["dir"]], "--step"),
        (
            ["continue", "--param", "kc", "--to", "300", "--max-points", "0", "--out", f["dir"]],
            "--max-points",
        ),
        (
            [
                "sweep",
                "--param",
                "kc",
                "--from",
                "290",
                "--to",
                "300",
                "--step",
                "1e-12",
                "--out",
                f["dir"] + "/s",
            ],
            "points",
        ),
        (
            [
                "sweep",
                "--param",
                "kc",
                "--from",
                "300",
                "--to",
                "290",
                "--step",
                "1",
                "--out",
                f["dir"] + "/s",
            ],
            "--from",
        ),
        (
            [
                "sweep",
                "--param",
                "kc",
                "--from",
                "290",
                "--to",
                "300",
                "--step",
                "0",
                "--out",
                f["dir"] + "/s",
            ],
            "--step",
        ),
        (
            [
                "sweep",
                "--param",
                "kc",
                "--from",
                "290",
                "--to",
                "291",
                "--step",
                "1",
                "--out",
                f["file"],
            ],
            "not a folder",
        ),
        (["continue", "--param", "kc", "--to", "296", "--out", f["file"]], "not a folder"),
        (["animate", "--strides", "0"], "--strides"),
        (["animate", "--strides", "inf"], "--strides"),
        (["animate", "--fps", "0"], "--fps"),
        (["animate", "--strides", "1", "--out", f["file"]], "not a folder"),
        (["animate", "--strides", "1", "--out", f["file"] + "/a.gif"], "not a folder"),
        (["demo", "--gif-strides", "0"], "--gif-strides"),
        (["demo", "--out", f["file"]], "not a folder"),
        (["rollout", "--strides", "inf"], "--strides"),
        (["rollout", "--strides", "0"], "--strides"),
        (["rollout", "--noise", "nan"], "--noise"),
        (["rollout", "--policy", f["dir"] + "/nothing"], "does not exist"),
        (["rollout", "--policy", "passive", "--strides", "1", "--video", "x.avi"], "--video"),
        (["margins", "--workers", "0"], "--workers"),
        (["margins", "--budget", "huge"], "--budget"),
        (
            ["margins", "--policy", "passive", "--budget", "test", "--out", f["file"]],
            "not a folder",
        ),
        (["train", "--n-timesteps", "inf"], "--n-timesteps"),
        (
            [
                "train",
                "--name",
                "x",
                "--runs-dir",
                f["dir"] + "/r",
                "--n-timesteps",
                "64",
                "--set",
                "not_a_hyperparameter=1",
            ],
            "not_a_hyperparameter",
        ),
        (["train", "--name", "nope", "--runs-dir", f["dir"] + "/r", "--resume"], "--resume"),
        (["compare", "--workers", "0"], "--workers"),
        (["reproduce"], "--out"),
        (["nonsense-command"], None),
        # red-team pass (issue 20): tracebacks
        (["train", "--config", f["unparsable"], "--runs-dir", f["dir"] + "/r"], "not valid YAML"),
        (_train(f, "--hp", "env_kwargs.bogus=1"), "bogus"),
        (_train(f, "--set", "env_kwargs.bogus=1"), "bogus"),  # the old spelling of --hp
        (_train(f, "--hp", "callback=[{agents.train.NoiseCurriculumCallback: {x: 1}}]"), "x"),
        (_train(f, "--set", "kc=-1"), "kc"),
        (_train(f, "--gait", f["list"]), "gait file"),
        (["train", "--seed", "-1"], "--seed"),
        (["rollout", "--seed", "-1"], "--seed"),
        (["rollout", "--seed", "4294967296"], "--seed"),
        # unbounded
        (["basin-map", "--grid", "100000", "--out", f["dir"] + "/b"], "--grid"),
        (["basin-map", "--grid", "1", "--out", f["dir"] + "/b"], "--grid"),
        (["basin-map", "--strides", "0", "--out", f["dir"] + "/b"], "--strides"),
        # accepted though wrong
        (_sweep(f, "kc", "-10", "10", "1"), "kc = -10"),
        (_sweep(f, "m1", "0", "1", "0.5"), "m1 = 0"),
        (_sweep(f, "gamma_b_deg", "80", "95", "5"), "gamma_b_deg = 90"),
        (_sweep(f, "zeta", "-1", "0", "0.5"), "zeta = -1"),
        (["continue", "--param", "kc", "--step", "-1", "--to", "305", "--out", f["dir"]], "--step"),
        (["stride", "--z=nan,0.5,-1,2.8,294,-147"], "--z"),
        (["stride", "--z=0.25,inf,-1,2.8,294,-147"], "--z"),
        (["fixed-point", "--z0=0.25,0.5,-1,2.8,nan,-147"], "--z0"),
        # a config cut short (fingerprint.json holds its sha256)
        (["rollout", "--policy", f["cut_policy"], "--strides", "1"], "config.yaml does not match"),
        (
            ["margins", "--policy", f["cut_policy"], "--budget", "test", "--out", f["dir"] + "/m"],
            "config.yaml does not match",
        ),
        (
            ["basin-map", "--policy", f["cut_policy"], "--grid", "2", "--out", f["dir"] + "/b"],
            "config.yaml does not match",
        ),
        (
            [
                "compare",
                "--entry",
                "cut=" + f["cut_policy"],
                "--budget",
                "test",
                "--workers",
                "1",
                "--out",
                f["dir"] + "/cmp",
            ],
            "config.yaml does not match",
        ),
        (["rollout", "--policy", f["cut_choice"], "--strides", "1"], "config.json does not match"),
        (
            ["margins", "--policy", f["cut_choice"], "--budget", "test", "--out", f["dir"] + "/m"],
            "config.json does not match",
        ),
        # policy files validated at load (issue 26 §2; every class: CHOICE_CASES below)
        (["rollout", "--policy", f["dt_choice"], "--strides", "1"], "expert.dt"),
        (
            ["margins", "--policy", f["both"], "--budget", "test", "--out", f["dir"] + "/m"],
            "ambiguous",
        ),
        (["rollout", "--policy", f["both"], "--strides", "1"], "ambiguous"),
        # overwrites
        (_train(f, "--export", f["cut_policy"]), "--force"),
        (_train(f, "--export-out", f["cut_policy"]), "--force"),
        (["fixed-point", "--save", f["dir"]], "--out"),
        (["fixed-point", "--out", f["file"]], "not a folder"),
        # messages
        (["margins", "--set", "kc=1"], "bound-env margins: error: unrecognized arguments"),
        (["rollout", "--policy", "nope"], "step-ppo/s0"),  # the names it knows
        # issue 26 §3: refused before any work, nothing left behind
        (["distill", "--expert", "lqr", "--out", f["dir"] + "/d"], "--expert"),
        (["distill", "--out", f["dir"] + "/d", "--export", "/sys/x/p"], "--export"),
        (["finetune", "--student", "default", "--out", "/sys/x/ft"], "--out"),
        (["rollout", "--policy", "passive", "--video", "/sys/x/v.gif"], "--video"),
        # names that become paths (one checker)
        (_compare(f, "..=lqr"), "--entry"),
        (_compare(f, "a|b=lqr"), "--entry"),
        (_compare(f, "passive=lqr"), "same name"),
        (_compare(f, "a b=lqr", "a_b=lqr"), "same name or folder"),
        (_compare(f, "lqr", "x=" + f["dir"] + "/nothing"), "does not exist"),
        (_train(f, "--name", "../x"), "--name"),
        # bounded, and named
        (["margins", "--scheduler", "local:100000", "--out", f["dir"] + "/m"], "--scheduler"),
        (["margins", "--scheduler", "tcp://127.0.0.1:1", "--out", f["dir"] + "/m"], "--scheduler"),
        (["margins", "--workers", "100000"], "--workers"),
    ]
    return cases


def _compare(f, *entries):
    argv = ["compare", "--budget", "test", "--workers", "1", "--out", f["dir"] + "/cmp-refused"]
    for e in entries:
        argv += ["--entry", e]
    return argv


def _train(f, *extra):
    """A train command that must fail before training (and before making its run folder)."""
    return ["train", "--name", "x", "--out", f["dir"] + "/runs", "--n-timesteps", "64", *extra]


def _sweep(f, param, lo, hi, step):
    return [
        "sweep",
        "--param",
        param,
        "--from=" + lo,
        "--to",
        hi,
        "--step",
        step,
        "--refine",
        "0",
        "--out",
        f["dir"] + "/sweep-" + param,
    ]


@pytest.mark.slow  # ~15 s: train imports torch
def test_cli_fuzz(files, capsys):
    failures = []
    for argv, word in _cases(files):
        try:
            code = main(argv)
        except SystemExit as e:  # argparse: usage error, exit 2
            code = e.code
        except Exception as e:  # noqa: BLE001 - what a user would see as a traceback
            failures.append(f"{argv}: {type(e).__name__}: {e}")
            continue
        err = capsys.readouterr().err
        if not code:
            failures.append(f"{argv}: exit 0")
        elif "Traceback" in err:
            failures.append(f"{argv}: traceback")
        elif word is not None and word not in err:
            failures.append(f"{argv}: error does not name {word!r}: {err.strip()[-300:]}")
    assert not failures, "\n".join(failures)
    # refused before anything was written: no run folder, no sweep rows, no basin map
    left = [
        n
        for n in ("runs", "sweep-kc", "sweep-m1", "b", "d", "m", "cmp-refused", "x")
        if (Path(files["dir"]) / n).exists()
    ]
    assert not left, left
    assert (Path(files["cut_policy"]) / "model.zip").is_file()  # --export refused, nothing lost


def test_gait_file_errors_name_the_file_and_the_key(files):
    from bound_env.model.params import load_gait

    with pytest.raises(ValueError, match="z_star_short.yaml.*z_star must be 6"):
        load_gait(files["z_star_short"])
    with pytest.raises(ValueError, match="bad_value.yaml.*kc"):
        load_gait(files["bad_value"])
    with pytest.raises(ValueError, match="list.yaml.*mapping"):
        load_gait(files["list"])


def test_fold_is_a_result_exit_0(tmp_path, capsys, monkeypatch):
    """A branch that ends at a fold (docs/analysis.md's arclength example, near k_c = 303) exits 0
    and reports it; only a branch that cannot start is an error."""
    from types import SimpleNamespace

    from bound_env.analysis import continuation

    point = SimpleNamespace(value=303.0, fold=True, pd=False, ns=False)
    folded = SimpleNamespace(
        points=[point], reason="fold: a real eigenvalue reached +1", reached=False
    )
    monkeypatch.setattr(continuation, "continue_branch", lambda *a, **k: folded)
    monkeypatch.setattr(continuation, "plot_branch", lambda *a, **k: None)
    argv = ["continue", "--param", "kc", "--to", "305", "--out", str(tmp_path)]
    assert main(argv) == 0
    assert "fold" in capsys.readouterr().out
    monkeypatch.setattr(
        continuation,
        "continue_branch",
        lambda *a, **k: SimpleNamespace(points=[], reason="no fixed point", reached=False),
    )
    assert main(argv) == 1


# -- environment API ---------------------------------------------------------------------


@pytest.fixture
def env():
    import gymnasium as gym

    import bound_env

    gym.register_envs(bound_env)
    e = gym.make("PassiveBound-v0")
    e.reset(seed=0)
    yield e
    e.close()


@pytest.mark.parametrize(
    "action",
    [
        None,
        np.array([1 + 2j]),
        1 + 0j,
        "0.5",
        [np.nan],
        np.array([np.inf]),
        np.zeros(2),
        [[0.1, 0.2]],
        object(),
    ],
)
def test_env_step_rejects_bad_actions(env, action):
    with pytest.raises(ValueError, match="action"):
        env.step(action)


@pytest.mark.parametrize(
    "z",
    [np.zeros((2, 3)), np.ones((6, 1)), [1.0] * 5, ["a"] * 6, [np.nan] * 6, np.ones(6) * (1 + 1j)],
)
def test_env_reset_rejects_bad_apex_states(env, z):
    with pytest.raises(ValueError, match="apex_state"):
        env.reset(options={"apex_state": z})


def test_env_gait_path_that_is_not_a_mapping(files):
    import gymnasium as gym

    with pytest.raises(ValueError, match="mapping"):
        gym.make("PassiveBound-v0", gait=files["list"])


# -- policy files (issue 26 §2): each class of bad file, fingerprint rewritten ------------------


def _set_npz(**arrays):
    def f(d):
        with np.load(d / "choice.npz") as z:
            a = dict(z)
        a.update(arrays)
        np.savez(d / "choice.npz", **a)

    return f


def _map_npz(key, fn):
    def f(d):
        with np.load(d / "choice.npz") as z:
            a = dict(z)
        a[key] = fn(a[key])
        np.savez(d / "choice.npz", **a)

    return f


def _set_cfg(path, value):
    def f(d):
        import json

        cfg = json.loads((d / "config.json").read_text())
        node = cfg
        for k in path[:-1]:
            node = node[k]
        node[path[-1]] = value
        (d / "config.json").write_text(json.dumps(cfg))

    return f


def _write(name, data):
    def f(d):
        (d / name).write_bytes(data) if isinstance(data, bytes) else (d / name).write_text(data)

    return f


def _nan_safe(d):
    text = (d / "config.json").read_text().replace('"safe": 0.05', '"safe": NaN')
    (d / "config.json").write_text(text)


def _fingerprint_folder(d):
    (d / "fingerprint.json").unlink()
    (d / "fingerprint.json").mkdir()


def _add_model_zip(d):

    shutil.copy(ARCHIVE_DIR / "ppo-v1" / "model.zip", d / "model.zip")


CHOICE_CASES = {  # name: (change to a copy of the shipped default, words the error must hold)
    "n_layers 0": (_set_npz(n_layers=np.array(0)), "n_layers"),
    "n_layers -1": (_set_npz(n_layers=np.array(-1)), "n_layers"),
    "n_layers list": (_set_npz(n_layers=np.array([3, 3])), "n_layers"),
    "n_layers float": (_set_npz(n_layers=np.array(3.0)), "n_layers"),
    "0-byte choice.npz": (_write("choice.npz", b""), "choice.npz: empty"),
    "garbage choice.npz": (_write("choice.npz", b"PK\x03\x04garbage"), "choice.npz"),
    "NaN weight": (_map_npz("W0", lambda w: np.where(w == w.flat[0], np.nan, w)), "W0"),
    "inf bias": (_map_npz("b1", lambda b: b + np.inf), "b1"),
    "complex weights": (_map_npz("W1", lambda w: w * (1 + 1j)), "W1"),
    "string weights": (_map_npz("W2", lambda w: w.astype(str)), "W2"),
    "mis-chained layer": (_map_npz("W1", lambda w: w[:, :-1]), "W1"),
    "rows out of range": (_map_npz("rows", lambda r: 2 * r), "rows"),
    "extra array": (_set_npz(W9=np.zeros((2, 2))), "W9"),
    "dt 0": (_set_cfg(("expert", "dt"), 0), "expert.dt"),
    "dt 1e-7 (unbounded work)": (_set_cfg(("expert", "dt"), 1e-7), "expert.dt"),
    "horizon '12'": (_set_cfg(("expert", "settings", "horizon"), "12"), "horizon"),
    "horizon 10**9": (_set_cfg(("expert", "settings", "horizon"), 10**9), "horizon"),
    "K '8'": (_set_cfg(("expert", "K"), "8"), "expert.K"),
    "safe -1": (_set_cfg(("expert", "settings", "safe"), -1), "safe"),
    "safe NaN": (_nan_safe, "safe"),
    "rtol 0": (_set_cfg(("expert", "settings", "rtol"), 0), "rtol"),
    "gain wrong shape": (_set_cfg(("expert", "gain"), [[1.0] * 6]), "expert.gain"),
    "unknown setting": (_set_cfg(("expert", "settings", "bogus"), 1), "bogus"),
    "0-byte config.json": (_write("config.json", b""), "config.json: empty"),
    "deeply nested config.json": (_write("config.json", "[" * 10**5 + "]" * 10**5), "nested"),
    "config.json a list": (_write("config.json", "[1, 2]"), "mapping"),
    "fingerprint.json a folder": (_fingerprint_folder, "fingerprint.json: not a file"),
    "model.zip beside choice.npz": (_add_model_zip, "ambiguous"),
}


@pytest.mark.parametrize("case", list(CHOICE_CASES))
def test_bad_choice_policy_files_are_refused_by_file_and_field(case, tmp_path):
    from agents.runtime.choice_policy import write_choice_fingerprint
    from agents.runtime.policy import load_controller, shipped_policies

    change, words = CHOICE_CASES[case]
    d = tmp_path / "pol"
    shutil.copytree(shipped_policies()["default"], d)
    change(d)
    if (d / "fingerprint.json").is_file():  # rewritten: only the schema can catch it
        write_choice_fingerprint(d)
    with pytest.raises(ValueError, match=None) as e:
        load_controller(d)
    msg = str(e.value)
    assert words in msg and "\n" not in msg, msg


def test_a_ppo_folder_with_a_choice_npz_dropped_in_is_refused(tmp_path):
    from agents.runtime.policy import load_controller, shipped_policies

    d = tmp_path / "ppo"
    shutil.copytree(ARCHIVE_DIR / "ppo-v1", d)
    shutil.copy(shipped_policies()["default"] / "choice.npz", d)
    with pytest.raises(ValueError, match="ambiguous"):
        load_controller(d)


@pytest.mark.parametrize(
    "text, word",
    [
        ("dt: 1.0e-7", "dt"),
        ("horizon: '12'", "horizon"),
        ("horizon: 100000", "horizon"),
        ("plan_rtol: 0", "plan_rtol"),
        ("safe: .nan", "safe"),
        ("max_torque: 1.0e+9", "max_torque"),
        ("cem_samples: true", "cem_samples"),
        ("offset_free: {gain: .nan}", "offset_free.gain"),
        ("offset_free: {max_shift: '-1'}", "offset_free.max_shift"),
        ("offset_free: {estimator: 3}", "offset_free.estimator"),
    ],
)
def test_bad_controller_specs_are_refused_by_key(tmp_path, text, word):
    from bound_env.control.spec import load_spec

    p = tmp_path / "m.yaml"
    p.write_text(f"controller: mpc\nK: 8\n{text}\n")
    with pytest.raises(ValueError, match=f"m.yaml: {word}"):
        load_spec(p)


# -- env options and stride actions (issue 26 §2) ---------------------------------------------


@pytest.mark.parametrize("env_id", ["PassiveBound-v0", "PassiveBoundStride-v1"])
@pytest.mark.parametrize(
    "options, word",
    [
        ([("apex_state", [0.25] * 6)], "options must be a dict"),
        ("apex_state", "options must be a dict"),
        ({"apex_sate": [0.25] * 6}, "unknown reset option 'apex_sate'"),
        ({"apex_state": ["0.25"] * 6}, "apex_state"),
        ({"apex_state": [True] * 6}, "apex_state"),
        ({"apex_state": [[0.25, 0.5], [1.0]]}, "apex_state"),
        ({"apex_state": {"y_g": 0.25}}, "apex_state"),
    ],
)
def test_env_reset_rejects_bad_options(env_id, options, word):
    import gymnasium as gym

    import bound_env

    gym.register_envs(bound_env)
    with gym.make(env_id) as e, pytest.raises(ValueError, match=word):
        e.reset(options=options)


@pytest.mark.parametrize(
    "action",
    [
        np.zeros((1, 4)),
        np.zeros((4, 1)),
        np.zeros(3),
        np.zeros(4, complex),
        np.array(["0"] * 4),
        np.zeros(4, bool),
        [[0.0, 0.0], [0.0]],
        None,
    ],
)
def test_stride_env_step_rejects_bad_actions(action):
    import gymnasium as gym

    import bound_env

    gym.register_envs(bound_env)
    with gym.make("PassiveBoundStride-v1") as e:
        e.reset(seed=0)
        with pytest.raises(ValueError, match="action"):
            e.step(action)
