"""Shared fixtures: the gait files, the environment, the command line.

Test tiers: ``pytest -m "not slow"`` is the fast tier (physics, environment, command line;
under a minute); ``pytest`` runs everything, as ``.ci/run`` does. A test that takes more than
a few seconds is marked ``@pytest.mark.slow``. Property tests (Hypothesis) run the "fast"
profile's few examples by default and the "ci" profile's many under ``CI=1``.
"""

import os
from pathlib import Path

import pytest
from hypothesis import HealthCheck, settings

from bound_env.model.params import load_gait

# Hypothesis: a few examples per property in the fast tier, many in CI (.ci/run sets CI=1);
# HYPOTHESIS_PROFILE picks one by name. Tests that set max_examples themselves keep theirs.
_HEALTH = [HealthCheck.function_scoped_fixture, HealthCheck.too_slow]
settings.register_profile("fast", max_examples=12, deadline=None, suppress_health_check=_HEALTH)
settings.register_profile("ci", max_examples=150, deadline=None, suppress_health_check=_HEALTH)
settings.load_profile(
    os.environ.get("HYPOTHESIS_PROFILE") or ("ci" if os.environ.get("CI") else "fast")
)

ROOT = Path(__file__).resolve().parent.parent
ENV_ID = "PassiveBound-v0"


@pytest.fixture(scope="session")
def paper_gait():
    """``configs/gaits/paper.yaml``: Table II, reproducing reading, the published apex state."""
    return load_gait("paper")


@pytest.fixture(scope="session")
def default_gait():
    """``configs/gaits/default.yaml``: the paper's parameters and the model's own fixed point."""
    return load_gait("default")


@pytest.fixture(scope="session")
def literal_gait():
    """``configs/gaits/paper-literal.yaml``: Table II read literally."""
    return load_gait("paper-literal")


@pytest.fixture
def make_env():
    """``make_env(**kwargs)``: ``gym.make("PassiveBound-v0", **kwargs)``, closed afterwards."""
    import gymnasium as gym

    import bound_env

    gym.register_envs(bound_env)
    made = []

    def make(**kwargs):
        env = gym.make(ENV_ID, **kwargs)
        made.append(env)
        return env

    yield make
    for env in made:
        env.close()


@pytest.fixture
def cli(capsys):
    """``cli(*argv)``: run ``bound-env argv`` in-process -> (exit code, stdout, stderr)."""
    from bound_env.commands.cli import main

    def run(*argv):
        code = main([str(a) for a in argv])
        out = capsys.readouterr()
        return code, out.out, out.err

    return run


@pytest.fixture
def load_script():
    """``load_script(name)``: ``scripts/<name>.py`` (or ``benchmarks/<name>.py`` given as
    ``"benchmarks/<name>"``) as a fresh module, so its ``main(argv)`` runs in-process and a
    test may monkeypatch what it imports."""
    import importlib.util

    def load(name: str):
        path = ROOT / (name if "/" in name else f"scripts/{name}")
        path = path.with_suffix(".py")
        spec = importlib.util.spec_from_file_location(f"loaded_{path.stem}", path)
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
        return mod

    return load
