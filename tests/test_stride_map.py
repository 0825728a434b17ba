"""The one stride map (bound_env.sim.stride_map): a stride of the step env, bit for bit; the batch
is the single robot; and everything that advances a stride under a profile lands on the same apex
for the same (z, u): the stride env, the MPC's planning model, distillation, fine-tuning and
margins' closed loop, on one-switch bang-bang rows from r = 0.1 starts."""

import gymnasium as gym
import numpy as np
import pytest

import bound_env
from bound_env.analysis.margins import ClosedLoop, random_directions
from bound_env.control import load_controller
from bound_env.sim.stride_map import (
    EVAL_RTOL,
    NO_KICK,
    StrideMap,
    interval_weights,
    max_intervals,
)

gym.register_envs(bound_env)
K = 8  # the LQR's basis: 8 windows of the nominal stride


@pytest.fixture(scope="module")
def lqr():
    return load_controller("lqr")


def bang_bang_rows(k: int) -> np.ndarray:
    """+-1 everywhere and every one-switch profile, both signs."""
    rows = [np.ones(k), -np.ones(k)]
    for j in range(1, k):
        for sign in (1.0, -1.0):
            u = np.full(k, sign)
            u[j:] = -sign
            rows.append(u)
    return np.array(rows)


def starts(z_star, n: int, r: float = 0.1, seed: int = 777) -> np.ndarray:
    """Apex states at relative size r along validation directions (not the test set's)."""
    return z_star + r * np.abs(z_star) * random_directions(n, seed)


def env_stride(z, a, max_torque=80.0):
    """PassiveBound-v0 started at the apex z, interval k stepped with a[min(k, len - 1)]."""
    env = gym.make("PassiveBound-v0", max_torque=max_torque, rtol=EVAL_RTOL).unwrapped
    env.reset(options={"apex_state": z})
    for k in range(max_intervals(env.task.dt)):
        _, _, terminated, _, info = env.step(np.array([a[min(k, len(a) - 1)]]))
        if "apex_z" in info:
            return info["apex_z"]
        if terminated:
            return None
    return None


def test_a_stride_is_the_step_envs_and_the_batch_is_the_single_robot(lqr):
    W = interval_weights(lqr.basis.edges, lqr.basis.phi, lqr.dt)
    sm = StrideMap("default", None, lqr.dt, 80.0)
    Z = np.concatenate([starts(lqr.z_ref, 2), starts(lqr.z_ref, 2, r=0.5)])  # some fall
    rows = bang_bang_rows(K)[::3]
    ZZ = np.repeat(Z, len(rows), axis=0)
    A = np.tile(rows, (len(Z), 1)) @ W.T
    batch = sm.run(ZZ, A)
    assert batch.ok.sum() > len(ZZ) // 2 and (~batch.ok).sum() > 0  # both outcomes occur
    for i in range(len(ZZ)):
        one = sm.run(ZZ[i][None], A[i][None])
        assert one.status[0] == batch.status[i]
        np.testing.assert_array_equal(one.z1[0], batch.z1[i])
        z1 = env_stride(ZZ[i], A[i])
        if batch.ok[i]:
            np.testing.assert_array_equal(batch.z1[i], z1)  # the step env's own kernel
        else:
            assert z1 is None and batch.failure(i) is not None


def test_kicks_and_slopes_are_the_envs(lqr):
    sm = StrideMap("default", None, lqr.dt, 80.0)
    z = lqr.z_ref
    a = np.zeros(1)
    kicked = sm.run(z[None], a[None], kicks=[(7, 4, 0.3)])
    env = gym.make("PassiveBound-v0", max_torque=80.0, rtol=EVAL_RTOL).unwrapped
    env.reset(options={"apex_state": z})
    for k in range(100):
        if k == 7:
            env.kick([0.3, 0.0, 0.0, 0.0])
        info = env.step(np.zeros(1))[4]
        if "apex_z" in info:
            break
    np.testing.assert_array_equal(kicked.z1[0], info["apex_z"])
    assert np.max(np.abs(kicked.z1[0] - sm.map(z, a))) > 1e-3  # the kick changed the stride
    np.testing.assert_array_equal(
        sm.run(z[None], a[None], kicks=[(NO_KICK, 4, 9.0)]).z1[0], sm.map(z, a)
    )
    # rough terrain: the stride env's slope change at the apex goes through the same map
    senv = gym.make("PassiveBoundStride-v1", K=K, max_torque=80.0).unwrapped
    alpha = senv.params.alpha
    out = senv.task.sim.run(z, np.zeros(K), slope=(alpha, alpha + 0.01))
    tilted = sm.run(z[None], a[None], slopes=[(alpha, alpha + 0.01)])
    np.testing.assert_array_equal(out.z1, tilted.z1[0])


PLAN_ATOL = 100.0  # x the planning rtol: the MPC's planning path (segments) against the plant


def test_every_user_of_a_stride_lands_on_the_same_apex(lqr):
    """The acceptance of "one stride map": the stride env, distillation's and fine-tuning's
    plant and margins' closed loop, for the same (z, u), on bang-bang rows from r = 0.1
    starts, agree to 1e-9; the MPC's own planning path (`MPCController.rollouts`, the call of
    every decision: its planning map at the planning tolerance, segments) to `PLAN_ATOL` x
    that tolerance."""
    from agents.experts.distill import plant_of, stride_of
    from agents.experts.finetune import rescue_env
    from agents.runtime.policy import load_controller as load_policy

    mpc = load_controller("mpc")
    student = load_policy("default")
    plant = plant_of(mpc)
    stride_env = gym.make("PassiveBoundStride-v1", basis="windows", K=K, max_torque=80.0)
    stride_env = stride_env.unwrapped
    finetune_env = rescue_env(student)  # PassiveBoundRescue-v0 + LibraryActions
    rows = bang_bang_rows(K)
    lib = {tuple(r): i for i, r in enumerate(student.rows) if i > 0}  # 0: the LQR's plan
    compared = {"stride env": 0, "mpc": 0, "distill": 0, "finetune": 0, "margins": 0}
    fell = 0
    for z in np.concatenate([starts(lqr.z_ref, 3), starts(lqr.z_ref, 1, r=0.5)]):
        for u in rows:
            a = mpc.profile_actions(u)[0]
            ref = env_stride(z, a)  # the plant: PassiveBound-v0
            stride_env.reset(options={"apex_state": z})
            info = stride_env.step(u.astype(np.float32))[4]
            got = {
                "stride env": info.get("apex_z"),
                "mpc": mpc_first_apex(mpc, z, u),
                "distill": stride_of(mpc, plant, z, u),
                "margins": ClosedLoop(Fixed(lqr, u), "default").stride(z).z1,
            }
            if tuple(u) in lib:  # a library row: the fine-tuning env's action
                finetune_env.reset(options={"apex_state": z})
                _, _, done, _, step_info = finetune_env.step(lib[tuple(u)])
                got["finetune"] = None if step_info["fell"] else finetune_env.unwrapped.z
            if ref is None:
                fell += 1
            for name, z1 in got.items():
                compared[name] += 1
                if ref is None:
                    assert z1 is None, name
                else:
                    atol = PLAN_ATOL * mpc.rtol if name == "mpc" else 1e-9
                    np.testing.assert_allclose(z1, ref, rtol=0, atol=atol, err_msg=name)
    assert fell > 0 and all(n >= 8 for n in compared.values()), compared


def mpc_first_apex(mpc, z, u):
    """The apex after the candidate u's own stride on the MPC's planning path (None: fell)."""
    outcome, strides, _, _, z_first = mpc.rollouts(z, u[None])
    return None if strides[0] == 0 else z_first[0]


def test_segments_agree_with_the_per_interval_stride(lqr):
    """The planning option (`StrideMap(segments=True)`: runs of equal interval actions as one
    segment, stopping at the apex) gives the same outcomes as the step env's per-interval
    stride and the same apex to the integrator tolerance, and it does merge intervals (it is
    not the per-interval path: the results differ above round-off). At the planning tolerance
    (1e-8, 1e-6) a marginal stride's outcome may differ (a brief leg overcompression stepped over):
    at most 1 in 100 here, and none at the evaluation tolerance."""
    W = interval_weights(lqr.basis.edges, lqr.basis.phi, lqr.dt)
    rows = np.concatenate([bang_bang_rows(K), np.random.default_rng(0).uniform(-1, 1, (8, K))])
    Z = np.concatenate([starts(lqr.z_ref, 3), starts(lqr.z_ref, 3, r=0.4)])
    ZZ, A = np.repeat(Z, len(rows), axis=0), np.tile(rows, (len(Z), 1)) @ W.T
    for rtol, atol in ((EVAL_RTOL, 1e-7), (1e-8, PLAN_ATOL * 1e-8), (1e-6, PLAN_ATOL * 1e-6)):
        per = StrideMap("default", None, lqr.dt, 80.0, rtol).run(ZZ, A)
        seg = StrideMap("default", None, lqr.dt, 80.0, rtol, segments=True).run(ZZ, A)
        assert per.ok.sum() > len(ZZ) // 2 and (~per.ok).sum() > 0  # both outcomes occur
        same = seg.status == per.status
        assert same.all() if rtol == EVAL_RTOL else (~same).sum() <= len(ZZ) // 100
        ok = same & per.ok
        np.testing.assert_allclose(seg.z1[ok], per.z1[ok], rtol=0, atol=atol)
        np.testing.assert_allclose(seg.period[ok], per.period[ok], rtol=0, atol=atol)
        assert np.max(np.abs(seg.z1[ok] - per.z1[ok])) > 1e-12
    with pytest.raises(ValueError, match="segments"):
        StrideMap(segments=True).run(Z[:1], A[:1], kicks=[None])


class Fixed:
    """A stride controller with one fixed profile u: the LQR's protocol, its plan u."""

    def __init__(self, lqr, u):
        self.lqr, self.u = lqr, np.asarray(u, dtype=float)
        self.env_kwargs = lqr.env_kwargs
        self.basis, self.max_torque, self.dt = lqr.basis, lqr.max_torque, lqr.dt

    def coefficients(self, z):
        return self.u

    def interval_actions(self, Z):
        from bound_env.control.controllers import grid_times, interval_actions_of

        U = np.tile(self.u, (len(np.atleast_2d(Z)), 1))
        return interval_actions_of(self.basis, self.max_torque, U, grid_times(self.dt), self.dt)


def test_stride_controllers_plan_for_n_apex_states_at_once(lqr):
    from agents.runtime.policy import load_controller as load_policy

    Z = np.concatenate([starts(lqr.z_ref, 6, r=0.02), starts(lqr.z_ref, 6, r=0.3)])
    U = lqr.plan(Z)
    assert U.shape == (len(Z), K)
    np.testing.assert_allclose(U, [lqr.coefficients(z) for z in Z], rtol=0, atol=1e-12)
    default = load_policy("default")
    U = default.plan(Z)
    np.testing.assert_array_equal(U, [default.plan(z) for z in Z])
    assert np.any(U != lqr.plan(Z))  # the network overrides the LQR somewhere out there
    mpc = load_controller("mpc")
    np.testing.assert_array_equal(mpc.plan(Z[5:7]), [mpc.plan(Z[5]), mpc.plan(Z[6])])
    # and their step env actions for n states at once are those of one state at a time
    A = default.interval_actions(Z[:3])
    assert A.shape == (3, max_intervals(default.dt))
    np.testing.assert_array_equal(A[1], default.interval_actions(Z[1])[0])


def test_bad_input_is_refused_with_a_one_line_error(lqr):
    sm = StrideMap("default", None, lqr.dt, 80.0)
    z = lqr.z_ref
    for Z, A, kicks, msg in (
        (z[None, :5], np.zeros((1, 3)), None, "Z must be"),
        (z[None], np.zeros((2, 3)), None, "A"),
        (np.full((1, 6), np.nan), np.zeros((1, 3)), None, "finite"),
        (z[None], np.full((1, 3), np.inf), None, "finite"),
        (z[None], np.zeros((1, 3)), [(3, 2, 0.1)], "kick"),
    ):
        with pytest.raises(ValueError, match=msg):
            sm.run(Z, A, kicks=kicks)
