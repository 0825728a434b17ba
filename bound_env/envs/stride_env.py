"""PassiveBoundStride-v1: the stride-level Gymnasium environment (one step = one stride).

A thin adapter around `bound_env.sim.stride_task.StrideTask`: one step is a macro-step of the
plant, the step env PassiveBound-v0, through the one stride map `bound_env.sim.stride_map`.
"""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
from gymnasium import spaces, utils

from ..model.params import Params
from ..model.stride import z_from_state
from ..sim.stride_task import (
    DEFAULT_BASIS,
    DEFAULT_CTRL_COST_WEIGHT,
    DEFAULT_STRIDE_MAX_TORQUE,
    DEFAULT_STRIDE_RTOL,
    StrideTask,
)
from ..sim.task import DEFAULT_DT, DEFAULT_RESET_NOISE_SCALE

# Observation bounds of the apex state z = [y_g, th1, th2, xdot_g, th1dot, th2dot] (SI), as the
# step env's (`bound_env.sim.task`): far outside anything a running robot reaches.
Z_LOW = np.array([-1.0, -2 * np.pi, -2 * np.pi, -100.0, -1000.0, -1000.0], dtype=np.float32)
Z_HIGH = np.array([10.0, 2 * np.pi, 2 * np.pi, 100.0, 1000.0, 1000.0], dtype=np.float32)


def check_coefficients(action, K: int) -> np.ndarray:
    """The coefficient vector as float64 of shape (K,); ValueError if it is not K real numbers
    of shape (K,) (no reshape of (1, K) or (K, 1), no cast of complex numbers, strings, bools
    or objects), or NaN/inf."""
    try:
        raw = np.asarray(action)
    except (TypeError, ValueError):  # ragged nested sequences
        raise ValueError(f"action must be K={K} real numbers, got {action!r}") from None
    if raw.dtype.kind not in "iuf":
        raise ValueError(f"action must be K={K} real numbers, got dtype {raw.dtype}")
    if raw.shape != (K,):
        raise ValueError(f"action must have shape ({K},) (K={K} coefficients), got {raw.shape}")
    u = raw.astype(np.float64)
    if not np.isfinite(u).all():
        raise ValueError(f"action must be finite (no NaN or inf), got {u.tolist()}")
    return u


def refuse_step_after_end(why: str | None) -> None:
    """The step-after-termination guard of the stride-level envs: ValueError (one line) when
    ``why`` (what ended the episode) is set; `reset` clears it."""
    if why:
        raise ValueError(f"step() after the episode ended ({why}): call reset() first")


class PassiveBoundStrideEnv(gym.Env, utils.EzPickle):
    r"""Stride-to-stride spine control of the passively bounding quadruped.

    ## Description

    The model of `PassiveBound-v0` (Yamasaki et al.: two rigid bodies joined by a
    spring-damper spine, massless spring legs, down a slope), seen at the apexes only. One step
    is one whole stride, from an apex to the next one after both legs have been in stance (the
    Poincare map of the paper, eq. 18), under a spine-torque profile the action chooses at the
    apex: tau(t) = `max_torque` * sum_i u_i phi_i(t), with t the time since the apex and
    phi_i a basis over the nominal stride (`bound_env.sim.stride_task`). This is the setting of
    event-based, stride-to-stride control (Poincare-map LQR, deadbeat control): the
    classical controllers of `bound_env.control` act here.

    **The plant is the step env.** One step is a macro-step of `PassiveBound-v0`: the
    profile is applied on the step env's control grid, interval k = [k dt, (k + 1) dt] from
    the apex holding the profile's average over it (dt = 10 ms), through the one stride map
    of the project (`bound_env.sim.stride_map`, the step env's own compiled kernel). So a stride
    here is bit-identical to the stride of a `PassiveBound-v0` episode started at the apex
    and stepped with those interval torques, and the stride controllers are designed,
    planned, trained and measured on this same map. Zero action is the passive Poincare map
    up to the integrator tolerance (50 zero-action strides from z* stay within 1e-9 of z*).

    ## Action Space

    `Box(-1, 1, (K,), float32)`: the coefficients u of the torque profile. Out-of-range
    values are clipped; NaN or inf raise `ValueError`.

    | Num | Action | Min | Max | Unit |
    | --- | --- | --- | --- | --- |
    | i   | coefficient u_i of basis function phi_i | -1 | 1 | N m / `max_torque` |

    Bases (`basis`): ``"windows"`` (default): K piecewise-constant windows splitting the
    nominal period T (0.3906 s for the default gait) evenly; ``"phases"``: one window per
    stance condition of the nominal stride (df, bs, df, fs, df for the default gait, so
    K = 5); ``"hats"``: K piecewise-linear hat functions with knots evenly from 0 to T (a
    smooth basis, applied as its average over 8 sub-windows per knot interval). Time is
    measured from the apex; **past T the last window's torque holds** until the apex (a
    stride longer than T, e.g. after a push that slows the robot, keeps the final torque).
    Positive torque pushes theta2 (front body relative to the back one) up.

    ## Observation Space

    `Box(low, high, (6,), float32)`: the apex state z, SI units.

    | Num | Observation | Min | Max | Unit |
    | --- | --- | --- | --- | --- |
    | 0 | y_g, height of the centre of mass above the slope | -1 | 10 | m |
    | 1 | theta1, pitch of the back body | -2 pi | 2 pi | rad |
    | 2 | theta2, front body relative to the back body | -2 pi | 2 pi | rad |
    | 3 | xdot_g, forward speed along the slope | -100 | 100 | m/s |
    | 4 | theta1dot | -1000 | 1000 | rad/s |
    | 5 | theta2dot | -1000 | 1000 | rad/s |

    ydot_g = 0 at an apex (eq. 17), so z is the whole state there; the observation is
    Markov. `info["apex_z"]` holds the same state in float64. After a failure the
    observation is z of the last state (clipped), which is not an apex.

    ## Rewards

    reward = alive + tracking + ctrl, each in `info`:

    - *alive* (`reward_alive`) = `alive_reward` (default 1) for a stride that ends at an
      apex, 0 for a fall;
    - *tracking* (`reward_tracking`) = -`tracking_cost_weight` (default 1) *
      sum_i ((z_i - z*_i) / s_i)^2 for the new apex state z, with z* the gait's fixed point
      and s = `apex_scales` (as in `PassiveBound-v0`); 0 after a fall;
    - *ctrl* (`reward_ctrl`) = -`ctrl_cost_weight` (default 0.1) * mean_i(u_i^2), u clipped.

    ## Starting State

    As `PassiveBound-v0`: z* + `reset_noise_scale` * s * U(-1, 1)^6 (default noise 0.5,
    0 starts on the cycle); `reset(options={"apex_state": z})` starts at z (SI, 6 numbers).

    ## Episode End

    ### Termination

    On a fall, with the failure reason in `info["failure"]` (the step env's reasons:
    `ground_contact_back_hip`, `ground_contact_spine_joint`, `ground_contact_front_hip`,
    `moving_backwards`, `leg_overcompressed_back|front`,
    `leg_extending_at_touchdown_back|front`, `no_apex` (no apex within 2 s), `non_finite`,
    `integration_failed`), None otherwise. A start state that is already impossible fails at
    the first step (its reason is already in the reset `info["failure"]`).

    ### Truncation

    After 100 strides, by `register(max_episode_steps=100)`.

    ## Info

    `failure`, `reward_alive`, `reward_tracking`, `reward_ctrl`, `stride` (strides completed),
    `period` (duration of the stride [s], to the failure on a fall), `effort` (mean |tau|
    over the stride [N m]), `tau_windows` (torque on each sub-window [N m]), and `apex_z`
    (float64, SI) after a completed stride; `reset()` gives `start_z` and `failure`.

    ## Arguments

    ```python
    import gymnasium as gym
    import bound_env
    gym.register_envs(bound_env)
    env = gym.make("PassiveBoundStride-v1", basis="windows", K=4, max_torque=80.0)
    ```

    | Parameter | Type | Default | Description |
    | --- | --- | --- | --- |
    | `gait` | **str, Path** | `"default"` | gait file (path, or name under `configs/gaits/`) |
    | `gait_overrides` | **dict** | `None` | gait keys to change, e.g. `{"kc": 300}` (1) |
    | `basis` | **str** | `"windows"` | `"windows"`, `"phases"` or `"hats"` |
    | `K` | **int** | `4` | number of basis functions (`"phases"`: the number of nominal phases) |
    | `max_torque` | **float** | `80.0` | torque at coefficient 1 [N m] (2) |
    | `reset_noise_scale` | **float** | `0.5` | start noise in units of `apex_scales` |
    | `alive_reward` | **float** | `1.0` | per completed stride |
    | `tracking_cost_weight` | **float** | `1.0` | weight of the apex tracking cost |
    | `ctrl_cost_weight` | **float** | `0.1` | weight of mean(u^2) |
    | `apex_scales` | **6 floats** | as `PassiveBound-v0` | unit of apex deviation (SI) |
    | `rtol` | **float** | `1e-10` | integrator tolerance (relative and absolute) |
    | `slope_noise_deg` | **float** | `0.0` | rough terrain: sigma of the slope at each apex [deg] |
    | `dt` | **float** | `0.01` | control grid of the plant, the step env's interval [s] |

    (1) z* and the basis (the nominal stride) stay the gait file's. (2) The saturation of the
    learned policies (`agents/policies/default`).

    New keyword arguments are passed through to `bound_env.sim.stride_task.StrideTask`, which
    takes the same keywords as `bound_env.sim.task.PassiveBoundTask` where they overlap.
    No rendering: `bound-env animate` shows the gait.

    ## Version History

    * v1: The plant is the step env: the profile acts through its interval averages on the
      step env's 10 ms grid (the one stride map, `bound_env.sim.stride_map`), as in `margins`,
      the MPC, distillation and fine-tuning. New argument `dt`.
    * v0: Initial version: the profile was applied on exact window edges of the nominal
      period (the integrator stopped at each edge), a different map from the step env's grid
      (a one-switch bang-bang profile landed up to 0.057 normalized apex error apart). No
      longer registered: `gym.make("PassiveBoundStride-v0")` raises Gymnasium's
      `DeprecatedEnv` naming v1. `slope_noise_deg` (rough terrain, as in `PassiveBound-v0`:
      the slope becomes alpha + sigma xi_k at every apex reached) was added to v0 with
      default 0.
    """

    metadata = {"render_modes": []}

    def __init__(
        self,
        gait: str = "default",
        gait_overrides: dict | None = None,
        basis: str = DEFAULT_BASIS,
        K: int | None = None,
        max_torque: float = DEFAULT_STRIDE_MAX_TORQUE,
        reset_noise_scale: float = DEFAULT_RESET_NOISE_SCALE,
        alive_reward: float = 1.0,
        tracking_cost_weight: float = 1.0,
        ctrl_cost_weight: float = DEFAULT_CTRL_COST_WEIGHT,
        apex_scales=None,
        rtol: float = DEFAULT_STRIDE_RTOL,
        slope_noise_deg: float = 0.0,
        dt: float = DEFAULT_DT,
    ):
        kwargs = dict(
            gait=gait,
            gait_overrides=gait_overrides,
            basis=basis,
            K=K,
            max_torque=max_torque,
            reset_noise_scale=reset_noise_scale,
            alive_reward=alive_reward,
            tracking_cost_weight=tracking_cost_weight,
            ctrl_cost_weight=ctrl_cost_weight,
            apex_scales=apex_scales,
            rtol=rtol,
            slope_noise_deg=slope_noise_deg,
            dt=dt,
        )
        utils.EzPickle.__init__(self, **kwargs)
        self.task = StrideTask(**kwargs)
        self.observation_space = spaces.Box(Z_LOW, Z_HIGH, dtype=np.float32)
        self.action_space = spaces.Box(-1.0, 1.0, (self.task.K,), dtype=np.float32)
        self._z = self.task.z_ref.copy()
        self._failure: str | None = None
        self._ended = False  # the last step terminated: step() needs a reset() first
        self._strides = 0
        self._alpha = self.task.params.alpha  # slope under the robot [rad] (rough terrain)

    @property
    def plant_task(self):
        """The one holder of the robot's plant (a `bound_env.sim.task.PassiveBoundTask`, on which
        every stride runs: ``set_params`` changes the next start check, slope draw and
        stride; model error, `bound_env.envs.randomized.RandomizedPlant`)."""
        return self.task.step_task

    @property
    def params(self) -> Params:
        """The plant's parameters (the gait's, with ``gait_overrides``; a drawn plant under
        `bound_env.envs.randomized.RandomizedPlant`)."""
        return self.task.params

    @property
    def z_ref(self) -> np.ndarray:
        """The reference apex state z* (SI)."""
        return self.task.z_ref.copy()

    @property
    def basis(self):
        """The torque basis (`bound_env.sim.stride_task.TorqueBasis`)."""
        return self.task.basis

    @property
    def alpha_deg(self) -> float:
        """The slope under the robot now [deg] (changes at each apex with ``slope_noise_deg``)."""
        return math.degrees(self._alpha)

    @property
    def z(self) -> np.ndarray:
        """The current apex state (SI, float64), a copy."""
        return self._z.copy()

    def _obs(self, z) -> np.ndarray:
        return np.clip(np.nan_to_num(z, nan=-1.0), Z_LOW, Z_HIGH).astype(np.float32)

    def apex_observation(self, z) -> np.ndarray:
        """The observation of the apex state z (SI): z itself, float32, clipped to the
        bounds (sensor noise, `bound_env.envs.randomized.RandomizedPlant`, adds to z first)."""
        return self._obs(np.asarray(z, dtype=float))

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        self._z = self.task.start_state(self.np_random, options)
        self._ended = False
        self._strides = 0
        self._alpha = self.task.params.alpha
        probe = self.task.step_task.new_batch(1)  # the step task's start check
        self.task.step_task.reset_robot(probe, 0, self._z)
        self._failure = self.task.step_task.info(probe, 0, reset=True)["failure"]
        return self._obs(self._z), {"start_z": self._z.copy(), "failure": self._failure}

    def step(self, action):
        refuse_step_after_end("the robot fell" if self._ended else None)
        u = np.clip(check_coefficients(action, self.task.K), -1.0, 1.0)
        taus = self.task.basis.torques(u, self.task.max_torque)
        slope = None
        if self.task.slope_noise_deg > 0.0 and self._strides > 0:
            # rough terrain, as PassiveBound-v0: the slope changes at every apex reached
            alpha = self.task.params.alpha + math.radians(self.task.slope_noise_deg) * float(
                self.np_random.standard_normal()
            )
            slope = (self._alpha, alpha)
        out = self.task.sim.run(self._z, u, slope)
        if slope is not None and out.z1 is not None:
            self._alpha = slope[1]
        failed = out.z1 is None
        alive, tracking, ctrl = self.task.rewards(out.z1, u, failed)
        info = {
            "failure": out.failure,
            "reward_alive": alive,
            "reward_tracking": tracking,
            "reward_ctrl": ctrl,
            "period": out.period,
            "effort": out.effort,
            "tau_windows": taus,
        }
        if failed:
            self._ended = True
            obs = self._obs(z_from_state(out.y_end))
        else:
            self._strides += 1
            self._z = out.z1
            info["apex_z"] = out.z1.copy()
            obs = self._obs(out.z1)
        info["stride"] = self._strides
        return obs, alive + tracking + ctrl, bool(failed), False, info
