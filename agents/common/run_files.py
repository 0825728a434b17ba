"""The files of a training run's folder besides its model (`agents.training.checkpoints`).

``config.yaml`` and ``run.json`` (`write_config`, `read_run_files`) and the evaluation curve
``eval.csv`` / ``eval.png`` (`append_csv`, `read_csv`, `plot_eval`; `truncate_csv` drops the
rows a resumed run computes again).
"""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import yaml

from bound_env.files.cache import atomic_write

EVAL_FIELDS = (
    "timesteps",
    "mean_reward",
    "std_reward",
    "mean_length",
    "mean_strides",
    "fall_rate",
    "noise_scale",
    "wall_time_s",
)


def append_csv(path: Path, row: dict) -> None:
    new = not path.exists()
    with path.open("a", newline="") as f:
        w = csv.DictWriter(f, fieldnames=EVAL_FIELDS)
        if new:
            w.writeheader()
        w.writerow({k: row.get(k, "") for k in EVAL_FIELDS})


def read_csv(path: Path) -> dict[str, np.ndarray]:
    with Path(path).open() as f:
        rows = list(csv.DictReader(f))
    return {
        k: np.array([float(r[k]) if r.get(k) not in (None, "") else math.nan for r in rows])
        for k in EVAL_FIELDS
    }


def plot_eval(csv_path: Path, png_path: Path, title: str | None = None, kept: str = "best") -> None:
    """Evaluation curve: mean return (± std; where the evaluation env's own reward is always 0,
    the episodes' mean length in strides instead) and fall rate against timesteps, and below it
    the basin validation score (``basin_validation.csv`` beside the CSV), if any. ``kept``:
    ``"best"`` (a run, which keeps its best-validation checkpoint in ``best/``) marks that
    checkpoint; ``"final"`` (an exported final model) marks the last point instead. The
    title names the start noise only when the run had one; legends sit outside the data."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if kept not in ("best", "final"):
        raise ValueError(f"kept must be 'best' or 'final', got {kept!r}")
    d = read_csv(csv_path)
    val_path = Path(csv_path).parent / "basin_validation.csv"
    val = np.loadtxt(val_path, delimiter=",", skiprows=1, ndmin=2) if val_path.exists() else None
    rows = 2 if val is not None and len(val) else 1
    fig, axes = plt.subplots(
        rows,
        1,
        figsize=(9.5, 3.8 * rows),
        dpi=100,
        sharex=True,
        squeeze=False,
        layout="constrained",
    )
    ax = axes[0, 0]
    t = d["timesteps"]
    no_return = len(t) > 0 and not np.any(d["mean_reward"]) and not np.any(d["std_reward"])
    if no_return:
        # the evaluation env's own reward is 0 (a task whose reward is its wrapper's): what
        # the evaluation episodes did is how long they lasted, in strides
        ax.plot(
            t, d["mean_strides"], color="C0", marker="o", ms=3, label="mean strides per episode"
        )
        ax.set_ylabel("evaluation: strides per episode", color="C0")
        ax.set_ylim(bottom=0)
        ax.text(
            0.01,
            0.04,
            "the evaluation env's own reward is 0 for this task (its reward is its wrapper's): "
            "episode length shown instead",
            transform=ax.transAxes,
            fontsize=8,
            color="0.3",
        )
    else:
        ax.plot(t, d["mean_reward"], color="C0", label="mean return (± std)")
        ax.fill_between(
            t,
            d["mean_reward"] - d["std_reward"],
            d["mean_reward"] + d["std_reward"],
            color="C0",
            alpha=0.2,
        )
        ax.set_ylabel("evaluation return", color="C0")
    ax2 = ax.twinx()
    ax2.plot(t, d["fall_rate"], color="C3", ls="--", label="fall rate")
    ax2.set_ylim(-0.05, 1.05)
    ax2.set_ylabel("fall rate", color="C3")
    noise = d["noise_scale"][-1] if len(t) else math.nan
    with_noise = f" (start noise {noise:g} × apex_scales)" if math.isfinite(noise) else ""
    ax.set_title(title or f"PPO evaluation{with_noise}")
    handles = ax.get_legend_handles_labels()[0] + ax2.get_legend_handles_labels()[0]
    ax2.legend(handles=handles, fontsize=8, loc="upper left", bbox_to_anchor=(1.1, 1.0))
    if rows == 2:
        axv = axes[1, 0]
        axv.plot(val[:, 0], val[:, 1], "o-", color="C2", ms=3, label="validation score")
        if kept == "best":
            k, mark = int(np.argmax(val[:, 1])), "best validation (kept in best/)"
        else:
            k, mark = len(val) - 1, "final model (exported; no selection)"
        axv.plot(val[k, 0], val[k, 1], "*", color="C1", ms=12, label=mark)
        axv.set_ylabel("basin validation\n(min rel. basin, xdot & y_g)")
        axv.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.1, 1.0))
    axes[-1, 0].set_xlabel("timesteps")
    fig.savefig(png_path)
    plt.close(fig)


def truncate_csv(path: Path, max_timesteps: int, column: str = "timesteps") -> None:
    """Keep the header and the complete rows with ``column`` <= ``max_timesteps`` (rows after a
    resumed checkpoint are computed again; a row cut short by a kill is dropped)."""
    path = Path(path)
    if not path.is_file():
        return
    lines = path.read_text().splitlines()
    if not lines:
        return
    header = lines[0].split(",")
    keep = [lines[0]]
    for line in lines[1:]:
        cells = line.split(",")
        try:
            ok = len(cells) == len(header) and float(cells[header.index(column)]) <= max_timesteps
        except ValueError:
            ok = False
        if ok:
            keep.append(line)
    atomic_write(path, "\n".join(keep) + "\n")


def read_run_files(run_dir: Path) -> tuple[dict, dict]:
    """(config.yaml, run.json) of a run, with a one-line error for a missing, truncated or
    malformed file."""
    saved = run_dir / "config.yaml"
    if not saved.is_file():
        raise FileNotFoundError(f"--resume: no run at {run_dir} (missing config.yaml)")
    try:
        data = yaml.safe_load(saved.read_text())
        env_id = data["run"]["env_id"]
        int(data["run"]["seed"])
        if not isinstance(data[env_id], dict):
            raise TypeError
    except (yaml.YAMLError, UnicodeDecodeError, KeyError, TypeError, ValueError):
        raise ValueError(
            f"{saved} is truncated or malformed (it needs a 'run:' entry with "
            "env_id and seed, and that env id's section)"
        ) from None
    info_path = run_dir / "run.json"
    info = {}
    if info_path.is_file():
        try:
            info = json.loads(info_path.read_text())
            if not isinstance(info, dict):
                raise ValueError
        except (ValueError, UnicodeDecodeError):
            raise ValueError(
                f"{info_path} is truncated or malformed JSON; repair it or move it away to resume"
            ) from None
    return data, info


def write_config(
    path: Path, env_id: str, hp: dict, seed: int, schedule: dict | None = None
) -> None:
    """The resolved section in rl-zoo3's format, plus a ``run:`` entry (env id, seed, and the
    evaluation and checkpoint schedule), written atomically."""
    data = {env_id: hp, "run": {"env_id": env_id, "seed": int(seed), **(schedule or {})}}
    atomic_write(path, yaml.safe_dump(data, sort_keys=False, default_flow_style=None))
