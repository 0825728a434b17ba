"""The package as a user gets it: sdist -> wheel -> a fresh venv, used from another directory.

The fresh venv gets only the wheel (``--no-deps``); its dependencies are the ones already
installed for the test run, reached through a ``.pth`` file (so the test needs no network and
does not reinstall torch). Nothing from the checkout is importable there: no ``PYTHONPATH``, the
working directory is outside the checkout, and the test checks where ``bound_env`` and
``agents`` were imported from.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import sysconfig
import tarfile
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
_ANYWHERE = shutil.ignore_patterns(
    ".git", "__pycache__", "*.egg-info", "*.nbi", "*.nbc", "*.pyc", ".pytest_cache", ".ruff_cache"
)
_TOP = {".venv", "out", "runs", "build", "dist", "reproduce"}  # outputs at the top level only


def _SKIP(folder, names):
    """copytree's ignore: caches anywhere, output folders only at the top of the checkout (a
    package may be called ``reproduce`` too)."""
    top = {n for n in names if n in _TOP} if Path(folder) == ROOT else set()
    return set(_ANYWHERE(folder, names)) | top


# site-packages entries of this project itself (an editable install), hidden from the fresh venv
_OWN = ("bound_env", "agents", "__editable__", "_bound_env", "__pycache__")


def _run(cmd, cwd, env, timeout=600):
    res = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)
    assert res.returncode == 0, f"{cmd} failed:\n{res.stdout[-3000:]}\n{res.stderr[-3000:]}"
    assert "Traceback" not in res.stderr, res.stderr[-3000:]
    return res.stdout


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("install")
    src = tmp / "src"
    shutil.copytree(ROOT, src, ignore=_SKIP)
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "NUMBA_CACHE_DIR")}
    # sdist first, then the wheel built from the sdist: both must be complete
    _run(
        [sys.executable, "-m", "build", "--no-isolation", "-o", str(tmp / "dist"), str(src)],
        cwd=tmp,
        env=env,
    )
    wheel = next((tmp / "dist").glob("*.whl"))
    sdist = next((tmp / "dist").glob("*.tar.gz"))
    venv = tmp / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True)
    py = venv / "bin" / "python"
    site = Path(
        subprocess.run(
            [str(py), "-c", "import sysconfig;print(sysconfig.get_paths()['purelib'])"],
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
    )
    # the dependencies, without this project's own (editable) install and its metadata
    deps = tmp / "deps"
    deps.mkdir()
    for lib in {sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]}:
        for item in Path(lib).iterdir():
            if not item.name.startswith(_OWN) and not (deps / item.name).exists():
                (deps / item.name).symlink_to(item)
    (site / "_bound_env_test_deps.pth").write_text(f"{deps}\n")
    _run(
        [str(py), "-m", "pip", "install", "--no-deps", "--no-index", "-q", str(wheel)],
        cwd=tmp,
        env=env,
    )
    work = tmp / "elsewhere"
    work.mkdir()
    env["XDG_CACHE_HOME"] = str(tmp / "cache")
    env["PATH"] = f"{venv / 'bin'}{os.pathsep}{env.get('PATH', '')}"
    return {
        "tmp": tmp,
        "wheel": wheel,
        "sdist": sdist,
        "py": str(py),
        "site": site,
        "cwd": work,
        "env": env,
        "exe": str(venv / "bin" / "bound-env"),
    }


@pytest.mark.slow
def test_wheel_and_sdist_hold_data_and_license(installed):
    names = zipfile.ZipFile(installed["wheel"]).namelist()
    for want in (
        "bound_env/configs/ppo.yaml",
        "bound_env/configs/gaits/default.yaml",
        "bound_env/configs/gaits/literal-cycle.yaml",
        "agents/policies/ppo-v1-final/s0/model.zip",
        "agents/policies/ppo-v1-final/s0/vecnormalize.pkl",
        "agents/policies/finetuned/s0/choice.npz",
        "agents/policies/finetuned/s0/config.json",
        "agents/policies/finetuned/s0/fingerprint.json",
        "agents/policies/literal-cycle/config.yaml",
        "bound_env/configs/ppo-stride.yaml",
        "agents/policies/step-ppo/s0/model.zip",
    ):
        assert want in names, want
    assert not [n for n in names if "policies/archive/" in n]  # not shipped (policy_table)
    # every controller spec, gait and config of the checkout is in the wheel
    for f in (ROOT / "configs").rglob("*.yaml"):
        assert f"bound_env/configs/{f.relative_to(ROOT / 'configs').as_posix()}" in names, f
    assert (ROOT / "configs" / "controllers" / "lqr.yaml").is_file()
    assert any(n.endswith("licenses/LICENSE") for n in names)
    # every module of the checkout is in the wheel (a new subpackage cannot be left out)
    for pkg in ("bound_env", "agents"):
        for f in (ROOT / pkg).rglob("*.py"):
            assert f.relative_to(ROOT).as_posix() in names, f
    with tarfile.open(installed["sdist"]) as t:
        members = {m.split("/", 1)[1] for m in t.getnames() if "/" in m}
    for want in (
        "LICENSE",
        "configs/ppo.yaml",
        "configs/gaits/paper.yaml",
        "agents/policies/ppo-v1-final/s0/model.zip",
        "agents/policies/finetuned/s0/choice.npz",
        "setup.py",
        "pyproject.toml",
    ):
        assert want in members, want


@pytest.mark.slow
def test_installed_package_runs_outside_the_checkout(installed):
    py, cwd, env, site = installed["py"], installed["cwd"], installed["env"], installed["site"]
    code = (
        "import json, gymnasium as gym, numpy as np, bound_env, agents\n"
        "gym.register_envs(bound_env)\n"
        "out = {'bound_env': bound_env.__file__, 'agents': agents.__file__}\n"
        "for i in ('PassiveBound-v0', 'PassiveBoundLiteral-v0'):\n"
        "    e = gym.make(i)\n"
        "    obs, _ = e.reset(seed=0)\n"
        "    obs, r, term, trunc, info = e.step(np.zeros(1, np.float32))\n"
        "    out[i] = [str(e.unwrapped.task.gait.path), bool(np.isfinite(obs).all()), term]\n"
        "print(json.dumps(out))\n"
    )
    got = json.loads(_run([py, "-c", code], cwd=cwd, env=env))
    for pkg in ("bound_env", "agents"):
        assert Path(got[pkg]).resolve().is_relative_to(site.resolve()), got[pkg]
    assert Path(got["PassiveBound-v0"][0]).name == "default.yaml"
    assert Path(got["PassiveBoundLiteral-v0"][0]).name == "literal-cycle.yaml"
    for i in ("PassiveBound-v0", "PassiveBoundLiteral-v0"):
        assert Path(got[i][0]).resolve().is_relative_to(site.resolve())
        assert got[i][1] and not got[i][2]

    stride = json.loads(
        _run([installed["exe"], "stride", "--gait", "default", "--json"], cwd=cwd, env=env)
    )
    assert stride["failure"] is None and stride["z1"] is not None

    # the test budget, in the default folder: compare below finds this column (and deadbeat's)
    # computed, as it finds any column of the same budget and code
    margins = json.loads(
        _run(
            [installed["exe"], "margins", "--policy", "passive", "--budget", "test", "--json"],
            cwd=cwd,
            env=env,
        )
    )
    assert 0.8 < margins["emax"] < 0.95  # the passive gait's e_max is 0.878 (docs/analysis.md)
    assert (cwd / "out" / "margins" / "passive" / "margins.json").is_file()

    # the acceptance run of the shipped default controller (a distilled stride controller):
    # 50 strides from z*, no fall; on the cycle its LQR gate plays (numerically) zero torque
    r = json.loads(
        _run(
            [installed["exe"], "rollout", "--policy", "default", "--strides", "50", "--json"],
            cwd=cwd,
            env=env,
        )
    )
    assert r["strides"] == 50 and r["fell"] is False and r["failure"] is None
    assert r["max_torque"] == 80.0 and 0.0 <= r["mean_abs_tau"] < 1e-6
    assert (cwd / "out" / "rollout" / "default" / "summary.json").is_file()

    # every built-in controller and shipped policy by name, from outside the checkout
    names = json.loads(
        _run(
            [
                py,
                "-c",
                "import json\nfrom agents.runtime.policy import policy_names\n"
                "from bound_env.control import controller_names\n"
                "from agents.common.config import resolve_config_path\n"
                "print(json.dumps([policy_names(), controller_names(), "
                "str(resolve_config_path('ppo-stride'))]))",
            ],
            cwd=cwd,
            env=env,
        )
    )
    want = {p.stem for p in (ROOT / "configs" / "controllers").glob("*.yaml")}
    assert set(names[1]) == want and want <= set(names[0])
    assert {"passive", "default", "step-ppo/s0", "step-ppo/s2"} <= set(names[0])
    assert Path(names[2]).resolve().is_relative_to(site.resolve())
    for name in sorted(want) + ["step-ppo/s1"]:
        r = json.loads(
            _run(
                [installed["exe"], "rollout", "--policy", name, "--strides", "2", "--json"],
                cwd=cwd,
                env=env,
            )
        )
        assert r["strides"] == 2 and r["fell"] is False, name
    for cmd in (
        ["margins", "--policy", "deadbeat", "--budget", "test", "--workers", "1", "--json"],
        [
            "basin-map",
            "--policy",
            "lqr",
            "--grid",
            "3",
            "--strides",
            "5",
            "--no-overlay",
            "--workers",
            "1",
            "--out",
            "out/basin-lqr",
            "--json",
        ],
    ):
        json.loads(_run([installed["exe"], *cmd], cwd=cwd, env=env))
    page = json.loads(
        _run(
            [installed["exe"], "compare", "--budget", "test", "--workers", "1", "--json"],
            cwd=cwd,
            env=env,
            timeout=1800,
        )
    )
    assert {"passive", "lqr", "deadbeat", "mpc"} <= set(page["entries"])  # the curated columns
    assert (cwd / "out" / "margins" / "MARGINS.md").is_file()

    # compiled code is cached under the user cache, never inside site-packages
    assert not list(site.rglob("*.nbi"))
    assert list((installed["tmp"] / "cache" / "bound_env" / "numba").rglob("*.nbi"))
