"""The caches that keep the tests (and every run) from redoing work: YAML parsed once per text."""

from __future__ import annotations

import numpy as np
import pytest

from bound_env.files.resources import gaits_dir, parse_yaml
from bound_env.model.params import load_gait


def test_parsed_yaml_is_a_fresh_copy_each_time():
    a = parse_yaml("x: [1, 2]\ny: {z: 3}\n")
    a["x"].append(9)
    a["y"]["z"] = 0
    assert parse_yaml("x: [1, 2]\ny: {z: 3}\n") == {"x": [1, 2], "y": {"z": 3}}


def test_a_changed_gait_file_is_read_again(tmp_path):
    path = tmp_path / "g.yaml"
    text = (gaits_dir() / "default.yaml").read_text()
    path.write_text(text)
    assert load_gait(path).params.kc == 295.0
    load_gait(path).meta["eigenvalues"].clear()  # a caller's copy, not the cache's
    assert len(load_gait(path).meta["eigenvalues"]) == 6
    path.write_text(text.replace("kc: 295.0", "kc: 296.0"))  # same size, same second
    assert load_gait(path).params.kc == 296.0
    path.write_text(text.replace("kc: 295.0", "kc: [295.0"))
    with pytest.raises(ValueError, match="not valid YAML"):
        load_gait(path)


# -- the DOP853 integrator of a right-hand side, compiled once per machine -----------------------

_OSCILLATOR = """
import numba

@numba.njit(cache=True)
def oscillator(t, y, aux, out):
    out[0] = y[1]
    out[1] = -y[0]
"""

_RUN = """
import sys

import numpy as np

sys.path.insert(0, sys.argv[1])
from rhs_module import oscillator

from bound_env.model._dop853 import make_dop853

step = make_dop853(oscillator).integrate
y, t, *_ = step(0.0, np.array([1.0, 0.0]), 1.0, np.zeros(0), 1e-10, 1e-10, 10_000)
assert abs(y[0] - np.cos(1.0)) < 1e-8
print(sum(step.stats.cache_hits.values()), sum(step.stats.cache_misses.values()))
"""


def test_an_integrator_is_compiled_for_its_right_hand_side_alone():
    """A module-level right-hand side gets integrators cached on disk under its own name."""
    from bound_env.model import _dop853, fast
    from bound_env.model.dynamics import rhs

    ode = _dop853.make_dop853(rhs)
    assert ode is _dop853.make_dop853(rhs) and ode.rk_step is fast.rk_step
    for d in vars(ode).values():
        assert d.py_func.__closure__ is None  # numba keys a closure on a per-process uuid
        assert d.py_func.__qualname__.split("[")[1].startswith("bound_env.model.dynamics.rhs-")
        assert d._cache.__class__.__name__ == "FunctionCache"  # on disk


@pytest.mark.slow  # two interpreters, the first compiles the integrator (~10 s)
def test_a_second_process_loads_the_integrator_from_the_disk_cache(tmp_path):
    import os
    import subprocess
    import sys

    (tmp_path / "rhs_module.py").write_text(_OSCILLATOR)
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache")}  # starts empty
    counts = []
    for _ in range(2):
        res = subprocess.run(
            [sys.executable, "-c", _RUN, str(tmp_path)],
            env=env,
            capture_output=True,
            text=True,
            timeout=600,
            check=True,
        )
        counts.append(tuple(int(v) for v in res.stdout.split()))
    assert counts[0] == (0, 1) and counts[1] == (1, 0), counts  # compiled once, then loaded


@pytest.mark.slow  # compiles two integrators (~3 s)
def test_right_hand_sides_made_at_run_time_under_one_name_get_their_own_integrators():
    """Two functions made at run time under one name are compiled in memory, each with its own
    integrator (on disk, one would load the other's)."""
    import numba

    from bound_env.model import _dop853

    def made(k):
        @numba.njit
        def growth(t, y, aux, out):
            out[0] = k * y[0]

        return growth

    for k in (1.0, 2.0):  # y' = k y from y = 1: the first trial step of h = 0.01 / k
        start = _dop853.make_dop853(made(k)).initial_step
        assert start._cache.__class__.__name__ == "NullCache"  # in memory only
        y1, f1 = np.empty(1), np.empty(1)
        start(0.0, np.ones(1), np.full(1, k), np.zeros(0), 1e-6, 1e-6, 1.0, 1.0, y1, f1)
        assert f1[0] == pytest.approx(k * 1.01, rel=1e-12)  # f(1 + h k) of its own k
