"""Several trainings of one recipe, one per seed, as tasks of an executor; then ``compare``.

``bound-env train --seeds 0,1,2 [--scheduler local|tcp://HOST:PORT] [--workers N]`` runs
`agents.training.train.train` once per seed, each as one task (`bound_env.sim.parallel`), with
``torch.set_num_threads(1)`` in the task (one core per training), and ends with
`agents.results.compare.compare` over the seeds (passive vs the recipe, mean and 95 % t interval).

Where the runs go (``--runs-transfer``):

- ``shared`` (default): each task writes ``<runs-dir>/<name>_s<seed>/`` itself. Right for the
  process pool and a LocalCluster (same machine), and for a cluster whose workers see
  ``--runs-dir`` on shared storage (NFS, Lustre, ...) at the same path.
- ``bytes``: each task trains in a temporary directory on its worker and sends the whole run
  directory back as a gzipped tar (a few MB); the client unpacks it into ``<runs-dir>``. For
  workers without shared storage. A run killed mid-way leaves nothing behind on the client
  (``--resume`` then needs ``shared``).
"""

from __future__ import annotations

import io
import shutil
import tarfile
import tempfile
import time
from pathlib import Path

TRANSFERS = ("shared", "bytes")


def parse_seeds(text: str) -> list[int]:
    """``"0,1,2"`` -> [0, 1, 2] (distinct non-negative integers)."""
    try:
        seeds = [int(t) for t in text.split(",") if t.strip() != ""]
    except ValueError:
        seeds = []
    if not seeds or len(set(seeds)) != len(seeds) or min(seeds) < 0:
        raise ValueError(f"--seeds must be distinct non-negative integers like 0,1,2, got {text!r}")
    return seeds


def train_task(kwargs: dict, transfer: str) -> dict:
    """One training (runs in a worker): ``train(**kwargs)`` with one torch thread."""
    import torch

    from .training.train import train

    torch.set_num_threads(1)
    t0 = time.perf_counter()
    if transfer == "shared":
        run = train(**kwargs)
        return {"run": str(run), "seconds": time.perf_counter() - t0}
    with tempfile.TemporaryDirectory(prefix="bound_env_run_") as tmp:
        run = train(**{**kwargs, "runs_dir": tmp})
        buf = io.BytesIO()
        with tarfile.open(fileobj=buf, mode="w:gz") as tar:
            tar.add(run, arcname=run.name)
        return {"name": run.name, "archive": buf.getvalue(), "seconds": time.perf_counter() - t0}


def unpack_run(archive: bytes, runs_dir: Path) -> Path:
    """Unpack a run sent back as bytes into ``runs_dir`` (replacing an older copy)."""
    runs_dir.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=runs_dir, prefix=".unpack_") as tmp:
        with tarfile.open(fileobj=io.BytesIO(archive), mode="r:gz") as tar:
            try:
                tar.extractall(tmp, filter="data")  # refuses paths outside tmp
            except TypeError:  # Python without extraction filters
                tar.extractall(tmp)  # noqa: S202 - written by our own train_task
        (name,) = [p.name for p in Path(tmp).iterdir()]
        dest = runs_dir / name
        if dest.exists():
            shutil.rmtree(dest)
        (Path(tmp) / name).rename(dest)
    return dest


def train_seeds(
    seeds: list[int],
    name: str,
    runs_dir: str | Path,
    train_kwargs: dict,
    scheduler: str | None = None,
    workers: int = 2,
    transfer: str = "shared",
    compare_budget: str | None = "quick",
    progress: bool = True,
) -> dict:
    """Train ``name``_s<seed> for every seed through one executor, then compare them with
    the passive gait (unless ``compare_budget`` is None). Returns {"runs": [...],
    "compare": path of the page or None}."""
    from bound_env.sim.parallel import TasksFailed, open_pool, run_tasks

    if transfer not in TRANSFERS:
        raise ValueError(f"--runs-transfer must be one of {TRANSFERS}, got {transfer!r}")
    runs_dir = Path(runs_dir)
    tasks = {}
    for seed in seeds:
        kw = {
            **train_kwargs,
            "seed": seed,
            "name": f"{name}_s{seed}",
            "runs_dir": str(runs_dir.resolve()),
            "progress_bar": False,
        }
        tasks[f"train {name}_s{seed}"] = (train_task, (kw, transfer), ({"seed": seed},))
    runs = {}
    with open_pool(scheduler, workers) as pool:
        done, failures = run_tasks(pool.executor, tasks, progress, f"train {name}")
        for key, res in done.items():
            run = Path(res["run"]) if transfer == "shared" else unpack_run(res["archive"], runs_dir)
            runs[key] = run
        if failures:
            raise TasksFailed(failures, len(tasks))
        ordered = [runs[k] for k in tasks]
        page = None
        if compare_budget is not None:
            from .results.compare import compare, default_entries
            from .runtime.policy import load_controller

            gait = load_controller(ordered[0]).env_kwargs.get("gait") or "default"
            passive = [e for e in default_entries() if e[1] == ["passive"] and e[2] == gait]
            entries = (passive or [("passive", ["passive"], gait)])[:1] + [
                (f"{name} ({len(seeds)} seeds)", [str(r) for r in ordered], gait)
            ]
            out = runs_dir / f"{name}_seeds"
            page = compare(
                entries,
                budget=compare_budget,
                out=out / "margins",
                docs=out,
                progress=progress,
                executor=pool.executor,
            )
    return {"runs": [str(r) for r in ordered], "compare": None if page is None else str(page)}
