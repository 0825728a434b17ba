"""The NumPy controllers of evaluation: the zero action and a PPO actor (`MLPController`), and
the check that a trained controller runs on the gait it was trained on (`check_gait`).

They are built by `agents.runtime.policy.load_controller` (from a name or a saved policy) and run
without torch (in the worker processes of `agents.results.margins` too).
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field

import numpy as np

from ..common.mlp import mlp_forward


@dataclass
class ZeroController:
    """The passive gait: zero spine torque in every interval."""

    name: str = "passive"
    env_kwargs: dict = field(default_factory=dict)
    decides_at_apex = False  # zero torque whatever the apex: no decision to time

    def __call__(self, obs: np.ndarray) -> float:
        return 0.0

    def batch(self, obs: np.ndarray) -> np.ndarray:
        """Actions for a batch of observations (one row each)."""
        return np.zeros(len(obs))

    def interval_actions(self, Z) -> np.ndarray:
        """Zero on every interval of every stride (the stride-controller protocol)."""
        return np.zeros((len(np.atleast_2d(Z)), 1))

    def fingerprint(self) -> str:
        return "passive"


@dataclass
class MLPController:
    """A PPO actor as NumPy: observation normalization, hidden layers, action layer, clip."""

    name: str
    layers: list  # [(W, b)] hidden layers, then the action layer
    activation: str
    obs_mean: np.ndarray | None = None  # VecNormalize statistics (None: no normalization)
    obs_var: np.ndarray | None = None
    epsilon: float = 1e-8
    clip_obs: float = 10.0
    env_kwargs: dict = field(default_factory=dict)
    obs_shape: tuple = ()
    seed: int | None = None
    obs_index: np.ndarray | None = None  # entries of the env's observation the policy reads

    def normalize(self, obs) -> np.ndarray:
        x = np.asarray(obs, dtype=np.float64)
        if self.obs_index is not None:
            x = x[self.obs_index]
        if self.obs_mean is None:
            return x
        return np.clip(
            (x - self.obs_mean) / np.sqrt(self.obs_var + self.epsilon),
            -self.clip_obs,
            self.clip_obs,
        )

    def __call__(self, obs: np.ndarray) -> float:
        out = mlp_forward(self.layers, self.normalize(obs), self.activation)
        return float(np.clip(out[0], -1.0, 1.0))

    def batch(self, obs: np.ndarray) -> np.ndarray:
        """Actions for a batch of observations (one row each), as ``__call__`` row by row (to
        rounding). Each row is computed alone (`mlp_forward` with ``exact_rows``): a row's
        action depends neither on the other rows nor on the machine's load."""
        x = np.asarray(obs, dtype=np.float64)
        if self.obs_index is not None:
            x = x[:, self.obs_index]
        if self.obs_mean is not None:
            x = np.clip(
                (x - self.obs_mean) / np.sqrt(self.obs_var + self.epsilon),
                -self.clip_obs,
                self.clip_obs,
            )
        out = mlp_forward(self.layers, x, self.activation, exact_rows=True)
        return np.clip(out[:, 0], -1.0, 1.0)

    def fingerprint(self) -> str:
        h = hashlib.sha256()
        for W, b in self.layers:
            h.update(np.ascontiguousarray(W).tobytes())
            h.update(np.ascontiguousarray(b).tobytes())
        if self.obs_index is not None:
            h.update(np.asarray(self.obs_index).tobytes())
        if self.obs_mean is not None:
            h.update(self.obs_mean.tobytes())
            h.update(self.obs_var.tobytes())
        h.update(repr(sorted(self.env_kwargs.items())).encode())
        # the activation and the normalization constants change the actions too
        h.update(repr((self.activation, self.epsilon, self.clip_obs)).encode())
        return h.hexdigest()[:16]


def same_gait(a, b) -> bool:
    """Whether two gait names/paths give the same parameters and reference apex state."""
    from bound_env.model.params import load_gait

    ga, gb = load_gait(a), load_gait(b)
    return ga.params == gb.params and np.array_equal(ga.z0, gb.z0)


def check_gait(controller, gait, force: bool = False) -> None:
    """ValueError when ``gait`` is not the gait ``controller`` was trained on (``force``
    allows it on purpose). Built-in controllers have no trained gait and take any."""
    trained = getattr(controller, "env_kwargs", {}).get("gait")
    if gait is None or trained is None or force or isinstance(controller, ZeroController):
        return
    if not same_gait(trained, gait):
        raise ValueError(
            f"policy {controller.name} was trained on gait {trained!r}, not "
            f"{str(gait)!r}; pass --force to evaluate it there on purpose"
        )
