"""Training survives SIGKILL at any moment: kill a real run (a subprocess) at several points,
one of them inside a checkpoint write, resume it, and check what a finished run must hold."""

from __future__ import annotations

import csv
import json
import os
import pickle
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parent.parent
TOTAL, EVAL, SAVE, N_STEPS = 3072, 256, 512, 128
SETS = [
    "n_envs=1",
    f"n_steps={N_STEPS}",
    "batch_size=64",
    "n_epochs=1",
    "callback=[]",
    "policy_kwargs=dict(net_arch=dict(pi=[8], vf=[8]))",
]


def _cmd(runs: Path, resume: bool = False) -> list[str]:
    cmd = [
        sys.executable,
        "-m",
        "bound_env.commands.cli",
        "train",
        "--name",
        "k",
        "--runs-dir",
        str(runs),
        "--vec-env",
        "dummy",
        "--no-progress",
    ]
    if resume:
        return cmd + ["--resume"]
    cmd += [
        "--seed",
        "1",
        "--n-timesteps",
        str(TOTAL),
        "--eval-freq",
        str(EVAL),
        "--save-freq",
        str(SAVE),
        "--n-eval-episodes",
        "1",
    ]
    for s in SETS:
        cmd += ["--set", s]
    return cmd


def _env(**extra) -> dict:
    env = {**os.environ, "PYTHONPATH": str(ROOT), **extra}
    env.pop("BOUND_ENV_TEST_CHECKPOINT_SLEEP", None)
    env.update(extra)
    return env


def _wait_for(pred, proc, timeout=600.0):
    t0 = time.monotonic()
    while not pred():
        assert proc.poll() is None, f"training ended early: {proc.returncode}"
        assert time.monotonic() - t0 < timeout, "timed out"
        time.sleep(0.05)


@pytest.mark.slow
def test_kill_anywhere_then_resume(tmp_path):
    runs = tmp_path / "runs"
    run = runs / "k"
    ckpts = run / "checkpoints"

    # 1. killed inside the write of the checkpoint at 1024 steps: model written, stats not
    proc = subprocess.Popen(
        _cmd(runs),
        cwd=tmp_path,
        stderr=subprocess.PIPE,
        text=True,
        env=_env(BOUND_ENV_TEST_CHECKPOINT_SLEEP="60@1024"),
    )
    for line in proc.stderr:
        if "[checkpoint hook] 1024 steps" in line:
            break
    assert proc.poll() is None
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert (ckpts / "rl_model_1024_steps.zip").is_file()
    assert not (ckpts / "rl_model_1024_steps.json").exists()

    # truncated run files: a one-line error, no traceback, nothing changed
    for name in ("config.yaml", "run.json"):
        good = (run / name).read_text()
        (run / name).write_text(good[: len(good) // 2])
        res = subprocess.run(
            _cmd(runs, resume=True),
            cwd=tmp_path,
            capture_output=True,
            text=True,
            env=_env(),
            timeout=600,
        )
        assert res.returncode == 2 and "Traceback" not in res.stderr, res.stderr
        assert name in res.stderr and len(res.stderr.strip().splitlines()) == 1, res.stderr
        (run / name).write_text(good)

    # 2. resumed from the newest complete checkpoint (512), killed at a random moment after
    #    the checkpoint at 2048 steps
    proc = subprocess.Popen(
        _cmd(runs, resume=True), cwd=tmp_path, stderr=subprocess.PIPE, text=True, env=_env()
    )
    _wait_for(lambda: (ckpts / "rl_model_2048_steps.json").is_file(), proc)
    time.sleep(np.random.default_rng().uniform(0.0, 0.5))
    proc.send_signal(signal.SIGKILL)
    err = proc.communicate()[1]
    assert "skipping incomplete checkpoint" in err and "rl_model_1024_steps.zip" in err
    info = json.loads((run / "run.json").read_text())
    assert [s["from"] for s in info["sessions"]] == [0, 512]

    # 3. resumed again, to the end
    res = subprocess.run(
        _cmd(runs, resume=True),
        cwd=tmp_path,
        capture_output=True,
        text=True,
        env=_env(),
        timeout=900,
    )
    assert res.returncode == 0, res.stderr[-3000:]

    info = json.loads((run / "run.json").read_text())
    froms = [s["from"] for s in info["sessions"]]
    assert len(froms) == 3 and froms[:2] == [0, 512] and froms[2] >= 2048
    assert [s["to"] for s in info["sessions"]][:2] == [None, None]  # the killed sessions
    assert info["timesteps_done"] == TOTAL and info["sessions"][-1]["to"] == TOTAL

    # normalization statistics kept their count through both kills: every training step and
    # one reset per session, nothing lost (fresh statistics would count from the resume)
    with (run / "vecnormalize.pkl").open("rb") as f:
        count = pickle.load(f).obs_rms.count
    assert TOTAL + 3 - 1 <= count <= TOTAL + 3 + 1e-3, count

    # the evaluation schedule continued: one row per 256 steps, no gap, no duplicate
    with (run / "eval.csv").open() as f:
        ts = [int(float(r["timesteps"])) for r in csv.DictReader(f)]
    assert ts == list(range(EVAL, TOTAL + 1, EVAL))

    # the monitor log was appended to, not restarted: one header, episodes from all sessions
    lines = (run / "monitor" / "0.monitor.csv").read_text().splitlines()
    assert sum(1 for x in lines if x.startswith("#")) == 1
    assert len(lines) > 2
