"""What the learned adaptive controller infers: its factor head's estimates against the truth.

    PYTHONPATH=. python scripts/adaptive_factors.py --policy adaptive/s0 adaptive/s1 \
        --mismatch pm10 --plants 32 --out docs/data/adaptive_factors.json

On the plants of validation seed 777 (`agents.experts.adaptive.validation_plants`: the
margins' plants of that seed, never the test seed's), each controller runs one episode per
plant from the nominal z* through the one stride map; after strides 1, 3, 10 and 30 (those
the robot reaches) its factor head's estimate of m1, m2, I1, I2, kb, kf, kc and zeta is
compared with the plant's true factor: per factor and stride, the Pearson correlation and
the rms error (in the factor's units, 0.0577 being a constant guess at 1 for a ±10 %
uniform draw). Written atomically to ``--out``, each entry with its ``fingerprint``
(`agents.results.provenance.row_fingerprint`: the code, the policy's data and files, the
spec's contents, the plants).
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from bound_env.files.values import number

CHECKPOINTS = (1, 3, 10, 30)


def factors_of(params, nominal, keys) -> np.ndarray:
    return np.array([getattr(params, k) / getattr(nominal, k) for k in keys])


def run(policy: str, spec: str, n: int) -> dict:
    from agents.experts.adaptive import FACTOR_KEYS, true_map, validation_plants
    from agents.results.provenance import row_fingerprint
    from agents.runtime.policy import load_controller
    from bound_env.model.mismatch import as_spec

    ctrl = load_controller(policy)
    # what made the entry (`agents.results.provenance.row_fingerprint`), before it is used
    fp = row_fingerprint(
        policy,
        ctrl,
        roots=("agents.experts.adaptive:true_map", "agents.experts.adaptive:validation_plants"),
        spec=as_spec(spec).to_dict(),
        plants=n,
        checkpoints=list(CHECKPOINTS),
    )
    plants = validation_plants(ctrl, spec, n)
    truth = np.array([factors_of(p, ctrl.params, FACTOR_KEYS) for p in plants])
    est = {s: np.full((n, len(FACTOR_KEYS)), np.nan) for s in CHECKPOINTS}
    for i, p in enumerate(plants):
        plant = true_map(ctrl, p)
        ctrl.reset()
        z = ctrl.z_ref.copy()
        for s in range(1, max(CHECKPOINTS) + 1):
            z = plant.map(z, ctrl.profile_actions(ctrl.plan(z))[0])
            if z is None:
                break
            if s in est:  # the estimate from the strides seen so far (the next decision's input)
                est[s][i] = list(ctrl.predicted_factors(ctrl.features(z)).values())
    out = {"policy": policy, "spec": spec, "plants": n, "keys": list(FACTOR_KEYS), "strides": {}}
    for s, E in est.items():
        ok = ~np.isnan(E[:, 0])
        row = {"robots": int(ok.sum())}
        for j, k in enumerate(FACTOR_KEYS):
            t, e = truth[ok, j], E[ok, j]
            r = float(np.corrcoef(t, e)[0, 1]) if ok.sum() > 2 and np.std(e) > 0 else None
            rms = float(np.sqrt(np.mean((t - e) ** 2))) if ok.any() else None
            row[k] = {"corr": r, "rms": rms}
        out["strides"][str(s)] = row
    out["fingerprint"] = fp
    return out


def parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--policy", nargs="+", required=True)
    ap.add_argument("--mismatch", default="pm10")
    ap.add_argument("--plants", type=number(int, 1, 4096), default=32)
    ap.add_argument("--out", required=True)
    return ap


def main(argv=None) -> int:
    ap = parser()
    args = ap.parse_args(argv)
    from agents.runtime.policy_args import check_run_arguments

    check_run_arguments(ap, args.policy, [args.mismatch])  # before the run starts
    from pathlib import Path

    from bound_env.files.cache import atomic_write

    res = [run(p, args.mismatch, args.plants) for p in args.policy]
    atomic_write(Path(args.out), json.dumps(res, indent=1) + "\n")
    for r in res:
        for s, row in r["strides"].items():
            cells = " ".join(
                f"{k} {row[k]['corr']:+.2f}" if row[k]["corr"] is not None else f"{k} -"
                for k in r["keys"]
            )
            print(f"{r['policy']} stride {s} ({row['robots']} robots): corr {cells}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
