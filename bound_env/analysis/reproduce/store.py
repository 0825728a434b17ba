"""Progress lines, plain JSON and the per-stage cache of the reproduction."""

from __future__ import annotations

import json
import math
import sys
import time
from pathlib import Path

import numpy as np

from ...files.cache import atomic_write, settings_hash


class ProgressLog:
    """``log(msg)``: a progress line on stderr with the seconds since the start (if enabled)."""

    def __init__(self, enabled: bool):
        self.enabled, self.t0 = enabled, time.perf_counter()

    def __call__(self, msg: str):
        if self.enabled:
            dt = time.perf_counter() - self.t0
            print(f"[reproduce {dt:6.1f}s] {msg}", file=sys.stderr, flush=True)


def jsonable(x):
    """Plain JSON: arrays to lists, complex to [re, im], non-finite floats to None."""
    if isinstance(x, dict):
        return {str(k): jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return jsonable(x.tolist())
    if isinstance(x, (complex, np.complexfloating)):
        return [jsonable(float(x.real)), jsonable(float(x.imag))]
    if isinstance(x, (np.bool_, bool)):
        return bool(x)
    if isinstance(x, (np.integer, int)):
        return int(x)
    if isinstance(x, (np.floating, float)):
        return float(x) if math.isfinite(x) else None
    return x


def config_hash(config: dict) -> str:
    return settings_hash(jsonable(config), length=12)


class Cache:
    """One JSON file per stage, named by the hash of the stage's configuration."""

    def __init__(self, out_dir: Path, force: bool, log: ProgressLog):
        self.dir = Path(out_dir) / "cache"
        self.dir.mkdir(parents=True, exist_ok=True)
        self.force, self.log = force, log
        self.hits: list[str] = []
        self.misses: list[str] = []

    def get(self, stage: str, config: dict, compute):
        path = self.dir / f"{stage}-{config_hash({'stage': stage, **config})}.json"
        if path.is_file() and not self.force:
            try:
                data = json.loads(path.read_text())
                self.hits.append(stage)
                self.log(f"{stage}: cached ({path.name})")
                return data
            except json.JSONDecodeError:
                pass
        self.log(f"{stage}: computing")
        t0 = time.perf_counter()
        data = jsonable(compute())
        data["seconds"] = time.perf_counter() - t0
        atomic_write(path, json.dumps(data))
        self.misses.append(stage)
        self.log(f"{stage}: done in {data['seconds']:.1f} s")
        return data
