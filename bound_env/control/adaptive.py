"""A classical adaptive controller: the shipped MPC that identifies its robot and re-designs.

``mpc-adaptive`` (configs/controllers/mpc-adaptive.yaml) sees only what a robot sees: the apex
states the loop hands it (noisy under sensor noise) and the actions it chose itself. At every
apex it

1. adds the last stride to its record: the apex state it started from, the interval actions
   it commanded (its plan's, `bound_env.sim.stride_protocol.interval_actions_of`) and the apex
   state it reached;
2. checks how well its current estimate predicted that stride (the innovation, normalized
   max |z_{k+1} - P(z_k, a_k; f^)|_i / s_i);
3. re-identifies the eight factors f (`bound_env.control.identify`: maximum a posteriori over
   the last ``window`` strides through the stride map, prior toward nominal) while it
   identifies (the first ``identify`` strides, and whenever an innovation exceeds
   ``trust_error``), unless the innovation is within ``deadband``: on the nominal plant the
   estimate then never leaves the nominal one, and the controller is the shipped mpc, bit for
   bit (zero torque on the cycle);
4. **acts on the estimate only once it has predicted a stride it was not fitted to**: an
   estimate is trusted when its innovation on the next stride is at most ``trust_error``.
   Until then the nominal (robust) mpc acts. A trusted estimate that differs from the one the
   controller was designed on by more than ``redesign`` (max |log f|) gets a new design
   (`bound_env.control.plant_design`, as the privileged reference on the true plant): the
   target at the estimated plant's own cycle, the LQR gain there, and the MPC planning on the
   estimated plant.

The estimate, the record and the design are the episode's: ``reset()`` (called by the loops
at every start, `bound_env.sim.stride_protocol.reset_controller`) forgets them. Like
`bound_env.control.offset_free.OffsetFree` it has no stateless ``interval_actions``: the
loops step it through the env, one robot per copy.
"""

from __future__ import annotations

import copy
import time

import numpy as np

from ..model.mismatch import EIGHT
from ..sim.stride_protocol import grid_times, interval_actions_of
from .anytime import Slices
from .controllers import OBS_TIME, OBS_Z
from .identify import PlantIdentifier
from .plant_design import RedesignedMPC

NAME = "mpc-adaptive"
from .adaptive_settings import (  # noqa: E402  (the spec's ``adaptive`` block)
    ADAPTIVE_DEFAULTS,
    check_adaptive,
)


class AdaptiveMPC(RedesignedMPC):
    """The shipped mpc identifying its plant online and re-designing on the estimate (module
    docstring; the design is `RedesignedMPC`'s). ``spec``: an mpc spec (name, path or
    `ControllerSpec`; default ``mpc-adaptive``); ``gait``: default the spec's; the keyword
    arguments: `ADAPTIVE_DEFAULTS` (default: the spec's ``adaptive`` block)."""

    NAME = NAME
    ROLE = "an adaptive controller"
    stateful = True  # the estimate is the episode's: reset() forgets it
    privileged = False

    def __init__(self, gait=None, spec=NAME, name: str | None = None, **settings):
        self._settings = settings
        super().__init__(gait, spec, name)
        b, cfg = self.base, self.config
        batch = 13 + 2 * b.basis.K  # the design's largest batch of strides (its Jacobian)
        if 0 < cfg["budget"] < batch:
            raise ValueError(
                f"{self.name}: adaptive.budget must be 0 or at least {batch} (the strides of "
                f"one design Jacobian), got {cfg['budget']}"
            )
        self.identifier = PlantIdentifier(
            b.gait, b.dt, b.max_torque, b.rtol, cfg["prior"], cfg["sigma"], cfg["candidates"]
        )
        self._times = grid_times(b.dt)
        self.decision_seconds: list = []  # every apex decision, identification included
        self.decision_kinds: list = []
        self.decision_work: list = []  # stride evaluations of identification and design
        self.reset()

    def _configure(self, spec) -> None:
        """The settings: the spec's ``adaptive`` block (else the defaults), updated by the
        keyword arguments (checked)."""
        cfg = dict(spec.adaptive or ADAPTIVE_DEFAULTS)
        if self._settings:
            checked = check_adaptive(self._settings, "AdaptiveMPC")
            cfg.update({k: checked[k] for k in self._settings})
        self.config = cfg

    # -- the episode -------------------------------------------------------------------------------
    def reset(self) -> None:
        """Forget the robot: the nominal estimate, no stride seen, the shipped mpc acting."""
        p = len(EIGHT)
        self.theta = np.zeros(p)  # the current estimate (log factors)
        self.fit = None
        self.trusted = False
        self.designed_theta = np.zeros(p)  # the estimate of the acting design
        self.design = None
        self.mpc = self.base
        self.strides = 0  # strides seen (transitions)
        self.delay = 0  # the actuation delay [intervals] the fits assume (chosen with them)
        self.searches = 0  # fits that searched for the global minimum
        self.innovations: list = []
        self._record: list = []  # per stride: (z_k, commanded actions, z_{k+1})
        self._z = None  # the apex the current stride started from
        self.last_actions = None  # its planned interval actions
        self._commanded: list = []  # the actions __call__ returned in it (the step protocol)
        self._end_work()

    def _end_work(self) -> None:
        """Drop the work in flight (a fit or a design being computed across decisions)."""
        job = getattr(self, "job", None)
        if job is not None:
            job.cancel()
        self.job, self.job_kind, self.job_theta = None, None, None

    @property
    def factors(self) -> dict:
        """The current estimate of the eight factors (1.0: nominal)."""
        return dict(zip(EIGHT, np.exp(self.theta).tolist(), strict=True))

    def applied(self, delay: int, window: int | None = None):
        """(Z, A, Z1) of the last ``window`` strides, A the interval actions the plant got if
        the actuation lags ``delay`` intervals: the last ``delay`` actions commanded in the
        stride before (zero torque before the first), then the stride's own, the last held
        (the stride map's convention)."""
        rec = self._record[-window:] if window else self._record
        first = len(self._record) - len(rec)
        n = len(self._times)
        A = np.empty((len(rec), n))
        for j, (_, c, _) in enumerate(rec):
            k = first + j
            prev = self._record[k - 1][1] if k > 0 else np.zeros(max(delay, 1))
            a = np.concatenate([prev[len(prev) - delay :] if delay else [], c])[:n]
            A[j, : len(a)] = a
            A[j, len(a) :] = a[-1]
        Z = np.array([r[0] for r in rec])
        Z1 = np.array([r[2] for r in rec])
        return Z, A, Z1

    def _observe(self, z) -> None:
        """A stride ended at the apex z: record it, check the estimate on it (a stride it was
        not fitted to), trust it or fall back, and start a fit when one is wanted."""
        if self._z is None:
            return
        cfg = self.config
        c = np.array(self._commanded) if self._commanded else self.last_actions
        self._record.append((self._z, np.asarray(c, dtype=float), z))
        self.strides += 1
        Z, A, Z1 = self.applied(self.delay, 1)
        e = float(np.max(np.abs(self.identifier.residuals(Z, A, Z1, self.theta))))
        self.innovations.append(e)
        if e <= cfg["deadband"]:
            return
        good = e <= cfg["trust_error"]
        if self.fit is not None:  # a fitted estimate met a stride it was not fitted to
            was = self.trusted
            self.trusted = good and self.fit.pred_std <= cfg["trust_std"]
            if was and not good and cfg["fallback"]:  # the model is wrong: back to mpc, refit
                self.mpc, self.design, self.designed_theta = self.base, None, np.zeros(len(EIGHT))
                if self.job_kind == "design":
                    self._end_work()
        settled = self.trusted and e <= cfg["settle"]
        listening = self.strides <= cfg["identify"] or (cfg["fallback"] and not good)
        if self.job is None and listening and not settled:
            self._start_fit()

    def _start_fit(self) -> None:
        """Start the fit of the last ``window`` strides, warm-started from the estimate; while
        it is not trusted (at most ``searches`` times per episode) it also searches, under
        every delay hypothesis (the cheapest fit wins)."""
        cfg = self.config
        search = 0 if self.trusted or self.searches >= cfg["searches"] else cfg["search"]
        self.searches += bool(search)
        delays = range(cfg["delays"] + 1) if search and self._commanded else [self.delay]
        data = [(d, self.applied(d, cfg["window"])) for d in delays]
        theta0, iters, ident, chunk = self.theta.copy(), cfg["iters"], self.identifier, None
        if cfg["budget"] > 0:
            chunk = cfg["budget"]

        def fit(slices):
            idf = copy.copy(ident)
            idf.map, idf.chunk = slices.meter(ident.map), chunk
            best = None
            for d, (Z, A, Z1) in data:
                f = idf.fit(Z, A, Z1, theta0, iters, search)
                if best is None or f.cost < best[0].cost:
                    best = (f, d)
            return best

        self._start(fit, "fit", theta0)

    def _start_design(self) -> None:
        """Start the design on the trusted estimate (`RedesignedMPC.redesigned` once ready)."""
        hint = self.design.z_ref if self.design is not None else None
        overrides, designer = self.identifier.overrides(self.theta), self.designer

        def design(slices):
            dz = copy.copy(designer)
            dz.meter = slices.meter
            return dz.design(overrides, z_hint=hint)

        self._start(design, "design", self.theta.copy())

    def _start(self, fn, kind: str, theta) -> None:
        self.job, self.job_kind, self.job_theta = Slices(fn, self.config["budget"]), kind, theta

    def _work(self) -> int:
        """This decision's slice of the work in flight (a design is started once a trusted
        estimate moved more than ``redesign`` from the acting design); its result taken once
        ready. Unbounded (``budget`` 0), a fit finished here is followed by its design in the
        same decision, so that the decision acts on it. Returns the stride evaluations spent."""
        spent, fitted = self._work_slice()
        while fitted and self.config["budget"] <= 0:
            more, fitted = self._work_slice()
            spent += more
        return spent

    def _work_slice(self) -> tuple[int, bool]:
        """One slice of `_work`: (stride evaluations spent, whether a fit finished)."""
        if self.job is None and self.trusted:
            if np.max(np.abs(self.theta - self.designed_theta)) > self.config["redesign"]:
                self._start_design()
        job = self.job
        if job is None:
            return 0, False
        done = job.advance()
        spent = job.spent
        if done:
            kind, theta = self.job_kind, self.job_theta
            self.job, self.job_kind, self.job_theta = None, None, None
            if job.error is not None:
                raise job.error
            if kind == "fit":
                self.fit, self.delay = job.result
                self.theta = self.fit.theta
                cfg = self.config
                if cfg["trust_rms"] > 0.0 and self.fit.transitions >= cfg["trust_strides"]:
                    if self.fit.rms <= cfg["trust_rms"]:  # the in-sample rule (off: 0)
                        self.trusted = True
            else:
                d = job.result
                self.mpc, self.design, self.designed_theta = self.redesigned(d), d, theta
        return spent, done and kind == "fit"

    def _decide(self, z) -> np.ndarray:
        t0 = time.perf_counter()
        z = np.asarray(z, dtype=float)
        self._observe(z)
        self.decision_work.append(self._work())
        u = self.mpc.plan(z)
        self.decision_kinds.append(self.mpc._kind)
        self._z = z.copy()
        b = self.base
        self.last_actions = interval_actions_of(b.basis, b.max_torque, [u], self._times, b.dt)[0]
        self._commanded = []
        self.decision_seconds.append(time.perf_counter() - t0)
        return u

    # -- the protocol of bound_env.control.controllers (the rest: RedesignedMPC's) ----------------
    def stride_action(self, z) -> np.ndarray:
        """The action of PassiveBoundStride-v1 at the apex z (one call per stride, in order:
        each call ends the last stride and starts the next)."""
        return self._decide(z)

    def on_apex(self, z, time_since_apex: float = 0.0) -> None:
        self._u = self._decide(z)
        self._t0 = float(time_since_apex)

    def __call__(self, obs) -> float:
        t = float(obs[OBS_TIME])
        if self._z is None:
            self.on_apex(np.asarray(obs, dtype=float)[list(OBS_Z)], t)
        t = self._t0 + self.dt * round((t - self._t0) / self.dt)
        taus = self.basis.torques(self._u, self.max_torque)
        a = float(np.clip(self.basis.average(taus, t, t + self.dt) / self.max_torque, -1.0, 1.0))
        self._commanded.append(a)
        return a

    def apex_torques(self, z) -> np.ndarray:
        return self.basis.torques(self._decide(z), self.max_torque)

    def settings(self) -> dict:
        return {**self.base.settings(), "adaptive": dict(self.config)}

    def fingerprint(self) -> str:
        return self._fingerprint(b"adaptive", repr(sorted(self.config.items())))

    def __getstate__(self):
        """A copy (the batched loops' per-robot copies, a worker's pickle) starts without the
        work in flight (a copy is made at an episode's start)."""
        state = dict(self.__dict__)
        state.update(job=None, job_kind=None, job_theta=None)
        return state

    def __del__(self):
        try:
            self._end_work()
        except Exception:  # noqa: BLE001  (interpreter shutdown)
            pass

    def __repr__(self) -> str:
        return f"AdaptiveMPC({self.name!r}, strides={self.strides}, trusted={self.trusted})"
