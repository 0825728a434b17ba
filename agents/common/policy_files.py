"""The files of a saved policy: where they are, what its run config says, and the fingerprint
that binds them together.

A trained PPO policy is a ``model.zip``, its ``VecNormalize`` statistics (``vecnormalize.pkl``)
and its run config (``config.yaml``: the environment it was trained on), in this project's
layout or in rl-zoo3's (`find_policy_files`). ``fingerprint.json`` holds the sha256 of the
model, the statistics and the settings files (`write_fingerprint`); `check_policy_files`
refuses a policy whose evaluation would be silently wrong. The loaders above it
(`agents.runtime.policy`, `agents.runtime.stride`, `agents.experts.distill`) read policies through
these functions.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import yaml

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
# the shipped policies, package data of `agents` (read with importlib.resources, so that an
# installed wheel finds them too); `agents.runtime.policy.SHIPPED_DIR`
SHIPPED = Path(str(resources.files("agents") / "policies"))
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


def refuse_privileged(section: dict, where) -> None:
    """ValueError (one line) when the run's ``env_wrapper`` handed the policy a privileged
    observation (`bound_env.envs.randomized.RandomizedPlant` with ``privileged_obs: true``, the true
    plant's factors; `RandomizedPlant.reads_privileged`): such a policy reads what no robot
    shows, so it is never scored or deployed."""
    from bound_env.envs.randomized import RandomizedPlant

    from .config import class_entries

    for name, kwargs in class_entries(section.get("env_wrapper")):
        if name.rsplit(".", 1)[-1] == "RandomizedPlant" and RandomizedPlant.reads_privileged(
            kwargs
        ):
            raise ValueError(
                f"{where}: trained with a privileged observation ({name.rsplit('.', 1)[-1]} "
                "privileged_obs: true, the true plant's factors), which no robot shows: it is "
                "not scored or deployed"
            )


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


# The files that define a policy, whatever its kind (a PPO model with its statistics, settings
# and base gain; a choice policy's network and expert): what a residual's base pin hashes.
POLICY_CONTENT_FILES = (
    "model.zip",
    "vecnormalize.pkl",
    "config.yaml",
    "base.json",
    "choice.npz",
    "config.json",
)


def policy_content_sha256(resolved) -> str:
    """The sha256 of what defines a controller, given as `agents.runtime.policy.resolve_policy`
    returns it: for a policy folder (or a model zip's folder) the sha256 of each of its
    `POLICY_CONTENT_FILES`, by name; for a classical controller (a built-in name) its spec
    file; for ``passive`` its name. Another policy swapped into the folder, or a file of it
    changed, changes it; the folder's path does not."""
    h = hashlib.sha256(b"policy content v1\n")
    if isinstance(resolved, str):  # a built-in controller: passive, or a classical spec
        h.update(f"builtin {resolved}\n".encode())
        if resolved != "passive":
            from bound_env.control.spec import resolve_spec_path

            h.update(f"spec {file_sha256(resolve_spec_path(resolved))}\n".encode())
        return h.hexdigest()
    p = Path(resolved)
    if p.is_file():  # a model zip or a spec file: that file, and its folder's settings
        h.update(f"{p.name} {file_sha256(p)}\n".encode())
        p = p.parent
    for name in POLICY_CONTENT_FILES:
        if (p / name).is_file():
            h.update(f"{name} {file_sha256(p / name)}\n".encode())
    return h.hexdigest()


def write_fingerprint(folder: str | Path, base: dict | None = None, **extra) -> Path:
    """Bind the files of the policy in ``folder`` together: the sha256 of ``model.zip``,
    ``vecnormalize.pkl`` and, when present, ``config.yaml`` and ``base.json``
    (`FINGERPRINTED_SETTINGS`) in ``fingerprint.json`` (written atomically), checked by
    `check_policy_files`. ``base`` (``{"policy": name, "sha256": ...}``) pins the base
    controller of a residual policy (`agents.runtime.policy.write_policy_fingerprint` finds it)."""
    import json

    from bound_env.files.cache import atomic_write

    folder = Path(folder)
    data = {"model.zip": file_sha256(folder / "model.zip")}
    for name in ("vecnormalize.pkl", *FINGERPRINTED_SETTINGS):
        if (folder / name).is_file():
            data[name] = file_sha256(folder / name)
    if base is not None:
        data["base"] = {"policy": str(base["policy"]), "sha256": str(base["sha256"])}
    data.update(extra)
    return atomic_write(folder / FINGERPRINT_FILE, json.dumps(data, indent=2) + "\n")


def check_base_pin(
    files: PolicyFiles, want: dict, base: str, current_sha256: str, force: bool
) -> list[str]:
    """ValueError when a residual policy's base controller ``base`` (its files' sha256 now:
    ``current_sha256``) is not the one it was trained over: its fingerprint ``want`` has no
    ``base`` (a residual's fingerprint must pin its base), or names another base or other
    content (another policy swapped into the base's folder, or a file of it changed);
    ``force`` evaluates it as it is, and the mismatch comes back as a warning."""
    fp = files.fingerprint
    pin = want.get("base")
    if pin is None:
        msg = (
            f"{fp}: missing key 'base' (the sha256 of the base controller {base!r} the "
            "residual was trained over), so a changed base would go unnoticed"
        )
    elif str(pin["policy"]) != str(base):
        msg = f"{fp}: base.policy is {pin['policy']!r}, but {files.config} trains over {base!r}"
    elif current_sha256 != pin["sha256"]:
        msg = (
            f"base {base!r} does not match {fp} (base.sha256): its files changed since the "
            "residual was trained over it (another policy in its place?)"
        )
    else:
        return []
    if not force:
        raise ValueError(
            msg + "; pass --force (margins, rollout, basin-map) to evaluate it with the base "
            "as it is"
        )
    return [msg]


def check_policy_files(
    files: PolicyFiles, section: dict, force: bool = False, env_given: bool = False, also=()
) -> list[str]:
    """ValueError for a policy whose evaluation would be silently wrong; returns warnings.

    - no config: the env kwargs it was trained with (``max_torque``, ``dt``, wrappers) are
      unknown (``force`` evaluates it with the env's defaults; ``env_given``: the caller names
      the env id it was trained on, a plain SB3 model's ``--env-id``);
    - trained with ``normalize`` but no ``vecnormalize.pkl`` beside the model;
    - a ``fingerprint.json`` (written at export and at the end of training) that does not match
      the model or the statistics: they belong to different policies;
    - a ``config.yaml`` (or ``base.json``) that does not match the fingerprint: edited or cut
      short since the policy was saved (a config cut before ``env_kwargs`` still parses, and
      would evaluate the policy at the env's default max_torque); ``force`` evaluates it as it
      is, with a warning;
    - a policy of this project's layout that rests on a base (a stride residual's
      ``base.json``, or ``also``: what a caller would check with the fingerprint, e.g. a
      step-level residual's base controller) but has no ``fingerprint.json`` (deleted, or
      saved before fingerprints): none of it can be checked, and a swapped base or a shifted
      reference would go unnoticed; ``force`` evaluates it as it is, with a warning naming
      what was not checked. Without a base, a missing fingerprint is a warning.
    """
    warnings = []
    if files.config is None and not env_given:
        msg = (
            f"policy {files.model}: no config.yaml beside it, so the environment it was "
            "trained on (max_torque, dt, observation filter) is unknown"
        )
        if not force:
            raise ValueError(
                msg + "; name it with --env-id (e.g. PassiveBound-v1), or pass --force to "
                "evaluate it with the env's defaults"
            )
        warnings.append(msg)
    if section.get("normalize") and files.vecnormalize is None:
        where = files.config.parent if files.config is not None else files.model.parent
        raise ValueError(
            f"policy {files.model} was trained with normalize="
            f"{section['normalize']!r} but {where} has no vecnormalize.pkl"
        )
    from .schema import read_fingerprint

    fp = files.fingerprint
    want = read_fingerprint(fp.parent)  # a folder or a broken file there is an error
    if want is not None:
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
    elif files.layout == "bound_env" and (also or (files.model.parent / "base.json").is_file()):
        folder = files.model.parent  # it rests on a base: a swapped one would go unnoticed
        unchecked = [f"that vecnormalize.pkl belongs to {files.model.name}"] * bool(
            files.vecnormalize
        )
        unchecked += [
            f"that {key} is the one it was saved with"
            for key in FINGERPRINTED_SETTINGS
            if (folder / key).is_file()
        ]
        unchecked += list(also)
        msg = f"{folder}: no {FINGERPRINT_FILE}, so it cannot be checked " + "; ".join(unchecked)
        if not force:
            raise ValueError(
                msg + "; pass --force (margins, rollout, basin-map) to evaluate it as it is"
            )
        warnings.append(msg)
    elif files.vecnormalize is not None and files.layout == "bound_env":
        warnings.append(
            f"{files.model.parent}: no {FINGERPRINT_FILE}, so it cannot be checked "
            "that vecnormalize.pkl belongs to this model"
        )
    return warnings


def source_name(path) -> str:
    """How a saved file names a policy it was made from: a shipped policy by its name
    relative to the package (``"distilled/s0"``, never the build machine's absolute path,
    which would travel into wheels), anything else as given."""
    text = str(path)
    try:
        rel = Path(text).resolve().relative_to(SHIPPED.resolve())
    except (ValueError, OSError):
        return text
    return rel.as_posix()


def load_vecnormalize(path: Path):
    """The ``VecNormalize`` object pickled at ``path`` (ValueError naming the file when it is
    truncated or foreign)."""
    import pickle

    try:
        with Path(path).open("rb") as f:
            return pickle.load(f)
    except Exception as e:  # noqa: BLE001 - a truncated or foreign pickle
        raise ValueError(
            f"cannot read {path} as VecNormalize statistics: {type(e).__name__}: {e}"
        ) from None
