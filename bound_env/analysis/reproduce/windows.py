"""Stage 3: Figs. 7-8, e_max against alpha and kc the paper's way."""

from __future__ import annotations

import numpy as np

from ...model.params import z_to_paper
from .claims import reproducing_gait
from .points import eig_list
from .settings import Budget


def _sweep_dict(res) -> dict:
    pts = []
    for q in res.points:
        pts.append(
            {
                "value": q.value,
                "converged": q.converged,
                "error": q.error,
                "failure": q.failure,
                "found": q.found,
                "emax": q.emax,
                "eigenvalues": eig_list(q.eigenvalues),
                "phases": q.phases,
                "has_ds": q.has_ds,
                "z": None if q.z is None else z_to_paper(q.z),
            }
        )
    base = res.base
    found = [q for q in res.points if q.found]
    ds_up = [q.value for q in found if q.value >= base and q.has_ds]
    nods_up = [q.value for q in found if q.value >= base and not q.has_ds]
    ds_down = [q.value for q in found if q.value <= base and q.has_ds]
    return {
        "param": res.param,
        "base": base,
        "points": pts,
        "converged_window": res.converged_window,
        "stable_window": res.stable_window,
        "ds_from": min(ds_up) if ds_up else None,
        "no_ds_up_to": max([v for v in nods_up if not ds_up or v < min(ds_up)], default=None),
        "ds_below_base": sorted(ds_down),
    }


def stage_sweeps(b: Budget, z_star_si, log) -> dict:
    from ..sweeps import sweep

    g = reproducing_gait()
    out = {}
    for key, (lo, hi, st) in (("alpha_deg", b.alpha_sweep), ("kc", b.kc_sweep)):
        for factor in (1, 2) if b.coarse_sweeps else (1,):
            vals = np.round(np.arange(lo, hi + 0.5 * st * factor, st * factor), 12)
            res = sweep(g.params, np.asarray(z_star_si, float), key, vals, refine=b.refine)
            d = _sweep_dict(res)
            d["step"] = st * factor
            name = key if factor == 1 else f"{key}_coarse"
            out[name] = d
            log(
                f"  {key} (step {st * factor:g}): 100-stride window {d['converged_window']}, "
                f"e_max < 1 window {d['stable_window']}, ds from {d['ds_from']}"
            )
    return out
