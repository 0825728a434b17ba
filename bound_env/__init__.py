"""Passive quadrupedal bounding with a spring-damper spine (Yamasaki et al.).

Importing the package registers these Gymnasium environments:

- ``PassiveBound-v0``: `bound_env.envs.env.PassiveBoundEnv` (with the native vector environment
  `bound_env.envs.vector.PassiveBoundVectorEnv` as its ``vector_entry_point``) on the passive gait
  of ``configs/gaits/default.yaml`` (the reproducing reading of Table II);
- ``PassiveBoundLiteral-v0``: the same classes on the *literal* reading of Table II, started on
  that reading's periodic (passively unstable) gait, ``gait="literal-cycle"``; its own id lets
  rl-zoo3-style configs key hyperparameters by it;
- ``PassiveBound-v1``, ``PassiveBoundLiteral-v1``: the same envs with the defaults of the
  published task, the one every shipped policy and controller acts in and every published
  margin was measured in (`PUBLISHED_TASK`: ``max_torque`` 80 N m; dt 0.01 s, rtol 1e-10 and
  the full observation as in v0), so that ``gym.make("PassiveBound-v1")`` and a shipped
  policy (`agents.runtime.rollout.load_policy`) fit as they are. v0 stays registered unchanged
  (40 N m; code and configs name it with their kwargs);
- ``PassiveBoundStride-v1``: the stride-level `bound_env.envs.stride_env.PassiveBoundStrideEnv`
  (one step = one stride of the step env, through the one stride map `bound_env.sim.stride_map`;
  v0, on exact window edges, is no longer registered: Gymnasium names v1 when v0 is asked);
- ``PassiveBoundRescue-v0``: `bound_env.envs.rescue_env.PassiveBoundRescueEnv`, the rescue task
  (starts past the LQR's safe radius, a stride per step, a return ends the episode), with
  continuous profile actions; `bound_env.envs.wrappers.LibraryActions` gives the profile
  library's discrete actions. Deprecated: it warns when made and goes in the next release
  (use v1);
- ``PassiveBoundRescue-v1``: `bound_env.envs.rescue_env.PassiveBoundRescueV1Env`, the same task
  paying for a return only (optional potential-based shaping), with an O(1) observation, a
  start-radius curriculum and an optional residual on the LQR's plan: the one standard RL
  learns.

```python
import gymnasium as gym
import bound_env

gym.register_envs(bound_env)
env = gym.make("PassiveBound-v1")  # the published task (v0: the same at 40 N m)
```

Gymnasium itself is imported lazily by those modules; the simulator (`bound_env.model.params`,
`bound_env.model.stride`, `bound_env.model.fast`) never needs it.

The package in rooms by job, lowest first (imports point down only, ``tests/test_layers.py``):

- `bound_env.files`: file schemas and value checks, the task cache, package resources, layouts;
- `bound_env.model`: the paper's model, its integrators, the stride, terrain and model error,
  the numerics on any map and the stride's exact Jacobian;
- `bound_env.sim`: the task and its kernels, the stride map and protocol, the process pool;
- `bound_env.analysis` and `bound_env.control`, side by side (neither imports the other): the
  Poincaré tools, the margins, the reproduction; the classical controllers;
- `bound_env.envs`: the Gymnasium envs, their wrappers and rendering;
- `bound_env.commands`: the ``bound-env`` command line.

The modules' old flat names (``bound_env.task``, ``bound_env.stride_map``, ...) stay importable
as aliases of the same module objects (`MOVED`): run configs naming
``bound_env.wrappers.RandomizedPlant``, Gymnasium entry points such as
``bound_env.env:PassiveBoundEnv``, the ``bound_env.cli:main`` console script of an older
install, pickles and users' scripts keep working. So do the old names of the modules that moved
into rooms of ``analysis/margins`` (``provenance``, ``model_error``) and
``analysis/reproduce`` (``document``), such as ``bound_env.analysis.margins.keys``. New code
imports the room's path.
"""

import importlib
import importlib.abc
import importlib.util
import sys

from .files.resources import configure_numba_cache

configure_numba_cache()  # before any compiled module is imported (see its docstring)

_ROOMS = {
    "model": "params dynamics events hybrid reference _dop853 fast stride terrain mismatch",
    "sim": "task task_kernels stride_map stride_task stride_protocol parallel",
    "envs": (
        "env stride_env vector rescue_common rescue_v0 rescue_v1 rescue_env wrappers randomized "
        "render"
    ),
    "commands": "cli cli_args render_cli",
    "files": "schema cache resources layout",
}
# old module name -> its module now
MOVED = {
    f"bound_env.{m}": f"bound_env.{room}.{m}" for room, ms in _ROOMS.items() for m in ms.split()
}
MOVED["bound_env.analysis.cli"] = "bound_env.commands.analysis_cli"
MOVED["bound_env.analysis.numerics"] = "bound_env.model.numerics"
MOVED["bound_env.analysis.variational"] = "bound_env.model.variational"
# the crowded folders of the analysis, in rooms by job: folder -> {room: its modules}
_SUBROOMS = {
    "analysis.margins": {
        "provenance": "code_closure fingerprint keys",
        "model_error": "hold_delta mismatch_report mismatch_tasks",
    },
    "analysis.reproduce": {"document": "report report_format report_numbers report_table"},
}
MOVED |= {
    f"bound_env.{folder}.{m}": f"bound_env.{folder}.{room}.{m}"
    for folder, rooms in _SUBROOMS.items()
    for room, ms in rooms.items()
    for m in ms.split()
}


class ModuleAliases(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Imports each old name of ``moved`` (old dotted name -> the module's name now) as the
    module it moved to: the same module object (`MOVED` here, `agents.MOVED`)."""

    def __init__(self, moved: dict[str, str]):
        self.moved = moved

    def find_spec(self, fullname, path=None, target=None):
        if fullname in self.moved:
            return importlib.util.spec_from_loader(fullname, self)
        return None

    def create_module(self, spec):
        module = importlib.import_module(self.moved[spec.name])
        spec.loader_state = module.__spec__  # the import sets the alias's spec on the module
        return module

    def exec_module(self, module):
        module.__spec__ = module.__spec__.loader_state


def install_aliases(moved: dict[str, str]) -> None:
    """Put a `ModuleAliases` of ``moved`` first on ``sys.meta_path``, once: before an installed
    copy that still has the old files."""
    if not any(isinstance(f, ModuleAliases) and f.moved == moved for f in sys.meta_path):
        sys.meta_path.insert(0, ModuleAliases(moved))


install_aliases(MOVED)

ENV_ID = "PassiveBound-v0"
LITERAL_ENV_ID = "PassiveBoundLiteral-v0"
MAX_EPISODE_STEPS = 3000  # time limit: 30 s at the default dt = 0.01 s, ~76 passive strides
STRIDE_ENV_ID = "PassiveBoundStride-v1"
# ids that name the stride env in a trained policy's config: v0 (no longer registered) too
STRIDE_ENV_IDS = (STRIDE_ENV_ID, "PassiveBoundStride-v0")
MAX_STRIDE_EPISODE_STEPS = 100  # time limit of the stride env: 100 strides
RESCUE_ENV_ID = "PassiveBoundRescue-v0"  # no max_episode_steps: its `horizon` kwarg truncates
RESCUE_ENV_ID_V1 = "PassiveBoundRescue-v1"  # the same task paying for returns only
# kwargs of the two control-interval envs (PassiveBoundEnv) registered under their own ids.
# The published task: v1's defaults (the settings of every shipped policy and controller
# that differ from v0's); the kwargs of every control-interval env id (PassiveBoundEnv).
PUBLISHED_TASK = {"max_torque": 80.0}
ENV_ID_V1 = "PassiveBound-v1"
LITERAL_ENV_ID_V1 = "PassiveBoundLiteral-v1"
ENV_KWARGS = {
    ENV_ID: {},
    LITERAL_ENV_ID: {"gait": "literal-cycle"},
    ENV_ID_V1: dict(PUBLISHED_TASK),
    LITERAL_ENV_ID_V1: {"gait": "literal-cycle", **PUBLISHED_TASK},
}
# No reward_threshold in the specs: the return mixes an alive bonus (+1 per step) with a
# tracking cost whose size depends on the start noise and the apex scales (env kwargs), so no
# single return means "solved"; policies are judged by their stability margins
# (bound_env.analysis.margins).


def _register() -> None:
    try:
        from gymnasium.envs.registration import register, registry
    except ModuleNotFoundError:  # the simulator works without Gymnasium
        return
    for env_id, kwargs in ENV_KWARGS.items():
        if env_id not in registry:
            register(
                id=env_id,
                entry_point="bound_env.envs.env:PassiveBoundEnv",
                vector_entry_point="bound_env.envs.vector:PassiveBoundVectorEnv",
                max_episode_steps=MAX_EPISODE_STEPS,
                kwargs=dict(kwargs),
            )
    if STRIDE_ENV_ID not in registry:
        register(
            id=STRIDE_ENV_ID,
            entry_point="bound_env.envs.stride_env:PassiveBoundStrideEnv",
            max_episode_steps=MAX_STRIDE_EPISODE_STEPS,
        )
    if RESCUE_ENV_ID not in registry:
        register(id=RESCUE_ENV_ID, entry_point="bound_env.envs.rescue_v0:PassiveBoundRescueEnv")
    if RESCUE_ENV_ID_V1 not in registry:
        register(
            id=RESCUE_ENV_ID_V1, entry_point="bound_env.envs.rescue_v1:PassiveBoundRescueV1Env"
        )
    # v0 is not out of date: it is the same env at 40 N m, which code, configs and published
    # commands name with their kwargs; Gymnasium's "consider upgrading to v1" would be noise.
    # PassiveBoundRescue-v0 stays the task of `bound-env finetune` (v1 is the one for RL)
    import warnings

    warnings.filterwarnings(
        "ignore",
        message=r".*The environment PassiveBound(Literal|Rescue)?-v0 is out of date",
        category=DeprecationWarning,
    )


_register()
