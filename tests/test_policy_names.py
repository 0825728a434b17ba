"""The curated set of shipped policies (issue 30): one name table (`agents.runtime.policy_table`)
for the loader, ``--policy``'s help and docs/learned.md; ``default`` a name for ``finetuned/s0``,
not a copy; the superseded policies archived, their old names saying where they went."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from agents.runtime.policy_table import (
    ALIASES,
    ARCHIVE_DIR,
    ARCHIVED,
    SHIPPED_DIR,
    archived_message,
    names_text,
    shipped_names,
)

ROOT = Path(__file__).resolve().parent.parent
CURATED = {"default", "literal-cycle"} | {
    f"{g}/s{k}"
    for g in (
        "finetuned",
        "step-ppo",
        "ppo-v1-final",
        "adaptive",
        "adaptive-nohist",
        "adaptive-nominal",
    )
    for k in range(3)
}
# the learned adaptive controller's names that say what it learned from (issue 47): a name
# for each seed folder of its group, not a copy
CURATED |= {
    f"student-mpc-adaptive{ablation}/s{k}"
    for ablation in ("", "-nohist", "-nominal")
    for k in range(3)
}


def test_the_shipped_set_is_the_curated_one():
    assert set(shipped_names()) == CURATED
    # default is a name for the seed folder, not a byte copy of it
    assert shipped_names()["default"] == SHIPPED_DIR / "finetuned" / "s0"
    assert ALIASES["default"][0] == "finetuned/s0"
    assert not (SHIPPED_DIR / "default").exists()
    for name in ARCHIVED:
        assert (ARCHIVE_DIR / name).is_dir() and not (SHIPPED_DIR / name).exists()


def test_default_loads_everywhere_it_did():
    from agents.runtime.policy import load_controller, policy_names, resolve_policy
    from agents.runtime.rollout import load_policy

    assert "default" in policy_names()
    assert resolve_policy("default") == SHIPPED_DIR / "finetuned" / "s0"
    a, b = load_controller("default"), load_controller("finetuned/s0")
    assert a.fingerprint() == b.fingerprint()
    make_env, act = load_policy("default")
    assert make_env.env_kwargs["max_torque"] == 80.0


@pytest.mark.parametrize("name", ["ppo-v1", "warm-started/s1", "distilled/s0", "stride-residual"])
def test_an_archived_name_says_where_it_went(name):
    from agents.runtime.policy import load_controller

    with pytest.raises(FileNotFoundError) as e:
        load_controller(name)
    msg = str(e.value)
    assert msg == archived_message(name) and "\n" not in msg
    assert str(ARCHIVE_DIR / name) in msg and "archived" in msg


def test_an_archived_name_on_the_command_line_is_one_line(cli):
    code, _, err = cli("rollout", "--policy", "ppo-v1", "--strides", "1")
    assert code == 2 and "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "archive" in lines[0] and "ppo-v1" in lines[0], err


def test_an_archived_policy_still_loads_by_its_path():
    from agents.runtime.policy import load_controller

    ctrl = load_controller(ARCHIVE_DIR / "distilled" / "s0")
    assert callable(getattr(ctrl, "on_apex", None))


def _squash(text: str) -> str:  # argparse wraps lines, also at hyphens
    return re.sub(r"\s+", "", text)


def test_help_and_docs_list_the_same_names():
    """``margins --help`` and docs/learned.md's list come from `names_text`."""
    from bound_env.commands.cli import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if getattr(a, "choices", None) and "margins" in a.choices)
    help_text = _squash(sub.choices["margins"].format_help())
    assert _squash(names_text("'")) in help_text
    doc = (ROOT / "docs" / "learned.md").read_text()
    block = re.search(r"<!-- policy-names:start -->(.*?)<!-- policy-names:end -->", doc, re.S)
    assert block is not None and block.group(1) == names_text()
    for name in CURATED - {"default"}:
        group = name.split("/")[0]
        assert group in block.group(1) and group in help_text
    for name in ARCHIVED:
        for end in ("`", "/"):
            assert f"`{name}{end}" not in block.group(1)
        for end in ("'", "/"):
            assert f"'{name}{end}" not in help_text


def test_an_archived_name_in_an_installed_package(monkeypatch, tmp_path):
    """A wheel has no archive: the message points at the repository."""
    import agents.runtime.policy_table as table

    monkeypatch.setattr(table, "ARCHIVE_DIR", tmp_path / "none")
    msg = table.archived_message("stride-residual/s0")
    assert "repository's agents/policies/archive/stride-residual/s0" in msg and "\n" not in msg
    assert table.archived_message("finetuned/s0") is None
