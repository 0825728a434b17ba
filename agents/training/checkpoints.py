"""Crash-safe files of a training run's model: policy folders and checkpoints.

`save_policy` writes a policy folder (``model.zip``, ``vecnormalize.pkl``, ``fingerprint.json``:
the final model and ``best/``); `save_checkpoint` writes ``checkpoints/rl_model_<N>_steps.*``,
complete or absent (its manifest written last), and `last_checkpoint` finds the newest complete
one (``--resume``).
"""

from __future__ import annotations

import json
import os
import re
import sys
import time
from pathlib import Path

from bound_env.files.cache import atomic_path, atomic_write

_CKPT = re.compile(r"rl_model_(\d+)_steps\.zip$")

# Test hook: "SECONDS" or "SECONDS@TIMESTEPS", a sleep inside a checkpoint write (of every
# checkpoint, or of the one at TIMESTEPS), between the model and its statistics: the window in
# which a kill used to leave a checkpoint without its normalization.
CHECKPOINT_SLEEP_ENV = "BOUND_ENV_TEST_CHECKPOINT_SLEEP"


def save_policy(model, folder: Path) -> None:
    """Save ``model.zip``, its ``vecnormalize.pkl`` (when normalizing) and ``fingerprint.json``
    binding the two, each under a temporary name and then renamed; the fingerprint last."""
    from ..runtime.policy import write_policy_fingerprint

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    with atomic_path(folder / "model.zip", suffix=".zip") as tmp:  # SB3 appends .zip otherwise
        model.save(tmp)
    vn = model.get_vec_normalize_env()
    if vn is not None:
        with atomic_path(folder / "vecnormalize.pkl") as tmp:
            vn.save(str(tmp))
    write_policy_fingerprint(folder)  # a residual's base pinned too


def checkpoint_paths(folder: Path, n: int) -> tuple[Path, Path, Path]:
    """(model zip, VecNormalize pkl, manifest) of the checkpoint at ``n`` timesteps."""
    folder = Path(folder)
    return (
        folder / f"rl_model_{n}_steps.zip",
        folder / f"rl_model_vecnormalize_{n}_steps.pkl",
        folder / f"rl_model_{n}_steps.json",
    )


def save_checkpoint(model, folder: Path, n: int) -> Path:
    """A checkpoint that is complete or absent: the model, then its VecNormalize statistics,
    each under a temporary name and renamed, then a manifest (sha256 of both) written last.
    `last_checkpoint` only takes checkpoints whose manifest matches their files."""
    from ..common.policy_files import file_sha256

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    zip_path, pkl_path, manifest = checkpoint_paths(folder, n)
    with atomic_path(zip_path, suffix=".zip") as tmp:
        model.save(tmp)
    hook = os.environ.get(CHECKPOINT_SLEEP_ENV, "")  # "SECONDS" or "SECONDS@TIMESTEPS"
    sleep, _, at = hook.partition("@")
    sleep = float(sleep) if sleep and (not at or int(at) == n) else 0.0
    if sleep > 0:  # test hook: a reproducible window between the model and its statistics
        print(
            f"[checkpoint hook] {n} steps: model written, sleeping {sleep:g} s",
            file=sys.stderr,
            flush=True,
        )
        time.sleep(sleep)
    entry = {"timesteps": int(n), "model": zip_path.name, "model_sha256": file_sha256(zip_path)}
    vn = model.get_vec_normalize_env()
    if vn is not None:
        with atomic_path(pkl_path) as tmp:
            vn.save(str(tmp))
        entry.update(vecnormalize=pkl_path.name, vecnormalize_sha256=file_sha256(pkl_path))
        if vn.norm_obs:  # norm_obs=False (e.g. configs/ppo-stride.yaml) keeps no obs_rms
            entry["obs_count"] = float(vn.obs_rms.count)
    atomic_write(manifest, json.dumps(entry, indent=2) + "\n")
    return zip_path


def _complete(zip_path: Path, pkl_path: Path, manifest: Path) -> bool:
    """Whether a checkpoint's manifest is readable and matches its files."""
    from ..common.policy_files import file_sha256

    try:
        entry = json.loads(manifest.read_text())
        if not zip_path.is_file() or file_sha256(zip_path) != entry["model_sha256"]:
            return False
        if "vecnormalize_sha256" in entry:
            return pkl_path.is_file() and file_sha256(pkl_path) == entry["vecnormalize_sha256"]
        return True
    except (OSError, ValueError, KeyError, TypeError):
        return False


def last_checkpoint(run_dir: Path) -> tuple[Path, Path | None, int] | None:
    """(model zip, VecNormalize pkl or None, timesteps) of the newest *complete* checkpoint.

    A checkpoint is complete when its manifest (written last by `save_checkpoint`) matches
    its files; incomplete ones (a kill during the write) are skipped with a warning. Runs
    from before manifests existed: the newest checkpoint whose zip is readable.
    """
    import zipfile

    folder = Path(run_dir) / "checkpoints"
    found = sorted(
        (
            (int(m.group(1)), p)
            for p in folder.glob("rl_model_*_steps.zip")
            if (m := _CKPT.search(p.name))
        ),
        reverse=True,
    )
    legacy = not any(folder.glob("rl_model_*_steps.json"))
    for n, zip_path in found:
        _, pkl_path, manifest = checkpoint_paths(folder, n)
        if legacy:
            if zipfile.is_zipfile(zip_path):
                return zip_path, (pkl_path if pkl_path.exists() else None), n
        elif _complete(zip_path, pkl_path, manifest):
            return zip_path, (pkl_path if pkl_path.exists() else None), n
        print(
            f"warning: skipping incomplete checkpoint {zip_path} (interrupted while it was "
            "written)",
            file=sys.stderr,
        )
    return None
