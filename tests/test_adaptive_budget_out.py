"""benchmarks/adaptive_budget.py --out writes its row with a fingerprint, replacing an earlier
row of the same policy and budget (the docs quote docs/data/adaptive_budget.json). Nothing
about speed is asserted."""

from __future__ import annotations

import json


def test_the_benchmark_writes_a_fingerprinted_row_and_replaces_its_own(tmp_path, load_script):
    mod = load_script("benchmarks/adaptive_budget")
    out = tmp_path / "budget.json"
    out.write_text(json.dumps({"note": "kept", "rows": [{"policy": "other", "budget": 0}]}))
    argv = [
        "--plants",
        "1",
        "--strides",
        "2",
        "--policy",
        "mpc-adaptive-bounded",
        "--out",
        str(out),
    ]
    assert mod.main(argv) == 0
    assert mod.main(argv) == 0  # a second run replaces its row
    data = json.loads(out.read_text())
    assert data["note"] == "kept"
    mine = [r for r in data["rows"] if r["policy"] == "mpc-adaptive-bounded"]
    assert len(mine) == 1 and len(data["rows"]) == 2
    row = mine[0]
    assert row["budget"] == 48 and row["n"] == 1 and row["decisions"] >= 1
    assert row["fingerprint"]["sources"] and row["fingerprint"]["code"]
    assert "--out" in row["made_with"] and row["max_ms"] >= row["p99_ms"] >= row["p50_ms"] > 0
