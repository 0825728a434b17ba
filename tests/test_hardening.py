"""The new surfaces, hardened: each unclean input ends in one line naming the parameter, file
or key (a non-zero exit for the command line), never a traceback, a hang, a silent NaN or
lost data. `LibraryActions`, `load_policy`/`act`, tampered policy folders (an empty
fingerprint, a swapped base), a policy of the rescue task, ``finetune`` reruns, a residual's
``config.yaml``, ``agents.results.headline``, ``scripts/page_on_dask.sh`` and streamed video."""

from __future__ import annotations

import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
import tracemalloc
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import bound_env
from bound_env.commands.cli import main

gym.register_envs(bound_env)
ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "scripts" / "page_on_dask.sh"
VENV_BIN = Path(sys.executable).parent


def one_line_error(argv, capsys) -> str:
    """Run the CLI in-process: a non-zero exit and one line on stderr (returned)."""
    try:
        code = main([str(a) for a in argv])
    except SystemExit as e:  # argparse
        code = e.code
    err = capsys.readouterr().err.strip()
    assert code not in (0, None), err
    lines = [ln for ln in err.splitlines() if not ln.startswith("warning:")]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


# -- LibraryActions ---------------------------------------------------------------------------


def test_library_actions_passes_the_env_checkers_and_is_recreated_from_its_spec():
    import warnings

    from gymnasium.utils.env_checker import check_env

    from bound_env.envs.wrappers import LibraryActions

    env = LibraryActions(gym.make("PassiveBoundRescue-v0"), rows=np.zeros((3, 8)))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # "a wrapper is applied": expected here
        check_env(env)
    again = gym.make(env.spec)  # RecordConstructorArgs: the wrapper and its rows come back
    assert isinstance(again, LibraryActions) and again.action_space.n == 3


@pytest.mark.parametrize("action", [True, np.bool_(True), np.inf, 1.5, 2.0, "1", None, [1, 2]])
def test_library_actions_refuses_what_is_not_one_integer(action):
    from bound_env.envs.wrappers import LibraryActions

    env = LibraryActions(gym.make("PassiveBoundRescue-v0"))
    env.reset(seed=0)
    with pytest.raises(ValueError, match="LibraryActions action must be an integer") as e:
        env.step(action)
    assert "\n" not in str(e.value)


@pytest.mark.parametrize("action", [66, -1, 10**30])
def test_library_actions_refuses_rows_out_of_range(action):
    from bound_env.envs.wrappers import LibraryActions

    env = LibraryActions(gym.make("PassiveBoundRescue-v0"))
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"LibraryActions action must be in \[0, 66\)"):
        env.step(action)
    env.step(np.int64(3))  # numpy integers and one-element integer arrays are actions
    env.reset(seed=0)  # (a stride may end the episode: a step after it is refused)
    env.step(np.array([2]))


def test_library_actions_rows_are_checked_by_name():
    from bound_env.envs.wrappers import LibraryActions

    for rows, word in ((np.full((3, 8), np.nan), "finite"), (np.zeros((3, 4)), "shape")):
        with pytest.raises(ValueError, match=f"LibraryActions rows.*{word}"):
            LibraryActions(gym.make("PassiveBoundRescue-v0"), rows)


# -- load_policy / act ------------------------------------------------------------------------


@pytest.mark.parametrize("policy", ["lqr", "ppo-v1-final/s0"])
def test_act_refuses_a_nan_observation(policy):
    from agents.runtime.rollout import load_policy

    make_env, act = load_policy(policy)
    env = make_env()
    obs, info = env.reset(seed=0)
    bad = obs.copy()
    bad[3] = np.nan
    with pytest.raises(ValueError, match=r"obs\[3\] is nan") as e:
        act(bad, info)
    assert "\n" not in str(e.value)


@pytest.mark.parametrize("policy", ["lqr", "ppo-v1-final/s0"])
def test_act_shared_between_two_envs_says_so(policy):
    from agents.runtime.rollout import load_policy

    make_env, act = load_policy(policy)
    a, b = make_env(reset_noise_scale=0.5), make_env(reset_noise_scale=0.5)
    oa, ia = a.reset(seed=1)
    ob, ib = b.reset(seed=2)
    with pytest.raises(ValueError, match="shared between two envs") as e:
        for _ in range(50):
            oa, _, _, _, ia = a.step(act(oa, ia))
            ob, _, _, _, ib = b.step(act(ob, ib))
    assert "max_torque =" not in str(e.value)  # not blamed on the env's max_torque


def test_act_with_the_wrong_max_torque_is_still_blamed_on_it():
    from agents.runtime.rollout import load_policy

    make_env, act = load_policy("lqr")
    env = make_env(max_torque=40.0, reset_noise_scale=0.5)
    obs, info = env.reset(seed=1)
    with pytest.raises(ValueError, match="max_torque = 40"):
        for _ in range(50):
            obs, _, _, _, info = env.step(act(obs, info))


def test_a_none_policy_or_controller_is_named():
    from agents.runtime.rollout import load_policy
    from bound_env.control import load_controller
    from bound_env.control.plain import PlainPolicy

    with pytest.raises(TypeError, match="policy must be a name"):
        load_policy(None)
    with pytest.raises(TypeError, match="controller must be a name"):
        load_controller(None)
    with pytest.raises(TypeError, match="PlainPolicy: controller must be a callable"):
        PlainPolicy(None)


def test_a_nan_gain_is_blamed_on_its_field_or_file(tmp_path):
    from bound_env.control import load_controller

    spec = (ROOT / "configs" / "controllers" / "lqr.yaml").read_text()
    head = spec.split("gain:")[0]
    p = tmp_path / "nan.yaml"
    rows = "\n".join(f"    - [{'.nan' if i == 0 else '1.0'}, 1, 1, 1, 1, 1]" for i in range(8))
    p.write_text(head + "gain:\n  default:\n" + rows + "\n")
    with pytest.raises(ValueError, match=r"nan.yaml: gain.default must be finite"):
        load_controller(p)
    g = tmp_path / "g.csv"
    g.write_text("\n".join(",".join(["nan"] + ["1"] * 5) for _ in range(8)))
    p.write_text(head + f"gain: {g.name}\n")
    with pytest.raises(ValueError, match=r"g.csv: gain \(from .*nan.yaml\) must be finite"):
        load_controller(p)


# -- tampered policy folders ------------------------------------------------------------------


@pytest.mark.parametrize(
    "name, key",
    [
        ("ppo-v1-final/s0", "model.zip"),
        ("default", "choice.npz"),
        ("step-ppo/s0", "model.zip"),
    ],
)
def test_an_empty_fingerprint_is_refused(tmp_path, capsys, name, key):
    from agents.runtime.policy import resolve_policy

    d = tmp_path / "pol"
    shutil.copytree(resolve_policy(name), d)
    (d / "fingerprint.json").write_text("{}")
    line = one_line_error(["rollout", "--policy", d, "--strides", "1"], capsys)
    assert "fingerprint.json" in line and f"missing key {key!r}" in line


def test_a_fingerprint_without_the_statistics_is_refused(tmp_path, capsys):
    from agents.runtime.policy_table import ARCHIVE_DIR

    d = tmp_path / "pol"
    shutil.copytree(ARCHIVE_DIR / "ppo-v1", d)
    fp = json.loads((d / "fingerprint.json").read_text())
    del fp["vecnormalize.pkl"]
    (d / "fingerprint.json").write_text(json.dumps(fp))
    line = one_line_error(["rollout", "--policy", d, "--strides", "1"], capsys)
    assert "missing key 'vecnormalize.pkl'" in line


@pytest.fixture
def shipped_copy(tmp_path, monkeypatch):
    """The shipped step-ppo/s0, its base `default` (the name of finetuned/s0) and another policy
    (an archived student), in a copy of the policies folder that the name lookup reads."""
    import agents.common.policy_files as pf
    import agents.runtime.kinds.folder as names  # where names resolve
    from agents.runtime.policy_table import ARCHIVE_DIR, SHIPPED_DIR

    root = tmp_path / "policies"
    for name in ("step-ppo/s0", "finetuned/s0"):
        shutil.copytree(SHIPPED_DIR / name, root / name)
    shutil.copytree(ARCHIVE_DIR / "distilled" / "s1", root / "distilled" / "s1")
    table = {
        "default": root / "finetuned" / "s0",
        "finetuned/s0": root / "finetuned" / "s0",
        "step-ppo/s0": root / "step-ppo" / "s0",
    }
    monkeypatch.setattr(names, "shipped_policies", lambda: dict(table))
    monkeypatch.setattr(pf, "SHIPPED", root)
    return root


def test_step_ppo_pins_the_content_of_its_base(shipped_copy, capsys):
    from agents.runtime.policy import base_pin, load_controller

    step = shipped_copy / "step-ppo" / "s0"
    pin = json.loads((step / "fingerprint.json").read_text())["base"]
    assert pin == base_pin("default")
    load_controller(step)  # as shipped: loads
    # the base folder swapped for another policy: refused, in one line
    shutil.rmtree(shipped_copy / "finetuned" / "s0")
    shutil.copytree(shipped_copy / "distilled" / "s1", shipped_copy / "finetuned" / "s0")
    line = one_line_error(["rollout", "--policy", step, "--strides", "1"], capsys)
    assert "base 'default' does not match" in line and "fingerprint.json" in line
    assert load_controller(step, force=True) is not None  # --force: as it is, with a warning
    assert "base 'default' does not match" in capsys.readouterr().err


def test_a_residual_fingerprint_without_its_base_is_refused(shipped_copy, capsys):
    step = shipped_copy / "step-ppo" / "s0"
    fp = json.loads((step / "fingerprint.json").read_text())
    del fp["base"]
    (step / "fingerprint.json").write_text(json.dumps(fp))
    line = one_line_error(["rollout", "--policy", step, "--strides", "1"], capsys)
    assert "missing key 'base'" in line


def test_a_policy_of_the_rescue_task_is_refused_naming_it(tmp_path, capsys):
    """What `bound-env train --config configs/ppo-rescue.yaml` writes: the config says the
    env id, and the message says how such a policy is evaluated (not "is config.yaml beside
    it?")."""
    d = tmp_path / "rescue-ppo-s0"
    d.mkdir()
    (d / "model.zip").write_bytes(b"PK")
    section = (ROOT / "configs" / "ppo-rescue.yaml").read_text()
    (d / "config.yaml").write_text(section + "run: {env_id: PassiveBoundRescue-v0, seed: 0}\n")
    line = one_line_error(["rollout", "--policy", d, "--strides", "1"], capsys)
    assert "PassiveBoundRescue-v0" in line and "rescue_eval.py" in line
    assert "beside it" not in line


# -- finetune reruns --------------------------------------------------------------------------


def _finetune_out(tmp_path, timesteps, recorded=True):
    import agents.experts.finetune as ft
    from agents.runtime.policy import resolve_policy

    student = resolve_policy("default")
    out = tmp_path / "ft"
    (out / "policy").mkdir(parents=True)
    cfg = ft.FinetuneConfig(timesteps=timesteps)
    settings = ft.run_settings(student, cfg)
    if recorded:
        settings["timesteps"] = timesteps
    (out / ft.SETTINGS_FILE).write_text(json.dumps(settings))
    for name in ("choice.npz", "config.json"):
        shutil.copy(Path(student) / name, out / "policy" / name)
    summary = {"timesteps": timesteps, "requested_timesteps": timesteps, "policy": "x"}
    (out / "summary.json").write_text(json.dumps(summary))
    return ft, student, out


@pytest.mark.parametrize("recorded", [True, False])  # False: a finetune.json of before
def test_finetune_refuses_a_shorter_rerun_into_the_same_out(tmp_path, recorded):
    ft, student, out = _finetune_out(tmp_path, 1000, recorded)
    before = (out / "policy" / "choice.npz").read_bytes()
    with pytest.raises(ValueError, match=r"--timesteps 500: .* --timesteps 1000") as e:
        ft.finetune(student, out, ft.FinetuneConfig(timesteps=500), progress=False)
    assert "\n" not in str(e.value)
    assert (out / "policy" / "choice.npz").read_bytes() == before  # nothing lost


def test_finetune_rerun_of_a_finished_run_keeps_its_policy(tmp_path, monkeypatch):
    ft, student, out = _finetune_out(tmp_path, 1000)
    before = (out / "policy" / "choice.npz").read_bytes()

    def no_training(*a, **k):
        raise AssertionError("a finished run was trained again")

    monkeypatch.setattr(ft, "_copy_actor", no_training)
    summary = ft.finetune(student, out, ft.FinetuneConfig(timesteps=1000), progress=False)
    assert summary["timesteps"] == 1000
    assert (out / "policy" / "choice.npz").read_bytes() == before


# -- a residual's config.yaml -----------------------------------------------------------------


@pytest.mark.parametrize(
    "old, new, words",
    [
        ("scale: 0.5,", "scael: 0.5,", ["config.yaml", "unknown key 'scael'"]),
        ("residual_cost: 0.05", "residual_cost: .nan", ["config.yaml", "residual_cost"]),
        ("ramp: 0.25", "ramp: '0.25'", ["config.yaml", "ramp"]),
        ("r_max: 0.45", "r_max: 1.0e-09", ["config.yaml", "r_max"]),
    ],
)
def test_a_bad_residual_setting_in_config_yaml_is_one_line(tmp_path, capsys, old, new, words):
    from agents.runtime.policy import shipped_policies

    d = tmp_path / "pol"
    shutil.copytree(shipped_policies()["step-ppo/s0"], d)
    (d / "fingerprint.json").unlink()  # a user's own run, not the shipped (pinned) one
    text = (d / "config.yaml").read_text()
    assert old in text
    (d / "config.yaml").write_text(text.replace(old, new))
    # --force: no fingerprint (issue 40); the setting is still refused
    line = one_line_error(["rollout", "--policy", d, "--strides", "1", "--force"], capsys)
    assert all(w in line for w in words), line


def test_residual_r_max_that_cannot_leave_the_safe_radius_is_refused():
    from agents.runtime.residual import ResidualOver

    env = gym.make("PassiveBound-v0", max_torque=80.0)
    with pytest.raises(ValueError, match="ResidualOver r_max 1e-09 cannot start past"):
        ResidualOver(env, r_max=1e-9)


# -- agents.results.headline
# --------------------------------------------------------------------------


def _headline_case(tmp_path, change) -> tuple[Path, Path]:
    head = json.loads((ROOT / "docs" / "headline.json").read_text())
    change(head)
    p = tmp_path / "headline.json"
    p.write_text(json.dumps(head))  # Python's json writes NaN as is: not strict JSON
    readme = tmp_path / "README.md"
    readme.write_text("x\n<!-- headline:start -->\nold\n<!-- headline:end -->\n")
    return p, readme


def _set(path, value):
    def change(head):
        d = head
        for k in path[:-1]:
            d = d[k]
        d[path[-1]] = value

    return change


def _drop(path):
    def change(head):
        d = head
        for k in path[:-1]:
            d = d[k]
        del d[path[-1]]

    return change


@pytest.mark.parametrize(
    "change, key",
    [
        (_set(("rows", 1, "r50", "value"), float("nan")), "rows[1].r50.value is NaN"),
        (_set(("rows", 0, "mfpt_sigma_100_deg", "low"), float("inf")), "low is Infinity"),
        (_drop(("rows",)), "rows: missing"),
        (_set(("rows",), {"a": 1}), "rows must be list"),
        (_drop(("rows", 2, "r50")), "rows[2].r50: missing"),
        (_set(("rows", 0, "r50"), 0.3), "rows[0].r50 must be a mapping"),
        (_set(("rows", 0, "label"), 3), "rows[0].label must be str"),
        (_set(("rows", 0, "r50", "value"), "0.2"), "rows[0].r50.value must be float"),
        (_set(("seed",), "12345"), "seed must be int"),
        (_set(("rows",), []), "rows: empty"),
    ],
)
def test_headline_refuses_a_malformed_headline_json_in_one_line(tmp_path, capsys, change, key):
    from agents.results.headline import (
        main as headline_main,  # `python -m agents.results.headline`, in-process
    )

    p, readme = _headline_case(tmp_path, change)
    before = readme.read_text()
    assert headline_main(["--json", str(p), "--readme", str(readme)]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and str(p) in lines[0] and key in lines[0], lines
    assert readme.read_text() == before  # a NaN never reaches the README


def test_load_json_strict_names_the_file_and_key(tmp_path):
    from bound_env.files.schema import load_json_strict

    p = tmp_path / "m.json"
    p.write_text('{"a": {"b": [1, 2, NaN]}}')
    with pytest.raises(ValueError, match=r"m.json: a.b\[2\] is NaN"):
        load_json_strict(p)
    p.write_text('{"a": {"b": true}}')
    with pytest.raises(ValueError, match=r"m.json: a.b must be float or null, got True"):
        load_json_strict(p, {"a": {"b": (float, None)}})
    assert load_json_strict(p, {"a": dict}) == {"a": {"b": True}}


# -- scripts/page_on_dask.sh ------------------------------------------------------------------


def _free_port() -> int:
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


def _script(args, port, bin_dir=VENV_BIN, **kw):
    env = {"PATH": "/usr/bin:/bin", "PORT": str(port), "BIN": str(bin_dir)}
    return subprocess.run(["bash", SCRIPT, *map(str, args)], env=env, **kw)


@pytest.mark.parametrize("workers", ["300", "0", "2x", "99999999999999999999"])
def test_page_on_dask_refuses_bad_workers_before_anything_starts(tmp_path, workers):
    t0 = time.perf_counter()
    r = _script([workers, tmp_path / "out"], _free_port(), capture_output=True, text=True)
    assert r.returncode == 2 and r.stderr.count("\n") == 1, r.stderr
    assert "WORKERS must be an integer from 1 to 256" in r.stderr
    assert time.perf_counter() - t0 < 5 and not (tmp_path / "out").exists()


@pytest.mark.skipif(not (VENV_BIN / "dask").exists(), reason="dask is not installed")
def test_page_on_dask_with_a_taken_port_fails_at_once_naming_it(tmp_path):
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    s.listen()
    port = s.getsockname()[1]
    try:
        t0 = time.perf_counter()
        r = _script([1, tmp_path / "out"], port, capture_output=True, text=True, timeout=60)
    finally:
        s.close()
    assert r.returncode == 2 and r.stderr.count("\n") == 1, r.stderr
    assert f"port {port} on 127.0.0.1 is taken" in r.stderr
    assert time.perf_counter() - t0 < 5 and not (tmp_path / "out").exists()


def _processes_naming(word: str) -> list[str]:
    out = []
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                cmd = (d / "cmdline").read_bytes().replace(b"\0", b" ").decode()
            except OSError:
                continue
            if word in cmd:
                out.append(f"{d.name}: {cmd[:100]}")
    return out


@pytest.mark.slow  # ~10 s: a real Dask scheduler and two workers start
@pytest.mark.skipif(not Path("/proc").is_dir(), reason="reads /proc")
@pytest.mark.skipif(not (VENV_BIN / "dask").exists(), reason="dask is not installed")
def test_page_on_dask_stopped_by_sigterm_leaves_nothing_running(tmp_path):
    fake = tmp_path / "bin"  # dask as installed; a compare that runs until stopped
    fake.mkdir()
    for name in ("dask", "python"):
        (fake / name).symlink_to(VENV_BIN / name)
    marker = f"compare-{os.getpid()}-{time.time_ns()}"
    (fake / "bound-env").write_text(f'#!/bin/sh\necho "{marker} $*" >&2\nsleep 600\n')
    (fake / "bound-env").chmod(0o755)
    port = _free_port()
    p = subprocess.Popen(
        ["bash", SCRIPT, "2", tmp_path / "out"],
        env={"PATH": "/usr/bin:/bin", "PORT": str(port), "BIN": str(fake)},
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        line = p.stderr.readline()  # compare started: the cluster is up
        assert marker in line, line
        assert len(_processes_naming(str(port))) >= 3  # the scheduler's port, 2 workers
        p.send_signal(signal.SIGTERM)
        assert p.wait(30) == 143
    finally:
        if p.poll() is None:
            p.kill()
    time.sleep(0.5)
    assert not _processes_naming(str(port)) and not _processes_naming("sleep 600"), (
        _processes_naming(str(port))
    )


# -- streamed video ---------------------------------------------------------------------------


def _frames(n, shape=(360, 640, 3)):
    rng = np.random.default_rng(0)
    for _ in range(n):
        yield rng.integers(0, 255, shape, dtype=np.uint8)


def test_video_writer_holds_one_frame_at_a_time(tmp_path):
    from PIL import Image

    from bound_env.envs.render import write_video

    peaks = {}
    for n in (4, 40):
        tracemalloc.start()
        write_video(_frames(n), tmp_path / f"v{n}.gif", fps=25)
        peaks[n] = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        with Image.open(tmp_path / f"v{n}.gif") as im:
            assert im.n_frames == n and im.info["duration"] == 40 and im.info["loop"] == 0
    assert peaks[40] < 1.5 * peaks[4], peaks  # 10x the frames, not 10x the memory
    assert peaks[40] < 20 * 640 * 360 * 3  # a few frames' worth, not 40


def test_video_writer_leaves_nothing_on_an_error(tmp_path):
    from bound_env.envs.render import VideoWriter, write_video

    with pytest.raises(ValueError, match="at least one frame"):
        write_video([], tmp_path / "empty.gif", fps=10)
    with pytest.raises(RuntimeError), VideoWriter(tmp_path / "v.gif", fps=10) as v:
        v.append(np.zeros((36, 64, 3), np.uint8))
        raise RuntimeError("interrupted")
    with pytest.raises(ValueError, match="must all be"), VideoWriter(tmp_path / "w.gif", 10) as v:
        v.append(np.zeros((36, 64, 3), np.uint8))
        v.append(np.zeros((36, 60, 3), np.uint8))
    assert list(tmp_path.iterdir()) == []


def test_video_writer_streams_an_mp4(tmp_path):
    pytest.importorskip("imageio_ffmpeg")
    import imageio.v2 as imageio

    from bound_env.envs.render import write_video

    write_video(_frames(5, (36, 64, 3)), tmp_path / "v.mp4", fps=10)
    assert len(imageio.mimread(tmp_path / "v.mp4")) == 5


@pytest.mark.parametrize(
    "options, word", [([1, 2], "options must be a dict"), ({"apex_stat": 1}, "apex_stat")]
)
def test_residual_reset_checks_its_options(options, word):
    from agents.runtime.residual import ResidualOver

    env = ResidualOver(gym.make("PassiveBound-v0", max_torque=80.0))
    with pytest.raises(ValueError, match=word):
        env.reset(seed=0, options=options)


@pytest.mark.parametrize("env_id", ["PassiveBound-v0", "PassiveBoundStride-v1"])
@pytest.mark.parametrize("dt", [1e-9, 5.0])
def test_env_dt_outside_the_files_range_is_refused_at_once(env_id, dt):
    """The spec files' dt range (`bound_env.files.schema.dt_value`) applies to the envs' own `dt`:
    dt = 1e-9 built a 25 GB matrix, dt = 5 s is longer than a stride."""
    t0 = time.perf_counter()
    with pytest.raises(ValueError, match=r"dt must be a finite number in \[0.0001, 0.1\]"):
        gym.make(env_id, dt=dt)
    assert time.perf_counter() - t0 < 10
