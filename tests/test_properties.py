"""Property tests (Hypothesis) of the surfaces of issue 40, for the classes behind its cases.

- the model-error spec: any YAML document, any ``MismatchSpec`` arguments and any
  ``--mismatch`` text give a one-line ValueError, or a spec that round-trips (its dict, and
  its dict through YAML, give the same spec back; its numbers are in their ranges);
- every registered env id: any ``make`` kwargs (near the defaults, at the edges, of the wrong
  type) and reset options give one ValueError/TypeError of one line, or an env whose
  observations and rewards are finite for a few steps;
- every Python script in scripts/: any arguments give argparse's one error line (exit 2) or
  a namespace inside the documented ranges; rescue_eval.py runs small ones to a result.

The number of examples is the profile's (tests/conftest.py: few by default, many in CI).
"""

from __future__ import annotations

import importlib
import importlib.util
import json
import math
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

import bound_env
from bound_env.model.mismatch import (
    MAX_DELAY,
    MAX_NOISE,
    NOISE_SCALES,
    PLANT_KEYS,
    PRESETS,
    MismatchSpec,
    as_spec,
    from_dict,
    load_spec,
    parse_specs,
)

gym.register_envs(bound_env)
ROOT = Path(__file__).resolve().parents[1]


def one_line(e: BaseException) -> str:
    text = str(e)
    assert text and "\n" not in text, repr(text)
    return text


# -- values ------------------------------------------------------------------------------------

ANY = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-(2**70), 2**70),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=6),
    st.lists(st.floats(allow_nan=True), max_size=3),
    st.dictionaries(st.text(max_size=4), st.integers(), max_size=2),
)
NAME = st.one_of(
    st.from_regex(r"[A-Za-z0-9][A-Za-z0-9._+ ()-]{0,20}", fullmatch=True),
    st.text(max_size=70),
    ANY,
)
DELTA = st.one_of(st.floats(0.0, 0.999), st.floats(-1.0, 2.0), ANY)
SIGMA = st.one_of(st.floats(0.0, MAX_NOISE), st.floats(-1.0, 1e7), ANY)
PARAMS = st.dictionaries(
    st.one_of(st.sampled_from(PLANT_KEYS), st.text(max_size=4)), DELTA, max_size=4
)
NOISE = st.dictionaries(
    st.one_of(st.sampled_from(list(NOISE_SCALES)), st.text(max_size=4)), SIGMA, max_size=4
)
DOCUMENT = st.one_of(
    st.fixed_dictionaries(
        {},
        optional={
            "params": st.one_of(PARAMS, ANY),
            "noise": st.one_of(NOISE, SIGMA),
            "delay": st.one_of(st.integers(-3, MAX_DELAY + 3), ANY),
            "name": NAME,
            "extra": ANY,
        },
    ),
    ANY,
)


def _checked(spec: MismatchSpec) -> MismatchSpec:
    """A spec that was accepted: in range, and the same after a round trip."""
    assert all(k in PLANT_KEYS and 0.0 <= d < 1.0 for k, d in spec.ranges)
    assert all(k in NOISE_SCALES and 0.0 <= s <= MAX_NOISE for k, s in spec.noise)
    assert 0 <= spec.delay <= MAX_DELAY and isinstance(spec.delay, int)
    again = from_dict(spec.to_dict())
    assert again == spec and again.name == spec.name
    assert from_dict(yaml.safe_load(yaml.safe_dump(spec.to_dict()))) == spec
    json.dumps(spec.to_dict(), allow_nan=False)  # strict JSON: it goes into margins.json
    return spec


# -- the model-error spec ----------------------------------------------------------------------


@given(doc=DOCUMENT)
def test_any_yaml_document_is_a_spec_or_one_line(tmp_path, doc):
    f = tmp_path / "spec.yaml"
    f.write_text(yaml.safe_dump(doc))
    try:
        spec = as_spec(f)
    except ValueError as e:
        assert str(f) in one_line(e)
        return
    spec = _checked(spec)
    again = tmp_path / "again.yaml"
    again.write_text(yaml.safe_dump(spec.to_dict()))
    assert load_spec(again) == spec


@given(text=st.text(max_size=60))
def test_any_yaml_text_is_a_spec_or_one_line(tmp_path, text):
    f = tmp_path / "text.yaml"
    f.write_text(text, encoding="utf-8")
    try:
        _checked(as_spec(f))
    except ValueError as e:
        assert str(f) in one_line(e)


PAIRS = st.one_of(
    PARAMS, NOISE, st.lists(st.tuples(st.sampled_from(PLANT_KEYS), DELTA), max_size=3), ANY
)


@given(ranges=PAIRS, noise=PAIRS, delay=st.one_of(st.integers(-3, 25), ANY), name=NAME)
def test_any_mismatch_spec_arguments_are_a_spec_or_one_line(ranges, noise, delay, name):
    try:
        spec = MismatchSpec(ranges=ranges, noise=noise, delay=delay, name=name)
    except ValueError as e:
        one_line(e)
        return
    _checked(spec)


PIECE = st.one_of(
    st.sampled_from(sorted(PRESETS)),
    st.lists(st.sampled_from(sorted(PRESETS)), min_size=1, max_size=3).map("+".join),
    st.text(alphabet="pm05+, /.ya", max_size=8),
)


@given(pieces=st.lists(PIECE, min_size=1, max_size=4))
def test_any_mismatch_text_is_specs_or_one_line(pieces):
    text = ",".join(pieces)
    try:
        specs = parse_specs(text)
    except ValueError as e:
        assert one_line(e).startswith("--mismatch")
        return
    names = [_checked(s).name for s in specs]
    assert len(set(names)) == len(names) == len(pieces)


# -- every env id: make kwargs and reset options -----------------------------------------------


def _num(lo, hi):
    """A float in [lo, hi], or an int there when there is one (an int is as good as a float)."""
    if math.ceil(lo) > hi:
        return st.floats(lo, hi)
    return st.one_of(st.floats(lo, hi), st.integers(int(math.ceil(lo)), int(hi)))


EDGE = st.one_of(
    st.sampled_from([0, -1, 0.0, -1e-9, 1e12, 1e300, math.nan, math.inf, -math.inf]), ANY
)
KWARGS = {  # a value near the defaults, else an edge or a value of any type
    "gait": st.sampled_from(["default", "paper", "literal-cycle", "nope"]),
    "gait_overrides": st.one_of(
        st.dictionaries(st.sampled_from(["kc", "kb", "zeta", "m1"]), _num(0.5, 400), max_size=2),
        st.dictionaries(st.text(max_size=3), ANY, max_size=1),
    ),
    "dt": _num(0.005, 0.02),
    "max_torque": _num(0, 200),
    "reset_noise_scale": _num(0, 1),
    "alive_reward": _num(-2, 2),
    "tracking_cost_weight": _num(0, 2),
    "ctrl_cost_weight": _num(0, 2),
    "apex_scales": st.lists(_num(0.01, 2), min_size=6, max_size=6),
    "exclude_current_positions_from_observation": st.booleans(),
    "rtol": st.sampled_from([1e-10, 1e-8, 1e-6]),
    "render_mode": st.sampled_from([None, "rgb_array", "human", "film"]),
    "width": st.integers(1, 64),
    "height": st.integers(1, 64),
    "slope_noise_deg": _num(0, 3),
    "config": st.none(),
    "basis": st.sampled_from(["windows", "phases", "hats", "stairs"]),
    "K": st.integers(1, 12),
    "controller": st.sampled_from(["lqr", "deadbeat", "damping", "lqr-of", "nope"]),
    "gain": st.none(),
    "safe": _num(0.01, 0.2),
    "r_min": _num(0, 0.2),
    "r_max": _num(0.1, 0.6),
    "axis_prob": _num(0, 1),
    "horizon": st.integers(1, 40),
    "shaping": _num(0, 2),
    "gamma": _num(0.5, 1),
    "action_mode": st.sampled_from(["direct", "lqr_residual", "other"]),
    "residual_scale": _num(0, 1),
    "terminate_at_horizon": st.booleans(),
}
ENV_IDS = sorted(i for i in gym.registry if i.startswith("PassiveBound"))


def _signature(env_id) -> list[str]:
    import inspect

    ep = gym.spec(env_id).entry_point
    mod, _, cls = ep.partition(":")
    init = getattr(importlib.import_module(mod), cls).__init__
    return [p for p in inspect.signature(init).parameters if p != "self"]


@st.composite
def make_kwargs(draw, env_id):
    names = [n for n in _signature(env_id) if n in KWARGS]
    chosen = draw(st.lists(st.sampled_from(names), max_size=3, unique=True))
    out = {}
    for n in chosen:
        if n == "render_mode":  # gymnasium's make reads it first (a non-string: its own error)
            out[n] = draw(st.one_of(KWARGS[n], st.none(), st.text(max_size=4)))
            continue
        out[n] = draw(st.one_of(KWARGS[n], KWARGS[n], EDGE))  # twice as often near the default
    if draw(st.integers(0, 9)) == 0:
        out["no_such_kwarg"] = 1
    return out


OPTIONS = st.one_of(
    st.none(),
    st.just({}),
    st.fixed_dictionaries(
        {"apex_state": st.one_of(st.just("z*"), st.lists(st.floats(allow_nan=True), max_size=7))}
    ),
    st.dictionaries(st.text(max_size=5), ANY, max_size=1),
    ANY,
)


@pytest.mark.parametrize("env_id", ENV_IDS)
@settings(max_examples=max(4, settings().max_examples // 2))
@given(data=st.data())
def test_every_env_makes_finite_steps_or_one_error(env_id, data):
    kwargs = data.draw(make_kwargs(env_id), label="kwargs")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            env = gym.make(env_id, **kwargs)
    except (ValueError, TypeError, FileNotFoundError) as e:  # no such gait file: its name
        one_line(e)
        return
    try:
        options = data.draw(OPTIONS, label="options")
        base = env.unwrapped
        if isinstance(options, dict) and options.get("apex_state") == "z*":
            options = {"apex_state": np.asarray(getattr(base, "z_ref", np.zeros(6)), float) * 1.2}
        try:
            obs, info = env.reset(seed=data.draw(st.integers(0, 2**32 - 1)), options=options)
        except (ValueError, TypeError) as e:
            one_line(e)
            return
        assert np.all(np.isfinite(obs)), (kwargs, options, obs)
        env.action_space.seed(0)
        for _ in range(3):
            obs, reward, term, trunc, info = env.step(env.action_space.sample())
            assert np.all(np.isfinite(obs)) and math.isfinite(float(reward)), (kwargs, obs, reward)
            if term or trunc:
                break
    finally:
        env.close()


# -- the scripts' arguments --------------------------------------------------------------------


def _script(name: str):
    path = ROOT / "scripts" / f"{name}.py"
    spec = importlib.util.spec_from_file_location(f"script_{name}", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


SCRIPTS = sorted(p.stem for p in (ROOT / "scripts").glob("*.py"))
TOKENS = st.one_of(
    st.sampled_from(["lqr", "passive", "nope", "", "ppo-v1", "-1", "0", "1", "2", "0.3", "1e9"]),
    st.sampled_from(["gain=0.5", "gain=abc", "estimator=x", "foo=1", "10", "0.99", "1.0"]),
    st.sampled_from(["nan", "inf", "-inf", "1e400", "12345", "4294967296", "x", "--json"]),
    st.text(max_size=5),
)


def _options(parser) -> list[str]:
    return [s for a in parser._actions for s in a.option_strings if s not in ("-h", "--help")]


@pytest.mark.parametrize("name", SCRIPTS)
@given(data=st.data())
def test_every_script_parses_arguments_to_one_error_or_a_namespace(name, data, capsys):
    mod = _script(name)
    if not hasattr(mod, "parser"):
        pytest.skip(f"scripts/{name}.py builds no parser() (issue 40: every Python script does)")
    p = mod.parser()
    words = data.draw(st.lists(st.one_of(st.sampled_from(_options(p)), TOKENS), max_size=6))
    try:
        args = p.parse_args(words)
    except SystemExit as e:
        text = capsys.readouterr().err.strip()
        assert e.code == 2 and ": error: " in text and "Traceback" not in text, text
        if not any("\n" in w for w in words):  # argparse echoes a token's own line breaks
            assert ": error: " in text.split("\n")[-1], text  # usage lines, then one error
        return
    capsys.readouterr()
    for key, value in vars(args).items():  # every number the parser gives is finite, in range
        for v in value if isinstance(value, list) else [value]:
            if isinstance(v, float):
                assert math.isfinite(v), (key, v)
            if key in RANGES and v is not None:  # None: not given (--table)
                lo, hi = RANGES[key]
                assert lo <= v <= hi, (key, v)


RANGES = {  # the documented range of each numeric option of the scripts
    "dirs": (1, 10_000),
    "workers": (1, 256),
    "seed": (0, 2**32 - 1),
    "table": (0, 2**32 - 1),
    "sizes": (5e-324, 1.0),  # > 0
    "delta": (0.0, 0.99),
    "robots": (1, 100_000),
    "strides": (10, 100_000),
    "plants": (1, 4096),
}


@settings(max_examples=max(3, settings().max_examples // 3))
@given(
    policies=st.lists(
        st.sampled_from(["lqr", "passive", "nope", "deadbeat"]), min_size=1, max_size=2
    ),
    sizes=st.lists(st.sampled_from(["0.001", "0.2", "0.4", "nan", "0", "-1", "2"]), max_size=2),
    dirs=st.sampled_from(["1", "2", "0", "x"]),
    seed=st.sampled_from(["0", "777", "12345", "-5"]),
)
def test_rescue_eval_gives_a_result_or_one_error(policies, sizes, dirs, seed, capsys):
    mod = _script("rescue_eval")
    argv = [*policies, "--dirs", dirs, "--seed", seed, "--json"]
    if sizes:
        argv += ["--sizes", *sizes]
    try:
        code = mod.main(argv)
    except SystemExit as e:
        code = e.code
    cap = capsys.readouterr()
    if code == 0:
        out = json.loads(cap.out)
        assert set(out) == set(policies)
        for r in out.values():
            assert all(x["n"] <= int(dirs) and 0 <= x["returned"] <= x["n"] for x in r["sizes"])
    else:
        err = cap.err.strip().split("\n")
        assert code == 2 and err and "Traceback" not in cap.err
        assert len(err) == 1 or ": error: " in err[-1], cap.err
