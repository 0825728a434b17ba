"""Every `bound-env` command the documentation shows in a code block works as written.

The fast tier parses each one with the real parser and checks what it names (a shipped
config and its env id section, a policy or controller name, a config or spec file): a command
that a reader copies fails there on a renamed flag, a retired env id, a config without the
section or a policy that is not shipped. The slow tier runs the "Train and measure" page end
to end, in a temporary folder, with the budgets the page itself shows (`--budget test`, small
`--n-timesteps`).
"""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
GENERATED = ("MARGINS.md", "REPRODUCTION.md")  # written by compare / reproduce
TUTORIAL = DOCS / "train-and-measure.md"
# folders that earlier commands on a page create (run folders, outputs): not looked up
PRODUCED = ("runs/", "out/", "logs/", "/tmp/", "DIR", "pol/")


def _pages() -> list[Path]:
    pages = [ROOT / "README.md", *sorted(DOCS.rglob("*.md"))]
    return [p for p in pages if p.name not in GENERATED]


def code_blocks(text: str) -> list[tuple[str, str]]:
    """(language, body) of every fenced block, in page order."""
    return re.findall(r"^```(\w*)[^\n]*\n(.*?)^```", text, re.S | re.M)


def block_commands(body: str) -> list[str]:
    """The ``bound-env ...`` command lines of a shell block (continuations joined; printed
    error lines such as ``bound-env rollout: error: ...`` left out)."""
    body = re.sub(r"\s*\\\n\s*", " ", body)
    out = []
    for line in body.splitlines():
        line = line.strip().removeprefix("$ ")
        if line.startswith("bound-env ") and not re.match(r"bound-env [a-z-]+:", line):
            out.append(line)
    return out


def doc_commands() -> list[tuple[str, str]]:
    """(page, command) for every documented command, placeholders kept."""
    found = []
    for page in _pages():
        for lang, body in code_blocks(page.read_text()):
            if lang in ("bash", "sh", "console", ""):
                found += [(str(page.relative_to(ROOT)), c) for c in block_commands(body)]
        for row in re.findall(r"^\|.*$", page.read_text(), re.M):  # tables' "made by" cells
            found += [
                (str(page.relative_to(ROOT)), c) for c in re.findall(r"`(bound-env [^`]+)`", row)
            ]
    return found


def argv_of(command: str) -> list[str]:
    """The argument list, with the pages' placeholders filled in: a seed ``S`` or ``$s``
    (0), ``sS`` (s0), ``NAME`` and ``PORT``."""
    text = command.replace("$s", "0").replace("sS", "s0")
    argv = shlex.split(text, comments=True)[1:]
    fill = {"S": "0", "NAME": "x", "PORT": "8786"}
    return [fill.get(a, a.replace("PORT", "8786")) for a in argv]


def _help_text(sub: str) -> str:
    from bound_env.commands.cli import build_parser

    action = build_parser()._subparsers._group_actions[0]
    return action.choices[sub].format_help()


def _produced(path: str) -> bool:
    return any(path.startswith(p) or p in path for p in PRODUCED)


def check_names(args) -> None:
    """What the parsed command names exists: a config file and its env id section, a policy,
    controller or spec, a student."""
    from agents.common.config import default_env_id, load_hyperparams, resolve_config_path
    from agents.runtime.policy import resolve_policy, unwrapped_name

    cmd = args.command
    if cmd == "train" and not args.resume:
        config = resolve_config_path(args.config)
        load_hyperparams(config, args.env_id or default_env_id(config))
        if args.init_from:
            resolve_policy(args.init_from)
    for key in ("policy", "student"):
        value = getattr(args, key, None)
        if isinstance(value, str) and not _produced(value) and cmd != "compare":
            resolve_policy(unwrapped_name(value))  # NAME+of: NAME
    for entry in getattr(args, "entry", None) or []:
        from agents.results.compare import parse_entry

        _, policies, _ = parse_entry(entry)
        for p in policies:
            if not _produced(p):
                resolve_policy(unwrapped_name(p))


DOC_COMMANDS = doc_commands()


def test_the_pages_show_commands():
    pages = {p for p, _ in DOC_COMMANDS}
    assert len(DOC_COMMANDS) >= 50
    assert "docs/train-and-measure.md" in pages and "docs/learned.md" in pages


@pytest.mark.parametrize(
    "page,command", DOC_COMMANDS, ids=[f"{p}:{c[:60]}" for p, c in DOC_COMMANDS]
)
def test_documented_command_parses_and_names_what_exists(page, command):
    from bound_env.commands.cli import build_parser

    argv = argv_of(command)
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as e:
        if e.code != 0:
            pytest.fail(f"{page}: `{command}` does not parse (exit {e.code})")
        return  # --help
    try:
        check_names(args)
    except (ValueError, FileNotFoundError) as e:
        pytest.fail(f"{page}: `{command}`: {e}")


def test_placeholders_are_filled():
    assert argv_of("bound-env train --seed S --name step-ppo-sS  # S = 0, 1") == [
        "train",
        "--seed",
        "0",
        "--name",
        "step-ppo-s0",
    ]
    assert block_commands("bound-env rollout: error: x\nbound-env demo \\\n  --json\n") == [
        "bound-env demo --json"
    ]


def test_train_takes_the_published_id_and_each_config_by_name():
    """`train --env-id PassiveBound-v1` has its section; a config with one section trains
    on that section's env without --env-id."""
    from agents.common.config import config_names, default_env_id, load_hyperparams

    v0 = load_hyperparams("ppo", "PassiveBound-v0")
    assert load_hyperparams("ppo", "PassiveBound-v1") == v0
    assert load_hyperparams("ppo-residual", "PassiveBound-v1") == load_hyperparams(
        "ppo-residual", "PassiveBound-v0"
    )
    assert default_env_id("ppo") == "PassiveBound-v0"
    assert default_env_id("ppo-stride") == "PassiveBoundStride-v1"
    assert default_env_id("ppo-rescue") == "PassiveBoundRescue-v1"  # the newest of one env
    for name in config_names():
        assert load_hyperparams(name, default_env_id(name))  # every shipped config by name


def test_no_retired_env_id_in_the_docs():
    for page in _pages():
        for line in page.read_text().splitlines():
            if "PassiveBoundStride-v0" in line:
                assert "--env-id PassiveBoundStride-v0" not in line, page
                assert not line.startswith("|"), f"{page}: {line}"  # no table shows it


def test_the_home_page_and_readme_link_the_tutorial():
    assert "](train-and-measure.md)" in (DOCS / "index.md").read_text()
    assert "](docs/train-and-measure.md)" in (ROOT / "README.md").read_text()
    assert "train-and-measure.md" in (ROOT / "mkdocs.yml").read_text()


def _run_page_step(lang: str, body: str, cwd: Path, env: dict) -> None:
    if lang == "python":
        r = subprocess.run(
            [sys.executable, "-c", body], cwd=cwd, env=env, capture_output=True, text=True,
            timeout=900,
        )  # fmt: skip
        assert r.returncode == 0, f"python block failed:\n{body}\n{r.stderr[-3000:]}"
        return
    for command in block_commands(body):
        argv = argv_of(command)
        if "--keep-defaults" in argv:
            continue  # every default column at the test budget: too long for the suite
        r = subprocess.run(
            [sys.executable, "-m", "bound_env.commands.cli", *argv, "--no-progress"],
            cwd=cwd, env=env, capture_output=True, text=True, timeout=1800,
        )  # fmt: skip
        assert r.returncode == 0, f"`{command}` failed:\n{r.stderr[-3000:]}"


@pytest.mark.slow  # the tutorial end to end: about 5 min on the shared 2-core machine
def test_train_and_measure_page_runs_as_written(tmp_path):
    """Every block of the tutorial, in order, in a fresh folder: the plain SB3 model is
    measured with --env-id, the trained run loads by its folder, and compare's page has the
    passive, lqr, mpc and new columns."""
    env = dict(os.environ, PYTHONPATH=str(ROOT), MPLBACKEND="Agg")
    blocks = code_blocks(TUTORIAL.read_text())
    assert [lang for lang, _ in blocks].count("python") >= 2
    for lang, body in blocks:
        _run_page_step(lang, body, tmp_path, env)
    assert (tmp_path / "runs" / "plain" / "model.zip").is_file()
    assert (tmp_path / "runs" / "mine" / "config.yaml").is_file()
    page = (tmp_path / "out" / "vs" / "MARGINS.md").read_text()
    for label in ("passive", "lqr", "mpc", "mine"):
        assert f"| {label}" in page or f"**{label}**" in page, label


def test_plain_sb3_model_is_measured_with_an_env_id(tmp_path, cli):
    """A plain SB3 `model.zip` (no config.yaml) is refused with a hint to --env-id, and with
    `--env-id PassiveBound-v1` it is evaluated at that id's registered kwargs (80 N m)."""
    import gymnasium as gym
    from stable_baselines3 import PPO

    import bound_env
    from agents.runtime.policy import load_controller

    gym.register_envs(bound_env)
    (tmp_path / "plain").mkdir()
    PPO("MlpPolicy", gym.make("PassiveBound-v1"), seed=0).save(tmp_path / "plain" / "model.zip")
    model = tmp_path / "plain" / "model.zip"
    with pytest.raises(ValueError, match="name it with --env-id"):
        load_controller(model)
    ctrl = load_controller(model, env_id="PassiveBound-v1")
    assert ctrl.env_kwargs["max_torque"] == 80.0
    assert load_controller(model, env_id="PassiveBoundLiteral-v1").env_kwargs["gait"] == (
        "literal-cycle"
    )
    with pytest.raises(ValueError, match="--env-id 'PassiveBoundStride-v1': a plain model.zip"):
        load_controller(model, env_id="PassiveBoundStride-v1")
    with pytest.raises(ValueError, match="not 'lqr'"):
        load_controller("lqr", env_id="PassiveBound-v1")
    # a config beside it names the id; another --env-id contradicts it
    (tmp_path / "plain" / "config.yaml").write_text("PassiveBound-v1: {}\n")
    assert load_controller(tmp_path / "plain").env_kwargs["max_torque"] == 80.0
    with pytest.raises(ValueError, match="was trained on PassiveBound-v1"):
        load_controller(tmp_path / "plain", env_id="PassiveBound-v0")
    archived = "agents/policies/archive/stride-residual/s0"
    code, _, err = cli("margins", "--policy", archived, "--env-id", "PassiveBound-v1")
    assert code != 0 and "--env-id PassiveBound-v1: policy" in err and len(err.splitlines()) == 1
