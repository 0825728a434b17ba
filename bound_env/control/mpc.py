"""Model-predictive stride controller: shooting over the next stride's torque profile.

At each apex z the controller chooses the coefficients u (in the LQR's basis, K windows of
the nominal stride) of the coming stride:

- **near the cycle** (normalized error max|(z - z*) / s| at most ``safe``) it is the LQR, so
  the cycle keeps zero torque and the LQR's e_max;
- **further out** it first tries the LQR's own plan; if the LQR then comes back within
  ``horizon`` strides that plan is kept. Otherwise it searches: a library of profiles (the
  LQR's plan, zero, +-max, every one-switch bang-bang profile, ``n_random`` random sign
  vectors, ``n_noise`` LQR plans plus N(0, ``noise``)), then ``cem_iters`` rounds of
  cross-entropy refinement around the best ``cem_elites``. Each candidate stride is followed
  by the LQR for up to ``horizon`` strides.

A candidate's score puts a **return** first (the normalized error falls to ``safe`` or below:
sooner is better), then **survival** of the whole horizon (a smaller final error is better),
then the **progress** of a fall (strides and the fraction of a stride survived).

The model is the plant itself: the one stride map (`bound_env.stride_map`), the step env's
own kernel, which holds the profile's average over each control interval [k dt, (k + 1) dt]
from the apex, as a stride-level controller outputs it (`bound_env.control.controllers`), at
the planning tolerance ``rtol``. So a plan holds in `margins`. Random candidates come from a
generator seeded by the bytes of z: the controller is a deterministic function of the apex
state. Every decision is timed (`decision_seconds`).
"""

from __future__ import annotations

import hashlib
import time
from dataclasses import dataclass, field

import numpy as np

from ..dynamics import jit, make_aux
from ..events import APEX, N_FLAGS
from ..params import Z_IN_Y
from ..stride_map import NO_KICK, StrideMap, interval_weights, stride
from ..task import N_S, reset_at_apex
from .controllers import (
    OBS_TIME,
    OBS_Z,
    StrideFeedback,
    grid_times,
    interval_actions_of,
)

_Z_IDX = np.array(Z_IN_Y, dtype=np.int64)
RETURNED, SURVIVED, FELL = 2, 1, 0  # a candidate's outcome, best first
# Who made a decision (``decision_kinds``): "gate" (within ``safe``: the LQR alone), "lqr"
# (past it, the LQR's own plan kept: it returns on the planning model, or a learned chooser
# picked it) and "override" (a searched or chosen profile instead of the LQR's plan).
DECISION_KINDS = ("gate", "lqr", "override")


@jit
def rollouts(
    z0, cand, aux0, cfg, n_obs, n_apex, W, G, z_ref, scales, horizon, safe, period, n_max
):
    """Every candidate's first stride (interval actions ``cand[c]``) from the apex z0, then
    the LQR u = clip(-G (z - z*), -1, 1) (interval actions W u) for up to ``horizon``
    strides, each a stride of the one stride map (`bound_env.stride_map.stride`) with the
    task constants ``cfg``.

    Returns (outcome, strides, error, progress) per candidate: `RETURNED` when the normalized
    error max|(z - z*) / s| reached ``safe`` (``strides`` strides after z0), else `SURVIVED`
    (``error``: the final normalized error) or `FELL` (``progress``: strides completed plus
    the fraction of a nominal ``period`` survived in the last one)."""
    n_c = cand.shape[0]
    y = np.zeros(8)
    aux = aux0.copy()
    flags = np.zeros(N_FLAGS, dtype=np.bool_)
    s = np.zeros(N_S)
    apex = np.zeros((n_apex, 8))
    obs = np.zeros(n_obs, dtype=np.float32)
    z = np.empty(6)
    outcome = np.zeros(n_c, dtype=np.int64)
    strides = np.zeros(n_c, dtype=np.int64)
    error = np.full(n_c, np.inf)
    progress = np.zeros(n_c)
    for c in range(n_c):
        z[:] = z0
        a = cand[c].copy()
        for k in range(horizon + 1):
            reset_at_apex(y, aux, flags, s, obs, aux0, z, cfg)
            status, t = stride(y, aux, flags, s, apex, obs, cfg, a, NO_KICK, 0, 0.0, n_max)[:2]
            if status != APEX:
                outcome[c] = FELL
                progress[c] = k + min(t / period, 1.0)
                break
            strides[c] = k + 1
            e = 0.0
            dz = np.empty(6)
            for i in range(6):
                z[i] = apex[0, _Z_IDX[i]]
                dz[i] = z[i] - z_ref[i]
                e = max(e, abs(dz[i]) / scales[i])
            error[c] = e
            if not np.isfinite(e):
                outcome[c] = FELL
                progress[c] = k + 1.0
                break
            if e <= safe:
                outcome[c] = RETURNED
                break
            if k == horizon:
                outcome[c] = SURVIVED
                break
            u = -(G @ dz)
            for j in range(u.shape[0]):
                u[j] = min(1.0, max(-1.0, u[j]))
            a = W @ u
    return outcome, strides, error, progress


def scores(outcome, strides, error, progress, horizon: int) -> np.ndarray:
    """One number per candidate, larger is better: a return (sooner first) over a survival
    (smaller final error first) over a fall (more progress first)."""
    s = np.where(outcome == FELL, progress, 0.0)
    s = np.where(outcome == SURVIVED, horizon + 2.0 + 1.0 / (1.0 + error), s)
    return np.where(outcome == RETURNED, 2.0 * horizon + 10.0 - strides, s)


def library(K: int, u_lqr: np.ndarray, rng, n_random: int, n_noise: int, noise: float):
    """The candidate coefficients (rows): LQR, zero, +-1, the 2 (K - 1) one-switch bang-bang
    profiles, random sign vectors, LQR + N(0, noise) (clipped)."""
    rows = [u_lqr, np.zeros(K), np.ones(K), -np.ones(K)]
    for j in range(1, K):
        step = np.where(np.arange(K) < j, 1.0, -1.0)
        rows += [step, -step]
    rows += list(rng.choice([-1.0, 1.0], size=(n_random, K)))
    rows += list(np.clip(u_lqr + noise * rng.standard_normal((n_noise, K)), -1.0, 1.0))
    return np.array(rows, dtype=float)


@dataclass
class MPCController:
    """Shooting MPC on the stride map with the LQR as terminal controller (module docstring).

    Same protocol as `StrideFeedback`: ``on_apex(z, t)`` plans the stride, ``__call__(obs)``
    gives the interval average of the plan, ``stride_action(z)`` the plan's coefficients."""

    name: str
    lqr: StrideFeedback
    params: object  # bound_env.params.Params of the gait (the planning model)
    safe: float = 0.05  # normalized error at or below which the LQR acts alone
    horizon: int = 12  # LQR strides after a candidate stride
    n_random: int = 24
    n_noise: int = 24
    noise: float = 0.5
    cem_iters: int = 2
    cem_samples: int = 24
    cem_elites: int = 6
    rtol: float = 1e-8  # planning tolerance (the evaluation runs at 1e-10)
    seed: int = 0
    library_seed: int = -1  # >= 0: the library's random rows are fixed (drawn from this seed)
    decision_seconds: list = field(default_factory=list, repr=False)
    # who made each decision (`DECISION_KINDS`): the gate, the LQR's own plan, an override
    decision_kinds: list = field(default_factory=list, repr=False)
    _kind: str = field(default="gate", repr=False)
    _u: np.ndarray | None = field(default=None, repr=False)
    _t0: float = field(default=0.0, repr=False)  # time since the apex of the first interval

    def __post_init__(self):
        b = self.lqr.basis
        self._W = interval_weights(b.edges, b.phi, self.lqr.dt)
        self._aux0 = make_aux(self.params.to_array())
        # the planning model: the one stride map at the planning tolerance
        self.model = StrideMap(self.gait, None, self.dt, self.max_torque, self.rtol)
        from ..task import APEX_SCALES

        self.scales = np.asarray(APEX_SCALES, dtype=float)
        self.searches = 0  # decisions that searched beyond the LQR's own plan
        self.evaluate(self.z_ref, np.zeros((1, self.basis.K)))  # compile (or load) it now

    # -- the protocol of bound_env.control.controllers --------------------------------------
    gait = property(lambda self: self.lqr.gait)
    max_torque = property(lambda self: self.lqr.max_torque)
    dt = property(lambda self: self.lqr.dt)
    basis = property(lambda self: self.lqr.basis)
    z_ref = property(lambda self: self.lqr.z_ref)
    env_kwargs = property(lambda self: self.lqr.env_kwargs)
    stride_env_kwargs = property(lambda self: self.lqr.stride_env_kwargs)

    def profile_actions(self, U) -> np.ndarray:
        """Rows of coefficients -> their interval averages W u (the planning model's actions;
        `interval_actions` is the step env's view of a stride, bit for bit)."""
        return np.atleast_2d(U) @ self._W.T

    def evaluate(self, z, U):
        """`rollouts` of the coefficient rows U from the apex z: (scores, outcome, strides)."""
        task = self.model.task
        out = rollouts(
            np.asarray(z, dtype=float),
            self.profile_actions(U),
            self._aux0,
            task.cfg,
            task.obs_dim,
            task.apex_capacity,
            self._W,
            self.lqr.gain,
            self.z_ref,
            self.scales,
            self.horizon,
            self.safe,
            self.basis.period,
            self.model.n_max,
        )
        return scores(*out, self.horizon), out[0], out[1]

    def plan(self, z) -> np.ndarray:
        """The coefficients of the stride from apex z (the decision, untimed); for n apex
        states Z (n, 6) at once, (n, K), each row decided alone."""
        z = np.asarray(z, dtype=float)
        if z.ndim == 2:
            return np.array([self.plan(zi) for zi in z]).reshape(len(z), self.basis.K)
        u_lqr = self.lqr.coefficients(z)
        if np.max(np.abs(z - self.z_ref) / self.scales) <= self.safe:
            self._kind = "gate"
            return u_lqr
        _, outcome, _ = self.evaluate(z, u_lqr[None])
        if outcome[0] == RETURNED:
            self._kind = "lqr"
            return u_lqr
        self._kind = "override"
        self.searches += 1
        rng = np.random.default_rng(
            [self.seed, *np.frombuffer(z.tobytes(), dtype=np.uint32).tolist()]
        )
        K = self.basis.K
        lib_rng = rng if self.library_seed < 0 else np.random.default_rng(self.library_seed)
        U = library(K, u_lqr, lib_rng, self.n_random, self.n_noise, self.noise)
        s, outcome, _ = self.evaluate(z, U)
        best_u, best_s = U[int(np.argmax(s))], float(np.max(s))
        for _ in range(self.cem_iters):
            elite = U[np.argsort(-s)[: self.cem_elites]]
            mu, sd = elite.mean(axis=0), elite.std(axis=0) + 0.05
            U = np.clip(mu + sd * rng.standard_normal((self.cem_samples, K)), -1.0, 1.0)
            s, _, _ = self.evaluate(z, U)
            if float(np.max(s)) > best_s:
                best_u, best_s = U[int(np.argmax(s))], float(np.max(s))
        return best_u

    def coefficients(self, z) -> np.ndarray:
        t0 = time.perf_counter()
        u = self.plan(z)
        self.decision_seconds.append(time.perf_counter() - t0)
        self.decision_kinds.append(self._kind)
        return u

    def stride_action(self, z) -> np.ndarray:
        return self.coefficients(z)

    def interval_actions(self, Z) -> np.ndarray:
        """The step env's actions of the strides from the apex states Z: each plan's interval
        averages on the grid k dt (the protocol of `bound_env.control.controllers`)."""
        U = [self.coefficients(z) for z in np.atleast_2d(np.asarray(Z, dtype=float))]
        return interval_actions_of(self.basis, self.max_torque, U, grid_times(self.dt), self.dt)

    def apex_torques(self, z) -> np.ndarray:
        """The profile planned at apex state z: torque on each sub-window [N m]."""
        return self.basis.torques(self.coefficients(z), self.max_torque)

    snaps_time = True  # the observed time is snapped to the apex's interval grid (__call__)

    def on_apex(self, z, time_since_apex: float = 0.0) -> None:
        self._u = self.coefficients(z)
        self._t0 = float(time_since_apex)

    def __call__(self, obs) -> float:
        t = float(obs[OBS_TIME])
        if self._u is None:
            self.on_apex(np.asarray(obs, dtype=float)[list(OBS_Z)], t)
        # the observation's time is float32: snap it to the interval grid t0 + k dt that
        # started at the apex, so that the torque is exactly the planned one
        t = self._t0 + self.dt * round((t - self._t0) / self.dt)
        taus = self.basis.torques(self._u, self.max_torque)
        tau = self.basis.average(taus, t, t + self.dt)
        return float(np.clip(tau / self.max_torque, -1.0, 1.0))

    def settings(self) -> dict:
        keys = ("safe", "horizon", "n_random", "n_noise", "noise", "cem_iters", "cem_samples")
        keys += ("cem_elites", "rtol", "seed", "library_seed")
        return {k: getattr(self, k) for k in keys}

    def fingerprint(self) -> str:
        h = hashlib.sha256(b"mpc")
        h.update(self.lqr.fingerprint().encode())
        h.update(repr(sorted(self.settings().items())).encode())
        h.update(np.ascontiguousarray(self.params.to_array(), dtype=float).tobytes())
        return h.hexdigest()[:16]

    def __getstate__(self):  # the plan and the timings are not part of the controller
        state = dict(self.__dict__)
        state["_u"] = None
        state["decision_seconds"] = []
        state["decision_kinds"] = []
        return state
