"""A learned stride controller distilled from the MPC expert (DAgger), and its controller.

**What the student chooses.** At an apex z past the expert's ``safe`` radius the student picks
one row of a fixed library of stride profiles (coefficients u of the LQR's basis): row 0 is the
LQR's own plan u_lqr(z), the others are zero, +-max, every one-switch bang-bang profile and
``n_random`` random sign vectors drawn once from ``library_seed``
(`bound_env.control.mpc.library`). An MLP maps the normalized apex error x = (z - z*) / s (s
the tasks' apex scales) to one logit per row; the controller plays the argmax. A categorical
head, because the expert's choices are multimodal: two different bang-bang profiles often
both rescue a start, and a regression would average them into a profile that rescues
neither. Within ``safe`` the controller is the LQR (the gate that keeps zero torque on the
cycle, as the expert does).

**The expert's labels.** For a state z the expert scores every library row by shooting (the
row's stride on the step env's interval torques, then the LQR for up to ``horizon`` strides;
`MPCController.evaluate`). The *good* rows are: the LQR's row alone if the LQR returns; else
every row that returns within one stride of the fastest return; else the three best rows that
survive the horizon. States from which every row falls carry no label. The loss is
-log sum_{good} p(row | x): any good row is a right answer.

**DAgger.** Round 0 labels starts z* + r |z*| xi (r ~ U(0, ``r_max``); xi uniform on the
6-sphere scaled to max |xi_i| = 1, or one axis with probability ``axis_prob``; the seeds are
disjoint from the test set's 12345 and from the validation seed) and the states the expert
visits from them; every later round rolls the current student out from fresh starts on the
planning model and labels the states it visits. The network is retrained on the aggregate
after each round. Each round's data is saved (``round_<k>.npz``, atomic), so a killed run
resumes at the first missing round.
"""

from __future__ import annotations

import json
import sys
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np

from bound_env.control.mpc import RETURNED, SURVIVED, MPCController, library
from bound_env.envs.rescue_env import sample_starts  # noqa: F401  (moved there; re-exported)
from bound_env.files.cache import atomic_write
from bound_env.sim.stride_map import EVAL_RTOL, StrideMap

from ..common.learn_config import DistillConfig  # noqa: F401 - importable from here as before
from ..common.mlp import linear_layers
from ..common.seeds import VALIDATION_SEED  # noqa: F401 - importable from here as before

# The loader half (the student as a controller), importable from here as before
from ..runtime.choice_policy import (  # noqa: F401
    FINGERPRINTED,
    POLICY_FILE,
    ChoicePolicyController,
    check_choice_fingerprint,
    expert_of,
    load_choice_policy,
    npz_bytes,
    save_policy,
    write_choice_fingerprint,
)
from .dagger import claim_run, dagger_rounds, mpc_expert, progress_log, tanh_mlp, train_minibatches

# --------------------------------------------------------------------------------------------
# Labels and rollouts on the planning model
# --------------------------------------------------------------------------------------------


def good_rows(outcome, strides, scores) -> np.ndarray | None:
    """The rows that count as right (module docstring); None when every row falls."""
    if outcome[0] == RETURNED:
        good = np.zeros(len(outcome), dtype=bool)
        good[0] = True
        return good
    ret = outcome == RETURNED
    if ret.any():
        return ret & (strides <= strides[ret].min() + 1)
    surv = outcome == SURVIVED
    if surv.any():
        top = np.argsort(-np.where(surv, scores, -np.inf))[:3]
        good = np.zeros(len(outcome), dtype=bool)
        good[top] = surv[top]
        return good
    return None


def plant_of(ctrl: MPCController) -> StrideMap:
    """The plant a stride controller acts on in training: the one stride map
    (`bound_env.sim.stride_map`) at the evaluation tolerance, as `margins` measures it."""
    return StrideMap(ctrl.gait, None, ctrl.dt, ctrl.max_torque, EVAL_RTOL)


def stride_of(ctrl: MPCController, plant: StrideMap, z, u):
    """The next apex from z under the coefficients u on ``plant`` (None on a fall)."""
    return plant.map(z, ctrl.profile_actions(u)[0])


class Labeller:
    def __init__(self, expert: MPCController, rows: np.ndarray):
        self.expert, self.rows = expert, rows
        self.plant = plant_of(expert)

    def past_safe(self, z) -> bool:
        e = self.expert
        return float(np.max(np.abs(z - e.z_ref) / e.scales)) > e.safe

    def label(self, z):
        """(good mask or None, the expert's row) at z."""
        U = self.rows.copy()
        U[0] = self.expert.lqr.coefficients(z)
        s, outcome, strides = self.expert.evaluate(z, U)
        good = good_rows(outcome, strides, s)
        best = 0 if outcome[0] == RETURNED else int(np.argmax(s))
        return good, best, U

    def rollout(self, z0, choose, strides: int, out: list) -> None:
        """From z0, ``strides`` strides of ``choose(z, good, best, U) -> u`` (stopping at a fall
        or within safe); every state past safe that has a label is appended to ``out``."""
        z = np.asarray(z0, dtype=float)
        for _ in range(strides):
            if not self.past_safe(z):
                return
            good, best, U = self.label(z)
            if good is not None:
                out.append((z.copy(), good))
            u = choose(z, good, best, U)
            z = stride_of(self.expert, self.plant, z, u)
            if z is None or not np.all(np.isfinite(z)):
                return


# --------------------------------------------------------------------------------------------
# Training (torch only here)
# --------------------------------------------------------------------------------------------


def fit(X, G, cfg: DistillConfig, scales, z_ref, log=print):
    """The classifier on inputs X (apex states) and good masks G: -log sum_good softmax."""
    import torch

    torch.manual_seed(cfg.seed)
    torch.set_num_threads(1)
    x = torch.as_tensor((X - z_ref) / scales, dtype=torch.float32)
    g = torch.as_tensor(G, dtype=torch.bool)
    net, _ = tanh_mlp((6, *cfg.hidden, G.shape[1]))
    n = len(x)

    def batch_loss(idx):
        lp = torch.log_softmax(net(x[idx]), dim=1)
        return -torch.logsumexp(lp.masked_fill(~g[idx], -1e9), dim=1).mean()

    total = train_minibatches(net, n, cfg, batch_loss)
    with torch.no_grad():
        pick = net(x).argmax(dim=1)
        acc = float(g[torch.arange(n), pick].float().mean())
    log(f"[distill] fit: {n} states, loss {total / n:.3f}, picks a good row on {acc:.1%}")
    return linear_layers(net)


def distill(cfg: DistillConfig, out_dir: Path, progress: bool = True) -> dict:
    """Run (or resume) DAgger into ``out_dir`` (`agents.experts.dagger`); returns the summary
    (also summary.json)."""
    out_dir = Path(out_dir)
    log = progress_log(progress)
    # everything that can refuse the run does so before the run folder is written to
    expert = mpc_expert(cfg.expert, "--expert")
    claim_run(out_dir, "distill.json", cfg, "use another --out")
    K = expert.basis.K
    rows = library(K, np.zeros(K), np.random.default_rng(cfg.library_seed), cfg.n_random, 0, 0.0)
    lab = Labeller(expert, rows)
    t0 = time.perf_counter()
    state = {"layers": None}
    history = []

    def collect(k: int) -> dict:
        rng = np.random.default_rng([cfg.seed, k, 4242])
        data: list = []
        n = cfg.starts_first if k == 0 else cfg.starts_round
        starts = sample_starts(rng, n, expert.z_ref, cfg.r_max, cfg.axis_prob)
        if k == 0:  # round 0: the expert's own choices, 4 strides

            def choose(z, good, best, U):
                return U[best]

            strides = 4
        else:
            student = ChoicePolicyController(
                name="student",
                lqr=expert.lqr,
                params=expert.params,
                safe=expert.safe,
                horizon=expert.horizon,
                rtol=expert.rtol,
                layers=state["layers"],
                rows=rows,
            )
            choose, strides = (lambda z, g, b, U, s=student: s.plan(z)), cfg.rollout_strides
        for i, z0 in enumerate(starts):
            lab.rollout(z0, choose, strides, data)
            if progress and (i + 1) % 250 == 0:
                log(
                    f"[distill] round {k}: {i + 1}/{n} starts, {len(data)} states "
                    f"({time.perf_counter() - t0:.0f} s)"
                )
        X = np.array([d[0] for d in data]).reshape(-1, 6)
        G = np.array([d[1] for d in data], dtype=bool).reshape(-1, len(rows))
        return {"X": X, "G": G}

    def refit(k: int, parts: list) -> None:
        X = np.concatenate([np.empty((0, 6))] + [p["X"] for p in parts])
        G = np.concatenate([np.empty((0, len(rows)), dtype=bool)] + [p["G"] for p in parts])
        state["layers"] = fit(X, G, cfg, expert.scales, expert.z_ref, log=log)
        history.append({"round": k, "states": int(len(parts[-1]["X"])), "total": int(len(X))})

    def saved(k: int, part: dict) -> str:
        return f"[distill] round {k}: {len(part['X'])} labelled states (saved)"

    dagger_rounds(cfg.rounds, out_dir, collect, refit, saved, log)
    save_policy(
        out_dir / "policy",
        expert,
        state["layers"],
        rows,
        {"distill": asdict(cfg)},
    )
    summary = {
        "rounds": history,
        "seconds": time.perf_counter() - t0,
        "policy": str(out_dir / "policy"),
    }
    atomic_write(out_dir / "summary.json", json.dumps(summary, indent=2) + "\n")
    return summary


def write_run_info(folder: Path, seed: int, command: str, seconds: float, made: str) -> None:
    """``run.json`` of an exported policy: how it was made (read by `compare`'s provenance)."""
    import os
    import platform

    info = {
        "seed": seed,
        "timesteps_done": made,
        "wall_time_s": seconds,
        "command": command,
        "machine": f"{platform.machine()}, {os.cpu_count()} cores",
        "selection": "final model, no selection",
    }
    atomic_write(Path(folder) / "run.json", json.dumps(info, indent=2) + "\n")


# --------------------------------------------------------------------------------------------
# bound-env distill
# --------------------------------------------------------------------------------------------


def check_export(export, force: bool) -> None:
    """``--export`` of distill and finetune, before the run: refused if it exists, unless
    ``force``, and where it could not be written (`bound_env.commands.cli_args.check_writable`)."""
    from bound_env.commands.cli_args import check_writable

    if export and Path(export).exists() and not force:
        raise ValueError(f"--export {export} exists; give --force to replace it")
    if export:
        check_writable(export, "--export")


def export_folder(src: Path, dest) -> Path:
    """Copy a policy folder to ``dest`` whole: a copy beside it under a name of its own (a
    folder: `bound_env.files.cache.atomic_path` writes files), then a rename; removed on failure."""
    import shutil
    import tempfile

    dest = Path(dest)
    dest.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{dest.name}.", suffix=".tmp", dir=dest.parent))
    try:
        shutil.copytree(src, tmp, dirs_exist_ok=True)  # and src's mode (mkdtemp's is 0700)
        shutil.rmtree(dest, ignore_errors=True)
        tmp.rename(dest)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return dest


def cmd_distill(args) -> int:
    from bound_env.commands.cli_args import check_writable

    out = Path(args.out or f"runs/distill_s{args.seed}")
    check_writable(out, "--out")
    check_export(args.export, args.force)
    cfg = DistillConfig(
        expert=args.expert,
        rounds=args.rounds,
        starts_first=args.starts,
        starts_round=max(1, args.starts // 2),
        epochs=args.epochs,
        seed=args.seed,
    )
    summary = distill(cfg, out, progress=not args.no_progress)
    states = sum(r["states"] for r in summary["rounds"])
    write_run_info(
        out / "policy",
        args.seed,
        "bound-env " + " ".join(sys.argv[1:]),
        summary["seconds"],
        f"{states} labelled states in {len(summary['rounds'])} DAgger rounds",
    )
    if args.export:
        summary["exported"] = str(export_folder(out / "policy", args.export))
    if args.json:
        print(json.dumps(summary))
    else:
        print(f"distilled policy: {summary.get('exported', summary['policy'])}")
    return 0
