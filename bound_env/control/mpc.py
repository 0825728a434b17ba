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

The model is the plant itself: the one stride map (`bound_env.sim.stride_map.StrideMap.run`), the
step env's own kernel, which holds the profile's average over each control interval
[k dt, (k + 1) dt] from the apex, as a stride-level controller outputs it
(`bound_env.control.controllers`), at the planning tolerance ``rtol``, with each run of equal
interval actions integrated as one segment (``segments``: the same strides to the integrator
tolerance, about half the cost); the LQR strides after a candidate are the LQR's own law
(``lqr.plan``). All live candidates advance together, one batch of strides per stride. So a
plan holds in `margins`.

The search is pruned where that cannot change the decision: the LQR's row of the library is
the plan already evaluated; candidates stop once enough others have returned sooner than they
still can (`rollouts`), the elites are taken in a stable order, and the cross-entropy rounds
are skipped when a candidate already returns after one stride (nothing scores higher).

Random candidates come from a generator seeded by the bytes of z: the controller is a
deterministic function of the apex state. Every decision is timed (`decision_seconds`).
"""

from __future__ import annotations

import hashlib
import time
from dataclasses import dataclass, field

import numpy as np

from ..model.events import APEX
from ..sim.stride_map import StrideMap
from ..sim.stride_protocol import (
    DECISION_KINDS,  # noqa: F401 - who decides (the protocol's)
    ProfileActions,
)
from .controllers import (
    OBS_TIME,
    OBS_Z,
    StrideFeedback,
    grid_times,
    interval_actions_of,
)

RETURNED, SURVIVED, FELL, PRUNED = 2, 1, 0, -1  # a candidate's outcome, best first
BEST_SCORE_STRIDES = 1  # a return after one stride: no candidate can score higher
# Who made a decision (``decision_kinds``): "gate" (within ``safe``: the LQR alone), "lqr"
# (past it, the LQR's own plan kept: it returns on the planning model, or a learned chooser
# picked it) and "override" (a searched or chosen profile instead of the LQR's plan).


def rollouts(
    model, z0, A0, lqr, profile_actions, scales, horizon, safe, period, prune=0, floor=-np.inf
):
    """Every candidate's first stride (interval actions ``A0[c]``) from the apex z0, then the
    LQR's own law (``lqr.plan``: u = clip(-G (z - z*), -1, 1), interval actions
    ``profile_actions(u)``) for up to ``horizon`` strides: all live candidates advanced
    together, one batch of strides of the planning map ``model`` per stride (`StrideMap.apexes`,
    the core of `StrideMap.run`).

    Returns (outcome, strides, error, progress, z_first) per candidate: `RETURNED` when the
    normalized error max|(z - z*) / s| reached ``safe`` (``strides`` after z0), else `SURVIVED`
    (``error``: the final normalized error) or `FELL` (``progress``: strides completed plus
    the fraction of a nominal ``period`` survived in the last one); ``z_first``: the apex
    state after the candidate's own stride (NaN where it fell). ``prune`` > 0: once that
    many candidates have returned, the others can no longer be among the ``prune`` best
    (`scores`: a later return scores lower), so they stop there as `PRUNED`; so do those whose
    best possible score (a return at the next stride) is at most ``floor``."""
    n_c = A0.shape[0]
    outcome = np.full(n_c, FELL, dtype=np.int64)
    strides = np.zeros(n_c, dtype=np.int64)
    error = np.full(n_c, np.inf)
    progress = np.zeros(n_c)
    z_first = np.full((n_c, 6), np.nan)
    live = np.arange(n_c)
    Z = np.tile(np.asarray(z0, dtype=float), (n_c, 1))
    A = A0
    z_ref = lqr.z_ref
    for k in range(horizon + 1):
        status, t, z1 = model.apexes(Z, A)
        ok = status == APEX
        fell = ~ok
        progress[live[fell]] = k + np.minimum(t[fell] / period, 1.0)
        rows, Z = live[ok], z1[ok]
        if k == 0:
            z_first[rows] = Z
        strides[rows] = k + 1
        e = np.max(np.abs(Z - z_ref) / scales, axis=1)
        error[rows] = e
        bad = ~np.isfinite(e)
        progress[rows[bad]] = k + 1.0
        back = ~bad & (e <= safe)
        outcome[rows[back]] = RETURNED
        go = ~bad & ~back
        if k == horizon:
            outcome[rows[go]] = SURVIVED
            break
        live, Z = rows[go], Z[go]
        if (prune > 0 and np.count_nonzero(outcome == RETURNED) >= prune) or (
            return_score(k + 2, horizon) <= floor
        ):
            outcome[live] = PRUNED
            break
        if not len(live):
            break
        A = profile_actions(lqr.plan(Z))
    return outcome, strides, error, progress, z_first


def scores(outcome, strides, error, progress, horizon: int) -> np.ndarray:
    """One number per candidate, larger is better: a return (sooner first) over a survival
    (smaller final error first) over a fall (more progress first); a pruned candidate (it
    scores below the pruning rank, `rollouts`) -inf."""
    s = np.where(outcome == FELL, progress, -np.inf)
    s = np.where(outcome == SURVIVED, horizon + 2.0 + 1.0 / (1.0 + error), s)
    return np.where(outcome == RETURNED, return_score(strides, horizon), s)


def return_score(strides, horizon: int):
    """The score of a return after ``strides`` strides (`scores`)."""
    return 2.0 * horizon + 10.0 - strides


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
    params: object  # bound_env.model.params.Params of the gait (the planning model)
    safe: float = 0.05  # normalized error at or below which the LQR acts alone
    horizon: int = 12  # LQR strides after a candidate stride
    n_random: int = 24
    n_noise: int = 24
    noise: float = 0.5
    cem_iters: int = 2
    cem_samples: int = 24
    cem_elites: int = 6
    rtol: float = 1e-8  # planning tolerance (the evaluation runs at 1e-10)
    # planning map: runs of equal interval actions integrated as one segment (`StrideMap`)
    segments: bool = True
    # a return ends the search (the first stride at which a candidate returns: the soonest
    # return of the round so far); False: the elites of every round are ranked in full
    early_exit: bool = False
    # > 0: the library's first ``screen`` rows (the LQR's plan first) are tried alone first;
    # when each of them falls within its first stride, before ``hopeless`` x the nominal
    # stride period, the state is given up (the plan: the one of them that falls latest)
    screen: int = 0
    hopeless: float = 0.75
    seed: int = 0
    library_seed: int = -1  # >= 0: the library's random rows are fixed (drawn from this seed)
    decision_seconds: list = field(default_factory=list, repr=False)
    # who made each decision (`DECISION_KINDS`): the gate, the LQR's own plan, an override
    decision_kinds: list = field(default_factory=list, repr=False)
    _kind: str = field(default="gate", repr=False)
    _u: np.ndarray | None = field(default=None, repr=False)
    _t0: float = field(default=0.0, repr=False)  # time since the apex of the first interval

    def __post_init__(self):
        # rows of coefficients -> their interval averages W u (the planning model's actions;
        # `interval_actions` is the step env's view of a stride, bit for bit)
        self.profile_actions = ProfileActions(self.lqr.basis, self.lqr.dt)
        # the planning model: the one stride map at the planning tolerance
        self.model = StrideMap(
            self.gait, None, self.dt, self.max_torque, self.rtol, segments=self.segments
        )
        from ..sim.task import APEX_SCALES

        self.scales = np.asarray(APEX_SCALES, dtype=float)
        self.searches = 0  # decisions that searched beyond the LQR's own plan
        self.given_up = 0  # searches that ended at the screen (every screened profile fell)
        self.evaluate(self.z_ref, np.zeros((1, self.basis.K)))  # compile (or load) it now

    # -- the protocol of bound_env.control.controllers --------------------------------------
    gait = property(lambda self: self.lqr.gait)
    max_torque = property(lambda self: self.lqr.max_torque)
    dt = property(lambda self: self.lqr.dt)
    basis = property(lambda self: self.lqr.basis)
    z_ref = property(lambda self: self.lqr.z_ref)
    env_kwargs = property(lambda self: self.lqr.env_kwargs)
    stride_env_kwargs = property(lambda self: self.lqr.stride_env_kwargs)

    def evaluate(self, z, U, prune: int = 0, floor: float = -np.inf):
        """`rollouts` of the coefficient rows U from the apex z: (scores, outcome, strides)
        (``prune``, ``floor``: see `rollouts`)."""
        out = self.rollouts(z, U, prune, floor)
        return scores(*out[:4], self.horizon), out[0], out[1]

    def rollouts(self, z, U, prune: int = 0, floor: float = -np.inf):
        """`rollouts` of the coefficient rows U from the apex z on the planning model: the
        path of every decision (`evaluate`)."""
        return rollouts(
            self.model,
            np.asarray(z, dtype=float),
            self.profile_actions(U),
            self.lqr,
            self.profile_actions,
            self.scales,
            self.horizon,
            self.safe,
            self.basis.period,
            prune,
            floor,
        )

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
        s0, outcome, strides = self.evaluate(z, u_lqr[None])
        if outcome[0] == RETURNED:
            self._kind = "lqr"
            return u_lqr
        self._kind = "override"
        self.searches += 1
        rng = np.random.default_rng(
            [self.seed, *np.frombuffer(z.tobytes(), dtype=np.uint32).tolist()]
        )
        lib_rng = rng if self.library_seed < 0 else np.random.default_rng(self.library_seed)
        U = library(self.basis.K, u_lqr, lib_rng, self.n_random, self.n_noise, self.noise)
        return self._search(z, U, s0, outcome[0] == FELL and strides[0] == 0, rng)

    def _search(self, z, U, s0, lqr_falls_at_once: bool, rng) -> np.ndarray:
        """The library U (row 0: the LQR's plan, already scored ``s0``), then the
        cross-entropy rounds (module docstring): the best row's coefficients."""
        K = self.basis.K
        # candidates each round must rank exactly: the elites of the next round, or only the
        # best (no rounds, or ``early_exit``: a return ends the search). Those below are
        # pruned: the same elites and best, exactly
        top = 1 if self.early_exit or self.cem_iters == 0 else self.cem_elites
        n_a = min(self.screen, len(U)) if self.screen > 0 else len(U)
        s, outcome, strides = self.evaluate(z, U[1:n_a], prune=top)
        s = np.concatenate([s0, s])
        returned = bool(np.any(outcome == RETURNED))
        falls_at_once = lqr_falls_at_once and np.all((outcome == FELL) & (strides == 0))
        if self.screen > 0 and falls_at_once and float(np.max(s)) < self.hopeless:
            # every screened profile falls early in the stride (a fall's score: the fraction
            # of the nominal period survived): hopeless
            self.given_up += 1
            return U[int(np.argmax(s))]
        if n_a < len(U) and not (self.early_exit and returned):
            s1, outcome, _ = self.evaluate(z, U[n_a:], prune=top)
            s = np.concatenate([s, s1])
            returned = returned or bool(np.any(outcome == RETURNED))
        U = U[: len(s)]
        order = np.argsort(-s, kind="stable")
        best_u, best_s = U[order[0]], float(s[order[0]])
        for it in range(self.cem_iters):
            if best_s >= self.best_score or (self.early_exit and returned):
                break  # nothing scores higher, or a return ends the search
            elite = U[order[: self.cem_elites]]
            mu, sd = elite.mean(axis=0), elite.std(axis=0) + 0.05
            U = np.clip(mu + sd * rng.standard_normal((self.cem_samples, K)), -1.0, 1.0)
            last = it == self.cem_iters - 1
            # the last round only has to beat the best so far (strictly)
            s, outcome, _ = self.evaluate(
                z,
                U,
                prune=1 if last or self.early_exit else self.cem_elites,
                floor=best_s if last else -np.inf,
            )
            returned = bool(np.any(outcome == RETURNED))
            order = np.argsort(-s, kind="stable")
            if float(s[order[0]]) > best_s:
                best_u, best_s = U[order[0]], float(s[order[0]])
        return best_u

    @property
    def best_score(self) -> float:
        """The score of a return after one stride (`scores`): no candidate scores higher."""
        return return_score(BEST_SCORE_STRIDES, self.horizon)

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

    def planned_profile(self):
        """(taus [N m], t0) of the last apex's plan, as ``__call__`` reads it (None before the
        first apex; `bound_env.sim.stride_protocol.profile_rows`)."""
        if self._u is None:
            return None
        memo = self.__dict__.get("_profile_memo")  # this plan's torques, made once per apex
        if memo is None or memo[0] is not self._u:
            memo = self._profile_memo = (self._u, self.basis.torques(self._u, self.max_torque))
        return memo[1], self._t0

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
        # the search's shortcuts, named only when on: the full search's settings (and its
        # fingerprint) are what they were before the shortcuts existed
        keys += tuple(k for k in ("early_exit", "screen") if getattr(self, k))
        keys += ("hopeless",) if self.screen else ()
        return {k: getattr(self, k) for k in keys}

    def fingerprint(self) -> str:
        h = hashlib.sha256(b"mpc")
        h.update(self.lqr.fingerprint().encode())
        h.update(repr(sorted(self.settings().items())).encode())
        h.update(np.ascontiguousarray(self.params.to_array(), dtype=float).tobytes())
        if not self.segments:  # the per-interval planning map
            h.update(b"per-interval")
        return h.hexdigest()[:16]

    def __getstate__(self):  # the plan and the timings are not part of the controller
        state = dict(self.__dict__)
        state["_u"] = None
        state["decision_seconds"] = []
        state["decision_kinds"] = []
        return state
