"""The committed results page knows which code made it.

Every column of ``docs/columns.json`` (and of ``docs/model_error.json``) records, per policy,
the fingerprint of what decided its numbers when it was computed
(`bound_env.analysis.margins.fingerprint`: the controller's data, its planning constants and
its code, and the commit). A column whose controller is no longer that (a changed spec, gain,
search setting, planning constant or controller code) makes the page stale: this test fails
and names the command that regenerates the page. Columns whose policy loads torch (the PPO
policies) are checked in the slow tier.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from bound_env.analysis.margins.fingerprint import CHECKED, column_fingerprint, stale_parts

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
FILES = ("columns.json", "model_error.json")
PAGE = "bound-env compare --budget full --workers 2 --docs docs"
REGENERATE = f"{PAGE} (then python -m agents.results.prose and python -m agents.results.headline)"


def regenerate_hint() -> str:
    """How to regenerate each committed file: the command its run recorded (``run.command``;
    the model-error section is its own `compare --mismatch` run), then the prose."""
    lines = []
    for name in FILES:
        path = DOCS / name
        run = json.loads(path.read_text()).get("run") or {} if path.is_file() else {}
        lines.append(f"  docs/{name}: {run.get('command') or PAGE}")
    return (
        "regenerate it with the command each file recorded:\n"
        + "\n".join(lines)
        + "\n  then python -m agents.results.prose and python -m agents.results.headline"
    )


def committed_columns():
    """(file, label, gait, policy, recorded fingerprint) of every committed column."""
    out = []
    for name in FILES:
        path = DOCS / name
        if not path.is_file():
            continue
        for col in json.loads(path.read_text()).get("columns") or []:
            fps = col.get("fingerprints") or [None] * len(col["policies"])
            for policy, fp in zip(col["policies"], fps, strict=True):
                out.append((name, col["label"], col["gait"], policy, fp))
    return out


def _needs_torch(policy: str) -> bool:
    return (ROOT / policy / "model.zip").is_file() or policy.endswith(".zip")


def stale_columns(rows) -> list[str]:
    """One line per committed column whose controller is not what made it."""
    from agents.runtime.policy import load_controller

    found = []
    for name, label, gait, policy, fp in rows:
        ctrl = load_controller(policy, gait=gait)  # passive: the zero controller
        parts = stale_parts(fp, ctrl)
        if parts:
            why = "no fingerprint recorded" if fp is None else f"its {', '.join(parts)} changed"
            found.append(f"docs/{name}: column {label!r} ({policy}): {why}")
    return found


def _check(rows):
    assert (DOCS / "columns.json").is_file(), (
        f"docs/columns.json is missing: the committed page predates column fingerprints; "
        f"regenerate it: {REGENERATE}"
    )
    stale = stale_columns(rows)
    assert not stale, "the committed page is stale:\n" + "\n".join(stale) + "\n" + regenerate_hint()


def test_every_committed_column_is_what_its_controller_is_now():
    _check([r for r in committed_columns() if not _needs_torch(r[3])])


@pytest.mark.slow  # loads torch for the PPO policies' columns
def test_every_committed_ppo_column_is_what_its_policy_is_now():
    _check([r for r in committed_columns() if _needs_torch(r[3])])


def test_a_changed_mpc_makes_its_column_stale(monkeypatch, tmp_path):
    """The check fails on a changed planning constant, search setting or controller code."""
    import bound_env.analysis.margins.fingerprint as fpmod
    import bound_env.control.mpc as mpc
    from bound_env.control import load_controller

    ctrl = load_controller("mpc")
    recorded = column_fingerprint(ctrl)
    rows = [("columns.json", "mpc", "default", "mpc", recorded)]
    assert stale_parts(recorded, ctrl) == []
    assert stale_columns(rows) == []
    # a planning constant
    monkeypatch.setattr(mpc, "BEST_SCORE_STRIDES", mpc.BEST_SCORE_STRIDES + 1)
    assert stale_parts(recorded, ctrl) == ["constants"]
    assert stale_columns(rows) == ["docs/columns.json: column 'mpc' (mpc): its constants changed"]
    monkeypatch.undo()
    # a search setting of its spec: the same controller with horizon 13
    spec = (ROOT / "configs" / "controllers" / "mpc.yaml").read_text()
    assert "horizon: 12" in spec
    (tmp_path / "mpc.yaml").write_text(spec.replace("horizon: 12", "horizon: 13"))
    assert stale_parts(recorded, load_controller(tmp_path / "mpc.yaml")) == ["config"]
    # its code (the module's syntax tree; a docstring or a comment does not count)
    source = Path(mpc.__file__).read_text()
    monkeypatch.setattr(fpmod, "_code_tree", lambda text: fpmod.ast.dump(fpmod.ast.parse(text)))
    assert "code" in stale_parts(recorded, ctrl)
    monkeypatch.undo()
    edited = source.replace('"""Model-predictive', '"""Edited: model-predictive', 1)
    assert fpmod._code_tree(edited) == fpmod._code_tree(source)
    assert fpmod._code_tree(source.replace("horizon + 2.0", "horizon + 3.0")) != (
        fpmod._code_tree(source)
    )


def test_nothing_recorded_is_stale_and_the_passive_gait_is_itself():
    assert stale_parts(None, None) == list(CHECKED)
    assert stale_parts(column_fingerprint(None), None) == []
    fp = column_fingerprint("passive", commit=False)
    assert fp["controller"] == "passive" and "commit" not in fp


def test_the_config_ignores_the_last_bits_of_a_design_but_not_a_change():
    """A gain designed on another machine (or with a cold compiler cache) differs in its last
    bits: the same config; a gain changed in its 6th digit is another config."""
    from bound_env.control import load_controller

    ctrl = load_controller("lqr")
    before = column_fingerprint(ctrl, commit=False)
    ctrl.gain = ctrl.gain * (1 + 1e-15)
    assert column_fingerprint(ctrl, commit=False)["config"] == before["config"]
    ctrl.gain = ctrl.gain * (1 + 1e-6)
    assert column_fingerprint(ctrl, commit=False)["config"] != before["config"]


def test_a_column_reads_the_same_config_from_any_checkout_and_after_use(tmp_path):
    """A policy folder loaded by its relative path, by its absolute path or from a copy in
    another folder (another checkout), and an offset-free controller after it ran (its
    estimator's state moved), have one config: what a fresh clone reads is what was recorded.
    A changed weight is another config."""
    import shutil

    from agents.runtime.policy import load_controller

    rel = "agents/policies/finetuned/s0"
    copy = tmp_path / "elsewhere" / rel
    shutil.copytree(ROOT / rel, copy)
    configs = {
        column_fingerprint(load_controller(p), commit=False)["config"]
        for p in (rel, str(ROOT / rel), str(copy))
    }
    assert len(configs) == 1
    of = load_controller("lqr-of")
    before = column_fingerprint(of, commit=False)["config"]
    of.state.d += 0.01  # the estimator after three updates on a plant off the model
    of.state.count += 3
    assert np.all(of.state.d != 0.0)
    assert column_fingerprint(of, commit=False)["config"] == before
    ctrl = load_controller(rel)
    W, b = ctrl.layers[0]
    ctrl.layers[0] = (W * (1 + 1e-5), b)
    assert column_fingerprint(ctrl, commit=False)["config"] not in configs
