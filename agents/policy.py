"""Controllers for evaluation: the zero action, or a trained PPO policy as plain NumPy.

A trained policy is a saved SB3 PPO model (``model.zip``), its ``VecNormalize`` statistics
(``vecnormalize.pkl``) and its run config (``config.yaml``, for the environment keyword
arguments it was trained with: ``max_torque``, ``dt``, ...). `load_controller` reads them once
(with torch) and returns an `MLPController`: the deterministic action
``clip(action_net(policy_net(normalize(obs))), -1, 1)``, exactly what
``model.predict(obs, deterministic=True)`` returns after ``VecNormalize.normalize_obs``, but
evaluated with NumPy in float64 (~10 us instead of ~150 us per call), picklable, and free of
torch in the worker processes of `agents.margins`.
"""

from __future__ import annotations

import hashlib
import pickle
from collections.abc import Callable
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

import numpy as np
import yaml

# Environment keyword arguments that shape the dynamics, the observation or the action; the
# evaluation environment takes these from the policy's run config (reward weights and start
# noise do not matter for evaluation).
DYNAMICS_KWARGS = ("gait", "gait_overrides", "dt", "max_torque", "apex_scales",
                   "exclude_current_positions_from_observation")
_ACTIVATIONS = {
    "Tanh": np.tanh,
    "ReLU": lambda x: np.maximum(x, 0.0),
    "ELU": lambda x: np.where(x > 0, x, np.expm1(np.minimum(x, 0.0))),
    "Identity": lambda x: x,
}


@dataclass
class ZeroController:
    """The passive gait: zero spine torque in every interval."""

    name: str = "passive"
    env_kwargs: dict = field(default_factory=dict)

    def __call__(self, obs: np.ndarray) -> float:
        return 0.0

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
        return np.clip((x - self.obs_mean) / np.sqrt(self.obs_var + self.epsilon),
                       -self.clip_obs, self.clip_obs)

    def __call__(self, obs: np.ndarray) -> float:
        act = _ACTIVATIONS[self.activation]
        x = self.normalize(obs)
        for W, b in self.layers[:-1]:
            x = act(W @ x + b)
        W, b = self.layers[-1]
        return float(np.clip((W @ x + b)[0], -1.0, 1.0))

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
        return h.hexdigest()[:16]


# The shipped policies, package data of `agents` (``agents/policies/<name>/``), read with
# importlib.resources so that an installed wheel finds them too.
SHIPPED_DIR = Path(str(resources.files("agents") / "policies"))

# Built-in controllers by name: name -> (factory(gait) -> controller, one-line description).
# ``--policy NAME`` in ``margins``, ``rollout`` and ``compare`` looks names up here first, then
# among the shipped policies, and only then reads NAME as a path. Modules that add classical
# controllers call `register_controller`.
CONTROLLERS: dict[str, tuple[Callable, str]] = {}


def register_controller(name: str, factory: Callable, description: str) -> None:
    """Make ``--policy name`` build ``factory(gait=...)`` (gait: name or path, or None)."""
    CONTROLLERS[name] = (factory, description)


register_controller("passive", lambda gait=None: ZeroController(), "zero spine torque")


def shipped_policies() -> dict[str, Path]:
    """{name: folder} of the policies shipped in ``agents/policies/``."""
    if not SHIPPED_DIR.is_dir():
        return {}
    return {p.name: p for p in sorted(SHIPPED_DIR.iterdir()) if (p / "model.zip").is_file()}


def policy_names() -> list[str]:
    """Every name ``--policy`` accepts besides a path."""
    return list(CONTROLLERS) + [n for n in shipped_policies() if n not in CONTROLLERS]


def resolve_policy(spec: str | Path) -> str | Path:
    """A built-in controller's name (returned as is), a shipped policy's folder, or a path."""
    text = str(spec)
    if text in CONTROLLERS:
        return text
    shipped = shipped_policies()
    if text in shipped:
        return shipped[text]
    p = Path(spec)
    if not p.exists():
        raise FileNotFoundError(
            f"policy {text!r} does not exist (give a name: {', '.join(policy_names())}; or a "
            "run or policy directory with model.zip, or a model .zip)")
    return p


def resolve_policy_files(path: str | Path) -> tuple[Path, Path | None, Path | None]:
    """(model zip, vecnormalize pkl or None, config yaml or None) for a policy directory
    (``model.zip`` inside) or a model zip (its siblings)."""
    p = Path(path)
    if p.is_dir():
        model = p / "model.zip"
        if not model.is_file():
            zips = sorted(p.glob("*.zip"))
            if len(zips) != 1:
                raise FileNotFoundError(f"no model.zip in policy directory {p}")
            model = zips[0]
    elif p.is_file():
        model = p
    else:
        raise FileNotFoundError(f"policy {str(path)!r} does not exist (give a run or policy "
                                "directory with model.zip, a model .zip, or 'passive')")
    folder = model.parent
    vecnorm = folder / "vecnormalize.pkl"
    config = folder / "config.yaml"
    return model, (vecnorm if vecnorm.is_file() else None), (config if config.is_file() else None)


def read_run_config(config: Path | None) -> tuple[dict, int | None, list]:
    """(environment kwargs that matter for evaluation, seed, env_wrapper entries) from a
    run's config.yaml."""
    if config is None:
        return {}, None, []
    data = yaml.safe_load(config.read_text()) or {}
    run = data.get("run") or {}
    env_id = run.get("env_id")
    section = data.get(env_id) if env_id else None
    if section is None:  # a plain rl-zoo3 file with one section
        sections = [v for k, v in data.items() if isinstance(v, dict) and k != "run"]
        section = sections[0] if len(sections) == 1 else {}
    env_kwargs = dict(section.get("env_kwargs") or {})
    if env_id and env_id != "PassiveBound-v0":
        import gymnasium as gym

        import agents  # noqa: F401 - registers PassiveBoundLiteral-v0

        env_kwargs = {**(gym.spec(env_id).kwargs or {}), **env_kwargs}
    kept = {k: v for k, v in env_kwargs.items() if k in DYNAMICS_KWARGS}
    return kept, run.get("seed"), section.get("env_wrapper") or []


def load_controller(path: str | Path, gait: str | Path | None = None):
    """A controller from a name (`policy_names`) or a saved policy (see the module docstring).

    ``gait`` is passed to built-in controllers that need one (a trained policy takes its own
    from its config). Raises FileNotFoundError for a missing path and ValueError for a file
    that is not a PPO MLP policy for PassiveBound's observation space.
    """
    path = resolve_policy(path)
    if isinstance(path, str):
        return CONTROLLERS[path][0](gait=gait)
    model_path, vecnorm_path, config_path = resolve_policy_files(path)
    from stable_baselines3 import PPO

    try:
        model = PPO.load(str(model_path), device="cpu")
    except Exception as e:  # noqa: BLE001 - a corrupt or foreign zip is the user's error
        raise ValueError(f"cannot load {model_path} as an SB3 PPO model: {e}") from None
    env_kwargs, seed, wrappers = read_run_config(config_path)
    obs_index = check_spaces(model, env_kwargs, wrappers, model_path)
    layers, activation = _extract_actor(model, model_path)
    ctrl = MLPController(name=str(path), layers=layers, activation=activation,
                         env_kwargs=env_kwargs, obs_shape=tuple(model.observation_space.shape),
                         seed=seed, obs_index=obs_index)
    if vecnorm_path is not None:
        with vecnorm_path.open("rb") as f:
            vn = pickle.load(f)
        if getattr(vn, "norm_obs", False):
            if tuple(vn.obs_rms.mean.shape) != ctrl.obs_shape:
                raise ValueError(f"{vecnorm_path}: statistics for observations of shape "
                                 f"{vn.obs_rms.mean.shape}, the model expects {ctrl.obs_shape}")
            ctrl.obs_mean = np.asarray(vn.obs_rms.mean, dtype=np.float64)
            ctrl.obs_var = np.asarray(vn.obs_rms.var, dtype=np.float64)
            ctrl.epsilon = float(vn.epsilon)
            ctrl.clip_obs = float(vn.clip_obs)
    return ctrl


def check_spaces(model, env_kwargs: dict, wrappers, model_path: Path) -> np.ndarray | None:
    """ValueError unless the model's spaces are those of PassiveBound with ``env_kwargs``
    (through the run's `agents.wrappers.ObservationFilter`, if any); returns its indices."""
    import gymnasium as gym

    import bound_env

    from .wrappers import observation_index

    gym.register_envs(bound_env)
    env = gym.make("PassiveBound-v0", **env_kwargs).unwrapped
    want_obs, want_act = env.observation_space, env.action_space
    index = observation_index(wrappers, env.task.obs_names)
    env.close()
    if index is not None:
        want_obs = gym.spaces.Box(want_obs.low[index], want_obs.high[index], dtype=want_obs.dtype)
    obs, act = model.observation_space, model.action_space
    # shapes decide; bounds are not compared (an MLP policy does not read them, and the
    # environment may tighten them without changing what an entry means)
    if not isinstance(obs, gym.spaces.Box) or obs.shape != want_obs.shape:
        got = obs.shape if isinstance(obs, gym.spaces.Box) else obs
        raise ValueError(
            f"policy {model_path} was trained for an observation space of shape {got}, but "
            f"PassiveBound (with {env_kwargs or 'default arguments'}"
            f"{', through its ObservationFilter' if index is not None else ''}) gives "
            f"{want_obs.shape}; is its run's config.yaml beside it?"
        )
    if not isinstance(act, gym.spaces.Box) or act.shape != want_act.shape:
        raise ValueError(f"policy {model_path} acts in {act}, PassiveBound expects {want_act}")
    return index


def _extract_actor(model, model_path: Path) -> tuple[list, str]:
    """Hidden layers of ``mlp_extractor.policy_net`` plus ``action_net`` as NumPy arrays."""
    from torch import nn

    policy = model.policy
    if type(policy.pi_features_extractor).__name__ != "FlattenExtractor":
        raise ValueError(f"{model_path}: only MLP policies on a flat observation are supported")
    layers, activation = [], "Identity"
    for m in policy.mlp_extractor.policy_net:
        if isinstance(m, nn.Linear):
            layers.append((m.weight.detach().double().numpy().copy(),
                           m.bias.detach().double().numpy().copy()))
        elif type(m).__name__ in _ACTIVATIONS:
            activation = type(m).__name__
        else:
            raise ValueError(f"{model_path}: unsupported layer {m} in the policy network")
    an = policy.action_net
    layers.append((an.weight.detach().double().numpy().copy(),
                   an.bias.detach().double().numpy().copy()))
    if getattr(policy, "squash_output", False):
        raise ValueError(f"{model_path}: squashed (gSDE) policies are not supported")
    return layers, activation
