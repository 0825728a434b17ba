"""PPO spine controllers for PassiveBound and the stability margins they buy.

- `agents.train`: training with Stable-Baselines3 PPO from rl-zoo3-style configs
  (``configs/ppo.yaml``), ``bound-env train``;
- `agents.policy`: a trained policy (or the zero action) as a fast NumPy controller;
- `agents.margins`: basin, Floquet multipliers, slope and stiffness windows, push recovery and
  effort of a closed loop, ``bound-env margins``;
- `agents.compare`: the passive vs learned table in ``docs/MARGINS.md``, ``bound-env compare``.

Importing the package registers ``PassiveBoundLiteral-v0``: ``PassiveBound-v0`` on the
*literal* reading of Table II, started on that reading's periodic (passively unstable) gait
(``gait="literal-cycle"``), so that rl-zoo3-style configs can
key its hyperparameters by their own environment id
(``rl_zoo3 train --env PassiveBoundLiteral-v0 --gym-packages agents``).
"""

LITERAL_ENV_ID = "PassiveBoundLiteral-v0"


def register_envs() -> None:
    """Register ``PassiveBoundLiteral-v0`` (idempotent)."""
    try:
        from gymnasium.envs.registration import register, registry
    except ModuleNotFoundError:
        return
    import bound_env

    if LITERAL_ENV_ID in registry:
        return
    register(
        id=LITERAL_ENV_ID,
        entry_point="bound_env.env:PassiveBoundEnv",
        kwargs={"gait": "literal-cycle"},
        max_episode_steps=bound_env.MAX_EPISODE_STEPS,
    )


register_envs()
