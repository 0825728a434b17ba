"""Fixed points of the Poincare map, z* = P(z*) (III.D.1), three ways.

1. `find_fixed_point`: Newton-Raphson on F(z) = P(z) - z with the central-difference Jacobian
   of eq. (23), globalised by a backtracking line search on ||F|| (a failed stride counts as
   an infinite residual and halves the step). Parameters can be freed as in Remy's
   FindPeriodicSolution: each freed gait key (``alpha_deg, gamma_b_deg, gamma_f_deg, kb,
   kf``; any gait key is accepted) joins the unknowns and needs one extra condition, a *pin*:
   ``("energy", E)`` fixes the apex energy [J] (`apex_energy`), ``("xdot_g", v)`` or any
   other component name of z fixes that component (SI value). With zero damping the fixed
   points of a fixed parameter set form one-parameter families (the energy is conserved), so
   there one pin more than freed parameters makes the problem well posed again (solved in
   the least-squares sense; the extra equation is consistent on the family).
2. `slope_secant`: the paper's slope angle search (III.D.5, eq. 27).
3. `paper_search`: the paper's whole process (III.D.4, steps C-F): secant on alpha, Newton
   updates of z_0, then touchdown angles, then leg stiffnesses - every loop bounded.

Every numerical failure (a start that falls, a stride failing during the search, a singular
Jacobian, no convergence) returns a result with ``converged=False`` and a ``reason``;
only misuse (unknown names, wrong number of pins) raises ``ValueError``.

Units: z in SI everywhere here; freed parameters in gait-file units (degrees for ``*_deg``).
Strides use ``rtol = atol = 1e-12`` (`ANALYSIS_TOL`), where P is reproducible to ~1e-13.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..model.numerics import (  # noqa: F401 - NewtonOutcome, scaled_rcond: re-exported (old home)
    NEWTON_MAX_ITER,
    NEWTON_TOL,
    NewtonOutcome,
    inf_norm,
    newton,
    scaled_rcond,
)
from ..model.params import GAIT_KEYS, Z_NAMES, Params, z_to_paper
from .poincare import (
    PAPER_STRIDES,
    IterationResult,
    StrideFailure,
    apex_energy,
    iterate,
    stride,
)
from .stability import DZ, recovery, stability

FREE_KEYS = ("alpha_deg", "gamma_b_deg", "gamma_f_deg", "kb", "kf")  # the usual free keys
PIN_NAMES = ("energy",) + Z_NAMES


# --------------------------------------------------------------------------------------------
# Fixed points with free parameters and pins
# --------------------------------------------------------------------------------------------


@dataclass
class FixedPointResult:
    """A fixed point z* = P(z*) of the map (or the last iterate and why it is not one)."""

    z: np.ndarray  # SI
    params: Params  # with the freed values
    residual: float  # max |P(z) - z| (SI); inf if the stride at z fails
    converged: bool
    reason: str
    iterations: int = 0
    jacobian: np.ndarray | None = None  # nabla P(z*) (6x6, eq. 22)
    eigenvalues: np.ndarray | None = None  # largest modulus first
    emax: float = math.nan
    phases: list = field(default_factory=list)
    durations: list = field(default_factory=list)
    strides_to_converge: int | None = None  # after +1 % on y_g (Fig. 6), None if never
    free: dict = field(default_factory=dict)  # freed gait keys -> values (gait units)
    method: str = "newton"
    history: list = field(default_factory=list)

    @property
    def has_ds(self) -> bool:
        return "ds" in self.phases

    def summary(self) -> dict:
        """Plain JSON: z in paper units, eigenvalues as [re, im] pairs."""
        out = {
            "z": [float(v) for v in z_to_paper(self.z)],
            "residual": float(self.residual) if math.isfinite(self.residual) else None,
            "eigenvalues": None
            if self.eigenvalues is None
            else [[float(v.real), float(v.imag)] for v in self.eigenvalues],
            "emax": None if not math.isfinite(self.emax) else float(self.emax),
            "phases": list(self.phases),
            "durations": [float(d) for d in self.durations],
            "strides_to_converge": self.strides_to_converge,
            "converged": bool(self.converged),
            "reason": self.reason,
            "iterations": int(self.iterations),
            "method": self.method,
        }
        out.update({k: float(v) for k, v in self.free.items()})
        return out


def normalize_pins(pin) -> list[tuple[str, float]]:
    """None, one ``(name, value)`` or a list of them -> a list of (name, value)."""
    if pin is None:
        return []
    if isinstance(pin, tuple) and len(pin) == 2 and isinstance(pin[0], str):
        pin = [pin]
    pins = []
    for item in pin:
        name, value = item
        if name not in PIN_NAMES:
            raise ValueError(f"unknown pin {name!r}; known: {PIN_NAMES}")
        pins.append((name, float(value)))
    return pins


def check_free(free) -> tuple[str, ...]:
    free = tuple(free or ())
    for k in free:
        if k not in GAIT_KEYS:
            raise ValueError(f"cannot free {k!r}: not a gait key; usually one of {FREE_KEYS}")
    if len(set(free)) != len(free):
        raise ValueError(f"a parameter is freed twice: {free}")
    return free


def param_step(key: str, value: float, dz: float = DZ) -> float:
    """Central-difference step for a freed parameter: dz in radians for angles (expressed in
    degrees), dz relative (at least dz absolute) otherwise."""
    if key.endswith("_deg"):
        return math.degrees(dz)
    return dz * max(1.0, abs(value))


def pin_residual(pins, z, params: Params) -> list[float]:
    """The extra conditions: apex energy or a component of z minus its pinned value."""
    out = []
    for name, value in pins:
        if name == "energy":
            out.append(apex_energy(z, params) - value)
        else:
            out.append(float(z[Z_NAMES.index(name)]) - value)
    return out


def make_residual(params: Params, free, pins, sim_kw):
    """F(u) for u = [z (SI), freed values]: [P(z) - z, pins]; None where a stride fails."""

    def residual(u):
        try:
            p = params.with_values(**dict(zip(free, u[6:], strict=True))) if free else params
        except ValueError:
            return None  # e.g. a touchdown angle outside (0, 90) deg
        res = stride(u[:6], p, **sim_kw)
        if res.z1 is None or not np.all(np.isfinite(res.z1)):
            return None
        return np.concatenate([res.z1 - u[:6], pin_residual(pins, u[:6], p)])

    return residual


def find_fixed_point(
    params: Params,
    z0,
    free=(),
    pin=None,
    tol: float = NEWTON_TOL,
    max_iter: int = NEWTON_MAX_ITER,
    dz: float = DZ,
    jacobian_method: str = "fd",
    recover: bool = True,
    analyse: bool = True,
    sim_kw: dict | None = None,
) -> FixedPointResult:
    """Newton-Raphson for z* = P(z*) from z0 (SI), optionally freeing parameters.

    ``free`` names gait keys to solve for; ``pin`` gives as many conditions (or one more for
    a conservative model), see the module docstring. With ``analyse`` the result carries
    nabla P(z*) by ``jacobian_method`` ("fd": eq. 23, or "variational"), its eigenvalues and
    e_max, the phases; with ``recover`` also the strides to recover from +1 % on y_g.
    """
    sim_kw = dict(sim_kw or {})
    free = check_free(free)
    pins = normalize_pins(pin)
    if len(pins) not in (len(free), len(free) + 1):
        raise ValueError(
            f"{len(free)} freed parameter(s) need {len(free)} pin(s) "
            f"(or one more for zero damping), got {len(pins)}"
        )
    gd = params.to_gait_dict()
    u0 = np.concatenate([np.asarray(z0, dtype=float).reshape(6), [gd[k] for k in free]])
    steps = np.concatenate([np.full(6, dz), [param_step(k, gd[k], dz) for k in free]])
    residual = make_residual(params, free, pins, sim_kw)
    out = newton(residual, u0, steps, tol=tol, max_iter=max_iter)
    reason = out.reason
    if reason == "the start falls":
        res0 = stride(u0[:6], params, **sim_kw)
        reason = f"the start falls: {res0.failure}"
    free_vals = dict(zip(free, (float(v) for v in out.u[6:]), strict=True))
    try:
        p_out = params.with_values(**free_vals) if free else params
    except ValueError:
        p_out = params
    result = FixedPointResult(
        z=out.u[:6].copy(),
        params=p_out,
        residual=inf_norm(None if out.residual is None else out.residual[:6]),
        converged=out.converged,
        reason=reason,
        iterations=out.iterations,
        free=free_vals,
        history=out.history,
    )
    if analyse:
        analyse_fixed_point(
            result, jacobian_method=jacobian_method, dz=dz, recover=recover, sim_kw=sim_kw
        )
    return result


def analyse_fixed_point(
    result: FixedPointResult, jacobian_method="fd", dz=DZ, recover=True, sim_kw=None
) -> FixedPointResult:
    """Fill in phases, durations and (when converged) eigenvalues, e_max and recovery."""
    sim_kw = dict(sim_kw or {})
    res = stride(result.z, result.params, **sim_kw)
    result.phases, result.durations = list(res.phases), [float(d) for d in res.durations]
    if not result.converged:
        return result
    try:
        st = stability(result.z, result.params, method=jacobian_method, dz=dz, **sim_kw)
    except StrideFailure as e:
        result.reason = f"converged, but the Jacobian failed: {e.reason}"
        return result
    result.jacobian, result.eigenvalues, result.emax = st.jacobian, st.eigenvalues, st.emax
    if recover:
        result.strides_to_converge = recovery(result.z, result.params, 0, **sim_kw).strides
    return result


# --------------------------------------------------------------------------------------------
# The paper's slope-angle secant (III.D.5, eq. 27)
# --------------------------------------------------------------------------------------------


@dataclass
class SecantResult:
    """alpha from eq. (27): the slope on which the gait's energy balances."""

    alpha_deg: float
    converged: bool  # |dE| <= tol_energy
    reason: str
    iterations: int
    history: list  # (alpha_deg, dE [J]) per evaluation; dE None where the run fell
    run: IterationResult | None = None  # the 100-stride run at the final alpha

    @property
    def fixed_point_found(self) -> bool:
        """The paper's acceptance (step C): energy balanced and max |z_99 - z_100| < 1e-5."""
        return self.converged and self.run is not None and self.run.converged


def energy_error(run: IterationResult, reference: str) -> float | None:
    """dE of eq. (27) from a run with energies; None if it fell.

    ``"start"``: E(z_n) - E(z_0), energy at the end of the n-th stride minus at the start of
    the run. ``"stride"``: E(z_n) - E(z_{n-1}), across the n-th stride alone.
    """
    if run.failure is not None:
        return None
    if reference == "start":
        return float(run.energies[-1] - run.energies[0])
    if reference == "stride":
        return float(run.energy_error)
    raise ValueError(f"energy reference must be 'start' or 'stride', got {reference!r}")


def slope_secant(
    params: Params,
    z0,
    alpha1_deg: float | None = None,
    d_alpha_deg: float = 0.01,
    n_strides: int = PAPER_STRIDES,
    reference: str = "start",
    tol_energy: float = 1e-9,
    max_iter: int = 30,
    sim_kw: dict | None = None,
) -> SecantResult:
    """The slope angle that balances the energy (III.D.5, eq. 27).

    From alpha_0 (``params``) and alpha_1 (``alpha1_deg``, default alpha_0 + d_alpha_deg),
    n strides are run from ``z0`` at each alpha_k and the energy error dE_k measured, then
    alpha_k = alpha_{k-2} - dE_{k-2} (alpha_{k-1} - alpha_{k-2}) / (dE_{k-1} - dE_{k-2}).

    What "balance" means. The apex energy (`apex_energy`, slope frame, without the
    -M g sin(alpha) x_g term) changes over a stride by the work of gravity along the slope
    minus the spine damper's loss. The paper's wording ("the energy error between the
    initial state of 100th step and the final state") admits two readings:

    - ``reference="start"`` (default): dE = E(z_100) - E(z_0). alpha is chosen so that the
      gait the run settles on has the energy of the start, i.e. the energy is pinned at the
      previous fixed point's level while kc changes (III.D.4 steps A-C). This is well posed
      for an asymptotically stable gait: z_100 ~ z*(alpha) and E(z*(alpha)) is monotone
      in alpha near the gait.
    - ``reference="stride"``: dE = E(z_100) - E(z_99), the imbalance across the 100th stride.
      For a near-conservative gait (e_max ~ 1, large kc) the run does not settle and this is
      the same condition as above; for an asymptotically stable gait it is ~0 for *every*
      alpha (z_99 ~ z_100), so its root is ill-conditioned. Offered for comparison.
    """
    sim_kw = dict(sim_kw or {})
    a0 = params.to_gait_dict()["alpha_deg"]
    a1 = a0 + d_alpha_deg if alpha1_deg is None else float(alpha1_deg)
    hist: list = []
    runs: dict = {}

    def evaluate(a):
        try:
            p = params.with_values(alpha_deg=a)
        except ValueError:
            hist.append((a, None))
            return None
        run = iterate(z0, p, n_strides, energies=True, **sim_kw)
        de = energy_error(run, reference)
        hist.append((a, de))
        runs[a] = run
        return de

    pts = []  # (alpha, dE) with dE finite, last two used by eq. (27)
    for a in (a0, a1):
        de = evaluate(a)
        if de is None:
            return SecantResult(
                a, False, f"the run at alpha = {a:.6g} deg falls", len(hist), hist, runs.get(a)
            )
        pts.append((a, de))
        if abs(de) <= tol_energy:
            return SecantResult(a, True, "energy balanced", len(hist), hist, runs[a])
    for _ in range(max_iter):
        (a_2, e_2), (a_1, e_1) = pts[-2], pts[-1]
        if e_1 == e_2:
            return SecantResult(
                a_1, False, "secant degenerate: equal energy errors", len(hist), hist, runs[a_1]
            )
        a = a_2 - e_2 * (a_1 - a_2) / (e_1 - e_2)  # eq. (27)
        de = evaluate(a)
        for _ in range(20):  # a run that falls: retreat towards the last good alpha
            if de is not None:
                break
            a = 0.5 * (a + a_1)
            de = evaluate(a)
        if de is None:
            return SecantResult(
                a_1, False, "runs fall near the secant's next alpha", len(hist), hist, runs[a_1]
            )
        pts.append((a, de))
        if abs(de) <= tol_energy or abs(a - a_1) < 1e-13:
            ok = abs(de) <= tol_energy
            return SecantResult(
                a,
                ok,
                "energy balanced" if ok else f"alpha stalled with dE = {de:.3e} J",
                len(hist),
                hist,
                runs[a],
            )
    a, de = pts[-1]
    return SecantResult(
        a,
        False,
        f"no balance in {max_iter} secant steps (dE = {de:.3e} J)",
        len(hist),
        hist,
        runs[a],
    )


# --------------------------------------------------------------------------------------------
# The paper's search process (III.D.4, steps A-F)
# --------------------------------------------------------------------------------------------


def ladder(
    params: Params, gamma_step_deg=0.5, gamma_max_deg=4.0, k_step=100.0, k_max_steps=3
) -> list[dict]:
    """Parameter changes tried in order (steps E-F): none; gamma_b then gamma_f by
    +-0.5 deg up to +-4 deg; then (kb, kf) together by +-100 N/m up to k_max_steps times."""
    gd = params.to_gait_dict()
    out: list[dict] = [{}]
    n = int(round(gamma_max_deg / gamma_step_deg))
    for i in range(1, n + 1):
        for key in ("gamma_b_deg", "gamma_f_deg"):
            for s in (1.0, -1.0):
                out.append({key: gd[key] + s * i * gamma_step_deg})
    for i in range(1, k_max_steps + 1):
        for s in (1.0, -1.0):
            out.append({"kb": gd["kb"] + s * i * k_step, "kf": gd["kf"] + s * i * k_step})
    return out


def paper_search(
    params: Params,
    z0,
    max_newton: int = 100,
    gamma_step_deg: float = 0.5,
    gamma_max_deg: float = 4.0,
    k_step: float = 100.0,
    k_max_steps: int = 3,
    reference: str = "start",
    polish: bool = True,
    max_candidates: int | None = None,
    sim_kw: dict | None = None,
    log=None,
) -> FixedPointResult:
    """The paper's search for a fixed point near z0 (III.D.4 steps C-F), bounded.

    For each candidate parameter set of `ladder` (unchanged first): step C, `slope_secant`
    for alpha and the 100-stride check; if the check fails, step D, one damped Newton update
    of z_0 at that alpha, and back to C, at most ``max_newton`` times. The first candidate
    passing the check gives z* = z_100 (then polished by Newton to 1e-10 at the found alpha
    if ``polish``). Worst case ~ candidates x max_newton x (a few 100-stride runs).
    """
    sim_kw = dict(sim_kw or {})
    cands = ladder(params, gamma_step_deg, gamma_max_deg, k_step, k_max_steps)
    cands = cands[:max_candidates] if max_candidates else cands
    tried = []
    for changes in cands:
        try:
            p = params.with_values(**changes)
        except ValueError as e:
            tried.append({"changes": changes, "outcome": f"invalid: {e}"})
            continue
        z = np.asarray(z0, dtype=float).copy()
        outcome = f"no fixed point after {max_newton} Newton updates"
        for k in range(max_newton + 1):
            sec = slope_secant(p, z, reference=reference, sim_kw=sim_kw)  # step C
            p_a = p.with_values(alpha_deg=sec.alpha_deg)
            if log:
                log(
                    f"paper_search {changes or 'initial'}: update {k}, alpha "
                    f"{sec.alpha_deg:.6f} deg, {sec.reason}, 100-stride error "
                    f"{sec.run.error if sec.run else math.nan:.2e}"
                )
            if sec.fixed_point_found:
                free = {"alpha_deg": sec.alpha_deg, **changes}
                tried.append({"changes": changes, "outcome": "found", "newton_updates": k})
                return _paper_result(p_a, sec.run.z_last, free, k, tried, polish, sim_kw)
            if k == max_newton:
                break
            step = newton(
                make_residual(p_a, (), [], sim_kw), z, np.full(6, DZ), tol=0.0, max_iter=1
            )  # step D: one damped Newton update
            if not (step.converged or step.reason.startswith("no convergence")):
                outcome = f"Newton update failed: {step.reason}"
                break
            z = step.u[:6]
        tried.append({"changes": changes, "outcome": outcome})
    res = FixedPointResult(
        z=np.asarray(z0, dtype=float),
        params=params,
        residual=math.inf,
        converged=False,
        reason=f"paper search: no fixed point after {len(tried)} parameter set(s)",
        method="paper",
        history=tried,
    )
    return analyse_fixed_point(res, sim_kw=sim_kw)


def _paper_result(p, z100, free, updates, tried, polish, sim_kw) -> FixedPointResult:
    if polish:
        res = find_fixed_point(p, z100, sim_kw=sim_kw)
        if not res.converged:  # keep the paper's z_100 and say so
            res = _unpolished(p, z100, sim_kw, f"found (polishing failed: {res.reason})")
    else:
        res = _unpolished(p, z100, sim_kw, "found (100-stride criterion)")
    res.method, res.free, res.iterations = "paper", free, updates
    res.history = tried
    return res


def _unpolished(p, z, sim_kw, reason) -> FixedPointResult:
    z1 = stride(z, p, **sim_kw).z1
    r = math.inf if z1 is None else float(np.max(np.abs(z1 - z)))
    res = FixedPointResult(z=np.asarray(z), params=p, residual=r, converged=True, reason=reason)
    return analyse_fixed_point(res, sim_kw=sim_kw)
