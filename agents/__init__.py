"""PPO spine controllers for PassiveBound and the stability margins they buy.

- `agents.train`: training with Stable-Baselines3 PPO from rl-zoo3-style configs
  (``configs/ppo.yaml``), ``bound-env train``; its callbacks (`agents.train_callbacks`),
  checkpoints (`agents.checkpoints`) and a run folder's other files (`agents.run_files`);
- `agents.policy`: a trained policy (or the zero action) as a fast NumPy controller;
- `agents.margins`: ``bound-env margins``, the front that loads a policy for
  `bound_env.analysis.margins` (basin, Floquet multipliers, slope and stiffness windows, push
  recovery and effort of a closed loop);
- `agents.compare`: the passive vs learned table in ``docs/MARGINS.md``, ``bound-env compare``.

``PassiveBoundLiteral-v0`` (``PassiveBound-v0`` on the *literal* reading of Table II, started on
that reading's periodic gait) is registered by `bound_env` itself, beside ``PassiveBound-v0``.
"""

from bound_env import LITERAL_ENV_ID  # noqa: E402,F401 - kept here for older imports


def register_envs() -> None:
    """Register ``PassiveBoundLiteral-v0`` (idempotent; `bound_env` registers it on import)."""
    import bound_env

    bound_env._register()
