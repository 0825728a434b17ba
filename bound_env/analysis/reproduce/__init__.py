"""``bound-env reproduce``: every published number of the paper, measured again, with evidence.

The command regenerates the analogues of Figs. 3-8 (PNG with CSV beside them) and writes
``REPRODUCTION.md``: one row per published number (paper, ours, difference, verdict, evidence
and the most likely cause of a miss), both readings of Table II side by side, the stiff-spine
path of Figs. 3-4, the literal reading's periodic gait, and the edge case of a hip below its
touchdown height.

Modules: `settings` (budgets, tolerances), `claims` (the published numbers: gait files and the
paper's claims), `store` (cache), `points`, `paths` (continuation on the one engine), one
module per stage (`reproducing`, `closest`, `windows`, `stiff`, `literal`), `figures`, the
report in its room `document` (`document.report_numbers`: the numbers it derives from the
stages; `document.report_format`: values as text; `document.report_table`: the table of every
published number; `document.report`: the other sections and the page; their old names
``bound_env.analysis.reproduce.report`` & co. stay importable), `gaits`, `pipeline` (`run`).

Stages (each cached as JSON in ``DIR/cache/<stage>-<hash>.json``, the hash of the stage's
configuration: budget, gait files, inputs from earlier stages and `CACHE_VERSION`):

1. ``reproducing``: the published gait under the reproducing reading: one stride from the
   published z*, Newton's fixed point from it, eigenvalues, recovery (Fig. 6), the periodic
   stride (Fig. 5), spine bends, theta2 amplitude, hip margins, the slope as printed in the
   text vs in the caption, c_c.
2. ``closest``: the alpha (kc fixed) and the kc (alpha fixed) whose fixed point lies closest
   to the published z* (bounded 1-D search along the branch), the sensitivity of z* to each
   published parameter within its printed rounding, and the paper's slope secant (eq. 27).
3. ``sweeps``: e_max against alpha and kc the paper's way (Figs. 7-8), windows, ds onset.
4. ``stiff``: the stiff-spine bound (kc = 20000, one-body-like) and the paths down to
   the published kc (Figs. 3-4): alpha chosen to hold the forward speed, alpha chosen to
   balance the energy (eq. 27, the paper's process, with its fallback ladder), and the
   energy level of the published gait followed upwards (pseudo-arclength in ln kc).
5. ``literal``: the literal reading: the stride from the published z*, Newton from there and
   nearby, the homotopy from the reproducing geometry, the fixed point at the published
   parameters with its eigenvalues, and the paper's path towards stiffer spines.

Units: z in SI inside, paper units [m, deg, deg, m/s, deg/s, deg/s] in the cache and report.
"""

from .claims import CLAIMS, literal_gait, published, reproducing_gait
from .closest import closest_on_branch, stage_closest
from .gaits import write_gait_files
from .literal import min_leg_fraction, stage_literal
from .paths import PathResult, arclength_path, natural_path, refine_emax_crossing
from .pipeline import run
from .points import eig_list, point_summary, rel_distance
from .reproducing import hip_margins, stage_reproducing
from .settings import CACHE_VERSION, FP_TOL, FULL, QUICK, RELAXED_LEG_FRAC, Budget
from .stiff import stage_stiff
from .store import Cache, config_hash, jsonable
from .windows import stage_sweeps

ROUNDING = CLAIMS.param_half_digit  # its name when this was one module

__all__ = [
    "CACHE_VERSION",
    "CLAIMS",
    "FP_TOL",
    "FULL",
    "QUICK",
    "RELAXED_LEG_FRAC",
    "ROUNDING",
    "Budget",
    "Cache",
    "PathResult",
    "arclength_path",
    "closest_on_branch",
    "config_hash",
    "eig_list",
    "hip_margins",
    "jsonable",
    "literal_gait",
    "min_leg_fraction",
    "natural_path",
    "point_summary",
    "published",
    "refine_emax_crossing",
    "rel_distance",
    "reproducing_gait",
    "run",
    "stage_closest",
    "stage_literal",
    "stage_reproducing",
    "stage_stiff",
    "stage_sweeps",
    "write_gait_files",
]
