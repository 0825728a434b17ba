"""No run is left half-done, mixed up or running (issue 26, §3): refused commands leave nothing
and refuse before any work, names that become paths are checked by one checker, a resumed
fine-tuning run must be the same run, interrupts stop the pool's workers and say how to resume,
and what grows is bounded."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from agents.runtime.policy_table import ARCHIVE_DIR
from bound_env.commands.cli import main
from bound_env.commands.cli_args import check_writable
from bound_env.files.values import check_name, name_key

ROOT = Path(__file__).resolve().parents[1]


def _run(argv, capsys):
    try:
        code = main(argv)
    except SystemExit as e:
        code = e.code
    err = capsys.readouterr().err
    assert code not in (0, None), f"{argv}: exit {code}"
    assert "Traceback" not in err
    return err.strip().splitlines()[-1]


@pytest.mark.parametrize(
    "name, ok",
    [
        ("lqr", True),
        ("a_b", True),
        ("seed-1.2+x", True),
        ("..", False),
        (".hidden", False),
        ("a/b", False),
        ("../x", False),
        ("a|b", False),
        ("a b", False),
        ("", False),
        ("x" * 65, False),
    ],
)
def test_one_name_checker(name, ok):
    if ok:
        assert check_name(name, "--name") == name
    else:
        with pytest.raises(ValueError, match="--name"):
            check_name(name, "--name")
    # compare's labels may hold single spaces (the default "passive literal"), which share a
    # folder with "_": name_key says so
    assert check_name("passive literal", "--entry", spaces=True)
    assert name_key("a b") == name_key("a_b") == name_key("A_b")
    with pytest.raises(ValueError, match="--entry"):
        check_name("a  b", "--entry", spaces=True)


def test_check_writable_probes_and_leaves_nothing(tmp_path):
    check_writable(tmp_path / "new" / "deeper", "--out")
    assert list(tmp_path.iterdir()) == []  # nothing made, the probe removed
    (tmp_path / "f").write_text("x")
    with pytest.raises(ValueError, match="--export .* is not a folder"):
        check_writable(tmp_path / "f" / "x", "--export")
    with pytest.raises(ValueError, match="--export .*cannot write"):
        check_writable("/sys/x/policy", "--export")  # read-only even for root


def test_refused_distill_leaves_nothing(tmp_path, capsys):
    out = tmp_path / "d"
    line = _run(["distill", "--expert", "lqr", "--out", str(out)], capsys)
    assert "--expert" in line and not out.exists()
    # --export where nothing can be written: refused before the run, not after it
    line = _run(["distill", "--out", str(out), "--export", "/sys/x/policy"], capsys)
    assert "--export" in line and not out.exists()


@pytest.mark.parametrize(
    "entries, word",
    [
        (["..=lqr"], "'..'"),
        (["a|b=lqr"], "'a|b'"),
        (["passive=lqr"], "same name"),
        (["a b=lqr", "a_b=lqr"], "same name or folder"),
        (["lqr", "LQR=deadbeat"], "same name or folder"),
        (["lqr", "x=" + "nothing-here"], "does not exist"),  # after a good column
        (["x=ppo-v1-final/s0,step-ppo/s0"], "share the folder"),
    ],
)
def test_compare_checks_every_entry_before_any_column(tmp_path, capsys, entries, word):
    argv = ["compare", "--budget", "test", "--workers", "1", "--out", str(tmp_path / "c")]
    for e in entries:
        argv += ["--entry", e]
    line = _run(argv, capsys)
    assert "--entry" in line and word in line
    assert list(tmp_path.iterdir()) == []  # no column computed, no folder made


def test_train_name_cannot_leave_the_runs_folder(tmp_path, capsys):
    argv = ["train", "--name", "../x", "--out", str(tmp_path / "runs"), "--n-timesteps", "64"]
    assert "--name" in _run(argv, capsys)
    assert list(tmp_path.iterdir()) == []
    from agents.training.train import train

    with pytest.raises(ValueError, match="--name"):
        train(name="../x", runs_dir=tmp_path / "runs", n_timesteps=64)


def test_finetune_refuses_to_resume_another_run(tmp_path):
    from agents.experts.finetune import SETTINGS_FILE, FinetuneConfig, check_settings, run_settings

    s0, s1 = ARCHIVE_DIR / "distilled" / "s0", ARCHIVE_DIR / "distilled" / "s1"
    out = tmp_path / "ft"
    check_settings(out, s0, FinetuneConfig(seed=0))  # a new folder: nothing to check
    out.mkdir()
    (out / SETTINGS_FILE).write_text(
        __import__("json").dumps(run_settings(s0, FinetuneConfig(seed=0)))
    )
    check_settings(out, s0, FinetuneConfig(seed=0, timesteps=10**6))  # train longer: same run
    with pytest.raises(ValueError, match="other settings .*seed"):
        check_settings(out, s0, FinetuneConfig(seed=1))
    with pytest.raises(ValueError, match="other settings .*student"):
        check_settings(out, s1, FinetuneConfig(seed=0))
    (out / SETTINGS_FILE).unlink()
    (out / "ckpt_2048_steps.zip").write_bytes(b"x")
    with pytest.raises(ValueError, match="checkpoints without"):
        check_settings(out, s0, FinetuneConfig(seed=0))


@pytest.mark.parametrize(
    "argv, word",
    [
        (["margins", "--scheduler", "local:100000"], "--scheduler"),
        (["margins", "--workers", "100000"], "--workers"),
        (["compare", "--workers", "257"], "--workers"),
        (["sweep", "--param", "kc", "--to", "300", "--workers", "100000"], "--workers"),
        (["margins", "--scheduler", "tcp://127.0.0.1:1"], "connection refused"),
        (["margins", "--scheduler", "tcp://127.0.0.1:abc"], "--scheduler"),
    ],
)
def test_scheduler_and_workers_are_bounded_and_named(tmp_path, capsys, argv, word):
    t0 = time.perf_counter()
    line = _run(
        [*argv, "--policy", "passive", "--budget", "test", "--out", str(tmp_path / "m")]
        if argv[0] == "margins"
        else [*argv, "--out", str(tmp_path / "m")],
        capsys,
    )
    assert word in line
    assert time.perf_counter() - t0 < 5.0  # a refused port fails at once, not after 20 s
    assert not (tmp_path / "m").exists()


def test_rollout_video_streams_its_frames_and_thins_long_runs(tmp_path, monkeypatch):
    from agents.runtime import rollout as ro

    class Sink:  # stands for bound_env.envs.render.VideoWriter: counts what reaches the file
        def __init__(self, path, fps):
            self.fps, self.n = fps, 0
            seen.append(self)

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            return False

        def append(self, frame):
            assert frame.shape == (360, 640, 3) and str(frame.dtype) == "uint8"
            self.n += 1

    seen = []
    monkeypatch.setattr(ro, "MAX_VIDEO_FRAMES", 16)
    monkeypatch.setattr(ro, "_video_writer", Sink)
    r = ro.rollout("passive", strides=2, video=tmp_path / "v.gif")
    (sink,) = seen
    assert r["video_every"] >= 4 and sink.n <= 24  # ~80 intervals, evenly thinned
    assert sink.n == r["steps"] // r["video_every"] + 1
    assert sink.fps == round(100 / r["video_every"])  # still real time
    with pytest.raises(ValueError, match="--video"):
        ro.rollout("passive", strides=1, video="/sys/x/v.gif")  # checked before the run


def test_rollout_video_file_has_every_streamed_frame(tmp_path):
    from PIL import Image

    from agents.runtime import rollout as ro

    r = ro.rollout("passive", strides=1, video=tmp_path / "v.gif")
    with Image.open(tmp_path / "v.gif") as im:
        assert im.n_frames == r["steps"] // r["video_every"] + 1
        assert im.size == (640, 360) and im.info["loop"] == 0
    assert [p.name for p in tmp_path.iterdir()] == ["v.gif"]  # no temporary left


def _children(pid: int) -> list[int]:
    try:
        return [int(x) for x in Path(f"/proc/{pid}/task/{pid}/children").read_text().split()]
    except OSError:
        return []


def _alive(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().split()[2] != "Z"
    except OSError:
        return False


@pytest.mark.skipif(not Path("/proc/self/task").is_dir(), reason="reads /proc")
@pytest.mark.parametrize("sig, code", [(signal.SIGTERM, 143), (signal.SIGINT, 130)])
def test_interrupted_margins_stops_its_workers_and_says_how_to_resume(tmp_path, sig, code):
    cmd = [
        sys.executable,
        "-c",
        "import sys; from bound_env.commands.cli import main; sys.exit(main())",
        "margins",
        "--policy",
        "passive",
        "--budget",
        "quick",  # (the test budget can finish before the signal on an idle machine)
        "--workers",
        "2",
        "--out",
        str(tmp_path / "m"),
        "--no-progress",  # (a log gets progress lines; the interruption is one line)
    ]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    # a Ctrl-C as from a terminal: SIGINT handled by default in the child, even when this
    # test runs in a background job (whose children start with SIGINT ignored, so Python
    # would never raise KeyboardInterrupt)
    p = subprocess.Popen(
        cmd,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    t0, kids = time.time(), []
    while time.time() - t0 < 60 and p.poll() is None and len(kids) < 2:
        kids = _children(p.pid)
        time.sleep(0.05)
    assert len(kids) >= 2, "the pool's workers did not start"
    time.sleep(0.3)
    p.send_signal(sig)
    _, err = p.communicate(timeout=30)
    assert p.returncode == code
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "interrupted" in lines[0] and "resume" in lines[0], err
    time.sleep(0.2)
    assert not [k for k in kids if _alive(k)]
