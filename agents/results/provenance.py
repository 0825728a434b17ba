"""How each column of the results page was made: its provenance section (`agents.results.page`).

A classical controller says its spec and how its design was chosen (`CLASSICAL_SELECTION`); a
trained policy its seed, timesteps, wall time, machine, command and whether a checkpoint was
selected (from its ``run.json`` and ``exported.json``), and its recipe how it was chosen
(`LEARNED_SELECTION`).
"""

from __future__ import annotations

import json
from pathlib import Path

from .formatting import ROOT, command_text, rel

# How each shipped classical design was chosen (docs/controllers.md, "Design table"): first on
# the quick budget with the test seed (its 32 random directions are the first 32 of the test
# set's: a selection on the test set), then re-chosen by the same criterion on the validation
# seed 777 (scripts/control_table.py): the same designs.
CLASSICAL_SELECTION = {
    "lqr": "its design (8 windows, Q = I, R = 0.1) was **first chosen on the quick budget with "
    "the test seed** (criterion: largest basin_min, then r50, the slope window, push recovery; "
    "its 32 random directions are the first 32 of the test set's 256, so that choice saw part of "
    "the test set), then **re-chosen on the validation seed 777** (seed 777's random "
    "directions, terrain and push samples, held out from the test set, seed 12345) among the 9 "
    "designs of the design table (docs/controllers.md): the same design, by a tie-break on r50 "
    "(0.1465 against 0.1462 for the other 8-window designs, which tie it on basin_min)",
    "deadbeat": "8 windows over 6: **first chosen on the quick budget with the test seed**, "
    "then **confirmed on the validation seed 777** by the same criterion (basin_min 4.8x "
    "against 3.9x the passive's on both; docs/controllers.md's design table)",
    "damping": "c is the spine's own damper c_c (the trivial baseline), not tuned on these "
    "yardsticks: no selection",
    "mpc": "**chosen on the validation seed 777**: its search settings (configs/controllers/"
    "mpc.yaml) were set before any measurement and kept against 4 variants (a longer horizon, "
    "a larger library, more cross-entropy rounds, a wider safe radius) on 96 random directions "
    "of seed 777 at r = 0.15-0.35 (docs/learned.md); its LQR is `lqr`'s design",
}
# How a learned recipe was chosen (docs/learned.md, "Selection, on held-out directions only"),
# said under its column's provenance
LEARNED_SELECTION = {
    "finetuned": "recipe **chosen on the validation seed 777** (96 random directions, r = "
    "0.15-0.35), never on the test set (seed 12345): each seed is PPO (1.5e6 strides) from the "
    "student distilled by DAgger from `mpc` with the same seed "
    "(`agents/policies/archive/distilled/sS`); fine-tuning was chosen over the distilled "
    "students and 1.5e6 strides over 3e5 there; "
    "the name `default` is seed 0 (no choice among seeds)",
    "step-ppo": "recipe (configs/ppo-residual.yaml) **chosen on the validation seed 777** "
    "(agents/runtime/residual.py `validation_curve`: 64 random directions, r = 0.2-0.4), never "
    "on the test set (seed 12345): step-level PPO on PassiveBound-v0 (`bound-env train --config "
    "ppo-residual`), a residual on `default`'s interval torques active past its safe radius; "
    "final models, one per seed",
    "warm-started": "ppo-v1's recipe (configs/ppo.yaml, 3e6 steps) unchanged, but the actor "
    "first clones the torques of the shipped `default` (fine-tuned/s0) in the training env "
    "(`train --init-from default`, agents/training/warmstart.py); final models, nothing chosen "
    "on any yardstick",
    "ppo-v1-final": "ppo-v1's recipe (configs/ppo.yaml) unchanged, its final models (the "
    "archived `ppo-v1` is a checkpoint selected on axis basins, left out here)",
}


def trained(g) -> bool:
    """Whether every policy of column ``g`` was trained (has a ``run.json``)."""
    return all((Path(p) / "run.json").is_file() for p in g["policies"])


def provenance(g) -> list[str]:
    """How each controller of a column was made."""
    lines = []
    for policy in g["policies"]:
        if policy == "passive":
            lines.append("zero spine torque (no controller)")
            continue
        p = Path(policy)
        info_path = p / "run.json"
        if not info_path.is_file():
            from ..runtime.policy import CONTROLLERS

            what = CONTROLLERS.get(policy, (None, None))[1]
            spec = ROOT / "configs" / "controllers" / f"{policy}.yaml"
            lines.append(
                f"controller `{policy}`"
                + (f": {what}" if what else "")
                + (f"; spec `{rel(str(spec))}`" if spec.is_file() else "")
                + "; designed, not trained: no seeds; "
                + CLASSICAL_SELECTION.get(
                    policy, "whether its spec was tuned on these yardsticks is not recorded here"
                )
            )
            continue
        info = json.loads(info_path.read_text())
        t = info.get("wall_time_s")
        exp_path = p / "exported.json"
        exp = json.loads(exp_path.read_text()) if exp_path.is_file() else {}
        if "timesteps" in exp:
            sel = (
                f"**selected**: the checkpoint with the best basin validation at "
                f"{exp['timesteps']} timesteps"
            )
        else:
            sel = "final model, **no selection**"
        made = info.get("timesteps_done", "?")
        made = made if isinstance(made, str) else f"{made} timesteps"  # or said in words
        lines.append(
            f"`{rel(policy)}`: seed {info.get('seed', '?')}, {made}, "
            f"{'%.1f min' % (t / 60) if t else '?'} of training on "
            f"{info.get('machine', '?')}; {sel}; command `{command_text(info.get('command', '?'))}`"
            + (f" ({info['note']})" if info.get("note") else "")
        )
    group = Path(g["policies"][0]).parent.name if g["policies"] else ""
    if group in LEARNED_SELECTION:
        lines.append(LEARNED_SELECTION[group])
    return lines


# --------------------------------------------------------------------------------------------
# The staleness check: is each committed column what its code and data make now?
# --------------------------------------------------------------------------------------------

PAGE_FILES = ("columns.json", "model_error.json")  # the committed page's files with columns
PAGE_COMMAND = "bound-env compare --budget full --workers 2 --docs docs"
AFTER = "then python -m agents.results.prose and python -m agents.results.headline"


def committed_columns(docs=None) -> list[dict]:
    """Every policy of every column of the committed page files (`PAGE_FILES` in ``docs``):
    its file, label, gait, policy, recorded fingerprint, and the file's budget, seed and the
    command its run recorded."""
    docs = Path(docs) if docs is not None else ROOT / "docs"
    out = []
    for name in PAGE_FILES:
        path = docs / name
        if not path.is_file():
            continue
        data = json.loads(path.read_text())
        command = (data.get("run") or {}).get("command") or PAGE_COMMAND
        for col in data.get("columns") or []:
            fps = col.get("fingerprints") or [None] * len(col["policies"])
            for policy, fp in zip(col["policies"], fps, strict=True):
                out.append(
                    {
                        "file": name,
                        "label": col["label"],
                        "gait": col["gait"],
                        "policy": policy,
                        "fingerprint": fp,
                        "budget": data.get("budget"),
                        "seed": data.get("seed"),
                        "command": command,
                    }
                )
    return out


def needs_torch(policy: str) -> bool:
    """Whether loading ``policy`` imports torch (a PPO model)."""
    return (ROOT / policy / "model.zip").is_file() or str(policy).endswith(".zip")


def column_staleness(row: dict, load: bool = True) -> list[str]:
    """The stale parts of one committed column's policy (`committed_columns`): its recorded
    fingerprint against what the code and data make now. ``load``: load the controller
    (its data, ``config``, is then checked too); else only the hashes that need no
    controller (the margins key's parts, the closure of the recorded roots, the files)."""
    from bound_env.analysis.margins.provenance.fingerprint import (
        CHECKED,
        VERSION,
        recorded_parts,
        stale_parts,
    )

    from .margins import fingerprint_now, policy_files_sha

    fp, gait, policy = row["fingerprint"], row["gait"], row["policy"]
    if not isinstance(fp, dict) or fp.get("version") != VERSION:
        return list(CHECKED)  # nothing recorded, or the first format: every part
    budget = row["budget"] or "full"
    if load:
        now = fingerprint_now(policy, gait, budget, row["seed"])
    else:
        now = recorded_parts(fp, gait, budget, row["seed"], files=policy_files_sha(policy))
    return stale_parts(fp, now)


def staleness_message(row: dict, parts: list[str]) -> str:
    """One line: the file, the column, the stale parts (what each is) and the command."""
    from bound_env.analysis.margins.provenance.fingerprint import PARTS, VERSION

    fp = row["fingerprint"]
    if not isinstance(fp, dict):
        why = "no fingerprint recorded"
    elif fp.get("version") != VERSION:
        why = f"its fingerprint is of an older format (version {fp.get('version', 1)})"
    else:
        why = "stale " + "; ".join(f"{p} ({PARTS[p]})" for p in parts)
    return (
        f"docs/{row['file']}: column {row['label']!r} ({row['policy']}): {why}; "
        f"regenerate: {row['command']}"
    )


def stale_columns(rows=None, load=None) -> list[str]:
    """One line per committed column's policy that is not what made it (`staleness_message`);
    ``load(policy)``: whether to load it (default: unless it needs torch)."""
    load = load or (lambda policy: not needs_torch(policy))
    out = []
    for row in committed_columns() if rows is None else rows:
        parts = column_staleness(row, load=load(row["policy"]))
        if parts:
            out.append(staleness_message(row, parts))
    return out


def _adaptive_hold_command(rows: list, out: str) -> str:
    """The ``scripts/adaptive_hold.py`` runs that remake ``rows``: one per seed and set of
    policies, with the specs that set was measured on (not every policy on every spec)."""
    groups: dict = {}  # (seed, policies) -> specs
    for seed in dict.fromkeys(r["seed"] for r in rows):
        by_spec: dict = {}
        for r in rows:
            if r["seed"] == seed:
                by_spec.setdefault(r["spec_name"], []).append(r["policy"])
        for spec, pols in by_spec.items():
            groups.setdefault((seed, tuple(dict.fromkeys(pols))), []).append(spec)
    return "; ".join(
        f"python scripts/adaptive_hold.py --policy {' '.join(pols)} --mismatch "
        f"{' '.join(specs)} --seed {seed} --out {out}"
        for (seed, pols), specs in groups.items()
    )


def _data_rows(docs: Path) -> dict:
    """{file: (its rows, the command that regenerates it)} of the data files the docs quote."""
    out = {}
    for name in ("hold_vs_delta.json", "hold_vs_delta_families.json"):
        path = docs / "data" / name
        if path.is_file():
            data = json.loads(path.read_text())
            rows = [r for c in data.get("columns", {}).values() for r in c.get("rows", [])]
            out[f"data/{name}"] = (rows, data.get("made_with"))
    for name in ("adaptive_hold_test.json", "adaptive_hold_validation.json"):
        path = docs / "data" / name
        if not path.is_file():
            continue
        rows = json.loads(path.read_text()).get("entries", [])
        out[f"data/{name}"] = (rows, _adaptive_hold_command(rows, rel(str(path))))
    path = docs / "data" / "adaptive_budget.json"
    if path.is_file():
        rows = json.loads(path.read_text()).get("rows", [])
        out["data/adaptive_budget.json"] = (rows, "; ".join(r["made_with"] for r in rows))
    path = docs / "data" / "adaptive_factors.json"
    if path.is_file():
        rows = json.loads(path.read_text())
        pols = " ".join(dict.fromkeys(r["policy"] for r in rows))
        specs = sorted({str(r.get("spec")) for r in rows})
        out["data/adaptive_factors.json"] = (
            rows,
            f"python scripts/adaptive_factors.py --policy {pols} --mismatch "
            f"{specs[0] if len(specs) == 1 else 'pm10'} --out {rel(str(path))}",
        )
    path = docs / "hold_eval.jsonl"
    if path.is_file():
        latest = {}  # a rerun appends: the last row of each (policy, delta, seed, set, n)
        for x in path.read_text().splitlines():
            if x.strip():
                r = json.loads(x)
                latest[(r["policy"], r["delta"], r["seed"], r.get("set", ""), r["n"])] = r
        rows = list(latest.values())
        pols = " ".join(dict.fromkeys(r["policy"] for r in rows))
        deltas = " ".join(f"{d:g}" for d in sorted({r["delta"] for r in rows}))
        seeds = sorted({r["seed"] for r in rows})
        out["hold_eval.jsonl"] = (
            rows,
            f"for s in {' '.join(map(str, seeds))}; do python scripts/hold_eval.py --policy "
            f"{pols} --delta {deltas} --seed $s --out {rel(str(path))}; done",
        )
    return out


def row_staleness(row: dict) -> str | None:
    """Why a data file's row is not what the code makes now (its code: bound_env's sources
    and its recorded closure; its policy's files), or None. Its inputs (spec, gait, strides)
    are the run's: a resumed run compares them (`reusable`)."""
    from bound_env.analysis.margins.provenance.fingerprint import VERSION, code_parts, margins_parts

    from .margins import policy_files_sha

    fp = row.get("fingerprint")
    if not isinstance(fp, dict) or fp.get("version") != VERSION:
        return "no fingerprint recorded"
    now = {"sources": margins_parts()["sources"], **code_parts(fp.get("roots") or [])}
    try:
        files = policy_files_sha(row.get("policy"))
    except (OSError, ValueError, TypeError):
        files = None
    if files is not None and fp.get("files") is not None:
        now["files"] = files
    parts = [k for k, v in now.items() if k != "roots" and fp.get(k) != v]
    return f"its {', '.join(parts)} changed" if parts else None


def stale_data(docs=None) -> list[str]:
    """One line per data file the docs quote (`_data_rows`) with a row that is not what the
    code and its policy's files make now: how many, the first, and the command."""
    docs = Path(docs) if docs is not None else ROOT / "docs"
    out = []
    for name, (rows, command) in _data_rows(docs).items():
        why = [(r, row_staleness(r)) for r in rows]
        bad = [(r, w) for r, w in why if w]
        if bad:
            r, w = bad[0]
            first = " ".join(str(r[k]) for k in ("policy", "delta", "spec_name", "seed") if k in r)
            out.append(
                f"docs/{name}: {len(bad)} of {len(rows)} rows stale ({first}: {w}); "
                f"regenerate: {command or 'the command in its docs'}"
            )
    return out


def main(argv=None) -> int:
    """``python -m agents.results.provenance [--load-all] [--data]``: the staleness check of
    the committed page (and of the data files the docs quote); exit 1 and one line per stale
    column (or file) when there is one."""
    import argparse
    import sys

    ap = argparse.ArgumentParser(description="Is every committed page column up to date?")
    ap.add_argument(
        "--load-all", action="store_true", help="load the PPO policies too (imports torch)"
    )
    ap.add_argument("--data", action="store_true", help="check the quoted data files too")
    args = ap.parse_args(argv)
    stale = stale_columns(load=(lambda p: True) if args.load_all else None)
    stale += stale_data() if args.data else []
    for line in stale:
        print(line, file=sys.stderr)
    if stale:
        print(AFTER, file=sys.stderr)
        return 1
    print(f"every column of {', '.join(PAGE_FILES)} is what its code and data make now")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())


# --------------------------------------------------------------------------------------------
# The rows of the resumable scripts (scripts/hold_vs_delta.py, hold_eval.py, adaptive_hold.py)
# --------------------------------------------------------------------------------------------


def row_fingerprint(policy, controller, gait="default", roots=(), **inputs) -> dict:
    """The fingerprint a script's row records (`bound_env.analysis.margins.provenance.fingerprint.
    run_fingerprint`): bound_env's sources, ``controller``'s code closure (and that of
    ``roots``), its data and files (``policy``'s: `margins.policy_files_sha`), the gait file
    and the row's ``inputs`` (a spec's contents, strides, robots, seed)."""
    from bound_env.analysis.margins.provenance.fingerprint import run_fingerprint

    from .margins import policy_files_sha

    files = policy_files_sha(policy) if isinstance(policy, (str, Path)) else None
    return run_fingerprint(controller, gait, files=files, roots=roots, **inputs)


def reusable(rows, now: dict, what: str, log=None):
    """The last of ``rows`` (a resumed row's earlier runs, oldest first) recorded under the
    fingerprint ``now``, or None; when some row was there under another fingerprint (or
    none), one line to ``log`` (stderr) says that ``what`` is recomputed, and which parts
    differ."""
    import sys

    from bound_env.analysis.margins.provenance.fingerprint import differing

    rows = list(rows)
    for row in reversed(rows):
        if not differing(row.get("fingerprint"), now):
            return row
    if rows:
        fp = rows[-1].get("fingerprint")
        why = (
            "it was made without a fingerprint"
            if not isinstance(fp, dict)
            else f"its {', '.join(differing(fp, now))} changed"
        )
        print(f"note: recomputing {what}: {why}", file=log or sys.stderr, flush=True)
    return None
