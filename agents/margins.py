"""Stability margins of a closed loop, passive or learned, on the same yardsticks.

``bound-env margins --policy passive|lqr|deadbeat|damping|SPEC.yaml|PATH`` evaluates the zero
action, a classical controller (`bound_env.control`, designed for ``--gait``) or a trained
policy (deterministic, with its ``VecNormalize`` observation normalization) on PassiveBound.
A controller's optional ``on_apex(z, time_since_apex)`` is described under "Controllers".

The closed-loop apex map
------------------------
Everything below is measured on the apex-to-apex map of the closed loop, P_pi: start an
episode at an apex state z with ``reset(options={"apex_state": z})``, step the policy until
the step in which a stride completes, and read ``info["apex_z"]``. Control intervals restart
at the apex (the reset puts t = 0 there and the observation's time-since-apex at 0), so P_pi
is a well defined function of z: the same z always meets the same sequence of control
instants. (Inside one long episode the dt grid drifts against the apex, and the apex
sequence is not exactly a map of z.) Iterating the map = chaining such one-stride episodes.
With zero action P_pi is the passive Poincare map P of the paper (eq. 18), up to the
integrator tolerance (rtol = 1e-10 here).

Measures (JSON keys)
--------------------
- ``emax``, ``eigenvalues``: the closed-loop fixed point z_cl (iteration, then Newton with
  central differences through the simulator with the policy in the loop) and the eigenvalues
  of the Jacobian of P_pi there (``[re, im]`` pairs, largest modulus first);
  ``fixed_point_shift`` = z_cl - z* (SI).
- ``basin`` (a **minimal fatal shock** per axis): for each apex component i and each sign,
  the largest relative perturbation s
  such that the loop started at z_cl + s |z*_i| e_i *returns*: max_j |z_j - z_cl_j| < 1e-4
  (SI) within a bounded number of strides, without a fall. **Uncapped**: s = 1e-3 and s = 1
  are tried first; while the loop returns, the bracket grows by doubling from the last
  success, up to the direction's *physical cap*: the smallest s at which the start state
  itself is invalid (a hip or the spine joint at or below the ground, or x_dot <= 0, as
  `bound_env.hybrid.start_status` says), else ``BASIN_CAP`` (64 |z*_i|). Then bisection on
  log s. An entry that reaches its cap says ``capped: true`` (and ``cap``, ``cap_reason``).
  Each entry has ``rel`` (units of |z*_i|), ``abs`` (SI), ``rel_cycle`` (units of the
  component's passive peak-to-peak range, below), ``capped``, ``share`` (= abs / the
  direction's ceiling) and ``beyond``: the first failing perturbation beyond the edge (size,
  failure reason or ``no_return``, stride, phase, and geometric mechanisms of its start).
  The perturbations are relative to the *passive* z* for every controller, so the absolute
  sizes are identical.
- ``basin_scale``: the two yardsticks per component: ``zstar`` = |z*_i| (the paper-style
  scale; ``basin_min`` and ``basin_curve`` use it, as before) and ``cycle`` = the peak-to-peak
  range of the component over one passive stride of the gait (so that a step in theta1 means
  as much as a step in xdot_g). ``basin_min`` (``basin_min_direction``) is the smallest
  ``rel`` of the 12 directions, ``basin_min_cycle`` (``basin_min_cycle_direction``) the
  smallest ``rel_cycle``.
- ``basin_ceiling`` (same shape as ``basin``): for each direction the largest perturbation
  from which *some* admissible open-loop torque profile (|tau| <= max_torque, piecewise
  constant over ``PROFILE_SEG`` control intervals) completes the first ``ceiling_strides``
  strides without a fall. Searched, at each tested size, over the zero profile, the two
  constant extremes, bang-bang profiles with one switch, random piecewise-constant profiles
  and a (1+1) evolution-strategy shooting optimizer started from the best of them (budget in
  ``settings``); grown and bisected like the basin. A search can only find profiles, so the
  ceiling is a lower bound on the true one. ``mechanism`` names what stops it at the first
  failing size: geometric ("back hip below touchdown height at the apex": the back hip's
  height at the start is below l_b cos gamma_b, so the leg cannot be placed; the start state
  invalid) or "no admissible profile found" with the best profile's failure.
  ``basin_share_min`` (``basin_share_min_direction``) is the smallest basin / ceiling.
- ``basin_curve`` (a **basin stability** estimate, Menck et al. 2013): the probability of
  returning against the size r of a perturbation in a random direction: z_cl + r |z*| * u
  with u uniform on the sphere and scaled to max |u_i| = 1 (so r is the largest relative
  perturbation of any component, in the ``zstar`` scale); the same directions (``--seed``,
  default ``CURVE_SEED``: the test set) for every size and every controller; 95 % Wilson
  intervals per point (``ci_low``, ``ci_high``); ``r50`` = the size at which P(return) first
  falls below 0.5, interpolated linearly in log r between the two sizes around the crossing
  (``r50_grid``: the largest grid size up to which P >= 0.5, the earlier definition, which
  depends on the grid); ``r50_ci`` = the same crossing of the interval's bounds.
  ``outcomes``: per size, the outcome (1: returned, 0: not) from each direction, in the
  order of ``random_directions(directions, direction_seed)``, for paired comparisons of two
  controllers on the same directions (`agents.compare`, `bound_env.analysis.paired`).
- ``terrain``: survival of ``terrain_runs`` runs of ``terrain_strides`` strides from z_cl on
  rough terrain (``slope_noise_deg`` = sigma: the slope changes by sigma xi at every apex,
  `bound_env.terrain`), each run one long episode with its own seed (``TERRAIN_SEED`` + k),
  against sigma [deg], with Wilson intervals; ``terrain_sigma50_deg`` = the sigma at which the
  survival first falls below one half (log-interpolated as r50; ``terrain_sigma50_grid_deg``:
  the largest grid sigma with survival >= 1/2; ``terrain_sigma50_ci_deg`` from the interval's
  bounds).
- ``mfpt`` (the **mean first-passage time**, Byl & Tedrake 2009): for each sigma of
  ``mfpt_sigmas``, ``mfpt_robots`` runs from z_cl on rough terrain for up to
  ``mfpt_strides`` strides (env seeds from the seed's MFPT base), batched on the task's
  kernel (`rough_episodes`); with a constant per-stride hazard, MFPT = strides attempted /
  falls (``strides_total``, ``failures``; the maximum-likelihood estimate with runs censored
  at the horizon), a lower bound (``lower_bound: true``, = strides_total) with no fall, and
  an exact Poisson interval (``ci``). ``mfpt_sigma_100_deg``: the sigma at which the MFPT
  falls to 100 strides, log MFPT interpolated linearly in log sigma (None if not bracketed).
- ``slope_window_deg``, ``kc_window``: the range of slope alpha (deg), and separately of
  spine stiffness k_c (N m/rad), containing the nominal value over which the loop started at
  z_cl survives ``window_strides`` strides (50) without a fall (``gait_overrides``); edges by
  an outward doubling scan, then bisection.
- ``push``: success rate (returns, as for the basin) against the size of a kick in forward
  speed (``xdot``, m/s) and in pitch rate (``th1dot``, rad/s) added to the state at a random
  control instant within a stride of the cycle, with a random sign; ``p50`` is the largest
  size up to which the rate stays >= 50 %.
- ``effort``: mean |tau| (N m, time average) over one stride of the closed-loop cycle, and
  ``effort_frac`` = effort / max_torque.

Controllers
-----------
`compute_margins` takes ``"passive"``, a policy path, or any controller object with the
protocol ``__call__(obs) -> float`` (normalized torque in [-1, 1]), ``fingerprint() -> str``
(changes whenever its actions can), optional ``env_kwargs`` (environment arguments it was
made for, e.g. ``max_torque``), optional ``name`` and optional ``on_apex(z, time_since_apex)``
(called at the start apex of every episode and at every apex reached).

Seeds
-----
``--seed`` (``seed``) picks every random sample: the directions, the rough-terrain runs, the
push trials and the MFPT robots (`sample_seeds`). The default (``DEFAULT_SEED`` = 12345) is
the test set that docs/MARGINS.md reports, with the samples it always had; any other seed is
a held-out (validation) set. The seed is in the JSON (``seed``, ``seed_role``) and the key.

Evaluations run through a `concurrent.futures` executor (``--workers N`` processes; any
object with ``submit`` returning futures can be passed to `compute_margins`). Every task's
result is cached in ``<out>/cache.jsonl`` under a key (`setup_key`) of the controller's
fingerprint and env kwargs, the gait's name and file contents, the budget, the seed, every
module setting that changes a result (`SETTINGS`: tolerances, seeds of the push and MFPT
samples, the ceiling search's settings) and a hash of the source (`source_hash`: every .py
file of bound_env/ and the margins modules of agents/), so an interrupted run resumes and a
changed setting or code never returns a stale result.
"""

from __future__ import annotations

import contextlib
import csv
import json
import math
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from bound_env.analysis.numerics import (  # noqa: F401 - bisect_threshold: re-exported
    bisect_threshold,
    fd_jacobian,
    map_fixed_point,
    sorted_eigenvalues,
)
from bound_env.cache import TaskCache, atomic_write, settings_hash
from bound_env.parallel import (
    SerialExecutor,  # noqa: F401 - its old home, kept as an alias
    TasksFailed,
    open_pool,
    run_tasks,
)
from bound_env.params import Z_NAMES, Z_SI_UNITS

from .policy import load_controller
from .stats import (
    crossing_on_grid,
    mfpt_crossing,
    mfpt_estimate,
    threshold_on_grid,
    wilson_interval,
)

ENV_ID = "PassiveBound-v0"
Z_LABELS, Z_UNITS = Z_NAMES, Z_SI_UNITS  # apex components and their SI units
RETURN_TOL = 1e-4  # "returned to the cycle": max-abs apex error below this (SI)
EVAL_RTOL = 1e-10  # integrator tolerance of every evaluation (training uses the env's 1e-8)
BASIN_LO, BASIN_HI = 1e-3, 1.0  # first bracket of the relative basin search (then it grows)
BASIN_CAP = 64.0  # largest relative perturbation tried where the start state stays valid
CURVE_SEED = 12345  # random directions of the test curve (training validation uses others)
DEFAULT_SEED = CURVE_SEED  # --seed: the test set (docs/MARGINS.md); any other is held out
TERRAIN_SEED = 20_000  # rough-terrain run k uses env seed TERRAIN_SEED + k (default seed)
PUSH_SEED = 2024  # push trial j of size index i: rng([i, kind, PUSH_SEED]) (default seed)
MFPT_SEED = 30_000  # MFPT robot k uses env seed MFPT_SEED + k (default seed)
MFPT_CHUNK = 16  # MFPT robots per task (a cached, resumable unit)
MFPT_LEVEL = 100.0  # mfpt_sigma_100_deg: the sigma at which the MFPT falls to this [strides]
PROFILE_SEG = 5  # ceiling search: control intervals per piece of a torque profile
PROFILE_SPAN = 1.3  # ceiling search: the profile covers 1.3 x the strides' nominal duration
# ceiling search, (1+1)-ES: share of pieces mutated, first step, growth on success, shrink on
# failure, step bounds
CEILING_ES = {"mutate": 0.3, "step": 0.5, "grow": 1.5, "shrink": 0.85, "min": 0.05, "max": 2.0}
CYCLE_RECORD_DT = 1e-3  # sampling of the passive stride for the cycle scale [s]
FD_REL = 1e-4  # central-difference step, relative to max(|z*_i|, FD_FLOOR_i)
FD_FLOOR = np.array([0.01, 0.01, 0.01, 0.1, 0.1, 0.1])  # SI floors of the FD step scale
Y_XDOT, Y_TH1DOT = 4, 6  # indices in the full state y = [x, y, th1, th2, xd, yd, th1d, th2d]


@dataclass(frozen=True)
class Budget:
    """How hard to look (iterations, strides, samples)."""

    name: str
    basin_iters: int  # bisection steps on log(s) per direction
    basin_strides: int  # strides allowed to return
    curve_sizes: tuple  # relative sizes r of random-direction perturbations
    curve_dirs: int  # random directions per size
    window_iters: int  # bisection steps per window edge
    window_strides: int  # strides to survive
    push_xdot: tuple  # kick sizes in xdot [m/s]
    push_th1dot: tuple  # kick sizes in th1dot [rad/s]
    push_samples: int  # random phases/signs per size
    newton_iters: int = 8
    settle_strides: int = 60  # map iterations before Newton
    ceiling_strides: int = 2  # strides an open-loop profile must complete
    ceiling_iters: int = 6  # bisection steps per ceiling
    ceiling_random: int = 16  # random piecewise-constant profiles per tested size
    ceiling_opt: int = 16  # (1+1)-ES shooting iterations per tested size
    terrain_sigmas: tuple = (0.05, 0.1, 0.2, 0.5, 1.0)  # slope noise [deg]
    terrain_runs: int = 16  # rough-terrain runs per sigma
    terrain_strides: int = 50  # strides to survive
    mfpt_sigmas: tuple = (0.2, 0.35, 0.6, 1.0)  # slope noise of the MFPT [deg]
    mfpt_robots: int = 16  # robots per sigma, each one long run from the cycle
    mfpt_strides: int = 100  # horizon of a run [strides] (censored there)


_CURVE_FULL = tuple(float(x) for x in np.round(np.geomspace(0.005, 0.5, 16), 5)) + (0.7, 1.0)
_TERRAIN_FULL = (0.02, 0.05, 0.1, 0.15, 0.2, 0.3, 0.5, 0.75, 1.0, 1.5, 2.0, 3.0)
_MFPT_FULL = (0.05, 0.1, 0.15, 0.2, 0.3, 0.4, 0.5, 0.75, 1.0, 1.5)
BUDGETS = {
    "test": Budget(
        "test",
        3,
        40,
        (0.01, 0.1),
        2,
        2,
        10,
        (0.1, 0.4),
        (0.5, 2.0),
        2,
        newton_iters=3,
        settle_strides=10,
        ceiling_strides=1,
        ceiling_iters=2,
        ceiling_random=2,
        ceiling_opt=2,
        terrain_sigmas=(0.05, 0.5),
        terrain_runs=2,
        terrain_strides=5,
        mfpt_sigmas=(0.2, 2.0),
        mfpt_robots=3,
        mfpt_strides=8,
    ),
    "quick": Budget(
        "quick",
        7,
        100,
        (0.01, 0.02, 0.04, 0.06, 0.1, 0.15, 0.25, 0.4, 0.7),
        32,
        5,
        50,
        (0.05, 0.1, 0.2, 0.3, 0.4, 0.6, 0.8),
        (0.25, 0.5, 1.0, 2.0, 3.0, 4.0, 6.0),
        8,
    ),
    "full": Budget(
        "full",
        14,
        300,
        _CURVE_FULL,
        256,
        10,
        50,
        (0.05, 0.1, 0.15, 0.2, 0.25, 0.3, 0.35, 0.4, 0.5, 0.6, 0.8, 1.0),
        (0.25, 0.5, 0.75, 1.0, 1.25, 1.5, 2.0, 2.5, 3.0, 4.0, 5.0, 6.0),
        64,
        ceiling_strides=2,
        ceiling_iters=8,
        ceiling_random=48,
        ceiling_opt=48,
        terrain_sigmas=_TERRAIN_FULL,
        terrain_runs=64,
        terrain_strides=100,
        mfpt_sigmas=_MFPT_FULL,
        mfpt_robots=32,
        # 2000-stride runs (64 000 strides per sigma): MFPTs up to ~10^4 strides are resolved,
        # longer ones reported as lower bounds; 10^4-stride runs made the page ~1.5 h on 2 cores
        mfpt_strides=2000,
    ),
    # ~1/3 of the full budget's cost where it matters (fewer curve sizes and push samples,
    # fewer terrain levels), the same definitions otherwise: 256 random directions, 300
    # strides to return, 64 rough-terrain runs of 100 strides
    "standard": Budget(
        "standard",
        10,
        300,
        (0.01, 0.02, 0.03, 0.05, 0.08, 0.12, 0.2, 0.35, 0.6),
        256,
        10,
        50,
        (0.05, 0.1, 0.15, 0.2, 0.3, 0.4, 0.6, 0.8),
        (0.25, 0.5, 0.75, 1.0, 1.5, 2.0, 3.0, 4.0),
        32,
        ceiling_strides=2,
        ceiling_iters=8,
        ceiling_random=48,
        ceiling_opt=48,
        terrain_sigmas=(0.02, 0.05, 0.1, 0.2, 0.3, 0.5, 0.75, 1.0),
        terrain_runs=64,
        terrain_strides=100,
        mfpt_sigmas=_MFPT_FULL,
        mfpt_robots=32,
        mfpt_strides=2000,
    ),
}
# Window scans: first offset from nominal, doubling up to the limit.
WINDOW_SCAN = {"alpha_deg": (0.005, 4.0), "kc": (0.5, 256.0)}


# --------------------------------------------------------------------------------------------
# Numerics: `bound_env.analysis.numerics` (the names below were defined here and stay importable)
# --------------------------------------------------------------------------------------------


def central_jacobian(f, z, steps) -> np.ndarray:
    """Jacobian of f at z by central differences with per-component ``steps`` (no one-sided
    fallback: a failing side raises). Alias of `numerics.fd_jacobian` with ``one_sided=False``."""
    return fd_jacobian(f, z, steps, one_sided=False)


def find_fixed_point(f, z0, steps, settle: int = 60, newton_iters: int = 8, tol: float = 1e-11):
    """Old name of `bound_env.analysis.numerics.map_fixed_point` (returns (z, residual,
    Jacobian)); `bound_env.analysis.find_fixed_point` is the Poincare map's."""
    return tuple(map_fixed_point(f, z0, steps, settle=settle, newton_iters=newton_iters, tol=tol))


def random_directions(n: int, seed: int = CURVE_SEED) -> np.ndarray:
    """n directions uniform on the 6-sphere, each scaled to max |u_i| = 1."""
    u = np.random.default_rng(seed).standard_normal((n, 6))
    return u / np.max(np.abs(u), axis=1, keepdims=True)


def check_seed(seed) -> int:
    """``--seed`` as an int in [0, 2**32) (numpy's seeds are non-negative), else ValueError."""
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or not 0 <= seed < 2**32:
        raise ValueError(f"--seed must be an integer in [0, 2**32), got {seed!r}")
    return int(seed)


def sample_seeds(seed: int = DEFAULT_SEED) -> dict:
    """The seeds of every random sample that ``--seed`` picks: the random directions
    (``directions``: `random_directions`' seed), the rough-terrain runs (``terrain``: run k
    uses env seed terrain + k), the push trials (``push``: the tail of their RNG key
    [size index, kind, *push]) and the MFPT robots (``mfpt``: robot k uses env seed mfpt + k).
    The default seed gives the test set's samples as they always were (directions of seed
    12345, terrain seeds 20000 + k, push key [i, kind, 2024]); any other seed gives fresh
    ones, derived from it (`numpy.random.SeedSequence`), for a held-out (validation) set."""
    seed = check_seed(seed)
    if seed == DEFAULT_SEED:
        return {"directions": seed, "terrain": TERRAIN_SEED, "push": [PUSH_SEED], "mfpt": MFPT_SEED}
    terrain, mfpt = (int(v) for v in np.random.SeedSequence([seed, 1]).generate_state(2) >> 2)
    return {"directions": seed, "terrain": terrain, "push": [PUSH_SEED, seed], "mfpt": mfpt}


# --------------------------------------------------------------------------------------------
# The closed loop
# --------------------------------------------------------------------------------------------


@dataclass
class StrideOut:
    """One stride of the closed-loop map."""

    z1: np.ndarray | None
    failure: str | None
    effort: float = math.nan  # time-averaged |tau| [N m]
    period: float = math.nan  # [s]
    steps: int = 0  # control intervals started
    phase: str | None = None  # stance condition at the end (at the failure)


class ClosedLoop:
    """A controller in the loop of one PassiveBound environment (no wrappers).

    ``stride(z)`` is the closed-loop apex map (see the module docstring); ``kick`` adds
    ``delta`` to one entry of the simulator state just before control interval ``step``.
    """

    def __init__(
        self,
        controller,
        gait: str = "default",
        gait_overrides: dict | None = None,
        env_extra: dict | None = None,
    ):
        import gymnasium as gym

        import bound_env

        gym.register_envs(bound_env)
        kwargs = dict(getattr(controller, "env_kwargs", None) or {})
        kwargs.update(env_extra or {})
        kwargs["gait"] = gait
        overrides = {**(kwargs.get("gait_overrides") or {}), **(gait_overrides or {})}
        kwargs["gait_overrides"] = overrides or None
        kwargs["rtol"] = EVAL_RTOL
        kwargs["reset_noise_scale"] = 0.0
        self.env = gym.make(ENV_ID, **kwargs).unwrapped
        self.controller = controller
        self.max_torque = float(self.env.task.max_torque)
        self.dt = float(self.env.task.dt)
        from bound_env.task import NO_APEX_TIME

        self.max_steps = int(math.ceil(NO_APEX_TIME / self.dt)) + 2
        self.i_since_apex = list(self.env.task.obs_names).index("time_since_apex")
        self.on_apex = getattr(controller, "on_apex", None)
        self.last_phase: str | None = None  # stance condition at the end of the last `run`

    def stride(self, z, kick: tuple | None = None) -> StrideOut:
        env, ctrl = self.env, self.controller
        z = np.asarray(z, dtype=float)
        obs, info = env.reset(options={"apex_state": z})
        if info["failure"] is not None:
            return StrideOut(None, info["failure"], phase="df")
        if self.on_apex is not None:
            self.on_apex(z, 0.0)
        t_prev, impulse = 0.0, 0.0
        for k in range(self.max_steps):
            if kick is not None and k == kick[0]:
                apply_kick(env, kick[1], kick[2])
            obs, _, terminated, _, info = env.step(np.array([ctrl(obs)]))
            tau = abs(info["tau"])
            if "apex_z" in info:
                t_apex = info["time"] - float(obs[self.i_since_apex])
                impulse += tau * max(0.0, t_apex - t_prev)
                return StrideOut(
                    np.array(info["apex_z"], dtype=float), None, impulse / t_apex, t_apex, k + 1
                )
            impulse += tau * (info["time"] - t_prev)
            t_prev = info["time"]
            if terminated:
                return StrideOut(None, info["failure"], steps=k + 1, phase=info["phase"])
        return StrideOut(None, "no_apex", steps=self.max_steps, phase=info["phase"])

    def map(self, z) -> np.ndarray | None:
        return self.stride(z).z1

    def run(
        self, z0, z_target, max_strides: int, kick: tuple | None = None, survive_only: bool = False
    ) -> tuple[bool, int, str | None]:
        """Iterate the map from z0 (the first stride kicked if ``kick``). Returns (success,
        strides, failure): success = returned within RETURN_TOL of ``z_target`` within
        ``max_strides`` (or, with ``survive_only``, did not fall in ``max_strides``)."""
        z = np.asarray(z0, dtype=float)
        self.last_phase = None
        for n in range(1, max_strides + 1):
            out = self.stride(z, kick if n == 1 else None)
            if out.z1 is None:
                self.last_phase = out.phase
                return False, n, out.failure
            z = out.z1
            if not np.all(np.isfinite(z)):
                return False, n, "non_finite"
            if not survive_only and np.max(np.abs(z - z_target)) < RETURN_TOL:
                return True, n, None
        return survive_only, max_strides, None

    def episode(self, z0, max_strides: int, seed: int | None = None) -> tuple:
        """One long episode from the apex state z0 (env seed ``seed``: with
        ``slope_noise_deg`` it fixes the terrain). Returns (survived ``max_strides`` strides,
        strides completed, failure)."""
        env, ctrl = self.env, self.controller
        z0 = np.asarray(z0, dtype=float)
        obs, info = env.reset(seed=seed, options={"apex_state": z0})
        if info["failure"] is not None:
            return False, 0, info["failure"]
        if self.on_apex is not None:
            self.on_apex(z0, 0.0)
        while True:
            obs, _, terminated, _, info = env.step(np.array([ctrl(obs)]))
            if terminated:
                self.last_phase = info["phase"]
                return False, info["stride"], info["failure"]
            if "apex_z" in info:
                if info["stride"] >= max_strides:
                    return True, info["stride"], None
                if self.on_apex is not None:
                    self.on_apex(np.array(info["apex_z"]), float(obs[self.i_since_apex]))

    def profile(self, z0, actions, max_strides: int, seg: int = PROFILE_SEG) -> tuple:
        """Open loop: the normalized torques ``actions[j]`` held over control intervals
        [j seg, (j + 1) seg) from the apex state z0, zero after the last piece. Returns
        (strides completed >= max_strides, progress score, failure, phase, strides) with
        score = strides completed + the fraction of a nominal stride survived since."""
        env = self.env
        obs, info = env.reset(options={"apex_state": np.asarray(z0, dtype=float)})
        if info["failure"] is not None:
            return False, 0.0, info["failure"], "df", 0
        n_act = len(actions)
        t_apex = 0.0
        for k in range(self.max_steps * max_strides):
            a = actions[k // seg] if k // seg < n_act else 0.0
            obs, _, terminated, _, info = env.step(np.array([a]))
            if "apex_z" in info:
                t_apex = info["time"] - float(obs[self.i_since_apex])
                if info["stride"] >= max_strides:
                    return True, float(info["stride"]), None, None, info["stride"]
            if terminated:
                frac = min(0.99, (info["time"] - t_apex) / max(self.period_hint, 1e-3))
                return (
                    False,
                    info["stride"] + frac,
                    info["failure"],
                    info["phase"],
                    info["stride"],
                )
        return False, float(info["stride"]), "no_apex", info["phase"], info["stride"]

    period_hint = 0.39  # s, nominal stride duration for the profile score (set by the tasks)


def apply_kick(env, index: int, delta: float) -> None:
    """Add ``delta`` to velocity entry ``index`` (4..7) of the simulator state y between two
    control intervals (`bound_env.env.PassiveBoundEnv.kick`). The controller sees it in the
    next observation (a push is sensed one control interval later, like a sampled sensor)."""
    if not 4 <= index <= 7:
        raise ValueError(f"a kick changes a velocity (state index 4..7), got index {index}")
    d = np.zeros(4)
    d[index - 4] = delta
    env.kick(d)


def rough_episodes(loop: ClosedLoop, z0, seeds, max_strides: int) -> dict:
    """`ClosedLoop.episode` for many robots at once: robot k runs the episode of
    ``loop.episode(z0, max_strides, seed=seeds[k])`` (the same task, hence ``loop``'s rough
    terrain, and the same slope draws from its own env RNG), all advanced together by the
    task's batch kernel, one controller call per control interval: ``batch(obs)`` for a
    controller that has one (and no ``on_apex``), else one copy per robot called row by row
    with ``on_apex`` at every apex, as the single env calls it (then bit-identical to
    ``episode``). Returns {"strides": completed strides per robot, "fell": 0/1 per robot,
    "failures": {reason: count}}."""
    import copy

    from gymnasium.utils import seeding

    from bound_env.task import _Z_IDX, FAIL_FIRST, FAILURE_NAMES, S_NAPEX, S_STATUS, S_STRIDES

    task, ctrl = loop.env.task, loop.controller
    n = len(seeds)
    z0 = task.check_apex_state(z0)
    b = task.new_batch(n)
    rngs = []
    for i, sd in enumerate(seeds):
        rngs.append(seeding.np_random(int(sd))[0])
        task.reset_robot(b, i, z0)
        task.draw_slope_noise(b, i, rngs[i])
    on_apex = getattr(ctrl, "on_apex", None)
    batched = callable(getattr(ctrl, "batch", None)) and on_apex is None
    copies = None if batched else [copy.deepcopy(ctrl) for _ in range(n)]
    if copies is not None and on_apex is not None:
        for c in copies:
            c.on_apex(z0.copy(), 0.0)
    strides = np.zeros(n, dtype=np.int64)
    fell = np.zeros(n, dtype=np.int64)
    failures: dict = {}
    live = b.s[:, S_STATUS] < FAIL_FIRST  # an invalid start fails at the reset (0 strides)
    for i in np.flatnonzero(~live):
        fell[i] = 1
        name = FAILURE_NAMES[int(b.s[i, S_STATUS])]
        failures[name] = failures.get(name, 0) + 1
    while live.any():
        if batched:
            b.actions[:] = ctrl.batch(b.obs)
        else:
            for i in np.flatnonzero(live):
                b.actions[i] = copies[i](b.obs[i])
        b.active[:] = live
        task.step(b)
        s = b.s
        apex = live & (s[:, S_NAPEX] > 0)
        for i in np.flatnonzero(apex):
            task.draw_slope_noise(b, i, rngs[i])
        failed = live & (s[:, S_STATUS] >= FAIL_FIRST)
        for i in np.flatnonzero(failed):
            fell[i], strides[i] = 1, int(s[i, S_STRIDES])
            name = FAILURE_NAMES[int(s[i, S_STATUS])]
            failures[name] = failures.get(name, 0) + 1
        live &= ~failed
        for i in np.flatnonzero(apex & live):
            strides[i] = int(s[i, S_STRIDES])
            if strides[i] >= max_strides:
                live[i] = False
            elif copies is not None and on_apex is not None:
                napex = int(s[i, S_NAPEX])
                z1 = b.apex[i, min(napex, b.apex.shape[1]) - 1][_Z_IDX]
                copies[i].on_apex(np.array(z1, dtype=float), float(b.obs[i, loop.i_since_apex]))
    return {"strides": strides.tolist(), "fell": fell.tolist(), "failures": failures}


# --------------------------------------------------------------------------------------------
# Tasks (run in worker processes)
# --------------------------------------------------------------------------------------------


@dataclass
class Setup:
    """Everything a worker needs; picklable."""

    controller: object
    gait: str
    budget: Budget
    z_star: np.ndarray
    z_cl: np.ndarray | None = None
    cycle_steps: int = 0
    key: str = ""
    period: float = math.nan  # closed-loop stride period [s]
    seed: int = DEFAULT_SEED  # --seed: the random directions, terrain and push samples


_LOOPS: dict = {}


def _loop(setup: Setup, overrides: dict | None = None, env_extra: dict | None = None) -> ClosedLoop:
    k = (
        setup.key,
        tuple(sorted((overrides or {}).items())),
        tuple(sorted((env_extra or {}).items())),
    )
    if k not in _LOOPS:
        if len(_LOOPS) > 64:
            _LOOPS.clear()
        _LOOPS[k] = ClosedLoop(setup.controller, setup.gait, overrides, env_extra)
        if math.isfinite(setup.period):
            _LOOPS[k].period_hint = setup.period
    return _LOOPS[k]


def fd_steps(z_star) -> np.ndarray:
    return FD_REL * np.maximum(np.abs(np.asarray(z_star)), FD_FLOOR)


def task_cycle(setup: Setup) -> dict:
    """Closed-loop fixed point, multipliers, effort on the cycle."""
    loop = _loop(setup)
    b = setup.budget
    z_cl, res, jac = map_fixed_point(
        loop.map,
        setup.z_star,
        fd_steps(setup.z_star),
        settle=b.settle_strides,
        newton_iters=b.newton_iters,
    )
    lam = sorted_eigenvalues(jac)
    out = loop.stride(z_cl)
    return {
        "z_cl": z_cl.tolist(),
        "residual": res,
        "jacobian": jac.tolist(),
        "eigenvalues": [[float(v.real), float(v.imag)] for v in lam],
        "emax": float(np.abs(lam[0])),
        "effort": out.effort,
        "period": out.period,
        "cycle_steps": out.steps,
        "max_torque": loop.max_torque,
    }


def start_geometry(z, loop: ClosedLoop) -> dict:
    """What the apex start state z itself rules out: ``invalid`` (the start failure, or None)
    and ``mechanisms``: geometric reasons a stride from z cannot go as the gait does."""
    from bound_env.dynamics import back_hip, front_hip, make_aux
    from bound_env.hybrid import failure_name, start_status, state_from_z
    from bound_env.params import P_GB, P_GF, P_LB, P_LF

    y = state_from_z(z)
    aux = make_aux(loop.env.params.to_array())
    code = start_status(y, aux)
    invalid = failure_name(code) if code != 0 else None
    mech = []
    if invalid is not None:
        mech.append(f"start state invalid ({invalid})")
    if back_hip(y, aux)[1] < aux[P_LB] * math.cos(aux[P_GB]):
        mech.append("back hip below touchdown height at the apex")
    if front_hip(y, aux)[1] < aux[P_LF] * math.cos(aux[P_GF]):
        mech.append("front hip below touchdown height at the apex")
    return {"invalid": invalid, "mechanisms": mech}


def physical_cap(loop: ClosedLoop, zc, zs, i: int, sign: int) -> tuple[float, str]:
    """(cap, reason): the smallest relative size s (units of |z*_i|) at which the start state
    z_cl + sign s z*_i e_i is invalid (doubling scan, then 40 bisection steps), or
    (BASIN_CAP, "numeric cap") if it stays valid up to BASIN_CAP."""

    def invalid(s):
        z = zc.copy()
        z[i] += sign * s * zs[i]
        return start_geometry(z, loop)["invalid"]

    good, bad = 0.0, BASIN_LO
    while bad <= BASIN_CAP and invalid(bad) is None:
        good, bad = bad, 2.0 * bad
    if bad > BASIN_CAP:
        return BASIN_CAP, "numeric cap"
    for _ in range(40):
        mid = 0.5 * (good + bad)
        if invalid(mid) is None:
            good = mid
        else:
            bad = mid
    return bad, f"start state invalid beyond ({invalid(bad)})"


def hip_thresholds(loop: ClosedLoop, zc, zs, i: int, sign: int, cap: float) -> dict:
    """For "back" and "front": the smallest relative size s <= cap at which that hip starts
    below its touchdown height l cos gamma at the apex (None if it never does up to cap);
    found by a doubling scan and 40 bisection steps on the start geometry alone."""
    out = {}
    for end in ("back", "front"):
        text = f"{end} hip below touchdown height at the apex"

        def below(s, text=text):
            z = zc.copy()
            z[i] += sign * s * zs[i]
            return text in start_geometry(z, loop)["mechanisms"]

        good, bad = 0.0, BASIN_LO
        while bad <= cap and not below(bad):
            good, bad = bad, 2.0 * bad
        if bad > cap:
            out[end] = None
            continue
        for _ in range(40):
            mid = 0.5 * (good + bad)
            if below(mid):
                bad = mid
            else:
                good = mid
        out[end] = bad
    return out


def _grown_search(ok, cap: float, iters: int) -> tuple[float, bool, float | None]:
    """`bisect_threshold` grown up to ``cap``, remembering the tested points: returns
    (edge, capped, smallest failing size tested or None)."""
    fails = []

    def test(s):
        good = ok(s)
        if not good:
            fails.append(s)
        return good

    s, capped = bisect_threshold(
        test, min(BASIN_LO, cap / 2), min(BASIN_HI, cap), iters, grow=True, cap=cap
    )
    first_fail = min(fails) if fails else None
    if not capped and first_fail is not None and first_fail >= cap:
        capped = True  # every size below the (invalid-start) cap returned
    return s, capped, first_fail


def task_basin(setup: Setup, i: int, sign: int) -> dict:
    loop = _loop(setup)
    zs, zc = setup.z_star, setup.z_cl
    n = setup.budget.basin_strides

    def start(s):
        z = zc.copy()
        z[i] += sign * s * zs[i]
        return z

    cap, cap_reason = physical_cap(loop, zc, zs, i, sign)
    s, capped, fail = _grown_search(
        lambda s: loop.run(start(s), zc, n)[0], cap, setup.budget.basin_iters
    )
    beyond = None
    if fail is not None:
        ok, strides, failure = loop.run(start(fail), zc, n)
        geo = start_geometry(start(fail), loop)
        beyond = {
            "rel": fail,
            "reason": failure or "no_return",
            "stride": strides,
            "phase": loop.last_phase if failure else None,
            "mechanisms": geo["mechanisms"],
        }
    return {
        "rel": s,
        "abs": abs(s * zs[i]),
        "capped": capped,
        "cap": cap,
        "cap_reason": cap_reason,
        "beyond": beyond,
    }


def _profile_search(
    loop: ClosedLoop, z, n_strides: int, n_pieces: int, b: Budget, rng: np.random.Generator
) -> tuple[bool, dict]:
    """Is there an admissible torque profile that completes ``n_strides`` strides from z?
    Candidates in order: zero, +-max, bang-bang with one switch, random piecewise-constant
    (half bang-bang valued, half uniform), then a (1+1)-ES shooting optimizer from the best.
    Returns (found, best: {score, failure, phase, stride})."""
    best = {"score": -1.0}
    best_a = None

    def trial(a):
        nonlocal best, best_a
        ok, score, failure, phase, strides = loop.profile(z, a, n_strides)
        if score > best["score"]:
            best = {"score": score, "failure": failure, "phase": phase, "stride": strides}
            best_a = np.array(a, dtype=float)
        return ok

    cands = [np.zeros(n_pieces), np.ones(n_pieces), -np.ones(n_pieces)]
    per_stride = max(2, n_pieces // max(1, n_strides))
    for k in range(1, per_stride, max(1, per_stride // 6)):
        a = np.where(np.arange(n_pieces) < k, 1.0, -1.0)
        cands += [a, -a]
    for j in range(b.ceiling_random):
        if j % 2 == 0:
            cands.append(rng.choice([-1.0, 1.0], n_pieces))
        else:
            cands.append(rng.uniform(-1.0, 1.0, n_pieces))
    for a in cands:
        if trial(a):
            return True, best
    es = CEILING_ES
    step = es["step"]
    for _ in range(b.ceiling_opt):
        mask = rng.random(n_pieces) < es["mutate"]
        child = np.clip(best_a + mask * rng.normal(0.0, step, n_pieces), -1.0, 1.0)
        before = best["score"]
        if trial(child):
            return True, best
        if best["score"] > before:
            step = min(es["max"], step * es["grow"])
        else:
            step = max(es["min"], step * es["shrink"])
    return False, best


def task_ceiling(setup: Setup, i: int, sign: int) -> dict:
    """The largest perturbation along (i, sign) from which some admissible open-loop torque
    profile completes the first ``ceiling_strides`` strides (see the module docstring)."""
    loop = _loop(setup)
    zs, zc, b = setup.z_star, setup.z_cl, setup.budget
    n = b.ceiling_strides
    period = setup.period if math.isfinite(setup.period) else 0.39
    n_pieces = int(math.ceil(PROFILE_SPAN * n * period / loop.dt / PROFILE_SEG))
    found_at: dict = {}

    def start(s):
        z = zc.copy()
        z[i] += sign * s * zs[i]
        return z

    def ok(s):
        rng = np.random.default_rng([i, 1 if sign > 0 else 0, int(round(s * 1e9)) % 2**32])
        found, best = _profile_search(loop, start(s), n, n_pieces, b, rng)
        found_at[s] = best
        return found

    cap, cap_reason = physical_cap(loop, zc, zs, i, sign)
    s, capped, fail = _grown_search(ok, cap, b.ceiling_iters)
    hips = hip_thresholds(loop, zc, zs, i, sign, cap)
    mechanism, beyond, geometric = None, None, False
    if capped:
        mechanism = cap_reason
        geometric = cap_reason != "numeric cap"
    elif fail is not None:
        geo = start_geometry(start(fail), loop)
        best = found_at.get(fail, {})
        beyond = {
            "rel": fail,
            "reason": best.get("failure"),
            "stride": best.get("stride"),
            "phase": best.get("phase"),
            "mechanisms": geo["mechanisms"],
        }
        # geometric: the edge sits at the size where a hip starts below its touchdown height
        # (within the bisection's resolution) and the best profile fails by that hip
        for end, at in hips.items():
            if (
                at is not None
                and s <= at <= fail * 1.001
                and f"ground_contact_{end}_hip" == best.get("failure")
            ):
                mechanism = f"{end} hip below touchdown height at the apex (from s = {at:.4g})"
                geometric = True
                # the geometric edge is known to ~1e-12: the ceiling is just below it if a
                # profile still completes the strides there (sharper than the bisection)
                if at * (1 - 1e-6) > s and ok(at * (1 - 1e-6)):
                    s = at * (1 - 1e-6)
        if mechanism is None:
            mechanism = (
                f"no admissible profile found within the search budget (best: "
                f"{best.get('failure')} in stride {(best.get('stride') or 0) + 1}, "
                f"phase {best.get('phase')})"
            )
    return {
        "rel": s,
        "abs": abs(s * zs[i]),
        "capped": capped,
        "cap": cap,
        "cap_reason": cap_reason,
        "mechanism": mechanism,
        "geometric": geometric,
        "hip_below_touchdown_from": hips,
        "beyond": beyond,
        "profile_pieces": n_pieces,
    }


def task_curve(setup: Setup, size: float) -> dict:
    """Basin stability at one size: the outcome (1: returned) from each random direction."""
    loop = _loop(setup)
    zs, zc = setup.z_star, setup.z_cl
    dirs = random_directions(setup.budget.curve_dirs, sample_seeds(setup.seed)["directions"])
    timed = getattr(loop.controller, "decision_seconds", None)  # a controller that times itself
    n0 = len(timed) if timed is not None else 0
    outcomes = [
        int(loop.run(zc + size * np.abs(zs) * u, zc, setup.budget.basin_strides)[0]) for u in dirs
    ]
    wins = sum(outcomes)
    out = {
        "size": size,
        "success": wins / len(dirs),
        "n": len(dirs),
        "k": int(wins),
        "outcomes": outcomes,
    }
    if timed is not None:  # every decision of these closed loops [s]
        out["decision_seconds"] = [float(t) for t in timed[n0:]]
    return out


def decision_summary(curve: list) -> dict | None:
    """p50, p99, mean and max of a controller's decision times over the random-direction
    curve's closed loops (None for a controller that does not time its decisions)."""
    ts = [t for c in curve for t in c.get("decision_seconds", [])]
    if not any("decision_seconds" in c for c in curve) or not ts:
        return None
    a = np.asarray(ts)
    return {
        "p50": float(np.median(a)),
        "p99": float(np.quantile(a, 0.99)),
        "mean": float(a.mean()),
        "max": float(a.max()),
        "n": int(a.size),
        "measured_on": "every decision of the random-direction curve's closed loops",
    }


def task_terrain(setup: Setup, sigma: float) -> dict:
    """Rough terrain: how many of ``terrain_runs`` episodes from z_cl with slope noise sigma
    [deg] survive ``terrain_strides`` strides."""
    loop = _loop(setup, env_extra={"slope_noise_deg": float(sigma)})
    b = setup.budget
    base = sample_seeds(setup.seed)["terrain"]
    k, strides, reasons = 0, [], {}
    for j in range(b.terrain_runs):
        ok, n, failure = loop.episode(setup.z_cl, b.terrain_strides, seed=base + j)
        k += ok
        strides.append(n)
        if failure:
            reasons[failure] = reasons.get(failure, 0) + 1
    return {
        "sigma_deg": sigma,
        "k": int(k),
        "n": b.terrain_runs,
        "success": k / b.terrain_runs,
        "mean_strides": float(np.mean(strides)),
        "failures": reasons,
    }


def task_window(setup: Setup, key: str, side: int) -> dict:
    """Edge of the survival window of gait parameter ``key`` on one side of nominal."""
    from bound_env.params import load_gait

    nominal = load_gait(setup.gait).params.to_gait_dict()[key]
    overrides0 = dict(setup.controller.env_kwargs.get("gait_overrides") or {})
    nominal = float(overrides0.get(key, nominal))
    first, limit = WINDOW_SCAN[key]
    b = setup.budget

    def survives(offset: float) -> bool:
        value = nominal + side * offset
        if key == "kc" and value <= 0:
            return False
        try:
            loop = _loop(setup, {key: value})
        except ValueError:  # invalid parameter value
            return False
        return loop.run(setup.z_cl, setup.z_cl, b.window_strides, survive_only=True)[0]

    good, bad, d = 0.0, None, first
    while d <= limit:
        if survives(d):
            good, d = d, 2 * d
        else:
            bad = d
            break
    if bad is None:
        return {"edge": nominal + side * good, "capped": True, "nominal": nominal}
    if good == 0.0 and not survives(0.0):
        return {"edge": math.nan, "capped": False, "nominal": nominal}
    for _ in range(b.window_iters):
        mid = 0.5 * (good + bad)
        if survives(mid):
            good = mid
        else:
            bad = mid
    return {"edge": nominal + side * good, "capped": False, "nominal": nominal}


def task_push(setup: Setup, kind: str, size: float, index: int) -> dict:
    loop = _loop(setup)
    y_index = {"xdot": Y_XDOT, "th1dot": Y_TH1DOT}[kind]
    rng = np.random.default_rng(
        [index, 0 if kind == "xdot" else 1, *sample_seeds(setup.seed)["push"]]
    )
    wins = 0
    n = setup.budget.push_samples
    steps = max(1, setup.cycle_steps - 1)
    for _ in range(n):
        k = int(rng.integers(0, steps))
        sign = 1.0 if rng.random() < 0.5 else -1.0
        wins += loop.run(
            setup.z_cl, setup.z_cl, setup.budget.basin_strides, kick=(k, y_index, sign * size)
        )[0]
    return {"kind": kind, "size": size, "success": wins / n, "n": n}


def task_mfpt(setup: Setup, sigma: float, chunk: int) -> dict:
    """Robots chunk * MFPT_CHUNK ... of the MFPT at slope noise sigma [deg]: each one run of up
    to ``mfpt_strides`` strides from z_cl (env seed = the seed's MFPT base + robot index),
    batched (`rough_episodes`)."""
    loop = _loop(setup, env_extra={"slope_noise_deg": float(sigma)})
    b = setup.budget
    first = chunk * MFPT_CHUNK
    robots = range(first, min(b.mfpt_robots, first + MFPT_CHUNK))
    base = sample_seeds(setup.seed)["mfpt"]
    out = rough_episodes(loop, setup.z_cl, [base + k for k in robots], b.mfpt_strides)
    return {"sigma_deg": sigma, "chunk": chunk, "robots": len(robots), **out}


TASKS = {
    "cycle": task_cycle,
    "basin": task_basin,
    "curve": task_curve,
    "window": task_window,
    "push": task_push,
    "ceiling": task_ceiling,
    "terrain": task_terrain,
    "mfpt": task_mfpt,
}


def run_task(setup: Setup, name: str, args: tuple) -> dict:
    """Worker entry point: one named task."""
    t0 = time.perf_counter()
    try:
        result = TASKS[name](setup, *args)
    except RuntimeError as e:
        result = {"error": str(e)}
    result["seconds"] = time.perf_counter() - t0
    return result


# --------------------------------------------------------------------------------------------
# Orchestration
# --------------------------------------------------------------------------------------------


def task_key(setup_key: str, name: str, args: tuple) -> str:
    """Cache key of one task: the setup's settings hash, the task name and its arguments."""
    return f"{setup_key}/{name}/{json.dumps(list(args))}"


def _run_all(
    executor, setup: Setup, jobs: list, cache: TaskCache, progress: bool, desc: str
) -> dict:
    """Run (name, args) jobs through the executor, using and filling the cache. A task that
    raises is reported (key and arguments) without stopping the others; then `TasksFailed`."""
    results, tasks = {}, {}
    for name, args in jobs:
        key = task_key(setup.key, name, args)
        hit = cache.get(key)
        if hit is not None:
            results[(name, args)] = hit
        else:
            tasks[key] = (run_task, (setup, name, args), (name, args))

    def keep(key, res):
        if "error" not in res:
            cache.put(key, res)

    done, failures = run_tasks(
        executor, tasks, progress and bool(tasks), desc, keep, done_before=len(results)
    )
    for key, res in done.items():
        results[tasks[key][2]] = res
    if failures:
        raise TasksFailed(
            failures,
            len(jobs),
            "; the others are cached: rerun to retry" if cache.path is not None else "",
        )
    return results


# Every module setting that changes a result: part of each cache key (with the budget, the
# seed, the gait file's contents, the controller's fingerprint and the source hash below).
SETTINGS = {
    "rtol": EVAL_RTOL,
    "return_tol": RETURN_TOL,
    "basin_lo": BASIN_LO,
    "basin_hi": BASIN_HI,
    "basin_cap": BASIN_CAP,
    "fd_rel": FD_REL,
    "fd_floor": FD_FLOOR.tolist(),
    "curve_seed": CURVE_SEED,
    "terrain_seed": TERRAIN_SEED,
    "push_seed": PUSH_SEED,
    "mfpt_seed": MFPT_SEED,
    "mfpt_chunk": MFPT_CHUNK,
    "profile_seg": PROFILE_SEG,
    "profile_span": PROFILE_SPAN,
    "ceiling_es": CEILING_ES,
    "ceiling_rng": "default_rng([component, sign > 0, round(s * 1e9) % 2**32])",
    "window_scan": WINDOW_SCAN,
    "env_id": ENV_ID,
    "cycle_record_dt": CYCLE_RECORD_DT,
}


# The agents modules whose code a margins result depends on (besides all of bound_env/):
# the tasks, the controllers (policy, stride) and the statistics.
AGENTS_SOURCES = ("margins.py", "policy.py", "stride.py", "stats.py")


def source_files() -> list[Path]:
    """Every .py file under bound_env/ and the margins modules of agents/ (`AGENTS_SOURCES`)."""
    import bound_env

    pkg = Path(bound_env.__file__).resolve().parent
    here = Path(__file__).resolve().parent
    return sorted(pkg.rglob("*.py")) + [here / name for name in AGENTS_SOURCES]


def source_hash(files=None) -> str:
    """sha256 (16 hex digits) of the names and contents of ``files`` (default:
    `source_files`): any change of the simulator, the task, the controllers or the margins
    code gives a new cache key (no hand-kept version number)."""
    import hashlib

    h = hashlib.sha256()
    for f in files if files is not None else source_files():
        f = Path(f)
        h.update(f"{f.parent.name}/{f.name}\0".encode())
        h.update(f.read_bytes())
        h.update(b"\0")
    return h.hexdigest()[:16]


def gait_key(gait) -> dict:
    """The gait's name and the sha256 of its file's contents (a changed file, a new key)."""
    import hashlib

    from bound_env.params import resolve_gait_path

    digest = hashlib.sha256(resolve_gait_path(gait).read_bytes()).hexdigest()
    return {"name": str(gait), "file_sha256": digest}


def setup_key(controller, gait: str, budget: Budget, seed: int = DEFAULT_SEED) -> str:
    """Cache key of one evaluation: the controller's fingerprint and env kwargs, the gait
    (name and file contents), the budget, the seed, `SETTINGS` and the `source_hash`."""
    env_kwargs = getattr(controller, "env_kwargs", None) or {}
    return settings_hash(
        {
            "controller": controller.fingerprint(),
            "gait": gait_key(gait),
            "budget": asdict(budget),
            "seed": check_seed(seed),
            "samples": sample_seeds(seed),
            "settings": SETTINGS,
            "source": source_hash(),
            "env_kwargs": sorted((str(k), repr(v)) for k, v in env_kwargs.items()),
        }
    )


def as_controller(policy, gait=None):
    """A name or a path -> `agents.policy.load_controller` (which refuses a trained policy on
    another ``gait``); an object with the controller protocol (``__call__`` and
    ``fingerprint``) is used as it is."""
    if isinstance(policy, (str, Path)):
        return load_controller(policy, gait=gait)
    if callable(policy) and callable(getattr(policy, "fingerprint", None)):
        return policy
    raise ValueError(
        f"policy must be 'passive', a policy path or a controller with __call__ "
        f"and fingerprint(), got {type(policy).__name__}"
    )


def controller_name(controller) -> str:
    return str(getattr(controller, "name", None) or type(controller).__name__)


def cycle_scale(gait: str) -> np.ndarray:
    """Peak-to-peak range of each apex component [y_g, th1, th2, xdot_g, th1dot, th2dot]
    over one passive stride from the gait's z* (SI): the ``cycle`` yardstick."""
    from bound_env.hybrid import simulate_stride
    from bound_env.params import load_gait

    g = load_gait(gait)
    res = simulate_stride(
        g.z0, g.params, backend="fast", rtol=EVAL_RTOL, atol=EVAL_RTOL, record_dt=CYCLE_RECORD_DT
    )
    tr = res.trajectory
    full = np.hstack([tr.q, tr.qd])[:, [1, 2, 3, 4, 6, 7]]
    return full.max(axis=0) - full.min(axis=0)


def compute_margins(
    policy="passive",
    budget: str | Budget = "quick",
    gait: str = "default",
    workers: int = 1,
    executor=None,
    out: str | Path | None = None,
    progress: bool = False,
    use_cache: bool = True,
    scheduler: str | None = None,
    seed: int = DEFAULT_SEED,
) -> dict:
    """All margins of ``policy`` (``"passive"``, a path, or a controller) as a JSON-able dict.

    ``policy`` may be any object with the controller protocol (module docstring).
    ``seed`` picks the random directions, the rough-terrain runs, the push trials and the
    MFPT robots (`sample_seeds`): the default is the test set of docs/MARGINS.md, any other
    a held-out (validation) set.
    ``executor``: any `concurrent.futures.Executor`-like object; default: the one
    `bound_env.parallel.open_pool` builds from ``scheduler`` and ``workers`` (a process pool
    of ``workers`` processes, in-process when ``workers == 1``, or Dask). ``out``: directory
    for the CSV/PNG outputs and the task cache.
    """
    from bound_env.params import load_gait

    if isinstance(budget, str):
        if budget not in BUDGETS:
            raise ValueError(f"budget must be one of {sorted(BUDGETS)}, got {budget!r}")
        budget = BUDGETS[budget]
    if workers < 1:
        raise ValueError(f"--workers must be at least 1, got {workers}")
    seed = check_seed(seed)
    controller = as_controller(policy, gait)
    g = load_gait(gait)
    z_star = np.asarray(g.z0, dtype=float)
    scale = {
        "names": list(Z_LABELS),
        "units": list(Z_UNITS),
        "zstar": np.abs(z_star).tolist(),
        "cycle": cycle_scale(gait).tolist(),
    }
    out_dir = Path(out) if out is not None else None
    if out_dir is not None:
        out_dir.mkdir(parents=True, exist_ok=True)
    cache = TaskCache(out_dir / "cache.jsonl" if (out_dir is not None and use_cache) else None)
    setup = Setup(
        controller=controller,
        gait=gait,
        budget=budget,
        z_star=z_star,
        key=setup_key(controller, gait, budget, seed),
        seed=seed,
    )
    t0 = time.perf_counter()
    with contextlib.ExitStack() as stack:
        if executor is None:
            executor = stack.enter_context(open_pool(scheduler, workers)).executor
        cyc = _run_all(executor, setup, [("cycle", ())], cache, False, "cycle")[("cycle", ())]
        if "error" in cyc:
            raise RuntimeError(f"no closed-loop cycle: {cyc['error']}")
        setup = replace(
            setup,
            z_cl=np.array(cyc["z_cl"]),
            cycle_steps=int(cyc["cycle_steps"]),
            period=float(cyc["period"]),
        )
        jobs = [("basin", (i, s)) for i in range(6) for s in (1, -1)]
        jobs += [("ceiling", (i, s)) for i in range(6) for s in (1, -1)]
        jobs += [("curve", (r,)) for r in budget.curve_sizes]
        jobs += [("terrain", (v,)) for v in budget.terrain_sigmas]
        chunks = range(math.ceil(budget.mfpt_robots / MFPT_CHUNK))
        jobs += [("mfpt", (v, c)) for v in budget.mfpt_sigmas for c in chunks]
        jobs += [("window", (k, s)) for k in ("alpha_deg", "kc") for s in (-1, 1)]
        jobs += [("push", ("xdot", v, j)) for j, v in enumerate(budget.push_xdot)]
        jobs += [("push", ("th1dot", v, j)) for j, v in enumerate(budget.push_th1dot)]
        res = _run_all(
            executor, setup, jobs, cache, progress, f"margins {controller_name(controller)}"
        )
    result = assemble(controller, gait, budget, z_star, cyc, res, scale, seed)
    result["seconds"] = time.perf_counter() - t0
    if out_dir is not None:
        write_outputs(result, out_dir)
    return result


def _direction_entry(r: dict, i: int, scale: dict) -> dict:
    e = {k: r.get(k) for k in ("rel", "abs", "capped", "cap", "cap_reason", "beyond")}
    e["rel_cycle"] = r["abs"] / scale["cycle"][i] if scale["cycle"][i] > 0 else math.nan
    for k in ("mechanism", "geometric", "hip_below_touchdown_from"):
        if k in r:
            e[k] = r[k]
    return e


def _rate_curve(xs, items) -> dict:
    k = [int(c["k"]) for c in items]
    n = [int(c["n"]) for c in items]
    rates = [c["success"] for c in items]
    ci = [wilson_interval(a, b) for a, b in zip(k, n, strict=True)]
    lo, hi = [c[0] for c in ci], [c[1] for c in ci]
    x50 = crossing_on_grid(xs, rates)
    return {
        "success": rates,
        "k": k,
        "n": n,
        "ci_low": lo,
        "ci_high": hi,
        "x50": x50,
        "x50_ci": [min(x50, crossing_on_grid(xs, lo)), max(x50, crossing_on_grid(xs, hi))],
        "x50_grid": threshold_on_grid(xs, rates),
        "x50_at_grid_end": bool(rates and rates[-1] >= 0.5),
    }


def mfpt_curve(budget: Budget, res: dict) -> list[dict]:
    """The MFPT per sigma from the chunks' results (`agents.stats.mfpt_estimate`)."""
    out = []
    chunks = range(math.ceil(budget.mfpt_robots / MFPT_CHUNK))
    for v in budget.mfpt_sigmas:
        parts = [res[("mfpt", (v, c))] for c in chunks]
        completed = sum(sum(p["strides"]) for p in parts)
        fell = sum(sum(p["fell"]) for p in parts)
        reasons: dict = {}
        for p in parts:
            for name, n in p["failures"].items():
                reasons[name] = reasons.get(name, 0) + n
        total = completed + fell  # strides attempted: the failing ones count
        est = mfpt_estimate(total, fell)
        out.append(
            {
                "sigma_deg": v,
                "robots": budget.mfpt_robots,
                "horizon": budget.mfpt_strides,
                "strides_total": int(total),
                "failures": int(fell),
                "mfpt": est["mfpt"],
                "lower_bound": est["lower_bound"],
                "ci": est["ci"],
                "failure_reasons": reasons,
            }
        )
    return out


def assemble(controller, gait, budget, z_star, cyc, res, scale=None, seed=DEFAULT_SEED) -> dict:
    scale = scale or {
        "names": list(Z_LABELS),
        "units": list(Z_UNITS),
        "zstar": np.abs(z_star).tolist(),
        "cycle": [math.nan] * 6,
    }
    basin, ceiling = {}, {}
    worst = (math.inf, None, math.nan)
    worst_cycle = (math.inf, None)
    worst_share = (math.inf, None)
    for i, label in enumerate(Z_LABELS):
        entry = {"unit": Z_UNITS[i], "z_star": float(z_star[i])}
        centry = dict(entry)
        for sign, sym in ((1, "+"), (-1, "-")):
            r = res[("basin", (i, sign))]
            entry[sym] = _direction_entry(r, i, scale)
            c = res.get(("ceiling", (i, sign)))
            if c is not None:
                centry[sym] = _direction_entry(c, i, scale)
                share = r["abs"] / c["abs"] if c["abs"] > 0 else math.nan
                entry[sym]["share"] = share
                if share < worst_share[0]:
                    worst_share = (share, f"{label}{sym}")
            if r.get("rel") is not None and r["rel"] < worst[0]:
                worst = (r["rel"], f"{label}{sym}", r["abs"])
            if entry[sym]["rel_cycle"] < worst_cycle[0]:
                worst_cycle = (entry[sym]["rel_cycle"], f"{label}{sym}")
        basin[label] = entry
        ceiling[label] = centry
    curve = [res[("curve", (r,))] for r in budget.curve_sizes]
    for c in curve:  # results cached before the success counts were kept
        c.setdefault("k", int(round(c["success"] * c["n"])))
    ccurve = _rate_curve(list(budget.curve_sizes), curve)
    terr = [res[("terrain", (v,))] for v in budget.terrain_sigmas]
    tcurve = _rate_curve(list(budget.terrain_sigmas), terr)
    samples = sample_seeds(seed)
    mfpt = (
        mfpt_curve(budget, res) if all(("mfpt", (v, 0)) in res for v in budget.mfpt_sigmas) else []
    )
    push = {}
    for kind, sizes in (("xdot", budget.push_xdot), ("th1dot", budget.push_th1dot)):
        rates = [res[("push", (kind, v, j))]["success"] for j, v in enumerate(sizes)]
        push[kind] = {
            "unit": "m/s" if kind == "xdot" else "rad/s",
            "sizes": list(sizes),
            "success": rates,
            "p50": threshold_on_grid(sizes, rates),
        }
    win = {(k, s): res[("window", (k, s))] for k in ("alpha_deg", "kc") for s in (-1, 1)}
    z_cl = np.array(cyc["z_cl"])
    curve_sizes = [c["size"] for c in curve]
    return {
        "policy": controller_name(controller),
        "gait": gait,
        "budget": budget.name,
        "seed": seed,
        "seed_role": "test" if seed == DEFAULT_SEED else "validation (held out)",
        "basin_scale": scale,
        "basin": basin,
        "basin_min": worst[0],
        "basin_min_direction": worst[1],
        "basin_min_abs": worst[2],
        "basin_min_cycle": worst_cycle[0],
        "basin_min_cycle_direction": worst_cycle[1],
        "basin_ceiling": ceiling,
        "basin_share_min": worst_share[0] if worst_share[1] else None,
        "basin_share_min_direction": worst_share[1],
        "basin_curve": {
            "sizes": curve_sizes,
            "success": ccurve["success"],
            "k": ccurve["k"],
            "n": ccurve["n"],
            "ci_low": ccurve["ci_low"],
            "ci_high": ccurve["ci_high"],
            "interval": "95% Wilson",
            "r50": ccurve["x50"],
            "r50_ci": ccurve["x50_ci"],
            "r50_grid": ccurve["x50_grid"],
            "r50_at_grid_end": ccurve["x50_at_grid_end"],
            "directions": budget.curve_dirs,
            "direction_seed": samples["directions"],
            "scale": "zstar",
            # per size, the outcome from each direction (1: returned), directions in the
            # order of random_directions(directions, direction_seed): for paired comparisons
            "outcomes": [c["outcomes"] for c in curve]
            if all("outcomes" in c for c in curve)
            else None,
        },
        "terrain": {
            "sigmas_deg": list(budget.terrain_sigmas),
            "survival": tcurve["success"],
            "k": tcurve["k"],
            "n": tcurve["n"],
            "ci_low": tcurve["ci_low"],
            "ci_high": tcurve["ci_high"],
            "interval": "95% Wilson",
            "runs": budget.terrain_runs,
            "strides": budget.terrain_strides,
            "seeds": [samples["terrain"], samples["terrain"] + budget.terrain_runs - 1],
            "mean_strides": [t["mean_strides"] for t in terr],
            "failures": [t["failures"] for t in terr],
        },
        "terrain_sigma50_deg": tcurve["x50"],
        "terrain_sigma50_grid_deg": tcurve["x50_grid"],
        "terrain_sigma50_ci_deg": tcurve["x50_ci"],
        "terrain_sigma50_at_grid_end": tcurve["x50_at_grid_end"],
        "mfpt": mfpt,
        "mfpt_sigma_100_deg": mfpt_crossing(
            [m["sigma_deg"] for m in mfpt],
            [m["mfpt"] for m in mfpt],
            [m["lower_bound"] for m in mfpt],
            MFPT_LEVEL,
        )
        if mfpt
        else None,
        "mfpt_settings": {
            "robots": budget.mfpt_robots,
            "horizon": budget.mfpt_strides,
            "sigmas_deg": list(budget.mfpt_sigmas),
            "seeds": [samples["mfpt"], samples["mfpt"] + budget.mfpt_robots - 1],
            "level": MFPT_LEVEL,
            "estimator": "strides_total / failures (constant-hazard MLE; censored at the "
            "horizon); no failure: lower bound strides_total; ci: exact Poisson",
        },
        "emax": cyc["emax"],
        "eigenvalues": cyc["eigenvalues"],
        "z_star": z_star.tolist(),
        "z_cl": z_cl.tolist(),
        "fixed_point_shift": (z_cl - z_star).tolist(),
        "fixed_point_residual": cyc["residual"],
        "slope_window_deg": [win[("alpha_deg", -1)]["edge"], win[("alpha_deg", 1)]["edge"]],
        "slope_window_capped": [win[("alpha_deg", -1)]["capped"], win[("alpha_deg", 1)]["capped"]],
        "slope_nominal_deg": win[("alpha_deg", 1)]["nominal"],
        "kc_window": [win[("kc", -1)]["edge"], win[("kc", 1)]["edge"]],
        "kc_window_capped": [win[("kc", -1)]["capped"], win[("kc", 1)]["capped"]],
        "kc_nominal": win[("kc", 1)]["nominal"],
        "push": push,
        "effort": cyc["effort"],
        "effort_frac": cyc["effort"] / cyc["max_torque"],
        "decision_seconds": decision_summary(curve),
        "max_torque": cyc["max_torque"],
        "period": cyc["period"],
        "settings": {
            "return_tol": RETURN_TOL,
            "rtol": EVAL_RTOL,
            "basin_strides": budget.basin_strides,
            "basin_iters": budget.basin_iters,
            "basin_first_bracket": [BASIN_LO, BASIN_HI],
            "basin_cap": BASIN_CAP,
            "window_strides": budget.window_strides,
            "push_samples": budget.push_samples,
            "ceiling": {
                "strides": budget.ceiling_strides,
                "iters": budget.ceiling_iters,
                "random_profiles": budget.ceiling_random,
                "optimizer_iters": budget.ceiling_opt,
                "piece_intervals": PROFILE_SEG,
            },
            "terrain_runs": budget.terrain_runs,
            "terrain_strides": budget.terrain_strides,
            "seed": seed,
            "samples": samples,
            "mfpt_robots": budget.mfpt_robots,
            "mfpt_strides": budget.mfpt_strides,
        },
    }


# --------------------------------------------------------------------------------------------
# Outputs
# --------------------------------------------------------------------------------------------


def write_outputs(result: dict, out_dir: Path) -> None:
    """margins.json, basin.csv, curve.csv, push.csv, mfpt.csv and PNG plots."""
    atomic_write(out_dir / "margins.json", json.dumps(result, indent=2) + "\n")
    for name, key in (("basin.csv", "basin"), ("ceiling.csv", "basin_ceiling")):
        with (out_dir / name).open("w", newline="") as f:
            w = csv.writer(f)
            w.writerow(
                [
                    "component",
                    "unit",
                    "sign",
                    "rel",
                    "abs",
                    "capped",
                    "rel_cycle",
                    "share",
                    "cap",
                    "beyond_rel",
                    "beyond_reason",
                    "beyond_stride",
                    "beyond_phase",
                    "mechanisms",
                ]
            )
            for label, e in result[key].items():
                for sym in ("+", "-"):
                    v = e.get(sym)
                    if v is None:
                        continue
                    bey = v.get("beyond") or {}
                    w.writerow(
                        [
                            label,
                            e["unit"],
                            sym,
                            v["rel"],
                            v["abs"],
                            v["capped"],
                            v.get("rel_cycle"),
                            v.get("share"),
                            v.get("cap"),
                            bey.get("rel"),
                            bey.get("reason"),
                            bey.get("stride"),
                            bey.get("phase"),
                            "; ".join(bey.get("mechanisms") or []),
                        ]
                    )
    c = result["basin_curve"]
    with (out_dir / "curve.csv").open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["size_rel", "success", "k", "n", "ci_low", "ci_high"])
        for row in zip(
            c["sizes"], c["success"], c["k"], c["n"], c["ci_low"], c["ci_high"], strict=True
        ):
            w.writerow(row)
    t = result["terrain"]
    with (out_dir / "terrain.csv").open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["sigma_deg", "survival", "k", "n", "ci_low", "ci_high", "mean_strides"])
        for row in zip(
            t["sigmas_deg"],
            t["survival"],
            t["k"],
            t["n"],
            t["ci_low"],
            t["ci_high"],
            t["mean_strides"],
            strict=True,
        ):
            w.writerow(row)
    if result.get("mfpt"):
        with (out_dir / "mfpt.csv").open("w", newline="") as f:
            w = csv.writer(f)
            w.writerow(
                [
                    "sigma_deg",
                    "strides_total",
                    "failures",
                    "mfpt",
                    "lower_bound",
                    "ci_low",
                    "ci_high",
                ]
            )
            for m in result["mfpt"]:
                w.writerow(
                    [
                        m["sigma_deg"],
                        m["strides_total"],
                        m["failures"],
                        m["mfpt"],
                        m["lower_bound"],
                        *m["ci"],
                    ]
                )
    with (out_dir / "push.csv").open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["kind", "unit", "size", "success"])
        for kind, e in result["push"].items():
            for s, p in zip(e["sizes"], e["success"], strict=True):
                w.writerow([kind, e["unit"], s, p])
    plot_margins([result], out_dir)


def plot_margins(results: list[dict], out_dir: Path, prefix: str = "") -> list[Path]:
    """basin, curve and push plots of one or more results (one colour each)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out_dir = Path(out_dir)
    paths = []
    labels = [r.get("label") or r["policy"] for r in results]

    fig, ax = plt.subplots(figsize=(7.0, 3.6), dpi=100)
    names = [f"{lab}{s}" for lab in Z_LABELS for s in ("+", "-")]
    x = np.arange(len(names))
    wbar = 0.8 / len(results)
    for k, (r, lab) in enumerate(zip(results, labels, strict=True)):
        vals = [r["basin"][c][s]["rel"] for c in Z_LABELS for s in ("+", "-")]
        ax.bar(x + (k - (len(results) - 1) / 2) * wbar, vals, wbar, label=lab)
    if any(r["basin"][c][s]["rel"] > 0 for r in results for c in Z_LABELS for s in "+-"):
        ax.set_yscale("log")  # an empty basin (all zero) has nothing to put on a log axis
    ax.set_xticks(x, names, rotation=45, ha="right")
    ax.set_ylabel("largest relative perturbation")
    ax.set_title("Basin along each apex component (units of |z*_i|; uncapped)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    paths.append(out_dir / f"{prefix}basin.png")
    fig.savefig(paths[-1])
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(5.0, 3.4), dpi=100)
    for r, lab in zip(results, labels, strict=True):
        c = r["basin_curve"]
        line = ax.plot(c["sizes"], c["success"], "o-", label=lab, ms=3)[0]
        if "ci_low" in c:
            ax.fill_between(
                c["sizes"], c["ci_low"], c["ci_high"], color=line.get_color(), alpha=0.15
            )
    ax.set_xscale("log")
    ax.set_xlabel("relative perturbation size r (random direction)")
    ax.set_ylabel("P(return)")
    ax.set_ylim(-0.05, 1.05)
    ax.legend(fontsize=8)
    fig.tight_layout()
    paths.append(out_dir / f"{prefix}curve.png")
    fig.savefig(paths[-1])
    plt.close(fig)

    fig, axes = plt.subplots(1, 2, figsize=(8.0, 3.4), dpi=100)
    for ax, kind, unit in ((axes[0], "xdot", "m/s"), (axes[1], "th1dot", "rad/s")):
        for r, lab in zip(results, labels, strict=True):
            ax.plot(r["push"][kind]["sizes"], r["push"][kind]["success"], "o-", label=lab)
        ax.set_xlabel(f"kick in {kind} [{unit}]")
        ax.set_ylabel("success rate")
        ax.set_ylim(-0.05, 1.05)
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    paths.append(out_dir / f"{prefix}push.png")
    fig.savefig(paths[-1])
    plt.close(fig)

    if all("terrain" in r for r in results):
        fig, ax = plt.subplots(figsize=(5.0, 3.4), dpi=100)
        for r, lab in zip(results, labels, strict=True):
            t = r["terrain"]
            line = ax.plot(t["sigmas_deg"], t["survival"], "o-", label=lab, ms=3)[0]
            ax.fill_between(
                t["sigmas_deg"], t["ci_low"], t["ci_high"], color=line.get_color(), alpha=0.15
            )
        ax.set_xscale("log")
        ax.set_xlabel("slope noise sigma per apex [deg]")
        ax.set_ylabel(f"P(survive {results[0]['terrain']['strides']} strides)")
        ax.set_ylim(-0.05, 1.05)
        ax.legend(fontsize=8)
        fig.tight_layout()
        paths.append(out_dir / f"{prefix}terrain.png")
        fig.savefig(paths[-1])
        plt.close(fig)

    if any(r.get("mfpt") for r in results):
        from matplotlib.ticker import NullFormatter

        fig, ax = plt.subplots(figsize=(5.0, 3.4), dpi=100)
        for r, lab in zip(results, labels, strict=True):
            m = r.get("mfpt") or []
            if not m:
                continue
            sig = np.array([e["sigma_deg"] for e in m])
            val = np.array([e["mfpt"] for e in m], dtype=float)
            lb = np.array([e["lower_bound"] for e in m], dtype=bool)
            line = ax.plot(sig, val, "-", label=lab)[0]
            ax.plot(sig[~lb], val[~lb], "o", ms=3, color=line.get_color())
            ax.plot(sig[lb], val[lb], "^", ms=5, mfc="none", color=line.get_color())
            lo = np.array([e["ci"][0] for e in m], dtype=float)
            hi = np.array([e["ci"][1] if e["ci"][1] is not None else np.nan for e in m])
            ok = ~lb & np.isfinite(lo) & np.isfinite(hi)
            if ok.any():
                ax.vlines(sig[ok], lo[ok], hi[ok], color=line.get_color(), alpha=0.5)
        ax.axhline(MFPT_LEVEL, color="0.6", lw=0.8, ls=":")
        ax.set_xscale("log")
        ax.set_yscale("log")
        grid = sorted({e["sigma_deg"] for r in results for e in (r.get("mfpt") or [])})
        ax.set_xticks(grid, [f"{v:g}" for v in grid])
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.set_xlabel("slope noise sigma per apex [deg]")
        ax.set_ylabel("MFPT [strides] (^: lower bound)")
        ax.legend(fontsize=8)
        fig.tight_layout()
        paths.append(out_dir / f"{prefix}mfpt.png")
        fig.savefig(paths[-1])
        plt.close(fig)
    return paths


def summary_text(r: dict) -> str:
    """A few human-readable lines."""
    lines = [
        f"policy {r['policy']}  gait {r['gait']}  budget {r['budget']}  seed {r.get('seed')}"
        f"  ({r['seconds']:.1f} s)",
        f"basin_min {r['basin_min']:.4g} ({r['basin_min_direction']}, "
        f"abs {r['basin_min_abs']:.4g})   cycle scale {r['basin_min_cycle']:.4g} "
        f"({r['basin_min_cycle_direction']})   share of ceiling "
        f"{_num(r['basin_share_min'])} ({r['basin_share_min_direction']})",
        f"r50 {r['basin_curve']['r50']:.3g} [{r['basin_curve']['r50_ci'][0]:.3g}, "
        f"{r['basin_curve']['r50_ci'][1]:.3g}]   terrain sigma50 "
        f"{r['terrain_sigma50_deg']:.3g} deg [{r['terrain_sigma50_ci_deg'][0]:.3g}, "
        f"{r['terrain_sigma50_ci_deg'][1]:.3g}]   MFPT = 100 strides at sigma "
        f"{_num(r.get('mfpt_sigma_100_deg'), 3)} deg",
        f"emax {r['emax']:.4f}   fixed-point shift max |dz| "
        f"{np.max(np.abs(r['fixed_point_shift'])):.3g}",
        f"slope window {r['slope_window_deg'][0]:.4f} .. {r['slope_window_deg'][1]:.4f} deg   "
        f"kc window {r['kc_window'][0]:.2f} .. {r['kc_window'][1]:.2f} N m/rad",
        f"push p50: xdot {r['push']['xdot']['p50']:g} m/s, th1dot {r['push']['th1dot']['p50']:g}"
        f" rad/s   effort {r['effort']:.3g} N m ({100 * r['effort_frac']:.2f} % of max torque)",
    ]
    d = r.get("decision_seconds")
    if d:
        lines.append(
            f"decision time p50 {1e3 * d['p50']:.3g} ms, p99 {1e3 * d['p99']:.3g} ms, mean "
            f"{1e3 * d['mean']:.3g} ms, max {1e3 * d['max']:.3g} ms ({d['n']} decisions)"
        )
    return "\n".join(lines)


def _num(v, digits: int = 4) -> str:
    return "-" if v is None or (isinstance(v, float) and math.isnan(v)) else f"{v:.{digits}g}"
