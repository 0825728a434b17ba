"""Physics tests of the hybrid simulator: energy, two back-ends, transitions, failures."""

import math

import numpy as np
import pytest

from bound_env.model.dynamics import back_hip, front_hip, make_aux, total_energy
from bound_env.model.hybrid import FAILURES, GUARD_NAMES, TIME_UP, simulate_stride, state_from_z
from bound_env.model.params import Params, load_gait, z_to_si

# Apex states [paper units] and touchdown angles [deg] that end in each failure (found by a
# random search over states and angles; the test checks the simulator still names them).
FAILURE_CASES = {
    "ground_contact_back_hip": (
        [0.2759, 8.7162, -7.6087, 0.6172, 826.3492, -278.2341],
        70.87,
        36.55,
    ),
    "ground_contact_front_hip": (
        [0.2773, 3.4413, -1.5684, 3.7583, -139.035, -99.1045],
        27.86,
        40.19,
    ),
    "moving_backwards": ([0.3186, 0.2994, 23.975, 2.297, 325.8121, -227.2007], 62.03, 71.52),
    "leg_overcompressed_front": (
        [0.2356, 9.0214, -1.6786, 2.8533, -126.1729, -285.053],
        40.39,
        51.09,
    ),
    "leg_overcompressed_back": (
        [0.1622, -3.8799, 3.1379, 2.2633, 327.3337, -60.8279],
        61.82,
        25.66,
    ),
    "leg_extending_at_touchdown_front": (
        [0.3414, -10.7923, 10.1828, 1.5248, -585.4398, -429.6129],
        10.37,
        71.39,
    ),
    "ground_contact_spine_joint": (
        [0.2765, -4.5757, -28.3011, 7.122, 472.4226, -639.2122],
        47.62,
        22.48,
    ),
    "leg_extending_at_touchdown_back": (
        [0.3219, 3.295, 0.4046, 2.1516, -621.1153, 34.3238],
        71.52,
        22.22,
    ),
}


@pytest.fixture(scope="module")
def gait(paper_gait):
    return paper_gait


def _chain(z, params, n, **kw):
    """n strides from z; returns the list of results (stops at a failure)."""
    out = []
    for _ in range(n):
        r = simulate_stride(z, params, **kw)
        out.append(r)
        if not r.ok:
            break
        z = r.z1
    return out


@pytest.mark.parametrize("backend", ["fast", "reference"])
def test_energy_conserved_without_damping_and_slope(gait, backend):
    params = gait.params.with_values(zeta=0.0, alpha_deg=0.0)
    strides = _chain(gait.z0, params, 2, backend=backend, rtol=1e-12, atol=1e-12, record_dt=0.005)
    assert all(r.ok for r in strides), [r.failure for r in strides]
    assert sum(r.t_end for r in strides) >= 1.0
    e0 = strides[0].energy0
    n_events = 0
    for r in strides:
        e = r.trajectory.energy
        assert np.max(np.abs(e - e0)) / abs(e0) <= 1e-9
        assert abs(r.energy1 - e0) / abs(e0) <= 1e-9
        n_events += len(r.events)
    assert n_events >= 2 * 5  # every stride crosses td/lo of both legs and an apex


def test_damping_dissipates(gait):
    """With damping and no slope, the energy falls monotonically through every transition."""
    params = gait.params.with_values(alpha_deg=0.0)
    r = simulate_stride(gait.z0, params, record_dt=0.002)
    assert r.ok
    assert np.all(np.diff(r.trajectory.energy) <= 1e-9)
    assert r.energy1 < r.energy0 - 1.0


@pytest.mark.parametrize(
    "case",
    ["star", "y+1%", "th1-1%", "xd+1%", "th2d-1%", "literal"],
)
def test_fast_and_reference_agree(gait, case):
    z, params = gait.z0.copy(), gait.params
    if case == "literal":
        lit = load_gait("paper-literal")
        z, params = lit.z0, lit.params
    elif case != "star":
        idx = {"y": 0, "th1": 1, "xd": 3, "th2d": 5}[case[:-3].rstrip("+-")]
        z[idx] *= 1.01 if "+" in case else 0.99
    ref = simulate_stride(z, params, backend="reference", rtol=1e-13, atol=1e-13)
    fast = simulate_stride(z, params, backend="fast", rtol=1e-12, atol=1e-12)
    assert ref.failure == fast.failure
    assert ref.phases == fast.phases
    if ref.ok:
        assert np.max(np.abs(ref.z1 - fast.z1)) <= 1e-8
    assert abs(ref.t_end - fast.t_end) <= 1e-8
    assert np.max(np.abs(ref.y_end - fast.y_end)) <= 1e-8


def test_fast_converges_with_tolerance(gait):
    ref = simulate_stride(gait.z0, gait.params, backend="reference", rtol=1e-13, atol=1e-13)
    errs = [
        np.max(np.abs(simulate_stride(gait.z0, gait.params, rtol=t, atol=t).z1 - ref.z1))
        for t in (1e-6, 1e-8, 1e-10, 1e-12)
    ]
    assert errs[-1] < 1e-10
    assert all(b < a for a, b in zip(errs, errs[1:], strict=False))


def test_published_gait_sequence_and_short_flight(gait):
    r = simulate_stride(gait.z0, gait.params)
    assert r.ok
    assert r.phases == ["df", "bs", "df", "fs", "df"]
    names = [e.name for e in r.events]
    assert names == ["touchdown_back", "liftoff_back", "touchdown_front", "liftoff_front", "apex"]
    # bs -> df and df -> fs are milliseconds apart (paper: 0.002 s)
    assert 0 < r.durations[2] < 0.005


def test_toe_placed_ahead_of_hip_and_leg_at_rest_length(gait):
    r = simulate_stride(gait.z0, gait.params, record_dt=0.001)
    td = next(e for e in r.events if e.name == "touchdown_back")
    k = int(np.argmin(np.abs(r.trajectory.t - td.t)))
    y = np.r_[r.trajectory.q[k], r.trajectory.qd[k]]
    hx, hy = back_hip(y, make_aux(gait.params.to_array()))
    assert hy == pytest.approx(gait.params.lb_bar * math.cos(gait.params.gamma_b), abs=1e-9)


def test_simultaneous_touchdown_goes_straight_to_double_stance():
    """A level, symmetric body with equal touchdown angles lands both legs at once: df -> ds."""
    p = Params(gamma_b=math.radians(30), gamma_f=math.radians(30), zeta=0.0, alpha=0.0)
    z = np.array([0.3, 0.0, 0.0, 2.0, 0.0, 0.0])
    aux = make_aux(p.to_array())
    y0 = state_from_z(z)
    assert back_hip(y0, aux)[1] == pytest.approx(front_hip(y0, aux)[1])
    for backend in ("fast", "reference"):
        r = simulate_stride(z, p, backend=backend)
        assert r.phases[:2] == ["df", "ds"], (backend, r.phases)
        assert {e.name for e in r.events[:2]} == {"touchdown_back", "touchdown_front"}
        assert r.events[0].t == r.events[1].t


def test_all_transitions_occur_somewhere(gait):
    """Every transition between df, bs, fs and ds, found in a few strides (states from a search)."""
    seen = set()
    cases = [
        (gait.z0, gait.params),
        (
            z_to_si([0.362, 12.6626, -16.7826, 2.8284, 93.0023, -323.8827]),
            gait.params.with_values(gamma_b_deg=48.35, gamma_f_deg=34.94),
        ),
        (
            z_to_si([0.3715, -10.3309, 17.2631, 0.9727, 44.2587, 150.2781]),
            gait.params.with_values(gamma_b_deg=23.95, gamma_f_deg=6.97),
        ),
        (
            np.array([0.3, 0.0, 0.0, 2.0, 0.0, 0.0]),
            Params(gamma_b=math.radians(30), gamma_f=math.radians(30), zeta=0.0, alpha=0.0),
        ),
    ]
    for z, p in cases:
        for backend in ("fast", "reference"):
            r = simulate_stride(z, p, backend=backend)
            assert r.ok, r.failure
            seen |= {(a, b) for a, b in zip(r.phases, r.phases[1:], strict=False)}
    expected = {
        ("df", "bs"),
        ("bs", "df"),
        ("df", "fs"),
        ("fs", "df"),
        ("bs", "ds"),
        ("fs", "ds"),
        ("ds", "bs"),
        ("ds", "fs"),
        ("df", "ds"),
    }
    assert expected <= seen, expected - seen


@pytest.mark.parametrize("reason", sorted(FAILURE_CASES))
def test_failure_reasons_are_reported(gait, reason):
    z, gb, gf = FAILURE_CASES[reason]
    p = gait.params.with_values(gamma_b_deg=gb, gamma_f_deg=gf)
    for backend in ("fast", "reference"):
        r = simulate_stride(z_to_si(z), p, backend=backend)
        assert r.failure == reason, backend
        assert r.z1 is None


def test_remaining_failure_reasons(gait):
    z = gait.z0
    assert simulate_stride(z, gait.params, t_max=0.1).failure == "no_apex"
    bad = z.copy()
    bad[4] = np.nan
    assert simulate_stride(bad, gait.params).failure == "non_finite"
    assert simulate_stride(z, gait.params, tau=np.inf).failure == "non_finite"
    low = z.copy()
    low[0] = 0.01
    assert simulate_stride(low, gait.params).failure.startswith("ground_contact")
    back = z.copy()
    back[3] = -1.0
    assert simulate_stride(back, gait.params).failure == "moving_backwards"
    assert simulate_stride(z, gait.params, rtol=1e-30, atol=1e-30).failure == ("integration_failed")
    stiff = gait.params.with_values(min_leg_frac=0.6)
    assert simulate_stride(z, stiff).failure == "leg_overcompressed_back"


def test_every_failure_reason_is_covered():
    covered = set(FAILURE_CASES) | {"no_apex", "non_finite", "integration_failed"}
    assert covered == set(FAILURES)


@pytest.mark.parametrize(
    "kw, name",
    [
        ({"m1": -1.0}, "m1"),
        ({"kb": -5.0}, "kb"),
        ({"kc": -1.0}, "kc"),
        ({"zeta": -0.1}, "zeta"),
        ({"gamma_b_deg": 0.0}, "gamma_b"),
        ({"gamma_f_deg": 95.0}, "gamma_f"),
        ({"I2": float("nan")}, "I2"),
        ({"lb_bar": 0.0}, "lb_bar"),
    ],
)
def test_invalid_parameters_name_the_parameter(gait, kw, name):
    with pytest.raises(ValueError, match=name):
        gait.params.with_values(**kw)


def test_damping_from_zeta(gait):
    """eqs. (25)-(26): I' = 0.64 kg m^2 under the reproducing reading, c_c = 3.886 N m s/rad."""
    p = gait.params
    assert p.I1_joint == pytest.approx(0.64)
    assert p.c_c == pytest.approx(0.4 * math.sqrt(0.64 * 295 / 2))
    zeta_back = p.c_c / 2 * math.sqrt((p.I1_joint + p.I2_joint) / (p.I1_joint * p.I2_joint * p.kc))
    assert zeta_back == pytest.approx(0.2)


def test_spine_torque_is_a_generalized_force_on_theta2_only(gait):
    """tau changes theta2's equation but conserves linear momentum: xddot, yddot unchanged."""
    from bound_env.model.dynamics import accelerations

    y = state_from_z(gait.z0)
    a0 = accelerations(y, make_aux(gait.params.to_array(0.0)))
    a1 = accelerations(y, make_aux(gait.params.to_array(5.0)))
    assert np.allclose(a0[:2], a1[:2], atol=1e-14)
    assert not np.allclose(a0[2:], a1[2:])
    # tau does work but stores none: the energy function does not depend on it
    aux0 = make_aux(gait.params.to_array(0.0))
    assert total_energy(y, aux0) == total_energy(y, make_aux(gait.params.to_array(5.0)))


def test_strict_rule_ends_at_the_first_apex_after_any_stance(gait):
    """A state whose flight after back stance has an apex: the strict stride ends there, the
    default stride goes on until both legs have been in stance."""
    z = z_to_si([0.2322, 1.4326, -5.1367, 3.0061, 642.134, -542.4661])
    p = gait.params.with_values(gamma_b_deg=47.73, gamma_f_deg=33.99)
    strict = simulate_stride(z, p, strict=True)
    full = simulate_stride(z, p)
    assert strict.ok and full.ok
    assert strict.phases == ["df", "bs", "df"]
    assert "fs" in full.phases and full.t_end > strict.t_end
    # on the published gait the flight between bs and fs has no apex: both rules agree
    a = simulate_stride(gait.z0, gait.params, strict=True)
    b = simulate_stride(gait.z0, gait.params)
    assert a.phases == b.phases and np.allclose(a.z1, b.z1, atol=0)


def test_both_back_ends_run_through_apexes_alike(default_gait):
    """Without stopping at the apex, every apex ends a stride and starts the next one (the
    touched-down flags are cleared by the events layer): both back-ends pass the same apexes,
    and each apex state is the next stride's start, as `simulate_stride` chains them."""
    from bound_env.model.dynamics import make_aux
    from bound_env.model.events import N_FLAGS
    from bound_env.model.fast import EV_APEXES, EV_LOGGED, Options, advance, event_log, recorder
    from bound_env.model.reference import simulate_reference

    g, t_end = default_gait, 1.0  # ~2.6 strides of 0.39 s
    y0 = state_from_z(g.z0)
    aux_r, flags_r, apexes = make_aux(g.params.to_array()), np.zeros(N_FLAGS, np.bool_), []
    status_r, t_r, _, events_r, _ = simulate_reference(
        y0, aux_r, flags_r, t_end=t_end, stop_at_apex=False, apexes=apexes
    )
    y, aux_f, flags_f = y0.copy(), make_aux(g.params.to_array()), np.zeros(N_FLAGS, np.bool_)
    log = event_log(64, np.empty((8, 8)))
    status_f, t_f, _ = advance(
        y, aux_f, flags_f, 0.0, t_end, 0.0, Options(1e-12, 1e-12, False), log, recorder(0, 0.0)
    )
    assert status_r == status_f == TIME_UP and t_r == pytest.approx(t_end) and t_f == t_end
    n_apex = int(log.count[EV_APEXES])
    assert n_apex == len(apexes) == 2
    np.testing.assert_allclose(log.apex_y[:n_apex], np.array(apexes), rtol=0, atol=1e-8)
    names_f = [GUARD_NAMES[i] for i in log.guard[: log.count[EV_LOGGED]]]
    assert names_f == [e.name for e in events_r]
    assert names_f.count("apex") == 2
    apex_t = [e.t for e in events_r if e.name == "apex"]
    one = simulate_stride(g.z0, g.params)
    assert apex_t[0] == pytest.approx(one.t_end, abs=1e-8)
    np.testing.assert_allclose(apexes[0][[1, 2, 3, 4, 6, 7]], one.z1, rtol=0, atol=1e-8)
    np.testing.assert_array_equal(flags_r, flags_f)
    np.testing.assert_array_equal(aux_r[-4:-2], aux_f[-4:-2])  # same contacts at t_end
