"""Learned stride-level spine control: residual RL on top of the stride LQR.

The policy acts once per stride on `PassiveBoundStride-v1` (one step = one apex-to-apex
stride; its action is the K coefficients u of the stride's spine-torque profile,
`bound_env.sim.stride_task`). Three rl-zoo3 ``env_wrapper`` entries (innermost first) turn that
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

The trained policy as a controller of the step env is `agents.runtime.stride_policy`; its cheap
validation curve on the stride map `agents.experts.stride_validation` (``python -m
agents.experts.stride_validation``). The classes here keep their dotted paths
(``agents.runtime.stride.StrideControl``, ...): the configs and the pickled models name them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import gymnasium as gym
import numpy as np
from stable_baselines3.common.callbacks import BaseCallback

from bound_env import STRIDE_ENV_ID as STRIDE_ENV_ID  # the env of these wrappers
from bound_env.envs.rescue_env import sample_direction  # noqa: F401  (moved there; re-exported)

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


def __getattr__(name):  # agents.runtime.stride.AnchoredMlpPolicy, importable by its dotted path
    if name == "AnchoredMlpPolicy":
        return anchored_policy_class()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
