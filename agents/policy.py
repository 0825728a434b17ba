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
import sys
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import partial
from importlib import resources
from pathlib import Path

import numpy as np
import yaml

from bound_env.resources import controllers_dir

from .mlp import extract_actor, mlp_forward

# Environment keyword arguments that shape the dynamics, the observation or the action; the
# evaluation environment takes these from the policy's run config (reward weights and start
# noise do not matter for evaluation).
DYNAMICS_KWARGS = (
    "gait",
    "gait_overrides",
    "dt",
    "max_torque",
    "apex_scales",
    "exclude_current_positions_from_observation",
)


@dataclass
class ZeroController:
    """The passive gait: zero spine torque in every interval."""

    name: str = "passive"
    env_kwargs: dict = field(default_factory=dict)

    def __call__(self, obs: np.ndarray) -> float:
        return 0.0

    def batch(self, obs: np.ndarray) -> np.ndarray:
        """Actions for a batch of observations (one row each)."""
        return np.zeros(len(obs))

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


def _classical(name: str, gait=None):
    """A classical controller of `bound_env.control` (a name or a spec .yaml), designed for
    ``gait`` (default: the spec's)."""
    from bound_env.control import load_controller as load_classical

    return load_classical(name, gait=None if gait is None else str(gait))


# the classical stride-level controllers: every spec in configs/controllers/ (the wheel's copy
# when installed), by its file name
_CLASSICAL_WHAT = {
    "lqr": "stride-to-stride LQR on the linearized stride map",
    "deadbeat": "one-stride deadbeat on the linearized stride map",
    "damping": "extra spine damping tau = -c theta2dot",
}
for _name in list(_CLASSICAL_WHAT) + sorted(
    p.stem for p in controllers_dir().glob("*.yaml") if p.stem not in _CLASSICAL_WHAT
):
    register_controller(
        _name, partial(_classical, _name), _CLASSICAL_WHAT.get(_name, f"controller spec {_name}")
    )


def shipped_policies() -> dict[str, Path]:
    """{name: folder} of the policies shipped in ``agents/policies/``: ``<name>/`` (e.g.
    ``default``) and one level of groups, ``<group>/<name>/`` named ``group/name`` (e.g.
    ``stride-residual/s0``, one folder per training seed)."""
    if not SHIPPED_DIR.is_dir():
        return {}
    out = {}

    def is_policy(folder: Path) -> bool:  # a PPO model, or a distilled student (agents.distill)
        return (folder / "model.zip").is_file() or (folder / "choice.npz").is_file()

    for p in sorted(SHIPPED_DIR.iterdir()):
        if is_policy(p):
            out[p.name] = p
        elif p.is_dir():
            for q in sorted(p.iterdir()):
                if is_policy(q):
                    out[f"{p.name}/{q.name}"] = q
    return out


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
            "run or policy directory with model.zip, or a model .zip)"
        )
    return p


_INFERENCE_ONLY = {
    "learning_rate": 0.0,
    "lr_schedule": lambda _: 0.0,
    "clip_range": lambda _: 0.0,
}  # replaces training-only pickled objects
FINGERPRINT_FILE = "fingerprint.json"  # sha256 of the model and its statistics, as one unit
# Files a fingerprint also covers when they are present: the run config (it sets max_torque, dt,
# the gait, the observation filter) and a residual policy's base controller. A fingerprint
# written before they were covered has no entry for them and is read as before.
FINGERPRINTED_SETTINGS = ("config.yaml", "base.json")


@dataclass
class PolicyFiles:
    """The files of a saved policy (see `find_policy_files`)."""

    model: Path
    vecnormalize: Path | None
    config: Path | None
    layout: str = "bound_env"  # or "rl-zoo3"
    env_id: str | None = None  # rl-zoo3: the run's env id (its params folder's name)

    @property
    def fingerprint(self) -> Path:
        return self.model.parent / FINGERPRINT_FILE


def _zoo_params_folder(folder: Path) -> Path | None:
    """The params folder (``<env id>/`` with ``config.yml``) of an rl-zoo3 run folder."""
    subs = [d for d in sorted(folder.iterdir()) if d.is_dir() and (d / "config.yml").is_file()]
    return subs[0] if len(subs) == 1 else None


def find_policy_files(path: str | Path) -> PolicyFiles:
    """The files of a policy given as a folder or a model zip.

    - this project's layout (``bound-env train`` runs, ``--export`` folders): ``model.zip``,
      ``vecnormalize.pkl`` and ``config.yaml`` side by side;
    - rl-zoo3's layout (``logs/ppo/<env id>_<n>/``): the model ``<env id>.zip`` (or
      ``best_model.zip``), and ``<env id>/config.yml`` + ``<env id>/vecnormalize.pkl`` in a
      subfolder; the run folder, its params subfolder or the model zip may be given.
    """
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(
            f"policy {str(path)!r} does not exist (give a run or policy "
            "directory with model.zip, a model .zip, or 'passive')"
        )
    folder = p if p.is_dir() else p.parent
    if (folder / "config.yml").is_file() and not (folder / "model.zip").is_file():
        folder = folder.parent  # the params folder of an rl-zoo3 run was given
        p = folder if p.is_dir() else p
    zoo = _zoo_params_folder(folder)
    if zoo is not None and not (folder / "config.yaml").is_file():
        if p.is_file():
            model = p
        else:
            cands = [folder / f"{zoo.name}.zip", folder / "best_model.zip"]
            model = next((c for c in cands if c.is_file()), None)
            if model is None:
                raise FileNotFoundError(
                    f"rl-zoo3 run folder {folder} has no {cands[0].name} or best_model.zip"
                )
        vn = zoo / "vecnormalize.pkl"
        return PolicyFiles(
            model, vn if vn.is_file() else None, zoo / "config.yml", "rl-zoo3", zoo.name
        )
    if p.is_dir():
        model = p / "model.zip"
        if not model.is_file():
            zips = sorted(p.glob("*.zip"))
            if len(zips) != 1:
                raise FileNotFoundError(f"no model.zip in policy directory {p}")
            model = zips[0]
    else:
        model = p
    vn, cfg = folder / "vecnormalize.pkl", folder / "config.yaml"
    return PolicyFiles(model, vn if vn.is_file() else None, cfg if cfg.is_file() else None)


def resolve_policy_files(path: str | Path) -> tuple[Path, Path | None, Path | None]:
    """(model zip, vecnormalize pkl or None, config or None): `find_policy_files` as a tuple."""
    f = find_policy_files(path)
    return f.model, f.vecnormalize, f.config


class _ZooLoader(yaml.SafeLoader):
    """YAML safe loading plus the one Python tag rl-zoo3 writes (an OrderedDict as pairs)."""


_ZooLoader.add_constructor(
    "tag:yaml.org,2002:python/object/apply:collections.OrderedDict",
    lambda loader, node: dict(
        loader.construct_sequence(node.value[0], deep=True)
        if isinstance(node, yaml.SequenceNode)
        else loader.construct_mapping(node, deep=True).get("args", [[]])[0]
    ),
)


def _read_yaml(path: Path, loader=yaml.SafeLoader):
    try:
        data = yaml.load(path.read_text(), Loader=loader)  # noqa: S506 - safe loaders only
    except (yaml.YAMLError, UnicodeDecodeError) as e:
        msg = str(e).splitlines()[0] if str(e) else type(e).__name__
        raise ValueError(f"{path}: not a readable YAML file ({msg})") from None
    if not isinstance(data, dict):
        raise ValueError(f"{path}: expected a mapping, got {type(data).__name__}")
    return data


def read_policy_section(files: PolicyFiles) -> tuple[dict, str, int | None]:
    """(hyperparameter section, env id, seed) of a policy's config; ({}, default id, None)
    without one."""
    if files.config is None:
        return {}, "PassiveBound-v0", None
    if files.layout == "rl-zoo3":
        return _read_yaml(files.config, _ZooLoader), files.env_id or "PassiveBound-v0", None
    data = _read_yaml(files.config)
    run = data.get("run") or {}
    env_id = run.get("env_id")
    section = data.get(env_id) if env_id else None
    if section is None:  # a plain rl-zoo3-style file with one section
        sections = {k: v for k, v in data.items() if isinstance(v, dict) and k != "run"}
        if len(sections) == 1:
            env_id, section = next(iter(sections.items()))
        else:
            section = {}
    if not isinstance(section, dict):
        raise ValueError(f"{files.config}: section {env_id!r} is not a mapping")
    return section, env_id or "PassiveBound-v0", run.get("seed")


def section_env_kwargs(section: dict, env_id: str) -> dict:
    """The environment kwargs that matter for evaluation (`DYNAMICS_KWARGS`): those of the
    registered env id, then the section's ``env_kwargs``."""
    env_kwargs = section.get("env_kwargs") or {}
    if not isinstance(env_kwargs, dict):
        raise ValueError(f"env_kwargs must be a mapping, got {env_kwargs!r}")
    if env_id != "PassiveBound-v0":
        import gymnasium as gym

        import bound_env  # noqa: F401 - registers the env ids

        try:
            spec_kwargs = gym.spec(env_id).kwargs or {}
        except gym.error.Error:
            raise ValueError(
                f"the policy was trained on {env_id!r}, which is not a registered environment"
            ) from None
        env_kwargs = {**spec_kwargs, **env_kwargs}
    return {k: v for k, v in env_kwargs.items() if k in DYNAMICS_KWARGS}


def read_run_config(config: Path | None) -> tuple[dict, int | None, list]:
    """(environment kwargs that matter for evaluation, seed, env_wrapper entries) from a
    run's config.yaml."""
    if config is None:
        return {}, None, []
    layout = "rl-zoo3" if config.name == "config.yml" else "bound_env"
    files = PolicyFiles(config, None, config, layout, config.parent.name)
    section, env_id, seed = read_policy_section(files)
    return section_env_kwargs(section, env_id), seed, section.get("env_wrapper") or []


def file_sha256(path: Path) -> str:
    h = hashlib.sha256()
    with Path(path).open("rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def write_fingerprint(folder: str | Path, **extra) -> Path:
    """Bind the files of the policy in ``folder`` together: the sha256 of ``model.zip``,
    ``vecnormalize.pkl`` and, when present, ``config.yaml`` and ``base.json``
    (`FINGERPRINTED_SETTINGS`) in ``fingerprint.json`` (written atomically), checked by
    `check_policy_files`."""
    import json

    from bound_env.cache import atomic_write

    folder = Path(folder)
    data = {"model.zip": file_sha256(folder / "model.zip")}
    for name in ("vecnormalize.pkl", *FINGERPRINTED_SETTINGS):
        if (folder / name).is_file():
            data[name] = file_sha256(folder / name)
    data.update(extra)
    return atomic_write(folder / FINGERPRINT_FILE, json.dumps(data, indent=2) + "\n")


def check_policy_files(files: PolicyFiles, section: dict, force: bool = False) -> list[str]:
    """ValueError for a policy whose evaluation would be silently wrong; returns warnings.

    - no config: the env kwargs it was trained with (``max_torque``, ``dt``, wrappers) are
      unknown (``force`` evaluates it with the env's defaults);
    - trained with ``normalize`` but no ``vecnormalize.pkl`` beside the model;
    - a ``fingerprint.json`` (written at export and at the end of training) that does not match
      the model or the statistics: they belong to different policies;
    - a ``config.yaml`` (or ``base.json``) that does not match the fingerprint: edited or cut
      short since the policy was saved (a config cut before ``env_kwargs`` still parses, and
      would evaluate the policy at the env's default max_torque); ``force`` evaluates it as it
      is, with a warning.
    """
    warnings = []
    if files.config is None:
        msg = (
            f"policy {files.model}: no config.yaml beside it, so the environment it was "
            "trained on (max_torque, dt, observation filter) is unknown"
        )
        if not force:
            raise ValueError(msg + "; pass --force to evaluate it with the env's defaults")
        warnings.append(msg)
    if section.get("normalize") and files.vecnormalize is None:
        where = files.config.parent if files.config is not None else files.model.parent
        raise ValueError(
            f"policy {files.model} was trained with normalize="
            f"{section['normalize']!r} but {where} has no vecnormalize.pkl"
        )
    fp = files.fingerprint
    if fp.is_file():
        import json

        try:
            want = json.loads(fp.read_text())
        except (json.JSONDecodeError, UnicodeDecodeError):
            raise ValueError(f"{fp}: not a readable JSON file") from None
        pairs = [("model.zip", files.model), ("vecnormalize.pkl", files.vecnormalize)]
        for key, path in pairs:
            if key in want and (path is None or file_sha256(path) != want[key]):
                raise ValueError(
                    f"{path or key} does not match {fp} (sha256): the model and "
                    "its normalization statistics belong to different policies"
                )
        for key in FINGERPRINTED_SETTINGS:
            path = files.model.parent / key
            if key in want and path.is_file() and file_sha256(path) != want[key]:
                msg = (
                    f"{path} does not match {fp} (sha256): it was changed or cut short "
                    "after the policy was saved"
                )
                if not force:
                    raise ValueError(
                        msg + "; pass --force (margins, rollout, basin-map) to evaluate the "
                        "policy with it as it is"
                    )
                warnings.append(msg)
    elif files.vecnormalize is not None and files.layout == "bound_env":
        warnings.append(
            f"{files.model.parent}: no {FINGERPRINT_FILE}, so it cannot be checked "
            "that vecnormalize.pkl belongs to this model"
        )
    return warnings


def same_gait(a, b) -> bool:
    """Whether two gait names/paths give the same parameters and reference apex state."""
    from bound_env.params import load_gait

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


def load_controller(path: str | Path, gait: str | Path | None = None, force: bool = False):
    """A controller from a name (`policy_names`) or a saved policy (see the module docstring).

    ``gait`` is passed to built-in controllers that need one; a trained policy takes its own
    from its config and refuses another one unless ``force`` (`check_gait`). Raises
    FileNotFoundError for a missing path and ValueError for a file that is not a PPO MLP
    policy for PassiveBound's observation space, or would be evaluated wrongly
    (`check_policy_files`).
    """
    if Path(str(path)).suffix in (".yaml", ".yml"):  # a classical controller's spec file
        return _classical(str(path), gait)
    path = resolve_policy(path)
    if isinstance(path, str):
        return CONTROLLERS[path][0](gait=gait)
    if Path(path).is_dir() and (Path(path) / "choice.npz").is_file():
        from .distill import load_choice_policy  # a distilled student (agents/distill.py)

        return load_choice_policy(path, gait=gait, force=force)
    files = find_policy_files(path)
    if files.config is not None and read_policy_section(files)[1] == "PassiveBoundStride-v0":
        from .stride import load_stride_policy  # a stride-level policy (agents/stride.py)

        return load_stride_policy(path, gait=gait, force=force)
    model_path, vecnorm_path = files.model, files.vecnormalize
    from stable_baselines3 import PPO

    try:
        # schedules are not needed to act, and rl-zoo3 pickles its own schedule classes
        model = PPO.load(str(model_path), device="cpu", custom_objects=_INFERENCE_ONLY)
    except Exception as e:  # noqa: BLE001 - a corrupt or foreign zip is the user's error
        raise ValueError(f"cannot load {model_path} as an SB3 PPO model: {e}") from None
    section, env_id, seed = read_policy_section(files)
    env_kwargs = section_env_kwargs(section, env_id)
    wrappers = section.get("env_wrapper") or []
    obs_index = check_spaces(model, env_kwargs, wrappers, model_path)
    for w in check_policy_files(files, section, force):
        print(f"warning: {w}", file=sys.stderr)
    layers, activation = extract_actor(model, model_path)
    ctrl = MLPController(
        name=str(path),
        layers=layers,
        activation=activation,
        env_kwargs=env_kwargs,
        obs_shape=tuple(model.observation_space.shape),
        seed=seed,
        obs_index=obs_index,
    )
    if vecnorm_path is not None:
        try:
            with vecnorm_path.open("rb") as f:
                vn = pickle.load(f)
        except Exception as e:  # noqa: BLE001 - a truncated or foreign pickle
            raise ValueError(
                f"cannot read {vecnorm_path} as VecNormalize statistics: {type(e).__name__}: {e}"
            ) from None
        if getattr(vn, "norm_obs", False):
            rms = getattr(vn, "obs_rms", None)
            if rms is None or tuple(np.shape(rms.mean)) != ctrl.obs_shape:
                raise ValueError(
                    f"{vecnorm_path}: statistics for observations of shape "
                    f"{np.shape(getattr(rms, 'mean', None))}, the model expects "
                    f"{ctrl.obs_shape}"
                )
            ctrl.obs_mean = np.asarray(rms.mean, dtype=np.float64)
            ctrl.obs_var = np.asarray(rms.var, dtype=np.float64)
            ctrl.epsilon = float(vn.epsilon)
            ctrl.clip_obs = float(vn.clip_obs)
    check_gait(ctrl, gait, force)
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
