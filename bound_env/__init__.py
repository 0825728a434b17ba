"""Passive quadrupedal bounding with a spring-damper spine (Yamasaki et al.).

Importing the package registers the Gymnasium environment ``PassiveBound-v0``
(`bound_env.env.PassiveBoundEnv`, with the native vector environment
`bound_env.vector.PassiveBoundVectorEnv` as its ``vector_entry_point``) and the stride-level
``PassiveBoundStride-v0`` (`bound_env.stride_env.PassiveBoundStrideEnv`, one step = one
stride)::

    import gymnasium as gym
    import bound_env

    gym.register_envs(bound_env)
    env = gym.make("PassiveBound-v0")

Gymnasium itself is imported lazily by those modules; the simulator (`bound_env.params`,
`bound_env.hybrid`, `bound_env.fast`) never needs it.
"""

ENV_ID = "PassiveBound-v0"
MAX_EPISODE_STEPS = 3000  # time limit: 30 s at the default dt = 0.01 s, ~76 passive strides
STRIDE_ENV_ID = "PassiveBoundStride-v0"
MAX_STRIDE_EPISODE_STEPS = 100  # time limit of the stride env: 100 strides


def _register() -> None:
    try:
        from gymnasium.envs.registration import register, registry
    except ModuleNotFoundError:  # the simulator works without Gymnasium
        return
    if ENV_ID not in registry:
        register(
            id=ENV_ID,
            entry_point="bound_env.env:PassiveBoundEnv",
            vector_entry_point="bound_env.vector:PassiveBoundVectorEnv",
            max_episode_steps=MAX_EPISODE_STEPS,
        )
    if STRIDE_ENV_ID not in registry:
        register(
            id=STRIDE_ENV_ID,
            entry_point="bound_env.stride_env:PassiveBoundStrideEnv",
            max_episode_steps=MAX_STRIDE_EPISODE_STEPS,
        )


_register()
