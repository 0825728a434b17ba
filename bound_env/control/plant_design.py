"""A stride controller designed on a given plant: its target cycle and LQR gain there.

The privileged reference (`bound_env.control.privileged`, the robot's true plant) and the
adaptive controller (`bound_env.control.adaptive`, its estimate of the plant) both re-design
the shipped MPC on a plant other than the nominal one; this module is that design, in one
place (`PlantDesigner.design`):

1. **The target: the plant's own cycle.** Newton on the plant's passive apex map,
   F(z) = P(z, 0) - z, from the nominal z* (or a hint), with the Jacobian by central
   differences in one batch of strides (`bound_env.model.numerics.newton`). A passive cycle
   needs no torque, so the loop that holds it spends nothing on it. It is kept if Newton
   converges within ``max_shift`` (normalized apex error max |z - z*|_i / s_i) of z*.
2. **Where the plant has none near z\\*** (the passive cycle ends in a fold within a few
   percent of the nominal parameters: half the ±5 % plants have none), the cycle with the least
   steady torque: min |u|^2 subject to P(z, u) = z, u the coefficients of the controller's
   torque basis (sequential quadratic programming, `forced_cycle`). The loop then holds it
   with the steady profile u_ss and the feedback around it.
3. **The gain there.** A = dP/dz, B = dP/du at (z_ss, u_ss) on the plant (central
   differences), and the discrete LQR gain of the controller's weights Q, R in the normalized
   coordinates (`bound_env.control.design.lqr_gain`); the nominal gain where the Riccati
   equation has no stabilizing solution.

The result is a `CycleFeedback`, u = clip(u_ss - G (z - z_ss), -1, 1), the LQR of the MPC's
protocol with a feedforward, and the plant's planning map for the MPC's search.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from ..model.mismatch import PLANT_KEYS, plant_values
from ..model.params import Params, load_gait
from ..sim.stride_map import EVAL_RTOL, StrideMap, interval_weights
from .controllers import StrideFeedback
from .design import FD_FLOOR_Z, FD_REL_Z, FD_U, lqr_gain, spectral_radius

CYCLE_TOL = 1e-9  # the cycle's residual max |P(z, u) - z| (SI) at which it is found
MAX_SHIFT = 4.0  # a cycle further than this from z* (max |z - z*|_i / s_i) is not taken
FORCED_ITERS = 30  # iterations of the least-torque cycle search
FORCED_OPT = 6  # of which the first this many also lower |u| (`PlantDesigner.forced_cycle`)
# weight of |dz / s|^2 against |du|^2 in its steps: tried in turn until a cycle within
# ``max_shift`` is found (a larger weight: a cycle nearer z*, more torque)
FORCED_EPS = (1e-2, 1.0, 100.0)
FORCED_SLACK = 1e-3  # normalized residual its first steps may keep
MAX_HALVINGS = 20  # step halvings of one step
NEWTON_ITERS = 25  # Newton iterations of the passive cycle


@dataclass
class CycleFeedback(StrideFeedback):
    """u = clip(u_ss - G (z - z_ss), -1, 1): the stride LQR around a cycle (z_ss, u_ss) that may
    need a steady profile u_ss (`StrideFeedback` with a feedforward; u_ss = 0 on a passive
    cycle)."""

    u_ref: np.ndarray = None  # u_ss (K,)

    def __post_init__(self):
        K = self.gain.shape[0]
        self.u_ref = np.zeros(K) if self.u_ref is None else np.asarray(self.u_ref, dtype=float)

    def coefficients(self, z) -> np.ndarray:
        dz = np.asarray(z, dtype=float) - self.z_ref
        return np.clip(self.u_ref - self.gain @ dz, -1.0, 1.0)

    def plan(self, Z) -> np.ndarray:
        Z = np.asarray(Z, dtype=float)
        if Z.ndim == 1:
            return self.coefficients(Z)
        return np.clip(self.u_ref[None, :] - (Z - self.z_ref) @ self.gain.T, -1.0, 1.0)

    def fingerprint(self) -> str:
        h = hashlib.sha256(super().fingerprint().encode())
        h.update(np.ascontiguousarray(self.u_ref, dtype=float).tobytes())
        return h.hexdigest()[:16]


@dataclass
class PlantDesign:
    """A controller's design on one plant (module docstring)."""

    overrides: dict  # the plant's gait-file values that differ from the nominal gait's
    z_ref: np.ndarray  # the target cycle z_ss (SI)
    u_ref: np.ndarray  # its steady coefficients u_ss (0 on a passive cycle)
    cycle: str  # "passive", "forced" or "nominal" (no cycle found: z*, no feedforward)
    gain: np.ndarray  # G (K x 6, SI)
    gain_source: str  # "lqr" (designed there) or "nominal"
    residual: float  # max |P(z_ss, u_ss) - z_ss| (SI)
    info: dict = field(default_factory=dict)


def plant_overrides(plant, gait="default") -> dict:
    """The gait-file values of ``plant`` that differ from ``gait``'s: ``plant`` is a
    `bound_env.model.params.Params` or a mapping of some of `bound_env.model.mismatch.PLANT_KEYS`
    to values in gait-file units (``info["plant"]`` of `bound_env.envs.wrappers.RandomizedPlant`).
    ValueError naming the key for anything else."""
    nominal = plant_values(load_gait(gait).params)
    if isinstance(plant, Params):
        values = plant_values(plant)
    elif isinstance(plant, Mapping):
        values = {}
        for k, v in plant.items():
            if k not in PLANT_KEYS:
                raise ValueError(f"plant: unknown parameter {k!r}; known: {PLANT_KEYS}")
            if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)):
                raise ValueError(f"plant: {k} must be a number, got {v!r}")
            if not math.isfinite(float(v)) or (k != "alpha_deg" and float(v) <= 0.0):
                raise ValueError(f"plant: {k} must be finite and > 0, got {v!r}")
            values[k] = float(v)
    else:
        raise ValueError(
            "plant must be a bound_env.params.Params or a mapping of "
            f"{', '.join(PLANT_KEYS)} to values, got {type(plant).__name__}"
        )
    return {k: v for k, v in values.items() if v != nominal[k]}


class PlantDesigner:
    """Designs ``lqr`` (a `StrideFeedback`: its basis, saturation, control interval and gait)
    with the weights Q, R (diagonal matrices, normalized coordinates) on any plant."""

    def __init__(self, lqr: StrideFeedback, Q, R, max_shift: float = MAX_SHIFT):
        from ..sim.task import APEX_SCALES

        self.lqr = lqr
        self.Q, self.R = np.asarray(Q, dtype=float), np.asarray(R, dtype=float)
        self.scales = np.asarray(APEX_SCALES, dtype=float)
        self.max_shift = float(max_shift)
        b = lqr.basis
        self.W = interval_weights(b.edges, b.phi, lqr.dt)  # interval actions a = W u
        self.z_nominal = np.asarray(lqr.z_ref, dtype=float)
        self.meter = None  # None, or a wrapper of every map it designs on (`anytime.Slices`)

    def plant_map(self, overrides: dict, rtol: float = EVAL_RTOL, segments=False) -> StrideMap:
        """The plant's stride map (the step env's, on the plant's parameters)."""
        lqr = self.lqr
        m = StrideMap(lqr.gait, overrides or None, lqr.dt, lqr.max_torque, rtol, segments)
        return m if self.meter is None else self.meter(m)

    # -- the pieces ------------------------------------------------------------------------------
    def _steps(self, z) -> np.ndarray:
        return FD_REL_Z * np.maximum(np.abs(z), FD_FLOOR_Z)

    def jacobians(self, sm: StrideMap, z, u):
        """(P(z, u), A = dP/dz, B = dP/du) by central differences in one batch (None where a
        stride fails)."""
        K = len(u)
        hz = self._steps(z)
        Z = np.concatenate([z[None], z + np.diag(hz), z - np.diag(hz), np.tile(z, (2 * K, 1))])
        U = np.tile(u, (1 + 12 + 2 * K, 1))
        U[13 : 13 + K] += FD_U * np.eye(K)
        U[13 + K :] -= FD_U * np.eye(K)
        r = sm.run(Z, U @ self.W.T)
        if not r.ok.all():
            return None
        z1 = r.z1
        A = ((z1[1:7] - z1[7:13]) / (2.0 * hz)[:, None]).T
        B = ((z1[13 : 13 + K] - z1[13 + K :]) / (2.0 * FD_U)).T
        return z1[0], A, B

    def passive_cycle(self, sm: StrideMap, z0):
        """Newton on P(z, 0) = z from z0: (z, residual, converged)."""
        from ..model.numerics import newton

        K = self.lqr.basis.K
        u0 = np.zeros(K)
        a0 = np.zeros((1, self.W.shape[0]))

        def F(z):
            r = sm.run(z[None], a0)
            return (r.z1[0] - z) if r.ok[0] else None

        def jac(z):
            out = self.jacobians(sm, z, u0)
            if out is None:
                from ..model.numerics import MapFailure

                raise MapFailure("a stride fails near the point", z)
            return out[1] - np.eye(6)

        o = newton(F, z0, self._steps(z0), tol=CYCLE_TOL, max_iter=NEWTON_ITERS, jacobian=jac)
        res = math.inf if o.residual is None else float(np.max(np.abs(o.residual)))
        return o.u, res, bool(o.converged)

    def forced_cycle(self, sm: StrideMap, z0, u0=None, eps: float = FORCED_EPS[0]):
        """A cycle of small steady torque near z0: min |u|^2 subject to P(z, u) = z.
        ``FORCED_OPT`` steps of sequential quadratic programming (each the least
        |u + du|^2 + eps |dz / s|^2 that zeroes the linearized residual, constraint curvature
        ignored), then Gauss-Newton steps of least change onto the cycle, each step halved
        until the residual falls (or, in the first phase, stays below ``FORCED_SLACK``).
        Returns (z, u, residual, converged)."""
        K = self.lqr.basis.K
        z = np.asarray(z0, dtype=float).copy()
        u = np.zeros(K) if u0 is None else np.asarray(u0, dtype=float).copy()
        s = self.scales
        H_inv = np.concatenate([np.full(6, 1.0 / eps), np.ones(K)])

        def residual(z_, u_):
            r = sm.run(z_[None], (u_ @ self.W.T)[None])
            return (r.z1[0] - z_) if r.ok[0] else None

        res = residual(z, u)
        if res is None:
            return z, u, math.inf, False
        size = float(np.max(np.abs(res / s)))
        for it in range(FORCED_ITERS):
            if np.max(np.abs(res)) <= CYCLE_TOL:
                break
            jac = self.jacobians(sm, z, u)
            if jac is None:
                break
            _, A, B = jac
            N = np.hstack([(A - np.eye(6)) * s[None, :], B])  # unknowns (dz / s, du)
            optimal = it < FORCED_OPT
            g = np.concatenate([np.zeros(6), u]) if optimal else np.zeros(6 + K)
            try:
                lam = np.linalg.solve((N * H_inv[None, :]) @ N.T, res - N @ (H_inv * g))
            except np.linalg.LinAlgError:
                break
            x = -H_inv * (g + N.T @ lam)
            dz, du = x[:6] * s, x[6:]
            bound = max(size, FORCED_SLACK) if optimal else size
            step = 1.0
            for _ in range(MAX_HALVINGS):
                zn, un = z + step * dz, np.clip(u + step * du, -1.0, 1.0)
                rn = residual(zn, un)
                if rn is not None and float(np.max(np.abs(rn / s))) < bound:
                    break
                step *= 0.5
            else:
                break
            z, u, res = zn, un, rn
            size = float(np.max(np.abs(res / s)))
        r = float(np.max(np.abs(res)))
        return z, u, r, r <= CYCLE_TOL

    def gain_at(self, sm: StrideMap, z, u):
        """(G, source): the LQR gain (SI) of the plant's map linearized at (z, u), or the
        nominal gain where that fails."""
        jac = self.jacobians(sm, z, u)
        if jac is not None:
            _, A, B = jac
            s = self.scales
            A_n, B_n = A * s[None, :] / s[:, None], B / s[:, None]
            try:
                G_n = lqr_gain(A_n, B_n, self.Q, self.R)
                return G_n / s[None, :], "lqr", spectral_radius(A - B @ (G_n / s[None, :]))
            except ValueError:
                pass
        return self.lqr.gain.copy(), "nominal", math.nan

    # -- the design ------------------------------------------------------------------------------
    def design(self, plant, z_hint=None, gait=None) -> PlantDesign:
        """The controller's design on ``plant`` (`plant_overrides`: a Params or a mapping of
        plant keys); ``z_hint``: where the cycle search starts (default: the nominal z*)."""
        overrides = plant_overrides(plant, self.lqr.gait if gait is None else gait)
        sm = self.plant_map(overrides)
        K = self.lqr.basis.K
        z0 = self.z_nominal if z_hint is None else np.asarray(z_hint, dtype=float)
        info: dict = {}
        z, res, ok = self.passive_cycle(sm, z0)
        shift = float(np.max(np.abs(z - self.z_nominal) / self.scales))
        if ok and shift <= self.max_shift:
            cycle, u = "passive", np.zeros(K)
        else:
            info["passive"] = {"residual": res, "shift": shift}
            for eps in FORCED_EPS:
                z, u, res, ok = self.forced_cycle(sm, z0, eps=eps)
                shift = float(np.max(np.abs(z - self.z_nominal) / self.scales))
                if ok and shift <= self.max_shift:
                    break
            if ok and shift <= self.max_shift:
                cycle = "forced"
                info["eps"] = eps
            else:
                info["forced"] = {"residual": res, "shift": shift}
                cycle, z, u = "nominal", self.z_nominal.copy(), np.zeros(K)
                res = math.nan
        G, source, rho = self.gain_at(sm, z, u)
        info["rho_closed"] = rho
        return PlantDesign(overrides, z, u, cycle, G, source, res, info)

    def feedback(self, d: PlantDesign, name: str | None = None) -> CycleFeedback:
        """The `CycleFeedback` of a design (the basis, saturation and gait of ``lqr``)."""
        lqr = self.lqr
        return CycleFeedback(
            name=name or lqr.name,
            kind=lqr.kind,
            gain=d.gain,
            z_ref=d.z_ref,
            basis=lqr.basis,
            max_torque=lqr.max_torque,
            dt=lqr.dt,
            gait=lqr.gait,
            design={"cycle": d.cycle, "gain": d.gain_source, **d.info},
            u_ref=d.u_ref,
        )


class RedesignedMPC:
    """The shipped mpc of a spec, re-designed on a plant other than the nominal one: the base
    of the privileged reference (`bound_env.control.privileged.PrivilegedMPC`, the true plant)
    and the adaptive controller (`bound_env.control.adaptive.AdaptiveMPC`, its estimate).

    ``spec``: an mpc spec (name, path or `bound_env.control.spec.ControllerSpec`; default the
    subclass's ``NAME``); ``gait``: default the spec's. ``base`` is the spec's mpc (designed
    without its ``privileged`` / ``adaptive`` block), ``mpc`` the acting one (``base`` until a
    design), ``designer`` the `PlantDesigner` with the spec's weights. The protocol of
    `bound_env.control.controllers` is the base's (gait, torque, basis, envs), the target the
    acting mpc's."""

    NAME = ""  # the shipped spec's name
    ROLE = "a re-designed controller"  # "<ROLE> re-designs an mpc spec" (the error message)

    def __init__(self, gait=None, spec=None, name: str | None = None):
        from dataclasses import replace

        from .build import design_controller
        from .spec import ControllerSpec, load_spec, weights

        spec = self.NAME if spec is None else spec
        s = spec if isinstance(spec, ControllerSpec) else load_spec(spec)
        if s.controller != "mpc":
            raise ValueError(f"{s.path}: {self.ROLE} re-designs an mpc spec, got {s.controller!r}")
        self._configure(s)
        s = replace(s, privileged=False, adaptive=None)
        self.base = design_controller(s, gait)
        self.name = str(name) if name is not None else (s.name if s.path else self.NAME)
        b = self.base
        self.designer = PlantDesigner(
            b.lqr, weights(s.path, "Q", s.Q, 6), weights(s.path, "R", s.R, b.basis.K)
        )
        self.mpc = self.base  # the acting controller

    def _configure(self, spec) -> None:
        """Read the subclass's own settings from the spec (before the design)."""

    def redesigned(self, d: PlantDesign):
        """The base MPC with the design ``d``: its LQR around d's cycle, planning on d's
        plant (a fresh record of decisions)."""
        from dataclasses import replace

        b = self.base
        fb = self.designer.feedback(d, name=b.lqr.name)
        mpc = replace(b, lqr=fb, decision_seconds=[], decision_kinds=[])
        mpc.model = self.designer.plant_map(d.overrides, b.rtol, b.segments)
        return mpc

    def _fingerprint(self, tag: bytes, *extra: str) -> str:
        h = hashlib.sha256(tag)
        h.update(self.base.fingerprint().encode())
        for e in extra:
            h.update(e.encode())
        return h.hexdigest()[:16]

    # -- the protocol of bound_env.control.controllers ---------------------------------------------
    gait = property(lambda self: self.base.gait)
    max_torque = property(lambda self: self.base.max_torque)
    dt = property(lambda self: self.base.dt)
    basis = property(lambda self: self.base.basis)
    env_kwargs = property(lambda self: self.base.env_kwargs)
    stride_env_kwargs = property(lambda self: self.base.stride_env_kwargs)
    z_ref = property(lambda self: self.mpc.z_ref)  # the current target
    snaps_time = True
