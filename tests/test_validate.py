"""Files and inputs a user can hand us are validated when they are read (issue 26, §2 and §4).

Property-based (Hypothesis): generated reset options, stride actions and policy files end in a
ValueError naming what is wrong, or work; never another exception, a hang or a silent cast.
The hand-written rows of each class are in tests/test_fuzz.py.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

FAST = settings(
    max_examples=25,
    deadline=None,  # the first call compiles or loads the env's kernels
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
ROOT = Path(__file__).resolve().parents[1]

# values of every JSON kind (NaN and inf included), most of them wrong where a number is due
JSON_VALUE = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-(2**40), 2**40),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=8),
    st.lists(st.floats(allow_nan=True), max_size=8),
    st.dictionaries(st.text(max_size=3), st.integers(), max_size=2),
)
ANY_VALUE = st.one_of(JSON_VALUE, st.complex_numbers(max_magnitude=10))  # and complex numbers


@pytest.fixture(scope="module")
def envs():
    import gymnasium as gym

    import bound_env

    gym.register_envs(bound_env)
    out = {i: gym.make(i) for i in ("PassiveBound-v0", "PassiveBoundStride-v1")}
    yield out
    for e in out.values():
        e.close()


# -- reset(options=...) -----------------------------------------------------------------------


@FAST
@given(
    env_id=st.sampled_from(["PassiveBound-v0", "PassiveBoundStride-v1"]),
    options=st.one_of(
        ANY_VALUE,
        st.dictionaries(st.text(max_size=12), ANY_VALUE, max_size=3),
        st.fixed_dictionaries({"apex_state": ANY_VALUE}),
    ),
)
def test_reset_options_are_checked(envs, env_id, options):
    """Only None or a dict of known keys is accepted; apex_state must be 6 finite reals."""
    env = envs[env_id]
    ok = options is None or (
        isinstance(options, dict)
        and set(options) <= {"apex_state"}
        and (options.get("apex_state") is None or _six_finite_reals(options["apex_state"]))
    )
    if ok:
        env.reset(seed=0, options=options)
    else:
        with pytest.raises(ValueError, match="option|apex_state"):
            env.reset(seed=0, options=options)


def _six_finite_reals(z) -> bool:
    if isinstance(z, bool) or not isinstance(z, list) or len(z) != 6:
        return False
    return all(
        isinstance(v, (int, float)) and not isinstance(v, bool) and np.isfinite(v) for v in z
    )


@FAST
@given(z=st.lists(st.floats(-1e3, 1e3), min_size=6, max_size=6))
def test_any_finite_apex_state_starts_or_fails_by_name(envs, z):
    """A finite start is accepted; an impossible one is reported in info, not raised."""
    for env in envs.values():
        _, info = env.reset(seed=0, options={"apex_state": z})
        assert "failure" in info


# -- stride env actions -----------------------------------------------------------------------


@FAST
@given(
    shape=st.sampled_from([(4,), (1, 4), (4, 1), (3,), (5,), (), (2, 2)]),
    dtype=st.sampled_from(["float32", "float64", "int64", "bool", "complex128", "U3", "object"]),
)
def test_stride_actions_of_wrong_shape_or_dtype_are_refused(envs, shape, dtype):
    env = envs["PassiveBoundStride-v1"]
    env.reset(seed=0)
    a = np.zeros(shape, dtype=dtype)
    if shape == (4,) and dtype in ("float32", "float64", "int64"):
        env.step(a)
    else:
        with pytest.raises(ValueError, match="action"):
            env.step(a)


@FAST
@given(u=st.lists(st.floats(allow_nan=True, allow_infinity=True), min_size=4, max_size=4))
def test_stride_actions_must_be_finite(envs, u):
    env = envs["PassiveBoundStride-v1"]
    env.reset(seed=0)
    if np.all(np.isfinite(u)):
        env.step(np.array(u))
    else:
        with pytest.raises(ValueError, match="finite"):
            env.step(np.array(u))


def test_stride_env_refuses_a_step_after_termination(envs):
    env = envs["PassiveBoundStride-v1"]
    z = env.unwrapped.z_ref * np.array([1, 1, 1, 0.3, 1, 1])  # far too slow: falls
    env.reset(options={"apex_state": z})
    for _ in range(10):
        _, _, terminated, _, _ = env.step(np.ones(4))
        if terminated:
            break
    assert terminated
    with pytest.raises(ValueError, match="reset"):
        env.step(np.zeros(4))
    env.reset(seed=0)  # and a reset starts a new episode
    env.step(np.zeros(4))


# -- policy files -----------------------------------------------------------------------------


@pytest.fixture(scope="module")
def choice_src():
    from agents.runtime.policy import shipped_policies

    return shipped_policies()["default"]


def _copy(src, tmp_path, name="p"):
    d = tmp_path / name
    if d.exists():
        shutil.rmtree(d)
    shutil.copytree(src, d)
    return d


@FAST
@given(
    key=st.sampled_from(["n_layers", "rows", "W0", "b0", "W2", "b2", "W7"]),
    value=st.one_of(
        st.integers(-5, 40).map(np.array),
        st.lists(st.floats(allow_nan=True, allow_infinity=True), max_size=4).map(np.array),
        st.sampled_from(["x", "8"]).map(np.array),
        st.complex_numbers(max_magnitude=2).map(lambda c: np.full((2, 2), c)),
    ),
)
def test_choice_npz_fields_are_checked(choice_src, tmp_path, key, value):
    """Any one array of choice.npz replaced: refused with the file and the array named (a
    fingerprint rewritten, so only the schema can catch it), or the policy still loads."""
    from agents.runtime.choice_policy import load_choice_policy, write_choice_fingerprint

    d = _copy(choice_src, tmp_path)
    with np.load(d / "choice.npz") as f:
        arrays = dict(f)
    arrays[key] = value
    np.savez(d / "choice.npz", **arrays)
    write_choice_fingerprint(d)
    try:
        ctrl = load_choice_policy(d)
    except ValueError as e:
        assert "choice.npz" in str(e) and "\n" not in str(e)
    else:  # accepted: then it acts, with finite numbers
        assert np.all(np.isfinite(ctrl.plan(ctrl.z_ref * 1.2)))


SETTINGS = ["K", "dt", "max_torque", "basis", "gain"]
MPC = ["safe", "horizon", "rtol", "n_random", "cem_elites", "noise"]


@FAST
@given(where=st.sampled_from(SETTINGS + MPC), value=JSON_VALUE)
def test_choice_config_fields_are_checked(choice_src, tmp_path, where, value):
    from agents.runtime.choice_policy import load_choice_policy, write_choice_fingerprint

    d = _copy(choice_src, tmp_path)
    cfg = json.loads((d / "config.json").read_text())
    (cfg["expert"] if where in SETTINGS else cfg["expert"]["settings"])[where] = value
    (d / "config.json").write_text(json.dumps(cfg))
    write_choice_fingerprint(d)
    try:
        load_choice_policy(d)
    except ValueError as e:
        assert "config.json" in str(e) and where in str(e) and "\n" not in str(e)


def test_shipped_choice_configs_name_their_sources_relative_to_the_package():
    from agents.runtime.policy import SHIPPED_DIR, shipped_policies, source_name

    for name, folder in shipped_policies().items():
        for f in ("config.json", "run.json", "exported.json"):
            if (folder / f).is_file():
                text = (folder / f).read_text()
                assert "/work/" not in text and '"/' not in text, (name, f)
    assert source_name(SHIPPED_DIR / "finetuned" / "s0") == "finetuned/s0"
    assert source_name("runs/x/policy") == "runs/x/policy"
    cfg = json.loads((shipped_policies()["default"] / "config.json").read_text())
    assert cfg["student"] == "distilled/s0" and cfg["expert"]["name"] == "distilled/s0"


# -- the command line -------------------------------------------------------------------------


def test_cli_parses_before_importing_the_heavy_modules():
    """Importing the CLI and building its parser (every sub-command registered) imports no
    numba, scipy, torch or stable_baselines3 (benchmarks/cli_startup.py times it)."""
    code = (
        "import sys\nfrom bound_env.commands.cli import build_parser\nbuild_parser()\n"
        "print(sorted(m for m in ('numba', 'scipy', 'torch', 'stable_baselines3') "
        "if m in sys.modules))"
    )
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == "[]"
    code = "from bound_env.commands.cli import main; import sys; sys.exit(main())"
    r = subprocess.run(
        [sys.executable, "-c", code, "--help"], capture_output=True, text=True, env=env
    )
    assert r.returncode == 0 and "compare" in r.stdout and "distill" in r.stdout
    r = subprocess.run(
        [sys.executable, "-c", code, "compare", "--budget", "nope"],
        capture_output=True,
        text=True,
        env=env,
    )
    assert r.returncode == 2 and "--budget" in r.stderr and "Traceback" not in r.stderr


def test_compare_defaults_to_quick_and_its_help_says_where_its_time_is(capsys):
    """The page's run time is one measured figure (docs/columns.json, quoted by the docs):
    the help points there instead of quoting a time of its own."""
    import re

    from bound_env.commands.cli import build_parser, main

    args = build_parser().parse_args(["compare"])
    assert args.budget == "quick"
    assert main(["compare", "--help"]) == 0
    out = " ".join(capsys.readouterr().out.split())
    assert "docs/columns.json" in out and not re.search(r"\d min\b", out)


def test_progress_lines_when_stderr_is_not_a_terminal(capsys, monkeypatch):
    from concurrent.futures import ThreadPoolExecutor

    from bound_env.sim.parallel import ProgressLines, run_tasks

    monkeypatch.setattr(ProgressLines, "EVERY_S", 1e9)  # by the 10 % rule only
    tasks = {i: (abs, (-i,)) for i in range(20)}
    with ThreadPoolExecutor(1) as ex:
        results, failures = run_tasks(ex, tasks, progress=True, desc="t")
    assert results == {i: i for i in range(20)} and not failures
    lines = capsys.readouterr().err.strip().splitlines()
    assert lines[0] == "[t] 0/20 tasks (0 %), 0 s"
    assert lines[-1].startswith("[t] 20/20 tasks (100 %)")
    assert 10 <= len(lines) <= 12  # every 2 tasks (10 %), not one per task


def test_rollout_summary_without_an_apex_says_so():
    from agents.runtime.rollout import summary_text

    r = {
        "apex_error": [],
        "fell": True,
        "failure": "ground_contact_front_hip",
        "policy": "passive",
        "gait": "default",
        "strides": 0,
        "requested_strides": 5,
        "mean_abs_tau": 0.0,
        "max_torque": 80.0,
    }
    text = summary_text(r)
    assert "nan" not in text and "no apex reached" in text
