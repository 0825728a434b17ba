"""What each kind of policy folder must hold, checked when it is loaded.

A fingerprint (``fingerprint.json``) proves that a folder's files were not changed by accident;
these schemas say whether they make sense: types, shapes, finite values, ranges, and sizes that
bound the work a policy can ask for. Each kind has its checks here, written with the field
checkers of `bound_env.files.schema`; every error is one line naming the file and the field.

- a distilled or fine-tuned choice policy (`agents.experts.distill`): ``choice.npz``
  (`check_choice_npz`) and ``config.json`` (`check_choice_config`);
- a PPO policy, step or stride level (`agents.runtime.policy`, `agents.runtime.stride`): the run
  config's ``env_kwargs`` (`check_env_kwargs`), the actor's weights (`check_layers`), the
  ``VecNormalize`` statistics (`check_obs_stats`) and a residual's ``base.json`` (`check_base`);
- every kind: ``fingerprint.json`` (`read_fingerprint`), and a folder that holds the files of
  two kinds is refused (`policy_kind`).
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np

from bound_env.files import schema as field

CHOICE_FILE = "choice.npz"  # a choice policy's network and library
CHOICE_CONFIG = "config.json"  # its frozen expert
FINGERPRINT = "fingerprint.json"
MAX_LAYERS = 16  # layers of a policy network (the shipped ones have 3)
MAX_WIDTH = 4096  # units of a layer (the shipped ones have 128)
MAX_ROWS = 4096  # rows of a choice policy's library (the shipped ones have 66)
APEX_DIM = 6  # the network's input: the apex state
MAX_RESIDUAL_SCALE = 100.0
_SHA256 = re.compile(r"[0-9a-f]{64}")
_FINGERPRINTED_EXT = (".zip", ".pkl", ".yaml", ".json", ".npz")
# the files a fingerprint must cover, by policy kind (`policy_kind`)
FINGERPRINT_REQUIRED = {"ppo": ("model.zip",), "choice": (CHOICE_FILE, CHOICE_CONFIG)}


def policy_kind(folder) -> str | None:
    """``"choice"`` (a ``choice.npz``), ``"ppo"`` (a ``model.zip``) or None (neither); a folder
    with both is ambiguous and refused."""
    folder = Path(folder)
    choice = os.path.lexists(folder / CHOICE_FILE)
    ppo = os.path.lexists(folder / "model.zip")
    if choice and ppo:
        raise ValueError(
            f"{folder}: holds both {CHOICE_FILE} (a distilled policy) and model.zip (a PPO "
            "policy), so which one it is is ambiguous; remove the file that does not belong"
        )
    return "choice" if choice else "ppo" if ppo else None


def read_fingerprint(folder) -> dict | None:
    """The ``fingerprint.json`` of a policy folder as {file name: sha256}, or None if there is
    none. Anything else in its place (a folder, a broken link, another JSON value) is an error:
    it never counts as "no fingerprint". A fingerprint must check something: it names the
    files that define the policy of its kind (`FINGERPRINT_REQUIRED`: ``model.zip``, and
    ``vecnormalize.pkl`` beside it; ``choice.npz`` and ``config.json``), so ``{}`` is refused.
    An optional ``base`` entry pins the base controller of a residual policy (`check_base_pin`):
    ``{"policy": its name, "sha256": the sha256 of its files}``."""
    fp = Path(folder) / FINGERPRINT
    if not os.path.lexists(fp):
        return None
    data = field.read_json(fp)
    field.mapping(data, str(fp))
    kind = policy_kind(folder)
    required = list(FINGERPRINT_REQUIRED.get(kind, ()))
    if kind == "ppo" and os.path.lexists(Path(folder) / "vecnormalize.pkl"):
        required.append("vecnormalize.pkl")  # the statistics belong to the model: one unit
    for name in required:
        if name not in data:
            raise ValueError(
                f"{fp}: missing key {name!r} (a fingerprint holds the sha256 of the files that "
                f"define the policy: {', '.join(required)})"
            )
    if not any(name.endswith(_FINGERPRINTED_EXT) for name in data):
        raise ValueError(f"{fp}: names no file, so it checks nothing")
    for name, digest in data.items():
        if name.endswith(_FINGERPRINTED_EXT):
            if not isinstance(digest, str) or not _SHA256.fullmatch(digest):
                raise ValueError(f"{fp}: {name} must be a sha256 (64 hex digits), got {digest!r}")
    if "base" in data:
        base = field.mapping(data["base"], f"{fp}: base", required=("policy", "sha256"))
        field.text(base["policy"], f"{fp}: base.policy")
        if not isinstance(base["sha256"], str) or not _SHA256.fullmatch(base["sha256"]):
            raise ValueError(f"{fp}: base.sha256 must be a sha256 (64 hex digits)")
    return data


# -- choice policies --------------------------------------------------------------------------


def check_choice_npz(path) -> tuple[list, np.ndarray]:
    """(layers [(W, b), ...], library rows) of a ``choice.npz``: ``n_layers`` one integer from
    1 to `MAX_LAYERS`; ``W<k>`` (width, inputs) and ``b<k>`` (width,) chained from the 6 apex
    numbers to one logit per library row; ``rows`` (n, K) in [-1, 1]; all real and finite."""
    from bound_env.sim.stride_task import MAX_K

    arrays = field.read_npz(path)
    where = str(path)
    if "n_layers" not in arrays:
        raise ValueError(f"{where}: n_layers: missing")
    n = arrays["n_layers"]
    if n.shape != ():
        raise ValueError(f"{where}: n_layers must be one integer, got shape {n.shape}")
    n = field.integer(n.item(), f"{where}: n_layers", 1, MAX_LAYERS)
    if "rows" not in arrays:
        raise ValueError(f"{where}: rows: missing")
    rows = field.real_array(arrays["rows"], f"{where}: rows", shape=(None, None), lo=-1, hi=1)
    if not (1 <= rows.shape[0] <= MAX_ROWS and 1 <= rows.shape[1] <= MAX_K):
        raise ValueError(f"{where}: rows must be (1 to {MAX_ROWS}, 1 to {MAX_K}), got {rows.shape}")
    names = {"n_layers", "rows"} | {f"{c}{k}" for k in range(n) for c in "Wb"}
    extra = sorted(set(arrays) - names)
    if extra:
        raise ValueError(f"{where}: unknown array {extra[0]!r} (n_layers is {n})")
    layers, inputs = [], APEX_DIM
    for k in range(n):
        for c in "Wb":
            if f"{c}{k}" not in arrays:
                raise ValueError(f"{where}: {c}{k}: missing (n_layers is {n})")
        W = field.real_array(arrays[f"W{k}"], f"{where}: W{k}", shape=(None, inputs))
        if W.shape[0] > MAX_WIDTH:
            raise ValueError(f"{where}: W{k} has {W.shape[0]} units, at most {MAX_WIDTH}")
        b = field.real_array(arrays[f"b{k}"], f"{where}: b{k}", shape=(W.shape[0],))
        layers.append((W, b))
        inputs = W.shape[0]
    if inputs != rows.shape[0]:
        raise ValueError(
            f"{where}: W{n - 1} has {inputs} outputs, but rows has {rows.shape[0]} rows (one "
            "logit per library row)"
        )
    return layers, rows


def check_choice_config(path) -> dict:
    """A choice policy's ``config.json``: ``kind`` "choice" and the frozen ``expert`` (its gait,
    basis, K, max_torque, dt, gain (K x 6) and search settings, as an mpc spec's:
    `bound_env.control.spec.check_mpc_settings`). Provenance keys are not checked."""
    from bound_env.control.spec import MAX_TORQUE_LIMIT, check_mpc_settings
    from bound_env.sim.stride_task import BASES, MAX_K

    cfg = field.read_json(path)
    where = str(path)
    field.mapping(cfg, where, required=("expert",))
    field.text(cfg.get("kind", "choice"), f"{where}: kind", ("choice",))
    ew = f"{where}: expert"
    e = field.mapping(
        cfg["expert"], ew, required=("gait", "basis", "K", "max_torque", "dt", "gain", "settings")
    )
    if "name" in e:
        field.text(e["name"], f"{ew}.name")
    field.text(e["gait"], f"{ew}.gait")
    field.text(e["basis"], f"{ew}.basis", BASES)
    K = field.integer(e["K"], f"{ew}.K", 1, MAX_K)
    field.real(e["max_torque"], f"{ew}.max_torque", 0.0, MAX_TORQUE_LIMIT, lo_open=True)
    field.dt_value(e["dt"], f"{ew}.dt")
    if not isinstance(e["gain"], list):
        raise ValueError(f"{ew}.gain must be a list of {K} rows of 6 numbers")
    field.real_array(e["gain"], f"{ew}.gain", shape=(K, APEX_DIM))
    allowed = ("safe", "horizon", "rtol", *(k for k in _mpc_keys() if k != "plan_rtol"))
    s = field.mapping(
        e["settings"], f"{ew}.settings", required=("safe", "horizon", "rtol"), allowed=allowed
    )
    check_mpc_settings(s, f"{ew}.settings", yaml_numbers=False)
    return cfg


def _mpc_keys():
    from bound_env.control.spec import MPC_DEFAULTS

    return tuple(MPC_DEFAULTS)


# -- PPO policies -----------------------------------------------------------------------------


def check_env_kwargs(env_kwargs, where: str) -> dict:
    """The ``env_kwargs`` of a PPO run config, as far as they bound the work: ``dt`` in
    [MIN_DT, MAX_DT], ``max_torque`` > 0 (the env checks the rest when it is built)."""
    from bound_env.control.spec import MAX_TORQUE_LIMIT

    field.mapping(env_kwargs, f"{where}: env_kwargs")
    if "dt" in env_kwargs:
        field.dt_value(env_kwargs["dt"], f"{where}: env_kwargs.dt")
    if "max_torque" in env_kwargs:
        field.real(
            env_kwargs["max_torque"],
            f"{where}: env_kwargs.max_torque",
            0.0,
            MAX_TORQUE_LIMIT,
            lo_open=True,
        )
    return env_kwargs


def check_layers(layers, where: str) -> list:
    """An actor's layers [(W, b)]: at most `MAX_LAYERS`, real and finite (NaN weights would
    silently act as something else), each W (width, inputs) chained, b (width,)."""
    if not 1 <= len(layers) <= MAX_LAYERS:
        raise ValueError(f"{where}: the network has {len(layers)} layers, 1 to {MAX_LAYERS}")
    inputs = None
    for k, (W, b) in enumerate(layers):
        W = field.real_array(W, f"{where}: layer {k} weights", shape=(None, inputs))
        field.real_array(b, f"{where}: layer {k} bias", shape=(W.shape[0],))
        inputs = W.shape[0]
    return layers


def check_obs_stats(vn, where: str, shape: tuple) -> tuple[np.ndarray, np.ndarray, float, float]:
    """(mean, var, epsilon, clip_obs) of `VecNormalize` statistics for observations of
    ``shape``: finite, var >= 0, epsilon > 0, clip_obs > 0."""
    rms = getattr(vn, "obs_rms", None)
    if rms is None:
        raise ValueError(f"{where}: obs_rms: missing (norm_obs is set)")
    mean = field.real_array(getattr(rms, "mean", None), f"{where}: obs_rms.mean", shape=shape)
    var = field.real_array(getattr(rms, "var", None), f"{where}: obs_rms.var", shape=shape, lo=0)
    eps = field.real(getattr(vn, "epsilon", None), f"{where}: epsilon", 0.0, 1.0, lo_open=True)
    clip = field.real(getattr(vn, "clip_obs", None), f"{where}: clip_obs", 0.0, lo_open=True)
    return mean, var, eps, clip


def check_base(path, K: int) -> dict:
    """A residual policy's ``base.json``: ``gain`` (K x 6), ``z_ref`` (6,), finite; ``name``."""
    data = field.read_json(path)
    where = str(path)
    field.mapping(data, where, required=("gain", "z_ref"), allowed=("gain", "z_ref", "name"))
    field.real_array(data["gain"], f"{where}: gain", shape=(K, APEX_DIM))
    field.real_array(data["z_ref"], f"{where}: z_ref", shape=(APEX_DIM,))
    if "name" in data:
        field.text(data["name"], f"{where}: name")
    return data


def check_residual_scale(value, where: str) -> float:
    return field.real(value, f"{where}: residual_scale", 0.0, MAX_RESIDUAL_SCALE, lo_open=True)
