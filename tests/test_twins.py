"""The merged twins of issue 47: one DAgger round for the two learned stride students, one
forced cycle (the learned adaptive expert's teacher uses bound_env.control.plant_design's),
one source of the learned adaptive recipe's defaults, and the learned controller's new names
beside the old ones."""

from __future__ import annotations

import json

import pytest

from agents.common.learn_config import DistillConfig


def test_claim_run_records_and_refuses_other_settings(tmp_path):
    from agents.experts.dagger import claim_run

    out = tmp_path / "run"
    claim_run(out, "distill.json", DistillConfig(seed=0), "use another --out")
    assert json.loads((out / "distill.json").read_text())["seed"] == 0
    claim_run(out, "distill.json", DistillConfig(seed=0), "use another --out")  # same: resumes
    with pytest.raises(ValueError) as e:
        claim_run(out, "distill.json", DistillConfig(seed=3), "use another --out")
    msg = str(e.value)
    assert "other settings (seed: 0 -> 3); use another --out" in msg and "\n" not in msg


def test_both_students_share_the_dagger_round():
    from agents.experts import adaptive, dagger, distill

    for name in ("claim_run", "dagger_rounds", "mpc_expert", "tanh_mlp", "train_minibatches"):
        assert getattr(distill, name) is getattr(dagger, name)
        assert getattr(adaptive, name) is getattr(dagger, name)


def test_mpc_expert_refuses_a_controller_that_is_not_an_mpc():
    from agents.experts.dagger import mpc_expert

    with pytest.raises(ValueError, match=r"^--expert 'lqr' is not an mpc controller spec$"):
        mpc_expert("lqr", "--expert")


def _recipe(name: str, seed: int = 0):
    from agents.common.config import load_hyperparams
    from agents.experts.adaptive_recipe import config_from_section

    env_id = "PassiveBoundStride-v1"
    return config_from_section(load_hyperparams(name, env_id), env_id, seed)


def test_the_recipe_yaml_holds_no_copy_of_the_code_defaults():
    """The learned adaptive recipe's defaults are written once (AdaptiveConfig): a key of the
    YAML's ``adaptive`` block is there because it differs from its default, and the recipe
    makes the settings the shipped policies were trained with (their config.json)."""
    import dataclasses

    import yaml

    from agents.common.config import resolve_config_path
    from agents.experts.adaptive import AdaptiveConfig

    section = yaml.safe_load(resolve_config_path("student-mpc-adaptive").read_text())
    block = section["PassiveBoundStride-v1"].get("adaptive") or {}
    defaults = dataclasses.asdict(AdaptiveConfig())
    copies = [k for k, v in block.items() if defaults.get(k) == (tuple(v) if k == "hidden" else v)]
    assert not copies, f"configs/student-mpc-adaptive.yaml repeats defaults: {copies}"
    from agents.runtime.policy_table import SHIPPED_DIR

    shipped = json.loads(
        (SHIPPED_DIR / "adaptive" / "s0" / "config.json").read_text()
    )["adaptive"]  # fmt: skip
    made = json.loads(json.dumps(dataclasses.asdict(_recipe("student-mpc-adaptive", 0))))
    assert made == shipped


def test_the_old_config_name_is_the_new_one():
    """``--config adaptive`` (configs/adaptive.yaml, the old name) reads the same sections as
    ``--config student-mpc-adaptive``."""
    import yaml

    from agents.common.config import config_names, resolve_config_path

    assert {"adaptive", "student-mpc-adaptive"} <= set(config_names())
    old, new = (yaml.safe_load(resolve_config_path(n).read_text())
                for n in ("adaptive", "student-mpc-adaptive"))  # fmt: skip
    assert old == new
    assert _recipe("adaptive", 2) == _recipe("student-mpc-adaptive", 2)


def test_the_learned_adaptive_controller_has_a_name_that_says_what_it_learned_from():
    """``student-mpc-adaptive/sK`` (and its ablations') is the folder ``adaptive/sK``, whose
    old name stays a name; both in ``--policy``'s help."""
    from agents.runtime.names import policy_names, resolve_policy
    from agents.runtime.policy_table import SHIPPED_DIR, names_text

    for k in range(3):
        for new, old in (
            ("student-mpc-adaptive", "adaptive"),
            ("student-mpc-adaptive-nohist", "adaptive-nohist"),
            ("student-mpc-adaptive-nominal", "adaptive-nominal"),
        ):
            assert resolve_policy(f"{new}/s{k}") == resolve_policy(f"{old}/s{k}")
            assert resolve_policy(f"{old}/s{k}") == SHIPPED_DIR / old / f"s{k}"
    assert {"student-mpc-adaptive/s0", "adaptive/s0"} <= set(policy_names())
    assert "`student-mpc-adaptive/s0`..`s2` (= `adaptive/s0`..`s2`)" in names_text()


def test_the_new_name_loads_the_same_controller():
    from agents.runtime.policy import load_controller

    a, b = load_controller("student-mpc-adaptive/s0"), load_controller("adaptive/s0")
    assert type(a) is type(b) and a.fingerprint() == b.fingerprint()
