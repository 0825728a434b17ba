"""PPO fine-tuning of a distilled stride controller (agents/experts/distill.py).

**The task** is the public env PassiveBoundRescue-v0 (`bound_env.envs.rescue_env`, made by
`gymnasium.make` in `rescue_env`): one step = one stride of the one stride map
(`bound_env.sim.stride_map`, the step env's own kernel at the evaluation tolerance 1e-10, as
PassiveBoundStride-v1 and `margins`), so what is learned is what `margins` measures. The
action is a row of the student's library (Discrete, `bound_env.envs.wrappers.LibraryActions`; row 0
the LQR's plan u_lqr(z)); the observation the normalized apex error x = (z - z*) / s. Episodes
start past the safe radius at z* + r |z*| xi (r ~ U(0, ``r_max``), the distillation's start
distribution). Reward: 1 per stride survived;
reaching the safe radius (where the LQR takes over for good) ends the episode with the strides
left to ``horizon`` as a bonus, so the return is the number of strides survived out of
``horizon`` and a rescue is worth surviving them all; a fall ends it with nothing more.

**Warm start**: PPO's actor (two tanh layers and the action head) starts with the distilled
weights, so its deterministic policy starts exactly as the student; the critic starts fresh and
is first fitted alone (``critic_warmup`` rollouts with the actor frozen). The categorical head
explores among the library's profiles, which are exactly the far-apart rescues (bang-bang,
random signs) that Gaussian noise on the coefficients never reached.
"""

from __future__ import annotations

import json
import sys
import time
from dataclasses import asdict
from pathlib import Path

import gymnasium as gym
import numpy as np

import bound_env
from bound_env import RESCUE_ENV_ID
from bound_env.envs.wrappers import LibraryActions
from bound_env.files.cache import atomic_write

from ..common.learn_config import FinetuneConfig
from ..common.mlp import linear_layers
from ..common.policy_files import source_name
from ..runtime.choice_policy import (
    ChoicePolicyController,
    frozen_lqr,
    load_choice_policy,
    save_policy,
)

gym.register_envs(bound_env)


def rescue_env_kwargs(policy: ChoicePolicyController, r_max=0.45, horizon=30) -> dict:
    """`gymnasium.make` arguments of PassiveBoundRescue-v0 for a distilled student: its own
    LQR (gait, basis, saturation, control grid and frozen gain) and safe radius."""
    return {
        **frozen_lqr(policy.lqr),
        "safe": policy.safe,
        "r_max": r_max,
        "horizon": horizon,
    }


def rescue_env(policy: ChoicePolicyController, r_max=0.45, horizon=30, axis_prob=0.25):
    """The env fine-tuning trains on: PassiveBoundRescue-v0 (`gymnasium.make`) on the
    student's LQR and safe radius, with the student's library as its discrete actions
    (`bound_env.envs.wrappers.LibraryActions`, row 0 the LQR's plan)."""
    import warnings

    kwargs = rescue_env_kwargs(policy, r_max, horizon)
    with warnings.catch_warnings():  # v0, deprecated, stays fine-tuning's task for a release
        warnings.filterwarnings("ignore", "PassiveBoundRescue-v0 is deprecated", DeprecationWarning)
        env = gym.make(RESCUE_ENV_ID, **kwargs, axis_prob=axis_prob)
    return LibraryActions(env, policy.rows)


ChoiceStrideEnv = rescue_env  # the name of the former private env (same starts and strides)


SETTINGS_FILE = "finetune.json"  # the settings of the run in a run folder (checked on resume)


def run_settings(student_dir, cfg: FinetuneConfig) -> dict:
    """What a resumed run must share with the one it resumes: the student (its folder and the
    sha256 of its choice.npz) and every setting but ``timesteps`` (a rerun may train longer)."""
    from ..common.policy_files import file_sha256

    student = Path(student_dir)
    settings = {k: v for k, v in asdict(cfg).items() if k != "timesteps"}
    return {
        "student": str(student.resolve()),
        "student_sha256": file_sha256(student / "choice.npz"),
        **settings,
    }


def check_settings(out_dir: Path, student_dir, cfg: FinetuneConfig) -> None:
    """ValueError (one line) when ``out_dir`` holds a run of other settings (`run_settings`),
    or checkpoints of a run that recorded none, so that a rerun never resumes a foreign one;
    or a run of more ``timesteps`` (recorded in `SETTINGS_FILE`): a shorter rerun would
    replace its policy by a less trained one (a rerun may train longer: it resumes)."""
    path = Path(out_dir) / SETTINGS_FILE
    want = run_settings(student_dir, cfg)
    if path.is_file():
        try:
            have = json.loads(path.read_text())
        except (OSError, ValueError) as e:
            raise ValueError(f"{path}: not a finetune settings file ({e})") from None
        if not isinstance(have, dict):
            raise ValueError(f"{path}: not a finetune settings file (not a mapping)")
        done = have.pop("timesteps", None)
        if have != want:
            keys = sorted(k for k in want if have.get(k) != want[k])
            raise ValueError(
                f"--out {out_dir} holds a run with other settings ({', '.join(keys)}); use "
                "another --out"
            )
        if done is None:  # written before timesteps were recorded: the summary has them
            done = _summary(out_dir).get("timesteps")
        if done is not None and (
            isinstance(done, bool) or not isinstance(done, int) or cfg.timesteps < done
        ):
            raise ValueError(
                f"--timesteps {cfg.timesteps}: --out {out_dir} holds a run of --timesteps "
                f"{done} ({path.name}); a shorter rerun would replace its policy by a less "
                f"trained one: use another --out, or --timesteps {done} or more to resume it"
            )
    elif any(Path(out_dir).glob("ckpt_*_steps.zip")):
        raise ValueError(
            f"--out {out_dir} holds checkpoints without {SETTINGS_FILE} (of which student and "
            "seed?); use another --out"
        )


def _summary(out_dir) -> dict:
    """The ``summary.json`` of a finished run in ``out_dir`` ({} if there is none)."""
    try:
        data = json.loads((Path(out_dir) / "summary.json").read_text())
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}


def _copy_actor(model, layers) -> None:
    import torch

    lin = [m for m in model.policy.mlp_extractor.policy_net if isinstance(m, torch.nn.Linear)]
    lin.append(model.policy.action_net)
    if len(lin) != len(layers):
        raise ValueError("the PPO actor and the distilled network differ in depth")
    with torch.no_grad():
        for m, (W, b) in zip(lin, layers, strict=True):
            m.weight.copy_(torch.as_tensor(W, dtype=torch.float32))
            m.bias.copy_(torch.as_tensor(b, dtype=torch.float32))


def _actor_layers(model) -> list:
    return linear_layers([*model.policy.mlp_extractor.policy_net, model.policy.action_net])


def finetune(student_dir, out_dir, cfg: FinetuneConfig, progress: bool = True) -> dict:
    """PPO from the distilled student in ``student_dir``; the final model is exported to
    ``out_dir/policy`` (same format as a distilled policy). Checkpoints every 50k steps;
    a rerun resumes from the last one."""
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.callbacks import CheckpointCallback
    from stable_baselines3.common.vec_env import DummyVecEnv

    torch.set_num_threads(1)
    out_dir = Path(out_dir)
    student = load_choice_policy(student_dir)
    check_settings(out_dir, student_dir, cfg)  # before the run folder is written to
    done = _summary(out_dir)
    if (out_dir / "policy" / "choice.npz").is_file() and done.get(
        "requested_timesteps"
    ) == cfg.timesteps:
        if progress:
            print(
                f"[finetune] {out_dir} is complete ({done['timesteps']} strides)", file=sys.stderr
            )
        return done  # a finished run is not trained or saved again
    out_dir.mkdir(parents=True, exist_ok=True)
    settings = {**run_settings(student_dir, cfg), "timesteps": cfg.timesteps}
    atomic_write(out_dir / SETTINGS_FILE, json.dumps(settings) + "\n")
    # PPO learns in whole rollouts: --timesteps rounded up to them, the critic's warm-up
    # (10 rollouts) included in it rather than added to it
    rollout = cfg.n_steps * cfg.n_envs
    n_rollouts = max(1, -(-cfg.timesteps // rollout))
    warm = min(cfg.critic_warmup, max(1, cfg.timesteps // rollout)) * rollout
    if progress:
        print(
            f"[finetune] {n_rollouts * rollout} strides: {n_rollouts} PPO rollouts of "
            f"{rollout}, the first {warm // rollout} train the critic alone",
            file=sys.stderr,
        )
    t0 = time.perf_counter()

    def make(i):
        def f():
            env = rescue_env(student, cfg.r_max, horizon=cfg.horizon)
            env.reset(seed=cfg.seed * 1000 + i)
            return gym.wrappers.RecordEpisodeStatistics(env)

        return f

    venv = DummyVecEnv([make(i) for i in range(cfg.n_envs)])
    venv.seed(cfg.seed)
    ckpts = sorted(out_dir.glob("ckpt_*_steps.zip"), key=lambda p: int(p.stem.split("_")[1]))
    if ckpts:
        model = PPO.load(ckpts[-1], env=venv, device="cpu")
        if progress:
            print(f"[finetune] resuming from {ckpts[-1].name}", file=sys.stderr)
    else:
        hidden = [W.shape[0] for W, _ in student.layers[:-1]]
        model = PPO(
            "MlpPolicy",
            venv,
            n_steps=cfg.n_steps,
            batch_size=cfg.batch_size,
            n_epochs=cfg.n_epochs,
            learning_rate=cfg.learning_rate,
            clip_range=cfg.clip_range,
            ent_coef=cfg.ent_coef,
            gamma=cfg.gamma,
            policy_kwargs={
                "net_arch": {"pi": hidden, "vf": [128, 128]},
                "activation_fn": torch.nn.Tanh,
            },
            seed=cfg.seed,
            device="cpu",
            verbose=0,
        )
        _copy_actor(model, student.layers)
        # the critic alone first: the actor's parameters frozen for the warm-up rollouts
        actor = list(model.policy.mlp_extractor.policy_net.parameters())
        actor += list(model.policy.action_net.parameters())
        for p in actor:
            p.requires_grad_(False)
        model.learn(warm, reset_num_timesteps=True)  # (at most --timesteps, in whole rollouts)
        for p in actor:
            p.requires_grad_(True)
        if progress:
            print(f"[finetune] critic warm-up: {warm} steps", file=sys.stderr)
    left = cfg.timesteps - model.num_timesteps
    if left > 0:
        model.learn(
            left,
            reset_num_timesteps=False,
            callback=CheckpointCallback(50_000 // cfg.n_envs, str(out_dir), "ckpt"),
            progress_bar=False,
        )
    final = out_dir / f"ckpt_{model.num_timesteps}_steps.zip"
    if not final.is_file():  # a longer rerun resumes from the end of this one
        from bound_env.files.cache import atomic_path

        with atomic_path(final, suffix=".zip") as tmp:  # SB3 appends .zip otherwise
            model.save(tmp)
    layers = _actor_layers(model)
    save_policy(
        out_dir / "policy",
        student,
        layers,
        student.rows,
        {"finetune": asdict(cfg), "student": source_name(student_dir)},
    )
    ep = [e["r"] for e in model.ep_info_buffer] if model.ep_info_buffer else []
    summary = {
        "timesteps": int(model.num_timesteps),
        "requested_timesteps": cfg.timesteps,
        "seconds": time.perf_counter() - t0,
        "mean_return_last": float(np.mean(ep)) if ep else None,
        "policy": str(out_dir / "policy"),
    }
    atomic_write(out_dir / "summary.json", json.dumps(summary, indent=2) + "\n")
    return summary


def cmd_finetune(args) -> int:
    from ..runtime.policy import resolve_policy
    from .distill import check_export, export_folder

    student = resolve_policy(args.student)
    if isinstance(student, str) or not (Path(student) / "choice.npz").is_file():
        raise ValueError(f"--student {args.student}: not a distilled policy (no choice.npz)")
    check_export(args.export, args.force)
    out = Path(args.out or f"runs/finetune_s{args.seed}")
    from bound_env.commands.cli_args import check_writable

    check_writable(out, "--out")
    cfg = FinetuneConfig(timesteps=args.timesteps, seed=args.seed)
    summary = finetune(student, out, cfg, progress=not args.no_progress)
    from .distill import write_run_info

    write_run_info(
        out / "policy",
        args.seed,
        "bound-env " + " ".join(sys.argv[1:]),
        summary["seconds"],
        f"{summary['timesteps']} PPO strides from the distilled student {args.student}",
    )
    if args.export:
        summary["exported"] = str(export_folder(out / "policy", args.export))
    print(json.dumps(summary) if args.json else f"fine-tuned policy: {summary['policy']}")
    return 0
