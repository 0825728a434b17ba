"""Stability margins of a closed loop, passive, classical or learned, on the same yardsticks.

`compute_margins` evaluates a loaded controller (the protocol under "Controllers") on
PassiveBound: the zero action, a classical controller (`bound_env.control`, designed for the
gait) or a trained policy (deterministic, with its observation normalization).
``bound-env margins --policy passive|lqr|deadbeat|damping|SPEC.yaml|PATH`` is this package
behind a thin front that lives outside the core (the agents plug-in): it loads ``--policy``
and hands the controller, and the files of its code outside bound_env/, to `compute_margins`.
A controller's optional ``on_apex(z, time_since_apex)`` is described under "Controllers".

The closed-loop apex map
------------------------
Everything below is measured on the apex-to-apex map of the closed loop, P_pi: start an
episode at an apex state z with ``reset(options={"apex_state": z})``, step the policy until
the step in which a stride completes, and read ``info["apex_z"]``. Control intervals restart
at the apex (the reset puts t = 0 there and the observation's time-since-apex at 0), so P_pi
is a well defined function of z: the same z always meets the same sequence of control
instants. (Inside one long episode the dt grid drifts against the apex, and the apex
sequence is not exactly a map of z.) Iterating the map = chaining such one-stride episodes.
With zero action P_pi is the passive Poincare map P of the paper (eq. 18), up to the
integrator tolerance (rtol = 1e-10 here).

Measures (JSON keys)
--------------------
- ``emax``, ``eigenvalues``: the closed-loop fixed point z_cl (iteration, then Newton with
  central differences through the simulator with the policy in the loop) and the eigenvalues
  of the Jacobian of P_pi there (``[re, im]`` pairs, largest modulus first);
  ``fixed_point_shift`` = z_cl - z* (SI).
- ``basin`` (a **minimal fatal shock** per axis): for each apex component i and each sign,
  the largest relative perturbation s
  such that the loop started at z_cl + s |z*_i| e_i *returns*: max_j |z_j - z_cl_j| < 1e-4
  (SI) within a bounded number of strides, without a fall. **Uncapped**: s = 1e-3 and s = 1
  are tried first; while the loop returns, the bracket grows by doubling from the last
  success, up to the direction's *physical cap*: the smallest s at which the start state
  itself is invalid (a hip or the spine joint at or below the ground, or x_dot <= 0, as
  `bound_env.model.hybrid.start_status` says), else ``BASIN_CAP`` (64 |z*_i|). Then bisection on
  log s. An entry that reaches its cap says ``capped: true`` (and ``cap``, ``cap_reason``).
  Each entry has ``rel`` (units of |z*_i|), ``abs`` (SI), ``rel_cycle`` (units of the
  component's passive peak-to-peak range, below), ``capped``, ``share`` (= abs / the
  direction's ceiling) and ``beyond``: the first failing perturbation beyond the edge (size,
  failure reason or ``no_return``, stride, phase, and geometric mechanisms of its start).
  The perturbations are relative to the *passive* z* for every controller, so the absolute
  sizes are identical.
- ``basin_scale``: the two yardsticks per component: ``zstar`` = |z*_i| (the paper-style
  scale; ``basin_min`` and ``basin_curve`` use it, as before) and ``cycle`` = the peak-to-peak
  range of the component over one passive stride of the gait (so that a step in theta1 means
  as much as a step in xdot_g). ``basin_min`` (``basin_min_direction``) is the smallest
  ``rel`` of the 12 directions, ``basin_min_cycle`` (``basin_min_cycle_direction``) the
  smallest ``rel_cycle``.
- ``basin_ceiling`` (same shape as ``basin``): for each direction the largest perturbation
  from which *some* admissible open-loop torque profile (|tau| <= max_torque, piecewise
  constant over ``PROFILE_SEG`` control intervals) completes the first ``ceiling_strides``
  strides without a fall. Searched, at each tested size, over the zero profile, the two
  constant extremes, bang-bang profiles with one switch, random piecewise-constant profiles
  and a (1+1) evolution-strategy shooting optimizer started from the best of them (budget in
  ``settings``); grown and bisected like the basin. A search can only find profiles, so the
  ceiling is a lower bound on the true one. ``mechanism`` names what stops it at the first
  failing size: geometric ("back hip below touchdown height at the apex": the back hip's
  height at the start is below l_b cos gamma_b, so the leg cannot be placed; the start state
  invalid) or "no admissible profile found" with the best profile's failure.
  ``basin_share_min`` (``basin_share_min_direction``) is the smallest basin / ceiling.
- ``basin_curve`` (a **basin stability** estimate, Menck et al. 2013): the probability of
  returning against the size r of a perturbation in a random direction: z_cl + r |z*| * u
  with u uniform on the sphere and scaled to max |u_i| = 1 (so r is the largest relative
  perturbation of any component, in the ``zstar`` scale); the same directions (``--seed``,
  default ``CURVE_SEED``: the test set) for every size and every controller; 95 % Wilson
  intervals per point (``ci_low``, ``ci_high``); ``r50`` = the size at which P(return) first
  falls below 0.5, interpolated linearly in log r between the two sizes around the crossing
  (``r50_grid``: the largest grid size up to which P >= 0.5, the earlier definition, which
  depends on the grid); ``r50_ci`` = the same crossing of the interval's bounds.
  ``outcomes``: per size, the outcome (1: returned, 0: not) from each direction, in the
  order of ``random_directions(directions, direction_seed)``, for paired comparisons of two
  controllers on the same directions (`agents.results.compare`, `bound_env.analysis.paired`).
- ``terrain``: survival of ``terrain_runs`` runs of ``terrain_strides`` strides from z_cl on
  rough terrain (``slope_noise_deg`` = sigma: the slope changes by sigma xi at every apex,
  `bound_env.model.terrain`), each run one long episode with its own seed (``TERRAIN_SEED`` + k),
  against sigma [deg], with Wilson intervals; ``terrain_sigma50_deg`` = the sigma at which the
  survival first falls below one half (log-interpolated as r50; ``terrain_sigma50_grid_deg``:
  the largest grid sigma with survival >= 1/2; ``terrain_sigma50_ci_deg`` from the interval's
  bounds).
- ``mfpt`` (the **mean first-passage time**, Byl & Tedrake 2009): for each sigma of
  ``mfpt_sigmas``, ``mfpt_robots`` runs from z_cl on rough terrain for up to
  ``mfpt_strides`` strides (env seeds from the seed's MFPT base), batched on the task's
  kernel (`rough_episodes`); with a constant per-stride hazard, MFPT = strides attempted /
  falls (``strides_total``, ``failures``; the maximum-likelihood estimate with runs censored
  at the horizon), a lower bound (``lower_bound: true``, = strides_total) with no fall, and
  an exact Poisson interval (``ci``). ``mfpt_sigma_100_deg``: the sigma at which the MFPT
  falls to 100 strides, log MFPT interpolated linearly in log sigma (None if not bracketed).
- ``slope_window_deg``, ``kc_window``: the range of slope alpha (deg), and separately of
  spine stiffness k_c (N m/rad), containing the nominal value over which the loop started at
  z_cl survives ``window_strides`` strides (50) without a fall (``gait_overrides``); edges by
  an outward doubling scan, then bisection.
- ``push``: success rate (returns, as for the basin) against the size of a kick in forward
  speed (``xdot``, m/s) and in pitch rate (``th1dot``, rad/s) added to the state at a random
  control instant within a stride of the cycle, with a random sign; ``p50`` is the largest
  size up to which the rate stays >= 50 %.
- ``effort``: mean |tau| (N m, time average) over one stride of the closed-loop cycle, and
  ``effort_frac`` = effort / max_torque.
- ``mismatch`` (with ``mismatch=``, ``--mismatch SPEC``): {spec name: block} of the margins
  under model error, each robot on its own plant with the spec's sensor noise and actuation
  delay (`bound_env.model.mismatch`): ``hold``, ``curve`` and ``r50`` (settled, not returned),
  ``mfpt``; the reference is `mismatch_tasks`' docstring, the text and the results page's
  section `mismatch_report`.
- ``seconds``, ``tasks``: the run's wall time and how many of its tasks it took from the cache
  (``cached``) and ``computed`` (a run that computed nothing timed only the assembly).
- ``fingerprint``: what decided these numbers (`fingerprint.column_fingerprint`, version 2):
  the cache key (``margins_key``) and its parts (``sources``, ``margins_settings``,
  ``budget``, ``gait``), the controller's code closure (``code``, ``constants``, from its
  ``roots``: `code_closure`), its data (``config``, ``files``), its own ``fingerprint()``
  and ``settings``, and the git ``commit`` (``dirty`` if a tracked .py file differed from it).

Controllers
-----------
`compute_margins` takes any controller object with the protocol
``__call__(obs) -> float`` (normalized torque in [-1, 1]), ``fingerprint() -> str``
(changes whenever its actions can), optional ``env_kwargs`` (environment arguments it was
made for, e.g. ``max_torque``), optional ``name`` and optional ``on_apex(z, time_since_apex)``
(called at the start apex of every episode and at every apex reached). Names and paths are
loaded by the caller (a classical controller by `bound_env.control.load_controller`).

Seeds
-----
``--seed`` (``seed``) picks every random sample: the directions, the rough-terrain runs, the
push trials and the MFPT robots (`sample_seeds`). The default (``DEFAULT_SEED`` = 12345) is
the test set that docs/MARGINS.md reports, with the samples it always had; any other seed is
a held-out (validation) set. The seed is in the JSON (``seed``, ``seed_role``) and the key.

Evaluations run through a `concurrent.futures` executor (``--workers N`` processes; any
object with ``submit`` returning futures can be passed to `compute_margins`). Every task's
result is cached in ``<out>/cache.jsonl`` under a key (`setup_key`) of the controller's
fingerprint and env kwargs, the gait's name and file contents, the budget, the seed, every
module setting that changes a result (`SETTINGS`: tolerances, seeds of the push and MFPT
samples, the ceiling search's settings), a hash of the source (`source_hash`: the code, without
docstrings and comments, of every .py file of bound_env/, this package included, and of the
files the caller passes as ``extra_sources``: code outside the project) and the controller's
code closure (`code_closure`: the project code its objects reach, e.g. a learned policy's
agents modules), so an interrupted run resumes and a changed setting or code never returns a
stale result.

Modules
-------
- `budget`: `Budget`, `BUDGETS`, the seeds and `sample_seeds`, `random_directions`;
- `closed_loop`: `ClosedLoop` (the apex map, kicks, episodes, open-loop profiles),
  `rough_episodes` (batched), `Setup` and `loop_for` (one loop per worker and setting);
  every batch of robots (``run_many``, `rough_episodes`, `mismatch_tasks.plant_runs`) runs
  through the one batched loop `bound_env.analysis.apex_loop.interval_loop`, each robot with
  a fresh controller state;
- the measures, one task each (run in worker processes): `cycle` (fixed point, multipliers,
  effort), `basin` (per axis), `ceiling`, `curve` (basin stability), `terrain` (survival and
  MFPT), `windows` (slope and k_c), `push`;
- `run`: `TASKS`, `run_task` and `compute_margins`;
- `assemble`: the JSON result from the tasks' results;
- `report`: margins.json, the CSV tables, the plots and `summary_text`;
- `stats`: Wilson and Student-t intervals, crossings on a grid, the MFPT estimate;
- `decision_times`: the controller's decision times, summarized.

Rooms (subpackages, above the measures and below `run`; old flat names such as
``bound_env.analysis.margins.provenance.keys`` stay importable, `bound_env.MOVED`):

- `provenance`: `provenance.keys`, the cache key (`SETTINGS`, `source_hash`, `setup_key`,
  `mismatch_key`); `provenance.fingerprint`, what decided a column's numbers
  (`column_fingerprint`, `stale_parts`) and a script's row (`run_fingerprint`);
  `provenance.code_closure`, a controller's code closure and the code text every code hash
  reads (`read_source`, `code_text`);
- `model_error`: `model_error.mismatch_tasks`, the model-error measures (``mm_hold``,
  ``mm_curve``, ``mm_mfpt``) and `mismatch_tasks.plant_runs`; `model_error.mismatch_report`:
  `mismatch_text`, `mismatch_markdown`; `model_error.hold_delta`: hold against the size of the
  model error, by family.
"""

from .assemble import assemble, controller_name, mfpt_curve
from .basin import (
    BASIN_CAP,
    BASIN_HI,
    BASIN_LO,
    grown_search,
    hip_thresholds,
    physical_cap,
    start_geometry,
    task_basin,
    task_basins,
)
from .budget import (
    BUDGETS,
    CURVE_SEED,
    DEFAULT_SEED,
    MFPT_CHUNK,
    MFPT_LEVEL,
    MFPT_SEED,
    PUSH_SEED,
    TERRAIN_SEED,
    WINDOW_SCAN,
    Budget,
    as_budget,
    check_seed,
    random_directions,
    sample_seeds,
)
from .ceiling import CEILING_ES, task_ceiling
from .closed_loop import (
    ENV_ID,
    EVAL_RTOL,
    PROFILE_SEG,
    PROFILE_SPAN,
    RETURN_TOL,
    ClosedLoop,
    Setup,
    StrideOut,
    apply_kick,
    loop_for,
    rough_episodes,
)
from .curve import decision_summary, task_curve
from .cycle import FD_FLOOR, FD_REL, fd_steps, task_cycle
from .push import Y_TH1DOT, Y_XDOT, task_push
from .report import Z_LABELS, Z_UNITS, column_styles, plot_margins, summary_text, write_outputs
from .run import (
    CYCLE_RECORD_DT,
    SETTINGS,
    TASKS,
    check_controller,
    compute_margins,
    cycle_scale,
    gait_key,
    run_task,
    setup_key,
    source_files,
    source_hash,
    task_key,
)
from .terrain import task_mfpt, task_terrain
from .windows import task_window

__all__ = [
    "BASIN_CAP",
    "BASIN_HI",
    "BASIN_LO",
    "BUDGETS",
    "CEILING_ES",
    "CURVE_SEED",
    "CYCLE_RECORD_DT",
    "DEFAULT_SEED",
    "ENV_ID",
    "EVAL_RTOL",
    "FD_FLOOR",
    "FD_REL",
    "MFPT_CHUNK",
    "MFPT_LEVEL",
    "MFPT_SEED",
    "PROFILE_SEG",
    "PROFILE_SPAN",
    "PUSH_SEED",
    "RETURN_TOL",
    "SETTINGS",
    "TASKS",
    "TERRAIN_SEED",
    "WINDOW_SCAN",
    "Y_TH1DOT",
    "Y_XDOT",
    "Z_LABELS",
    "Z_UNITS",
    "Budget",
    "ClosedLoop",
    "Setup",
    "StrideOut",
    "apply_kick",
    "as_budget",
    "assemble",
    "check_controller",
    "check_seed",
    "compute_margins",
    "controller_name",
    "cycle_scale",
    "decision_summary",
    "fd_steps",
    "gait_key",
    "grown_search",
    "hip_thresholds",
    "loop_for",
    "mfpt_curve",
    "physical_cap",
    "column_styles",
    "plot_margins",
    "random_directions",
    "rough_episodes",
    "run_task",
    "sample_seeds",
    "setup_key",
    "source_files",
    "source_hash",
    "start_geometry",
    "summary_text",
    "task_basin",
    "task_basins",
    "task_ceiling",
    "task_curve",
    "task_cycle",
    "task_key",
    "task_mfpt",
    "task_push",
    "task_terrain",
    "task_window",
    "write_outputs",
]
