"""The ``--policy`` argument of the agents' commands (``rollout``, ``margins``, ``compare``,
``basin-map``, ...): its help text and the folder name a policy's outputs go under."""

from __future__ import annotations

from pathlib import Path

from bound_env.files.resources import controllers_dir

from .policy_table import names_text

# the classical controllers by name: the specs in configs/controllers/ (a cheap glob: the help
# is built on every start of bound-env)
_CONTROLLER_NAMES = ", ".join(sorted(p.stem for p in controllers_dir().glob("*.yaml")))
POLICY_HELP = (
    "'passive', a shipped policy (" + names_text("'") + "; 'default' is the learned "
    "controller chosen on validation), a classical controller (" + _CONTROLLER_NAMES + ": "
    "bound_env.control, or a controller spec .yaml), or a path: a run/policy folder, a "
    "model .zip, an rl-zoo3 run folder (archived policies: agents/policies/archive/NAME); "
    "any stride controller's name + '+of' (e.g. 'default+of', 'mpc+of') holds the robot's own "
    "cycle (bound_env.control.offset_free)"
)


def policy_label(policy: str) -> str:
    """A folder name for a policy given by name or path."""
    from .policy import policy_names

    return policy if policy in policy_names() else Path(policy).resolve().name


def check_run_arguments(ap, policies, specs, skip=()) -> None:
    """A script's ``--policy`` and ``--mismatch`` values, before any run: every policy loads
    (but those in ``skip``) and every model-error spec reads, else ``ap.error`` naming the
    option and the value (a one-line usage error, exit 2)."""
    from bound_env.model.mismatch import as_spec

    from .policy import load_controller

    for spec in specs:
        try:
            as_spec(spec)
        except ValueError as e:
            ap.error(f"--mismatch {spec}: {e}")
    for policy in policies:
        if policy in skip:
            continue
        try:
            load_controller(policy)
        except (OSError, ValueError) as e:
            ap.error(f"--policy {policy}: {e}")
