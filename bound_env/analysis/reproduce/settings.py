"""How much work the reproduction does, and its tolerances."""

from __future__ import annotations

from dataclasses import dataclass

CACHE_VERSION = 1
FP_TOL = 1e-11  # Newton tolerance for the fixed points reported (|P(z) - z|, SI)
RELAXED_LEG_FRAC = 0.05  # min_leg_frac used to explore the literal reading (diagnostic only)

# Continuation settings of the stages (units of each path's own coordinate s)
STIFF_ALPHA0_DEG = 0.01  # slope [deg] the stiff-spine start's Newton starts from
ARC_STEP_MAX = 4  # the published energy level: largest arclength step / first step (ln kc)
HOMOTOPY_DS, HOMOTOPY_DS_MAX = 0.02, 0.1  # literal homotopy, lambda from 0 (reproducing) to 1
LITERAL_ALPHA_DS, LITERAL_ALPHA_DS_MAX = 0.1, 0.5  # literal: alpha back to the published [deg]
LITERAL_PATH_STEP = 0.05  # literal: first step of the path to stiffer spines (ln kc)
CLOSEST_BOUNDS = {"alpha_deg": (1.85, 2.00), "kc": (286.0, 300.0)}  # closest-z* search ranges
CLOSEST_KC_XATOL = 100  # the kc search tolerance is this x the alpha search's
MULTISTART_REL = (0.02, 0.05, 0.05, 0.1, 0.2, 0.3)  # literal: relative spread near z_published
MULTISTART_WIDE = (0.02, 4.0, 8.0, 0.5, 100.0, 150.0)  # ... absolute spread (paper units)
MULTISTART_SEED = 0
LITERAL_RECORD_DT = 1e-3  # sampling of the literal stride from z_published [s]


@dataclass(frozen=True)
class Budget:
    """How much work each stage does. ``full`` is the committed report; ``quick`` the tests."""

    name: str = "full"
    alpha_sweep: tuple = (1.80, 2.10, 0.005)  # from, to, step [deg]
    kc_sweep: tuple = (280.0, 320.0, 0.5)  # [N m/rad]
    refine: int = 6  # bisections of each window edge
    coarse_sweeps: bool = True  # repeat the sweeps with twice the step (criterion vs. step)
    search_xatol: float = 1e-6  # closest-alpha search tolerance [deg]; kc uses x 100
    kc_stiff: float = 20000.0  # the stiff spine [N m/rad]
    path_step: float = 0.02  # first step of the natural paths in ln kc
    path_step_max: float = 0.02
    arc_step: float = 0.01  # pseudo-arclength step (ln kc units)
    family_step: float = 0.01  # forward-speed step of the stiff-family scan [m/s]
    family_max: int = 100  # points per direction in that scan
    literal_starts: int = 100  # multi-start Newton under the literal reading
    literal_kc_max: float = 20000.0  # the literal paper-path goes this stiff
    record_dt: float = 5e-4  # sampling of the periodic stride (Fig. 5) [s]


FULL = Budget()
QUICK = Budget(
    name="quick",
    alpha_sweep=(1.80, 2.10, 0.05),
    kc_sweep=(280.0, 320.0, 5.0),
    refine=1,
    coarse_sweeps=False,
    search_xatol=1e-3,
    kc_stiff=2000.0,
    path_step=0.3,
    path_step_max=0.5,
    arc_step=0.1,
    family_step=0.1,
    family_max=6,
    literal_starts=6,
    literal_kc_max=2000.0,
    record_dt=2e-3,
)
