"""Learned stride-level spine control: residual RL on top of the stride LQR.

The policy acts once per stride on `PassiveBoundStride-v1` (one step = one apex-to-apex
stride; its action is the K coefficients u of the stride's spine-torque profile,
`bound_env.stride_task`). Three rl-zoo3 ``env_wrapper`` entries (innermost first) turn that
env into the training task of ``configs/ppo-stride.yaml``:

- `DirectionStarts`: every episode starts at z* + r |z*| xi, the yardstick's own perturbation
  (`bound_env.analysis.margins`: r relative to |z*_i|, xi uniform on the 6-sphere scaled to
  max |xi_i| = 1, or one axis), with r ~ U(0, ``r_max``). ``r_max`` is set well past the
  LQR's r50 (~0.15) on purpose: many starts are unviable, and a fall that comes later is still
  better.
- `StrideControl`: the observation becomes the relative apex error x = (z - z*) / |z*|, and
  the action a residual du on a classical base controller: u = clip(u_base(z) +
  ``residual_scale`` du, -1, 1), with u_base the LQR of ``configs/controllers/<base>.yaml``.
  ``base: null`` is the plain (non-residual) policy, u = du.
- `YardstickReward`: the reward of the yardstick: per stride, ``alive`` plus
  ``contraction_weight`` * clip(log(e_k / e_{k+1}), -1, 1) with e = max_i |x_i| (floored at
  ``e_floor``: the contraction of the apex error, stride over stride), minus ``ctrl_weight`` *
  mean(a^2) of the policy's own action (for the residual, du: it keeps the policy on the LQR
  where the LQR suffices and the torque on the cycle near zero); a fall costs
  ``fall_penalty`` * (1 - k / ``horizon``) after k strides, so an early fall costs more.

`ZeroActionNet` (a callback) zeroes the policy's last layer at the start of training, so the
deterministic residual policy starts *exactly* as its base controller.

`StridePolicyController` runs a trained stride policy inside the step env (`PassiveBound-v0`)
with the protocol of `bound_env.analysis.margins.ClosedLoop`: at every apex (``on_apex``) it
picks the coefficients u, and each control interval outputs the interval average of the
profile's torque, as `bound_env.control.StrideFeedback` does. Inference is NumPy (no torch in
margins' workers); the base gain is read from the policy's own ``base.json`` (written at training
time), so a later change of ``configs/controllers/lqr.yaml`` does not change a trained policy.
"""

from __future__ import annotations

import hashlib
import json
import math
import sys
from dataclasses import dataclass, field
from pathlib import Path

import gymnasium as gym
import numpy as np
from stable_baselines3.common.callbacks import BaseCallback

# policies trained before v1 (agents/policies/stride-residual) name v0: they load, and act on v1
from bound_env import STRIDE_ENV_ID, STRIDE_ENV_IDS
from bound_env.rescue_env import sample_direction  # noqa: F401  (moved there; re-exported)

from .controllers import check_gait
from .mlp import extract_actor, mlp_forward
from .policy_files import (
    check_policy_files,
    find_policy_files,
    load_vecnormalize,
    read_policy_section,
)
from .schema import (
    check_base,
    check_env_kwargs,
    check_layers,
    check_obs_stats,
    check_residual_scale,
)

BASE_FILE = "base.json"
# tolerance of the nominal stride that sets the basis' window edges in the step env: that of
# `bound_env.control.load_controller`, so a zero residual plays out exactly as the LQR there
BASIS_RTOL = 1e-12  # the base controller of a residual policy, beside its model.zip


# --------------------------------------------------------------------------------------------
# Training wrappers
# --------------------------------------------------------------------------------------------


def _stride_env(env: gym.Env):
    u = env.unwrapped
    if not hasattr(u, "task") or not hasattr(u.task, "sim"):
        raise ValueError(f"{type(env).__name__}: needs a PassiveBoundStride-v1 environment")
    return u


class DirectionStarts(gym.Wrapper):
    """Start each episode at z* + r |z*| xi, r ~ U(r_min, r_max) (see the module docstring).

    :param r_max: largest start, relative to |z*_i| (the LQR's r50 is about 0.15).
    :param r_min: smallest start.
    :param axis_prob: probability of a single-axis direction (the basin's 12 directions).
    """

    def __init__(
        self, env: gym.Env, r_max: float = 0.3, r_min: float = 0.0, axis_prob: float = 0.25
    ):
        super().__init__(env)
        u = _stride_env(env)
        if not (0.0 <= r_min <= r_max and math.isfinite(r_max)):
            raise ValueError(f"need 0 <= r_min <= r_max, got r_min={r_min}, r_max={r_max}")
        if not 0.0 <= axis_prob <= 1.0:
            raise ValueError(f"axis_prob must lie in [0, 1], got {axis_prob}")
        self.z_ref = np.array(u.z_ref, dtype=float)
        self.r_min, self.r_max, self.axis_prob = float(r_min), float(r_max), float(axis_prob)

    def sample_start(self, rng: np.random.Generator) -> np.ndarray:
        r = rng.uniform(self.r_min, self.r_max)
        return self.z_ref + r * np.abs(self.z_ref) * sample_direction(rng, self.axis_prob)

    def reset(self, *, seed=None, options=None):
        if options and options.get("apex_state") is not None:
            return self.env.reset(seed=seed, options=options)
        if seed is not None:
            self.env.reset(seed=seed)
        z = self.sample_start(self.env.unwrapped.np_random)
        return self.env.reset(options={**(options or {}), "apex_state": z})


@dataclass
class BaseGain:
    """u_base(z) = clip(-G (z - z*), -1, 1): a stride-level linear controller."""

    gain: np.ndarray  # (K, 6), SI
    z_ref: np.ndarray  # (6,)
    name: str = "lqr"

    def __call__(self, z) -> np.ndarray:
        return np.clip(-(self.gain @ (np.asarray(z, dtype=float) - self.z_ref)), -1.0, 1.0)

    def to_json(self) -> dict:
        return {"name": self.name, "gain": self.gain.tolist(), "z_ref": self.z_ref.tolist()}

    @classmethod
    def from_json(cls, data: dict) -> BaseGain:
        return cls(
            np.asarray(data["gain"], dtype=float),
            np.asarray(data["z_ref"], dtype=float),
            str(data.get("name", "lqr")),
        )


def design_base(base: str, gait: str, basis_name: str, K: int, max_torque: float) -> BaseGain:
    """The base controller ``base`` (a spec of `bound_env.control`) for this stride env;
    ValueError if its basis or saturation differ from the env's."""
    from bound_env.control import StrideFeedback, load_controller

    ctrl = load_controller(base, gait=gait)
    if not isinstance(ctrl, StrideFeedback):
        raise ValueError(f"base {base!r} is not a stride-level controller (lqr or deadbeat)")
    if ctrl.basis.name != basis_name or ctrl.basis.K != K or ctrl.max_torque != max_torque:
        raise ValueError(
            f"base {base!r} uses basis {ctrl.basis.name!r}, K={ctrl.basis.K}, max_torque="
            f"{ctrl.max_torque}; the env has {basis_name!r}, K={K}, max_torque={max_torque}"
        )
    return BaseGain(
        np.array(ctrl.gain, dtype=float), np.array(ctrl.z_ref, dtype=float), Path(str(base)).stem
    )


class StrideControl(gym.Wrapper):
    """Relative apex error in, residual coefficients out (see the module docstring).

    :param base: a stride-level controller spec (``"lqr"``, a .yaml) or None (plain policy).
    :param residual_scale: u = clip(u_base + residual_scale * du, -1, 1).
    :param base_gain: an explicit `BaseGain` (or its JSON dict) instead of designing ``base``.
    """

    def __init__(
        self, env: gym.Env, base: str | None = "lqr", residual_scale: float = 1.0, base_gain=None
    ):
        super().__init__(env)
        u = _stride_env(env)
        task = u.task
        if not (math.isfinite(residual_scale) and residual_scale > 0):
            raise ValueError(f"residual_scale must be positive, got {residual_scale!r}")
        self.residual_scale = float(residual_scale)
        self.z_ref = np.array(task.z_ref, dtype=float)
        self.scale = np.abs(self.z_ref)
        if isinstance(base_gain, dict):
            base_gain = BaseGain.from_json(base_gain)
        if base_gain is None and base is not None:
            base_gain = design_base(
                base, str(task.gait.path), task.basis.name, task.K, task.max_torque
            )
        self.base = base_gain
        big = np.float32(1e3)
        self.observation_space = gym.spaces.Box(-big, big, (6,), dtype=np.float32)

    def observe(self, z) -> np.ndarray:
        x = (np.asarray(z, dtype=float) - self.z_ref) / self.scale
        return np.clip(x, -1e3, 1e3).astype(np.float32)

    def coefficients(self, z, du) -> np.ndarray:
        du = np.clip(np.asarray(du, dtype=float), -1.0, 1.0)
        u0 = self.base(z) if self.base is not None else 0.0
        return np.clip(u0 + self.residual_scale * du, -1.0, 1.0)

    def reset(self, **kwargs):
        obs, info = self.env.reset(**kwargs)
        return self.observe(self.env.unwrapped.z), info

    def step(self, action):
        z = self.env.unwrapped.z
        obs, reward, terminated, truncated, info = self.env.step(self.coefficients(z, action))
        z1 = info.get("apex_z")
        return (
            self.observe(z1) if z1 is not None else self.observe(self.env.unwrapped.z),
            reward,
            terminated,
            truncated,
            info,
        )


class YardstickReward(gym.Wrapper):
    """The reward of the yardstick (see the module docstring); the env's own reward is kept in
    ``info["reward_env"]``."""

    def __init__(
        self,
        env: gym.Env,
        alive: float = 1.0,
        contraction_weight: float = 1.0,
        ctrl_weight: float = 0.5,
        fall_penalty: float = 20.0,
        horizon: int = 30,
        e_floor: float = 1e-3,
    ):
        super().__init__(env)
        u = _stride_env(env)
        for key, v in (
            ("alive", alive),
            ("contraction_weight", contraction_weight),
            ("ctrl_weight", ctrl_weight),
            ("fall_penalty", fall_penalty),
        ):
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"{key} must be a non-negative number, got {v!r}")
        if not (horizon >= 1 and e_floor > 0):
            raise ValueError(f"need horizon >= 1 and e_floor > 0, got {horizon}, {e_floor}")
        self.z_ref = np.array(u.z_ref, dtype=float)
        self.scale = np.abs(self.z_ref)
        self.alive, self.contraction_weight = float(alive), float(contraction_weight)
        self.ctrl_weight, self.fall_penalty = float(ctrl_weight), float(fall_penalty)
        self.horizon, self.e_floor = int(horizon), float(e_floor)
        self._e = 1.0

    def error(self, z) -> float:
        return max(self.e_floor, float(np.max(np.abs((np.asarray(z) - self.z_ref) / self.scale))))

    def reset(self, **kwargs):
        obs, info = self.env.reset(**kwargs)
        self._e = self.error(self.env.unwrapped.z)
        return obs, info

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        a = np.clip(np.asarray(action, dtype=float), -1.0, 1.0)
        r = -self.ctrl_weight * float(np.mean(a * a))
        if info.get("apex_z") is None:
            k = int(info.get("stride", 0))
            r -= self.fall_penalty * max(0.0, 1.0 - k / self.horizon)
        else:
            e1 = self.error(info["apex_z"])
            r += self.alive + self.contraction_weight * float(
                np.clip(math.log(self._e / e1), -1.0, 1.0)
            )
            self._e = e1
        info["reward_env"] = reward
        return obs, r, terminated, truncated, info


class ZeroActionNet(BaseCallback):
    """Zero the weights and bias of the policy's last layer (``action_net``) before the first
    update of a new run, so that the deterministic policy outputs exactly 0 (a residual
    policy starts as its base controller). A resumed run is left alone."""

    def _on_training_start(self) -> None:
        if self.num_timesteps > 0:
            return
        import torch as th

        with th.no_grad():
            self.model.policy.action_net.weight.zero_()
            self.model.policy.action_net.bias.zero_()

    def _on_step(self) -> bool:
        return True


def anchored_policy_class():
    """`AnchoredMlpPolicy`, built on first use (keeps torch out of a plain import)."""
    global _ANCHORED
    if _ANCHORED is None:
        from stable_baselines3.common.distributions import DiagGaussianDistribution
        from stable_baselines3.common.policies import ActorCriticPolicy

        class AnchoredMlpPolicy(ActorCriticPolicy):
            """PPO's MLP actor-critic whose action mean is g(x) (net(x) - net(0)), with
            g(x) = |x|^2 / (|x|^2 + gate_scale^2) (g = 1 if gate_scale is 0).

            The residual vanishes at observation 0, the reference apex state z* (the
            observation of `StrideControl` is x = (z - z*) / |z*|), whatever the weights:
            under a residual on the LQR (u_lqr(z*) = 0) the closed loop keeps z* as its
            cycle with zero torque. With the gate, the residual also vanishes to second
            order, so the closed loop's linearization at z* is the LQR's (same e_max): the
            residual only acts farther out. Needs an unnormalized observation
            (``norm_obs=False``)."""

            def __init__(self, *args, gate_scale: float = 0.0, **kwargs):
                self.gate_scale = float(gate_scale)
                super().__init__(*args, **kwargs)

            def _get_constructor_parameters(self):
                data = super()._get_constructor_parameters()
                data["gate_scale"] = self.gate_scale
                return data

            def _get_action_dist_from_latent(self, latent_pi):
                raise NotImplementedError("AnchoredMlpPolicy needs the observation")

            def _dist(self, obs, latent_pi):
                import torch as th

                if not isinstance(self.action_dist, DiagGaussianDistribution):
                    raise ValueError("AnchoredMlpPolicy needs a Box action space")
                zero = th.zeros((1, *self.observation_space.shape), device=latent_pi.device)
                latent0 = self.mlp_extractor.forward_actor(self.pi_features_extractor(zero))
                mean = self.action_net(latent_pi) - self.action_net(latent0)
                if self.gate_scale > 0:
                    q = th.sum(th.square(obs.float()), dim=-1, keepdim=True)
                    mean = mean * (q / (q + self.gate_scale**2))
                return self.action_dist.proba_distribution(mean, self.log_std)

            def forward(self, obs, deterministic: bool = False):
                features = self.extract_features(obs)
                if self.share_features_extractor:
                    latent_pi, latent_vf = self.mlp_extractor(features)
                else:
                    latent_pi = self.mlp_extractor.forward_actor(features[0])
                    latent_vf = self.mlp_extractor.forward_critic(features[1])
                values = self.value_net(latent_vf)
                distribution = self._dist(obs, latent_pi)
                actions = distribution.get_actions(deterministic=deterministic)
                log_prob = distribution.log_prob(actions)
                actions = actions.reshape((-1, *self.action_space.shape))
                return actions, values, log_prob

            def evaluate_actions(self, obs, actions):
                features = self.extract_features(obs)
                if self.share_features_extractor:
                    latent_pi, latent_vf = self.mlp_extractor(features)
                else:
                    latent_pi = self.mlp_extractor.forward_actor(features[0])
                    latent_vf = self.mlp_extractor.forward_critic(features[1])
                distribution = self._dist(obs, latent_pi)
                return (
                    self.value_net(latent_vf),
                    distribution.log_prob(actions),
                    distribution.entropy(),
                )

            def get_distribution(self, obs):
                features = super().extract_features(obs, self.pi_features_extractor)
                return self._dist(obs, self.mlp_extractor.forward_actor(features))

        AnchoredMlpPolicy.__module__ = __name__
        AnchoredMlpPolicy.__qualname__ = "AnchoredMlpPolicy"
        _ANCHORED = AnchoredMlpPolicy
    return _ANCHORED


_ANCHORED = None


def __getattr__(name):  # agents.stride.AnchoredMlpPolicy, importable by its dotted path
    if name == "AnchoredMlpPolicy":
        return anchored_policy_class()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


# --------------------------------------------------------------------------------------------
# The trained policy as a controller of the step env
# --------------------------------------------------------------------------------------------


@dataclass
class StridePolicyController:
    """A trained stride policy in the margins protocol (see the module docstring).

    u = clip(u_base(z) + residual_scale * clip(mlp(x), -1, 1), -1, 1), x = (z - z*) / |z*|,
    chosen at each apex; each control interval outputs the interval average of the profile
    tau(t) = max_torque * sum_i u_i phi_i(t) (normalized by max_torque).
    """

    name: str
    layers: list  # [(W, b)] hidden layers, then the action layer
    activation: str
    z_ref: np.ndarray
    edges: np.ndarray  # sub-window edges of the torque basis [s]
    phi: np.ndarray  # (n_sub, K)
    max_torque: float
    base: BaseGain | None = None
    residual_scale: float = 1.0
    anchored: bool = False  # residual = g(x) (net(x) - net(0)) (`AnchoredMlpPolicy`)
    gate_scale: float = 0.0  # g(x) = |x|^2 / (|x|^2 + gate_scale^2), 1 if 0
    obs_mean: np.ndarray | None = None  # VecNormalize statistics of x (None: none)
    obs_var: np.ndarray | None = None
    epsilon: float = 1e-8
    clip_obs: float = 10.0
    dt: float = 0.01
    gait: str = "default"
    seed: int | None = None
    _taus: np.ndarray | None = field(default=None, repr=False)

    @property
    def env_kwargs(self) -> dict:
        return {"gait": self.gait, "max_torque": self.max_torque, "dt": self.dt}

    @property
    def basis(self):
        from bound_env.stride_task import TorqueBasis

        return TorqueBasis("policy", self.edges, self.phi)

    def _net(self, x) -> np.ndarray:
        return mlp_forward(self.layers, x, self.activation)

    def residual(self, z) -> np.ndarray:
        """du = clip(mean action, -1, 1) at apex state z."""
        x = (np.asarray(z, dtype=float) - self.z_ref) / np.abs(self.z_ref)
        x = np.clip(x, -1e3, 1e3).astype(np.float32).astype(float)  # the env's observation
        if self.obs_mean is not None:
            x = np.clip(
                (x - self.obs_mean) / np.sqrt(self.obs_var + self.epsilon),
                -self.clip_obs,
                self.clip_obs,
            )
        mean = self._net(x)
        if self.anchored:
            mean = mean - self._net(np.zeros_like(x))
            if self.gate_scale > 0:
                q = float(np.dot(x, x))
                mean = mean * (q / (q + self.gate_scale**2))
        return np.clip(mean, -1.0, 1.0)

    def coefficients(self, z) -> np.ndarray:
        u0 = self.base(z) if self.base is not None else 0.0
        return np.clip(u0 + self.residual_scale * self.residual(z), -1.0, 1.0)

    def stride_action(self, z) -> np.ndarray:
        """The action of PassiveBoundStride-v1 at apex state z."""
        return self.coefficients(z)

    def interval_actions(self, Z) -> np.ndarray:
        """The step env's actions of the strides from the apex states Z (the protocol of
        `bound_env.control.controllers`)."""
        from bound_env.control.controllers import interval_actions_of, observed_times

        U = [self.coefficients(z) for z in np.atleast_2d(np.asarray(Z, dtype=float))]
        return interval_actions_of(self.basis, self.max_torque, U, observed_times(self.dt), self.dt)

    def apex_torques(self, z) -> np.ndarray:
        """The profile planned at apex state z: torque on each sub-window [N m]."""
        return self.max_torque * (self.phi @ self.coefficients(z))

    snaps_time = False  # the profile is read at the observed (float32) time since the apex

    def on_apex(self, z, time_since_apex: float = 0.0) -> None:
        self._taus = self.apex_torques(z)

    def __call__(self, obs) -> float:
        from bound_env.control.controllers import OBS_TIME, OBS_Z

        t = float(obs[OBS_TIME])
        if self._taus is None:
            self.on_apex(np.asarray(obs, dtype=float)[list(OBS_Z)], t)
        tau = self.basis.average(self._taus, t, t + self.dt)
        return float(np.clip(tau / self.max_torque, -1.0, 1.0))

    def fingerprint(self) -> str:
        h = hashlib.sha256(b"stride-policy")
        for W, b in self.layers:
            h.update(np.ascontiguousarray(W).tobytes())
            h.update(np.ascontiguousarray(b).tobytes())
        arrays = [self.z_ref, self.edges, self.phi]
        if self.base is not None:
            arrays.append(self.base.gain)
        if self.obs_mean is not None:
            arrays += [self.obs_mean, self.obs_var]
        for a in arrays:
            h.update(np.ascontiguousarray(a, dtype=float).tobytes())
        h.update(
            repr(
                (
                    self.max_torque,
                    self.dt,
                    self.gait,
                    self.residual_scale,
                    self.activation,
                    self.anchored,
                    self.gate_scale,
                )
            ).encode()
        )
        return h.hexdigest()[:16]

    def __getstate__(self):
        state = dict(self.__dict__)
        state["_taus"] = None
        return state


def wrapper_kwargs(env_wrappers, name: str) -> dict | None:
    """The kwargs of the ``env_wrapper`` entry whose class is ``name`` (None if absent)."""
    from .config import class_entries

    for path, kw in class_entries(env_wrappers):
        if path.rsplit(".", 1)[-1] == name:
            return dict(kw)
    return None


def load_stride_policy(path, gait=None, force: bool = False) -> StridePolicyController:
    """A trained stride policy (folder or model zip) -> `StridePolicyController` (reads the
    model once, with torch; the controller itself is NumPy). Checks as
    `agents.policy.load_controller` does: the fingerprint of model and statistics, and the gait
    (another ``gait`` than the policy's own is refused unless ``force``)."""
    from stable_baselines3 import PPO

    from bound_env.stride_task import StrideTask

    files = find_policy_files(path)
    model_path, vecnorm_path = files.model, files.vecnormalize
    section, env_id, seed = read_policy_section(files)
    if env_id not in STRIDE_ENV_IDS:
        raise ValueError(f"policy {path} was trained on {env_id}, not {STRIDE_ENV_ID}")
    for w in check_policy_files(files, section, force):
        print(f"warning: {w}", file=sys.stderr)
    env_kwargs = check_env_kwargs(dict(section.get("env_kwargs") or {}), str(files.config))
    wrappers = section.get("env_wrapper") or []
    ctl = wrapper_kwargs(wrappers, "StrideControl")
    if ctl is None:
        raise ValueError(f"{files.config}: no agents.stride.StrideControl in env_wrapper")
    residual_scale = check_residual_scale(ctl.get("residual_scale", 1.0), str(files.config))
    try:
        model = PPO.load(str(model_path), device="cpu")
    except Exception as e:  # noqa: BLE001 - a corrupt or foreign zip is the user's error
        raise ValueError(f"cannot load {model_path} as an SB3 PPO model: {e}") from None
    trained_gait = str(env_kwargs.get("gait", "default"))
    task = StrideTask(
        gait=trained_gait,
        basis=env_kwargs.get("basis", "windows"),
        K=env_kwargs.get("K"),
        max_torque=env_kwargs.get("max_torque", 80.0),
        rtol=BASIS_RTOL,
    )
    if tuple(model.observation_space.shape) != (6,) or tuple(model.action_space.shape) != (task.K,):
        raise ValueError(
            f"policy {model_path} has spaces {model.observation_space.shape} -> "
            f"{model.action_space.shape}; its stride env needs (6,) -> ({task.K},)"
        )
    base = None
    if ctl.get("base") is not None:
        base_path = model_path.parent / BASE_FILE
        if not base_path.is_file():
            raise FileNotFoundError(f"residual policy {path}: missing {base_path}")
        base = BaseGain.from_json(check_base(base_path, task.K))
    layers, activation = extract_actor(model, model_path)
    check_layers(layers, str(model_path))
    ctrl = StridePolicyController(
        name=str(path),
        layers=layers,
        activation=activation,
        z_ref=task.z_ref.copy(),
        edges=task.basis.edges.copy(),
        phi=task.basis.phi.copy(),
        max_torque=task.max_torque,
        base=base,
        residual_scale=residual_scale,
        gait=trained_gait,
        seed=seed,
        anchored=type(model.policy).__name__ == "AnchoredMlpPolicy",
        gate_scale=float(getattr(model.policy, "gate_scale", 0.0)),
    )
    if vecnorm_path is not None:
        vn = load_vecnormalize(vecnorm_path)
        if getattr(vn, "norm_obs", False):
            if ctrl.anchored:
                raise ValueError(f"{vecnorm_path}: an AnchoredMlpPolicy needs norm_obs=False")
            stats = check_obs_stats(vn, str(vecnorm_path), (6,))
            ctrl.obs_mean, ctrl.obs_var, ctrl.epsilon, ctrl.clip_obs = stats
    check_gait(ctrl, gait, force)
    return ctrl


def write_base(run_dir: Path, venv) -> None:
    """Write the base controller of a residual run's envs to ``run_dir/base.json``."""
    # has_attr, not get_attr + AttributeError: in a SubprocVecEnv the failing getattr would kill
    # the worker process (the parent then sees EOFError).
    if not venv.has_attr("base"):
        return
    from bound_env.cache import atomic_write

    bases = venv.get_attr("base")
    if bases and bases[0] is not None:
        atomic_write(Path(run_dir) / BASE_FILE, json.dumps(bases[0].to_json(), indent=2) + "\n")


# --------------------------------------------------------------------------------------------
# A cheap validation curve on the stride map (not the yardstick)
# --------------------------------------------------------------------------------------------

VALIDATION_SEED = 2024  # margins' random directions use 12345; these are other directions


def stride_curve(
    ctrl,
    sizes=(0.05, 0.1, 0.15, 0.2, 0.25, 0.3),
    n_dirs: int = 64,
    seed: int = VALIDATION_SEED,
    strides: int = 60,
    tol: float = 1e-4,
    gait: str = "default",
    settle: int = 200,
) -> dict:
    """Return probability of a stride-level controller (``stride_action(z)``; a controller
    without it is passive) against the relative start size r, on the *stride* map of
    PassiveBoundStride-v1 (the one stride map, rtol 1e-10), from z* + r |z*| xi with ``n_dirs``
    directions of seed ``seed`` (disjoint from margins' seed-12345 directions), around the
    closed loop's own cycle z_cl (``settle`` strides from z*; as margins, starts at
    z_cl + r |z*| xi). Returned: within ``tol`` (SI, max-abs) of z_cl in ``strides`` strides
    without a fall. ``effort``: mean |tau| over a stride of the cycle [N m].
    A validation curve, cheaper than `bound_env.analysis.margins` and no substitute for it."""
    from bound_env.stride_task import StrideTask

    task = StrideTask(gait=gait, basis="windows", K=getattr(getattr(ctrl, "basis", None), "K", 4))
    act = getattr(ctrl, "stride_action", None)
    z_ref = task.z_ref
    u = np.random.default_rng(seed).standard_normal((n_dirs, 6))
    dirs = u / np.max(np.abs(u), axis=1, keepdims=True)
    taus_of = (
        (lambda z: task.basis.torques(act(z), task.max_torque))
        if act is not None
        else (lambda z: np.zeros(task.basis.phi.shape[0]))
    )
    z_cl, effort = z_ref.copy(), 0.0  # the closed loop's own cycle, by iteration from z*
    for _ in range(settle):
        o = task.sim.run_torques(z_cl, taus_of(z_cl))
        if o.z1 is None:
            return {
                "sizes": list(sizes),
                "p_return": [0.0] * len(sizes),
                "n_dirs": n_dirs,
                "seed": seed,
                "r50": 0.0,
                "failure_on_cycle": o.failure,
            }
        z_cl, effort = o.z1, o.effort
    out = []
    for r in sizes:
        ok = 0
        for xi in dirs:
            z = z_cl + r * np.abs(z_ref) * xi
            for _ in range(strides):
                o = task.sim.run_torques(z, taus_of(z))
                if o.z1 is None:
                    break
                z = o.z1
                if np.max(np.abs(z - z_cl)) < tol:
                    ok += 1
                    break
        out.append(ok / n_dirs)
    return {
        "sizes": list(sizes),
        "p_return": out,
        "n_dirs": n_dirs,
        "seed": seed,
        "r50": r50_of(sizes, out),
        "effort": effort,
        "fixed_point_shift": (z_cl - z_ref).tolist(),
    }


def r50_of(sizes, p) -> float:
    """Largest size up to which the return rate stays >= 0.5, linearly interpolated at the
    first crossing (0 if the first size is already below 0.5)."""
    if not p or p[0] < 0.5:
        return 0.0
    for i in range(1, len(p)):
        if p[i] < 0.5:
            f = (p[i - 1] - 0.5) / (p[i - 1] - p[i])
            return float(sizes[i - 1] + f * (sizes[i] - sizes[i - 1]))
    return float(sizes[-1])


def main(argv=None, *, load_controller) -> int:
    """``python -m agents.stride POLICY [POLICY ...]``: the validation curve as JSON lines."""
    # load_controller: `agents.policy.load_controller`, given by the script block below
    import argparse

    p = argparse.ArgumentParser(prog="python -m agents.stride", description=main.__doc__)
    p.add_argument("policies", nargs="+", help="passive, lqr, a spec .yaml or a policy dir")
    p.add_argument("--n-dirs", type=int, default=64)
    p.add_argument("--seed", type=int, default=VALIDATION_SEED)
    args = p.parse_args(argv)
    for path in args.policies:
        try:
            ctrl = load_controller(path)
        except (FileNotFoundError, ValueError) as e:
            print(f"error: {e}", file=sys.stderr)
            return 2
        r = stride_curve(ctrl, n_dirs=args.n_dirs, seed=args.seed)
        print(json.dumps({"policy": str(path), **r}), flush=True)
    return 0


# python -m agents.stride: the file runs as the module __main__ (never as agents.stride), which
# takes `agents.policy.load_controller` from above (agents.policy loads stride policies with
# `load_stride_policy`, so agents.stride itself never imports it)
if __name__ == "__main__":
    from agents.policy import load_controller

    raise SystemExit(main(load_controller=load_controller))
