"""A resumable script reuses a row only under the same fingerprint (issue 48, item 6).

scripts/hold_vs_delta.py, scripts/hold_eval.py and scripts/adaptive_hold.py record each row's
fingerprint (`agents.results.provenance.row_fingerprint`: the code, the controller's data and
files, the gait, the spec's contents, the strides) and reuse a resumed row only when it is the
same; otherwise they recompute it and say so. The measure itself is replaced here by a
counter (its own tests are tests/test_hold_eval.py and the margins'): what is checked is which
rows are measured again.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

from bound_env.files.resources import controllers_dir


def _lqr_copy(tmp_path) -> Path:
    spec = tmp_path / "mylqr.yaml"
    shutil.copyfile(Path(controllers_dir()) / "lqr.yaml", spec)
    return spec


def _edit_gain(spec: Path) -> None:
    text = spec.read_text()
    assert "- [9.33" in text
    spec.write_text(text.replace("- [9.33", "- [9.34", 1))


def test_hold_vs_delta_reuses_a_row_only_under_its_fingerprint(
    tmp_path, monkeypatch, capsys, load_script
):
    mod = load_script("hold_vs_delta")
    calls = []

    def hold_row(ctrl, delta, seed, gait="default", budget="quick", spec="pm10"):
        calls.append((delta, str(gait)))
        return {"k": 1, "n": 2, "effort_median": 0.5, "delta": delta, "seed": seed}

    monkeypatch.setattr(mod, "hold_row", hold_row)
    spec = _lqr_copy(tmp_path)
    out = tmp_path / "h.json"
    argv = ["--policy", str(spec), "--delta", "5", "--seed", "777", "--out", str(out)]
    assert mod.main(argv) == 0 and len(calls) == 1
    row = json.loads(out.with_suffix(".jsonl").read_text())
    assert row["fingerprint"]["files"] and row["fingerprint"]["sources"]
    assert mod.main(argv) == 0 and len(calls) == 1  # resumed: the same row
    assert "recomputing" not in capsys.readouterr().err
    _edit_gain(spec)  # the spec file edited
    assert mod.main(argv) == 0 and len(calls) == 2
    err = capsys.readouterr().err
    assert "note: recomputing" in err and "config" in err and "files" in err
    assert mod.main(argv) == 0 and len(calls) == 2  # the new row is reused
    assert mod.main([*argv, "--gait", "literal-cycle"]) == 0 and len(calls) == 3
    assert "gait" in capsys.readouterr().err
    data = json.loads(out.read_text())
    assert (
        data["columns"][str(spec)]["rows"][0]["fingerprint"]["gait"] != row["fingerprint"]["gait"]
    )


def test_hold_eval_reuses_a_row_only_under_its_fingerprint(
    tmp_path, monkeypatch, capsys, load_script
):
    mod = load_script("hold_eval")
    calls = []

    def hold(setup):
        calls.append(setup.mismatch_budget.hold_strides)
        n = setup.mismatch_budget.plants
        return {"held": [True] * n, "strides": [1] * n, "tail_effort": [1.0] * n}

    monkeypatch.setattr(mod, "hold", hold)
    spec = _lqr_copy(tmp_path)
    out = tmp_path / "rows.jsonl"
    argv = ["--policy", str(spec), "--delta", "0.05", "--robots", "2", "--out", str(out)]
    assert mod.main([*argv, "--strides", "20"]) == 0 and calls == [20]
    assert mod.main([*argv, "--strides", "20"]) == 0 and calls == [20]
    assert mod.main([*argv, "--strides", "30"]) == 0 and calls == [20, 30]
    assert "note: recomputing" in capsys.readouterr().err
    _edit_gain(spec)
    assert mod.main([*argv, "--strides", "30"]) == 0 and calls == [20, 30, 30]
    rows = [json.loads(x) for x in out.read_text().splitlines()]
    # a recomputed row replaces the one before it: one row per key, the newest
    assert len(rows) == 1 and rows[0]["fingerprint"]["inputs"]
    assert mod.main([*argv, "--delta", "0.1", "--strides", "30"]) == 0 and len(calls) == 4
    rows = [json.loads(x) for x in out.read_text().splitlines()]
    assert [r["delta"] for r in rows] == [0.05, 0.1]  # 0.05 kept, 0.1 added


def test_adaptive_hold_reuses_an_entry_only_under_its_fingerprint(
    tmp_path, monkeypatch, capsys, load_script
):
    mod = load_script("adaptive_hold")
    calls = []

    def hold_entry(policy, spec_text, seed, ctrl=None):
        from bound_env.model.mismatch import as_spec

        calls.append(policy)
        spec = as_spec(spec_text)
        return {
            "policy": policy,
            "spec_name": spec.name,
            "seed": seed,
            "held": 1,
            "n": 2,
            "effort_median": 0.5,
            "seconds": 0.0,
        }

    monkeypatch.setattr(mod, "hold_entry", hold_entry)
    spec = tmp_path / "mine.yaml"
    spec.write_text("name: mine\nparams: {m1: 0.1, kc: 0.1}\n")
    out = tmp_path / "a.json"
    argv = ["--policy", "lqr", "--mismatch", str(spec), "--seed", "777", "--out", str(out)]
    assert mod.main(argv) == 0 and calls == ["lqr"]
    assert mod.main(argv) == 0 and calls == ["lqr"]
    spec.write_text("name: mine\nparams: {m1: 0.1, kc: 0.2}\n")  # the spec edited
    assert mod.main(argv) == 0 and calls == ["lqr", "lqr"]
    assert "note: recomputing lqr mine seed 777: its inputs changed" in capsys.readouterr().err
    entries = json.loads(out.read_text())["entries"]
    assert len(entries) == 1 and entries[0]["fingerprint"]["inputs"]
    # an entry of an older run, without a fingerprint, is recomputed in its place
    entries[0].pop("fingerprint")
    out.write_text(json.dumps({"entries": entries}))
    assert mod.main(argv) == 0 and calls == ["lqr"] * 3
    assert "made without a fingerprint" in capsys.readouterr().err
    assert len(json.loads(out.read_text())["entries"]) == 1
