"""PPO spine controllers for PassiveBound and the stability margins they buy, in rooms by job.

- `agents.cli`, `agents.multiseed`: the ``bound-env`` commands of this package; several seeds
  of one recipe;
- `agents.results`: the results page and the margins commands (``bound-env margins``,
  ``compare``, ``basin-map``, ``demo``);
- `agents.training`: PPO from rl-zoo3-style configs (``configs/ppo.yaml``), ``bound-env train``,
  its callbacks, checkpoints and resume;
- `agents.experts`: learning from an expert controller (``bound-env distill``, ``finetune``,
  residual policies);
- `agents.runtime`: what a ``--policy`` name loads, as a fast NumPy controller;
- `agents.common`: what every room shares (run configs, policy files, networks, wrappers).

Imports point down only: ``cli`` -> ``multiseed`` -> ``results`` -> ``training``, ``experts``
-> ``runtime`` -> ``common`` (``tests/test_layers.py``).

The modules' old flat names (``agents.policy``, ``agents.wrappers``, ...) stay importable as
aliases of the same module objects (`MOVED`): users' scripts, run configs naming
``agents.wrappers.PerturbedStarts`` and the shipped policies' pickled classes
(``agents.stride.ZeroActionNet``) keep loading.

``PassiveBoundLiteral-v0`` (``PassiveBound-v0`` on the *literal* reading of Table II, started on
that reading's periodic gait) is registered by `bound_env` itself, beside ``PassiveBound-v0``.
"""

from bound_env import (
    LITERAL_ENV_ID,  # noqa: E402,F401 - kept here for older imports
    install_aliases,
)

_ROOMS = {
    "results": (
        "basin_cli compare decisions demo formatting headline margins margins_cli page "
        "page_inputs page_tables prose provenance table_split"
    ),
    "training": "checkpoints train train_callbacks warmstart",
    "experts": "distill finetune learn_cli stride_validation",
    "runtime": (
        "controllers names policy policy_args policy_table residual rollout stride stride_policy"
    ),
    "common": "config learn_config mlp policy_files run_files schema wrappers",
}
# old flat module name -> its module now
MOVED = {f"agents.{m}": f"agents.{room}.{m}" for room, ms in _ROOMS.items() for m in ms.split()}


install_aliases(MOVED)  # bound_env's finder: old names are the same module objects


def register_envs() -> None:
    """Register ``PassiveBoundLiteral-v0`` (idempotent; `bound_env` registers it on import)."""
    import bound_env

    bound_env._register()
