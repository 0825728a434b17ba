"""The DAgger round that both learned stride controllers share: the choice student
(`agents.experts.distill`) and the learned adaptive student (`agents.experts.adaptive`).

A run lives in a folder. `mpc_expert` loads the expert (an mpc spec, else one line), `claim_run`
records the run's settings there (a folder that holds another run's settings is refused, with
what differs), and `dagger_rounds` runs the rounds: each round's data is collected (or read
back: ``round_<k>.npz``, written atomically, so a killed run resumes at the first missing
round) and the student is refitted on all rounds so far. `tanh_mlp` and `train_minibatches`
are the network and the training loop of both fits (torch, imported only when a fit runs).
"""

from __future__ import annotations

import json
import sys
from collections.abc import Callable
from dataclasses import asdict
from pathlib import Path

import numpy as np

from bound_env.files.cache import atomic_write

from ..runtime.choice_policy import npz_bytes


def progress_log(progress: bool) -> Callable[[str], None]:
    """A log that prints to stderr when ``progress``, else says nothing."""

    def log(msg: str) -> None:
        if progress:
            print(msg, file=sys.stderr, flush=True)

    return log


def mpc_expert(spec: str, what: str):
    """The expert: the classical controller ``spec``, which must be an mpc (a one-line
    ValueError naming ``what`` otherwise)."""
    from bound_env.control import load_controller as load_classical
    from bound_env.control.mpc import MPCController

    expert = load_classical(spec)
    if not isinstance(expert, MPCController):
        raise ValueError(f"{what} {spec!r} is not an mpc controller spec")
    return expert


def claim_run(out_dir: Path, file: str, cfg, hint: str) -> None:
    """Record the settings ``cfg`` (a dataclass) in ``out_dir/file``: a folder that holds a run
    with other settings is refused (one line: each setting that differs, then ``hint``)."""
    settings = json.dumps(asdict(cfg), sort_keys=True, default=str)
    cfg_path = out_dir / file
    old = json.loads(cfg_path.read_text()) if cfg_path.is_file() else None
    new = json.loads(settings)
    if old is not None and old != new:
        changed = "; ".join(
            f"{k}: {old.get(k)!r} -> {new.get(k)!r}"
            for k in sorted(set(old) | set(new))
            if old.get(k) != new.get(k)
        )
        raise ValueError(f"{out_dir}: holds a run with other settings ({changed}); {hint}")
    out_dir.mkdir(parents=True, exist_ok=True)
    atomic_write(cfg_path, settings + "\n")


def dagger_rounds(
    rounds: int,
    out_dir: Path,
    collect: Callable[[int], dict],
    refit: Callable[[int, list], None],
    saved: Callable[[int, dict], str],
    log: Callable[[str], None],
) -> list[dict]:
    """The DAgger loop: for round r, its data (the arrays of ``round_<r>.npz`` when saved,
    logged with ``saved(r, part)``; else ``collect(r)``, then saved), and ``refit(r, parts)``
    on every round's data so far. Returns the rounds' data."""
    parts: list[dict] = []
    for r in range(rounds):
        path = out_dir / f"round_{r}.npz"
        if path.is_file():
            with np.load(path) as d:
                part = {key: d[key] for key in d.files}
            log(saved(r, part))
        else:
            part = collect(r)
            atomic_write(path, npz_bytes(**part))
        parts.append(part)
        refit(r, parts)
    return parts


def tanh_mlp(sizes):
    """(net, its layers): ``torch.nn.Linear`` between consecutive ``sizes``, tanh between
    them (none after the last)."""
    import torch

    mods = []
    for j in range(len(sizes) - 1):
        mods.append(torch.nn.Linear(sizes[j], sizes[j + 1]))
        if j < len(sizes) - 2:
            mods.append(torch.nn.Tanh())
    return torch.nn.Sequential(*mods), mods


def train_minibatches(net, n: int, cfg, batch_loss) -> float:
    """Adam at ``cfg.lr`` with a cosine schedule over ``cfg.epochs`` epochs of shuffled
    minibatches of ``cfg.batch`` (the shuffle seeded with ``cfg.seed``); ``batch_loss(idx)``
    is the loss of the rows ``idx``. Returns the last epoch's summed loss (sum of a batch's
    loss times its rows)."""
    import torch

    opt = torch.optim.Adam(net.parameters(), lr=cfg.lr)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, cfg.epochs)
    gen = torch.Generator().manual_seed(cfg.seed)
    total = 0.0
    for _ in range(cfg.epochs):
        perm = torch.randperm(n, generator=gen)
        total = 0.0
        for i in range(0, n, cfg.batch):
            idx = perm[i : i + cfg.batch]
            loss = batch_loss(idx)
            opt.zero_grad()
            loss.backward()
            opt.step()
            total += float(loss.detach()) * len(idx)
        sched.step()
    return total
