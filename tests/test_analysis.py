"""Poincare analysis: fixed points, eigenvalues, continuation, the paper's secant, failures,
sweeps and the CLI, on configs/gaits/default.yaml."""

import json
import math

import numpy as np
import pytest

from bound_env.analysis.continuation import continue_branch, read_branch_csv
from bound_env.analysis.fixed_point import (
    find_fixed_point,
    ladder,
    paper_search,
    slope_secant,
)
from bound_env.analysis.poincare import apex_energy, iterate, paper_convergence, stride
from bound_env.analysis.stability import (
    jacobian,
    recovery,
    spine_oscillations,
    stability,
)
from bound_env.analysis.sweeps import sweep
from bound_env.commands.cli import main
from bound_env.model.params import load_gait, z_to_paper

ALPHA_DEG = 1.9343  # the gait's slope [deg]


@pytest.fixture(scope="module")
def gait(default_gait):
    return default_gait


@pytest.fixture(scope="module")
def fixed(gait):
    """The gait's fixed point solved afresh (rtol = atol = 1e-12)."""
    res = find_fixed_point(gait.params, gait.z0, recover=False)
    assert res.converged, res.reason
    return res


def _residual(z, params):
    return float(np.max(np.abs(stride(z, params).z1 - z)))


def test_newton_from_perturbed_start(gait, fixed):
    res = find_fixed_point(gait.params, gait.z0 * 1.01)
    assert res.converged, res.reason
    assert res.residual <= 1e-10
    assert _residual(res.z, gait.params) <= 1e-10  # independent check of the residual
    assert np.max(np.abs(res.z - fixed.z)) < 1e-9
    assert 2 <= res.iterations <= 8
    assert res.phases == ["df", "bs", "df", "fs", "df"]
    assert 0.85 < res.emax < 0.9
    assert res.strides_to_converge is not None and 20 < res.strides_to_converge < 150


def test_eigenvalues_independent_of_integration_tolerance(gait):
    """Fixed point and FD eigenvalues at rtol = atol = 1e-11 and 1e-12 agree to 1e-6."""
    lams = []
    for tol in (1e-11, 1e-12):
        kw = {"rtol": tol, "atol": tol}
        res = find_fixed_point(gait.params, gait.z0, recover=False, sim_kw=kw)
        assert res.converged, res.reason
        lams.append(res.eigenvalues)
    assert np.max(np.abs(lams[0] - lams[1])) < 1e-6
    assert abs(np.abs(lams[1][0]) - 0.87815) < 1e-4


def test_fd_jacobian_predicts_a_small_perturbation(gait, fixed):
    """Eq. (21): P(z* + dz) - z* ~ nabla P dz to second order."""
    dz = 1e-4 * np.array([1.0, -2.0, 1.5, 3.0, -10.0, 7.0])
    lin = fixed.jacobian @ dz
    act = stride(fixed.z + dz, gait.params).z1 - fixed.z
    assert np.max(np.abs(act - lin)) < 1e-3 * np.max(np.abs(lin))


def test_jacobian_method_validated(gait, fixed):
    with pytest.raises(ValueError, match="fd"):
        jacobian(fixed.z, gait.params, method="bogus")


def test_variational_jacobian_matches_fd(gait, fixed):
    pytest.importorskip("bound_env.model.variational")
    st = stability(fixed.z, gait.params, method="variational")
    assert np.max(np.abs(st.eigenvalues - fixed.eigenvalues)) < 1e-6


def test_continuation_retraces_branch(gait, fixed):
    fwd = continue_branch(gait.params, fixed.z, "kc", 300.0, step=1.0)
    assert fwd.reached, fwd.reason
    assert np.allclose(fwd.values(), [295, 296, 297, 298, 299, 300])
    end = fwd.points[-1]
    back = continue_branch(gait.params.with_values(kc=300.0), end.z, "kc", 295.0, step=1.0)
    assert back.reached, back.reason
    assert np.allclose(back.values(), fwd.values()[::-1])
    assert np.max(np.abs(back.z()[::-1] - fwd.z())) < 1e-9
    assert np.max(np.abs(back.emax()[::-1] - fwd.emax())) < 1e-6
    assert all(p.residual <= 1e-10 for p in fwd.points + back.points)
    # the gait gains a double stance phase on the way (the paper's squares, Figs. 3-4, 8)
    assert not fwd.points[0].has_ds and fwd.points[-1].has_ds
    # pseudo-arclength reaches the same end point
    arc = continue_branch(gait.params, fixed.z, "kc", 300.0, step=1.0, method="arclength")
    assert arc.reached, arc.reason
    assert arc.points[-1].value == 300.0
    assert np.max(np.abs(arc.points[-1].z - end.z)) < 1e-9


def test_arclength_passes_the_fold_in_alpha(gait, fixed):
    """The stable branch ends at a fold near alpha = 2.03 deg: a real eigenvalue reaches +1
    and the branch turns back (unstable); natural continuation cannot pass it."""
    p = gait.params.with_values(alpha_deg=2.02)
    br = continue_branch(
        p, fixed.z, "alpha_deg", 2.06, step=0.004, method="arclength", max_points=12
    )
    folds = [pt for pt in br.points if pt.fold]
    assert len(folds) == 1, [(pt.value, pt.emax) for pt in br.points]
    i = br.points.index(folds[0])
    assert br.points[i - 1].emax < 1.0 < folds[0].emax
    assert 2.025 < max(br.values()) < 2.04
    nat = continue_branch(p, fixed.z, "alpha_deg", 2.06, step=0.004)
    assert not nat.reached


def test_free_alpha_with_pinned_speed_recovers_alpha(gait, fixed):
    p = gait.params.with_values(alpha_deg=2.0)
    res = find_fixed_point(
        p, fixed.z * 1.01, free=("alpha_deg",), pin=("xdot_g", fixed.z[3]), recover=False
    )
    assert res.converged, res.reason
    assert abs(res.free["alpha_deg"] - ALPHA_DEG) < 1e-7
    assert math.isclose(res.params.to_gait_dict()["alpha_deg"], res.free["alpha_deg"])
    assert np.max(np.abs(res.z - fixed.z)) < 1e-8
    # pinning the energy instead finds the same gait
    e = apex_energy(fixed.z, gait.params)
    res_e = find_fixed_point(p, fixed.z, free=("alpha_deg",), pin=("energy", e), analyse=False)
    assert res_e.converged and abs(res_e.free["alpha_deg"] - ALPHA_DEG) < 1e-7


def test_free_parameter_needs_a_pin(gait):
    with pytest.raises(ValueError, match="pin"):
        find_fixed_point(gait.params, gait.z0, free=("alpha_deg",))
    with pytest.raises(ValueError, match="gait key"):
        find_fixed_point(gait.params, gait.z0, free=("zzz",), pin=("energy", 1.0))


def test_slope_secant_finds_alpha_back(gait, fixed):
    """Eq. (27): from alpha = 2.0 deg, the slope that balances the energy of the start z*."""
    sec = slope_secant(gait.params.with_values(alpha_deg=2.0), fixed.z)
    assert sec.converged, sec.reason
    assert abs(sec.alpha_deg - ALPHA_DEG) < 1e-6
    assert sec.fixed_point_found  # and the 100-stride check passes there
    assert sec.iterations < 15


def test_paper_search_from_perturbed_slope(gait, fixed):
    res = paper_search(
        gait.params.with_values(alpha_deg=2.0), fixed.z, max_newton=3, max_candidates=1
    )  # bounded even if the secant breaks
    assert res.converged and res.method == "paper"
    assert abs(res.free["alpha_deg"] - ALPHA_DEG) < 1e-6
    assert res.residual < 1e-10


def test_paper_ladder_is_bounded():
    from bound_env.model.params import Params

    steps = ladder(Params())
    assert steps[0] == {}
    assert len(steps) == 1 + 2 * 2 * 8 + 2 * 3
    assert {"gamma_b_deg": 46.7 + 4.0} in steps and {"gamma_f_deg": 44.6 - 4.0} in steps
    assert {"kb": 2720.0, "kf": 2720.0} in steps


def test_start_that_falls_returns_a_reason(gait):
    res = find_fixed_point(gait.params, np.array([0.2, 0.0, 0.0, 0.5, 0.0, 0.0]))
    assert not res.converged
    assert "falls" in res.reason and "ground_contact" in res.reason
    assert res.residual == math.inf and res.eigenvalues is None
    assert res.summary()["residual"] is None  # valid JSON


def test_degenerate_problem_returns_a_reason(gait, fixed):
    """Two freed parameters pinned by the same condition twice: a singular Jacobian."""
    res = find_fixed_point(
        gait.params,
        fixed.z * 1.01,
        free=("alpha_deg", "kb"),
        pin=[("xdot_g", fixed.z[3]), ("xdot_g", fixed.z[3])],
    )
    assert not res.converged
    assert "singular" in res.reason


def test_no_convergence_is_bounded(gait, fixed):
    res = find_fixed_point(gait.params, fixed.z * 1.01, max_iter=1, analyse=False)
    assert not res.converged and "no convergence in 1 iterations" in res.reason


def test_zero_damping_family_with_pinned_energy(gait):
    """Without damping on the level ground the fixed points form families: Newton alone
    reports a singular Jacobian; pinning the energy picks one, with an eigenvalue 1."""
    p = gait.params.with_values(zeta=0.0, alpha_deg=0.0)
    near = find_fixed_point(p, gait.z0, analyse=False)
    assert not near.converged and "singular" in near.reason
    res = find_fixed_point(p, near.z, pin=("energy", apex_energy(near.z, p)), recover=False)
    assert res.converged, res.reason
    assert np.min(np.abs(res.eigenvalues - 1.0)) < 1e-5


def test_energy_balance_over_the_periodic_stride(gait, fixed):
    """apex_energy is the simulator's energy at x_g = 0; it returns to itself on z*."""
    r = stride(fixed.z, gait.params)
    assert math.isclose(apex_energy(fixed.z, gait.params), r.energy0, rel_tol=1e-14)
    assert abs(apex_energy(r.z1, gait.params) - apex_energy(fixed.z, gait.params)) < 1e-8
    assert r.energy1 < r.energy0  # the total energy keeps falling down the slope


def test_paper_convergence_check(gait, fixed):
    run = paper_convergence(fixed.z * 1.001, gait.params)
    assert run.converged and run.strides == 100 and run.error < 1e-5
    short = iterate(fixed.z * 1.01, gait.params, 5)
    assert not short.converged and short.history.shape == (6, 6)


def test_recovery_and_spine_oscillations(gait, fixed):
    rec = recovery(fixed.z, gait.params, component=0, rel=-0.01)
    assert rec.failure is None
    assert rec.strides_loose <= rec.strides < 300
    assert rec.deviation[rec.strides] < 1e-5 <= rec.deviation[rec.strides - 1]
    osc = spine_oscillations(fixed.z, gait.params)
    assert osc.count == 2.0 and osc.minima == 2 and osc.maxima == 2  # Fig. 5
    assert osc.extrema_phase == ["bs", "bs", "fs", "fs"]


def test_sweep_finds_a_window(gait, fixed):
    res = sweep(gait.params, fixed.z, "kc", [293.0, 294.0, 296.0, 300.0, 303.0, 304.0])
    w = res.converged_window
    assert w is not None and w[0] <= 294.0 and 300.0 <= w[1] < 303.0
    assert res.points[res.values().tolist().index(304.0)].failure is not None


def test_cli_fixed_point_json(capsys, tmp_path):
    rc = main(["fixed-point", "--gait", "default", "--json"])
    out = json.loads(capsys.readouterr().out)
    assert rc == 0
    for key in (
        "z",
        "residual",
        "eigenvalues",
        "emax",
        "phases",
        "durations",
        "strides_to_converge",
        "converged",
        "reason",
    ):
        assert key in out
    assert out["converged"] and out["residual"] <= 1e-10
    assert len(out["z"]) == 6 and abs(out["z"][3] - 2.829) < 1e-3  # paper units
    assert len(out["eigenvalues"]) == 6 and all(len(e) == 2 for e in out["eigenvalues"])
    assert out["phases"] == ["df", "bs", "df", "fs", "df"]
    rc = main(
        [
            "fixed-point",
            "--gait",
            "default",
            "--set",
            "alpha_deg=2.0",
            "--free",
            "alpha_deg",
            "--pin",
            "xdot_g=2.8290929553434365",
            "--json",
            "--save",
            str(tmp_path / "fp.yaml"),
        ]
    )
    out = json.loads(capsys.readouterr().out)
    assert rc == 0 and abs(out["alpha_deg"] - ALPHA_DEG) < 1e-6
    saved = load_gait(tmp_path / "fp.yaml")
    assert abs(saved.params.to_gait_dict()["alpha_deg"] - ALPHA_DEG) < 1e-6
    assert np.allclose(z_to_paper(saved.z_star), out["z"], rtol=0, atol=1e-12)
    assert saved.meta["fixed_point"]["phases"] == out["phases"]


def test_cli_fixed_point_failure(capsys):
    rc = main(["fixed-point", "--gait", "default", "--z0=0.2,0,0,0.5,0,0", "--json"])
    out = json.loads(capsys.readouterr().out)
    assert rc == 1 and not out["converged"] and "falls" in out["reason"]
    assert main(["fixed-point", "--gait", "default", "--z0", "1,2"]) == 2


def test_cli_continue_writes_and_reuses(capsys, tmp_path):
    args = [
        "continue",
        "--gait",
        "default",
        "--param",
        "kc",
        "--to",
        "297",
        "--step",
        "1",
        "--out",
        str(tmp_path),
        "--quiet",
    ]
    assert main(args) == 0
    assert (tmp_path / "branch.png").stat().st_size > 0
    pts = read_branch_csv(tmp_path / "branch.csv", "kc")
    assert [p.value for p in pts] == [295.0, 296.0, 297.0]
    assert pts[-1].has_ds and not pts[0].has_ds
    mtime = (tmp_path / "branch.csv").stat().st_mtime_ns
    capsys.readouterr()
    assert main(args) == 0  # same configuration: reused, not recomputed
    assert (tmp_path / "branch.csv").stat().st_mtime_ns == mtime
    assert "3 points" in capsys.readouterr().out


def test_continuation_with_freed_slope_keeps_the_energy(gait, fixed):
    """The paper's Figs. 3-4 scheme: kc decreases, alpha is solved for at pinned energy."""
    e0 = apex_energy(fixed.z, gait.params)
    br = continue_branch(
        gait.params, fixed.z, "kc", 290.0, step=2.5, free=("alpha_deg",), pin=("energy", e0)
    )
    assert br.reached, br.reason
    alphas = [pt.free["alpha_deg"] for pt in br.points]
    assert abs(alphas[0] - ALPHA_DEG) < 1e-8
    assert np.all(np.diff(alphas) > 0)  # softer spine: steeper slope
    for pt in br.points:
        p = gait.params.with_values(kc=pt.value, alpha_deg=pt.free["alpha_deg"])
        assert abs(apex_energy(pt.z, p) - e0) < 1e-9
        assert _residual(pt.z, p) < 1e-10


def test_continuation_resumes_after_a_row_cut_short(gait, fixed, tmp_path):
    """A kill in the middle of appending a row: the next run warns, drops that row and
    recomputes it, and ends with the same branch."""
    full = continue_branch(gait.params, fixed.z, "kc", 297.0, step=1.0, out_dir=tmp_path)
    csv_path, js = tmp_path / "branch.csv", tmp_path / "branch.json"
    text = csv_path.read_text()
    csv_path.write_text(text[: len(text) - 40])  # the last row loses its tail
    state = json.loads(js.read_text())
    js.write_text(json.dumps({**state, "status": "running"}))
    with pytest.warns(RuntimeWarning, match="truncated last line"):
        again = continue_branch(gait.params, fixed.z, "kc", 297.0, step=1.0, out_dir=tmp_path)
    assert again.reached and [p.value for p in again.points] == [295.0, 296.0, 297.0]
    assert np.array_equal(again.z(), full.z())
    assert [p.value for p in read_branch_csv(csv_path, "kc")] == [295.0, 296.0, 297.0]


def test_branch_csv_rows_read_back_bit_for_bit(tmp_path):
    """Every float a resumed continuation reads back from branch.csv is the one computed,
    including angles, whose deg -> rad round trip is not exact (~1 value in 7 moves)."""
    from bound_env.analysis.continuation import (
        BranchPoint,
        csv_header,
        csv_line,
        point_row,
    )
    from bound_env.model.params import z_to_si

    rng = np.random.default_rng(3)
    zs = rng.normal(scale=[0.1, 0.05, 0.05, 1.0, 1.0, 1.0], size=(200, 6)) + [0.3, 0, 0, 1, 0, 0]
    lossy = [z for z in zs if not np.array_equal(z_to_si(z_to_paper(z)), z)]
    assert len(lossy) > 20  # the case this test is about occurs
    lam = rng.normal(size=6) + 1j * rng.normal(size=6)
    pts = [
        BranchPoint(
            value=float(k) / 3.0,
            z=z,
            residual=1e-13 / 7.0,
            eigenvalues=lam,
            emax=float(np.max(np.abs(lam))),
            phases=["df", "bs"],
            period=0.39 / 7.0,
            free={"alpha_deg": 2.0 / 3.0},
            iterations=3,
            step=0.1 / 3.0,
        )
        for k, z in enumerate(lossy)
    ]
    path = tmp_path / "branch.csv"
    text = csv_line(csv_header("kc", ["alpha_deg"]))
    text += "".join(csv_line(point_row(i, p, ["alpha_deg"])) for i, p in enumerate(pts))
    path.write_text(text, newline="")
    back = read_branch_csv(path, "kc", ["alpha_deg"])
    for a, b in zip(pts, back, strict=True):
        assert np.array_equal(a.z, b.z)
        assert (a.value, a.residual, a.period, a.step, a.free) == (
            b.value,
            b.residual,
            b.period,
            b.step,
            b.free,
        )
        assert np.array_equal(a.eigenvalues, b.eigenvalues)


def test_natural_engine_calls_on_stall_and_goes_on_from_its_point(gait, fixed):
    """The paper's fallback ladder plugs in as natural()'s on_stall hook: where every
    correction fails (here kc in (296, 297.2) is made invalid) the hook is called at the last
    good point; the point it returns restarts the continuation, which then reaches the target."""
    from bound_env.analysis.continuation import FixedPointPath, StepControl, natural

    def params_of(kc):
        if 296.0 < kc < 297.2:
            raise ValueError(f"kc = {kc} is not allowed here")
        return gait.params.with_values(kc=kc)

    path = FixedPointPath(params_of)
    calls = []

    def hop(s, u, info, direction):  # a stand-in for the ladder: jump over the gap
        calls.append((s, direction, info))
        out = path.correct(297.3, u)
        return (297.3, out.u) if out.converged else "no way across"

    pts = [(295.0, fixed.z.copy())]
    stop = natural(path, pts, 297.5, StepControl(1.0, 1.0, 0.3), on_stall=hop)
    assert stop.reached, stop
    assert [s for s, _ in pts] == [295.0, 296.0, 297.3, 297.5]
    assert len(calls) == 1 and calls[0][:2] == (296.0, 1.0) and "not allowed" in calls[0][2]
    for s, u in pts:
        assert _residual(u, gait.params.with_values(kc=s)) < 1e-10
    gave_up = natural(
        path,
        [(295.0, fixed.z.copy())],
        297.5,
        StepControl(1.0, 1.0, 0.3),
        on_stall=lambda *a: "the ladder is exhausted",
    )
    assert gave_up.kind == "the ladder is exhausted" and not gave_up.reached
