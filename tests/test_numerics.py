"""The shared numerics (`bound_env.model.numerics`) and job files (`bound_env.files.cache`) on
known answers: linear maps, a synthetic threshold, a cache line cut short by a kill."""

from __future__ import annotations

import json
import os
import threading

import numpy as np
import pytest

from bound_env.files.cache import (
    TaskCache,
    append_line,
    atomic_path,
    atomic_write,
    read_lines,
    settings_hash,
)
from bound_env.model.numerics import (
    MapFailure,
    bisect_threshold,
    fd_jacobian,
    map_fixed_point,
    newton,
    sorted_eigenvalues,
)


def _linear_map(seed=1):
    rng = np.random.default_rng(seed)
    a = 0.4 * rng.standard_normal((4, 4)) / 2.0
    b = rng.standard_normal(4)
    return a, b, np.linalg.solve(np.eye(4) - a, b)


def test_fd_jacobian_of_a_quadratic_and_its_one_sided_fallback():
    def f(u):
        return np.array([u[0] ** 2 + u[1], 3.0 * u[0] * u[1]])

    u = np.array([0.7, -1.2])
    exact = np.array([[2 * u[0], 1.0], [3 * u[1], 3 * u[0]]])
    assert np.allclose(fd_jacobian(f, u, 1e-5), exact, atol=1e-8)

    def cut(v):  # fails to the right of u[0] (a stride that falls on one side)
        return None if v[0] > u[0] else f(v)

    one_sided = fd_jacobian(cut, u, 1e-7)
    assert np.allclose(one_sided, exact, atol=1e-5)
    with pytest.raises(MapFailure, match="component 0"):
        fd_jacobian(cut, u, 1e-7, one_sided=False)
    with pytest.raises(MapFailure, match="both sides"):
        fd_jacobian(lambda v: None if abs(v[1] + 1.2) > 0 else f(v), u, 1e-7)


def test_newton_solves_a_fixed_point_and_reports_failures():
    a, b, z_fix = _linear_map()
    out = newton(lambda z: a @ z + b - z, np.zeros(4), np.full(4, 1e-6), tol=1e-12)
    assert out.converged and out.reason == "converged"
    assert np.allclose(out.u, z_fix, atol=1e-10)
    falls = newton(lambda z: None, np.zeros(4), 1e-6)
    assert not falls.converged and falls.reason == "the start falls"
    flat = newton(lambda z: np.array([z[0] ** 2 + 1.0]), np.array([0.0]), 1e-6)
    assert not flat.converged and flat.reason.startswith("singular Jacobian")


def test_map_fixed_point_and_its_multipliers():
    a, b, z_fix = _linear_map(2)
    z, res, jac = map_fixed_point(
        lambda z: a @ z + b, z_fix + 0.5, np.full(4, 1e-4), settle=2, newton_iters=4
    )
    assert res < 1e-11 and np.allclose(z, z_fix, atol=1e-10)
    lam = sorted_eigenvalues(jac)
    assert np.allclose(np.sort_complex(lam), np.sort_complex(np.linalg.eigvals(a)), atol=1e-8)
    assert np.all(np.diff(np.abs(lam)) <= 1e-12)  # largest modulus first
    with pytest.raises(MapFailure):
        map_fixed_point(lambda z: None, z_fix, np.full(4, 1e-4))


def test_sorted_eigenvalues_puts_positive_imaginary_first():
    rot = np.array([[0.0, -0.5], [0.5, 0.0]])
    lam = sorted_eigenvalues(np.block([[rot, np.zeros((2, 1))], [np.zeros((1, 2)), 0.1]]))
    assert lam[0] == pytest.approx(0.5j) and lam[1] == pytest.approx(-0.5j)
    assert lam[2] == pytest.approx(0.1)


def test_bisect_threshold_linear_and_log():
    lin, capped = bisect_threshold(lambda s: s < 0.3, 0.0, 1.0, iters=30, log=False)
    assert not capped and 0.3 - 1e-8 < lin < 0.3
    lg, _ = bisect_threshold(lambda s: s < 0.05, 1e-3, 1.0, iters=30)
    assert 0.05 * (1 - 1e-6) < lg < 0.05
    assert bisect_threshold(lambda s: True, 1e-3, 2.0, 3) == (2.0, True)
    assert bisect_threshold(lambda s: False, 1e-3, 2.0, 3) == (0.0, False)


def test_settings_hash_depends_on_every_setting():
    a = settings_hash({"rtol": 1e-10, "budget": "quick"})
    assert a == settings_hash({"budget": "quick", "rtol": 1e-10})  # key order does not matter
    assert a != settings_hash({"rtol": 1e-9, "budget": "quick"})


def test_task_cache_skips_a_truncated_last_line_with_a_warning(tmp_path):
    path = tmp_path / "cache.jsonl"
    cache = TaskCache(path)
    cache.put("k/basin/[0, 1]", {"rel": 0.25})
    cache.put("k/basin/[0, -1]", {"rel": 0.5})
    with open(path, "a") as f:  # a kill in the middle of the third append
        f.write(json.dumps({"key": "k/curve/[0.1]", "result": {"success": 1.0}})[:17])
    with pytest.warns(RuntimeWarning, match="truncated last line"):
        again = TaskCache(path)
    assert again.get("k/basin/[0, 1]") == {"rel": 0.25} and "k/curve/[0.1]" not in again
    again.put("k/curve/[0.1]", {"success": 1.0})  # the file was cut back: appends stay clean
    lines = read_lines(path)
    assert len(lines) == 3 and json.loads(lines[-1])["result"] == {"success": 1.0}


def test_append_line_and_missing_file(tmp_path):
    assert read_lines(tmp_path / "none.csv") == []
    append_line(tmp_path / "a.csv", "x,y")
    append_line(tmp_path / "a.csv", "1,2")
    assert (tmp_path / "a.csv").read_text() == "x,y\n1,2\n"


def test_atomic_write_leaves_no_partial_file(tmp_path, monkeypatch):
    path = tmp_path / "results.json"
    atomic_write(path, '{"old": 1}')
    assert path.read_text() == '{"old": 1}'

    def killed(fd):
        raise OSError("killed while writing")

    monkeypatch.setattr(os, "fsync", killed)
    with pytest.raises(OSError, match="killed"):
        atomic_write(path, '{"new": 2, "long": "' + "x" * 10000 + '"}')
    assert path.read_text() == '{"old": 1}'  # the old file, whole
    assert sorted(p.name for p in tmp_path.iterdir()) == ["results.json"]  # no temp file
    monkeypatch.undo()
    atomic_write(path, b"\x00bytes")
    assert path.read_bytes() == b"\x00bytes"


def test_two_writers_of_one_file_both_succeed(tmp_path, monkeypatch):
    """Two threads write one file at once, both with their data written before either renames
    (a barrier in fsync): each has its own temporary file, so both succeed and the file holds
    one of the two contents, whole, with no temporary file left."""
    path = tmp_path / "results.json"
    contents = [b"a" * 1_000_000, b"b" * 2_000_000]
    barrier = threading.Barrier(2)
    fsync = os.fsync

    def fsync_together(fd):
        barrier.wait(timeout=30)
        fsync(fd)

    monkeypatch.setattr(os, "fsync", fsync_together)
    errors = []

    def write(data):
        try:
            atomic_write(path, data)
        except BaseException as e:  # noqa: BLE001 - reported by the assert below
            errors.append(e)

    threads = [threading.Thread(target=write, args=(c,)) for c in contents]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=60)
    assert errors == []
    assert path.read_bytes() in contents
    assert sorted(p.name for p in tmp_path.iterdir()) == ["results.json"]


def test_atomic_path_for_a_writer_that_wants_a_path(tmp_path):
    path = tmp_path / "anim.gif"
    with atomic_path(path, suffix=path.suffix) as tmp:
        assert tmp.parent == tmp_path and tmp.name.endswith(".gif") and tmp != path
        tmp.write_bytes(b"GIF")
    assert path.read_bytes() == b"GIF"
    with pytest.raises(ValueError, match="no writer"), atomic_path(path) as tmp:
        tmp.write_bytes(b"half")
        raise ValueError("no writer")
    assert path.read_bytes() == b"GIF"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["anim.gif"]
    mode = os.stat(path).st_mode & 0o777
    umask = os.umask(0)
    os.umask(umask)
    assert mode == 0o666 & ~umask  # the usual mode, not a private temporary file's 0600
