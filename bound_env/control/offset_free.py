"""Offset-free stride control: any stride controller held on the plant's own cycle.

The classical designs and the learned controllers drive the apex state z toward the nominal
fixed point z* of the model. A robot whose parameters differ from the model's by a few percent
has its own cycle elsewhere (or none near z* that is stable), and a controller that insists on
z* burns torque to hold a gait the robot cannot hold passively, and falls. `OffsetFree` wraps
any stride controller (the protocol of `bound_env.control.controllers`) and moves its target
to the plant's own cycle, estimated from the apex map the robot shows (offset-free control
with a constant disturbance observer):

- the nominal model, linearized at (z*, a = 0) in the step env's **interval actions** a (so
  that it takes any controller's profile, whatever its basis):
  `z_{k+1} - z* ~ A (z_k - z*) + B a_k + d`, with d a constant offset, zero on the nominal
  plant (`interval_model`);
- the target is the cycle on which the plant needs no steady torque,
  z_ss = z* + (I - A)^-1 d^ (its normalized shift max |z_ss - z*|_i / s_i limited to
  ``max_shift``; s: the apex scales), and the inner controller is fed z - z_ss + z*: it acts
  on the error from z_ss as it acts on the error from z*;
- at each apex the estimate d^ is updated from the last stride, by one of two estimators:

  ``innovation`` (a disturbance observer): e = (z_{k+1} - z*) - A (z_k - z*) - B a_k - d^,
  d^ <- d^ + L e. At a fixed point z_f, d^ = (I - A)(z_f - z*) - B a_f, so
  z_f - z_ss = (I - A)^-1 B a_f, and for the LQR a_f = -K (z_f - z_ss), hence
  (I + K (I - A)^-1 B) a_f = 0: a_f = 0.

  ``torque`` (the default, chosen on validation plants): the steady torque is integrated
  away, d^ <- d^ - L (I - A) H^+ a_k, i.e. the target moves by -L H^+ a_k, where
  H = (I + K (I - A)^-1 B)^-1 K is the model's steady torque a = -H (z_p - z_ss) with which
  the inner loop (its gain K = -da/dz at z*) holds a target z_ss off the plant's passive
  cycle z_p. The target stops only where the torque is zero. It reads only the torques the
  inner controller chose, not the model's one-stride prediction, whose error on a
  mismatched plant the innovation estimator takes for an offset and chases.

  Updates with max |e_i / s_i| <= ``deadband`` are not made, so that the integrator's
  round-off on the nominal cycle (1e-10) leaves d^ exactly 0: on the nominal plant from z*
  the wrapped controller is the inner one, bit for bit, and its torque at z* exactly zero.

Either way the loop can settle only on a cycle that needs no torque, stable or not for the
passive robot (the inner controller stabilizes it), as long as the target stays within
``max_shift``; beyond, it holds the limited target with a steady torque.

State. The wrapper remembers, per robot, d^ and the last stride's apex state and actions. The
step protocol (``on_apex`` / ``__call__``, `PlainPolicy`, `ClosedLoop` in its env loop) keeps
one robot's state; ``reset()`` forgets it (`PlainPolicy.restart`, `ClosedLoop.run` and
``episode`` call it at each start, the batched loop `bound_env.analysis.apex_loop.interval_loop`
on each robot's copy). Batched loops keep one `OffsetFreeState` per batch
(``start(n)``) and call ``plan_actions(state, Z, rows)``. The wrapper has no stateless
``interval_actions``: the margins' batched stride path assumes a memoryless controller, so a
`ClosedLoop` steps it through the env instead.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from ..files.schema import real
from ..sim.stride_map import StrideMap, max_intervals
from .controllers import OBS_TIME
from .design import DESIGN_RTOL, FD_FLOOR_Z, FD_REL_Z, FD_U

# the wrapper's settings and their defaults (`offset_free` in a spec; `+of` on a name);
# chosen on the validation plants (seed 777, scripts/hold_eval.py; docs/controllers.md)
OF_DEFAULTS = {"estimator": "torque", "gain": 0.1, "deadband": 1e-7, "max_shift": 1.0}
ESTIMATORS = ("torque", "innovation")
OF_LIMITS = {"gain": (0.0, 1.0), "deadband": (0.0, 1.0), "max_shift": (0.0, 100.0)}
SUFFIX = "+of"  # ``--policy NAME+of``: NAME wrapped in `OffsetFree` with `OF_DEFAULTS`


@dataclass(frozen=True)
class IntervalModel:
    """The nominal stride map linearized at (z*, a = 0) in the interval actions (SI)."""

    A: np.ndarray  # (6, 6)
    B: np.ndarray  # (6, n): d z1 / d a_k for interval k of the stride (zero after the apex)
    z_ref: np.ndarray  # z*
    scales: np.ndarray  # the apex scales s
    M: np.ndarray  # (I - A)^-1

    @property
    def n(self) -> int:
        return self.B.shape[1]


@lru_cache(maxsize=8)
def _interval_model(gait: str, dt: float, max_torque: float) -> IntervalModel:
    from ..sim.task import APEX_SCALES

    sm = StrideMap(gait, None, dt, max_torque, DESIGN_RTOL)
    z0 = sm.z_ref.copy()
    n = max_intervals(dt)
    # A: central differences in z (the design's steps), zero action
    hz = FD_REL_Z * np.maximum(np.abs(z0), FD_FLOOR_Z)
    Z = np.concatenate([z0 + np.diag(hz), z0 - np.diag(hz)])
    r = sm.run(Z, np.zeros(n))
    if not r.ok.all():
        raise ValueError(f"gait {gait!r}: the stride map fails near z*: no linearization there")
    A = ((r.z1[:6] - r.z1[6:]) / (2.0 * hz)[:, None]).T  # column j: d z1 / d z_j
    # B: central differences in each interval's action (only the intervals before the apex
    # matter; the probes of the later ones return z* exactly)
    n_b = min(n, int(np.ceil(1.5 * float(r.period.max()) / dt)) + 1)
    E = np.zeros((2 * n_b, n))
    E[np.arange(n_b), np.arange(n_b)] = FD_U
    E[n_b + np.arange(n_b), np.arange(n_b)] = -FD_U
    r = sm.run(np.broadcast_to(z0, (2 * n_b, 6)), E)
    if not r.ok.all():
        raise ValueError(f"gait {gait!r}: the stride map fails near z*: no linearization there")
    B = ((r.z1[:n_b] - r.z1[n_b:]) / (2.0 * FD_U)).T
    M = np.linalg.inv(np.eye(6) - A)
    return IntervalModel(A, B, z0, np.asarray(APEX_SCALES, dtype=float), M)


def interval_model(gait: str = "default", dt: float = 0.01, max_torque: float = 80.0):
    """The `IntervalModel` of a gait (cached per process; ~0.3 s the first time)."""
    return _interval_model(str(gait), float(dt), float(max_torque))


@dataclass
class OffsetFreeState:
    """Per robot: the offset estimate d^, the last apex state and its stride's actions."""

    d: np.ndarray  # (n, 6)
    z_prev: np.ndarray  # (n, 6)
    a_prev: np.ndarray  # (n, model.n)
    has_prev: np.ndarray  # (n,) bool
    count: np.ndarray  # (n,) int: the estimate's updates so far


class OffsetFree:
    """``inner`` (a stride controller) held on the plant's own cycle (module docstring)."""

    stateful = True

    def __init__(
        self,
        inner,
        gain: float = OF_DEFAULTS["gain"],
        deadband: float = OF_DEFAULTS["deadband"],
        max_shift: float = OF_DEFAULTS["max_shift"],
        name: str | None = None,
        model: IntervalModel | None = None,
        estimator: str = OF_DEFAULTS["estimator"],
    ):
        if estimator not in ESTIMATORS:
            raise ValueError(
                f"offset_free: estimator must be one of {ESTIMATORS}, got {estimator!r}"
            )
        self.estimator = estimator
        if isinstance(inner, OffsetFree):
            raise ValueError(
                f"{inner.name!r} is held offset-free already: a second {SUFFIX} would estimate "
                "the same offset twice, each chasing the other's shift (give it once)"
            )
        if not callable(getattr(inner, "interval_actions", None)) or not callable(
            getattr(inner, "on_apex", None)
        ):
            raise ValueError(
                f"{getattr(inner, 'name', inner)!r} is not a stride controller "
                "(no interval_actions / on_apex): only stride controllers can be held offset-free"
            )
        given = {"gain": gain, "deadband": deadband, "max_shift": max_shift}
        for key, v in given.items():  # any real number type (np.float32 too), not a bool
            lo, hi = OF_LIMITS[key]
            try:
                given[key] = real(v, f"offset_free: {key}", lo, hi)
            except ValueError:
                raise ValueError(
                    f"offset_free: {key} must be a number in [{lo}, {hi}], got {v!r}"
                ) from None
        gain, deadband, max_shift = given["gain"], given["deadband"], given["max_shift"]
        if gain <= 0.0:
            raise ValueError(f"offset_free: gain must be > 0, got {gain!r}")
        self.inner = inner
        self.gain, self.deadband, self.max_shift = float(gain), float(deadband), float(max_shift)
        self.name = name if name is not None else f"{getattr(inner, 'name', 'controller')}{SUFFIX}"
        kw = self.env_kwargs
        self.model = model or interval_model(
            kw.get("gait", "default"), kw.get("dt", 0.01), kw.get("max_torque", 80.0)
        )
        if self.estimator == "torque":
            self.P_d = self.torque_preconditioner()
        self.reset()

    def torque_preconditioner(self) -> np.ndarray:
        """(I - A) pinv(H), with H = (I + K M B)^-1 K the steady torque a = -H (z_p - z_ss) the
        inner controller (its gain K = -da/dz at z*, by central differences) needs to hold
        a target z_ss off the plant's passive cycle z_p: d^ <- d^ - L (I - A) pinv(H) a moves
        the target by -L pinv(H) a, toward z_p."""
        m = self.model
        h = 1e-4 * m.scales
        Z = np.concatenate([m.z_ref + np.diag(h), m.z_ref - np.diag(h)])
        logs = [getattr(self.inner, k, None) for k in ("decision_seconds", "decision_kinds")]
        sizes = [len(x) if isinstance(x, list) else 0 for x in logs]
        acts = np.atleast_2d(self.inner.interval_actions(Z))
        for x, n0 in zip(logs, sizes, strict=True):  # the probes are not decisions (the MPC's log)
            if isinstance(x, list):
                del x[n0:]
        a = np.zeros((12, m.n))
        k = min(m.n, acts.shape[1])
        a[:, :k] = acts[:, :k]
        K = -((a[:6] - a[6:]) / (2.0 * h)[:, None]).T  # (n, 6)
        H = np.linalg.solve(np.eye(m.n) + K @ m.M @ m.B, K)
        return (np.eye(6) - m.A) @ np.linalg.pinv(H)

    # -- the protocol of bound_env.control.controllers ----------------------------------------
    @property
    def env_kwargs(self) -> dict:
        return dict(getattr(self.inner, "env_kwargs", None) or {})

    @property
    def gait(self):
        return self.env_kwargs.get("gait", "default")

    @property
    def dt(self) -> float:
        return float(self.env_kwargs.get("dt", 0.01))

    @property
    def max_torque(self) -> float:
        return float(self.env_kwargs.get("max_torque", 80.0))

    @property
    def z_ref(self) -> np.ndarray:
        return self.model.z_ref

    def settings(self) -> dict:
        return {
            "estimator": self.estimator,
            "gain": self.gain,
            "deadband": self.deadband,
            "max_shift": self.max_shift,
        }

    def fingerprint(self) -> str:
        inner = getattr(self.inner, "fingerprint", None)
        h = hashlib.sha256(b"offset-free")
        h.update((inner() if callable(inner) else repr(self.inner)).encode())
        h.update(repr(sorted(self.settings().items())).encode())
        return h.hexdigest()[:16]

    # -- the estimator, batched ----------------------------------------------------------------
    def start(self, n: int) -> OffsetFreeState:
        """A fresh state for ``n`` robots (d^ = 0, no stride seen)."""
        return OffsetFreeState(
            d=np.zeros((n, 6)),
            z_prev=np.zeros((n, 6)),
            a_prev=np.zeros((n, self.model.n)),
            has_prev=np.zeros(n, dtype=bool),
            count=np.zeros(n, dtype=np.int64),
        )

    def update(self, state: OffsetFreeState, rows, Z) -> None:
        """Robots ``rows`` reached the apex states Z: update their d^ from their last stride."""
        m = self.model
        rows = np.asarray(rows, dtype=np.int64)
        Z = np.atleast_2d(np.asarray(Z, dtype=float))
        seen = state.has_prev[rows]
        if not seen.any():
            return
        r, z1 = rows[seen], Z[seen]
        if self.estimator == "torque":  # integrate the steady torque away
            e = -(state.a_prev[r] @ self.P_d.T)
        else:
            e = (
                (z1 - m.z_ref)
                - (state.z_prev[r] - m.z_ref) @ m.A.T
                - state.a_prev[r] @ m.B.T
                - state.d[r]
            )
        big = np.max(np.abs(e) / m.scales, axis=1) > self.deadband
        r, e = r[big], e[big]
        state.count[r] += 1
        state.d[r] += self.gain * e

    def shifts(self, state: OffsetFreeState, rows) -> np.ndarray:
        """z_ss - z* of robots ``rows``: (I - A)^-1 d^, its normalized size limited."""
        m = self.model
        S = state.d[np.asarray(rows, dtype=np.int64)] @ m.M.T
        size = np.max(np.abs(S) / m.scales, axis=1)
        over = size > self.max_shift
        S[over] *= (self.max_shift / size[over])[:, None]
        return S

    def targets(self, state: OffsetFreeState, rows=None) -> np.ndarray:
        """The target cycles z_ss of robots ``rows`` (default: all)."""
        rows = np.arange(len(state.d)) if rows is None else rows
        return self.model.z_ref + self.shifts(state, rows)

    def record(self, state: OffsetFreeState, rows, Z, A) -> None:
        """Robots ``rows`` start a stride from Z with the interval actions A (the last one
        holds past its end, as in `bound_env.sim.stride_map`)."""
        rows = np.asarray(rows, dtype=np.int64)
        A = np.atleast_2d(np.asarray(A, dtype=float))
        n = self.model.n
        a = np.repeat(A[:, -1:], n, axis=1)
        k = min(n, A.shape[1])
        a[:, :k] = A[:, :k]
        state.z_prev[rows] = Z
        state.a_prev[rows] = a
        state.has_prev[rows] = True

    def plan_actions(self, state: OffsetFreeState, Z, rows=None) -> np.ndarray:
        """The interval actions of the strides of robots ``rows`` (default: all) from the apex
        states Z, after updating their estimates: the inner controller's at Z - z_ss + z*."""
        Z = np.atleast_2d(np.asarray(Z, dtype=float))
        rows = np.arange(len(Z)) if rows is None else np.asarray(rows, dtype=np.int64)
        self.update(state, rows, Z)
        A = np.atleast_2d(self.inner.interval_actions(Z - self.shifts(state, rows)))
        self.record(state, rows, Z, A)
        return A

    # -- the step protocol (one robot) --------------------------------------------------------
    def reset(self) -> None:
        """Forget the robot: d^ = 0 and no stride seen (the start of an episode)."""
        self.state = self.start(1)
        self._z = None  # the apex the current stride started from
        self._actions: list[float] = []  # its actions so far

    def on_apex(self, z, time_since_apex: float = 0.0) -> None:
        z = np.asarray(z, dtype=float)[None]
        if self._z is not None and self._actions:
            self.record(self.state, [0], self._z, np.array(self._actions)[None])
        self.update(self.state, [0], z)
        self._z, self._actions = z, []
        self.inner.on_apex(z[0] - self.shifts(self.state, [0])[0], time_since_apex)

    def __call__(self, obs) -> float:
        if self._z is None:  # no apex announced yet: the observation at a reset is one
            from .controllers import OBS_Z

            self.on_apex(np.asarray(obs, dtype=float)[list(OBS_Z)], float(obs[OBS_TIME]))
        a = float(self.inner(obs))
        self._actions.append(a)
        return a

    @property
    def offset(self) -> np.ndarray:
        """d^ of the step protocol's robot."""
        return self.state.d[0].copy()
