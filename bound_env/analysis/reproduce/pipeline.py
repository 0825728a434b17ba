"""``bound-env reproduce``: every stage (or its cache), then figures, CSVs and the report."""

from __future__ import annotations

import json
import shutil
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np

from ...files.cache import atomic_write
from .claims import gait_config, literal_gait, reproducing_gait
from .closest import stage_closest
from .document.report import write_report
from .figures import write_figures
from .gaits import write_gait_files
from .literal import stage_literal
from .reproducing import stage_reproducing
from .settings import CACHE_VERSION, FULL, QUICK
from .stiff import stage_stiff
from .store import Cache, ProgressLog, jsonable
from .windows import stage_sweeps


def run(
    out_dir,
    quick: bool = False,
    force: bool = False,
    progress: bool = True,
    write_gaits: bool = False,
    docs_dir=None,
) -> dict:
    """Run every stage (or read it from the cache), write figures, CSVs and REPRODUCTION.md."""
    t0 = time.perf_counter()
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    log = ProgressLog(progress)
    b = QUICK if quick else FULL
    cache = Cache(out_dir, force, log)
    base_cfg = {
        "version": CACHE_VERSION,
        "budget": asdict(b),
        "paper": gait_config(reproducing_gait()),
        "literal": gait_config(literal_gait()),
    }
    results: dict = {"budget": asdict(b)}
    results["reproducing"] = cache.get("reproducing", base_cfg, lambda: stage_reproducing(b, log))
    z_star = np.asarray(results["reproducing"]["fixed_point"]["z_si"], float)
    cfg = {**base_cfg, "z_star": z_star}
    results["closest"] = cache.get("closest", cfg, lambda: stage_closest(b, z_star, log))
    results["sweeps"] = cache.get("sweeps", cfg, lambda: stage_sweeps(b, z_star, log))
    results["stiff"] = cache.get("stiff", cfg, lambda: stage_stiff(b, z_star, log))
    results["literal"] = cache.get("literal", cfg, lambda: stage_literal(b, z_star, log))
    results["cache"] = {"hits": cache.hits, "misses": cache.misses}
    results["compute_seconds"] = {
        k: results[k].get("seconds")
        for k in ("reproducing", "closest", "sweeps", "stiff", "literal")
    }
    log("figures")
    figs = write_figures(results, out_dir / "figures")
    results["figures"] = [str(p.relative_to(out_dir)) for p in figs]
    results["wall_seconds"] = time.perf_counter() - t0
    report = write_report(results, out_dir / "REPRODUCTION.md")
    atomic_write(
        out_dir / "results.json",
        json.dumps(
            jsonable(
                {k: v for k, v in results.items() if k != "figures"}
                | {"figures": results["figures"]}
            )
        ),
    )
    if write_gaits:
        for pth in write_gait_files(results):
            log(f"wrote {pth}")
    if docs_dir is not None:
        docs_dir = Path(docs_dir)
        (docs_dir / "figures").mkdir(parents=True, exist_ok=True)
        shutil.copy(report, docs_dir / "REPRODUCTION.md")
        for pth in figs:
            if pth.suffix == ".png":
                shutil.copy(pth, docs_dir / "figures" / pth.name)
        log(f"copied the report and figures to {docs_dir}")
    log(f"done in {time.perf_counter() - t0:.1f} s; wrote {report}")
    results["report"] = str(report)
    return results
