"""Tests of the classical controllers (bound_env.control): the linearization, the LQR's and the
deadbeat's closed loops measured through the simulator against their design, the step-env
protocol (interval averages, on_apex), specs and bad input."""

import json
import subprocess
import sys
from dataclasses import replace

import gymnasium as gym
import numpy as np
import pytest

import bound_env
from bound_env.control import (
    ControllerSpec,
    deadbeat_gain,
    is_controller,
    load_controller,
    load_spec,
    lqr_gain,
    spectral_radius,
)
from bound_env.model.params import load_gait
from bound_env.sim.stride_task import make_basis

gym.register_envs(bound_env)
Z_STAR = load_gait("default").z0


def closed_loop_jacobian(ctrl):
    """Fixed point and Jacobian of the closed-loop stride map z -> P(z, u(z)), measured in
    PassiveBoundStride-v1: Newton with a central-difference Jacobian."""
    from bound_env.analysis.margins import fd_steps
    from bound_env.model.numerics import map_fixed_point

    env = gym.make("PassiveBoundStride-v1", **ctrl.stride_env_kwargs).unwrapped

    def f(z):
        env.reset(options={"apex_state": z})
        info = env.step(ctrl.stride_action(z))[4]
        return info.get("apex_z")

    return map_fixed_point(f, Z_STAR, fd_steps(Z_STAR), settle=20, newton_iters=6)


def test_lqr_closed_loop_emax_matches_the_design():
    ctrl = load_controller("lqr")
    A, B = np.array(ctrl.design["A"]), np.array(ctrl.design["B"])
    predicted = spectral_radius(A - B @ ctrl.gain)
    assert predicted == pytest.approx(ctrl.design["rho_closed"])
    assert predicted < 0.9 * spectral_radius(A)  # the feedback does something
    z_cl, res, jac = closed_loop_jacobian(ctrl)
    assert res < 1e-10 and np.max(np.abs(z_cl - Z_STAR)) < 1e-8  # z* stays the fixed point
    assert spectral_radius(jac) == pytest.approx(predicted, abs=1e-3)
    # zero apex error, zero torque
    np.testing.assert_array_equal(ctrl.coefficients(Z_STAR), 0.0)


def test_deadbeat_places_every_eigenvalue_at_zero():
    # designed on the current map (the shipped spec stores the gain it was designed with)
    ctrl = load_controller(replace(load_spec("deadbeat"), gain=None))
    assert ctrl.design["source"] == "designed"
    A, B = np.array(ctrl.design["A"]), np.array(ctrl.design["B"])
    assert np.max(np.abs(A - B @ ctrl.gain)) < 1e-9
    _, _, jac = closed_loop_jacobian(ctrl)
    assert spectral_radius(jac) < 1e-3
    # a small error is removed in one stride, to second order
    env = gym.make("PassiveBoundStride-v1", **ctrl.stride_env_kwargs).unwrapped
    z = Z_STAR + 1e-4 * np.array([0.02, 0.1, 0.2, 0.1, 1.0, 1.0])
    env.reset(options={"apex_state": z})
    z1 = env.step(ctrl.stride_action(z))[4]["apex_z"]
    assert np.max(np.abs(z1 - Z_STAR) / np.abs(z - Z_STAR)) < 1e-2


def test_variational_and_finite_difference_linearizations_agree():
    fd = load_controller(ControllerSpec("lqr", basis="windows", K=3))
    var = load_controller(ControllerSpec("lqr", basis="windows", K=3, jacobian="variational"))
    A_fd, A_var = np.array(fd.design["A"]), np.array(var.design["A"])
    scale = np.abs(A_fd).max()
    assert np.max(np.abs(A_fd - A_var)) < 1e-5 * scale
    assert np.max(np.abs(np.abs(np.linalg.eigvals(A_var)).max() - 0.8781471)) < 1e-6


def test_step_env_output_is_the_interval_average_of_the_profile():
    ctrl = load_controller("lqr")
    z = Z_STAR + np.array([0.004, 0.0, 0.0, -0.02, 0.0, 0.0])
    ctrl.on_apex(z, 0.0)
    taus = ctrl.basis.torques(ctrl.coefficients(z), ctrl.max_torque)
    assert np.any(np.abs(taus) > 1.0)
    T = ctrl.basis.period
    obs = np.zeros(16, np.float32)
    grid = np.arange(0.0, T + 0.05, 0.01)
    impulse = 0.0
    for t in grid:
        obs[15] = t
        a = ctrl(obs)
        impulse += a * ctrl.max_torque * 0.01
        inside = np.searchsorted(ctrl.basis.edges, [t, t + 0.01], side="right")
        if inside[0] == inside[1] and t + 0.01 < T:  # an interval inside one window
            assert a * ctrl.max_torque == pytest.approx(taus[inside[0] - 1])
    # the intervals deliver the profile's impulse (the last window holds past T), up to the
    # float32 rounding of the observation's time (~1e-8 s per interval edge)
    exact = np.dot(taus, np.diff(ctrl.basis.edges)) + taus[-1] * (grid[-1] + 0.01 - T)
    assert impulse == pytest.approx(exact, rel=1e-6)


def test_damping_controller():
    ctrl = load_controller("damping")
    assert ctrl.c == 3.886 and ctrl.env_kwargs["max_torque"] == 80.0
    obs = np.zeros(16, np.float32)
    obs[6] = 2.0  # theta2dot
    assert ctrl(obs) == pytest.approx(-3.886 * 2.0 / 80.0)
    obs[6] = -1000.0
    assert ctrl(obs) == 1.0  # saturated


def test_riccati_without_stabilizing_solution_says_so():
    A = np.diag([1.5, 0.5])
    B = np.array([[0.0], [1.0]])  # the unstable mode is not reachable
    with pytest.raises(ValueError, match="no stabilizing solution"):
        lqr_gain(A, B, np.eye(2), np.eye(1))
    with pytest.raises(ValueError, match="rank"):
        deadbeat_gain(np.eye(6), np.ones((6, 4)))


def test_bad_specs_get_one_line_errors(tmp_path, cli):
    def spec(text):
        p = tmp_path / "c.yaml"
        p.write_text(text)
        return p

    with pytest.raises(ValueError, match=r"c\.yaml: unknown key 'Qx'"):
        load_spec(spec("controller: lqr\nQx: 1\n"))
    with pytest.raises(ValueError, match="controller must be one of"):
        load_spec(spec("controller: pid\n"))
    with pytest.raises(ValueError, match="unknown key 'c'"):
        load_spec(spec("controller: lqr\nc: 1\n"))
    with pytest.raises(ValueError, match="max_torque"):
        load_spec(spec("controller: lqr\nmax_torque: -3\n"))
    with pytest.raises(ValueError, match=r"R must be"):
        load_controller(spec("controller: lqr\nK: 2\nR: [1, 2, 3]\n"))
    with pytest.raises(ValueError, match=r"gain has shape \(2, 6\).*K=4 needs a \(4, 6\)"):
        load_controller(spec("controller: lqr\nK: 4\ngain: [[0,0,0,0,0,0],[0,0,0,0,0,0]]\n"))
    with pytest.raises(ValueError, match="deadbeat needs B of rank 6"):
        load_controller(spec("controller: deadbeat\nK: 4\n"))
    with pytest.raises(FileNotFoundError):
        load_spec("no-such-controller")
    assert is_controller("lqr") and is_controller("x.yaml") and not is_controller("passive")
    # an explicit gain of the right shape is used as given
    g = np.zeros((2, 6))
    g[0, 3] = 1.5
    np.save(tmp_path / "g.npy", g)
    ctrl = load_controller(spec("controller: lqr\nK: 2\ngain: g.npy\n"))
    np.testing.assert_array_equal(ctrl.gain, g)
    # the CLI: one line on stderr, exit code 2
    p = spec("controller: lqr\nbogus: 1\n")
    code, _, err = cli(
        "margins", "--policy", p, "--budget", "test", "--no-cache", "--out", tmp_path / "m"
    )
    assert code == 2
    assert err.strip().count("\n") == 0 and "unknown key 'bogus'" in err


def test_phases_basis_and_hats_design():
    ctrl = load_controller(ControllerSpec("lqr", basis="phases", K=None, R=1.0))
    assert ctrl.basis.K == 5 and ctrl.design["rho_closed"] < 0.5
    h = load_controller(ControllerSpec("lqr", basis="hats", K=6, R=0.1))
    assert h.design["rho_closed"] < 0.2
    assert make_basis("hats", 6, 0.4).K == 6


@pytest.mark.slow
def test_margins_schema_and_acceptance_numbers(tmp_path):
    """bound-env margins --policy lqr|deadbeat --budget quick --json (the issue's acceptance):
    basin_min >= 5x passive, emax <= 0.7 (lqr), emax < 0.1 (deadbeat)."""
    res = {}
    for name in ("passive", "lqr", "deadbeat"):
        r = subprocess.run(
            [
                sys.executable,
                "-m",
                "bound_env.commands.cli",
                "margins",
                "--policy",
                name,
                "--budget",
                "quick",
                "--json",
                "--out",
                str(tmp_path / name),
            ],
            capture_output=True,
            text=True,
            check=True,
        )
        res[name] = json.loads(r.stdout)
    for key in (
        "basin",
        "basin_min",
        "basin_curve",
        "emax",
        "eigenvalues",
        "effort",
        "slope_window_deg",
        "kc_window",
        "push",
        "fixed_point_shift",
    ):
        assert key in res["lqr"]
    assert res["lqr"]["basin_min"] >= 5 * res["passive"]["basin_min"]
    assert res["lqr"]["emax"] <= 0.7
    assert res["deadbeat"]["emax"] < 0.1
    assert res["lqr"]["effort"] < 1e-6  # zero torque on the cycle


def test_a_long_step_env_episode_with_notify_apex_follows_the_stride_env():
    """Over a whole episode (not one stride per episode), the controller told every apex by
    notify_apex brings a perturbed start back to the cycle in the step env too."""
    from bound_env.control import notify_apex

    ctrl = load_controller("lqr")
    env = gym.make("PassiveBound-v0", max_torque=80.0, rtol=1e-10).unwrapped
    z0 = Z_STAR * (1 + np.array([0.0, 0.0, 0.0, -0.05, 0.0, 0.0]))  # outside the passive basin
    obs, info = env.reset(options={"apex_state": z0})
    notify_apex(ctrl, obs, info)
    apexes = []
    for _ in range(1200):
        obs, _, terminated, _, info = env.step(np.array([ctrl(obs)], np.float32))
        notify_apex(ctrl, obs, info)
        assert not terminated
        if "apex_z" in info:
            apexes.append(info["apex_z"])
    assert len(apexes) >= 25
    assert np.max(np.abs(apexes[-1] - Z_STAR) / np.abs(Z_STAR)) < 1e-3
    env.reset(options={"apex_state": z0})  # the passive gait falls from there
    for _ in range(1200):
        if env.step(np.zeros(1, np.float32))[2]:
            break
    else:
        raise AssertionError("the passive gait survived a start outside its basin")


def test_rollout_runs_the_controllers_by_name():
    """``bound-env rollout --policy lqr``: the stride-level controller is told every apex and
    brings a start the passive gait falls from back to the cycle."""
    from agents.runtime.rollout import rollout

    lqr = rollout("lqr", strides=40, seed=3, noise=1.0)
    passive = rollout("passive", strides=40, seed=3, noise=1.0)
    assert passive["fell"] and not lqr["fell"] and lqr["strides"] == 40
    assert lqr["apex_error"][-1] < 1e-6 and lqr["max_torque"] == 80.0


def test_a_spec_stores_gains_per_gait(tmp_path):
    """The shipped specs store the gains they were designed with, per gait; a gait the
    mapping does not list is designed on the current map."""
    shipped = load_controller("lqr", gait="literal-cycle")
    assert shipped.design["source"] == "gain"
    assert not np.array_equal(shipped.gain, load_controller("lqr").gain)
    text = (bound_env.control.CONTROLLERS_DIR / "lqr.yaml").read_text()
    only_default = text[: text.index("  literal-cycle:")]
    spec = tmp_path / "lqr1.yaml"
    spec.write_text(only_default)
    assert load_controller(spec).design["source"] == "gain"
    designed = load_controller(spec, gait="literal-cycle")
    assert designed.design["source"] == "designed"
    assert np.max(np.abs(designed.gain - shipped.gain)) < 0.05 * np.max(np.abs(shipped.gain))
