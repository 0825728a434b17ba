"""Rough terrain: the slope frame change at an apex, and the env option slope_noise_deg."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

import bound_env
from bound_env.model.dynamics import kinetic_energy, make_aux, total_energy
from bound_env.model.hybrid import state_from_z
from bound_env.model.params import P_ALPHA, P_GX, P_GY, load_gait
from bound_env.model.terrain import change_slope
from bound_env.sim.task import S_XI

gym.register_envs(bound_env)


def _world(y, alpha):
    """Centre of mass position and velocity in a world frame (X forward, Y up) whose origin is
    the slope frame's origin: e_x = (cos a, -sin a), e_y = (sin a, cos a)."""
    ex, ey = (
        np.array([math.cos(alpha), -math.sin(alpha)]),
        np.array([math.sin(alpha), math.cos(alpha)]),
    )
    return y[0] * ex + y[1] * ey, y[4] * ex + y[5] * ey


@pytest.mark.parametrize("d_deg", [-3.0, -0.5, 0.7, 4.0])
def test_frame_change_keeps_speed_and_energy(d_deg):
    gait = load_gait("default")
    aux = make_aux(gait.params.to_array())
    y = state_from_z(gait.z0)  # an apex, x_g = 0: the pivot is the frames' common origin
    y[5] = 0.05  # not only at an apex
    alpha = aux[P_ALPHA]
    pos0, vel0 = _world(y, alpha)
    e0, k0 = total_energy(y, aux), kinetic_energy(y, aux)
    y1, aux1 = y.copy(), aux.copy()
    assert change_slope(y1, aux1, math.radians(d_deg))
    assert aux1[P_ALPHA] == pytest.approx(alpha + math.radians(d_deg), abs=1e-15)
    assert math.hypot(aux1[P_GX], aux1[P_GY]) == pytest.approx(gait.params.g, rel=1e-12)
    pos1, vel1 = _world(y1, aux1[P_ALPHA])
    assert np.allclose(pos1, pos0, atol=1e-14) and np.allclose(vel1, vel0, atol=1e-14)
    assert math.hypot(y1[4], y1[5]) == pytest.approx(math.hypot(y[4], y[5]), rel=1e-14)
    assert kinetic_energy(y1, aux1) == pytest.approx(k0, rel=1e-14)
    assert total_energy(y1, aux1) == pytest.approx(e0, rel=1e-13)
    # pitch from the new ground line; the relative angle and the rates do not change
    assert y1[2] == pytest.approx(y[2] + math.radians(d_deg), abs=1e-15)
    assert (y1[3], y1[6], y1[7]) == (y[3], y[6], y[7])
    # away from x_g = 0 the energy changes by the potential's offset only: m g times the
    # change of the pivot's height as seen by the two frames
    y2, aux2 = y.copy(), aux.copy()
    y2[0] = 3.0
    e2 = total_energy(y2, aux2)
    change_slope(y2, aux2, math.radians(d_deg))
    m, g = gait.params.m1 + gait.params.m2, gait.params.g
    offset = m * g * 3.0 * (math.sin(alpha) - math.sin(aux2[P_ALPHA]))
    assert total_energy(y2, aux2) - e2 == pytest.approx(offset, rel=1e-9, abs=1e-9)


def test_frame_change_refuses_a_stance_leg():
    gait = load_gait("default")
    aux = make_aux(gait.params.to_array(), back_stance=True)
    y = state_from_z(gait.z0)
    y0 = y.copy()
    assert not change_slope(y, aux, 0.01)
    assert np.array_equal(y, y0)


def _apexes(env, n_strides, seed=0):
    env.reset(seed=seed)
    out = []
    while len(out) < n_strides:
        _, _, term, _, info = env.step(np.zeros(1))
        assert not term, info["failure"]
        if "apex_z" in info:
            out.append(np.array(info["apex_z"]))
    return np.array(out)


def test_zero_slope_noise_leaves_the_cycle_bit_identical():
    plain = gym.make("PassiveBound-v0", reset_noise_scale=0.0).unwrapped
    zero = gym.make("PassiveBound-v0", reset_noise_scale=0.0, slope_noise_deg=0.0).unwrapped
    a = _apexes(plain, 12)
    state = zero.np_random.bit_generator.state if zero._np_random is not None else None
    b = _apexes(zero, 12)
    assert np.array_equal(a, b)  # bit-identical
    assert np.max(np.abs(a - plain.z_ref)) < 1e-8  # and on the cycle
    assert state is None or zero.np_random.bit_generator.state == state
    # the rough-terrain path with every draw zero (stop at the apex, tilt by 0, go on) is the
    # same motion up to the integrator's tolerance
    rough = gym.make("PassiveBound-v0", reset_noise_scale=0.0, slope_noise_deg=1.0).unwrapped
    rough.reset(seed=0)
    rough.task.draw_slope_noise = lambda b, i, rng: b.s[i, S_XI:].fill(0.0)
    rough._b.s[0, S_XI:] = 0.0
    got = []
    while len(got) < 12:
        _, _, term, _, info = rough.step(np.zeros(1))
        assert not term
        if "apex_z" in info:
            got.append(np.array(info["apex_z"]))
    assert np.max(np.abs(np.array(got) - a)) < 1e-6
    assert rough.alpha_deg == pytest.approx(plain.alpha_deg, abs=1e-12)


def test_slope_noise_changes_the_slope_at_each_apex_from_the_seed():
    env = gym.make("PassiveBound-v0", reset_noise_scale=0.0, slope_noise_deg=0.3).unwrapped
    runs = []
    for _ in range(2):
        env.reset(seed=5)
        slopes = []
        for _ in range(200):
            _, _, term, _, info = env.step(np.zeros(1))
            if "apex_z" in info:
                slopes.append(env.alpha_deg)
            if term:
                break
        runs.append(slopes)
    assert runs[0] == runs[1] and len(runs[0]) >= 2  # the seed fixes the terrain
    nominal = math.degrees(env.task.params.alpha)
    steps = np.diff([nominal] + runs[0])
    assert np.all(steps != 0)
    # alpha_k = alpha + sigma xi_k: around the nominal slope, not a random walk
    assert np.all(np.abs(np.array(runs[0]) - nominal) < 0.3 * 5)
    with pytest.raises(ValueError, match="slope_noise_deg"):
        gym.make("PassiveBound-v0", slope_noise_deg=-1.0)
    with pytest.raises(ValueError, match="slope_noise_deg"):
        gym.make_vec(
            "PassiveBound-v0",
            num_envs=2,
            vectorization_mode="vector_entry_point",
            slope_noise_deg=0.5,
        )


def test_stride_env_slope_noise():
    def apexes(env, n, seed=0):
        env.reset(seed=seed)
        out, slopes = [], []
        for _ in range(n):
            _, _, term, _, info = env.step(np.zeros(env.action_space.shape))
            if term:
                break
            out.append(info["apex_z"])
            slopes.append(env.alpha_deg)
        return np.array(out), slopes

    plain = gym.make("PassiveBoundStride-v1", reset_noise_scale=0.0).unwrapped
    zero = gym.make("PassiveBoundStride-v1", reset_noise_scale=0.0, slope_noise_deg=0.0).unwrapped
    a, _ = apexes(plain, 5)
    b, _ = apexes(zero, 5)
    assert len(a) == 5 and np.array_equal(a, b)  # bit-identical without noise
    rough = gym.make("PassiveBoundStride-v1", reset_noise_scale=0.0, slope_noise_deg=0.2).unwrapped
    c, slopes = apexes(rough, 5, seed=4)
    d, slopes2 = apexes(rough, 5, seed=4)
    nominal = math.degrees(rough.params.alpha)
    assert slopes == slopes2 and np.array_equal(c, d)  # the seed fixes the terrain
    assert slopes[0] == nominal and all(s != nominal for s in slopes[1 : len(c)])
    assert np.array_equal(c[0], a[0])  # the first stride runs on the nominal slope
    assert not np.allclose(c[1:], a[1 : len(c)], atol=1e-9)
