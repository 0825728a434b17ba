"""Wrappers of the bound_env environments.

`LibraryActions`: the discrete actions of the rescue task (`PassiveBoundRescue-v0`): a row of
a fixed library of stride profiles, row 0 the LQR's own plan at the current apex state.

    import gymnasium as gym
    import bound_env
    from bound_env.envs.wrappers import LibraryActions

    gym.register_envs(bound_env)
    env = LibraryActions(gym.make("PassiveBoundRescue-v0"))  # Discrete(66)
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np

from ..control.mpc import library
from ..files.schema import integer, real_array

LIBRARY_N_RANDOM = 48  # random sign rows of the default library (distillation's default)
LIBRARY_SEED = 5  # their generator's seed (distillation's default)


def default_library(K: int, n_random: int = LIBRARY_N_RANDOM, seed: int = LIBRARY_SEED):
    """The library the distilled controllers choose from (`bound_env.control.mpc.library`
    without noise rows): row 0 a placeholder (zeros) for the LQR's plan, then zero, +-1, the
    2 (K - 1) one-switch bang-bang profiles and ``n_random`` random sign vectors of
    ``seed``; (4 + 2 (K - 1) + n_random, K)."""
    return library(K, np.zeros(K), np.random.default_rng(seed), n_random, 0, 0.0)


class LibraryActions(gym.ActionWrapper, gym.utils.RecordConstructorArgs):
    """``Discrete(len(rows))`` actions for an env whose action is the coefficients of a stride
    profile (`PassiveBoundRescue-v0`, `PassiveBoundRescue-v1` with ``action_mode="direct"``):
    action 0 plays the LQR's plan at the current apex state as observed
    (``env.unwrapped.lqr.coefficients(env.unwrapped.z_observed)``: the true state, or under
    `bound_env.envs.randomized.RandomizedPlant`'s sensor noise the noisy one, in either order of
    the two wrappers), action j > 0 the row ``rows[j]`` (row 0 of ``rows`` is not used).
    ``rows`` defaults to `default_library`; rows must be finite, within [-1, 1], and have one
    column per coefficient. An env whose action is a residual on the LQR's plan (v1's
    ``action_mode="lqr_residual"``) is refused in one line: row 0 would play the plan twice.

    An action is one integer in [0, len(rows)) (a Python or numpy integer, or a numpy array
    holding one); a bool, a float (``1.5``, ``inf``, even ``2.0``) or a row out of range is
    refused with a ValueError naming the action. The wrapper records its constructor's
    arguments (`gymnasium.utils.RecordConstructorArgs`), so ``gymnasium``'s ``check_env`` and
    ``gym.make(env.spec)`` can recreate it.
    """

    def __init__(self, env: gym.Env, rows=None):
        gym.utils.RecordConstructorArgs.__init__(self, rows=rows)
        gym.ActionWrapper.__init__(self, env)
        if not isinstance(env.action_space, gym.spaces.Box) or env.action_space.shape is None:
            raise ValueError(  # e.g. a LibraryActions already: its actions are rows, not a profile
                f"LibraryActions needs an env whose action is a profile's coefficients (a Box), "
                f"got {env.action_space}: wrap the env once"
            )
        base = env.unwrapped
        if not (hasattr(base, "lqr") and hasattr(base, "z")):
            raise ValueError("LibraryActions needs an env with an LQR and an apex state z "
                             "(PassiveBoundRescue-v0)")  # fmt: skip
        if getattr(base, "action_mode", "direct") != "direct":
            raise ValueError(
                f"LibraryActions plays whole profiles; this env's action_mode="
                f"{base.action_mode!r} takes a residual on the LQR's plan (row 0 would play "
                "it twice): make the env with action_mode='direct'"
            )
        K = int(env.action_space.shape[0])
        if rows is None:
            rows = default_library(K)
        self.rows = real_array(rows, "LibraryActions rows", shape=(None, K), lo=-1.0, hi=1.0)
        self.action_space = gym.spaces.Discrete(len(self.rows))

    def action(self, action) -> np.ndarray:
        a = action
        if isinstance(a, np.ndarray) and a.size == 1 and a.dtype.kind in "iu":
            a = a.reshape(()).item()  # SB3 and vector envs pass a 0-d or (1,) array
        a = integer(a, "LibraryActions action")
        if not 0 <= a < len(self.rows):
            raise ValueError(f"LibraryActions action must be in [0, {len(self.rows)}), got {a}")
        if a:
            return self.rows[a].copy()
        base = self.env.unwrapped  # the LQR plans on the apex state as observed (sensor noise)
        return base.lqr.coefficients(getattr(base, "z_observed", base.z))


def __getattr__(name: str):
    """`RandomizedPlant` (`bound_env.envs.randomized`), importable from here."""
    if name == "RandomizedPlant":
        from .randomized import RandomizedPlant

        return RandomizedPlant
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
