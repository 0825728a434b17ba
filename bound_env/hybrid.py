"""The hybrid simulator's public names in one place (kept for the documented import paths).

The simulator is a one-way chain; this module only re-exports it:

- `bound_env.events`: guards, resets, status codes, stride flags, failure names, `Event`;
- `bound_env.reference`: the reference back-end (``solve_ivp``, DOP853), `simulate_reference`;
- `bound_env.fast`: the compiled back-end, `simulate_fast` and `advance`;
- `bound_env.stride`: `simulate_stride`, `StrideResult`, `Trajectory`, apex-state helpers.
"""

from .events import (
    APEX,
    CONTINUE,
    EVENT_COINCIDENCE,
    F_BACKWARD,
    F_EXT_B,
    F_EXT_F,
    F_GROUND_B,
    F_GROUND_F,
    F_GROUND_J,
    F_INTEGRATION,
    F_NO_APEX,
    F_NON_FINITE,
    F_SHORT_B,
    F_SHORT_F,
    FAIL_FIRST,
    FAILURES,
    FL_STRICT,
    FL_TOUCHED_B,
    FL_TOUCHED_F,
    G_APEX,
    G_BACKWARD,
    G_GROUND_B,
    G_GROUND_F,
    G_GROUND_J,
    G_LO_B,
    G_LO_F,
    G_SHORT_B,
    G_SHORT_F,
    G_TD_B,
    G_TD_F,
    GUARD_DIRECTION,
    GUARD_NAMES,
    N_FLAGS,
    N_GUARDS,
    PHASES,
    TIME_UP,
    Event,
    apex_armed,
    apply_events,
    coincident,
    failure_name,
    guard_values,
    phase_index,
    start_status,
)
from .fast import simulate_fast
from .reference import (
    REFERENCE_H_MIN,
    REFERENCE_MAX_STEPS,
    REFERENCE_WALL_S,
    simulate_reference,
)
from .stride import (
    DEFAULT_T_MAX,
    StrideResult,
    Trajectory,
    phases_from_events,
    simulate_stride,
    state_from_z,
    z_from_state,
)

__all__ = [
    "APEX", "CONTINUE", "EVENT_COINCIDENCE", "F_BACKWARD", "F_EXT_B", "F_EXT_F", "F_GROUND_B",
    "F_GROUND_F", "F_GROUND_J", "F_INTEGRATION", "F_NO_APEX", "F_NON_FINITE", "F_SHORT_B",
    "F_SHORT_F", "FAIL_FIRST", "FAILURES", "FL_STRICT", "FL_TOUCHED_B", "FL_TOUCHED_F", "G_APEX",
    "G_BACKWARD", "G_GROUND_B", "G_GROUND_F", "G_GROUND_J", "G_LO_B", "G_LO_F", "G_SHORT_B",
    "G_SHORT_F", "G_TD_B", "G_TD_F", "GUARD_DIRECTION", "GUARD_NAMES", "N_FLAGS", "N_GUARDS",
    "PHASES", "TIME_UP", "Event", "apex_armed", "apply_events", "coincident", "failure_name",
    "guard_values", "phase_index", "start_status", "simulate_fast", "simulate_reference",
    "REFERENCE_H_MIN", "REFERENCE_MAX_STEPS", "REFERENCE_WALL_S",
    "DEFAULT_T_MAX", "StrideResult", "Trajectory", "phases_from_events", "simulate_stride",
    "state_from_z", "z_from_state",
]
