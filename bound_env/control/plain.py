"""A controller as a function of what the env gives it: ``act(obs, info)`` for the plain loop.

Every Gymnasium user writes the same loop:

```python
obs, info = env.reset(seed=0)
while not (terminated or truncated):
    obs, reward, terminated, truncated, info = env.step(act(obs, info))
```

A stride controller (LQR, deadbeat, MPC, the distilled and stride-level policies) plans its
torque profile at every apex from the exact apex state, which only the env's ``info`` carries
(``start_z`` after a reset, ``apex_z`` after the step that passed an apex); the observation is
float32 and taken at the end of the interval, after the apex. `PlainPolicy` is the loop side of
that protocol (`bound_env.control.controllers.notify_apex`) folded into the policy: called with
the info that came with ``obs`` it announces each apex, then returns the controller's action,
so the plain loop gives the same trajectory as the CLI's ``bound-env rollout`` bit for bit.

It fails loudly where the loop would silently go wrong:

- a stride controller called without ``info`` (``act(obs)``): TypeError (it could only re-plan
  from its first observation and falls within a few strides); feedback controllers (a PPO
  MLP, damping, passive) take ``act(obs)`` and ``act(obs, info)``;
- a first call whose info is not a reset's, an info that skipped an apex (the stride count
  rose without ``apex_z``: a step was taken without calling ``act``), an info older than the
  last one, or one of a failed episode: ValueError;
- an env whose settings differ from the controller's, where they show: the observation's
  length (a full or, for a policy trained through an observation filter, a filtered one is
  accepted), ``info["tau"]`` after a non-zero action (the env's ``max_torque``), and
  ``info["time"]`` between two calls (the env's ``dt``): ValueError naming the setting.
  The integrator tolerance and the gait do not show in what the env returns.

A privileged controller (``privileged`` true: `bound_env.control.privileged`, an upper
reference that reads the robot's true plant) gets ``info["plant"]`` at each reset of an env
that reports it (`bound_env.envs.wrappers.RandomizedPlant`); no other controller ever does.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping

import numpy as np

from ..sim.stride_protocol import notify_apex, reset_controller
from ..sim.task import DEFAULT_DT, OBS_NAMES

FULL_OBS_DIM = len(OBS_NAMES) - 1  # the default observation (x_g excluded)
_MAKE = 'gym.make("PassiveBound-v1") (or the env factory of agents.runtime.rollout.load_policy)'
_SHARED = "one act per env: call load_policy once per env, or copy.deepcopy(act)"


class PlainPolicy:
    """``act(obs, info=None) -> np.ndarray`` (float32, shape (1,)) for the plain loop (module
    docstring). ``controller`` follows `bound_env.control.controllers`' protocol;
    ``obs_index``: the entries of the full observation it reads (None: all), so that it
    takes both the full observation and the filtered one; ``full_dim``: the length of the
    env's full observation (default: x_g excluded, 16)."""

    def __init__(self, controller, obs_index=None, full_dim: int = FULL_OBS_DIM, name=None):
        if not callable(controller):
            raise TypeError(
                "PlainPolicy: controller must be a callable controller (obs -> action in "
                f"[-1, 1]), got {type(controller).__name__}; load one with "
                "agents.runtime.rollout.load_policy(NAME) or "
                "bound_env.control.load_controller(NAME)"
            )
        self.controller = controller  # public; the loop below calls its own reference
        self._ctrl = controller
        self.name = str(name if name is not None else getattr(controller, "name", controller))
        self.needs_info = callable(getattr(controller, "on_apex", None))
        kwargs = dict(getattr(controller, "env_kwargs", None) or {})
        mt = kwargs.get("max_torque")
        self.max_torque = None if mt is None else float(mt)  # None: any (the zero action)
        self.dt = float(kwargs.get("dt", DEFAULT_DT))
        self.obs_index = None if obs_index is None else np.asarray(obs_index)
        self._read = {int(full_dim): self.obs_index}  # observation length -> entries read
        if self.obs_index is not None:
            self._read[len(self.obs_index)] = None
        self._answers = deque(maxlen=8)  # the last actions returned (any episode)
        self.restart()

    def restart(self) -> None:
        """Forget the episode (the next call must bring a reset's info), and a stateful
        controller's memory of it."""
        reset_controller(self._ctrl)
        self._started = False
        self._info = None  # the last info seen (a repeat call announces nothing)
        self._time = None
        self._stride = None
        self._action = None

    # -- checks -----------------------------------------------------------------------------
    def _observation(self, obs) -> np.ndarray:
        x = np.asarray(obs)
        if x.ndim != 1 or x.dtype.kind not in "fiu" or x.shape[0] not in self._read:
            lengths = " or ".join(str(n) for n in sorted(self._read))
            raise ValueError(
                f"policy {self.name}: obs must be one observation of PassiveBound (length "
                f"{lengths}), got shape {x.shape}; make the env with {_MAKE}"
            )
        if not np.all(np.isfinite(x)):
            bad = int(np.flatnonzero(~np.isfinite(x))[0])
            raise ValueError(
                f"policy {self.name}: obs[{bad}] is {x[bad]} (an observation must be finite); "
                "a fallen or diverged env must be reset before acting"
            )
        index = self._read[x.shape[0]]
        return x if index is None else x[index]

    def _check_info(self, info) -> bool:
        """Validate ``info`` against the last call; True if it announces something new."""
        if not isinstance(info, Mapping):
            raise TypeError(
                f"policy {self.name}: info must be the dict that env.reset or env.step "
                f"returned with obs, got {type(info).__name__}"
            )
        if info is self._info:
            return False  # the same step asked twice: nothing new
        if info.get("failure") is not None:
            raise ValueError(
                f"policy {self.name}: the episode has ended (failure {info['failure']!r}); "
                "call env.reset() before acting again"
            )
        if "start_z" in info:  # a reset: a new episode
            self.restart()
            self._started = True
            if getattr(self._ctrl, "privileged", False) is True and "plant" in info:
                self._ctrl.set_plant(info["plant"])  # the privileged reference reads the plant
        elif not self._started:
            raise ValueError(
                f"policy {self.name}: the first call of an episode must pass the info of "
                "env.reset(): obs, info = env.reset(...); act(obs, info)"
            )
        else:
            self._check_step(info)
        self._info = info
        self._time = info.get("time", self._time)
        self._stride = info.get("stride", self._stride)
        return True

    def _check_step(self, info) -> None:
        t, stride = info.get("time"), info.get("stride")
        if self.needs_info and stride is not None and self._stride is not None:
            passed = int(stride) - int(self._stride)
            if passed > (1 if "apex_z" in info else 0):
                raise ValueError(
                    f"policy {self.name}: an apex passed without being announced (stride "
                    f"{self._stride} -> {stride}); call act(obs, info) after every step "
                    f"({_SHARED})"
                )
        if t is not None and self._time is not None:
            step = float(t) - float(self._time)
            if step <= 0.0:
                raise ValueError(
                    f"policy {self.name}: info is not newer than the last one (time {t} after "
                    f"{self._time}); pass the info that env.step returned with obs, and give "
                    f"each env its own act ({_SHARED})"
                )
            if not math.isclose(step, self.dt, rel_tol=1e-9, abs_tol=1e-12):
                raise ValueError(
                    f"policy {self.name}: the env advanced {step:.6g} s since the last call; "
                    f"the policy acts every dt = {self.dt:g} s: make the env with {_MAKE} "
                    "and call act once per step"
                )
        tau, a = info.get("tau"), self._action
        if self.max_torque is not None and tau is not None and a is not None and a != 0.0:
            if not math.isclose(float(tau), self.max_torque * a, rel_tol=1e-9, abs_tol=1e-12):
                if self._answered(float(tau)):
                    raise ValueError(
                        f"policy {self.name}: the env applied tau = {float(tau):.6g} N m, the "
                        f"torque of an earlier answer of act, not of its last one ({a:.6g}): "
                        f"act is shared between two envs or loops ({_SHARED})"
                    )
                raise ValueError(
                    f"policy {self.name}: the env applied tau = {float(tau):.6g} N m for the "
                    f"action {a:.6g}, i.e. max_torque = {float(tau) / a:.6g} N m; the policy "
                    f"acts with max_torque = {self.max_torque:g} N m: make the env with "
                    f"{_MAKE} and step with the action act returned"
                )

    def _answered(self, tau: float) -> bool:
        """Whether ``tau`` is the torque of one of act's earlier answers (not its last)."""
        earlier = list(self._answers)[:-1]
        return any(
            math.isclose(tau, self.max_torque * b, rel_tol=1e-9, abs_tol=1e-12) for b in earlier
        )

    # -- the policy -------------------------------------------------------------------------
    def __call__(self, obs, info=None) -> np.ndarray:
        x = self._observation(obs)
        if info is None:
            if self.needs_info:
                raise TypeError(
                    f"policy {self.name} plans each stride at the apex and needs the env's "
                    "info: call act(obs, info) with the info returned with obs "
                    "(obs, info = env.reset(...); obs, r, term, trunc, info = "
                    "env.step(act(obs, info)))"
                )
        elif self._check_info(info) and self.needs_info:
            notify_apex(self._ctrl, obs, info)
        a = float(self._ctrl(x))
        out = np.array([a], dtype=np.float32)
        self._action = float(out[0])
        self._answers.append(self._action)
        return out

    def __repr__(self) -> str:
        return f"PlainPolicy({self.name!r}, needs_info={self.needs_info})"
