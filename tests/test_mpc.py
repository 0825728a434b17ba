"""Tests of the model-predictive stride controller (bound_env.control.mpc): its model is the
step env's torque, its plans hold in the step env, zero torque on the cycle, determinism, a
search that never does worse than the LQR's own plan, and its spec's bad input."""

import gymnasium as gym
import numpy as np
import pytest

import bound_env
from bound_env.control import load_controller, load_spec
from bound_env.control.mpc import FELL, RETURNED

gym.register_envs(bound_env)


@pytest.fixture(scope="module")
def mpc():
    return load_controller("mpc")


def starts(mpc, r, n, seed=777):
    """n apex states at relative size r along random directions (not the test set's)."""
    u = np.random.default_rng(seed).standard_normal((n, 6))
    u /= np.max(np.abs(u), axis=1, keepdims=True)
    return mpc.z_ref + r * np.abs(mpc.z_ref) * u


def step_env_stride(ctrl, z):
    """One stride of the step env (margins' closed loop): the apex state reached, or None."""
    env = gym.make("PassiveBound-v0", **ctrl.env_kwargs, rtol=1e-10, reset_noise_scale=0.0)
    env = env.unwrapped
    obs, _ = env.reset(options={"apex_state": z})
    ctrl.on_apex(z, 0.0)
    for _ in range(400):
        obs, _, terminated, _, info = env.step(np.array([ctrl(obs)]))
        if "apex_z" in info:
            return np.asarray(info["apex_z"])
        if terminated:
            return None
    return None


def test_interval_actions_are_the_step_envs(mpc):
    """The planning model's action on each control interval equals what the controller
    outputs there in the step env (the interval average of its profile)."""
    rng = np.random.default_rng(0)
    u = rng.uniform(-1, 1, mpc.basis.K)
    a = mpc.profile_actions(u)[0]
    mpc._u = u
    dt = mpc.dt
    for k in range(len(a) + 3):
        out = mpc_output(mpc, k * dt)
        assert out == pytest.approx(a[min(k, len(a) - 1)], abs=1e-12)
    # the impulse over the nominal stride is the profile's
    T = mpc.basis.period
    t = dt * np.arange(len(a))
    widths = np.minimum(t[1:], T) - t[:-1]
    impulse = mpc.max_torque * np.dot(a[:-1], widths)
    assert impulse == pytest.approx(
        np.dot(mpc.basis.torques(u, mpc.max_torque), np.diff(mpc.basis.edges)), rel=1e-12
    )


def mpc_output(ctrl, t):
    obs = np.zeros(16)
    from bound_env.control.controllers import OBS_TIME

    obs[OBS_TIME] = t
    return ctrl(obs)


def test_zero_torque_on_the_cycle_and_the_lqr_near_it(mpc):
    assert np.array_equal(mpc.coefficients(mpc.z_ref), np.zeros(mpc.basis.K))
    z = starts(mpc, 0.01, 4)
    for zi in z:
        assert np.array_equal(mpc.plan(zi), mpc.lqr.coefficients(zi))


def test_plans_are_deterministic_and_never_worse_than_the_lqr(mpc):
    """Deterministic plans; the search replaces the LQR's plan only where that plan does not
    return (on the planning model), and its plans return from more of these starts than the
    LQR's own plans do."""
    other = load_controller("mpc")
    searched = returns_mpc = returns_lqr = 0
    for z in starts(mpc, 0.25, 12):
        u = mpc.plan(z)
        assert np.array_equal(u, other.plan(z))
        u_lqr = mpc.lqr.coefficients(z)
        _, outcome, _ = mpc.evaluate(z, np.array([u, u_lqr]))
        if not np.array_equal(u, u_lqr):
            searched += 1
            assert outcome[1] != RETURNED  # the LQR's own plan is kept when it returns
        returns_mpc += outcome[0] == RETURNED
        returns_lqr += outcome[1] == RETURNED
    assert searched > 0  # these starts do exercise the search
    assert returns_mpc > returns_lqr


def test_a_plan_holds_in_the_step_env(mpc):
    """Where the plan predicts a stride, the step env (rtol 1e-10) reaches the same apex to
    the planning tolerance; where it rescues a start the LQR loses, the step env agrees."""
    rescued = 0
    for z in starts(mpc, 0.25, 16):
        u = mpc.plan(z)
        _, out_mpc, n_mpc = mpc.evaluate(z, u[None])
        _, out_lqr, _ = mpc.evaluate(z, mpc.lqr.coefficients(z)[None])
        z1 = step_env_stride(mpc, z)
        if out_mpc[0] == FELL and n_mpc[0] == 0:
            assert z1 is None
            continue
        assert z1 is not None
        # the model's own first stride, replayed alone
        pred = predicted_apex(mpc, z, u)
        np.testing.assert_allclose(z1, pred, rtol=0, atol=1e-9)  # the same map, at rtol 1e-10
        rescued += out_mpc[0] == RETURNED and out_lqr[0] != RETURNED
    assert rescued > 0


def predicted_apex(ctrl, z, u):
    """The planning model's first stride at the evaluation tolerance."""
    from bound_env.sim.stride_map import EVAL_RTOL, StrideMap

    plant = StrideMap(ctrl.gait, None, ctrl.dt, ctrl.max_torque, EVAL_RTOL)
    return plant.map(z, ctrl.profile_actions(u)[0])


def test_the_mpc_rescues_more_than_the_lqr_in_the_step_env(mpc):
    """Closed loops in the step env from 12 validation starts at r = 0.25: the MPC returns
    from at least as many, and from some the LQR loses."""
    from bound_env.analysis.margins import ClosedLoop

    lqr = mpc.lqr
    wins = {}
    for name, ctrl in (("mpc", mpc), ("lqr", lqr)):
        loop = ClosedLoop(ctrl, "default")
        wins[name] = [loop.run(z, mpc.z_ref, 100)[0] for z in starts(mpc, 0.25, 12)]
    assert sum(wins["mpc"]) > sum(wins["lqr"])


def test_every_closed_loop_decision_is_timed(mpc):
    """Margins' closed loop (a batch of strides through the stride map) times each apex
    decision once: as many timings (and kinds) as strides started, each the time of that
    decision: the searches (overrides) take far longer than the gate's decisions."""
    from bound_env.analysis.margins import ClosedLoop

    ctrl = load_controller("mpc")
    runs = ClosedLoop(ctrl, "default").run_many(starts(ctrl, 0.2, 4, seed=778), ctrl.z_ref, 40)
    assert len(ctrl.decision_seconds) == len(ctrl.decision_kinds) == sum(n for _, n, _ in runs)
    t, kinds = np.array(ctrl.decision_seconds), np.array(ctrl.decision_kinds)
    assert (kinds == "override").any() and (kinds == "gate").any()
    assert np.median(t[kinds == "override"]) > 5 * np.median(t[kinds == "gate"])


def test_decisions_are_timed(mpc):
    """A decision's recorded time is the decision's own: within the time of the call around
    it, and most of it (a search at r = 0.3 takes milliseconds)."""
    import time

    for z in starts(mpc, 0.3, 3, seed=779):
        n = len(mpc.decision_seconds)
        t0 = time.perf_counter()
        mpc.coefficients(z)
        outside = time.perf_counter() - t0
        assert len(mpc.decision_seconds) == n + 1
        assert 0.5 * outside <= mpc.decision_seconds[-1] <= outside


@pytest.mark.parametrize(
    "text, message",
    [
        ("horizon: 0", "horizon"),
        ("horizon: 2.5", "horizon"),
        ("safe: -1", "safe"),
        ("n_random: -3", "n_random"),
        ("bogus: 1", "bogus"),
    ],
)
def test_bad_mpc_specs_are_refused(tmp_path, text, message):
    p = tmp_path / "m.yaml"
    p.write_text(f"controller: mpc\nK: 8\n{text}\n")
    with pytest.raises(ValueError, match=message):
        load_spec(p)


def test_decision_summary_of_the_curve():
    from bound_env.analysis.margins import decision_summary

    curve = [
        {"size": 0.1, "decision_seconds": [0.001, 0.003]},
        {"size": 0.2, "decision_seconds": [0.002]},
    ]
    d = decision_summary(curve)
    assert d["n"] == 3 and d["p50"] == 0.002 and d["max"] == 0.003
    assert d["mean"] == pytest.approx(0.002)
    assert decision_summary([{"size": 0.1, "success": 1.0}]) is None  # an untimed controller


@pytest.mark.slow
def test_margins_reports_the_mpcs_decision_times(tmp_path):
    """`bound-env margins --policy mpc` (test budget): every closed-loop decision is timed."""
    import json
    import subprocess
    import sys

    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "bound_env.commands.cli",
            "margins",
            "--policy",
            "mpc",
            "--budget",
            "test",
            "--out",
            str(tmp_path),
            "--json",
            "--workers",
            "1",
            "--quiet",
        ],
        capture_output=True,
        text=True,
        check=True,
    )
    out = json.loads(r.stdout)
    d = out["decision_seconds"]
    # every closed loop of the curve (2 sizes x 2 directions) decides at least once; that
    # each decision is timed exactly once is test_every_closed_loop_decision_is_timed's
    assert d["n"] >= 4 and d["p50"] > 0
    # the real-time yardstick: every apex decision of every measure, the curve's among them
    every = out["decision_times"]
    assert every["n"] > d["n"] and every["p50"] <= every["p99"]
    assert out["effort"] < 1e-6  # zero torque on the cycle


def _rollout_strides(ctrl, Z) -> int:
    """Strides the controller's planning map advances to decide every state of Z."""
    n, apexes = [0], ctrl.model.apexes

    def counted(Zb, A):
        n[0] += len(Zb)
        return apexes(Zb, A)

    ctrl.model.apexes = counted
    try:
        for z in Z:
            ctrl.plan(z)
    finally:
        del ctrl.model.apexes
    return n[0]


def test_the_search_shortcuts_keep_the_returns_and_do_less():
    """The shipped mpc searches with its shortcuts (a return ends the search; a state whose
    screened profiles all fall within their first stride is given up): from validation starts
    around its r50 its plans return (on the planning model) wherever the full search's do,
    it gives some states up, and it advances far fewer planning strides."""
    from dataclasses import replace

    fast = load_controller("mpc")
    assert fast.early_exit and fast.screen > 0
    full = replace(fast, early_exit=False, screen=0)
    Z = np.concatenate([starts(fast, r, 8, seed=780) for r in (0.2, 0.3, 0.4)])
    returned = {}
    for name, ctrl in (("fast", fast), ("full", full)):
        U = np.array([ctrl.plan(z) for z in Z])
        returned[name] = [
            ctrl.rollouts(z, u[None])[0][0] == RETURNED for z, u in zip(Z, U, strict=True)
        ]
    assert sum(returned["full"]) > 0
    assert all(f or not g for f, g in zip(returned["fast"], returned["full"], strict=True))
    assert fast.given_up > 0 and full.given_up == 0
    assert _rollout_strides(fast, Z) < 0.7 * _rollout_strides(full, Z)


def test_a_given_up_state_falls_whatever_the_screen_tried():
    """A given-up state: the LQR's plan and every screened library row fall within their
    first stride, each before ``hopeless`` x the nominal period, and the plan is the one of
    them that falls latest."""
    from bound_env.control.mpc import library

    mpc = load_controller("mpc")
    for z in starts(mpc, 0.4, 12, seed=781):
        n = mpc.given_up
        u = mpc.plan(z)
        if mpc.given_up == n:
            continue
        rng = np.random.default_rng([mpc.seed, *np.frombuffer(z.tobytes(), np.uint32).tolist()])
        u_lqr = mpc.lqr.coefficients(z)
        U = library(mpc.basis.K, u_lqr, rng, mpc.n_random, mpc.n_noise, mpc.noise)
        s, outcome, strides = mpc.evaluate(z, U[: mpc.screen])
        assert np.all((outcome == FELL) & (strides == 0)) and np.max(s) < mpc.hopeless
        assert np.array_equal(u, U[int(np.argmax(s))])
        return
    pytest.fail("no state of these was given up")


def test_the_full_search_is_named_as_before():
    """With the shortcuts off (a spec without them) the settings, hence the fingerprint, do
    not name them; on, they do, and the fingerprint differs."""
    from dataclasses import replace

    fast = load_controller("mpc")
    full = replace(fast, early_exit=False, screen=0)
    assert not {"early_exit", "screen", "hopeless"} & set(full.settings())
    assert fast.settings()["early_exit"] is True and fast.settings()["screen"] == fast.screen
    assert fast.settings()["hopeless"] == fast.hopeless
    assert fast.fingerprint() != full.fingerprint()


@pytest.mark.parametrize(
    "text, message",
    [("early_exit: 1", "early_exit"), ("early_exit: maybe", "early_exit"),
     ("screen: -1", "screen"), ("screen: 2.5", "screen"), ("hopeless: 0", "hopeless"),
     ("hopeless: 1.5", "hopeless")],
)  # fmt: skip
def test_bad_search_shortcuts_are_refused(tmp_path, text, message):
    p = tmp_path / "m.yaml"
    p.write_text(f"controller: mpc\nK: 8\n{text}\n")
    with pytest.raises(ValueError, match=message):
        load_spec(p)
