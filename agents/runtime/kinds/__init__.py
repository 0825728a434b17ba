"""The kinds of policy ``--policy`` loads, one module per kind, and `load_controller`."""

from __future__ import annotations

from pathlib import Path

from . import residual, step
from .apex import APEX_KINDS
from .folder import read_folder, unwrapped_name, wrapped_policy
from .step import check_env_id

# every kind, in the order they are tried: each module says how a folder is recognised as its
# kind (``RECOGNISED_BY``, a cheap look at its files, `PolicyFolder.meets`), and checks and
# loads it (``load``)
KINDS = (*APEX_KINDS, residual, step)


def load_controller(
    path: str | Path,
    gait: str | Path | None = None,
    force: bool = False,
    env_id: str | None = None,
):
    """A controller from a name (`agents.runtime.kinds.folder.policy_names`) or a saved policy:
    the name or path resolved and its folder read once (`read_folder`), then loaded by the
    first kind of `KINDS` that recognises it.

    ``gait`` is passed to built-in controllers that need one; a trained policy takes its own
    from its config and refuses another one unless ``force`` (`check_gait`). ``env_id`` names
    the env a plain SB3 ``model.zip`` without ``config.yaml`` was trained on (its registered
    kwargs are the policy's env kwargs, `check_env_id`); for a policy with a config it must be
    the config's own id. Raises
    FileNotFoundError for a missing path and ValueError for a file that is not a PPO MLP
    policy for PassiveBound's observation space, or would be evaluated wrongly
    (`check_policy_files`).
    """
    text = str(path)
    if unwrapped_name(text) != text:  # NAME+of: NAME held on the robot's own cycle
        from bound_env.control.offset_free import OffsetFree
        from bound_env.control.privileged import is_privileged

        inner = wrapped_policy(text)
        ctrl = load_controller(inner, gait, force, env_id)
        if is_privileged(ctrl):  # OffsetFree never hands it the plant: it would run as mpc+of
            raise ValueError(
                f"{getattr(ctrl, 'name', inner)!r} is privileged: it is designed on the robot's "
                f"true plant and aims at that plant's own cycle already, so {text!r} has no "
                "offset to estimate (give it without +of)"
            )
        return OffsetFree(ctrl, name=text)
    if env_id is not None:
        check_env_id(env_id)
    folder = read_folder(path)  # a spec .yaml as given, else resolve_policy: once
    if env_id is not None and isinstance(folder.path, str):  # a built-in name or a spec
        raise ValueError(f"--env-id is for a trained policy's model.zip, not {str(path)!r}")
    kind = folder.kind_in(KINDS, residual.wrapped)
    if kind in APEX_KINDS:
        ctrl = kind.load(folder, gait, force)
        if env_id is not None:
            raise ValueError(
                f"--env-id {env_id}: policy {path} is a distilled student or a stride-level "
                "policy, which carries its own env id (drop --env-id)"
            )
        return ctrl
    return kind.load(folder, gait, force, env_id)
