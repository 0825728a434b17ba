"""Kind "step": a step-level PPO policy (SB3 ``model.zip``, ``vecnormalize.pkl``, ``config.yaml``).

Everything `agents.runtime.kinds.apex` leaves: a plain SB3 model, or one whose actor acts
through its run's controller wrapper (kind "residual", `agents.runtime.kinds.residual`). The
model is read once (with torch) and becomes an `MLPController`
(`agents.runtime.controllers`): NumPy inference, picklable, free of torch in the workers.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from ...common.mlp import checked_actor
from ...common.policy_files import (
    check_base_pin,
    check_policy_files,
    load_vecnormalize,
    policy_content_sha256,
    refuse_privileged,
    section_env_kwargs,
)
from ...common.schema import check_env_kwargs, check_obs_stats, read_fingerprint
from ..controllers import MLPController, check_gait
from .folder import PolicyFolder, resolve_policy

NAME = "step"

_INFERENCE_ONLY = {
    "learning_rate": 0.0,
    "lr_schedule": lambda _: 0.0,
    "clip_range": lambda _: 0.0,
}  # replaces training-only pickled objects


def check_env_id(env_id: str) -> str:
    """``env_id`` when a plain SB3 model can be evaluated on it (a registered control-interval
    env: ``PassiveBound-v0``/``-v1``, ``PassiveBoundLiteral-v0``/``-v1``), else ValueError."""
    from bound_env import ENV_KWARGS

    if env_id not in ENV_KWARGS:
        raise ValueError(
            f"--env-id {env_id!r}: a plain model.zip is evaluated on one of "
            f"{', '.join(ENV_KWARGS)} (a stride or rescue policy needs its run's config.yaml)"
        )
    return env_id


RECOGNISED_BY = ("any",)  # whatever the kinds before it leave


def load(folder: PolicyFolder, gait=None, force: bool = False, env_id: str | None = None):
    """The `MLPController` of a step-level PPO policy (through its controller wrapper, if its
    run has one): the checks of `agents.runtime.policy.load_controller`."""
    path = folder.path
    files = folder.files
    if files.config is not None:
        refuse_privileged(folder.section, files.config)
    trained_on = folder.env_id
    if trained_on is not None and trained_on.startswith("PassiveBoundRescue"):
        raise ValueError(
            f"policy {path} was trained on {trained_on} (one profile per stride from the "
            "rescue task's starts, read from its config.yaml), which margins, rollout, "
            "compare and load_policy do not evaluate; measure its returns with "
            f"scripts/rescue_eval.py {path}, or act in gym.make({trained_on!r}) with "
            "model.predict"
        )
    model_path, vecnorm_path = files.model, files.vecnormalize
    from stable_baselines3 import PPO

    try:
        # schedules are not needed to act, and rl-zoo3 pickles its own schedule classes
        model = PPO.load(str(model_path), device="cpu", custom_objects=_INFERENCE_ONLY)
    except Exception as e:  # noqa: BLE001 - a corrupt or foreign zip is the user's error
        raise ValueError(f"cannot load {model_path} as an SB3 PPO model: {e}") from None
    section, trained_on, seed = folder.run
    if env_id is not None and files.config is None:
        trained_on = env_id  # a plain SB3 model: the env id the user names
    elif env_id is not None and env_id != trained_on:
        raise ValueError(
            f"--env-id {env_id}: policy {path} was trained on {trained_on} ({files.config})"
        )
    env_kwargs = check_env_kwargs(section_env_kwargs(section, trained_on), str(files.config))
    wrappers = section.get("env_wrapper") or []
    residual = controller_wrapper(wrappers)
    if residual is None:
        obs_index = check_spaces(model, env_kwargs, wrappers, model_path)
    else:
        obs_index = None
    base = residual_base(section)
    pinned = [f"that base {base!r} is the controller it was trained over"] if base else []
    warnings = check_policy_files(files, section, force, env_given=env_id is not None, also=pinned)
    want = read_fingerprint(files.model.parent) if files.layout == "bound_env" else None
    if base is not None and want is not None:  # a residual's base: the one it was trained over
        sha = policy_content_sha256(resolve_policy(base))
        warnings += check_base_pin(files, want, base, sha, force)
    for w in warnings:
        print(f"warning: {w}", file=sys.stderr)
    layers, activation = checked_actor(model, model_path)
    ctrl = MLPController(
        name=str(path),
        layers=layers,
        activation=activation,
        env_kwargs=env_kwargs,
        obs_shape=tuple(model.observation_space.shape),
        seed=seed,
        obs_index=obs_index,
    )
    read_vecnormalize(ctrl, vecnorm_path)
    if residual is not None:  # e.g. agents.runtime.residual.ResidualOver: the actor acts through it
        cls, kwargs = residual
        ctrl = cls.policy_controller(ctrl, kwargs, model, model_path)
    check_gait(ctrl, gait, force)
    return ctrl


def residual_base(section: dict) -> str | None:
    """The base controller's name of a run whose actor acts through a controller wrapper
    (`controller_wrapper`: `agents.runtime.residual.ResidualOver`'s ``base``, by default
    ``"default"``), or None."""
    import inspect

    found = controller_wrapper(section.get("env_wrapper") or [])
    if found is None:
        return None
    cls, kwargs = found
    if "base" in kwargs:
        return kwargs["base"]
    param = inspect.signature(cls.__init__).parameters.get("base")
    return None if param is None else param.default


def controller_wrapper(env_wrappers) -> tuple | None:
    """(class, kwargs) of the run's ``env_wrapper`` through which its actor acts (a wrapper
    class with ``policy_controller``: `agents.runtime.residual.ResidualOver`), or None."""
    from ...common.config import class_entries, get_class_by_name

    found = []
    for name, kwargs in class_entries(env_wrappers):
        cls = get_class_by_name(name)
        if callable(getattr(cls, "policy_controller", None)):
            found.append((cls, dict(kwargs or {})))
    if len(found) > 1:
        raise ValueError(f"more than one controller wrapper in env_wrapper: {env_wrappers!r}")
    return found[0] if found else None


def read_vecnormalize(ctrl: MLPController, vecnorm_path: Path | None) -> None:
    """Set ``ctrl``'s observation normalization from a ``vecnormalize.pkl`` (if any)."""
    if vecnorm_path is not None:
        vn = load_vecnormalize(vecnorm_path)
        if getattr(vn, "norm_obs", False):
            rms = getattr(vn, "obs_rms", None)
            if rms is None or tuple(np.shape(rms.mean)) != ctrl.obs_shape:
                raise ValueError(
                    f"{vecnorm_path}: statistics for observations of shape "
                    f"{np.shape(getattr(rms, 'mean', None))}, the model expects "
                    f"{ctrl.obs_shape}"
                )
            stats = check_obs_stats(vn, str(vecnorm_path), ctrl.obs_shape)
            ctrl.obs_mean, ctrl.obs_var, ctrl.epsilon, ctrl.clip_obs = stats


def check_spaces(model, env_kwargs: dict, wrappers, model_path: Path) -> np.ndarray | None:
    """ValueError unless the model's spaces are those of PassiveBound with ``env_kwargs``
    (through the run's `agents.common.wrappers.ObservationFilter`, if any); returns its indices."""
    import gymnasium as gym

    import bound_env

    from ...common.wrappers import observation_index

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
