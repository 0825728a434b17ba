"""The `bound-env stride` command line (a contract)."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

from bound_env.model.params import z_to_paper

ROOT = Path(__file__).resolve().parent.parent


def test_stride_json_has_the_documented_keys(cli):
    code, out, _ = cli("stride", "--gait", "configs/gaits/paper.yaml", "--json")
    assert code == 0
    d = json.loads(out)
    for key in ("z0", "z1", "phases", "durations", "failure", "energy"):
        assert key in d
    assert d["failure"] is None
    assert d["z0"] == pytest.approx([0.2536, 0.6303, -1.152, 2.840, 293.2, -143.7])
    assert d["phases"] == ["df", "bs", "df", "fs", "df"]
    assert len(d["durations"]) == len(d["phases"])
    assert set(d["energy"]) == {"start", "end"}


def test_stride_defaults_to_z_star_and_returns_to_it(cli, default_gait):
    code, out, _ = cli("stride", "--gait", "default", "--json")
    d = json.loads(out)
    z_star = z_to_paper(default_gait.z_star)
    assert d["z0"] == pytest.approx(list(z_star), abs=1e-9)
    assert d["z1"] == pytest.approx(list(z_star), abs=1e-6)


def test_stride_overrides_z_backend_and_repeat(cli):
    code, out, _ = cli(
        "stride",
        "--gait",
        "paper",
        "--set",
        "kc=300",
        "--set",
        "alpha_deg=2.0",
        "--z=0.25,0.5,-1,2.83,294,-147",
        "--repeat",
        "3",
        "--backend",
        "reference",
        "--json",
    )
    d = json.loads(out)
    assert code == 0 and d["repeat"] == 3 and d["backend"] == "reference"
    assert d["z0"] == pytest.approx([0.25, 0.5, -1, 2.83, 294, -147])
    code2, out2, _ = cli("stride", "--gait", "paper", "--json")
    assert json.loads(out2)["z1"] != d["z1"]


@pytest.mark.parametrize(
    "argv, words",
    [
        (["stride", "--gait", "nope"], "no gait file"),
        (["stride", "--set", "kc=-3"], "kc"),
        (["stride", "--set", "bogus=1"], "bogus"),
        (["stride", "--z=1,2,3"], "6 comma-separated"),
        (["stride", "--repeat", "0"], "repeat"),
    ],
)
def test_bad_input_is_a_clear_error(cli, argv, words):
    code, _, err = cli(*argv)
    assert code == 2
    assert words in err


def test_console_script_runs_from_the_venv():
    exe = Path(sys.executable).parent / "bound-env"
    if not exe.exists():
        pytest.skip("console script not installed next to this interpreter")
    res = subprocess.run(
        [str(exe), "stride", "--gait", "paper", "--json"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert res.returncode == 0, res.stderr
    assert json.loads(res.stdout)["failure"] is None


def _commands(parser):
    (sub,) = [a for a in parser._actions if a.dest == "command"]
    return set(sub.choices)


def test_agents_plug_in_through_the_entry_point_group():
    from importlib.metadata import entry_points

    from bound_env.commands.cli import PLUGIN_GROUP, build_parser

    names = {ep.value for ep in entry_points(group=PLUGIN_GROUP)}
    if "agents.cli:register" not in names:
        pytest.skip("the bound_env.commands entry points are not installed (pip install -e .)")
    assert {"train", "margins", "compare"} <= _commands(build_parser())


def test_core_cli_works_without_plugins(monkeypatch, cli):
    from importlib.metadata import EntryPoint

    import bound_env.commands.cli as core

    gone = EntryPoint("gone", "no_such_package.cli:register", core.PLUGIN_GROUP)
    monkeypatch.setattr(core, "entry_points", lambda group: [gone] if group else [])
    commands = _commands(core.build_parser())
    assert {"stride", "fixed-point", "reproduce", "animate", "demo"} <= commands
    assert not commands & {"train", "margins", "compare"}
    code, out, _ = cli("stride", "--gait", "paper", "--json")
    assert code == 0 and json.loads(out)["failure"] is None
