"""PassiveBoundRescue-v0 and -v1: the rescue task, one step = one stride from a start past the
safe radius (the public import path of both).

The task that fine-tuning solves (`agents.experts.finetune`), public: starts beyond the safe
radius of the LQR (where the gate hands over to a learned controller), a stride of the one
stride map (`bound_env.sim.stride_map`) per step, and a return inside the safe radius ends the
episode. v0 (`PassiveBoundRescueEnv`, `bound_env.envs.rescue_v0`; deprecated, it warns when made)
pays for survival; v1 (`PassiveBoundRescueV1Env`, `bound_env.envs.rescue_v1`) pays for a return
only, so that standard RL learns to rescue. What they share (the start distribution
`sample_direction`, `sample_starts`, the LQR `rescue_lqr`, the checks, `RescueBase`) is
`bound_env.envs.rescue_common`; everything is importable from here as before.
"""

from .rescue_common import (  # noqa: F401 - the rescue task's API, importable from here
    ACTION_MODES,
    DEFAULT_AXIS_PROB,
    DEFAULT_CONTROLLER,
    DEFAULT_GAMMA,
    DEFAULT_HORIZON,
    DEFAULT_R_MAX,
    DEFAULT_RESIDUAL_SCALE,
    MAX_R,
    MAX_SHAPING,
    MAX_START_DRAWS,
    RescueBase,
    check_start_radius,
    number_in,
    rescue_lqr,
    sample_direction,
    sample_starts,
)
from .rescue_v0 import DEPRECATION, PassiveBoundRescueEnv  # noqa: F401
from .rescue_v1 import PassiveBoundRescueV1Env  # noqa: F401
