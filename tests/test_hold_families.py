"""Hold against delta for any spec's family (issue 45, item 6): `hold_delta.spec_at` sets the
parameters a spec varies to each delta and keeps its noise and delay; `scripts/hold_vs_delta.py
--mismatch` draws one family per spec."""

from __future__ import annotations

import json

import pytest

from bound_env.analysis.margins.model_error.hold_delta import (
    family,
    hold_delta_table,
    hold_row,
    spec_at,
)
from bound_env.control import load_controller
from bound_env.model.mismatch import as_spec


@pytest.mark.parametrize(
    "given, delta, preset",
    [
        ("pm10", 0.05, "pm5"),
        ("pm10+noise", 0.2, "pm20+noise"),
        ("pm15+delay1", 0.1, "pm10+delay1"),
        ("all10", 0.05, "all5"),
        ("pm10+noise+delay1", 0.15, "pm15+noise+delay1"),
    ],
)
def test_a_family_at_a_presets_delta_is_that_preset(given, delta, preset):
    """So its plants, noise streams and outcomes are the margins' own of that preset."""
    assert spec_at(given, delta) == as_spec(preset)


def test_a_family_keeps_its_noise_and_delay_and_names_itself(tmp_path):
    s = spec_at("pm10+noise+delay1", 0.125)
    assert dict(s.ranges)["kc"] == 0.125 and "lb_bar" not in dict(s.ranges)
    assert s.noise == as_spec("noise").noise and s.delay == 1
    assert s.name == "pm12.5+noise+delay1" and family(s) == "pm+noise+delay1"
    assert family("all10") == "all" and family("pm5+delay2") == "pm+delay2"
    f = tmp_path / "two.yaml"
    f.write_text("params: {m1: 0.1, kc: 0.2}\nnoise: 0.01\n")
    two = spec_at(str(f), 0.05)
    assert dict(two.ranges) == {"m1": 0.05, "kc": 0.05} and two.has_noise
    assert family(str(f)) == "params(m1,kc)+noise"
    with pytest.raises(ValueError, match="varies no plant parameter"):
        family("noise+delay1")
    with pytest.raises(ValueError, match=r"delta 1\.0"):
        spec_at("pm10", 1.0)


def test_hold_row_of_a_family_measures_that_family():
    """The delay family's row is the hold under pmD+delay1, the margins' own: here the same
    as the parameter-only row's plants, and other outcomes (one interval of delay)."""
    lqr = load_controller("lqr")
    pm = hold_row(lqr, 0.2, 777, budget="test")
    delayed = hold_row(lqr, 0.2, 777, budget="test", spec="pm10+delay2")
    assert (pm["family"], pm["spec"]) == ("pm", "pm20")
    assert (delayed["family"], delayed["spec"]) == ("pm+delay2", "pm20+delay2")
    assert delayed["strides_reached"] != pm["strides_reached"]
    again = hold_row(lqr, 0.2, 777, budget="test", spec="pm20")
    assert again["strides_reached"] == pm["strides_reached"]


def test_the_script_runs_one_family_per_spec_and_refuses_bad_ones(
    tmp_path, monkeypatch, capsys, load_script
):
    mod = load_script("hold_vs_delta")
    calls = []

    def fake(ctrl, delta, seed, gait="default", budget="quick", spec="pm10"):
        calls.append((spec, delta))
        s = spec_at(spec, delta)
        return {"k": 1, "n": 2, "ci": [0.1, 0.9], "effort_median": 0.5, "delta": delta,
                "seed": seed, "family": family(s), "spec": s.name}  # fmt: skip

    monkeypatch.setattr(mod, "hold_row", fake)
    out = tmp_path / "h.json"
    argv = ["--policy", "lqr", "--delta", "5", "20", "--seed", "777", "--out", str(out)]
    fams = ["--mismatch", "pm10", "pm10+delay1"]
    assert mod.main([*argv, *fams]) == 0
    assert calls == [("pm10", 0.05), ("pm10", 0.2), ("pm10+delay1", 0.05), ("pm10+delay1", 0.2)]
    data = json.loads(out.read_text())
    assert data["families"] == ["pm", "pm+delay1"]
    assert [r["spec"] for r in data["columns"]["lqr"]["rows"]] == [
        "pm5", "pm20", "pm5+delay1", "pm20+delay1"
    ]  # fmt: skip
    assert "pm+delay1:" in hold_delta_table(data)
    assert mod.main([*argv, "--mismatch", "pm15+delay1"]) == 0 and len(calls) == 4  # resumed
    for bad, says in (
        (["--mismatch", "noise"], "--mismatch: mismatch 'noise': it varies no plant parameter"),
        (["--mismatch", "pm10", "pm5"], "are the same family 'pm'"),
        (["--mismatch", "pm12"], "--mismatch: unknown mismatch preset"),
        (["--delta", "0"], "--delta: 0 is not a percentage in (0, 100)"),
        (["--delta", "nan"], "--delta: nan is not a percentage"),
    ):
        with pytest.raises(SystemExit) as e:
            mod.main([*argv, *bad])
        err = capsys.readouterr().err.strip().splitlines()
        assert e.value.code == 2 and says in err[-1], err
