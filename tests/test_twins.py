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
