"""Executors (bound_env.sim.parallel), Dask clusters with real processes, and the basin atlas.

Cluster tests bind to 127.0.0.1 on free ports, are bounded in time, and kill every process
they start (process groups, in ``finally``).
"""

from __future__ import annotations

import json
import operator
import os
import signal
import socket
import subprocess
import sys
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest

from agents.runtime.policy_table import ARCHIVE_DIR
from bound_env.commands.cli import main
from bound_env.sim.parallel import (
    MAX_RESTARTS,
    RestartingProcessPool,
    SerialExecutor,
    TasksFailed,
    check_scheduler,
    open_pool,
    run_tasks,
)

ROOT = Path(__file__).resolve().parent.parent
BIN = Path(sys.executable).parent
ENV = {**os.environ, "PYTHONPATH": str(ROOT)}
TIMEOUT_S = 600  # any single run (generous: the machine may be loaded by other jobs)


# -- the executor module -------------------------------------------------------------------------


def test_scheduler_option_is_checked():
    for ok in (None, "local", "local:2", "tcp://127.0.0.1:8786"):
        check_scheduler(ok)
    for bad in ("", "lokal", "local:0", "local:x", "127.0.0.1", "tcp://"):
        with pytest.raises(ValueError, match="--scheduler"):
            check_scheduler(bad)


def test_missing_dask_is_a_one_line_error(monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "distributed", None)  # as if not installed
    rc = main(["basin-map", "--grid", "2", "--scheduler", "local", "--out", "unused"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2
    assert len(err) == 1 and 'pip install -e ".[dask]"' in err[0], err


@pytest.mark.parametrize("workers", [1, 2])
def test_a_failing_task_is_reported_and_the_others_finish(workers, capsys):
    tasks = {f"div-{d}": (operator.truediv, (1.0, d)) for d in (1, 2, 0, 4)}
    with open_pool(None, workers) as pool:
        assert isinstance(pool.executor, SerialExecutor if workers == 1 else RestartingProcessPool)
        done, failures = run_tasks(pool.executor, tasks, desc="div")
    assert done == {"div-1": 1.0, "div-2": 0.5, "div-4": 0.25}
    assert [f.key for f in failures] == ["div-0"] and failures[0].args == (1.0, 0)
    assert "ZeroDivisionError" in failures[0].error
    err = capsys.readouterr().err
    assert "div-0" in err and "(1.0, 0)" in err and "ZeroDivisionError" in err


def _die_once(marker, x):
    """Kill this worker process (SIGKILL) the first time, return 2 x afterwards."""
    if not os.path.exists(marker):
        open(marker, "w").close()
        os.kill(os.getpid(), signal.SIGKILL)
    return 2 * x


def _die(x):
    os.kill(os.getpid(), signal.SIGKILL)


def test_process_pool_recovers_from_a_killed_worker(tmp_path, capsys):
    """A killed worker breaks a ProcessPoolExecutor for good; the local pool restarts and
    resubmits the unfinished tasks, so every result arrives; a task that kills its worker
    every time fails after MAX_RESTARTS with BrokenProcessPool, a one-line report."""
    tasks = {f"x{i}": (operator.mul, (i, 3)) for i in range(8)}
    tasks["killer"] = (_die_once, (str(tmp_path / "died"), 21))
    with open_pool(None, 2) as pool:
        done, failures = run_tasks(pool.executor, tasks, desc="kill")
        assert pool.executor.restarts == 1
        assert pool.executor.submit(operator.add, 1, 2).result(timeout=60) == 3  # still usable
    assert not failures and done == {**{f"x{i}": 3 * i for i in range(8)}, "killer": 42}
    assert "worker process died" in capsys.readouterr().err
    with open_pool(None, 2) as pool:
        done, failures = run_tasks(pool.executor, {"always": (_die, (1,))}, desc="kill")
        assert pool.executor.restarts == MAX_RESTARTS
    assert not done and [f.key for f in failures] == ["always"]
    assert "BrokenProcessPool" in failures[0].error and "restarts" in failures[0].error


# -- helpers for real clusters -------------------------------------------------------------------


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def spawn(args, log: Path) -> subprocess.Popen:
    """A process in its own process group (so that it and its children can be killed)."""
    return subprocess.Popen(
        args,
        stdout=log.open("w"),
        stderr=subprocess.STDOUT,
        env=ENV,
        cwd=ROOT,
        start_new_session=True,
    )


def run(argv, timeout=TIMEOUT_S, cwd=ROOT) -> subprocess.CompletedProcess:
    """Run a command in its own process group; the whole group (pool workers, a
    LocalCluster's processes) is killed afterwards, also on a timeout."""
    p = subprocess.Popen(
        [str(a) for a in argv],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=ENV,
        cwd=cwd,
        start_new_session=True,
    )
    try:
        out, err = p.communicate(timeout=timeout)
    finally:
        kill(p)
    return subprocess.CompletedProcess(p.args, p.returncode, out, err)


def kill(p: subprocess.Popen, sig=signal.SIGKILL) -> None:
    try:
        os.killpg(p.pid, sig)
    except ProcessLookupError:
        pass
    try:
        p.wait(timeout=20)
    except subprocess.TimeoutExpired:
        pass


@contextmanager
def dask_cluster(tmp_path: Path, n_workers: int = 2):
    """``dask scheduler`` and ``n_workers`` ``dask worker`` processes (no nanny: killing a
    worker process kills the worker) on 127.0.0.1; yields (address, worker processes)."""
    pytest.importorskip("distributed")
    from distributed import Client

    port = free_port()
    address = f"tcp://127.0.0.1:{port}"
    procs = []
    try:
        procs.append(
            spawn(
                [
                    str(BIN / "dask"),
                    "scheduler",
                    "--host",
                    "127.0.0.1",
                    "--port",
                    str(port),
                    "--dashboard-address",
                    ":0",
                    "--no-show",
                ],
                tmp_path / "scheduler.log",
            )
        )
        workers = []
        for k in range(n_workers):
            w = spawn(
                [
                    str(BIN / "dask"),
                    "worker",
                    address,
                    "--host",
                    "127.0.0.1",
                    "--nthreads",
                    "1",
                    "--no-nanny",
                    "--name",
                    f"w{k}",
                    "--death-timeout",
                    "60",
                ],
                tmp_path / f"worker{k}.log",
            )
            procs.append(w)
            workers.append(w)
        with Client(address, timeout="60s") as c:
            c.wait_for_workers(n_workers, timeout=120)
        yield address, workers
    finally:
        for p in reversed(procs):
            kill(p)


def npz_arrays(path: Path) -> dict:
    with np.load(path) as d:
        return {k: d[k] for k in d.files}


def assert_same_map(a: Path, b: Path) -> None:
    x, y = npz_arrays(a), npz_arrays(b)
    assert x.keys() == y.keys()
    for k in x:
        assert np.array_equal(x[k], y[k]), k


@pytest.fixture(scope="module")
def warm_cache(tmp_path_factory):
    """Compile (or load) every kernel the basin map and the margins run, once, in one process
    that writes Numba's cache, before any run that compares processes bit for bit. With a
    cold cache (a fresh clone) the first process compiles in-session while the others load
    the cache, and the two can differ by round-off (fast-math; docs/developers.md, "Round-off
    depends on the compile"): a comparison of two executors must compare the same machine
    code. It also keeps a worker killed on purpose from dying while it writes the cache."""
    tmp = tmp_path_factory.mktemp("warm")
    for argv in (
        ["basin-map", "--grid", "2", "--strides", "3", "--out", tmp / "b", "--no-overlay"],
        ["margins", "--policy", "passive", "--budget", "test", "--out", tmp / "m", "--no-cache"],
    ):
        r = run([BIN / "bound-env", *argv, "--workers", "1", "--quiet"])
        assert r.returncode == 0, r.stderr


def basin_cli(out: Path, *extra) -> subprocess.CompletedProcess:
    return run(
        [
            BIN / "bound-env",
            "basin-map",
            "--grid",
            "12",
            "--chunk",
            "12",
            "--out",
            out,
            "--json",
            *extra,
        ]
    )


# -- the basin atlas -----------------------------------------------------------------------------


@pytest.mark.slow
def test_passive_batch_is_the_iterated_passive_map():
    """The compiled batch gives exactly the strides of simulate_stride chained."""
    from bound_env.analysis.basin import FELL, REASONS, RETURNED, BasinSpec, run_chunk
    from bound_env.model.hybrid import simulate_stride
    from bound_env.model.params import load_gait

    g = load_gait("default")
    zs = np.asarray(g.z0)
    spec = BasinSpec(
        axes=(3, 0),
        values=(zs[3] + np.array([-0.3, -0.03, 0.0, 0.05]), zs[0] + np.array([0.0, 0.01])),
        z_slice=zs,
        z_target=zs,
        max_strides=60,
    )
    res = run_chunk(spec, 0)
    outcomes = set()
    for k, z0 in enumerate(spec.starts()):
        z = z0
        for n in range(1, 61):
            r = simulate_stride(z, g.params)
            if r.failure:
                assert (res["outcome"][k], REASONS[res["reason"][k]], res["strides"][k]) == (
                    FELL,
                    r.failure,
                    n,
                )
                break
            z = r.z1
            if np.max(np.abs(z - zs)) < 1e-4:
                assert (res["outcome"][k], res["strides"][k]) == (RETURNED, n)
                break
        assert np.array_equal(res["z_last"][k], z)
        outcomes.add(int(res["outcome"][k]))
    assert outcomes >= {FELL, RETURNED}


@pytest.mark.slow
def test_zero_action_through_the_vector_kernel_matches_the_passive_map():
    """Physics cross-check: the closed loop with zero action (interval-by-interval, kernel of
    the vector env) and the compiled passive strides give the same outcomes away from the
    basin's edge."""
    from agents.runtime.controllers import ZeroController
    from bound_env.analysis.basin import BasinSpec, run_chunk
    from bound_env.model.params import load_gait

    zs = np.asarray(load_gait("default").z0)
    vals = (zs[3] + np.linspace(-0.25, 0.25, 6), zs[0] + np.linspace(-0.02, 0.02, 5))
    passive = run_chunk(BasinSpec((3, 0), vals, zs, zs, max_strides=80, chunk=30), 0)
    zero = run_chunk(
        BasinSpec((3, 0), vals, zs, zs, controller=ZeroController(), max_strides=80, chunk=30), 0
    )
    same = passive["outcome"] == zero["outcome"]
    assert same.mean() >= 0.9, (passive["outcome"], zero["outcome"])
    both = same & (passive["outcome"] == 0)
    assert both.any()
    assert np.all(np.abs(passive["strides"][both] - zero["strides"][both]) <= 1)


@pytest.mark.slow
def test_basin_map_files_resume_and_bad_input(tmp_path, capsys, warm_cache):
    out = tmp_path / "b"
    assert (
        main(
            [
                "basin-map",
                "--grid",
                "6",
                "--chunk",
                "9",
                "--workers",
                "1",
                "--out",
                str(out),
                "--json",
                "--axes",
                "theta1,theta1dot",
            ]
        )
        == 0
    )
    s = json.loads(capsys.readouterr().out)
    a = npz_arrays(out / "basin.npz")
    assert a["outcome"].shape == (6, 6) and list(a["axes"]) == ["theta1", "theta1dot"]
    assert (out / "basin.png").stat().st_size > 10_000
    assert s["starts"] == 36 and abs(sum(s["fraction"].values()) - 1) < 1e-12
    fell = a["outcome"] == 1
    assert np.all(a["reason"][fell] > 0) and np.all(a["reason"][~fell] == 0)
    chunks = sorted((out / "chunks").glob("*.npz"))
    assert len(chunks) == 4
    # a lost chunk is recomputed, the others are read back: the same map
    chunks[1].unlink()
    mtimes = {p: p.stat().st_mtime_ns for p in chunks if p.exists()}
    assert (
        main(
            [
                "basin-map",
                "--grid",
                "6",
                "--chunk",
                "9",
                "--workers",
                "1",
                "--out",
                str(tmp_path / "b2"),
                "--axes",
                "theta1,theta1dot",
            ]
        )
        == 0
    )
    os.replace(tmp_path / "b2" / "basin.npz", tmp_path / "ref.npz")
    capsys.readouterr()
    assert (
        main(
            [
                "basin-map",
                "--grid",
                "6",
                "--chunk",
                "9",
                "--workers",
                "1",
                "--out",
                str(out),
                "--axes",
                "theta1,theta1dot",
            ]
        )
        == 0
    )
    assert all(p.stat().st_mtime_ns == t for p, t in mtimes.items())
    assert chunks[1].exists()
    assert_same_map(out / "basin.npz", tmp_path / "ref.npz")
    for argv, word in (
        (["--axes", "xdot_g"], "--axes"),
        (["--axes", "y_g,y_g"], "--axes"),
        (["--range", "1,0,0,1"], "--range"),
        (["--grid", "1"], "--grid"),
    ):
        assert main(["basin-map", "--out", str(tmp_path / "x"), *argv]) == 2
        assert word in capsys.readouterr().err


# -- real clusters -------------------------------------------------------------------------------


@pytest.mark.slow
def test_local_cluster_margins_equal_the_serial_run(tmp_path, warm_cache):
    """``margins`` for passive: LocalCluster with 2 worker processes vs serial, the same JSON
    (apart from the wall time). Budget ``test``: ``quick`` (margins v2) takes minutes on a
    loaded 2-core machine; the tasks are the same kinds."""
    pytest.importorskip("distributed")
    runs = {}
    for name, extra in (("serial", ["--workers", "1"]), ("dask", ["--scheduler", "local:2"])):
        p = run(
            [
                BIN / "bound-env",
                "margins",
                "--policy",
                "passive",
                "--budget",
                "test",
                "--out",
                tmp_path / name,
                "--json",
                *extra,
            ]
        )
        assert p.returncode == 0, p.stderr
        runs[name] = json.loads(p.stdout)
        runs[name].pop("seconds"), runs[name].pop("cpu_seconds")
    assert "Dask scheduler tcp://127.0.0.1:" in p.stderr
    assert json.dumps(runs["dask"]) == json.dumps(runs["serial"])


@pytest.mark.slow
def test_remote_scheduler_basin_map_equals_the_process_pool(tmp_path, warm_cache):
    """``dask scheduler`` + two ``dask worker`` processes; basin-map through tcp:// gives the
    process pool's map, also when a worker is killed (SIGKILL) in the middle of the run."""
    ref = basin_cli(tmp_path / "pool", "--workers", "2", "--no-overlay")
    assert ref.returncode == 0, ref.stderr
    with dask_cluster(tmp_path) as (address, workers):
        r = basin_cli(tmp_path / "dask", "--scheduler", address, "--no-overlay")
        assert r.returncode == 0, r.stderr
        assert_same_map(tmp_path / "pool" / "basin.npz", tmp_path / "dask" / "basin.npz")
        # again, killing worker 0 once the first chunk is in
        out = tmp_path / "killed"
        client = spawn(
            [
                str(BIN / "bound-env"),
                "basin-map",
                "--grid",
                "12",
                "--chunk",
                "12",
                "--out",
                str(out),
                "--no-overlay",
                "--scheduler",
                address,
            ],
            tmp_path / "client.log",
        )
        try:
            t0 = time.monotonic()
            while not list((out / "chunks").glob("*.npz")) if (out / "chunks").exists() else True:
                assert client.poll() is None, (tmp_path / "client.log").read_text()
                assert time.monotonic() - t0 < TIMEOUT_S
                time.sleep(0.05)
            kill(workers[0])
            assert len(list((out / "chunks").glob("*.npz"))) < 12  # killed mid-run
            assert client.wait(timeout=TIMEOUT_S) == 0, (tmp_path / "client.log").read_text()
        finally:
            kill(client)
        assert len(list((out / "chunks").glob("*.npz"))) == 12
        assert_same_map(tmp_path / "pool" / "basin.npz", out / "basin.npz")


@pytest.mark.slow
def test_killed_client_resumes_with_the_missing_tasks_only(tmp_path, warm_cache):
    """Kill the client (SIGKILL, with its LocalCluster) mid-run, rerun on another executor:
    the cached tasks are not run again, and the result equals an uninterrupted run."""
    pytest.importorskip("distributed")
    out = tmp_path / "m"
    cache = out / "cache.jsonl"
    argv = [
        str(BIN / "bound-env"),
        "margins",
        "--policy",
        "passive",
        "--budget",
        "test",
        "--out",
        str(out),
        "--json",
    ]
    client = spawn(argv + ["--scheduler", "local:2"], tmp_path / "client.log")
    try:
        t0 = time.monotonic()
        while not cache.exists() or len(cache.read_text().splitlines()) < 4:
            assert client.poll() is None, (tmp_path / "client.log").read_text()
            assert time.monotonic() - t0 < TIMEOUT_S
            time.sleep(0.05)
    finally:
        kill(client)
    before = cache.read_text().splitlines()
    keys_before = [json.loads(line)["key"] for line in before if line.strip()]
    r = run(argv + ["--workers", "2"])
    assert r.returncode == 0, r.stderr
    after = [json.loads(line)["key"] for line in cache.read_text().splitlines() if line.strip()]
    assert after[: len(keys_before)] == keys_before
    assert len(after) == len(set(after)), "a cached task ran again"
    full = run(argv[:-3] + ["--out", tmp_path / "full", "--json", "--workers", "2"])
    a, b = json.loads(r.stdout), json.loads(full.stdout)
    a.pop("seconds"), b.pop("seconds"), a.pop("cpu_seconds"), b.pop("cpu_seconds")
    # the runs' records of their work: the resumed one took the killed one's tasks from the cache
    ta, tb = a.pop("tasks"), b.pop("tasks")
    assert ta == {"cached": len(keys_before), "computed": len(after) - len(keys_before)}, ta
    assert tb == {"cached": 0, "computed": len(after)}, tb
    assert a == b
    full_keys = [
        json.loads(line)["key"]
        for line in (tmp_path / "full" / "cache.jsonl").read_text().splitlines()
        if line.strip()
    ]
    assert sorted(after) == sorted(full_keys)


@pytest.mark.slow
def test_failing_task_on_a_dask_worker_does_not_stop_the_run(capsys):
    pytest.importorskip("distributed")
    with open_pool("local:2", quiet=True) as pool:
        tasks = {f"div-{d}": (operator.truediv, (1.0, d)) for d in (1, 0, 4)}
        done, failures = run_tasks(pool.executor, tasks, desc="div")
    assert done == {"div-1": 1.0, "div-4": 0.25}
    assert [f.key for f in failures] == ["div-0"] and "ZeroDivisionError" in failures[0].error
    assert "div-0 (1.0, 0)" in capsys.readouterr().err
    with pytest.raises(TasksFailed, match="1 of 3 tasks failed"):
        raise TasksFailed(failures, 3)


@pytest.mark.slow
def test_sweep_directions_as_two_tasks_give_the_serial_sweep():
    from bound_env.analysis.sweeps import sweep
    from bound_env.model.params import load_gait

    g = load_gait("default")
    kw = dict(n_strides=30, polish=False)
    vals = [293.0, 294.0, 296.0, 297.0]
    serial = sweep(g.params, g.z0, "kc", vals, **kw)
    with open_pool(None, 2) as pool:
        par = sweep(g.params, g.z0, "kc", vals, executor=pool.executor, **kw)
    assert [p.value for p in serial.points] == [p.value for p in par.points]
    assert len(serial.points) == 5  # the base value too
    for a, b in zip(serial.points, par.points, strict=True):
        assert (a.converged, a.error, a.emax, a.failure) == (
            b.converged,
            b.error,
            b.emax,
            b.failure,
        )
        assert np.array_equal(a.z, b.z)


@pytest.mark.slow
def test_multi_seed_training_on_a_local_cluster_ends_with_compare(tmp_path):
    """``train --seeds 0,1 --scheduler local:2`` with a tiny budget: one run per seed, sent
    back as bytes, then the compare page over both seeds."""
    pytest.importorskip("distributed")
    sets = [
        "n_envs=2",
        "n_steps=256",
        "batch_size=128",
        "n_epochs=1",
        "policy_kwargs=dict(net_arch=dict(pi=[16], vf=[16]))",
        "callback=[]",
    ]
    argv = [
        str(BIN / "bound-env"),
        "train",
        "--seeds",
        "0,1",
        "--scheduler",
        "local:2",
        "--name",
        "tiny",
        "--n-timesteps",
        "2048",
        "--runs-dir",
        str(tmp_path / "runs"),
        "--runs-transfer",
        "bytes",
        "--compare-budget",
        "test",
        "--eval-freq",
        "1024",
        "--n-eval-episodes",
        "1",
        "--save-freq",
        "1024",
        "--no-progress",
    ]
    for s in sets:
        argv += ["--set", s]
    r = run(argv, timeout=3 * TIMEOUT_S, cwd=tmp_path)
    assert r.returncode == 0, r.stderr[-3000:]
    for seed in (0, 1):
        rdir = tmp_path / "runs" / f"tiny_s{seed}"
        info = json.loads((rdir / "run.json").read_text())
        assert info["seed"] == seed and info["timesteps_done"] >= 2048
        assert (rdir / "model.zip").is_file()
    page = tmp_path / "runs" / "tiny_seeds" / "MARGINS.md"
    assert page.is_file() and "tiny (2 seeds)" in page.read_text()


@pytest.mark.slow
def test_per_observation_controllers_run_one_copy_per_robot():
    """A controller without batch() (the margins protocol, with on_apex) gives the same map
    as the same law with batch()."""
    from agents.runtime.policy import load_controller
    from bound_env.analysis.basin import BasinSpec, run_chunk
    from bound_env.model.params import load_gait

    class RowByRow:  # the shipped policy, seen through __call__ only
        def __init__(self, inner):
            self.inner, self.env_kwargs, self.starts = inner, inner.env_kwargs, []

        def __call__(self, obs):
            return self.inner.batch(np.asarray(obs)[None])[0]

        def on_apex(self, z, t):
            self.starts.append(np.array(z))

        def fingerprint(self):
            return "row-by-row " + self.inner.fingerprint()

    ctrl = load_controller(ARCHIVE_DIR / "ppo-v1")
    zs = np.asarray(load_gait("default").z0)
    vals = (zs[3] + np.linspace(-0.2, 0.2, 3), zs[0] + np.linspace(-0.01, 0.01, 2))
    a = run_chunk(BasinSpec((3, 0), vals, zs, zs, controller=ctrl, max_strides=30), 0)
    b = run_chunk(BasinSpec((3, 0), vals, zs, zs, controller=RowByRow(ctrl), max_strides=30), 0)
    for k in ("outcome", "reason", "strides", "phase", "z_last"):
        assert np.array_equal(a[k], b[k]), k
