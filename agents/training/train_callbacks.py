"""The Stable-Baselines3 callbacks of a training run (`agents.training.train`).

`NoiseCurriculumCallback` (the start-perturbation curriculum) and `BasinValidationCallback`
(keeps the checkpoint with the widest basin on validation directions) are named in a config's
``callback:`` list, as ``agents.training.train.<name>`` in the shipped configs and saved runs
(`agents.training.train` imports them); `train` adds `CSVEvalCallback` (``eval.csv``, ``eval.png``)
and `AtomicCheckpointCallback` (`agents.training.checkpoints.save_checkpoint` on a timestep
schedule).
"""

from __future__ import annotations

import json
import math
import sys
import time
from pathlib import Path

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback, EvalCallback

from ..common.run_files import append_csv, plot_eval
from ..common.seeds import VALIDATION_SEED
from .checkpoints import save_checkpoint, save_policy


class NoiseCurriculumCallback(BaseCallback):
    """Raise the start perturbation of `agents.common.wrappers.PerturbedStarts` over training.

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
        import bound_env.sim.task as task_mod

        from ..common.mlp import extract_actor
        from ..common.policy_files import DYNAMICS_KWARGS
        from ..common.wrappers import observation_index
        from ..runtime.controllers import MLPController

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
        from bound_env.model.numerics import bisect_threshold, map_fixed_point
        from bound_env.model.params import load_gait

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
