"""Hyperparameter files in rl-zoo3's format, read and pre-processed the way rl-zoo3 does it.

A file maps an environment id to its hyperparameters (``configs/ppo.yaml``)::

    PassiveBound-v0:
      n_envs: 2
      n_timesteps: !!float 1e6
      policy: MlpPolicy
      normalize: "dict(norm_obs=True, norm_reward=True)"
      learning_rate: lin_3e-4            # rl-zoo3's linear schedule
      policy_kwargs: "dict(net_arch=dict(pi=[64, 64], vf=[64, 64]), activation_fn=nn.Tanh)"
      env_wrapper:
        - agents.common.wrappers.PerturbedStarts: {noise_scale: 1.0}
      callback:
        - agents.training.train.NoiseCurriculumCallback: {start: 0.5, end: 3.0}
      env_kwargs: {max_torque: 40.0}
      ...                                # every other key goes to the PPO constructor

Keys that are not constructor arguments of the algorithm, as in rl-zoo3: ``n_envs``,
``n_timesteps``, ``normalize``, ``env_wrapper``, ``callback``, ``frame_stack`` (unsupported
here), plus ``env_kwargs`` (keyword arguments of ``gymnasium.make``; rl-zoo3 takes them from
its ``--env-kwargs`` option).
"""

from __future__ import annotations

import copy
import importlib
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from bound_env.files.resources import configs_dir

CONFIG_DIR = configs_dir()  # the repository's configs/, or the wheel's copy (package data)
DEFAULT_CONFIG = CONFIG_DIR / "ppo.yaml"
DEFAULT_ENV_ID = "PassiveBound-v0"
# Keys of a section that are not PPO constructor arguments.
_NON_ALGO_KEYS = ("n_envs", "n_timesteps", "normalize", "env_wrapper", "callback", "env_kwargs")


def config_names() -> list[str]:
    """Names of the shipped hyperparameter files (``configs/*.yaml``: ``ppo``, ``ppo-stride``)."""
    return sorted(p.stem for p in CONFIG_DIR.glob("*.yaml"))


def resolve_config_path(path: str | Path) -> Path:
    """A config file's path, or the name of a shipped one (``ppo-stride`` or
    ``ppo-stride.yaml``), read from the repository's ``configs/`` or the wheel's copy."""
    p = Path(path)
    if p.is_file():
        return p
    if p.parent == Path(".") and p.suffix in ("", ".yaml"):
        cand = CONFIG_DIR / f"{p.stem}.yaml"
        if cand.is_file():
            return cand
    if p.exists():
        raise ValueError(f"config {str(path)!r} is not a file")
    raise FileNotFoundError(
        f"no config file {str(path)!r} (give a path or a shipped name: {', '.join(config_names())})"
    )


def read_config_file(path: str | Path) -> dict:
    """The whole YAML file: {env_id: hyperparameters}; ``path`` may be a shipped name."""
    path = resolve_config_path(path)
    try:
        data = yaml.safe_load(path.read_text())
    except (yaml.YAMLError, UnicodeDecodeError) as e:
        where = getattr(e, "problem_mark", None)
        at = f" at line {where.line + 1}" if where is not None else ""
        problem = getattr(e, "problem", None) or type(e).__name__
        raise ValueError(f"config file {path}: not valid YAML{at} ({problem})") from None
    if not isinstance(data, dict):
        raise ValueError(f"{path}: expected a mapping of environment ids to hyperparameters")
    return data


def default_env_id(path: str | Path) -> str:
    """The env id ``train`` uses when none is given: the file's only section (``ppo-stride``:
    ``PassiveBoundStride-v1``), the newest version when every section is one env's
    (``ppo-rescue``: ``PassiveBoundRescue-v1``), else `DEFAULT_ENV_ID` (``ppo``)."""
    data = read_config_file(path)
    sections = [k for k, v in data.items() if isinstance(v, dict)]
    families = {s.rsplit("-v", 1)[0] for s in sections}
    if len(families) == 1 and all(s.rsplit("-v", 1)[-1].isdigit() for s in sections):
        return max(sections, key=lambda s: int(s.rsplit("-v", 1)[1]))
    return DEFAULT_ENV_ID


def load_hyperparams(path: str | Path, env_id: str) -> dict:
    """The section of ``env_id`` (a deep copy), with a clear error naming the known ids."""
    data = read_config_file(path)
    if env_id not in data or not isinstance(data[env_id], dict):
        known = sorted(k for k, v in data.items() if isinstance(v, dict))
        raise ValueError(f"no hyperparameters for {env_id!r} in {path}; it has {known}")
    return copy.deepcopy(data[env_id])


def parse_set(text: str) -> tuple[list[str], Any]:
    """``"key=value"`` (``key`` may be dotted, e.g. ``env_kwargs.max_torque``); the value is
    parsed as YAML, so ``1e5``, ``true``, ``[1, 2]`` and ``lin_3e-4`` all work."""
    if "=" not in text:
        raise ValueError(f"--set {text!r} must look like KEY=VALUE")
    key, raw = text.split("=", 1)
    parts = [p for p in key.strip().split(".") if p]
    if not parts:
        raise ValueError(f"--set {text!r}: empty key")
    try:
        value = yaml.safe_load(raw)
    except yaml.YAMLError:
        value = raw
    if isinstance(value, str):  # YAML reads 1e5 as a string; numbers should be numbers
        try:
            value = float(value)
        except ValueError:
            pass
    return parts, value


def apply_sets(hp: dict, sets: list[str] | None) -> dict:
    """Apply ``--set`` overrides in order (dotted keys descend into dictionaries)."""
    for text in sets or []:
        parts, value = parse_set(text)
        node = hp
        for p in parts[:-1]:
            if p in node and not isinstance(node[p], dict):
                raise ValueError(f"--set {text!r}: {p!r} is not a mapping (set it whole)")
            node = node.setdefault(p, {})
        node[parts[-1]] = value
    return hp


def get_class_by_name(name: str):
    """``"package.module.Class"`` -> the class."""
    module_name, _, cls_name = name.rpartition(".")
    if not module_name:
        raise ValueError(f"{name!r} is not a dotted class path")
    try:
        module = importlib.import_module(module_name)
    except ModuleNotFoundError as e:
        raise ValueError(f"cannot import {module_name!r} for {name!r}: {e}") from None
    try:
        return getattr(module, cls_name)
    except AttributeError:
        raise ValueError(f"{module_name} has no {cls_name!r}") from None


def class_entries(value) -> list[tuple[str, dict]]:
    """rl-zoo3's list syntax: a class path, a {path: kwargs} dict, or a list of either."""
    if value is None:
        return []
    items = value if isinstance(value, list) else [value]
    out = []
    for item in items:
        if isinstance(item, str):
            out.append((item, {}))
        elif isinstance(item, dict) and len(item) == 1:
            ((name, kwargs),) = item.items()
            out.append((name, dict(kwargs or {})))
        else:
            raise ValueError(f"expected a class path or {{path: kwargs}}, got {item!r}")
    return out


def eval_kwargs_string(text: str) -> dict:
    """rl-zoo3's ``policy_kwargs: "dict(...)"`` strings, with ``nn`` (torch.nn) in scope."""
    from torch import nn

    try:
        value = eval(text, {"__builtins__": {}}, {"dict": dict, "nn": nn, "list": list})  # noqa: S307
    except Exception as e:  # noqa: BLE001 - any syntax or name error is the user's
        raise ValueError(f"cannot evaluate {text!r}: {e}") from None
    if not isinstance(value, dict):
        raise ValueError(f"{text!r} must evaluate to a dict")
    return value


def linear_schedule(initial_value: float):
    """rl-zoo3's ``lin_<value>``: decreases linearly from ``initial_value`` to 0."""
    initial_value = float(initial_value)

    def schedule(progress_remaining: float) -> float:
        return progress_remaining * initial_value

    return schedule


@dataclass
class TrainSpec:
    """A pre-processed section: what to build and what to pass to PPO."""

    n_envs: int
    n_timesteps: int
    env_kwargs: dict
    normalize_kwargs: dict | None  # None: no VecNormalize
    wrappers: list = field(default_factory=list)  # [(class, kwargs)], innermost first
    callbacks: list = field(default_factory=list)  # [(class, kwargs)]
    algo_kwargs: dict = field(default_factory=dict)

    def wrap(self, env):
        """Apply the ``env_wrapper`` chain to one environment."""
        for cls, kwargs in self.wrappers:
            env = cls(env, **kwargs)
        return env


# the counts of a section: (lowest, highest) whole number
HP_COUNTS = {
    "n_envs": (1, 1024),
    "n_timesteps": (1, 10**12),
    "n_steps": (1, 10**8),
    "batch_size": (1, 10**8),
    "n_epochs": (1, 10**6),
}


def hp_count(hp: dict, key: str, default=None) -> int:
    """A hyperparameter that counts (`HP_COUNTS`): a whole number (``1e5`` and ``100000.0``
    too; not a bool, a list, text or a fraction) in its range; ValueError naming the key."""
    v = hp.get(key, default)
    lo, hi = HP_COUNTS[key]
    ok = not isinstance(v, bool) and isinstance(v, (int, float)) and math.isfinite(v)
    if not ok or v != int(v) or not lo <= v <= hi:
        raise ValueError(f"hyperparameter {key} must be a whole number in [{lo}, {hi}], got {v!r}")
    return int(v)


def hp_real(v, key: str) -> float:
    """A real hyperparameter (a learning rate, a clip range): a finite number > 0."""
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
        raise ValueError(f"hyperparameter {key} must be a finite number > 0, got {v!r}")
    return float(v)


def preprocess(hp: dict) -> TrainSpec:
    """Turn a section into a `TrainSpec` (schedules, normalization, classes), as rl-zoo3 does."""
    hp = copy.deepcopy(hp)
    if "frame_stack" in hp:
        raise ValueError("frame_stack is not supported (the PassiveBound observation is Markov)")
    if "n_timesteps" not in hp:
        raise ValueError("the hyperparameters need n_timesteps")
    n_envs = hp_count(hp, "n_envs", 1)
    n_timesteps = hp_count(hp, "n_timesteps")
    normalize = hp.get("normalize", False)
    normalize_kwargs = None
    if isinstance(normalize, str):
        normalize_kwargs = eval_kwargs_string(normalize)
    elif isinstance(normalize, dict):
        normalize_kwargs = dict(normalize)
    elif normalize:
        normalize_kwargs = {}
    if normalize_kwargs is not None and "gamma" in hp:
        normalize_kwargs["gamma"] = float(hp["gamma"])  # rl-zoo3 uses the algorithm's gamma
    env_kwargs = dict(hp.get("env_kwargs") or {})
    shaping, env_gamma = env_kwargs.get("shaping"), env_kwargs.get("gamma")
    if shaping and env_gamma is not None and "gamma" in hp and env_gamma != hp["gamma"]:
        # potential-based shaping keeps the optimal policy only at the learner's discount
        raise ValueError(
            f"gamma: {hp['gamma']!r}, but env_kwargs.gamma (the shaping's discount, shaping "
            f"{shaping!r}) is {env_gamma!r}: set both (--hp gamma=G --hp env_kwargs.gamma=G)"
        )
    wrappers = [(get_class_by_name(n), kw) for n, kw in class_entries(hp.get("env_wrapper"))]
    callbacks = [(get_class_by_name(n), kw) for n, kw in class_entries(hp.get("callback"))]
    algo = {k: v for k, v in hp.items() if k not in _NON_ALGO_KEYS}
    for key in ("learning_rate", "clip_range", "clip_range_vf"):
        v = algo.get(key)
        if isinstance(v, str):
            kind, _, value = v.partition("_")
            if kind != "lin":
                raise ValueError(f"{key}: only 'lin_<value>' schedules are known, got {v!r}")
            try:
                start = float(value)
            except ValueError:
                raise ValueError(f"{key}: 'lin_<value>' needs a number, got {v!r}") from None
            algo[key] = linear_schedule(hp_real(start, key))
        elif v is not None:
            algo[key] = hp_real(v, key)
    if isinstance(algo.get("policy"), str) and "." in algo["policy"]:  # a class path
        algo["policy"] = get_class_by_name(algo["policy"])
    if isinstance(algo.get("policy_kwargs"), str):
        algo["policy_kwargs"] = eval_kwargs_string(algo["policy_kwargs"])
    for key in ("n_steps", "batch_size", "n_epochs"):
        if key in algo:
            algo[key] = hp_count(algo, key)
    return TrainSpec(
        n_envs=n_envs,
        n_timesteps=n_timesteps,
        env_kwargs=env_kwargs,
        normalize_kwargs=normalize_kwargs,
        wrappers=wrappers,
        callbacks=callbacks,
        algo_kwargs=algo,
    )
