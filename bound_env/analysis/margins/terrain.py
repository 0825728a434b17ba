"""Rough terrain: survival over a fixed horizon (JSON ``terrain``) and the mean first-passage
time (JSON ``mfpt``; one task per chunk of `MFPT_CHUNK` robots, batched by `rough_episodes`)."""

from __future__ import annotations

import numpy as np

from .budget import MFPT_CHUNK, sample_seeds
from .closed_loop import Setup, loop_for, rough_episodes
from .curve import Decisions


def task_terrain(setup: Setup, sigma: float) -> dict:
    """Rough terrain: how many of ``terrain_runs`` episodes from z_cl with slope noise sigma
    [deg] survive ``terrain_strides`` strides."""
    loop = loop_for(setup, env_extra={"slope_noise_deg": float(sigma)})
    b = setup.budget
    base = sample_seeds(setup.seed)["terrain"]
    kinds = Decisions(loop.controller)
    # the runs of loop.episode(z_cl, terrain_strides, seed=base + j), batched
    out = rough_episodes(loop, setup.z_cl, [base + j for j in range(b.terrain_runs)],
                         b.terrain_strides)  # fmt: skip
    k, strides, reasons = b.terrain_runs - sum(out["fell"]), out["strides"], out["failures"]
    res = {
        "sigma_deg": sigma,
        "k": int(k),
        "n": b.terrain_runs,
        "success": k / b.terrain_runs,
        "mean_strides": float(np.mean(strides)),
        "failures": reasons,
    }
    return kinds.into(res)


def task_mfpt(setup: Setup, sigma: float, chunk: int) -> dict:
    """Robots chunk * MFPT_CHUNK ... of the MFPT at slope noise sigma [deg]: each one run of up
    to ``mfpt_strides`` strides from z_cl (env seed = the seed's MFPT base + robot index),
    batched (`rough_episodes`)."""
    loop = loop_for(setup, env_extra={"slope_noise_deg": float(sigma)})
    b = setup.budget
    first = chunk * MFPT_CHUNK
    robots = range(first, min(b.mfpt_robots, first + MFPT_CHUNK))
    base = sample_seeds(setup.seed)["mfpt"]
    kinds = Decisions(loop.controller)
    out = rough_episodes(loop, setup.z_cl, [base + k for k in robots], b.mfpt_strides)
    return kinds.into({"sigma_deg": sigma, "chunk": chunk, "robots": len(robots), **out})
