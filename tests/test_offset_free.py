"""Offset-free stride control (bound_env.control.offset_free): zero torque and a zero estimate
on the nominal cycle, the robot's own cycle held on a mismatched plant where the plain LQR
needs torque, the state per robot and its reset, loading by name and by spec."""

import gymnasium as gym
import numpy as np
import pytest

import bound_env
from bound_env.control import OffsetFree, PlainPolicy, is_controller, load_controller
from bound_env.control.offset_free import interval_model
from bound_env.model.dynamics import make_aux
from bound_env.model.params import load_gait
from bound_env.sim.stride_map import StrideMap

gym.register_envs(bound_env)
Z_STAR = load_gait("default").z0
HEAVY = {"m1": 10.4 * 1.05}  # the back body 5 % heavier
INERT = {"I1": 0.443375 * 1.05, "I2": 0.443375 * 1.05}  # both inertias 5 % larger


@pytest.fixture(scope="module")
def lqr():
    return load_controller("lqr")


@pytest.fixture(scope="module")
def nominal():
    return StrideMap("default")


def heavy_aux(values=HEAVY):
    p = load_gait("default").params.with_values(**values)
    return make_aux(p.to_array())[None]


def run(ctrl, sm, strides, aux=None):
    """Batched closed loop of one robot from z*: (apex states, efforts, state or None)."""
    z = Z_STAR.copy()[None]
    state = ctrl.start(1) if getattr(ctrl, "stateful", False) else None
    zs, eff = [z[0]], []
    for _ in range(strides):
        A = ctrl.plan_actions(state, z) if state is not None else ctrl.interval_actions(z)
        r = sm.run(z, A, aux=aux)
        if not r.ok[0]:
            break
        z = r.z1
        zs.append(z[0])
        eff.append(float(r.effort[0]))
    return np.array(zs), np.array(eff), state


def test_the_nominal_model_is_the_lqrs_linearization(lqr):
    m = interval_model()
    np.testing.assert_allclose(m.A, np.array(lqr.design["A"]), rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(m.M @ (np.eye(6) - m.A), np.eye(6), atol=1e-9)
    assert m.B.shape[0] == 6 and np.abs(m.B[:, -1]).max() == 0.0  # nothing after the apex


def test_zero_torque_and_zero_estimate_on_the_nominal_cycle(lqr, nominal):
    of = OffsetFree(lqr)
    state = of.start(3)
    A = of.plan_actions(state, np.tile(Z_STAR, (3, 1)))
    assert np.all(A == 0.0)  # exactly zero at z*
    zs, eff, state = run(of, nominal, 30)
    assert len(eff) == 30
    assert np.all(state.d == 0.0)  # round-off of the nominal cycle never enters d^
    assert np.all(of.shifts(state, [0]) == 0.0)
    zl, effl, _ = run(lqr, nominal, 30)
    np.testing.assert_array_equal(zs, zl)  # it is the LQR there, bit for bit
    np.testing.assert_array_equal(eff, effl)
    # the step protocol: the first interval at z* is exactly zero
    of.reset()
    of.on_apex(Z_STAR, 0.0)
    obs = np.zeros(16)
    assert of(obs) == 0.0


@pytest.mark.parametrize("values", [HEAVY, INERT], ids=["m1+5%", "I1,I2+5%"])
def test_holds_the_robots_own_passive_cycle(lqr, nominal, values):
    """The back body 5 % heavier, or both inertias 5 % larger: the LQR holds a gait near z*
    with steady torque; the offset-free LQR finds the plant's own cycle, which needs none."""
    of = load_controller("lqr-of")
    zs, eff, _ = run(of, nominal, 100, heavy_aux(values))
    assert len(eff) == 100
    _, eff_lqr, _ = run(lqr, nominal, 100, heavy_aux(values))
    assert len(eff_lqr) == 100
    assert eff[-10:].mean() < 0.01 < 1.0 < eff_lqr[-10:].mean()
    # a zero-torque stride from where it settled returns there: the plant's passive cycle
    s = interval_model().scales
    r = nominal.run(zs[-1][None], np.zeros(1), aux=heavy_aux(values))
    assert np.max(np.abs(r.z1[0] - zs[-1]) / s) < 1e-2
    assert np.max(np.abs(zs[-1] - Z_STAR) / s) > 0.1  # and it is not z*


def test_state_is_per_robot_and_reset_between_episodes(lqr, nominal):
    of = OffsetFree(lqr)
    aux = np.concatenate([heavy_aux(), make_aux(load_gait("default").params.to_array())[None]])
    state = of.start(2)
    Z = np.tile(Z_STAR, (2, 1))
    for _ in range(5):
        A = of.plan_actions(state, Z)
        Z = nominal.run(Z, A, aux=aux).z1
    assert np.any(state.d[0] != 0.0) and np.all(state.d[1] == 0.0)
    # the step protocol: an episode on the heavy plant, then reset
    env = gym.make("PassiveBound-v0", gait_overrides=HEAVY, **of.env_kwargs).unwrapped
    policy = PlainPolicy(of)
    obs, info = env.reset(options={"apex_state": Z_STAR})
    for _ in range(200):
        obs, _, term, _, info = env.step(policy(obs, info))
        if term:
            break
    assert np.any(of.offset != 0.0)
    policy.restart()  # a new episode forgets the plant
    assert np.all(of.offset == 0.0) and not of.state.has_prev.any()
    of.on_apex(Z_STAR + 0.01, 0.0)
    of.reset()
    assert of._z is None and np.all(of.offset == 0.0)


def test_step_protocol_holds_the_same_cycle_as_the_batched_one(lqr, nominal):
    """The env loop (ClosedLoop, one control interval at a time, ``on_apex`` / ``__call__``)
    and the batched plan settle on the same cycle of the heavier plant; ``run`` is an
    episode (the estimate starts afresh)."""
    from bound_env.analysis.margins.closed_loop import ClosedLoop

    of = OffsetFree(lqr)
    loop = ClosedLoop(of, "default", HEAVY)
    assert loop.stride_map is None  # stateful: stepped through the env, not the batched map
    ok, _, fail = loop.run(Z_STAR, Z_STAR, 6, survive_only=True)
    assert ok and fail is None and np.any(of.offset != 0.0)
    d6 = of.offset
    loop.run(Z_STAR, Z_STAR, 6, survive_only=True)
    np.testing.assert_array_equal(of.offset, d6)  # the same episode again
    of.reset()
    z = Z_STAR.copy()
    for _ in range(100):
        out = loop.next_stride(z)  # one episode (``stride`` starts each afresh)
        assert out.z1 is not None
        z = out.z1
    zs, eff, _ = run(OffsetFree(lqr), nominal, 100, heavy_aux())
    assert out.effort < 0.05 and eff[-1] < 0.05
    assert np.max(np.abs(z - zs[-1]) / interval_model().scales) < 1e-2


def test_loading_by_name_and_spec(lqr):
    from agents.runtime.policy import load_controller as load_policy

    for name in ("lqr+of", "lqr-of"):
        c = load_controller(name)
        assert isinstance(c, OffsetFree) and c.name == name
        np.testing.assert_array_equal(c.inner.gain, lqr.gain)
        assert is_controller(name)
        assert isinstance(load_policy(name), OffsetFree)
    assert load_controller("lqr-of").fingerprint() != load_controller("lqr").fingerprint()
    learned = load_policy("default+of")  # the learned controller, wrapped
    assert isinstance(learned, OffsetFree) and learned.name == "default+of"
    state = learned.start(2)
    assert np.all(learned.plan_actions(state, np.tile(Z_STAR, (2, 1))) == 0.0)
    from agents.runtime.rollout import load_policy as rollout_policy

    make, act = rollout_policy("default+of")  # the plain loop, through the base's env
    env = make()
    obs, info = env.reset(options={"apex_state": Z_STAR})
    assert act(obs, info)[0] == 0.0 and isinstance(act.controller, OffsetFree)
    env.close()
    mpc = load_policy("mpc+of")
    assert mpc.inner.decision_kinds == [] and mpc.inner.decision_seconds == []
    d = load_policy("deadbeat+of")
    assert isinstance(d, OffsetFree) and d.inner.kind == "deadbeat"
    assert not is_controller("nonsense+of")
    with pytest.raises(ValueError, match="not a stride controller"):
        load_policy("damping+of")
    with pytest.raises(FileNotFoundError):
        load_policy("nonsense+of")


@pytest.mark.parametrize(
    "block, match",
    [
        ("offset_free: 3", "offset_free must be true or a mapping"),
        ("offset_free: {gain: 0}", "offset_free.gain"),
        ("offset_free: {gain: 2}", "offset_free.gain"),
        ("offset_free: {max_shift: -1}", "offset_free.max_shift"),
        ("offset_free: {foo: 1}", "unknown key 'foo' in offset_free"),
        ("offset_free: {estimator: kalman}", "offset_free.estimator must be one of"),
    ],
)
def test_bad_offset_free_block(tmp_path, block, match):
    p = tmp_path / "bad.yaml"
    p.write_text(f"controller: lqr\nK: 8\n{block}\n")
    with pytest.raises(ValueError, match=match):
        load_controller(str(p))


def test_a_spec_with_offset_free_true(tmp_path):
    p = tmp_path / "of.yaml"
    p.write_text("controller: lqr\nK: 8\nR: 0.1\noffset_free: true\n")
    c = load_controller(str(p))
    assert isinstance(c, OffsetFree) and c.name == "of"
    p.write_text("controller: lqr\nK: 8\noffset_free: {estimator: innovation, gain: '0.3'}\n")
    c = load_controller(str(p))
    assert c.estimator == "innovation" and c.gain == 0.3 and c.max_shift == 1.0
    p.write_text("controller: lqr\nK: 8\noffset_free: false\n")
    assert not isinstance(load_controller(str(p)), OffsetFree)
