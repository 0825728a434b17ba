"""rl-zoo3 reads configs/ppo.yaml as we say: its own ExperimentManager preprocessing takes the
env kwargs, wrappers and callbacks from the file (``scripts/setup.sh`` installs the ``[zoo]``
extra, so CI runs it; skipped only where rl-zoo3 is not installed)."""

from __future__ import annotations

import argparse
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


@pytest.mark.parametrize("env_id", ["PassiveBound-v0", "PassiveBoundLiteral-v0"])
def test_rl_zoo3_preprocessing_takes_env_kwargs_from_the_config(env_id, tmp_path):
    pytest.importorskip("rl_zoo3")
    from rl_zoo3.exp_manager import ExperimentManager

    import bound_env  # noqa: F401 - registers both env ids, as --gym-packages bound_env does
    from agents.common.config import DEFAULT_CONFIG, load_hyperparams
    from agents.training.train_callbacks import BasinValidationCallback, NoiseCurriculumCallback

    ours = load_hyperparams(DEFAULT_CONFIG, env_id)
    em = ExperimentManager(
        argparse.Namespace(),
        "ppo",
        env_id,
        str(tmp_path),
        config=str(ROOT / "configs" / "ppo.yaml"),
        n_timesteps=1000,
    )
    hp, _ = em.read_hyperparameters()
    _, wrapper, callbacks, _ = em._preprocess_hyperparams(hp)
    assert em.env_kwargs == ours["env_kwargs"] and em.env_kwargs  # from the file, no flag
    assert wrapper is not None
    kinds = {type(c) for c in callbacks}
    assert kinds <= {NoiseCurriculumCallback, BasinValidationCallback} and kinds
