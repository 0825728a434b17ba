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

``--export-out DIR`` (CLI; old spelling ``--export``) copies the policy files to DIR: the
final model and its statistics (no selection); ``--export-from best`` takes the checkpoint in
``best/`` instead (the one ``BasinValidationCallback`` selected), when the run kept one.
``--resume`` continues from the last checkpoint with its ``VecNormalize`` statistics and its
timestep count (the curriculum is a function of the timestep count, so it resumes too); it
reads the run's own ``config.yaml`` and ignores ``--config``/``--set``.
"""

from __future__ import annotations

import json
import math
import platform
import sys
import time
from pathlib import Path

import numpy as np
from stable_baselines3.common.callbacks import EvalCallback

from bound_env.files.cache import atomic_write

from ..common.config import (
    DEFAULT_CONFIG,
    TrainSpec,
    apply_sets,
    default_env_id,
    load_hyperparams,
    parse_set,
    preprocess,
)
from ..common.run_files import plot_eval, read_run_files, truncate_csv, write_config
from .checkpoints import last_checkpoint, save_policy
from .train_callbacks import (
    AtomicCheckpointCallback,
    BasinValidationCallback,
    CSVEvalCallback,
    NoiseCurriculumCallback,
)

RUNS_DIR = Path("runs")


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

    from .. import register_envs

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
# Training
# --------------------------------------------------------------------------------------------


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
        over = spec.env_kwargs.get("gait_overrides")
        if over and "gait_overrides" in msg:  # train --set KEY=VALUE gave them
            keys = ", ".join(f"{k}={v}" for k, v in dict(over).items())
            raise ValueError(
                f"--set {keys} (env_kwargs.gait_overrides): {env_id} takes no gait overrides; "
                "give them to an env that takes them (PassiveBound-v0), or drop --set"
            ) from None
        raise ValueError(f"cannot make {env_id} from its env_kwargs: {msg}") from None
    env.close()


def resolve_section(
    config: str | Path, env_id: str, sets: list[str] | None, n_timesteps: int | None
) -> dict:
    hp = apply_sets(load_hyperparams(config, env_id), sets)
    if n_timesteps is not None:
        hp["n_timesteps"] = int(n_timesteps)
    return hp


def check_resume(run_dir, run: tuple, given: dict) -> None:
    """ValueError (one line, naming the setting) when a ``--resume`` is given a setting that
    differs from the run's (``run``: its env id, seed, hyperparameters and run.json): an env
    id, a seed, a hyperparameter (``--hp``, ``--gait``, ``--set``; ``n_timesteps`` may
    change) or a warm start, as ``given`` (None: not given). A resume continues the run as it
    was made; another setting is another run (another ``--name``)."""
    import copy

    env_id, seed, hp, info = run  # the run's own: from its config.yaml and run.json
    hint = "a resume continues the run as it was made; train another --name for another setting"
    if given.get("env_id") is not None and given["env_id"] != env_id:
        raise ValueError(
            f"--resume: {run_dir} was trained on {env_id}, not --env-id {given['env_id']} ({hint})"
        )
    if given.get("seed") is not None and int(given["seed"]) != seed:
        raise ValueError(
            f"--resume: {run_dir} has seed {seed}, not --seed {given['seed']} ({hint})"
        )
    for text in given.get("sets") or []:
        parts, _ = parse_set(text)
        if parts == ["n_timesteps"]:
            continue  # the budget may grow (as --n-timesteps)
        old = copy.deepcopy(hp)
        new = apply_sets(copy.deepcopy(hp), [text])
        if new != old:
            key = ".".join(parts)
            was = _lookup(old, parts)
            raise ValueError(
                f"--resume: --hp {text} differs from the run's {key} = {was!r} in {run_dir} "
                f"({hint})"
            )
    warm = (info.get("init_from") or {}).get("policy")
    if given.get("init_from") is not None and str(given["init_from"]) != warm:
        was = f"was warm-started from {warm}" if warm else "had no warm start"
        raise ValueError(
            f"--resume: {run_dir} {was}, not --init-from {given['init_from']} ({hint})"
        )


def _lookup(hp: dict, parts: list[str]):
    """The value at a dotted key, or "unset"."""
    node = hp
    for p in parts:
        if not isinstance(node, dict) or p not in node:
            return "unset"
        node = node[p]
    return node


def train(
    config: str | Path = DEFAULT_CONFIG,
    env_id: str | None = None,
    name: str | None = None,
    seed: int | None = None,
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

    ``env_id`` None: the config's only section, else ``PassiveBound-v0`` (`default_env_id`).
    ``seed`` None: 0.

    ``resume`` continues ``runs_dir/name`` as it was made: its env id, seed, hyperparameters
    and warm start; a setting given that differs from the run's (`check_resume`) is a one-line
    ValueError naming it (only ``n_timesteps`` and the evaluation and checkpoint schedule
    may change). Given again with the run's own values, they are accepted.

    ``init_from``: a stride controller whose torques the actor clones before PPO
    (`agents.training.warmstart`; a fresh run only, a resume continues from its checkpoint)."""
    import torch as th
    from stable_baselines3 import PPO
    from stable_baselines3.common.utils import set_random_seed
    from stable_baselines3.common.vec_env import VecNormalize

    from bound_env.files.values import check_name

    given = {"env_id": env_id, "seed": seed, "sets": sets, "init_from": init_from}
    if env_id is None:
        env_id = default_env_id(config)
    seed = 0 if seed is None else seed
    name = check_name(name or f"{env_id}_s{seed}", "--name")  # a folder of runs_dir, no path
    run_dir = Path(runs_dir) / name
    prev_info: dict = {}
    schedule = {"eval_freq": eval_freq, "save_freq": save_freq, "n_eval_episodes": n_eval_episodes}
    if resume:
        data, prev_info = read_run_files(run_dir)
        env_id = data["run"]["env_id"]
        seed = int(data["run"]["seed"])
        hp = data[env_id]
        check_resume(run_dir, (env_id, seed, hp, prev_info), given)
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
        from ..runtime.policy import load_controller

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
        # the command's name, not the build machine's path to it (run.json travels in wheels)
        "command": " ".join([Path(sys.argv[0]).name, *sys.argv[1:]]),
    }
    atomic_write(info_path, json.dumps(info, indent=2) + "\n")

    th.set_num_threads(1)
    set_random_seed(seed)
    venv = make_vec(
        env_id, spec, spec.n_envs, seed, vec_env, run_dir / "monitor", append=ckpt is not None
    )
    from ..runtime.stride_policy import write_base

    write_base(run_dir, venv)  # a residual stride policy's base controller
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
