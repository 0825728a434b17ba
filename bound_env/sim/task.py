"""The PassiveBound task: start state, observation, reward and termination around the passive gait.

This is the task layer between the hybrid simulator (`bound_env.model.fast.advance`, which knows
nothing of Gymnasium) and the Gymnasium adapters (`bound_env.envs.env` for one robot,
`bound_env.envs.vector` for many). It decides

- the **start** state: an apex state z on S_apex (eq. 17), the gait's z* plus seeded noise, or
  one given by the caller;
- the **action**: a normalized spine torque a in [-1, 1], tau = max_torque * a [N m], held
  constant over one control interval dt and integrated event-accurately;
- the **observation** (`OBS_NAMES`), the **reward** terms and the **termination** (every
  simulator failure, plus no apex within `NO_APEX_TIME`).

One control interval of a batch of robots is a single compiled call (`step_batch`, or
`step_batch_parallel` with one thread per robot), so that one robot and many robots share the
same code and give bit-identical results. The per-robot state lives in a `Batch` of arrays.
The compiled kernels and the flat layouts they read are `bound_env.sim.task_kernels` (re-exported
here); this module is the Python side: the settings (`TaskConfig`), batches, start states and
infos.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from pathlib import Path

import numpy as np

from ..files.schema import dt_value
from ..model.dynamics import make_aux
from ..model.events import (
    FAIL_FIRST,
    FAILURES,
    N_FLAGS,
    PHASES,
    failure_name,
)
from ..model.params import Z_IN_Y, Z_NAMES, Gait, load_gait
from ..model.stride import DEFAULT_T_MAX

# The compiled side (`bound_env.sim.task_kernels`): the kernels, the observation's layout and the
# flat layouts of the per-robot state and the task's constants, importable from here as before.
from .task_kernels import (  # noqa: F401
    CONFIG_LAYOUT,
    N_OBS_FULL,
    N_XI,
    OBS_NAMES,
    OBS_UNITS,
    STATE_LAYOUT,
    C,
    S,
    advance_interval,
    advance_rough,
    observe,
    reset_at_apex,
    reward_terms,
    start_at_state,
    step_batch,
    step_batch_parallel,
    step_env,
    strict_jit,
    tracking_cost,
)

globals().update(STATE_LAYOUT.constants())  # S_T, ..., S_XI, N_S (imported by env, vector)
globals().update(CONFIG_LAYOUT.constants())  # C_DT, ..., N_CFG

# ---------------------------------------------------------------------------------------------
# Defaults (constructor arguments of the environments).
# ---------------------------------------------------------------------------------------------
DEFAULT_DT = 0.01  # control interval [s]; the passive stride lasts 0.3906 s (~39 intervals)
# Largest spine torque [N m]. On the default gait's passive cycle theta2 spans -3.30 .. +8.29 deg,
# so the spine spring's torque k_c |theta2| peaks at 295 * 0.1448 = 42.7 N m (29.9 N m for the
# half peak-to-peak swing); 40 N m held for one stride moves the next apex state by 0.4 to 1.8
# `APEX_SCALES` per component.
DEFAULT_MAX_TORQUE = 40.0
DEFAULT_RESET_NOISE_SCALE = 0.5  # passive survival over 60 strides: 83 % of such starts
DEFAULT_ALIVE_REWARD = 1.0  # per control interval in which nothing failed
DEFAULT_TRACKING_COST_WEIGHT = 1.0  # per completed stride, times the normalized apex error
DEFAULT_CTRL_COST_WEIGHT = 0.1  # per control interval, times a^2 = (tau / max_torque)^2
DEFAULT_RTOL = 1e-10  # integrator tolerance (relative and absolute), that of the stride env and
# of every evaluation: zero action stays within 1e-9 of z* (at 1e-8: 1.07e-9 after 31 strides)
NO_APEX_TIME = DEFAULT_T_MAX  # no apex within this time [s] ends the episode ("no_apex"): 2 s

# Unit of apex deviation per component of z = [y_g, th1, th2, xdot_g, th1dot, th2dot] (SI):
# round numbers near the half-width of the passive basin of the default gait along each axis
# (measured: 0.015-0.022 m, 0.09-0.10 rad, 0.19-0.22 rad, 0.057-0.092 m/s, 0.78-2.7 rad/s,
# 1.2-1.4 rad/s). Used both for the start noise and for the tracking cost.
APEX_SCALES = np.array([0.02, 0.1, 0.2, 0.1, 1.0, 1.0])

# Observation bounds (the observation is clipped to them; only a robot that has already failed,
# or one flung far beyond anything a 20 kg robot on a slope reaches, could meet one).
_X_BOUND = 1e5  # |x_g| [m]: ~10 h of bounding at 2.8 m/s
_Y_BOUNDS = (-1.0, 10.0)  # y_g [m]; y_g > 0 whenever both hips and the spine joint are up
_ANGLE_BOUND = 2.0 * math.pi  # |theta1|, |theta2| [rad]; a flip puts a hip into the ground first
_SPEED_BOUND = 100.0  # |xdot_g|, |ydot_g| [m/s]
_RATE_BOUND = 1000.0  # |theta1dot|, |theta2dot| [rad/s]
# Leg lengths lie in [0, 2 l_bar] (a stance leg lifts off at l_bar), leg angles in [-pi, pi]
# (atan2), the 0/1 entries in [0, 1], the time since the apex in [0, NO_APEX_TIME + dt].


_Z_IDX = np.array(Z_IN_Y)  # z = y[_Z_IDX] at an apex (eq. 17)
_PHASE_OBJECTS = np.array(PHASES, dtype=object)
# failure reason (None for success) by status code
FAILURE_NAMES = tuple(failure_name(c) for c in range(FAIL_FIRST + len(FAILURES)))


# ---------------------------------------------------------------------------------------------
# Python side: configuration, batches of robots, start states, info dictionaries.
# ---------------------------------------------------------------------------------------------


# the keys ``reset(options=...)`` of PassiveBound-v0 and PassiveBoundStride-v1 reads
RESET_OPTIONS = ("apex_state",)


def check_reset_options(options) -> dict:
    """``options`` of ``reset``: None or a dict whose keys are `RESET_OPTIONS`; ValueError
    otherwise (a typo such as ``apex_sate`` would silently give a random start)."""
    if options is None:
        return {}
    if not isinstance(options, dict):
        raise ValueError(
            f"options must be a dict (keys: {', '.join(RESET_OPTIONS)}) or None, "
            f"got {type(options).__name__}"
        )
    for key in options:
        if key not in RESET_OPTIONS:
            raise ValueError(f"unknown reset option {key!r} (known: {', '.join(RESET_OPTIONS)})")
    return options


def check_number(name, value, minimum, strict=False) -> float:
    """``value`` as a finite float above (``strict``) or at least ``minimum``, else ValueError."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(v) or v < minimum or (strict and v == minimum):
        rel = "greater than" if strict else "at least"
        raise ValueError(f"{name} must be finite and {rel} {minimum:g}, got {value!r}")
    return v


@dataclass(frozen=True)
class TaskConfig:
    """The task's settings: one field per keyword argument of PassiveBound-v0 (the table in
    `bound_env.envs.env.PassiveBoundEnv`'s docstring has their meaning and units). Checked when
    built: a bad value is a ValueError naming the setting. Both environments build one from
    their keyword arguments; `PassiveBoundTask` takes it."""

    gait: str | Path = "default"
    gait_overrides: dict | None = None
    dt: float = DEFAULT_DT
    max_torque: float = DEFAULT_MAX_TORQUE
    reset_noise_scale: float = DEFAULT_RESET_NOISE_SCALE
    alive_reward: float = DEFAULT_ALIVE_REWARD
    tracking_cost_weight: float = DEFAULT_TRACKING_COST_WEIGHT
    ctrl_cost_weight: float = DEFAULT_CTRL_COST_WEIGHT
    apex_scales: tuple | None = None  # None: APEX_SCALES
    exclude_current_positions_from_observation: bool = True
    rtol: float = DEFAULT_RTOL
    slope_noise_deg: float = 0.0

    def __post_init__(self):
        put = object.__setattr__  # normalize the values of a frozen instance
        for name in ("dt", "max_torque", "rtol"):
            put(self, name, check_number(name, getattr(self, name), 0.0, strict=True))
        # the range a file may set (bounded work per stride: dt = 1e-9 would build a matrix of
        # 25 GB); the stride env's plant is one of these too
        put(self, "dt", dt_value(self.dt, "dt"))
        for name in (
            "slope_noise_deg",
            "reset_noise_scale",
            "alive_reward",
            "tracking_cost_weight",
            "ctrl_cost_weight",
        ):
            put(self, name, check_number(name, getattr(self, name), 0.0))
        if self.apex_scales is not None:
            scales = np.asarray(self.apex_scales, dtype=float)
            if scales.shape != (6,) or not np.all(np.isfinite(scales)) or np.any(scales <= 0):
                raise ValueError(
                    f"apex_scales must be 6 positive numbers, got {self.apex_scales!r}"
                )
            put(self, "apex_scales", tuple(float(v) for v in scales))
        if self.gait_overrides is not None:
            put(self, "gait_overrides", dict(self.gait_overrides))

    @classmethod
    def resolve(
        cls,
        config: TaskConfig | None = None,
        settings: dict | None = None,
        defaults_keep_config: bool = False,
    ) -> TaskConfig:
        """``config`` with ``settings`` (keyword arguments) changed, or a new config from the
        settings alone when ``config`` is None. With ``defaults_keep_config`` (a signature
        that lists every setting with its default) a setting at its default value leaves the
        config's value. Unknown names are a ValueError."""
        settings = dict(settings or {})
        unknown = sorted(set(settings) - set(TASK_SETTINGS))
        if unknown:
            raise ValueError(f"unknown task setting(s) {unknown}; known: {TASK_SETTINGS}")
        if config is None:
            return cls(**settings)
        if not isinstance(config, TaskConfig):
            raise ValueError(f"config must be a TaskConfig, got {type(config).__name__}")
        if defaults_keep_config:
            settings = {k: v for k, v in settings.items() if not _is_default(k, v)}
        return replace(config, **settings) if settings else config


def _is_default(name: str, value) -> bool:
    """Is ``value`` the default of the setting ``name`` (None, or an equal number/string)?"""
    default = TaskConfig.__dataclass_fields__[name].default
    if value is None or default is None:
        return value is default
    try:
        return bool(value == default)
    except (TypeError, ValueError):  # e.g. an array compared with a number
        return False


TASK_SETTINGS = tuple(f.name for f in fields(TaskConfig))  # names of the task's settings


@dataclass
class Batch:
    """State of ``n`` robots (row i is robot i); the kernels update it in place."""

    y: np.ndarray  # (n, 8) float64: [x_g, y_g, th1, th2, xdot_g, ydot_g, th1dot, th2dot]
    aux: np.ndarray  # (n, N_AUX) float64: parameters, tau, contacts, toes
    flags: np.ndarray  # (n, N_FLAGS) bool: legs touched down since the last apex
    s: np.ndarray  # (n, S.SIZE) float64: the `S_*` columns
    apex: np.ndarray  # (n, cap, 8) float64: apex states passed in the last interval
    obs: np.ndarray  # (n, obs_dim) float32
    actions: np.ndarray  # (n,) float64: normalized torques of the next interval
    active: np.ndarray  # (n,) bool: which robots the next kernel call steps

    @property
    def n(self) -> int:
        return self.y.shape[0]


class PassiveBoundTask:
    """Spine control around the passive bounding gait: configuration and task logic.

    Takes a `TaskConfig`, or its fields as keyword arguments (those of
    `bound_env.envs.env.PassiveBoundEnv`, see its docstring), or both (the keywords change the
    config). The reference apex state ``z_ref`` is the gait's z* (its ``z_star``, else
    ``z_published``) and is not changed by ``gait_overrides``.
    """

    def __init__(self, config: TaskConfig | None = None, **settings):
        config = TaskConfig.resolve(config, settings)
        self.config = config
        self.slope_noise_deg = config.slope_noise_deg
        self.gait: Gait = load_gait(config.gait, config.gait_overrides)
        self.params = self.gait.params
        self.z_ref = self.gait.z0  # SI
        self.dt = config.dt
        self.max_torque = config.max_torque
        self.reset_noise_scale = config.reset_noise_scale
        scales = APEX_SCALES if config.apex_scales is None else config.apex_scales
        self.apex_scales = np.array(scales, dtype=float)
        self.include_x = not config.exclude_current_positions_from_observation
        rtol = config.rtol
        alive_reward, tracking_cost_weight, ctrl_cost_weight = (
            config.alive_reward,
            config.tracking_cost_weight,
            config.ctrl_cost_weight,
        )
        self.obs_names = OBS_NAMES if self.include_x else OBS_NAMES[1:]
        self.obs_units = OBS_UNITS if self.include_x else OBS_UNITS[1:]
        self.apex_capacity = 4 + int(self.dt / 0.05)  # strides last ~0.4 s
        cfg = np.zeros(C.SIZE)
        cfg[[C.DT, C.MAX_TORQUE, C.RTOL, C.ATOL, C.NO_APEX]] = (
            self.dt,
            self.max_torque,
            rtol,
            rtol,
            NO_APEX_TIME,
        )
        cfg[[C.ALIVE, C.TRACKING, C.CTRL]] = alive_reward, tracking_cost_weight, ctrl_cost_weight
        cfg[C.INCLUDE_X] = float(self.include_x)
        cfg[C.ZREF : C.ZREF + 6] = self.z_ref
        cfg[C.ZSCALE : C.ZSCALE + 6] = self.apex_scales
        p = self.params
        leg, pi = 2.0 * max(p.lb_bar, p.lf_bar), math.pi
        a, w, v = _ANGLE_BOUND, _RATE_BOUND, _SPEED_BOUND
        bounds = [  # in the order of OBS_NAMES
            (-_X_BOUND, _X_BOUND),
            _Y_BOUNDS,  # x_g, y_g
            (-a, a),
            (-a, a),
            (-v, v),
            (-v, v),
            (-w, w),
            (-w, w),  # angles, speeds, rates
            (0, 1),
            (0, 1),
            (0, leg),
            (-pi, pi),
            (0, leg),
            (-pi, pi),  # contacts, legs
            (0, 1),
            (0, 1),
            (0, NO_APEX_TIME + self.dt),  # touched flags, time since apex
        ]
        self._obs_low = np.array([b[0] for b in bounds], dtype=np.float32)
        self._obs_high = np.array([b[1] for b in bounds], dtype=np.float32)
        cfg[C.OBS_LOW : C.OBS_LOW + N_OBS_FULL] = self._obs_low
        cfg[C.OBS_HIGH : C.OBS_HIGH + N_OBS_FULL] = self._obs_high
        cfg[C.SLOPE_NOISE] = math.radians(self.slope_noise_deg)
        cfg[C.ALPHA_NOMINAL] = self.params.alpha
        self.cfg = cfg
        self._aux0 = make_aux(self.params.to_array())

    def set_params(self, params) -> None:
        """Run the robots started from now on (`reset_robot`, and every stride of a
        `bound_env.sim.stride_map.StrideMap` on this task) on ``params`` (a
        `bound_env.model.params.Params`): another plant under the same task (model error,
        `bound_env.model.mismatch`). The task is the one holder of its plant: nothing keeps a copy
        of it. z_ref, the observation bounds and the other settings stay the gait's; rough
        terrain's mean slope becomes ``params.alpha``."""
        self.params = params
        self.cfg[C.ALPHA_NOMINAL] = params.alpha
        self._aux0 = make_aux(params.to_array())

    @property
    def aux0(self) -> np.ndarray:
        """The parameter vector a robot starts with (`bound_env.model.dynamics.make_aux` of
        ``params``): read it at each start, never keep it (`set_params` replaces it)."""
        return self._aux0

    # -- spaces --------------------------------------------------------------------------------
    @property
    def obs_dim(self) -> int:
        return len(self.obs_names)

    def obs_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(low, high) of the observation, float32 (the kernel clips to exactly these)."""
        k0 = 0 if self.include_x else 1
        return self._obs_low[k0:].copy(), self._obs_high[k0:].copy()

    # -- batches ---------------------------------------------------------------------------------
    def new_batch(self, n: int) -> Batch:
        """Arrays for ``n`` robots, each at z_ref (call `reset_robot` before stepping)."""
        b = Batch(
            y=np.zeros((n, 8)),
            aux=np.tile(self._aux0, (n, 1)),
            flags=np.zeros((n, N_FLAGS), dtype=np.bool_),
            s=np.zeros((n, S.SIZE)),
            apex=np.zeros((n, self.apex_capacity, 8)),
            obs=np.zeros((n, self.obs_dim), dtype=np.float32),
            actions=np.zeros(n),
            active=np.ones(n, dtype=np.bool_),
        )
        for i in range(n):
            self.reset_robot(b, i, self.z_ref)
        return b

    def start_state(self, rng: np.random.Generator, options: dict | None = None) -> np.ndarray:
        """The start apex state z (SI): ``options["apex_state"]`` if given, else
        z_ref + reset_noise_scale * apex_scales * U(-1, 1) (one draw per component).
        ``options`` is None or a dict of `RESET_OPTIONS` (`check_reset_options`)."""
        options = check_reset_options(options)
        if options.get("apex_state") is not None:
            return self.check_apex_state(options["apex_state"])
        noise = rng.uniform(-1.0, 1.0, size=6)
        return self.z_ref + self.reset_noise_scale * self.apex_scales * noise

    @staticmethod
    def check_apex_state(z) -> np.ndarray:
        msg = f"apex_state must be 6 real numbers {Z_NAMES} in SI units (shape (6,)), got {z!r}"
        try:
            raw = np.asarray(z)
        except (TypeError, ValueError):  # ragged nested sequences
            raise ValueError(msg) from None
        # no silent reshape of (2, 3) or (6, 1), no cast of strings, bools, complex or objects
        if raw.ndim != 1 or raw.dtype.kind not in "iuf":
            raise ValueError(msg)
        try:
            z = np.array(raw, dtype=float).reshape(6)
        except (TypeError, ValueError):
            raise ValueError(msg) from None
        if not np.all(np.isfinite(z)):
            raise ValueError(f"apex_state must be finite, got {z.tolist()}")  # one line
        return z

    def reset_robot(self, b: Batch, i: int, z: np.ndarray) -> None:
        """Put robot i at the apex state z (x_g = 0, both legs in flight, t = 0)."""
        z = np.asarray(z, dtype=float).reshape(6)
        reset_at_apex(b.y[i], b.aux[i], b.flags[i], b.s[i], b.obs[i], self._aux0, z, self.cfg)

    def restart_robot(self, b: Batch, i: int) -> None:
        """Start robot i again at t = 0 from its full state and parameters as they are (after
        the caller changed them: a slope change, parameter overrides)."""
        start_at_state(b.y[i], b.aux[i], b.flags[i], b.s[i], b.obs[i], self.cfg)

    def draw_slope_noise(self, b: Batch, i: int, rng: np.random.Generator) -> None:
        """Rough terrain only (``slope_noise_deg > 0``): fresh standard normal draws xi for
        the slope changes at robot i's next apexes (call after `reset_robot` and after every
        interval in which a stride completed). Without slope noise no number is drawn."""
        if self.slope_noise_deg > 0.0:
            b.s[i, S.XI : S.XI + N_XI] = rng.standard_normal(N_XI)

    @staticmethod
    def failed(b: Batch) -> np.ndarray:
        """Per robot: did its last interval (or its start state) fail? (terminates it)"""
        return b.s[:, S.STATUS] >= FAIL_FIRST

    def step(self, b: Batch, parallel: bool = False) -> None:
        """One control interval for the robots with ``b.active`` (torques in ``b.actions``)."""
        kernel = step_batch_parallel if parallel else step_batch
        kernel(b.y, b.aux, b.flags, b.s, b.apex, b.obs, self.cfg, b.actions, b.active)

    # -- info ----------------------------------------------------------------------------------
    def info(self, b: Batch, i: int, reset: bool = False) -> dict:
        """The info dictionary of robot i after a step (or, with ``reset``, after a reset)."""
        s = b.s[i].tolist()  # Python floats in one call (this runs at every step)
        status = int(s[S.STATUS])
        info = {
            "x_position": s[S.X],
            "phase": PHASES[int(s[S.PHASE])],
            "stride": int(s[S.STRIDES]),
            "time": s[S.T],
            "tau": s[S.TAU],
            "energy": s[S.ENERGY],
            "reward_alive": s[S.ALIVE],
            "reward_tracking": s[S.TRACKING],
            "reward_ctrl": s[S.CTRL],
            "failure": FAILURE_NAMES[status],
        }
        if reset:
            info["start_z"] = b.y[i][_Z_IDX]
        elif s[S.NAPEX] > 0.0:
            n = int(s[S.NAPEX])
            info["apex_z"] = b.apex[i, min(n, b.apex.shape[1]) - 1][_Z_IDX]
            info["apex_count"] = n
        return info

    def vector_info(self, b: Batch, rows=None, reset_rows=None) -> dict:
        """Infos of the robots in ``rows`` (bool mask; None: all), batched as Gymnasium's vector
        envs batch them: one array per key plus a ``_key`` mask, zeros (None) where the mask
        is off. Robots in ``reset_rows`` (None: none) report their reset info, the others their
        step info."""
        s = b.s.T  # one row per S_* column
        full = rows is None
        if full:
            rows = np.ones(b.n, dtype=np.bool_)
        info = {}

        def put(key, values, mask=rows, full=full):
            if not full:
                values = np.where(mask.reshape(-1, *([1] * (values.ndim - 1))), values, 0)
                values = values.astype(values.dtype, copy=False)
            info[key], info["_" + key] = values, mask.copy()

        put("x_position", s[S.X].copy())
        phase = _PHASE_OBJECTS[s[S.PHASE].astype(np.int64)]
        if not full:
            phase[~rows] = None
        put("phase", phase, full=True)
        put("stride", s[S.STRIDES].astype(np.int64))
        put("time", s[S.T].copy())
        put("tau", s[S.TAU].copy())
        put("energy", s[S.ENERGY].copy())
        put("reward_alive", s[S.ALIVE].copy())
        put("reward_tracking", s[S.TRACKING].copy())
        put("reward_ctrl", s[S.CTRL].copy())
        failure = np.full(b.n, None, dtype=object)
        if s[S.STATUS].max() >= FAIL_FIRST:
            for i in np.flatnonzero(rows & (s[S.STATUS] >= FAIL_FIRST)):
                failure[i] = FAILURE_NAMES[int(s[S.STATUS, i])]
        put("failure", failure, full=True)
        if s[S.NAPEX].max() > 0:
            apex_rows = rows & (s[S.NAPEX] > 0)
            if reset_rows is not None:
                apex_rows &= ~reset_rows
            if apex_rows.any():
                napex = s[S.NAPEX].astype(np.int64)
                last = np.clip(napex, 1, b.apex.shape[1]) - 1
                z = b.apex[np.arange(b.n), last][:, _Z_IDX]
                put("apex_z", z, apex_rows, full=False)
                put("apex_count", napex, apex_rows, full=False)
        if reset_rows is not None:
            start_rows = rows & reset_rows
            if start_rows.any():
                put("start_z", b.y[:, _Z_IDX], start_rows, full=False)
        return info
