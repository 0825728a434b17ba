"""``bound-env margins``'s front: a policy spec in, a loaded controller handed to the core.

The stability margins (the closed-loop apex map, the measures, the JSON keys, the task cache)
are `bound_env.analysis.margins`, whose docstring is the reference. This module only loads
``policy`` (`as_controller`): ``"passive"``, a classical controller's name or spec .yaml
(`bound_env.control`, through `agents.runtime.policy.load_controller`; no torch), a shipped policy's
name or a trained policy's path (`agents.runtime.policy.load_controller`, torch only while it
loads), or a controller object as it is; and it names the files that define it
(`policy_files_sha`: a spec, a policy's weights and settings), which the core records in the
column's fingerprint. The agents code a controller runs is in the core's cache key and
fingerprint through its code closure (`bound_env.analysis.margins.provenance.code_closure`),
object by object, rather than as whole files (`policy_sources`, now empty).

The names this module used to define (``ClosedLoop``, ``random_directions``, ``BUDGETS``,
``summary_text``, ...) stay importable from here for users' scripts; the project's own code
imports them from `bound_env.analysis.margins`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from bound_env.analysis import margins as core
from bound_env.analysis.margins import *  # noqa: F403 - the old names, for users' scripts
from bound_env.analysis.margins import DEFAULT_SEED, Budget, as_budget, check_seed
from bound_env.model.numerics import (  # noqa: F401 - old names, for users' scripts
    bisect_threshold,
    fd_jacobian,
    map_fixed_point,
    sorted_eigenvalues,
)
from bound_env.sim.parallel import SerialExecutor  # noqa: F401 - its old home, kept as an alias

from ..runtime.policy import load_controller

# The agents modules whose code a controller loaded here may run: the loaders (policy.py,
# policy_files.py), a trained PPO policy (controllers.py, mlp.py), a stride-level policy
# (stride.py), a distilled student (choice_policy.py). bound_env/ (the classical controllers
# included) is hashed by the core itself.
POLICY_SOURCES = (
    "runtime/policy.py",
    "common/policy_files.py",
    "runtime/controllers.py",
    "common/mlp.py",
    "runtime/stride.py",
    "runtime/choice_policy.py",
    "runtime/adaptive_policy.py",
    "runtime/residual.py",
    "common/wrappers.py",
)


def as_controller(policy, gait=None):
    """A name or a path -> `agents.runtime.policy.load_controller` (which refuses a trained policy
    on another ``gait``); an object with the controller protocol (``__call__`` and
    ``fingerprint``) is used as it is."""
    if isinstance(policy, (str, Path)):
        return load_controller(policy, gait=gait)
    if callable(policy) and callable(getattr(policy, "fingerprint", None)):
        return policy
    raise ValueError(
        f"policy must be 'passive', a policy path or a controller with __call__ "
        f"and fingerprint(), got {type(policy).__name__}"
    )


def policy_sources(controller) -> list[Path]:
    """The core's ``extra_sources`` for ``controller``: none. The agents code it runs is in
    the core's cache key and fingerprint through its code closure, object by object (the
    zero controller's closure is not ``MLPController``'s, though one module holds both);
    `POLICY_SOURCES` stays for older imports."""
    return []


def policy_files_sha(policy) -> str | None:
    """sha256 (16 hex digits) of the files that define ``policy`` (a name or a path:
    `agents.common.policy_files.policy_content_sha256`, its spec or its policy folder's
    weights and settings; ``NAME+of``: NAME's, tagged), None for a controller object or a
    name that resolves to no file."""
    if not isinstance(policy, (str, Path)):
        return None
    from ..common.policy_files import policy_content_sha256
    from ..runtime.names import resolve_policy, wrapped_policy

    text, tag = str(policy), ""
    try:
        resolved = resolve_policy(text)
    except (OSError, ValueError):
        if not text.endswith("+of"):
            return None
        text, tag = wrapped_policy(text), "+of"
        try:
            resolved = resolve_policy(text)
        except (OSError, ValueError):
            return None
    return policy_content_sha256(resolved)[:16] + tag


def fingerprint_now(policy, gait="default", budget=None, seed=None, controller=None) -> dict:
    """``policy``'s fingerprint as `compute_margins` would record it now
    (`bound_env.analysis.margins.provenance.fingerprint.column_fingerprint`; ``controller``: the
    policy already loaded), without the commit."""
    from bound_env.analysis.margins.provenance.fingerprint import column_fingerprint

    ctrl = controller if controller is not None else as_controller(policy, gait)
    return column_fingerprint(
        ctrl,
        commit=False,
        gait=gait,
        budget=budget,
        seed=seed,
        extra_sources=policy_sources(ctrl),
        files=policy_files_sha(policy),
    )


def compute_margins(
    policy="passive",
    budget: str | Budget = "quick",
    gait: str = "default",
    workers: int = 1,
    executor=None,
    out: str | Path | None = None,
    progress: bool = False,
    use_cache: bool = True,
    scheduler: str | None = None,
    seed: int = DEFAULT_SEED,
    mismatch=None,
    mismatch_budget: str | None = None,
    nominal: bool = True,
) -> dict:
    """`bound_env.analysis.margins.compute_margins` of ``policy`` (``"passive"``, a name, a
    path or a controller: `as_controller`), with its files' hash (`policy_files_sha`) in its
    fingerprint. The other arguments are the core's."""
    # the arguments' errors come before a policy is loaded
    as_budget(budget)
    if workers < 1:
        raise ValueError(f"--workers must be at least 1, got {workers}")
    check_seed(seed)
    controller = as_controller(policy, gait)
    return core.compute_margins(
        controller,
        budget=budget,
        gait=gait,
        workers=workers,
        executor=executor,
        out=out,
        progress=progress,
        use_cache=use_cache,
        scheduler=scheduler,
        seed=seed,
        extra_sources=policy_sources(controller),
        mismatch=mismatch,
        files=policy_files_sha(policy),
        mismatch_budget=mismatch_budget,
        nominal=nominal,
    )


# --------------------------------------------------------------------------------------------
# Old names of `bound_env.model.numerics` functions (they were defined here)
# --------------------------------------------------------------------------------------------


def central_jacobian(f, z, steps) -> np.ndarray:
    """Jacobian of f at z by central differences with per-component ``steps`` (no one-sided
    fallback: a failing side raises). Alias of `numerics.fd_jacobian` with ``one_sided=False``."""
    return fd_jacobian(f, z, steps, one_sided=False)


def find_fixed_point(f, z0, steps, settle: int = 60, newton_iters: int = 8, tol: float = 1e-11):
    """Old name of `bound_env.model.numerics.map_fixed_point` (returns (z, residual,
    Jacobian)); `bound_env.analysis.find_fixed_point` is the Poincare map's."""
    return tuple(map_fixed_point(f, z0, steps, settle=settle, newton_iters=newton_iters, tol=tol))
