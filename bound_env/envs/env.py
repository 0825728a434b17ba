"""PassiveBound-v0: the Gymnasium environment for spine control around the passive gait.

A thin adapter: the task (`bound_env.sim.task.PassiveBoundTask`) decides the start state, the
observation, the reward and the termination; the hybrid simulator (`bound_env.model.fast`)
integrates; this class only speaks Gymnasium's API (spaces, seeding, ``step``/``reset``/``render``).
"""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
from gymnasium import spaces, utils

from ..files.schema import integer
from ..model.params import P_ALPHA, Params
from ..sim.task import (
    DEFAULT_ALIVE_REWARD,
    DEFAULT_CTRL_COST_WEIGHT,
    DEFAULT_DT,
    DEFAULT_MAX_TORQUE,
    DEFAULT_RESET_NOISE_SCALE,
    DEFAULT_RTOL,
    DEFAULT_TRACKING_COST_WEIGHT,
    S_NAPEX,
    S_REWARD,
    S_STRIDES,
    S_T,
    S_TAU,
    TASK_SETTINGS,
    PassiveBoundTask,
    TaskConfig,
)

RENDER_MODES = ("human", "rgb_array")
MAX_FRAME = 4096  # frame width and height [pixels] at most


def check_action(action, n: int = 1) -> np.ndarray:
    """The normalized torque(s) as float64 of shape (n,); ValueError if NaN/inf or mis-shaped.

    Out-of-range values are not an error: the task clips them to [-1, 1].
    """
    if action is None:
        raise ValueError(f"action must hold {n} real number(s), got None")
    raw = np.asarray(action)
    if raw.dtype.kind not in "biuf":  # complex, strings, objects: never coerced silently
        raise ValueError(f"action must hold {n} real number(s), got {action!r}")
    a = raw.astype(np.float64)
    if a.size != n:
        raise ValueError(f"action must hold {n} number(s), got shape {a.shape}")
    a = a.reshape(n)
    if not np.isfinite(a).all():
        raise ValueError(f"action must be finite (no NaN or inf), got {a.tolist()}")
    return a


def _action_value(action) -> float:
    """`check_action` for one robot, as a Python float (a fast path for the usual arrays)."""
    if type(action) is np.ndarray and action.shape == (1,) and action.dtype.kind == "f":
        x = float(action[0])
        if math.isfinite(x):
            return x
    return float(check_action(action)[0])


def make_spaces(task: PassiveBoundTask) -> tuple[spaces.Box, spaces.Box]:
    """(observation space, action space) of one robot."""
    low, high = task.obs_bounds()
    return (spaces.Box(low, high, dtype=np.float32), spaces.Box(-1.0, 1.0, (1,), dtype=np.float32))


def render_text(s) -> str:
    """Overlay text of a frame: time, strides, spine torque."""
    return f"t {s[S_T]:5.2f} s   stride {int(s[S_STRIDES])}   tau {s[S_TAU]:+5.1f} N m"


class PassiveBoundEnv(gym.Env, utils.EzPickle):
    r"""Spine control of a passively bounding two-body quadruped going down a slope.

    ## Description

    The planar model of Yamasaki et al., *Quadrupedal Bounding with Spring-damper Body Joint*:
    two rigid bodies joined by a spring-damper spine (k_c, c_c), massless spring legs with
    pin feet, on a slope of angle alpha. Without any input the robot bounds down the slope on a
    passive limit cycle: every stride (apex to apex, ~0.39 s, flight - back stance - flight -
    front stance - flight) returns to the same apex state z* = [y_g, theta1, theta2, xdot_g,
    theta1dot, theta2dot]. The default gait's cycle is stable but its basin is small; a spine
    torque tau between the two bodies lets an agent bring the robot back onto the cycle from
    states the passive dynamics cannot recover from, and earlier than they would.

    Zero action is exactly the passive model. Contacts (touchdown, liftoff), apexes and
    failures are located exactly on the integrator's dense output within each control
    interval (`bound_env.model.fast.advance`), so a control interval never steps over an event.

    ## Action Space

    The action space is a `Box(-1, 1, (1,), float32)`: the normalized spine torque a. Values
    outside [-1, 1] are clipped; a NaN or infinite action raises `ValueError`.

    | Num | Action                                             | Min | Max | Unit               |
    | --- | -------------------------------------------------- | --- | --- | ------------------ |
    | 0   | spine torque tau = `max_torque` * a, held for `dt` | -1  | 1   | N m / `max_torque` |

    tau is a generalized force on theta2 (the front body relative to the back one): positive
    tau pushes theta2 up, and its reaction acts on the back body.

    ## Observation Space

    `Box(low, high, (16,), float32)`. Angles are in radians, positions in the slope frame (x
    along the slope, downhill forward; y normal to it). With
    `exclude_current_positions_from_observation=False`, x_g is prepended (shape (17,)).
    The observation is Markov: with it, the next observation, reward and termination follow
    from the action alone (x_g affects none of them).

    | Num | Observation                                               | Min   | Max      | Unit  |
    | --- | --------------------------------------------------------- | ----- | -------- | ----- |
    | 0   | y_g, height of the centre of mass above the slope         | -1    | 10       | m     |
    | 1   | theta1, pitch of the back body (> 0 raises the front)     | -2 pi | 2 pi     | rad   |
    | 2   | theta2, front body relative to the back body (spine)      | -2 pi | 2 pi     | rad   |
    | 3   | xdot_g, velocity of the centre of mass along the slope    | -100  | 100      | m/s   |
    | 4   | ydot_g, velocity of the centre of mass normal to it       | -100  | 100      | m/s   |
    | 5   | theta1dot                                                 | -1000 | 1000     | rad/s |
    | 6   | theta2dot                                                 | -1000 | 1000     | rad/s |
    | 7   | back leg in stance                                        | 0     | 1        | 0/1   |
    | 8   | front leg in stance                                       | 0     | 1        | 0/1   |
    | 9   | back leg length (rest length lb_bar in flight)            | 0     | 2 l_max  | m     |
    | 10  | back leg angle from the slope normal, toe ahead > 0       | -pi   | pi       | rad   |
    |     | (touchdown angle gamma_b in flight)                       |       |          |       |
    | 11  | front leg length (rest length lf_bar in flight)           | 0     | 2 l_max  | m     |
    | 12  | front leg angle from the slope normal, toe ahead > 0      | -pi   | pi       | rad   |
    |     | (touchdown angle gamma_f in flight)                       |       |          |       |
    | 13  | back leg has touched down since the last apex             | 0     | 1        | 0/1   |
    | 14  | front leg has touched down since the last apex            | 0     | 1        | 0/1   |
    | 15  | time since the last apex (or since the start)             | 0     | 2 + dt   | s     |
    | excluded | x_g, position of the centre of mass along the slope  | -1e5  | 1e5      | m     |

    (l_max = max(lb_bar, lf_bar).) A flight leg is held at its rest length and touchdown
    angle, as the model assumes, so entries 9-12 are continuous at touchdown; at liftoff the
    leg angle jumps back to the touchdown angle (the massless leg snaps back), and entries 7-8
    jump at every contact change (a policy that must be continuous in the state can drop
    them, as `agents.common.wrappers.ObservationFilter` does). Entries 13-14
    decide whether the next apex ends a stride (both legs must have touched down), entry 15
    when the episode ends for lack of an apex. The bounds are far outside anything a running
    robot reaches; the observation is clipped to them, which can only matter in the state a
    failure leaves behind. x_g is always in `info["x_position"]`.

    ## Rewards

    The reward of a control interval is *reward = alive + tracking + ctrl*:

    - *alive* = `alive_reward` (default 1) in every interval that ends without a failure
      (0 in the terminating one).
    - *tracking* = -`tracking_cost_weight` (default 1) * sum_i ((z_i - z*_i) / s_i)^2, paid in
      the interval in which a stride completes, for the new apex state z (summed if several
      strides complete in one interval). z* is the gait's fixed point `z_star` (for a gait
      file without one, such as `paper-literal`, its `z_published`), not changed by
      `gait_overrides`, and s = `apex_scales` (default [0.02 m, 0.1 rad, 0.2 rad, 0.1 m/s,
      1 rad/s, 1 rad/s], about the half-width of the passive basin along each axis).
    - *ctrl* = -`ctrl_cost_weight` (default 0.1) * a^2, with a the clipped normalized action.

    Zero action on the cycle earns the highest possible return (every term at its maximum, up
    to integration error: the apex states stay within ~1e-9 of z*). `info` holds each term as
    `reward_alive`, `reward_tracking`, `reward_ctrl`.

    ## Starting State

    At an apex (x_g = 0, ydot_g = 0, both legs in flight): z = z* + `reset_noise_scale` *
    s * U(-1, 1)^6, one uniform draw per component with s = `apex_scales`, so a noise scale of
    1 reaches about the edge of the passive basin along each axis. `reset_noise_scale=0`
    starts exactly on the cycle. `reset(options={"apex_state": z})` starts at the given apex
    state z (6 numbers, SI units: m, rad, rad, m/s, rad/s, rad/s), ignoring the noise.
    Passive survival over 60 strides from the default noise 0.5 is ~83 % (97.5 % at 0.3,
    46 % at 0.75, 26 % at 1.0).

    ## Episode End

    ### Termination

    On every failure of the simulator, named in `info["failure"]` (None otherwise): a hip or
    the spine joint touching the ground (`ground_contact_back_hip`,
    `ground_contact_spine_joint`, `ground_contact_front_hip`), `moving_backwards`,
    `leg_overcompressed_back|front`, `leg_extending_at_touchdown_back|front`, `non_finite`,
    `integration_failed`, and `no_apex` when no stride completes within 2 s of simulated time.
    A start state that is already impossible fails at the first step (its reason is already
    in the reset `info["failure"]`).

    ### Truncation

    After 3000 steps (30 s at dt = 0.01, ~76 strides), by `register(max_episode_steps=3000)`.

    ## Info

    `x_position` [m], `phase` ("df", "bs", "fs" or "ds"), `stride` (strides completed since the
    reset), `time` [s], `tau` [N m], `energy` (total mechanical energy [J]), `reward_alive`,
    `reward_tracking`, `reward_ctrl`, `failure`; on a step in which a stride completes also
    `apex_z` (the new apex state, SI, 6 numbers; the last one if several) and `apex_count`.
    `reset()` returns the same keys (reward terms 0) plus `start_z`, the start apex state.

    ## Rough terrain

    With `slope_noise_deg` = sigma > 0 the slope changes at every apex: alpha_k = alpha +
    sigma * xi_k, xi_k standard normal from the env's RNG (`reset(seed=...)` fixes the
    terrain). The ground tilts under the robot in flight about the point below its centre of
    mass and the state is re-expressed in the new slope frame (`bound_env.model.terrain`: theta1
    shifts by the change, the velocity components rotate, the height becomes y_g cos d). The
    apex state in `info["apex_z"]` is the one before the tilt; the reset restores the nominal
    slope. `env.unwrapped.alpha_deg` is the slope under the robot now. With sigma = 0 (default)
    nothing is drawn and every result is bit-identical to the smooth slope.

    ## Arguments

    ```python
    import gymnasium as gym
    import bound_env
    gym.register_envs(bound_env)
    env = gym.make("PassiveBound-v0", max_torque=40.0, reset_noise_scale=0.5)
    ```

    | Parameter | Type | Default | Description |
    | --- | --- | --- | --- |
    | `gait` | **str, Path** | `"default"` | gait file (path, or name under `configs/gaits/`) |
    | `gait_overrides` | **dict** | `None` | gait keys to change, e.g. `{"kc": 300}`; z* stays |
    | `dt` | **float** | `0.01` | control interval [s] |
    | `max_torque` | **float** | `40.0` | spine torque at action 1 [N m] |
    | `reset_noise_scale` | **float** | `0.5` | start noise in units of `apex_scales` |
    | `alive_reward` | **float** | `1.0` | alive bonus per interval |
    | `tracking_cost_weight` | **float** | `1.0` | weight of the apex tracking cost |
    | `ctrl_cost_weight` | **float** | `0.1` | weight of the control cost |
    | `apex_scales` | **6 floats** | see Rewards | unit of apex deviation per component (SI) |
    | `exclude_current_positions_from_observation` | **bool** | `True` | omit x_g |
    | `rtol` | **float** | `1e-10` | integrator tolerance (relative, absolute); training uses 1e-8 |
    | `render_mode` | **str** | `None` | `"rgb_array"` or `"human"` |
    | `width`, `height` | **int** | `640`, `360` | frame size [pixels] |
    | `slope_noise_deg` | **float** | `0.0` | rough terrain: sigma of the slope change [deg] |
    | `config` | **TaskConfig** | `None` | all task settings at once (see below) |

    The task settings (every row above but the rendering ones) are one frozen
    `bound_env.sim.task.TaskConfig`; `config=` passes one whole, and keyword arguments not at
    their default change it.

    `max_torque` is of the order of the spine spring's torque on the passive cycle: k_c
    |theta2| peaks at 295 N m/rad * 0.1448 rad = 42.7 N m (theta2 spans -3.3 to +8.3 deg).

    ## Version History

    * v0: Initial version. `slope_noise_deg` (rough terrain) added later with default 0,
      which leaves every result bit-identical.
    * v1 (`PassiveBound-v1`, `PassiveBoundLiteral-v1`): the same class with the published
      task's defaults, `max_torque` 80 N m (`bound_env.PUBLISHED_TASK`), the torque every
      shipped policy and controller uses; v0 (40 N m) stays registered unchanged.
    """

    metadata = {"render_modes": list(RENDER_MODES), "render_fps": round(1 / DEFAULT_DT)}

    def __init__(
        self,
        gait: str = "default",
        gait_overrides: dict | None = None,
        dt: float = DEFAULT_DT,
        max_torque: float = DEFAULT_MAX_TORQUE,
        reset_noise_scale: float = DEFAULT_RESET_NOISE_SCALE,
        alive_reward: float = DEFAULT_ALIVE_REWARD,
        tracking_cost_weight: float = DEFAULT_TRACKING_COST_WEIGHT,
        ctrl_cost_weight: float = DEFAULT_CTRL_COST_WEIGHT,
        apex_scales=None,
        exclude_current_positions_from_observation: bool = True,
        rtol: float = DEFAULT_RTOL,
        render_mode: str | None = None,
        width: int = 640,
        height: int = 360,
        slope_noise_deg: float = 0.0,
        config: TaskConfig | None = None,
    ):
        settings = {k: v for k, v in locals().items() if k in TASK_SETTINGS}
        utils.EzPickle.__init__(
            self, **settings, render_mode=render_mode, width=width, height=height, config=config
        )
        if render_mode is not None and render_mode not in RENDER_MODES:
            raise ValueError(
                f"render_mode must be one of {RENDER_MODES} or None, got {render_mode!r}"
            )
        self.task = PassiveBoundTask(
            TaskConfig.resolve(config, settings, defaults_keep_config=True)
        )
        self.dt = self.task.dt
        self.metadata = {"render_modes": list(RENDER_MODES), "render_fps": round(1 / self.dt)}
        self.observation_space, self.action_space = make_spaces(self.task)
        self.observation_structure = dict(
            zip(self.task.obs_names, self.task.obs_units, strict=True)
        )
        self.render_mode = render_mode
        self.width = integer(width, "width", 1, MAX_FRAME)  # [pixels]; a bool or 1.5 refused
        self.height = integer(height, "height", 1, MAX_FRAME)
        self._renderer = None
        self._b = self.task.new_batch(1)

    # -- the simulator's state, for analysis --------------------------------------------------
    @property
    def plant_task(self) -> PassiveBoundTask:
        """The one holder of the robot's plant (`PassiveBoundTask.set_params` changes the
        robot of the next reset: model error, `bound_env.envs.randomized.RandomizedPlant`)."""
        return self.task

    @property
    def params(self) -> Params:
        """Physical parameters in use (the gait's, with ``gait_overrides``)."""
        return self.task.params

    @property
    def alpha_deg(self) -> float:
        """The slope under the robot now [deg] (changes at each apex with ``slope_noise_deg``)."""
        return math.degrees(self._b.aux[0, P_ALPHA])

    @property
    def z_ref(self) -> np.ndarray:
        """The reference apex state z* (SI) the tracking term compares against."""
        return self.task.z_ref.copy()

    @property
    def state(self) -> np.ndarray:
        """Full state y = [x_g, y_g, th1, th2, xdot_g, ydot_g, th1dot, th2dot] (SI), a copy."""
        return self._b.y[0].copy()

    @property
    def aux(self) -> np.ndarray:
        """Parameter and contact vector of the simulator (`bound_env.model.dynamics`), a copy."""
        return self._b.aux[0].copy()

    def kick(self, delta_qdot) -> None:
        """An impulse between two control intervals: add ``delta_qdot`` = [d xdot_g, d ydot_g,
        d theta1dot, d theta2dot] (SI) to the velocities. Positions, contacts and toes stay, so
        the hybrid state stays consistent; the next observation shows the kick."""
        d = np.asarray(delta_qdot, dtype=np.float64).reshape(4)
        if not np.isfinite(d).all():
            raise ValueError(f"kick must be finite, got {d.tolist()}")
        self._b.y[0, 4:] += d

    # -- Gymnasium API ---------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        z = self.task.start_state(self.np_random, options)
        self.task.reset_robot(self._b, 0, z)
        self.task.draw_slope_noise(self._b, 0, self.np_random)
        if self.render_mode == "human":
            self.render()
        return self._b.obs[0].copy(), self.task.info(self._b, 0, reset=True)

    def step(self, action):
        b = self._b
        b.actions[0] = _action_value(action)
        self.task.step(b)
        s = b.s[0]
        if s[S_NAPEX] > 0.0:
            self.task.draw_slope_noise(b, 0, self.np_random)
        terminated = self.task.failed(b)[0]
        if self.render_mode == "human":
            self.render()
        return b.obs[0].copy(), float(s[S_REWARD]), bool(terminated), False, self.task.info(b, 0)

    def render(self):
        if self.render_mode is None:
            gym.logger.warn(
                "You are calling render method without specifying any render mode. "
                'Set render_mode at initialization, e.g. gym.make("PassiveBound-v0", '
                'render_mode="rgb_array")'
            )
            return None
        if self._renderer is None:
            from .render import Renderer

            self._renderer = Renderer(self.render_mode, self.width, self.height)
        b = self._b
        return self._renderer.render(b.y[0], b.aux[0], text=render_text(b.s[0]))

    def close(self):
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
