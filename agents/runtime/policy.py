"""Controllers for evaluation by name or path: `load_controller`.

``--policy`` takes a built-in controller's name (`CONTROLLERS`: ``passive`` and the classical
controllers of `bound_env.control`), a shipped policy's name (`shipped_policies`) or a path.
A trained PPO policy is a saved SB3 PPO model (``model.zip``), its ``VecNormalize`` statistics
(``vecnormalize.pkl``) and its run config (``config.yaml``, for the environment keyword
arguments it was trained with: ``max_torque``, ``dt``, ...; `agents.common.policy_files`).
`load_controller` reads them once (with torch) and returns an `MLPController`
(`agents.runtime.controllers`): the deterministic action
``clip(action_net(policy_net(normalize(obs))), -1, 1)``, exactly what
``model.predict(obs, deterministic=True)`` returns after ``VecNormalize.normalize_obs``, but
evaluated with NumPy in float64 (~10 us instead of ~150 us per call), picklable, and free of
torch in the worker processes of the margins (`bound_env.analysis.margins`). Every kind of
policy (built-in name or spec, choice and adaptive students, stride policy, residual, plain SB3)
is recognised, checked and loaded by its module in `agents.runtime.kinds`; this module keeps the
loader's names importable from here as before.
"""

from __future__ import annotations

from pathlib import Path

from ..common.policy_files import (  # noqa: F401 - the policy-file API, importable from here as before
    DYNAMICS_KWARGS,
    FINGERPRINT_FILE,
    FINGERPRINTED_SETTINGS,
    SHIPPED,
    PolicyFiles,
    check_base_pin,
    check_policy_files,
    file_sha256,
    find_policy_files,
    load_vecnormalize,
    policy_content_sha256,
    read_policy_section,
    read_run_config,
    refuse_privileged,
    resolve_policy_files,
    section_env_kwargs,
    source_name,
    write_fingerprint,
)
from ..common.schema import check_env_kwargs, check_layers, check_obs_stats, read_fingerprint  # noqa: F401
from .controllers import MLPController, ZeroController, check_gait, same_gait  # noqa: F401 - re-exported
from .kinds import KINDS, load_controller  # noqa: F401 - the loader, importable from here as before
from .kinds.apex import load_apex_controller  # noqa: F401
from .kinds.folder import (  # noqa: F401 - the names API, importable from here as before
    CONTROLLERS,
    SHIPPED_DIR,
    classical_controller,
    policy_names,
    register_controller,
    resolve_policy,
    shipped_policies,
    unwrapped_name,
    wrapped_policy,
)
from .kinds.step import (  # noqa: F401 - the step kind's parts, importable from here as before
    check_env_id,
    check_spaces,
    controller_wrapper,
    read_vecnormalize,
    residual_base,
)


def base_pin(base) -> dict:
    """``{"policy": base, "sha256": ...}``: the content of a residual's base controller now
    (`agents.common.policy_files.policy_content_sha256`), what its fingerprint pins."""
    return {"policy": str(base), "sha256": policy_content_sha256(resolve_policy(base))}


def write_policy_fingerprint(folder) -> Path:
    """`agents.common.policy_files.write_fingerprint` of a saved PPO policy, with the pin of its
    base controller when its ``config.yaml`` trains a residual over one (`residual_base`): written
    at the end of training and at export, so a base changed later is refused at load."""
    folder = Path(folder)
    base = None
    if (folder / "config.yaml").is_file():
        files = PolicyFiles(folder / "model.zip", None, folder / "config.yaml")
        name = residual_base(read_policy_section(files)[0])
        base = None if name is None else base_pin(name)
    return write_fingerprint(folder, base=base)
