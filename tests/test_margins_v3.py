"""Margins v3: --seed (test set and held-out sets), per-direction outcomes and paired
statistics, the mean first-passage time on rough terrain, the complete cache key."""

from __future__ import annotations

import math
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import binomtest, chi2, lognorm

from agents.results.margins import POLICY_SOURCES, as_controller, policy_sources
from agents.runtime.controllers import MLPController, ZeroController
from bound_env.analysis import margins
from bound_env.analysis.margins import (
    BUDGETS,
    CURVE_SEED,
    DEFAULT_SEED,
    ClosedLoop,
    Setup,
    random_directions,
    rough_episodes,
    run_task,
    sample_seeds,
    setup_key,
)
from bound_env.analysis.margins.stats import crossing_on_grid, mfpt_crossing, mfpt_estimate
from bound_env.analysis.paired import (
    bootstrap_delta_x50,
    compare_paired,
    crossing,
    mcnemar_exact,
    paired_curve,
    sign_test,
)
from bound_env.control.spec import CONTROLLERS_DIR
from bound_env.model.params import GAITS_DIR, load_gait

Z_STAR = np.asarray(load_gait("default").z0, dtype=float)


def _setup(controller=None, budget="test", seed=DEFAULT_SEED, key="v3") -> Setup:
    return Setup(
        controller=controller or ZeroController(),
        gait="default",
        budget=BUDGETS[budget],
        z_star=Z_STAR,
        z_cl=Z_STAR,
        key=f"{key}-{seed}",
        period=0.39,
        seed=seed,
    )


# -- the seed ------------------------------------------------------------------------------------


def test_default_seed_is_the_old_test_set():
    assert DEFAULT_SEED == CURVE_SEED == 12345
    # the directions the code drew before --seed existed: default_rng(12345), normalized
    old = np.random.default_rng(12345).standard_normal((256, 6))
    old /= np.max(np.abs(old), axis=1, keepdims=True)
    assert np.array_equal(random_directions(256, seed=DEFAULT_SEED), old)
    assert np.array_equal(random_directions(256), old)
    # the old terrain seeds (20000 + k) and push key ([i, kind, 2024])
    assert sample_seeds(DEFAULT_SEED) == {
        "directions": 12345,
        "terrain": 20_000,
        "push": [2024],
        "mfpt": margins.MFPT_SEED,
    }
    # the quick budget's directions are the first of the test set's (MARGINS.md says so)
    q = BUDGETS["quick"].curve_dirs
    assert np.array_equal(random_directions(q), old[:q])


def test_cli_default_seed_is_the_test_set():
    from bound_env.commands.cli import build_parser

    parser = build_parser()
    for cmd in ("margins", "compare"):
        sub = parser._subparsers._group_actions[0].choices[cmd]
        assert sub.parse_args([]).seed == DEFAULT_SEED, cmd
        assert sub.parse_args(["--seed", "7"]).seed == 7


def test_another_seed_draws_other_samples():
    s7 = sample_seeds(7)
    d = sample_seeds(DEFAULT_SEED)
    assert s7["directions"] == 7 and not np.array_equal(
        random_directions(32, 7), random_directions(32)
    )
    assert s7["terrain"] != d["terrain"] and s7["mfpt"] != d["mfpt"] and s7["push"] != d["push"]
    assert sample_seeds(7) == s7  # deterministic
    for bad in (-1, 2**32, 1.5, True, "3"):
        with pytest.raises(ValueError, match="--seed"):
            sample_seeds(bad)


def test_curve_task_keeps_per_direction_outcomes_of_its_seed():
    a = run_task(_setup(), "curve", (0.02,))
    b = run_task(_setup(seed=7), "curve", (0.02,))
    for r in (a, b):
        assert len(r["outcomes"]) == r["n"] == BUDGETS["test"].curve_dirs
        assert sum(r["outcomes"]) == r["k"] and set(r["outcomes"]) <= {0, 1}
    # passive at r = 0.02 (twice its r50): the loop's outcome depends on the direction, and
    # the direction on the seed: the same task, run by hand on seed 7's directions
    loop = ClosedLoop(ZeroController(), "default")
    dirs = random_directions(BUDGETS["test"].curve_dirs, 7)
    want = [int(loop.run(Z_STAR + 0.02 * np.abs(Z_STAR) * u, Z_STAR, 40)[0]) for u in dirs]
    assert b["outcomes"] == want


# -- rough terrain: batched episodes and the MFPT ----------------------------------------------


@pytest.mark.parametrize("name", ["passive", "lqr"])
def test_batched_rough_episodes_are_the_single_env_episodes(name):
    ctrl = as_controller(name, "default")  # passive: batch(); lqr: copies with on_apex
    loop = ClosedLoop(ctrl, "default", None, {"slope_noise_deg": 0.6})
    seeds = [11, 12, 13, 14, 15]
    got = rough_episodes(loop, loop.env.z_ref, seeds, 40)
    want = [loop.episode(loop.env.z_ref, 40, seed=s) for s in seeds]
    assert got["strides"] == [w[1] for w in want]
    assert got["fell"] == [int(not w[0]) for w in want]
    assert sum(got["failures"].values()) == sum(got["fell"])
    assert any(got["fell"]) or name == "lqr"  # sigma 0.6 fells the passive gait


def test_mfpt_estimate_known_cases():
    e = mfpt_estimate(400, 4)
    assert e["mfpt"] == 100.0 and not e["lower_bound"]
    lo, hi = e["ci"]
    assert lo == pytest.approx(800 / chi2.ppf(0.975, 10)) and hi == pytest.approx(
        800 / chi2.ppf(0.025, 8)
    )
    assert lo < 100 < hi
    z = mfpt_estimate(1000, 0)  # no fall: a lower bound, the 'rule of 3.7' interval
    assert z["lower_bound"] and z["mfpt"] == 1000 and z["ci"][1] is None
    assert z["ci"][0] == pytest.approx(1000 / 3.6889, rel=1e-4)
    with pytest.raises(ValueError):
        mfpt_estimate(5, 6)


def test_mfpt_estimate_recovers_a_known_hazard_under_censoring():
    # 400 robots per experiment, per-stride fall probability 1/100, censored at 150 strides:
    # a quarter of the runs never fall, and the censored estimate still finds the mean
    # first-passage time of 100 strides; its 95 % interval covers it in ~95 % of experiments
    rng = np.random.default_rng(0)
    est, covered, naive = [], 0, []
    for _ in range(200):
        first = rng.geometric(0.01, size=400)  # the stride in which each robot falls
        fell = first <= 150
        e = mfpt_estimate(int(np.where(fell, first, 150).sum()), int(fell.sum()))
        est.append(e["mfpt"])
        covered += e["ci"][0] <= 100 <= e["ci"][1]
        naive.append(first[fell].mean())  # ignoring the censored runs
    assert np.mean(est) == pytest.approx(100, rel=0.03)
    assert 0.9 <= covered / 200 <= 0.99
    assert np.mean(naive) < 70  # biased low without the censoring


def test_mfpt_crossing_log_log_and_unbracketed_curves():
    # 400 -> 25 from sigma 0.2 to 0.4 falls through 100 halfway in log: sigma sqrt(0.08)
    s = mfpt_crossing([0.1, 0.2, 0.4], [1000.0, 400.0, 25.0], [True, False, False])
    assert s == pytest.approx(math.sqrt(0.2 * 0.4))
    assert mfpt_crossing([0.1, 0.2], [50.0, 20.0], [False, False]) is None  # below at once
    assert mfpt_crossing([0.1, 0.2], [5000.0, 800.0], [True, False]) is None  # never below
    # a zero-failure point whose bound is below 100 says nothing: undetermined, no crossing
    assert mfpt_crossing([0.1, 0.2, 0.4], [40.0, 30.0, 10.0], [True, True, False]) is None


def test_mfpt_task_and_curve():
    setup = _setup()
    b = setup.budget
    res = {("mfpt", (v, 0)): run_task(setup, "mfpt", (v, 0)) for v in b.mfpt_sigmas}
    for r in res.values():
        assert r["robots"] == b.mfpt_robots == len(r["strides"]) == len(r["fell"])
        assert all(0 <= n <= b.mfpt_strides for n in r["strides"])
        assert all(
            n == b.mfpt_strides for n, f in zip(r["strides"], r["fell"], strict=True) if not f
        )
    curve = margins.mfpt_curve(b, res)
    for m, v in zip(curve, b.mfpt_sigmas, strict=True):
        r = res[("mfpt", (v, 0))]
        assert m["strides_total"] == sum(r["strides"]) + sum(r["fell"])
        assert m["failures"] == sum(r["fell"])
        assert m["lower_bound"] == (m["failures"] == 0)
    assert curve[-1]["failures"] == b.mfpt_robots  # 2 deg of slope noise fells every robot


# -- paired statistics ---------------------------------------------------------------------------


def test_mcnemar_exact_known_case():
    a = [1] * 7 + [0] * 2 + [1] * 20 + [0] * 11  # 7 directions only a returns, 2 only b
    b = [0] * 7 + [1] * 2 + [1] * 20 + [0] * 11
    m = mcnemar_exact(a, b)
    assert (m["b"], m["c"]) == (7, 2)
    assert m["p"] == pytest.approx(binomtest(7, 9, 0.5).pvalue)
    assert m["p"] == pytest.approx(92 / 512)  # 2 P(X >= 7), X ~ Bin(9, 1/2)
    assert m["delta"] == pytest.approx(5 / 40)
    assert sign_test([0.5, -0.25, 0, 1])["n_pos"] == 2
    with pytest.raises(ValueError):
        mcnemar_exact([0, 1], [1])
    with pytest.raises(ValueError):
        mcnemar_exact([0, 2], [1, 1])


def test_identical_columns_differ_by_nothing():
    rng = np.random.default_rng(3)
    sizes = [0.01, 0.03, 0.1, 0.3]
    x = (rng.random((4, 64)) < np.array([[0.95], [0.7], [0.4], [0.1]])).astype(float)
    for row in paired_curve(sizes, x, x):
        assert row["delta"] == 0 and row["p"] == 1.0
    d = bootstrap_delta_x50(sizes, x, x, n_boot=300)
    assert d["delta"] == d["low"] == d["high"] == 0.0
    assert not compare_paired(sizes, x, x, n_boot=300)["stands_out"]


def test_crossing_is_the_grid_crossing_of_the_margins_stats():
    rng = np.random.default_rng(5)
    xs = [0.01, 0.02, 0.05, 0.1, 0.2, 0.5]
    rates = np.sort(rng.random((200, 6)), axis=1)[:, ::-1]
    rates[:20] = 0.9  # never below
    rates[20:40, 0] = 0.3  # below at once
    got = crossing(xs, rates)
    want = [crossing_on_grid(xs, list(r)) for r in rates]
    assert got == pytest.approx(want, rel=1e-12, abs=0)


def _synthetic(rng, sizes, n_dirs, factor):
    """Outcomes of two loops on the same directions: direction d returns up to its own
    threshold t_d (lognormal), the column's thresholds ``factor`` times the reference's."""
    t = lognorm.rvs(0.6, scale=0.1, size=n_dirs, random_state=rng)
    s = np.asarray(sizes)[:, None]
    return (s <= factor * t).astype(float), (s <= t).astype(float)


def test_bootstrap_interval_covers_a_known_difference():
    sizes = [0.02, 0.04, 0.06, 0.08, 0.1, 0.13, 0.17, 0.22, 0.3]
    # the population curves P(t > r), crossed on the same grid: the true Delta r50
    true = crossing(sizes, lognorm.sf(np.array(sizes) / 1.3, 0.6, scale=0.1)) - crossing(
        sizes, lognorm.sf(np.array(sizes), 0.6, scale=0.1)
    )
    rng = np.random.default_rng(11)
    covered, excludes_zero, trials = 0, 0, 40
    for _ in range(trials):
        a, b = _synthetic(rng, sizes, 256, 1.3)
        d = bootstrap_delta_x50(sizes, a, b, n_boot=400, seed=int(rng.integers(1 << 30)))
        covered += d["low"] <= true <= d["high"]
        excludes_zero += d["low"] > 0
    assert covered >= 0.85 * trials  # a 95 % interval, up to the grid's interpolation
    assert excludes_zero >= 0.9 * trials  # a 30 % wider basin is seen on 256 directions
    a, b = _synthetic(np.random.default_rng(2), sizes, 256, 1.3)
    res = compare_paired(sizes, a, b, n_boot=400)
    assert res["stands_out"] and all(p < 0.05 for p in res["p_around_r50"])
    # with no effect, the interval covers 0 in most trials
    zero = 0
    for _ in range(20):
        a, _ = _synthetic(rng, sizes, 256, 1.0)
        b2, _ = _synthetic(rng, sizes, 256, 1.0)
        d = bootstrap_delta_x50(sizes, a, b2, n_boot=300)
        zero += d["low"] <= 0 <= d["high"]
    assert zero >= 17


def test_seeds_are_resampled_too():
    sizes = [0.02, 0.05, 0.1, 0.2, 0.4]
    rng = np.random.default_rng(4)
    a1, b = _synthetic(rng, sizes, 128, 1.2)
    one = bootstrap_delta_x50(sizes, a1, b, n_boot=300)
    three = bootstrap_delta_x50(sizes, np.stack([a1, a1, a1]), b, n_boot=300)
    assert one["resampled"] == "directions" and three["resampled"] == "directions and seeds"
    assert three["delta"] == pytest.approx(one["delta"])  # identical seeds: the same column
    a2, _ = _synthetic(rng, sizes, 128, 0.9)  # a seed that is worse
    spread = bootstrap_delta_x50(sizes, np.stack([a1, a2]), b, n_boot=300)
    assert spread["high"] - spread["low"] > one["high"] - one["low"]
    with pytest.raises(ValueError, match="pair"):
        paired_curve(sizes, a1[:, :10], b)


def test_compare_pairs_each_column_with_lqr_and_trained_ones_with_mpc(tmp_path):
    from agents.results.compare import _provenance, paired_comparisons, paired_text

    sizes = [0.02, 0.05, 0.1, 0.2, 0.4]
    rng = np.random.default_rng(8)
    good, ref = _synthetic(rng, sizes, 96, 1.5)

    def run(outcomes):
        return {
            "basin_curve": {
                "sizes": sizes,
                "directions": 96,
                "direction_seed": DEFAULT_SEED,
                "outcomes": outcomes.astype(int).tolist(),
            }
        }

    trained = tmp_path / "s0"
    trained.mkdir()
    (trained / "run.json").write_text("{}")
    groups = [
        {"label": "lqr", "gait": "default", "policies": ["lqr"], "runs": [run(ref)]},
        {"label": "mpc", "gait": "default", "policies": ["mpc"], "runs": [run(ref)]},
        {"label": "learned", "gait": "default", "policies": [str(trained)], "runs": [run(good)]},
        {"label": "lit", "gait": "literal-cycle", "policies": ["passive"], "runs": [run(ref)]},
    ]
    pairs = paired_comparisons(groups, n_boot=300)
    made = {(p["column"], p["reference"]) for p in pairs if "skipped" not in p}
    assert made == {("mpc", "lqr"), ("learned", "lqr"), ("learned", "mpc")}
    skipped = [p for p in pairs if "skipped" in p]
    assert [p["column"] for p in skipped] == ["lit"]
    learned = next(p for p in pairs if p["column"] == "learned" and p["reference"] == "lqr")
    assert learned["stands_out"] and learned["delta_r50"]["low"] > 0
    text = paired_text(pairs)
    assert "**learned** vs lqr" in text and "stands out of the noise** (better)" in text
    assert "within the noise" in text  # mpc vs lqr: identical outcomes
    # the classical columns say how they were chosen
    lqr_text = " ".join(_provenance({"policies": ["lqr"]}))
    assert "chosen on the validation seed 777" in lqr_text and "no selection" not in lqr_text


# -- the cache key -------------------------------------------------------------------------------


def test_cache_key_has_every_ingredient(tmp_path, monkeypatch):
    c = ZeroController()
    q = BUDGETS["quick"]
    k0 = setup_key(c, "default", q)
    assert setup_key(c, "default", q) == k0  # deterministic
    assert "version" not in margins.SETTINGS  # a source hash, not a hand-kept number
    # the seed
    assert setup_key(c, "default", q, seed=7) != k0
    assert setup_key(c, "default", q, seed=DEFAULT_SEED) == k0
    # budget fields, including the MFPT's
    assert setup_key(c, "default", replace(q, mfpt_strides=q.mfpt_strides + 1)) != k0
    # module constants: push seed, ceiling search, profile span are in SETTINGS
    assert margins.SETTINGS["push_seed"] == margins.PUSH_SEED
    assert margins.SETTINGS["ceiling_es"] == margins.CEILING_ES
    assert margins.SETTINGS["profile_span"] == margins.PROFILE_SPAN == 1.3
    assert margins.SETTINGS["mfpt_seed"] == margins.MFPT_SEED
    for key, value in (("push_seed", 2025), ("profile_span", 1.4), ("return_tol", 1e-5)):
        with monkeypatch.context() as m:
            m.setitem(margins.SETTINGS, key, value)
            assert setup_key(c, "default", q) != k0, key
    with monkeypatch.context() as m:
        m.setitem(margins.CEILING_ES, "mutate", 0.31)
        assert setup_key(c, "default", q) != k0
    # the gait file's contents, not only its name
    gait = tmp_path / "g.yaml"
    shutil.copyfile(GAITS_DIR / "default.yaml", gait)
    kg = setup_key(c, gait, q)
    gait.write_text(gait.read_text().replace("kc: 295.0", "kc: 296.0"))
    assert setup_key(c, gait, q) != kg


def test_cache_key_follows_the_source(tmp_path, monkeypatch):
    from bound_env.analysis.margins import run as margins_run

    files = margins_run.source_files()
    names = {str(f) for f in files}
    import bound_env

    pkg = Path(bound_env.__file__).resolve().parent
    assert {str(p) for p in pkg.rglob("*.py")} == names  # the core hashes its own sources
    assert any(f.name == "run.py" and f.parent.name == "margins" for f in files)
    c = ZeroController()
    q = BUDGETS["quick"]
    k0 = setup_key(c, "default", q)
    # the agents code a controller runs is in the key through its code closure, object by
    # object (`code_closure`), not as whole files: the front names none
    assert policy_sources(c) == []
    assert {"runtime/policy.py", "runtime/controllers.py", "common/mlp.py"} <= set(POLICY_SOURCES)
    from bound_env.analysis.margins.provenance import code_closure

    mlp = (Path(code_closure.ROOT) / "agents" / "common" / "mlp.py").resolve()
    real = code_closure.read_source
    edited = real(mlp).replace("h = act(affine(h, W, b))", "h = act(affine(h, 0.9 * W, b))")
    assert edited != real(mlp)
    monkeypatch.setattr(
        code_closure, "read_source", lambda p: edited if Path(p).resolve() == mlp else real(p)
    )
    assert setup_key(c, "default", q) == k0  # the zero controller runs no MLP
    monkeypatch.undo()
    own = tmp_path / "own.py"
    own.write_text("GAIN = 1\n")
    k_own = setup_key(c, "default", q, extra_sources=[own])
    assert k_own != k0
    own.write_text("GAIN = 2\n")
    assert setup_key(c, "default", q, extra_sources=[own]) != k_own
    # a copy of the sources; editing the simulator's integrator changes the key
    copies = []
    for f in files:
        dst = tmp_path / f.parent.name / f.name
        dst.parent.mkdir(exist_ok=True)
        if not dst.exists():
            shutil.copyfile(f, dst)
        copies.append(dst)
    from bound_env.analysis.margins import keys

    monkeypatch.setattr(keys, "source_files", lambda extra=(): copies + list(extra))
    k0 = setup_key(c, "default", q)
    fast = tmp_path / "model" / "fast.py"
    fast.write_text(fast.read_text() + "\n# a comment\n")
    assert setup_key(c, "default", q) == k0  # a comment is no code
    fast.write_text(fast.read_text() + "\nA_CHANGE = 1\n")
    assert setup_key(c, "default", q) != k0


def test_cache_key_follows_controller_spec_and_policy_weights(tmp_path):
    from bound_env.control import load_controller as load_classical

    q = BUDGETS["quick"]
    spec = tmp_path / "lqr2.yaml"
    shutil.copyfile(CONTROLLERS_DIR / "lqr.yaml", spec)
    k_spec = setup_key(load_classical(spec), "default", q)
    assert policy_sources(load_classical(spec)) == []  # bound_env's: hashed by the core
    text = spec.read_text()
    # the shipped spec stores its gain: a changed gain changes the key
    spec.write_text(text.replace("- [9.33", "- [9.34", 1))
    assert setup_key(load_classical(spec), "default", q) != k_spec
    # without the stored gain the spec is designed from Q, R: a changed R changes the key
    designed = text[: text.index("\ngain:")] + "\n"
    spec.write_text(designed)
    k_designed = setup_key(load_classical(spec), "default", q)
    spec.write_text(designed.replace("R: 0.1", "R: 0.2"))
    assert setup_key(load_classical(spec), "default", q) != k_designed
    rng = np.random.default_rng(0)
    layers = [(rng.normal(size=(4, 3)), rng.normal(size=4)), (rng.normal(size=(1, 4)), np.zeros(1))]
    mlp = MLPController("m", layers, "Tanh", env_kwargs={"max_torque": 80.0})
    k_mlp = setup_key(mlp, "default", q)
    assert setup_key(replace(mlp, activation="ReLU"), "default", q) != k_mlp
    w = [(W.copy(), b.copy()) for W, b in layers]
    w[0][0][0, 0] += 1e-9
    assert setup_key(replace(mlp, layers=w), "default", q) != k_mlp
    assert setup_key(replace(mlp, env_kwargs={"max_torque": 40.0}), "default", q) != k_mlp


def test_selected_shipped_policies_state_their_validation_directions():
    """A checkpoint chosen by BasinValidationCallback says which directions chose it."""
    import json

    import yaml

    from agents.runtime.policy import SHIPPED_DIR
    from agents.runtime.policy_table import ARCHIVE_DIR

    checked = 0  # the selected checkpoint ppo-v1 is archived now: its folder is checked there
    for folder in sorted([*SHIPPED_DIR.iterdir(), *ARCHIVE_DIR.iterdir()]):
        exp = folder / "exported.json"
        if not exp.is_file() or "timesteps" not in json.loads(exp.read_text()):
            continue  # a final model: nothing was selected
        cfg = yaml.safe_load((folder / "config.yaml").read_text())
        callbacks = next(iter(cfg.values()))["callback"]
        entry = next(c for c in callbacks if "BasinValidationCallback" in str(c))
        kwargs = next(iter(entry.values()))
        assert "directions" in kwargs or "direction_seed" in kwargs, folder.name
        # the stated directions build (as the callback builds them) ...
        from agents.training.train_callbacks import BasinValidationCallback

        dirs = BasinValidationCallback(**kwargs).validation_directions()
        assert dirs.shape[1] == 6 and np.allclose(np.max(np.abs(dirs), axis=1), 1.0)
        # ... and the exported checkpoint is the one they chose: the best validation score
        # of the run, at the exported timesteps
        exp_data = json.loads(exp.read_text())
        rows = np.genfromtxt(folder / "basin_validation.csv", delimiter=",", names=True)
        best = int(np.argmax(rows["basin_min"]))
        assert rows["timesteps"][best] == exp_data["timesteps"], folder.name
        assert rows["basin_min"][best] == pytest.approx(exp_data["basin_validation"], rel=1e-12)
        checked += 1
    assert checked >= 1
