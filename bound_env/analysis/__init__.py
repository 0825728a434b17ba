"""Poincare analysis of the bounding gait (paper Sec. III.D and IV).

The main functions are re-exported here (``from bound_env.analysis import find_fixed_point``);
``stability`` is the module, its function is ``bound_env.analysis.stability.stability``.

Modules, read top to bottom:

- `poincare`: the map P on S_apex (eqs. 17-18), stride iteration, the paper's 100-stride
  convergence check, the apex energy.
- `stability`: nabla P by central differences (eqs. 22-23) or variational equations,
  eigenvalues and e_max, recovery from +-1 % perturbations (Fig. 6), spine oscillations
  per stride (Fig. 5).
- `fixed_point`: Newton-Raphson for P(z) = z with free parameters and pins, the paper's
  slope secant (eq. 27) and its search process (III.D.4).
- `continuation_engine`: the one continuation engine (`natural` with an ``on_stall`` hook
  for the paper's fallback ladder, pseudo-arclength `arclength`) along any scalar path.
- `continuation`: `continue_branch` in kc or alpha with fold, period-doubling and
  Neimark-Sacker flags (Figs. 3-4), its files and plot (the engine's names re-exported).
- `sweeps`: e_max against alpha and kc the paper's way, stability windows (Figs. 7-8).
- `bound_env.model.numerics` (its old name ``bound_env.analysis.numerics`` still imports):
  finite-difference Jacobian, Newton, fixed points of a map, eigenvalue sort, bisection, on
  any map ``f(z) -> z | None`` (the margins and the controllers' designs use them too);
  `bound_env.model.variational` (old name ``bound_env.analysis.variational``), the exact
  Jacobian.
- `margins` (a package): stability margins of a closed loop with any controller (basin,
  ceiling, basin stability, rough terrain and MFPT, windows, push; ``bound-env margins``).
- `paired`: paired comparisons of two closed loops scored on the same random samples
  (exact McNemar / sign test, bootstrap of the difference of r50; `bound-env compare`).
- `reproduce` (a package; `reproduce_report` is its old name for the figures and report):
  ``bound-env reproduce``, every published number measured again (Figs. 3-8,
  REPRODUCTION.md).
- `bound_env.commands.analysis_cli` (old name ``bound_env.analysis.cli``): ``bound-env
  fixed-point``, ``bound-env continue``, ``bound-env sweep``, ``bound-env reproduce``.
"""

import importlib

# Names re-exported lazily, so that ``bound_env.commands.analysis_cli`` (imported by every run of
# the ``bound-env`` command to register its sub-commands) does not load the simulator.
_EXPORTS = {
    "continuation": ("Branch", "BranchPoint", "continue_branch", "plot_branch"),
    "fixed_point": ("FixedPointResult", "find_fixed_point", "paper_search", "slope_secant"),
    "poincare": (
        "ANALYSIS_TOL",
        "IterationResult",
        "StrideFailure",
        "apex_energy",
        "iterate",
        "paper_convergence",
        "poincare_map",
    ),
    "stability": ("jacobian", "recovery", "recovery_all", "spine_oscillations"),
    "sweeps": ("SweepResult", "plot_sweep", "sweep", "write_sweep_csv"),
}
_WHERE = {name: mod for mod, names in _EXPORTS.items() for name in names}
__all__ = sorted(_WHERE)


def __getattr__(name):
    if name in _WHERE:
        return getattr(importlib.import_module(f".{_WHERE[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
