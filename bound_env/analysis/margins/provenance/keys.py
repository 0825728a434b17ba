"""The margins task cache's keys (`setup_key`, `mismatch_key`) and their parts: `SETTINGS`,
every bound_env source (`source_hash`), the gait file (`gait_key`), the controller's
fingerprint and code closure (`code_closure.code_parts`). A column's fingerprint
(`fingerprint.column_fingerprint`) records the key and checks its parts."""

from __future__ import annotations

from dataclasses import asdict
from pathlib import Path

from bound_env.files.cache import settings_hash

from ..basin import BASIN_CAP, BASIN_HI, BASIN_LO
from ..budget import (
    CURVE_SEED,
    DEFAULT_SEED,
    MFPT_CHUNK,
    MFPT_SEED,
    PUSH_SEED,
    TERRAIN_SEED,
    WINDOW_SCAN,
    Budget,
    check_seed,
    sample_seeds,
)
from ..ceiling import CEILING_ES
from ..closed_loop import ENV_ID, EVAL_RTOL, PROFILE_SEG, PROFILE_SPAN, RETURN_TOL
from ..cycle import FD_FLOOR, FD_REL
from ..model_error.mismatch_tasks import MISMATCH_BUDGETS, MISMATCH_SEED, SETTLE_NOISE
from .code_closure import ROOT, code_parts, file_code_hash, object_roots

CYCLE_RECORD_DT = 1e-3  # sampling of the passive stride for the cycle scale [s]


# Every module setting that changes a result: part of each cache key (with the budget, the
# seed, the gait file's contents, the controller's fingerprint and the source hash below).
SETTINGS = {
    "rtol": EVAL_RTOL,
    "return_tol": RETURN_TOL,
    "basin_lo": BASIN_LO,
    "basin_hi": BASIN_HI,
    "basin_cap": BASIN_CAP,
    "fd_rel": FD_REL,
    "fd_floor": FD_FLOOR.tolist(),
    "curve_seed": CURVE_SEED,
    "terrain_seed": TERRAIN_SEED,
    "push_seed": PUSH_SEED,
    "mfpt_seed": MFPT_SEED,
    "mfpt_chunk": MFPT_CHUNK,
    "profile_seg": PROFILE_SEG,
    "profile_span": PROFILE_SPAN,
    "ceiling_es": CEILING_ES,
    "ceiling_rng": "default_rng([component, sign > 0, round(s * 1e9) % 2**32])",
    "window_scan": WINDOW_SCAN,
    "env_id": ENV_ID,
    "cycle_record_dt": CYCLE_RECORD_DT,
}
# The model-error tasks' settings (with the spec: `mismatch_key`).
MISMATCH_SETTINGS = {"mismatch_seed": MISMATCH_SEED, "settle_noise": SETTLE_NOISE}


def source_files(extra=()) -> list[Path]:
    """Every .py file under bound_env/ (the simulator, the task, the classical controllers and
    this package), then the ``extra`` files: the code of a controller that lives outside
    bound_env/, named by the caller (`compute_margins`' ``extra_sources``)."""
    pkg = ROOT / "bound_env"
    return sorted(pkg.rglob("*.py")) + [Path(f) for f in extra]


def source_hash(files=None) -> str:
    """sha256 (16 hex digits) of the names and code of ``files`` (default: `source_files`):
    each ``.py`` file's syntax tree without its docstrings (`code_closure.file_code_hash`:
    an edited docstring or comment changes nothing), any other file's bytes. Any change of
    the simulator, the task, the controllers or the margins code gives a new cache key (no
    hand-kept version number)."""
    import hashlib

    h = hashlib.sha256()
    for f in files if files is not None else source_files():
        f = Path(f)
        h.update(f"{f.parent.name}/{f.name}\0".encode())
        h.update(file_code_hash(f).encode())
        h.update(b"\0")
    return h.hexdigest()[:16]


def gait_key(gait) -> dict:
    """The gait's name and the sha256 of its file's contents (a changed file, a new key)."""
    import hashlib

    from bound_env.model.params import resolve_gait_path

    digest = hashlib.sha256(resolve_gait_path(gait).read_bytes()).hexdigest()
    return {"name": str(gait), "file_sha256": digest}


def setup_key(
    controller, gait: str, budget: Budget, seed: int = DEFAULT_SEED, extra_sources=()
) -> str:
    """Cache key of one evaluation: the controller's fingerprint and env kwargs, the gait
    (name and file contents), the budget, the seed, `SETTINGS`, the `source_hash` of
    bound_env/ and ``extra_sources``, and the controller's code closure
    (`fingerprint.code_parts`: the project code its objects reach, bound_env's and the rest)."""
    env_kwargs = getattr(controller, "env_kwargs", None) or {}
    return settings_hash(
        {
            "controller": controller.fingerprint(),
            "gait": gait_key(gait),
            "budget": asdict(budget),
            "seed": check_seed(seed),
            "samples": sample_seeds(seed),
            "settings": SETTINGS,
            "source": source_hash(source_files(extra_sources)),
            "env_kwargs": sorted((str(k), repr(v)) for k, v in env_kwargs.items()),
            "closure": code_parts(object_roots(controller)),
        }
    )


def mismatch_key(key: str, spec, budget: Budget, mismatch_budget: str | None = None) -> str:
    """Cache key of the model-error tasks: the evaluation's key (`setup_key`), the spec, its
    budget (``mismatch_budget``'s, default ``budget``'s name's) and `MISMATCH_SETTINGS`."""
    return settings_hash(
        {
            "setup": key,
            "mismatch": spec.to_dict(),
            "mismatch_budget": asdict(MISMATCH_BUDGETS[mismatch_budget or budget.name]),
            "settings": MISMATCH_SETTINGS,
        }
    )
