"""The settings of the two learning runs, `agents.experts.distill` and `agents.experts.finetune`
(plain dataclasses: the command line reads their defaults without importing NumPy or torch)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass
class DistillConfig:
    """Settings of one distillation run (all of them go into its config.json)."""

    expert: str = "mpc"  # controller spec of the expert (its LQR, safe radius and horizon)
    n_random: int = 48  # random sign rows of the library
    library_seed: int = 5
    r_max: float = 0.45  # starts up to this relative size
    axis_prob: float = 0.25
    rounds: int = 4  # DAgger rounds (round 0: expert data)
    starts_first: int = 3000  # starts labelled in round 0
    starts_round: int = 1500  # starts the student is rolled out from in each later round
    rollout_strides: int = 6  # strides of a student rollout (states past `safe` are labelled)
    hidden: tuple = (128, 128)
    epochs: int = 60
    batch: int = 256
    lr: float = 3e-3
    seed: int = 0


@dataclass
class FinetuneConfig:
    timesteps: int = 300_000
    n_envs: int = 8
    n_steps: int = 256
    batch_size: int = 256
    n_epochs: int = 5
    learning_rate: float = 1e-4
    clip_range: float = 0.1
    ent_coef: float = 0.001
    gamma: float = 0.98
    critic_warmup: int = 10  # rollouts with the actor frozen
    r_max: float = 0.45
    horizon: int = 30
    seed: int = 0
