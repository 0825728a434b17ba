"""Train spine-torque policies with Stable-Baselines3 PPO (``bound-env train``).

A run is fully described by its config section and its seed, and keeps everything under
``runs/<name>/``:

=========================  ===========================================================
``config.yaml``            the resolved section, keyed by env id (rl-zoo3 format), plus ``run:``
``run.json``               seed, env id, timesteps, wall time, versions, command
``model.zip``              the final model
``vecnormalize.pkl``       its ``VecNormalize`` statistics (observation and reward)
``eval.csv``, ``eval.png`` the evaluation curve (deterministic policy, curriculum's final noise)
``tb/``                    TensorBoard logs
``checkpoints/``           ``rl_model_<N>_steps.zip`` + ``rl_model_vecnormalize_<N>_steps.pkl``
                           + ``rl_model_<N>_steps.json`` (manifest, written last)
``monitor/``               SB3 ``Monitor`` files of the training environments
``basin_validation.csv``   `BasinValidationCallback` scores; ``best/`` its best checkpoint
=========================  ===========================================================

**Crash safety.** Every file is written under a temporary name and renamed. A checkpoint is
complete or absent: the model, then its statistics, then a manifest with the sha256 of both;
``--resume`` takes the newest checkpoint whose manifest matches (a kill during a write leaves
an incomplete one, skipped with a warning). A resume continues the run: the monitor logs are
appended to, ``run.json`` gets one session per start or resume (a killed session keeps
``"to": null``), evaluations and checkpoints keep their schedule in timesteps (stored in
``config.yaml``'s ``run:`` entry), and the rows of ``eval.csv``/``basin_validation.csv``
written after the resumed checkpoint are dropped and computed again, so the curve has neither
gaps nor duplicates. A truncated ``config.yaml`` or ``run.json`` is a one-line error.

``--export DIR`` (CLI) copies the policy files to DIR, taking the model from ``best/`` when
the run kept one. ``--resume`` continues from the last checkpoint with its ``VecNormalize``
statistics and its timestep count (the curriculum is a function of the timestep count, so it
resumes too); it reads the run's own ``config.yaml`` and ignores ``--config``/``--set``.
"""

from __future__ import annotations

import csv
import json
import math
import os
import platform
import re
import sys
import time
from pathlib import Path

import numpy as np
import yaml
from stable_baselines3.common.callbacks import BaseCallback, EvalCallback

from bound_env.cache import atomic_path, atomic_write

from .config import (
    DEFAULT_CONFIG,
    DEFAULT_ENV_ID,
    TrainSpec,
    apply_sets,
    load_hyperparams,
    preprocess,
)

RUNS_DIR = Path("runs")
EVAL_FIELDS = (
    "timesteps",
    "mean_reward",
    "std_reward",
    "mean_length",
    "mean_strides",
    "fall_rate",
    "noise_scale",
    "wall_time_s",
)
_CKPT = re.compile(r"rl_model_(\d+)_steps\.zip$")
# Test hook: "SECONDS" or "SECONDS@TIMESTEPS", a sleep inside a checkpoint write (of every
# checkpoint, or of the one at TIMESTEPS), between the model and its statistics: the window in
# which a kill used to leave a checkpoint without its normalization.
CHECKPOINT_SLEEP_ENV = "BOUND_ENV_TEST_CHECKPOINT_SLEEP"


# --------------------------------------------------------------------------------------------
# Environments
# --------------------------------------------------------------------------------------------


def make_env(
    env_id: str,
    env_kwargs: dict | None = None,
    spec: TrainSpec | None = None,
    seed: int | None = None,
    monitor_file: str | None = None,
    append: bool = False,
):
    """One environment: ``gymnasium.make`` -> ``Monitor`` -> the config's ``env_wrapper``s.

    Module-level (and importing ``bound_env``) so that `SubprocVecEnv` workers can rebuild it.
    """
    import gymnasium as gym
    from stable_baselines3.common.monitor import Monitor

    import bound_env

    from . import register_envs

    gym.register_envs(bound_env)
    register_envs()
    env = gym.make(env_id, **(env_kwargs or {}))
    env = Monitor(
        env, filename=monitor_file, info_keywords=("stride",), override_existing=not append
    )  # a resumed run appends to its monitor logs
    if spec is not None:
        env = spec.wrap(env)
    if seed is not None:
        env.action_space.seed(seed)
    return env


def make_vec(
    env_id: str,
    spec: TrainSpec,
    n_envs: int,
    seed: int,
    vec_env: str = "auto",
    monitor_dir: Path | None = None,
    append: bool = False,
):
    """``n_envs`` environments in a `SubprocVecEnv` (n_envs > 1) or a `DummyVecEnv`."""
    from functools import partial

    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

    fns = []
    for i in range(n_envs):
        mon = str(monitor_dir / str(i)) if monitor_dir is not None else None
        fns.append(partial(make_env, env_id, spec.env_kwargs, spec, seed + i, mon, append))
    kind = vec_env if vec_env != "auto" else ("subproc" if n_envs > 1 else "dummy")
    if kind == "subproc":
        venv = SubprocVecEnv(fns)
    elif kind == "dummy":
        venv = DummyVecEnv(fns)
    else:
        raise ValueError(f"vec_env must be auto, dummy or subproc, got {vec_env!r}")
    venv.seed(seed)
    return venv


# --------------------------------------------------------------------------------------------
# Callbacks
# --------------------------------------------------------------------------------------------


def save_policy(model, folder: Path) -> None:
    """Save ``model.zip``, its ``vecnormalize.pkl`` (when normalizing) and ``fingerprint.json``
    binding the two, each under a temporary name and then renamed; the fingerprint last."""
    from .policy_files import write_fingerprint

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    with atomic_path(folder / "model.zip", suffix=".zip") as tmp:  # SB3 appends .zip otherwise
        model.save(tmp)
    vn = model.get_vec_normalize_env()
    if vn is not None:
        with atomic_path(folder / "vecnormalize.pkl") as tmp:
            vn.save(str(tmp))
    write_fingerprint(folder)


class NoiseCurriculumCallback(BaseCallback):
    """Raise the start perturbation of `agents.wrappers.PerturbedStarts` over training.

    ``noise_scale`` goes linearly from ``start`` to ``end`` (apex_scales units; 1 is about the
    edge of the passive basin) over the first ``ramp`` fraction of the run's timesteps and
    then stays at ``end``. It is a function of the timestep count, so a resumed run
    continues where it stopped. Logged as ``curriculum/noise_scale``.
    """

    def __init__(self, start: float = 0.5, end: float = 3.0, ramp: float = 0.6, verbose: int = 0):
        super().__init__(verbose)
        if not (0 <= start and 0 <= end and 0 < ramp <= 1):
            raise ValueError(f"need start, end >= 0 and 0 < ramp <= 1, got {start}, {end}, {ramp}")
        self.start, self.end, self.ramp = float(start), float(end), float(ramp)
        self.value = float(start)

    def value_at(self, timesteps: int, total: int) -> float:
        frac = min(1.0, timesteps / max(1.0, self.ramp * total))
        return self.start + (self.end - self.start) * frac

    def _apply(self) -> None:
        total = getattr(self.model, "_total_timesteps", 0) or 1
        self.value = self.value_at(self.num_timesteps, total)
        self.training_env.env_method("set_noise_scale", self.value)
        self.logger.record("curriculum/noise_scale", self.value)

    def _on_training_start(self) -> None:
        self._apply()

    def _on_rollout_start(self) -> None:
        self._apply()

    def _on_step(self) -> bool:
        return True


VALIDATION_SEED = 777  # random directions of the checkpoint validation (the test uses 12345)


class BasinValidationCallback(BaseCallback):
    """Keep the checkpoint with the widest basin on a *validation* set of directions.

    Every ``eval_freq`` timesteps the current deterministic policy (with the training
    ``VecNormalize`` statistics) is put in the closed loop of the margins: its
    closed-loop fixed point is found, then, along each of ``n_directions`` random directions
    (seed ``direction_seed``, drawn like the margins' random-direction curve but from another
    seed, so disjoint from the test set: neither the 12 axis directions of the basin nor the
    curve's directions, nor the rough-terrain seeds), the largest size that returns, by
    ``iters`` log-bisection steps with ``strides`` strides to return. The smallest of them is
    the validation score, written to ``basin_validation.csv``; a new best is saved as
    ``best/model.zip`` + ``best/vecnormalize.pkl``, which ``--export-from best`` ships
    (``--export`` ships the final model by default). ``directions`` (a list of (component,
    sign)) restores the old axis-aligned check, which overlaps the test: use it only for
    monitoring.
    """

    def __init__(
        self,
        eval_freq: int = 100_000,
        directions=None,
        n_directions: int = 8,
        direction_seed: int = VALIDATION_SEED,
        iters: int = 8,
        strides: int = 100,
        verbose: int = 0,
    ):
        super().__init__(verbose)
        self.eval_freq = int(eval_freq)
        self.directions = None if directions is None else [tuple(d) for d in directions]
        self.n_directions, self.direction_seed = int(n_directions), int(direction_seed)
        self.iters, self.strides = int(iters), int(strides)
        self.run_dir: Path | None = None  # set by `train`
        self.env_kwargs: dict = {}
        self.env_wrapper = None
        self.best = -1.0
        self._last = 0

    def validation_directions(self) -> np.ndarray:
        """The validation perturbation directions (rows; units of |z*_i|, max |u_i| = 1)."""
        from bound_env.analysis.margins import random_directions

        if self.directions is not None:
            out = np.zeros((len(self.directions), 6))
            for k, (i, sign) in enumerate(self.directions):
                out[k, i] = sign
            return out
        return random_directions(self.n_directions, seed=self.direction_seed)

    def _on_step(self) -> bool:
        if self.num_timesteps - self._last >= self.eval_freq:
            self._last = self.num_timesteps
            self.validate()
        return True

    def controller(self):
        import bound_env.task as task_mod

        from .controllers import MLPController
        from .mlp import extract_actor
        from .policy_files import DYNAMICS_KWARGS
        from .wrappers import observation_index

        layers, activation = extract_actor(self.model, Path("(training)"))
        kwargs = {k: v for k, v in self.env_kwargs.items() if k in DYNAMICS_KWARGS}
        names = task_mod.PassiveBoundTask(
            **{k: v for k, v in kwargs.items() if k != "apex_scales"}
        ).obs_names
        ctrl = MLPController(
            name="validation",
            layers=layers,
            activation=activation,
            env_kwargs=kwargs,
            obs_index=observation_index(self.env_wrapper, names),
        )
        vn = self.model.get_vec_normalize_env()
        if vn is not None and vn.norm_obs:
            ctrl.obs_mean = np.array(vn.obs_rms.mean, dtype=np.float64)
            ctrl.obs_var = np.array(vn.obs_rms.var, dtype=np.float64)
            ctrl.epsilon, ctrl.clip_obs = float(vn.epsilon), float(vn.clip_obs)
        return ctrl

    def score(self, ctrl) -> float:
        from bound_env.analysis.margins import BASIN_HI, BASIN_LO, ClosedLoop, fd_steps
        from bound_env.analysis.numerics import bisect_threshold, map_fixed_point
        from bound_env.params import load_gait

        gait = self.env_kwargs.get("gait", "default")
        loop = ClosedLoop(ctrl, gait)
        zs = np.asarray(load_gait(gait).z0, dtype=float)
        try:
            zc, res, _ = map_fixed_point(loop.map, zs, fd_steps(zs), settle=30, newton_iters=4)
        except RuntimeError:
            return 0.0
        if res > 1e-6:
            return 0.0
        worst = BASIN_HI
        for u in self.validation_directions():

            def ok(s, u=u):
                return loop.run(zc + s * np.abs(zs) * u, zc, self.strides)[0]

            worst = min(worst, bisect_threshold(ok, BASIN_LO, BASIN_HI, self.iters)[0])
            if worst == 0.0:
                break
        return float(worst)

    def validate(self) -> float:
        t0 = time.perf_counter()
        value = self.score(self.controller())
        self.logger.record("eval/basin_validation", value)
        if self.run_dir is not None:
            path = self.run_dir / "basin_validation.csv"
            new = not path.exists()
            with path.open("a") as f:
                if new:
                    f.write("timesteps,basin_min,seconds\n")
                f.write(f"{self.num_timesteps},{value},{time.perf_counter() - t0:.2f}\n")
            if value > self.best:
                save_policy(self.model, self.run_dir / "best")
                (self.run_dir / "best" / "best.json").write_text(
                    json.dumps({"timesteps": self.num_timesteps, "basin_validation": value}) + "\n"
                )
        self.best = max(self.best, value)
        return value


class CSVEvalCallback(EvalCallback):
    """`EvalCallback` that also writes ``eval.csv`` (one row per evaluation) and ``eval.png``.

    Besides SB3's mean/std reward and episode length it records the fraction of evaluation
    episodes that ended in a fall and the mean number of strides per episode.
    """

    def __init__(
        self,
        *args,
        csv_path: Path,
        png_path: Path,
        noise_scale: float = math.nan,
        every: int | None = None,
        done: int = 0,
        **kwargs,
    ):
        super().__init__(*args, **kwargs)
        # the schedule counts timesteps (every ``every``), so a resumed run continues it
        self.every = int(every) if every else None
        self._last_k = done // self.every if self.every else 0
        self.csv_path, self.png_path = Path(csv_path), Path(png_path)
        self.noise_scale = noise_scale
        self._falls: list[bool] = []
        self._strides: list[int] = []
        self._t0 = time.perf_counter()

    def _log_success_callback(self, locals_, globals_) -> None:
        super()._log_success_callback(locals_, globals_)
        if locals_["done"]:
            info = locals_["info"]
            self._falls.append(info.get("failure") is not None)
            self._strides.append(int(info.get("stride", 0)))

    def _on_step(self) -> bool:
        if self.every:
            k = self.num_timesteps // self.every
            due = k > self._last_k
            if not due:
                return True
            self._last_k = k
            saved, self.eval_freq = self.eval_freq, 1  # SB3 evaluates when n_calls % freq == 0
        else:
            due = self.eval_freq > 0 and self.n_calls % self.eval_freq == 0
        if due:
            self._falls, self._strides = [], []
        cont = super()._on_step()
        if self.every:
            self.eval_freq = saved
        if due and self.evaluations_results:
            rewards = np.asarray(self.evaluations_results[-1], dtype=float)
            lengths = np.asarray(self.evaluations_length[-1], dtype=float)
            row = {
                "timesteps": self.num_timesteps,
                "mean_reward": float(rewards.mean()),
                "std_reward": float(rewards.std()),
                "mean_length": float(lengths.mean()),
                "mean_strides": float(np.mean(self._strides)) if self._strides else math.nan,
                "fall_rate": float(np.mean(self._falls)) if self._falls else math.nan,
                "noise_scale": self.noise_scale,
                "wall_time_s": time.perf_counter() - self._t0,
            }
            append_csv(self.csv_path, row)
            self.logger.record("eval/fall_rate", row["fall_rate"])
            try:
                plot_eval(self.csv_path, self.png_path)
            except Exception as e:  # noqa: BLE001 - a plot must never stop training
                print(f"eval plot failed: {e}", file=sys.stderr)
        return cont


def append_csv(path: Path, row: dict) -> None:
    new = not path.exists()
    with path.open("a", newline="") as f:
        w = csv.DictWriter(f, fieldnames=EVAL_FIELDS)
        if new:
            w.writeheader()
        w.writerow({k: row.get(k, "") for k in EVAL_FIELDS})


def read_csv(path: Path) -> dict[str, np.ndarray]:
    with Path(path).open() as f:
        rows = list(csv.DictReader(f))
    return {
        k: np.array([float(r[k]) if r.get(k) not in (None, "") else math.nan for r in rows])
        for k in EVAL_FIELDS
    }


def plot_eval(csv_path: Path, png_path: Path, title: str | None = None) -> None:
    """Evaluation curve: mean return (± std) and fall rate against timesteps, and below it
    the basin validation score (``basin_validation.csv`` beside the CSV), if any."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    d = read_csv(csv_path)
    val_path = Path(csv_path).parent / "basin_validation.csv"
    val = np.loadtxt(val_path, delimiter=",", skiprows=1, ndmin=2) if val_path.exists() else None
    rows = 2 if val is not None and len(val) else 1
    fig, axes = plt.subplots(
        rows, 1, figsize=(6.4, 3.6 * rows), dpi=100, sharex=True, squeeze=False
    )
    ax = axes[0, 0]
    t = d["timesteps"]
    ax.plot(t, d["mean_reward"], color="C0", label="mean return")
    ax.fill_between(
        t,
        d["mean_reward"] - d["std_reward"],
        d["mean_reward"] + d["std_reward"],
        color="C0",
        alpha=0.2,
    )
    ax.set_ylabel("evaluation return", color="C0")
    ax2 = ax.twinx()
    ax2.plot(t, d["fall_rate"], color="C3", ls="--", label="fall rate")
    ax2.set_ylim(-0.05, 1.05)
    ax2.set_ylabel("fall rate", color="C3")
    noise = d["noise_scale"][-1] if len(t) else math.nan
    ax.set_title(title or f"PPO evaluation (start noise {noise:g} x apex_scales)")
    if rows == 2:
        axv = axes[1, 0]
        axv.plot(val[:, 0], val[:, 1], "o-", color="C2", ms=3)
        best = int(np.argmax(val[:, 1]))
        axv.plot(val[best, 0], val[best, 1], "*", color="C1", ms=12, label="kept (best)")
        axv.set_ylabel("basin validation\n(min rel. basin, xdot & y_g)")
        axv.legend(fontsize=8)
    axes[-1, 0].set_xlabel("timesteps")
    fig.tight_layout()
    fig.savefig(png_path)
    plt.close(fig)


# --------------------------------------------------------------------------------------------
# Training
# --------------------------------------------------------------------------------------------


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
    from .policy_files import file_sha256

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
    from .policy_files import file_sha256

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


class AtomicCheckpointCallback(BaseCallback):
    """`save_checkpoint` every ``save_freq`` timesteps (counted in timesteps, so a resumed run
    keeps the schedule)."""

    def __init__(self, save_freq: int, save_path: Path, done: int = 0, verbose: int = 0):
        super().__init__(verbose)
        self.save_freq, self.save_path = max(int(save_freq), 1), Path(save_path)
        self._last_k = done // self.save_freq

    def _on_step(self) -> bool:
        k = self.num_timesteps // self.save_freq
        if k > self._last_k:
            self._last_k = k
            save_checkpoint(self.model, self.save_path, self.num_timesteps)
        return True


def truncate_csv(path: Path, max_timesteps: int, column: str = "timesteps") -> None:
    """Keep the header and the complete rows with ``column`` <= ``max_timesteps`` (rows after a
    resumed checkpoint are computed again; a row cut short by a kill is dropped)."""
    path = Path(path)
    if not path.is_file():
        return
    lines = path.read_text().splitlines()
    if not lines:
        return
    header = lines[0].split(",")
    keep = [lines[0]]
    for line in lines[1:]:
        cells = line.split(",")
        try:
            ok = len(cells) == len(header) and float(cells[header.index(column)]) <= max_timesteps
        except ValueError:
            ok = False
        if ok:
            keep.append(line)
    atomic_write(path, "\n".join(keep) + "\n")


def _continue_evaluations(cb: EvalCallback, path: Path, done: int) -> None:
    """Preload an EvalCallback's arrays from its ``evaluations.npz`` (rows up to ``done``)."""
    try:
        with np.load(path) as d:
            keep = d["timesteps"] <= done
            cb.evaluations_timesteps = d["timesteps"][keep].tolist()
            cb.evaluations_results = d["results"][keep].tolist()
            cb.evaluations_length = d["ep_lengths"][keep].tolist()
    except (OSError, KeyError, ValueError):
        pass  # absent or cut short by a kill: it restarts (eval.csv is the record)


def read_run_files(run_dir: Path) -> tuple[dict, dict]:
    """(config.yaml, run.json) of a run, with a one-line error for a missing, truncated or
    malformed file."""
    saved = run_dir / "config.yaml"
    if not saved.is_file():
        raise FileNotFoundError(f"--resume: no run at {run_dir} (missing config.yaml)")
    try:
        data = yaml.safe_load(saved.read_text())
        env_id = data["run"]["env_id"]
        int(data["run"]["seed"])
        if not isinstance(data[env_id], dict):
            raise TypeError
    except (yaml.YAMLError, UnicodeDecodeError, KeyError, TypeError, ValueError):
        raise ValueError(
            f"{saved} is truncated or malformed (it needs a 'run:' entry with "
            "env_id and seed, and that env id's section)"
        ) from None
    info_path = run_dir / "run.json"
    info = {}
    if info_path.is_file():
        try:
            info = json.loads(info_path.read_text())
            if not isinstance(info, dict):
                raise ValueError
        except (ValueError, UnicodeDecodeError):
            raise ValueError(
                f"{info_path} is truncated or malformed JSON; repair it or move it away to resume"
            ) from None
    return data, info


def check_algo_kwargs(algo_kwargs: dict, algo_class) -> None:
    """ValueError naming hyperparameters the algorithm's constructor does not take (a typo in
    the config or in ``--set`` would otherwise be a TypeError deep inside SB3)."""
    import inspect

    params = inspect.signature(algo_class.__init__).parameters
    if any(p.kind is p.VAR_KEYWORD for p in params.values()):
        return
    unknown = sorted(set(algo_kwargs) - set(params) - {"policy"})
    if unknown:
        known = sorted(k for k in params if k not in ("self", "env", "policy"))
        raise ValueError(
            f"unknown hyperparameter(s) {unknown} for {algo_class.__name__}; known: {known}"
        )


def check_env_spec(env_id: str, spec: TrainSpec) -> None:
    """ValueError (one line) for ``env_kwargs``, ``env_wrapper`` or ``callback`` arguments that
    `gymnasium.make` or the classes would refuse (a typo in the config or in ``--hp
    env_kwargs.KEY=...`` would otherwise be a TypeError after the run folder was made): the
    arguments are bound to the classes' signatures and one environment is made and closed."""
    import inspect

    import gymnasium as gym

    for kind, entries in (("env_wrapper", spec.wrappers), ("callback", spec.callbacks)):
        for cls, kwargs in entries:
            try:
                sig = inspect.signature(cls)
                if kind == "env_wrapper":
                    sig.bind(None, **kwargs)
                else:
                    sig.bind(**kwargs)
            except TypeError as e:
                raise ValueError(f"{kind} {cls.__name__} {kwargs}: {e}") from None
    try:
        env = make_env(env_id, spec.env_kwargs, spec)
    except (TypeError, ValueError, gym.error.Error) as e:
        msg = str(e).splitlines()[0] if str(e) else type(e).__name__
        msg = msg.split(" was raised from the environment creator")[0]  # gymnasium's wording
        raise ValueError(f"cannot make {env_id} from its env_kwargs: {msg}") from None
    env.close()


def resolve_section(
    config: str | Path, env_id: str, sets: list[str] | None, n_timesteps: int | None
) -> dict:
    hp = apply_sets(load_hyperparams(config, env_id), sets)
    if n_timesteps is not None:
        hp["n_timesteps"] = int(n_timesteps)
    return hp


def train(
    config: str | Path = DEFAULT_CONFIG,
    env_id: str = DEFAULT_ENV_ID,
    name: str | None = None,
    seed: int = 0,
    n_timesteps: int | None = None,
    sets: list[str] | None = None,
    resume: bool = False,
    runs_dir: str | Path = RUNS_DIR,
    vec_env: str = "auto",
    eval_freq: int | None = None,
    n_eval_episodes: int | None = None,
    save_freq: int | None = None,
    progress_bar: bool = True,
    verbose: int = 0,
    init_from: str | None = None,
) -> Path:
    """Train PPO as the config section of ``env_id`` says; returns the run directory.

    ``init_from``: a stride controller whose torques the actor clones before PPO
    (`agents.warmstart`; a fresh run only, a resume continues from its checkpoint)."""
    import torch as th
    from stable_baselines3 import PPO
    from stable_baselines3.common.utils import set_random_seed
    from stable_baselines3.common.vec_env import VecNormalize

    name = name or f"{env_id}_s{seed}"
    run_dir = Path(runs_dir) / name
    prev_info: dict = {}
    schedule = {"eval_freq": eval_freq, "save_freq": save_freq, "n_eval_episodes": n_eval_episodes}
    if resume:
        data, prev_info = read_run_files(run_dir)
        env_id = data["run"]["env_id"]
        seed = int(data["run"]["seed"])
        hp = data[env_id]
        for key, value in schedule.items():  # the run's own schedule unless given again
            if value is None:
                schedule[key] = data["run"].get(key)
        if n_timesteps is not None:
            hp["n_timesteps"] = int(n_timesteps)
        ckpt = last_checkpoint(run_dir)
        if ckpt is None:
            raise FileNotFoundError(
                f"--resume: no complete checkpoint under {run_dir / 'checkpoints'}"
            )
    else:
        hp = resolve_section(config, env_id, sets, n_timesteps)
        if (run_dir / "model.zip").exists() or last_checkpoint(run_dir) is not None:
            raise ValueError(f"run {run_dir} exists; use --resume or another --name")
        ckpt = None
    teacher = None
    if init_from is not None and ckpt is None:  # loaded before the run folder exists
        from .policy import load_controller

        teacher = load_controller(init_from)
        if not hasattr(teacher, "on_apex"):
            raise ValueError(f"--init-from {init_from}: not a stride controller (no on_apex)")
    for key, default in (("eval_freq", 20_000), ("save_freq", 50_000), ("n_eval_episodes", 10)):
        schedule[key] = int(schedule[key] if schedule[key] is not None else default)
        if schedule[key] < 1:
            raise ValueError(f"{key} must be at least 1, got {schedule[key]}")
    eval_freq, save_freq = schedule["eval_freq"], schedule["save_freq"]
    n_eval_episodes = schedule["n_eval_episodes"]
    spec = preprocess(hp)
    check_algo_kwargs(spec.algo_kwargs, PPO)
    check_env_spec(env_id, spec)  # before the run folder exists: a bad key leaves nothing behind
    run_dir.mkdir(parents=True, exist_ok=True)
    (run_dir / "monitor").mkdir(exist_ok=True)
    write_config(run_dir / "config.yaml", env_id, hp, seed, schedule)
    done = ckpt[2] if ckpt is not None else 0
    if ckpt is not None:  # what was written after the checkpoint is computed again
        truncate_csv(run_dir / "eval.csv", done)
        truncate_csv(run_dir / "basin_validation.csv", done)
    info_path = run_dir / "run.json"
    sessions = list(prev_info.get("sessions", [])) if resume else []
    sessions.append(
        {
            "from": done,
            "to": None,
            "wall_time_s": None,
            "started": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
            "resumed": bool(resume),
        }
    )
    info = {
        **(prev_info if resume else {}),
        "env_id": env_id,
        "seed": seed,
        "n_timesteps": spec.n_timesteps,
        "sessions": sessions,
        "command": " ".join(sys.argv),
    }
    atomic_write(info_path, json.dumps(info, indent=2) + "\n")

    th.set_num_threads(1)
    set_random_seed(seed)
    venv = make_vec(
        env_id, spec, spec.n_envs, seed, vec_env, run_dir / "monitor", append=ckpt is not None
    )
    from .stride import write_base

    write_base(run_dir, venv)  # a residual stride policy's base controller (agents/stride.py)
    eval_env = make_vec(env_id, spec, 1, seed + 10_000, "dummy")
    callbacks, curriculum_end = [], math.nan
    for cls, kwargs in spec.callbacks:
        cb = cls(**kwargs)
        callbacks.append(cb)
        if isinstance(cb, NoiseCurriculumCallback):
            curriculum_end = cb.end
        if isinstance(cb, BasinValidationCallback):
            cb.run_dir, cb.env_kwargs = run_dir, dict(spec.env_kwargs)
            cb.env_wrapper = hp.get("env_wrapper")
            prev = run_dir / "best" / "best.json"
            if ckpt is not None and prev.exists():
                cb.best = json.loads(prev.read_text())["basin_validation"]
                cb._last = ckpt[2]
    if not math.isnan(curriculum_end):
        eval_env.env_method("set_noise_scale", curriculum_end)
    else:
        got = eval_env.get_attr("noise_scale") if _has_attr(eval_env, "noise_scale") else [math.nan]
        curriculum_end = float(got[0])
    if spec.normalize_kwargs is not None:
        if ckpt is not None and ckpt[1] is not None:
            venv = VecNormalize.load(str(ckpt[1]), venv)
            venv.training = True
        else:
            venv = VecNormalize(venv, **spec.normalize_kwargs)
        eval_kwargs = {k: v for k, v in spec.normalize_kwargs.items() if k != "norm_reward"}
        eval_env = VecNormalize(eval_env, training=False, norm_reward=False, **eval_kwargs)

    if ckpt is not None:
        model = PPO.load(str(ckpt[0]), env=venv, device="cpu", tensorboard_log=str(run_dir / "tb"))
        model.num_timesteps = done
    else:
        model = PPO(
            env=venv,
            seed=seed,
            device="cpu",
            tensorboard_log=str(run_dir / "tb"),
            verbose=verbose,
            **spec.algo_kwargs,
        )
    if teacher is not None:
        from .warmstart import clone, collect

        bc_env = make_env(env_id, spec.env_kwargs, spec, seed + 20_000)
        X, A = collect(bc_env, teacher, seed, progress=progress_bar)
        bc_env.close()
        info["init_from"] = {"policy": str(init_from), **clone(model, venv, X, A, seed)}
        atomic_write(info_path, json.dumps(info, indent=2) + "\n")
    n_envs = spec.n_envs
    # evaluation before the checkpoint of the same step, so a checkpoint never precedes an
    # evaluation it should include; both count timesteps, so a resume keeps their schedules
    callbacks.append(
        CSVEvalCallback(
            eval_env,
            n_eval_episodes=n_eval_episodes,
            eval_freq=max(eval_freq // n_envs, 1),
            log_path=str(run_dir),
            best_model_save_path=None,
            deterministic=True,
            csv_path=run_dir / "eval.csv",
            png_path=run_dir / "eval.png",
            noise_scale=curriculum_end,
            every=eval_freq,
            done=done,
            warn=False,
            verbose=verbose,
        )
    )
    callbacks.append(AtomicCheckpointCallback(save_freq, run_dir / "checkpoints", done=done))
    if ckpt is not None:  # SB3's evaluations.npz continues too (its rows up to the checkpoint)
        _continue_evaluations(callbacks[-2], run_dir / "evaluations.npz", done)
    remaining = max(0, spec.n_timesteps - done)
    t0 = time.perf_counter()
    model.learn(
        total_timesteps=remaining,
        callback=callbacks,
        progress_bar=progress_bar,
        reset_num_timesteps=ckpt is None,
        tb_log_name="PPO",
    )
    wall = time.perf_counter() - t0
    save_policy(model, run_dir)
    if (run_dir / "eval.csv").exists():
        plot_eval(run_dir / "eval.csv", run_dir / "eval.png")
    venv.close()
    eval_env.close()
    sessions[-1].update(to=int(model.num_timesteps), wall_time_s=wall)
    info.update(
        {
            "timesteps_done": int(model.num_timesteps),
            "n_envs": n_envs,
            "wall_time_s": sum(x.get("wall_time_s") or 0.0 for x in sessions),
            "sessions": sessions,
            "python": platform.python_version(),
            "versions": _versions(),
            "machine": f"{platform.machine()}, {_ncpu()} cores",
        }
    )
    atomic_write(info_path, json.dumps(info, indent=2) + "\n")
    return run_dir


def _has_attr(venv, attr: str) -> bool:
    # VecEnv.has_attr: a getattr that raises inside a SubprocVecEnv worker would kill it.
    return bool(venv.has_attr(attr))


def _ncpu() -> int:
    import os

    return os.cpu_count() or 1


def _versions() -> dict:
    import gymnasium
    import stable_baselines3
    import torch

    return {
        "stable_baselines3": stable_baselines3.__version__,
        "torch": torch.__version__,
        "gymnasium": gymnasium.__version__,
        "numpy": np.__version__,
    }


def write_config(
    path: Path, env_id: str, hp: dict, seed: int, schedule: dict | None = None
) -> None:
    """The resolved section in rl-zoo3's format, plus a ``run:`` entry (env id, seed, and the
    evaluation and checkpoint schedule), written atomically."""
    data = {env_id: hp, "run": {"env_id": env_id, "seed": int(seed), **(schedule or {})}}
    atomic_write(path, yaml.safe_dump(data, sort_keys=False, default_flow_style=None))
