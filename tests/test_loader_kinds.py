"""The loader's table of kinds (`agents.runtime.kinds`): every shipped kind is recognised as
its kind and loads the controller it loaded before the table (fingerprints and first actions
from tests/data/loader_reference.json, written by the loader of names.py/policy.py), and the
frozen-expert record is written byte for byte as before."""

import copy
import json
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import bound_env
from agents.runtime.kinds import KINDS, load_controller
from agents.runtime.kinds.apex import kind_of
from agents.runtime.kinds.folder import read_folder
from agents.runtime.kinds.residual import wrapped
from agents.runtime.policy_table import ARCHIVE_DIR, SHIPPED_DIR

REFERENCE = json.loads((Path(__file__).parent / "data" / "loader_reference.json").read_text())
KIND = {
    "passive": "builtin",
    "lqr": "builtin",
    "default": "choice",
    "finetuned/s1": "choice",
    "agents/policies/archive/distilled/s0": "choice",
    "adaptive/s0": "adaptive",
    "agents/policies/archive/stride-residual/s0": "stride",
    "step-ppo/s0": "residual",
    "ppo-v1-final/s0": "step",
    "literal-cycle": "step",
}


@pytest.mark.parametrize("name", sorted(KIND))
def test_each_shipped_policy_is_recognised_as_its_kind(name):
    folder = read_folder(name)
    assert kind_of(folder, KINDS, wrapped=wrapped).NAME == KIND[name]


@pytest.mark.parametrize("name", sorted(REFERENCE["policies"]))
def test_shipped_policies_load_the_controllers_they_loaded_before(name):
    want = REFERENCE["policies"][name]
    ctrl = load_controller(name)
    assert type(ctrl).__name__ == want["type"]
    assert ctrl.fingerprint() == want["fingerprint"]
    gym.register_envs(bound_env)
    acts = []
    for obs in REFERENCE["obs"]:
        c = copy.deepcopy(ctrl)
        if hasattr(c, "reset"):
            c.reset()
        acts.append(float(c(np.asarray(obs))))
    assert acts == want["actions"]  # exactly: the same arrays, the same arithmetic


def test_the_folder_is_read_once():
    folder = read_folder("step-ppo/s0")
    assert folder.path == SHIPPED_DIR / "step-ppo" / "s0"
    assert {"model.zip", "config.yaml", "fingerprint.json"} <= folder.names
    assert folder.files is folder.files and folder.run is folder.run  # read once, kept
    assert folder.env_id == "PassiveBound-v0" and "env_wrapper" in folder.section


@pytest.mark.parametrize("kind", ["finetuned/s0", "adaptive/s0"])
def test_frozen_expert_record_is_written_byte_for_byte(tmp_path, kind):
    """Re-saving a shipped student from its loaded controller writes its config.json as
    shipped (written by the two save_policy functions before their record was shared)."""
    from agents.runtime import adaptive_policy, choice_policy

    src = SHIPPED_DIR / kind
    cfg = json.loads((src / "config.json").read_text())
    ctrl = load_controller(kind)
    expert = choice_policy.expert_of(cfg["expert"])
    expert.name = cfg["expert"]["name"]
    if kind.startswith("adaptive"):
        rest = {k: v for k, v in cfg.items() if k not in ("kind", "expert", "factor_keys")}
        rest = {k: v for k, v in rest.items() if k not in ("factor_range", "gate_surprise")}
        adaptive_policy.save_policy(tmp_path, expert, ctrl, rest)
    else:
        rest = {k: v for k, v in cfg.items() if k not in ("kind", "expert")}
        choice_policy.save_policy(tmp_path, expert, ctrl.layers, ctrl.rows, rest)
    assert (tmp_path / "config.json").read_bytes() == (src / "config.json").read_bytes()


def test_rescue_env_kwargs_hold_the_frozen_lqr():
    from agents.experts.finetune import rescue_env_kwargs

    student = load_controller(ARCHIVE_DIR / "distilled" / "s0")
    cfg = json.loads((ARCHIVE_DIR / "distilled" / "s0" / "config.json").read_text())
    frozen = {k: cfg["expert"][k] for k in ("gait", "basis", "K", "max_torque", "dt", "gain")}
    kwargs = rescue_env_kwargs(student, r_max=0.4, horizon=20)
    assert list(kwargs) == [*frozen, "safe", "r_max", "horizon"]  # the order gym.make saw
    assert {k: kwargs[k] for k in frozen} == frozen
    assert (kwargs["safe"], kwargs["r_max"], kwargs["horizon"]) == (student.safe, 0.4, 20)


def test_old_import_paths_name_the_same_functions():
    import agents.runtime.names as names
    import agents.runtime.policy as policy
    from agents.runtime.kinds import apex, folder, step

    assert policy.load_controller is load_controller
    assert names.load_apex_controller is apex.load_apex_controller is policy.load_apex_controller
    assert names.resolve_policy is folder.resolve_policy is policy.resolve_policy
    assert names.CONTROLLERS is folder.CONTROLLERS
    assert policy.check_spaces is step.check_spaces
    assert policy.controller_wrapper is step.controller_wrapper
