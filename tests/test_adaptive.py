"""The privileged reference (bound_env.control.privileged) and the classical adaptive controller
(bound_env.control.adaptive, identify, plant_design): the plant's own cycle found and held, the
plant handed only to a privileged controller, identification converging on a known plant, the
estimate reset per episode, nothing spent on the nominal cycle, and bad specs refused."""

from dataclasses import replace

import numpy as np
import pytest

from bound_env.control import load_controller
from bound_env.control.adaptive import AdaptiveMPC, check_adaptive
from bound_env.control.identify import PlantIdentifier
from bound_env.control.plant_design import plant_overrides
from bound_env.control.privileged import PrivilegedMPC, is_privileged
from bound_env.model.dynamics import make_aux
from bound_env.model.mismatch import EIGHT, sample_plant_params
from bound_env.model.params import load_gait
from bound_env.sim.stride_map import EVAL_RTOL, StrideMap
from bound_env.sim.stride_protocol import reset_controller

NOMINAL = load_gait("default").params
Z_STAR = load_gait("default").z0
# a plant 4-6 % off the nominal one with a passive cycle near z* (checked below)
PLANT = replace(NOMINAL, m1=NOMINAL.m1 * 1.04, I2=NOMINAL.I2 * 0.95, zeta=NOMINAL.zeta * 1.06)


@pytest.fixture(scope="module")
def mpc():
    return load_controller("mpc")


@pytest.fixture(scope="module")
def privileged():
    return PrivilegedMPC()


@pytest.fixture(scope="module")
def nominal_map():
    return StrideMap("default", None, 0.01, 80.0, EVAL_RTOL)


def loop(ctrl, sm, strides, params=None, z0=Z_STAR):
    """One robot from z0 through the stride map on ``params`` (the step protocol's apex
    decisions, ``on_apex``, and the interval actions they chose): (apex states, efforts)."""
    aux = None if params is None else make_aux(params.to_array())[None]
    z, zs, eff = np.array(z0, dtype=float), [], []
    reset_controller(ctrl)
    for _ in range(strides):
        ctrl.on_apex(z, 0.0)
        r = sm.run(z[None], ctrl.interval_actions(z[None]) if hasattr(ctrl, "interval_actions")
                   else ctrl.last_actions[None], aux=aux)  # fmt: skip
        if not r.ok[0]:
            break
        z = r.z1[0]
        zs.append(z)
        eff.append(float(r.effort[0]))
    return np.array(zs), np.array(eff)


# -- the privileged reference -------------------------------------------------------------------


def test_the_privileged_reference_is_marked_and_nominal_is_mpc(mpc, privileged):
    assert privileged.privileged is True and is_privileged(privileged)
    assert not is_privileged(mpc) and not is_privileged(AdaptiveMPC())
    assert load_controller("mpc-privileged").privileged is True
    # without a plant, or on the nominal one, it is the shipped mpc
    z = Z_STAR + np.array([0.004, 0.0, 0.0, 0.03, 0.2, 0.0])
    for plant in (None, NOMINAL, {"m1": NOMINAL.m1}):
        assert privileged.set_plant(plant) is None and privileged.mpc is privileged.base
        assert np.array_equal(privileged.plan(z), mpc.plan(z))
    assert privileged.fingerprint() != mpc.fingerprint()


def test_the_privileged_reference_aims_at_the_plants_own_cycle(privileged):
    d = privileged.set_plant(PLANT)
    try:
        assert d.cycle == "passive" and np.all(d.u_ref == 0.0)
        sm = StrideMap("default", plant_overrides(PLANT), 0.01, 80.0, EVAL_RTOL)
        z1 = sm.map(d.z_ref, np.zeros(1))
        assert np.max(np.abs(z1 - d.z_ref)) < 1e-8  # a cycle of the plant, not of the model
        assert np.max(np.abs(d.z_ref - Z_STAR) / privileged.designer.scales) > 0.05
        assert privileged.z_ref is privileged.mpc.lqr.z_ref
        # held from the nominal z* on the plant, it spends nothing once there
        zs, eff = loop(privileged, StrideMap("default", None, 0.01, 80.0, EVAL_RTOL), 40, PLANT)
        assert len(zs) == 40 and eff[-1] < 1e-6
        assert np.max(np.abs(zs[-1] - d.z_ref)) < 1e-6
    finally:
        privileged.set_plant(None)


def test_a_plant_without_a_passive_cycle_gets_the_least_torque_cycle(privileged):
    # pm5's plant 0 of the validation seed: its passive cycle ends in a fold near z*
    from bound_env.analysis.margins.model_error.mismatch_tasks import mismatch_seeds

    p = sample_plant_params("pm5", 1, mismatch_seeds(777)["plants"], NOMINAL)[0]
    d = privileged.set_plant(p)
    try:
        assert d.cycle == "forced" and np.abs(d.u_ref).max() > 0.0
        sm = StrideMap("default", plant_overrides(p), 0.01, 80.0, EVAL_RTOL)
        W = privileged.designer.W
        assert np.max(np.abs(sm.map(d.z_ref, W @ d.u_ref) - d.z_ref)) < 1e-8
        mean_tau = float(np.abs(privileged.basis.torques(d.u_ref, 80.0)).mean())
        assert mean_tau < 2.0  # far less than holding the nominal z* costs there (~12 N m)
    finally:
        privileged.set_plant(None)


def test_plant_overrides_refuse_bad_plants():
    assert plant_overrides(NOMINAL) == {}
    assert plant_overrides({"kc": 300.0}) == {"kc": 300.0}
    for bad, word in (
        ({"mass": 1.0}, "unknown parameter 'mass'"),
        ({"m1": -1.0}, "m1 must be finite and > 0"),
        ({"m1": float("nan")}, "m1 must be finite"),
        ({"m1": "10"}, "m1 must be a number"),
        ([1.0], "must be a bound_env.params.Params or a mapping"),
    ):
        with pytest.raises(ValueError, match=word):
            plant_overrides(bad)


def test_the_model_error_loop_hands_the_plant_to_privileged_controllers_only():
    from bound_env.analysis.margins import Setup, as_budget
    from bound_env.analysis.margins.model_error.mismatch_tasks import MismatchBudget, task_mm_hold
    from bound_env.model.mismatch import as_spec

    seen = []

    class Recorder(PrivilegedMPC):
        def set_plant(self, plant):
            seen.append((self.privileged, plant))
            return super().set_plant(plant)

    mb = MismatchBudget("t", 2, 3, 1, (), 3, (), 0, 0)
    for privileged, key in ((True, "a"), (False, "b")):
        ctrl = Recorder()
        ctrl.privileged = privileged
        setup = Setup(
            controller=ctrl, gait="default", budget=as_budget("test"), z_star=Z_STAR,
            key=f"test-privileged-{key}", seed=777, mismatch=as_spec("pm5"), mismatch_budget=mb,
        )  # fmt: skip
        task_mm_hold(setup)
    assert len(seen) == 2 and all(p is True for p, _ in seen)
    assert seen[0][1] != seen[1][1] and seen[0][1].m1 != NOMINAL.m1  # each robot's own plant


# -- identification -----------------------------------------------------------------------------


def test_identification_converges_on_a_known_plant(privileged, nominal_map):
    """Noise-free strides of a plant 4-6 % off, each from a start near z* under a random
    torque profile (an excitation): the eight factors within 1e-3 of the truth."""
    ident = PlantIdentifier()
    rng = np.random.default_rng(5)
    scales = privileged.designer.scales
    Z = Z_STAR + 0.05 * scales * rng.uniform(-1.0, 1.0, (6, 6))
    A = rng.uniform(-0.3, 0.3, (6, 8)) @ privileged.designer.W.T
    r = nominal_map.run(Z, A, aux=np.tile(make_aux(PLANT.to_array()), (6, 1)))
    assert r.ok.all()
    fit = ident.fit(Z, A, r.z1, None, 10, search=4)
    true = np.array([getattr(PLANT, k) / getattr(NOMINAL, k) for k in EIGHT])
    assert np.max(np.abs(np.exp(fit.theta) - true)) < 1e-3
    assert fit.rms < 1e-4 and fit.transitions == 6
    assert np.max(fit.std) < 0.02  # the posterior is narrow
    # the nominal plant's own strides leave the estimate at nominal
    r0 = nominal_map.run(Z, A)
    assert np.max(np.abs(ident.fit(Z, A, r0.z1).theta)) < 1e-5


# -- the adaptive controller --------------------------------------------------------------------


def test_adaptive_is_mpc_on_the_nominal_cycle(mpc, nominal_map):
    ctrl = AdaptiveMPC()
    assert ctrl.stateful and not ctrl.privileged and not hasattr(ctrl, "interval_actions")
    z = Z_STAR.copy()
    for _ in range(20):
        u = ctrl.stride_action(z)
        assert np.array_equal(u, mpc.plan(z))
        r = nominal_map.run(z[None], ctrl.last_actions[None])
        assert r.ok[0] and float(r.effort[0]) <= 1e-6  # nothing spent on the nominal cycle
        z = r.z1[0]
    assert np.all(ctrl.theta == 0.0) and ctrl.mpc is ctrl.base and ctrl.strides == 19


def test_adaptive_identifies_holds_and_resets_per_episode(privileged, nominal_map):
    ctrl = AdaptiveMPC()
    aux = make_aux(PLANT.to_array())[None]
    z = Z_STAR.copy()
    for _ in range(30):  # the fit and the design spread over the decisions
        u = ctrl.stride_action(z)
        r = nominal_map.run(z[None], ctrl.last_actions[None], aux=aux)
        assert r.ok[0]
        z = r.z1[0]
    # the estimate predicts the strides (it is refined until they are within `settle`), and
    # aims at (nearly) the true plant's own passive cycle, where it spends little
    assert ctrl.trusted and ctrl.design.cycle == "passive" and ctrl.mpc is not ctrl.base
    assert max(ctrl.innovations[-3:]) <= ctrl.config["settle"]
    true_cycle = privileged.designer.design(PLANT).z_ref
    scales = privileged.designer.scales
    off = np.max(np.abs(ctrl.z_ref - true_cycle) / scales)
    assert off < 0.25 * np.max(np.abs(true_cycle - Z_STAR) / scales)  # far nearer than z*
    assert float(r.effort[0]) < 0.5
    del u
    reset_controller(ctrl)  # the loops' per-episode reset
    assert np.all(ctrl.theta == 0.0) and ctrl.strides == 0 and ctrl.mpc is ctrl.base
    assert ctrl.fit is None and not ctrl.trusted and ctrl.design is None


def test_adaptive_settings_are_checked():
    assert check_adaptive(True, "f")["window"] == 10 and check_adaptive(False, "f") is None
    for bad, word in (
        ({"windows": 3}, "unknown key 'windows' in adaptive"),
        ({"window": 0}, "adaptive.window must be an integer"),
        ({"prior": -1.0}, "adaptive.prior"),
        ({"trust_error": "x"}, "adaptive.trust_error must be a number"),
        ([1], "adaptive must be true or a mapping"),
    ):
        with pytest.raises(ValueError, match=word):
            check_adaptive(bad, "f.yaml")
    with pytest.raises(ValueError, match="window"):
        AdaptiveMPC(window=0)


def test_specs_refuse_bad_privileged_and_adaptive_blocks(tmp_path):
    from bound_env.control.spec import CONTROLLERS_DIR, load_spec

    base = (CONTROLLERS_DIR / "mpc.yaml").read_text()
    for extra, word in (
        ("privileged: yes please\n", "privileged must be true or false"),
        ("privileged: true\nadaptive: true\n", "exclude each other"),
        ("adaptive: {window: -2}\n", "adaptive.window"),
    ):
        f = tmp_path / "x.yaml"
        f.write_text(base + extra)
        with pytest.raises(ValueError, match=word):
            load_spec(f)
    f = tmp_path / "l.yaml"
    f.write_text((CONTROLLERS_DIR / "lqr.yaml").read_text() + "privileged: true\n")
    with pytest.raises(ValueError, match="unknown key 'privileged' for a lqr controller"):
        load_spec(f)


# -- never shipped or deployed; marked where it is shown --------------------------------------


def test_the_privileged_reference_is_refused_where_a_policy_is_shipped_or_deployed():
    from agents.results.demo import compare_from_start
    from agents.runtime.policy import load_controller as load_policy_controller
    from agents.runtime.policy_table import ALIASES
    from agents.runtime.residual import load_base

    with pytest.raises(ValueError, match="privileged: it reads the robot's true plant"):
        load_base("mpc-privileged")  # no residual policy (trained, exported) on top of it
    with pytest.raises(ValueError, match="cannot be shown as the demo's controller"):
        compare_from_start("mpc-privileged")
    for alias in ALIASES:  # `default` and every alias name a deployable policy
        assert not is_privileged(load_policy_controller(alias))
    assert load_base("mpc") is not None  # the refusal is the privileged one's only


def test_plain_policy_hands_the_plant_to_a_privileged_controller_only():
    import gymnasium as gym

    import bound_env
    from bound_env.control import PlainPolicy
    from bound_env.envs.wrappers import RandomizedPlant

    gym.register_envs(bound_env)
    env = RandomizedPlant(gym.make("PassiveBound-v1"), mismatch="pm5")
    obs, info = env.reset(seed=3)
    ctrl = PrivilegedMPC()
    act = PlainPolicy(ctrl)
    act(obs, info)
    assert ctrl.plant == plant_overrides(info["plant"]) and ctrl.plant  # the drawn plant
    adaptive = AdaptiveMPC()
    PlainPolicy(adaptive)(obs, info)
    assert adaptive.mpc is adaptive.base and adaptive.strides == 0  # never told the plant
    env.close()


def test_model_error_tables_mark_privileged_columns_and_censored_r50():
    from bound_env.analysis.margins.model_error.mismatch_report import mismatch_markdown, r50_text

    def block(privileged, success):
        sizes = [0.01, 0.1, 0.4]
        n = 4
        curve = [
            {"size": s, "outcomes": [int(i < round(p * n)) for i in range(n)], "success": p,
             "ci_low": max(0.0, p - 0.3), "ci_high": min(1.0, p + 0.3)}
            for s, p in zip(sizes, success, strict=True)
        ]  # fmt: skip
        from bound_env.analysis.margins.stats import crossing_on_grid

        return {
            "spec": {"name": "pm10", "params": {"m1": 0.1}, "noise": {}, "delay": 0},
            "privileged": privileged,
            "seeds": {"plants": 1, "noise": 2},
            "budget": {"plants": n},
            "plants": [{}] * n,
            "hold": {"strides": 20, "k": 2, "n": n, "ci": [0.1, 0.9], "outcomes": [1, 1, 0, 0],
                     "effort_strides": 5, "effort_median": 1.0, "effort_median_ci": [0.5, 2]},
            "curve": curve,
            "curve_strides": 20,
            "r50": crossing_on_grid(sizes, success),
            "r50_ci": [crossing_on_grid(sizes, [c["ci_low"] for c in curve]),
                       crossing_on_grid(sizes, [c["ci_high"] for c in curve])],
            "mfpt": [],
        }  # fmt: skip

    floor = block(False, [0.25, 0.0, 0.0])  # fails already at the smallest size
    top = block(True, [1.0, 1.0, 1.0])  # never fails
    assert r50_text(floor).startswith("< 0.01 [< 0.01, ")
    assert r50_text(top) == "> 0.4 [> 0.4, > 0.4]"
    md = mismatch_markdown({"lqr": floor, "mpc-privileged": top, "lqr2": floor}, specs=("pm10",))
    assert "| mpc-privileged (**privileged**: reads the true plant) |" in md
    assert "| lqr |" in md and "0 [0, 0]" not in md
    assert "≥ +0.4 (r50 > 0.4, ref r50 < 0.01)" in md  # a bound, not a bootstrapped number
    assert "both r50 < 0.01: no difference measured" in md


def test_censored_crossings_are_named():
    from bound_env.analysis.margins.stats import crossing_censored, x50_text
    from bound_env.analysis.paired import bootstrap_delta_x50, censored, delta_text

    xs = [0.01, 0.1, 0.4]
    assert crossing_censored(xs, [0.2, 0.1, 0.0]) == "below"
    assert crossing_censored(xs, [0.9, 0.8, 0.6]) == "above"
    assert crossing_censored(xs, [0.9, 0.4, 0.0]) is None
    assert x50_text(0.0, "below", xs) == "< 0.01" and x50_text(0.4, "above", xs) == "> 0.4"
    assert x50_text(0.0312, None, xs) == "0.0312"
    assert censored(xs, [[0.2, 0.1, 0.0], [0.9, 0.4, 0.0]]) == "below"
    a = np.array([[1, 1, 1, 1], [1, 1, 0, 0], [0, 0, 0, 0]])  # within the grid
    b = np.array([[1, 1, 1, 0], [1, 0, 0, 0], [0, 0, 0, 0]])
    d = bootstrap_delta_x50(xs, a, b, n_boot=200)
    assert d["censored"] is None and d["censored_ref"] is None and 0.0 <= d["censored_share"]
    assert delta_text(d, xs).startswith(f"{d['delta']:+.3g} [")


# -- the margins' closed loop starts every stride afresh -------------------------------------------


@pytest.mark.parametrize("name", ["lqr-of", "mpc-adaptive"])
def test_a_closed_loop_stride_forgets_the_strides_asked_before(name):
    """``ClosedLoop.stride`` is the map of a fresh controller: the strides asked before it
    (the fixed point's iterates and finite-difference probes) teach a stateful controller
    nothing; ``next_stride`` continues an episode."""
    from bound_env.analysis.margins import ClosedLoop

    heavy = {"m1": float(NOMINAL.m1) * 1.05}
    ctrl = load_controller(name)
    assert ctrl.stateful
    loop = ClosedLoop(ctrl, "default", heavy)
    first = loop.stride(Z_STAR).z1
    probe = Z_STAR * (1.0 + 0.02 * np.array([1.0, -1.0, 1.0, -1.0, 1.0, -1.0]))
    for z in (probe, Z_STAR, probe):
        assert loop.stride(z).z1 is not None
    np.testing.assert_array_equal(loop.stride(Z_STAR).z1, first)
    # continuing: the controller remembers the stride before (and acts differently)
    loop.stride(probe)
    z1 = loop.next_stride(Z_STAR).z1
    if name == "mpc-adaptive":  # it saw a stride (one stride is not enough to trust a fit)
        assert ctrl.strides == 1 and ctrl.innovations[0] > ctrl.config["deadband"]
    else:
        assert not np.array_equal(z1, first)


def test_the_fixed_point_of_mpc_adaptive_on_the_nominal_plant_is_mpcs(mpc):
    """The nominal fixed-point task (iterates and central-difference probes) leaves
    mpc-adaptive untaught: its cycle and multipliers are mpc's, bit for bit."""
    from bound_env.analysis.margins import ClosedLoop, fd_steps
    from bound_env.model.numerics import map_fixed_point

    ctrl = load_controller("mpc-adaptive")
    loop = ClosedLoop(ctrl, "default")
    got = map_fixed_point(loop.map, Z_STAR, fd_steps(Z_STAR), settle=4, newton_iters=2)
    want = map_fixed_point(
        ClosedLoop(mpc, "default").map, Z_STAR, fd_steps(Z_STAR), settle=4, newton_iters=2
    )
    for a, b in zip(got, want, strict=True):
        np.testing.assert_array_equal(a, b)
    assert not ctrl.trusted and ctrl.fit is None and ctrl.strides == 0


def test_the_adaptive_and_privileged_mpcs_share_one_design_and_one_set_of_defaults(privileged):
    """One base (`RedesignedMPC`: the spec's mpc, the designer, the protocol) and the
    adaptive defaults written once (the shipped spec says ``adaptive: true``)."""
    from bound_env.control.adaptive_settings import ADAPTIVE_DEFAULTS
    from bound_env.control.plant_design import RedesignedMPC
    from bound_env.control.spec import load_spec

    assert load_spec("mpc-adaptive").adaptive == ADAPTIVE_DEFAULTS
    ctrl = AdaptiveMPC()
    for c in (ctrl, privileged):
        assert isinstance(c, RedesignedMPC) and c.mpc is c.base and c.z_ref is c.base.z_ref
    assert ctrl.base.fingerprint() == privileged.base.fingerprint()
    with pytest.raises(ValueError, match="an adaptive controller re-designs an mpc spec"):
        AdaptiveMPC(spec="lqr")
    with pytest.raises(ValueError, match="a privileged controller re-designs an mpc spec"):
        PrivilegedMPC(spec="lqr")


def test_the_adaptive_and_privileged_mpcs_are_the_shipped_mpc_underneath(mpc, nominal_map):
    """Their base is the shipped mpc (settings and fingerprint, its search's early exit,
    screen and hopeless included), and off the cycle on the nominal plant mpc-adaptive's
    searched decisions are mpc's, bit for bit."""
    for name in ("mpc-adaptive", "mpc-privileged"):
        base = load_controller(name).base
        assert base.settings() == mpc.settings() and base.fingerprint() == mpc.fingerprint()
    ctrl = AdaptiveMPC()
    z = Z_STAR * (1.0 + 0.08 * np.array([1.0, -1.0, 0.5, -0.5, 1.0, -1.0]))
    for _ in range(8):
        assert np.array_equal(ctrl.stride_action(z), mpc.plan(z))
        r = nominal_map.run(z[None], ctrl.last_actions[None])
        assert r.ok[0]
        z = r.z1[0]
    assert "lqr" in ctrl.decision_kinds  # the search ran (and kept the LQR plan)
    assert np.all(ctrl.theta == 0.0) and ctrl.mpc is ctrl.base


def test_every_decision_runs_within_its_budget_and_the_work_is_the_same_spread_or_not():
    """Identification and design run ``budget`` stride evaluations per apex decision at most
    (spread over the strides); spread or in one go, the fit and the design are the same, bit
    for bit; a budget below one design Jacobian is refused, naming the key."""
    from bound_env.control.anytime import Slices

    aux = make_aux(PLANT.to_array())[None]
    nominal = StrideMap("default", None, 0.01, 80.0, EVAL_RTOL)
    runs = {}
    for budget in (32, 0):
        ctrl = AdaptiveMPC(spec="mpc-adaptive-bounded", budget=budget)
        z = Z_STAR.copy()
        for _ in range(30):
            ctrl.stride_action(z)
            r = nominal.run(z[None], ctrl.last_actions[None], aux=aux)
            assert r.ok[0]
            z = r.z1[0]
        runs[budget] = ctrl
    spread = runs[32]
    assert max(spread.decision_work) <= 32 and sum(w > 0 for w in spread.decision_work) > 5
    assert spread.trusted and spread.design is not None
    # the same fit, in slices or in one go
    idf = spread.identifier
    Z, A, Z1 = spread.applied(0, 10)

    def fit(slices, chunk):
        import copy

        i = copy.copy(idf)
        i.map, i.chunk = slices.meter(idf.map), chunk
        return i.fit(Z, A, Z1, None, 4, 2)

    whole = Slices(lambda s: fit(s, None), 0)
    assert whole.advance()
    parts = Slices(lambda s: fit(s, 32), 32)
    n = 1
    while not parts.advance():
        assert parts.spent <= 32
        n += 1
    assert n > 3 and parts.total == whole.total
    np.testing.assert_array_equal(parts.result.theta, whole.result.theta)
    np.testing.assert_array_equal(parts.result.cov, whole.result.cov)
    with pytest.raises(ValueError, match="adaptive.budget must be 0 or at least 29"):
        AdaptiveMPC(budget=20)
    with pytest.raises(ValueError, match="adaptive.budget"):
        check_adaptive({"budget": -1}, "f.yaml")


def _trusted_on_plant(ctrl, nominal_map, strides=30):
    """``ctrl`` run ``strides`` strides on PLANT from z*: the last apex state."""
    aux = make_aux(PLANT.to_array())[None]
    z = Z_STAR.copy()
    for _ in range(strides):
        ctrl.stride_action(z)
        r = nominal_map.run(z[None], ctrl.last_actions[None], aux=aux)
        assert r.ok[0]
        z = r.z1[0]
    return z


def test_unbounded_the_decision_that_finishes_a_trusted_fit_acts_on_its_design(nominal_map):
    """With ``budget`` 0 a fit finished in a decision is followed by its design in the same
    decision: no decision ends trusted on an estimate that the acting design is not of (the
    design lagged one stride behind every fit before)."""
    ctrl = AdaptiveMPC()
    aux = make_aux(PLANT.to_array())[None]
    z, acted = Z_STAR.copy(), 0
    for _ in range(30):
        ctrl.stride_action(z)
        if ctrl.trusted:
            moved = np.max(np.abs(ctrl.theta - ctrl.designed_theta))
            assert moved <= ctrl.config["redesign"], (ctrl.strides, moved)
            acted += ctrl.mpc is not ctrl.base
        r = nominal_map.run(z[None], ctrl.last_actions[None], aux=aux)
        assert r.ok[0]
        z = r.z1[0]
    assert acted > 20  # trusted and acting on its design most of the episode


@pytest.mark.parametrize("fallback", [False, True])
def test_fallback_decides_what_acts_after_a_mispredicted_stride(mpc, nominal_map, fallback):
    """A trusted estimate meets a stride it mispredicts (the robot is pushed: the next apex is
    not where the stride led). ``fallback: true``: the shipped mpc acts again (its action),
    and it refits after ``identify`` strides too; ``false`` (shipped): the design stays."""
    ctrl = AdaptiveMPC(fallback=fallback)
    z = _trusted_on_plant(ctrl, nominal_map)
    assert ctrl.trusted and ctrl.mpc is not ctrl.base and ctrl.strides > ctrl.config["identify"]
    design, fit = ctrl.mpc, ctrl.fit
    pushed = z * (1.0 + 0.05 * np.array([1.0, -1.0, 1.0, -1.0, 1.0, -1.0]))
    u = ctrl.stride_action(pushed)
    assert ctrl.innovations[-1] > ctrl.config["trust_error"]
    if fallback:
        assert ctrl.mpc is ctrl.base and not ctrl.trusted and ctrl.fit is not fit
        np.testing.assert_array_equal(u, mpc.plan(pushed))
    else:
        assert ctrl.mpc is design and ctrl.fit is fit
        assert not np.array_equal(u, mpc.plan(pushed))
    with pytest.raises(ValueError, match="adaptive.fallback must be true or false"):
        check_adaptive({"fallback": 1}, "f.yaml")


def test_the_adaptive_keys_have_spellings_that_say_which(tmp_path):
    """``descents_per_fit`` is ``search`` and ``fits_per_episode`` is ``searches``: the same
    setting under the same limits, in a spec file as in a block; both spellings of one setting
    are refused, and an error names the spelling the user wrote."""
    from bound_env.control.spec import CONTROLLERS_DIR, load_spec

    assert check_adaptive({"descents_per_fit": 2, "fits_per_episode": 5}, "f.yaml") == (
        check_adaptive({"search": 2, "searches": 5}, "f.yaml")
    )
    assert check_adaptive({"descents_per_fit": 2}, "f.yaml")["search"] == 2
    with pytest.raises(ValueError, match=r"^f.yaml: adaptive.descents_per_fit must be an"):
        check_adaptive({"descents_per_fit": 1.5}, "f.yaml")
    with pytest.raises(ValueError, match="adaptive.fits_per_episode and adaptive.searches are one"):
        check_adaptive({"fits_per_episode": 1, "searches": 2}, "f.yaml")
    with pytest.raises(ValueError, match=r"allowed: .*descents_per_fit \(= search\)"):
        check_adaptive({"descent": 1}, "f.yaml")
    base = (CONTROLLERS_DIR / "mpc-adaptive.yaml").read_text()
    new = tmp_path / "new.yaml"
    new.write_text(base.replace("adaptive: true", "adaptive: {descents_per_fit: 2}"))
    old = tmp_path / "old.yaml"
    old.write_text(base.replace("adaptive: true", "adaptive: {search: 2}"))
    assert "adaptive: {descents_per_fit: 2}" in new.read_text()
    a, b = load_spec(new), load_spec(old)
    assert a.path != b.path and a.adaptive == b.adaptive and a.adaptive["search"] == 2
