"""The committed results page knows which code and data made it.

Every column of ``docs/columns.json`` (and of ``docs/model_error.json``) records, per policy,
the fingerprint of what decided its numbers
(`bound_env.analysis.margins.provenance.fingerprint`: the margins cache key's parts, the
controller's code closure and its data). The check
(`agents.results.provenance.stale_columns`) compares hashes and reruns nothing; a column whose
code or data is no longer what made it fails it, with a line naming the file, the column, the
stale part and the command that regenerates the file. The PPO columns are checked in the fast
tier by their hashes (their recorded closure roots, their files); the slow tier loads them
(torch) to check their data too.

Each audited edit below (issue 44) is made through the source-reading layer
(`code_closure.read_source`), never on the files themselves.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from agents.results import provenance
from agents.results.margins import fingerprint_now
from bound_env.analysis.margins.provenance import code_closure
from bound_env.analysis.margins.provenance.fingerprint import (
    CHECKED,
    VERSION,
    code_parts,
    column_fingerprint,
    recorded_parts,
    stale_parts,
)

ROOT = Path(__file__).resolve().parent.parent
BUDGET, SEED = "full", 12345
# the columns the audit named (passive, lqr, mpc, fine-tuned, mpc-adaptive)
AUDITED = ("passive", "lqr", "mpc", "agents/policies/finetuned/s0", "mpc-adaptive")


def test_every_committed_column_is_what_its_code_and_data_make_now():
    """Every column of the committed page files, the PPO ones by their hashes."""
    rows = provenance.committed_columns()
    assert {r["file"] for r in rows} == {"columns.json", "model_error.json"}
    stale = provenance.stale_columns(rows)
    assert not stale, (
        "the committed page is stale (after a change of the code or data, regenerate it):\n"
        + "\n".join(stale)
        + "\n"
        + provenance.AFTER
    )


@pytest.mark.slow  # loads torch for the PPO policies' columns: their data too
def test_every_committed_ppo_column_is_what_its_policy_is_now():
    rows = [r for r in provenance.committed_columns() if provenance.needs_torch(r["policy"])]
    assert rows
    stale = provenance.stale_columns(rows, load=lambda policy: True)
    assert not stale, "the committed page is stale:\n" + "\n".join(stale)


@pytest.fixture(scope="module")
def loaded():
    """The audited columns' controllers, loaded once, and their fingerprints as recorded."""
    from agents.runtime.policy import load_controller

    ctrls = {p: load_controller(p, gait="default") for p in AUDITED}
    recorded = {p: record(p, ctrls[p]) for p in AUDITED}
    return ctrls, recorded


def record(policy, ctrl, gait="default"):
    return fingerprint_now(policy, gait, BUDGET, SEED, controller=ctrl)


def edit_source(monkeypatch, rel: str, old: str, new: str) -> None:
    """``rel`` (a project file) as the hashes read it: ``old`` replaced by ``new`` once."""
    path = (ROOT / rel).resolve()
    text = path.read_text()
    assert text.count(old) >= 1, f"{rel} no longer has {old!r}: update the audited edit"
    edited = text.replace(old, new, 1)
    assert edited != text
    real = code_closure.read_source

    def read(p):
        return edited if Path(p).resolve() == path else real(p)

    monkeypatch.setattr(code_closure, "read_source", read)


def stale_after(loaded) -> dict:
    ctrls, recorded = loaded
    return {p: stale_parts(recorded[p], record(p, ctrls[p])) for p in AUDITED}


def test_the_audited_columns_are_fresh_as_recorded(loaded):
    assert stale_after(loaded) == {p: [] for p in AUDITED}


# (file, old, new, {column: the parts it must name}; every other audited column: "sources")
AUDITED_EDITS = {
    "stride_map.EVAL_RTOL 1e-10 -> 1e-6": (
        "bound_env/sim/stride_map.py",
        "EVAL_RTOL = 1e-10",
        "EVAL_RTOL = 1e-6",
        {"mpc": ["sources", "constants"], "mpc-adaptive": ["sources", "constants"]},
    ),
    "stride_map.RETURN_TOL": (
        "bound_env/sim/stride_map.py",
        "RETURN_TOL = 1e-4",
        "RETURN_TOL = 1e-3",
        {},
    ),
    "task._ANGLE_BOUND (the fall criterion)": (
        "bound_env/sim/task.py",
        "_ANGLE_BOUND = 2.0 * math.pi",
        "_ANGLE_BOUND = 1.5 * math.pi",
        {"mpc": ["sources", "constants"]},
    ),
    "budget.MFPT_LEVEL 100 -> 50": (
        "bound_env/analysis/margins/budget.py",
        "MFPT_LEVEL = 100.0",
        "MFPT_LEVEL = 50.0",
        {},
    ),
    "identify.LM_MU0": (
        "bound_env/control/identify.py",
        "LM_MU0 = 1e-3",
        "LM_MU0 = 1e-2",
        {"mpc-adaptive": ["sources", "constants"]},
    ),
    "plant_design.MAX_SHIFT": (
        "bound_env/control/plant_design.py",
        "MAX_SHIFT = 4.0",
        "MAX_SHIFT = 3.0",
        {"mpc-adaptive": ["sources", "constants"]},
    ),
    "mpc's StrideMap swapped for another class": (
        "bound_env/control/mpc.py",
        "from ..sim.stride_map import StrideMap\n",
        "from ..sim.stride_map import Strides as StrideMap\n",
        {"mpc": ["sources", "code"], "mpc-adaptive": ["sources", "code"]},
    ),
}


@pytest.mark.parametrize("edit", sorted(AUDITED_EDITS))
def test_an_audited_edit_makes_every_column_that_uses_it_stale(loaded, monkeypatch, edit):
    """Every bound_env edit stales every column through the margins key's ``sources`` (every
    bound_env source decides the margins); one in a controller's closure names its
    ``constants`` or ``code`` too."""
    rel, old, new, named = AUDITED_EDITS[edit]
    edit_source(monkeypatch, rel, old, new)
    stale = stale_after(loaded)
    for policy in AUDITED:
        assert "sources" in stale[policy], (policy, stale[policy])
        for part in named.get(policy, []):
            assert part in stale[policy], (policy, part, stale[policy])
    # the check's line names the column, the part and the command
    row = {
        "file": "columns.json",
        "label": "mpc",
        "gait": "default",
        "policy": "mpc",
        "fingerprint": loaded[1]["mpc"],
        "budget": BUDGET,
        "seed": SEED,
        "command": provenance.PAGE_COMMAND,
    }
    (line,) = provenance.stale_columns([row])
    assert line.startswith("docs/columns.json: column 'mpc' (mpc): stale sources (bound_env")
    assert line.endswith("regenerate: " + provenance.PAGE_COMMAND)


def test_the_hidden_layers_of_mlp_forward_stale_the_learned_columns_only(loaded, monkeypatch):
    """agents code is not in the margins key's sources: the learned column's closure sees it,
    the classical and passive columns do not use it."""
    mlp = code_parts(["agents.runtime.controllers:MLPController"])
    edit_source(
        monkeypatch,
        "agents/common/mlp.py",
        "        h = act(affine(h, W, b))",
        "        h = act(affine(h, 0.9 * W, b))",
    )
    stale = stale_after(loaded)
    assert stale["agents/policies/finetuned/s0"] == ["code"]
    assert stale["passive"] == stale["lqr"] == stale["mpc"] == stale["mpc-adaptive"] == []
    # a PPO column (MLPController), checked from its recorded roots without torch
    assert code_parts(["agents.runtime.controllers:MLPController"])["code"] != mlp["code"]


def test_editing_mlp_controller_leaves_passive_fresh(loaded, monkeypatch):
    """ZeroController and MLPController share a module; the closure is per object."""
    ppo = {"roots": ["agents.runtime.controllers:MLPController"]}
    ppo.update(recorded_parts(ppo, "default", BUDGET, SEED))
    edit_source(
        monkeypatch,
        "agents/runtime/controllers.py",
        "        return float(np.clip(out[0], -1.0, 1.0))",
        "        return float(np.clip(out[0], -0.9, 0.9))",
    )
    stale = stale_after(loaded)
    assert stale["passive"] == []
    assert stale_parts(ppo, recorded_parts(ppo, "default", BUDGET, SEED)) == ["code"]


def test_passive_on_two_gaits_has_two_fingerprints(loaded):
    ctrls, recorded = loaded
    literal = record("passive", ctrls["passive"], gait="literal-cycle")
    assert stale_parts(recorded["passive"], literal) == ["gait"]


def test_a_docstring_or_comment_edit_stales_nothing(loaded, monkeypatch):
    text = (ROOT / "bound_env/sim/stride_map.py").read_text()
    first = text.index('"""') + 3
    edited = text[:first] + "Edited. " + text[first:]
    edited = edited.replace("EVAL_RTOL = 1e-10  #", "EVAL_RTOL = 1e-10  # edited comment;", 1)
    edited = edited.replace('    """', '    """Edited: ', 1)  # a function's docstring
    assert edited != text
    edit_source(monkeypatch, "bound_env/sim/stride_map.py", text, edited)
    assert stale_after(loaded) == {p: [] for p in AUDITED}


def test_an_edit_of_a_module_no_column_uses_stales_none(loaded, monkeypatch):
    """agents/runtime/residual.py (step-level residual PPO) is no audited column's code."""
    text = (ROOT / "agents/runtime/residual.py").read_text()
    edit_source(monkeypatch, "agents/runtime/residual.py", text, text + "\nEDITED = 1\n")
    assert stale_after(loaded) == {p: [] for p in AUDITED}


def test_the_first_format_and_nothing_recorded_read_as_stale():
    rows = provenance.committed_columns()
    old = {"controller": "passive", "config": "x", "constants": "y", "code": "z"}
    row = dict(rows[0], fingerprint=old, policy="passive", gait="default")
    assert provenance.column_staleness(row) == list(CHECKED)
    (line,) = provenance.stale_columns([row])
    assert "older format (version 1)" in line and "regenerate: " in line
    (line,) = provenance.stale_columns([dict(row, fingerprint=None)])
    assert "no fingerprint recorded" in line
    assert stale_parts(None, None) == list(CHECKED)
    fp = column_fingerprint("passive", commit=False)
    assert fp["controller"] == "passive" and "commit" not in fp and fp["version"] == VERSION


def test_a_changed_spec_or_weight_is_stale_data(tmp_path, loaded):
    """A search setting of a spec (a copy with horizon 13) changes the data and the files; a
    weight changed in its 6th digit changes the data."""
    from bound_env.control import load_controller

    spec = (ROOT / "configs" / "controllers" / "mpc.yaml").read_text()
    assert "horizon: 12" in spec
    (tmp_path / "mpc.yaml").write_text(spec)
    before = fingerprint_now(tmp_path / "mpc.yaml", budget=BUDGET, seed=SEED)
    (tmp_path / "mpc.yaml").write_text(spec.replace("horizon: 12", "horizon: 13"))
    after = fingerprint_now(tmp_path / "mpc.yaml", budget=BUDGET, seed=SEED)
    assert stale_parts(before, after) == ["config", "files"]
    ctrl = load_controller("lqr")
    before = column_fingerprint(ctrl, commit=False)
    ctrl.gain = ctrl.gain * (1 + 1e-15)  # the last bits of a design: the same data
    assert stale_parts(before, ctrl) == []
    ctrl.gain = ctrl.gain * (1 + 1e-6)
    assert stale_parts(before, ctrl) == ["config"]


def test_a_column_reads_the_same_fingerprint_from_any_checkout_and_after_use(tmp_path):
    """A policy folder loaded by its relative path, by its absolute path or from a copy in
    another folder (another checkout), and an offset-free controller after it ran (its
    estimator's state moved), have one fingerprint: what a fresh clone reads is what was
    recorded. A changed weight is another config."""
    from agents.runtime.policy import load_controller

    rel = "agents/policies/finetuned/s0"
    copy = tmp_path / "elsewhere" / rel
    shutil.copytree(ROOT / rel, copy)
    fps = [fingerprint_now(p, budget=BUDGET, seed=SEED) for p in (rel, str(ROOT / rel), copy)]
    assert all(stale_parts(fps[0], f) == [] for f in fps[1:])
    of = load_controller("lqr-of")
    before = column_fingerprint(of, commit=False)
    of.state.d += 0.01  # the estimator after three updates on a plant off the model
    of.state.count += 3
    assert np.all(of.state.d != 0.0)
    assert stale_parts(before, of) == []
    ctrl = load_controller(rel)
    W, b = ctrl.layers[0]
    ctrl.layers[0] = (W * (1 + 1e-5), b)
    assert stale_parts(fps[0], fingerprint_now(rel, budget=BUDGET, seed=SEED, controller=ctrl)) == [
        "config"
    ]


def test_compare_records_the_new_fingerprint(tmp_path, monkeypatch):
    """What `compute_margins` records is what the check recomputes: a column made now is fresh
    (the core's fingerprint, without running a task: its assembly is replaced)."""
    import bound_env.analysis.margins.run as run
    from agents.results.margins import compute_margins

    class Stop(Exception):
        pass

    seen, real = {}, run.column_fingerprint

    def capture(ctrl, **kw):
        seen.update(real(ctrl, **kw))
        raise Stop

    monkeypatch.setattr(run, "column_fingerprint", capture)
    with pytest.raises(Stop):
        compute_margins("lqr", budget="quick", out=tmp_path)
    assert seen["version"] == VERSION and seen["files"] and seen["margins_key"]
    assert stale_parts(seen, fingerprint_now("lqr", budget="quick")) == []
    json.dumps(seen)  # JSON-able, as columns.json holds it


def test_every_quoted_data_file_records_a_current_fingerprint():
    """docs/data/hold_vs_delta.json and hold_vs_delta_families.json, adaptive_hold_test.json and
    adaptive_hold_validation.json, adaptive_factors.json, adaptive_budget.json and
    docs/hold_eval.jsonl: every row records the fingerprint of what made it, and it is what the
    code and its policy's files make now."""
    stale = provenance.stale_data()
    assert not stale, "a data file the docs quote is stale:\n" + "\n".join(stale)


def test_a_data_row_is_stale_after_a_code_edit_and_fresh_after_a_docstring_edit(monkeypatch):
    from agents.runtime.policy import load_controller

    fp = provenance.row_fingerprint("lqr", load_controller("lqr"), spec={"m1": 0.1}, strides=100)
    row = {"policy": "lqr", "delta": 0.1, "seed": 777, "fingerprint": fp}
    assert provenance.row_staleness(row) is None
    assert provenance.row_staleness(dict(row, fingerprint=None)) == "no fingerprint recorded"
    text = (ROOT / "bound_env/sim/stride_map.py").read_text()
    edit_source(monkeypatch, "bound_env/sim/stride_map.py", '"""', '"""Edited. ')
    assert provenance.row_staleness(row) is None
    monkeypatch.undo()
    edit_source(monkeypatch, "bound_env/sim/stride_map.py", "EVAL_RTOL = 1e-10", "EVAL_RTOL = 1e-6")
    assert provenance.row_staleness(row) == "its sources changed"
    assert text == (ROOT / "bound_env/sim/stride_map.py").read_text()  # the file itself untouched


def test_the_adaptive_hold_regenerate_command_measures_only_the_rows_that_are_there():
    """One run per seed and set of policies, with the specs that set has: not every policy on
    every spec (which would measure rows that nobody quotes)."""
    rows = [
        {"policy": p, "spec_name": s, "seed": 12345}
        for p, s in [("lqr", "pm10"), ("mpc", "pm10"), ("lqr", "pm15"), ("mpc", "pm15")]
    ] + [{"policy": "mpc-adaptive", "spec_name": "all10", "seed": 12345}]
    rows.append({"policy": "lqr", "spec_name": "pm10", "seed": 777})
    cmd = provenance._adaptive_hold_command(rows, "x.json").split("; ")
    assert cmd == [
        "python scripts/adaptive_hold.py --policy lqr mpc --mismatch pm10 pm15 --seed 12345 "
        "--out x.json",
        "python scripts/adaptive_hold.py --policy mpc-adaptive --mismatch all10 --seed 12345 "
        "--out x.json",
        "python scripts/adaptive_hold.py --policy lqr --mismatch pm10 --seed 777 --out x.json",
    ]
