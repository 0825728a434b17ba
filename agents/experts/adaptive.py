"""A learned adaptive stride controller: it infers its robot from its own recent strides.

**What it is.** A stride controller distilled from a privileged teacher. Its input is not
only the apex it stands on but also its last ``k`` strides: at apex t it reads
x_t = (z_t - z*) / s and, for j = 1..k, the apex x_{t-j} it saw, the coefficients u_{t-j} it
played from there, and the *surprise* of that stride, the part of the next apex the nominal
linear stride map (A, B: the LQR's design) did not predict,
r_{t-j} = (z_{t-j+1} - z* - A dz_{t-j} - B u_{t-j}) / s. A robot 10 % off its model shows
in the surprise from the first stride on. Slots with no stride yet (an episode's start) are
zeros with a 0 ``valid`` flag.

**Explicit or implicit inference: both, cheaply.** One small tanh MLP (a shared trunk) has two
linear heads: a correction Delta of the LQR's plan, u = clip(u_lqr(z) + Delta, -1, 1) (K
coefficients, regressed on the teacher's plan), and an auxiliary head that regresses the
eight plant factors (m1, m2, I1, I2, kb, kf, kc, zeta) in units of the training range,
(f - 1) / delta. The auxiliary head is trained beside the correction (UP-OSI's explicit
identification as a supervision signal), but the correction reads the trunk's latent, not
the prediction (RMA's implicit route): a factor the strides do not reveal costs the
correction nothing, and the prediction shows what the trunk has inferred
(`AdaptiveController.predicted_factors`). A window of k strides rather than a recurrent cell:
the stride map is Markov in the apex state, so a few transitions identify the plant, and a
window resets exactly, trains without backpropagation through time and runs in
microseconds.

**The teacher** is privileged (`CycleTeacher`): the expert's LQR gain G about the true plant's
cycle nearest the nominal one, (z_c, u_c) with z_c = P(z_c, u_c) (`forced_cycle`: the passive
cycle where the plant has one near z*, else the least-change forced one), u = clip(u_c - G
(z - z_c), -1, 1) at the true state; where no such cycle is found, the shipped MPC planning
on the true plant (`privileged_teacher`: its planning map built on the true plant).
Unclipped, its plan differs from the nominal LQR's by a constant per plant,
u_c + G (z_c - z*): what the student has to infer.
The student sees only its own apexes (noisy under the ``noise`` preset). The target of a
state is the teacher's plan minus the LQR's plan at the state the student saw. (A first try
with the MPC on the true plant as the only teacher, and the distilled student's categorical
head over a fixed library of profiles, held 9, 4, 0 of 32 validation plants over three
DAgger rounds; the MPC's plans regressed, 4 and 1.)

**The gate.** The LQR alone acts where the apex is within ``safe`` of z* *and* the last
stride's surprise is at most ``gate_surprise`` (none yet at an episode's start), so the
nominal cycle keeps exactly zero torque while a robot off its model is corrected even near
z*; the no-history ablation (k = 0) gates on the radius alone.

**DAgger** (`train_adaptive`): each round draws ``episodes`` robots (plants from
``mismatch``, a `bound_env.model.mismatch` spec; starts at z* or near it), runs ``strides`` strides
of the teacher (round 0) or of the current student, labels every state the gate does not
take with the teacher on that robot's plant, aggregates, and refits. Every round's data is
saved (``round_<k>.npz``, atomic), so a killed run resumes at the first missing round; after
each fit the validation hold (the plants of validation seed 777, nominal z*, the stride map)
is recorded: the validation curve of the model card.

**State.** The history belongs to an episode: ``reset()`` clears it, and the loops call it at
every start (`bound_env.sim.stride_protocol.reset_controller`, ``stateful = True``). So this
controller offers no stateless ``interval_actions`` or ``apex_torques`` (the margins' batched
stride paths would share one history among many robots): loops run it through its own
``on_apex`` / ``__call__``, a copy per robot.
"""

from __future__ import annotations

import copy
import json
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from bound_env.control.mpc import MPCController
from bound_env.files.cache import atomic_write
from bound_env.model.mismatch import as_spec, plant_params, plant_values, sample_factors
from bound_env.model.params import Z_NAMES
from bound_env.sim.stride_map import EVAL_RTOL, StrideMap

from ..common.mlp import linear_layers
from ..common.seeds import VALIDATION_SEED

# The controller half, importable from here
from ..runtime.adaptive_policy import (  # noqa: F401
    FACTOR_KEYS,
    POLICY_FILE,
    AdaptiveController,
    load_adaptive_policy,
    make_controller,
    n_features,
    save_policy,
)
from .dagger import claim_run, dagger_rounds, mpc_expert, progress_log, tanh_mlp, train_minibatches


@dataclass
class AdaptiveConfig:
    """Settings of one training run (all of them go into its config.json)."""

    expert: str = "mpc"  # the expert's controller spec (its LQR gain; the fallback teacher)
    teacher: str = "cycle"  # "cycle": `CycleTeacher`; "mpc": `privileged_teacher`
    gate_surprise: float = 0.02  # the gate: within safe and the last surprise at most this
    summary: bool = True  # the episode's means of the history slots as inputs too (k > 0)
    beta: float = 0.5  # DAgger round r >= 1: the teacher acts at a stride with probability beta^r
    mismatch: str = "pm10+noise"  # the training plants and sensor noise (bound_env.model.mismatch)
    k: int = 3  # strides of history (0: the no-history ablation)
    rounds: int = 4  # DAgger rounds (round 0: the teacher acts)
    episodes_first: int = 150
    episodes_round: int = 100
    strides: int = 20  # strides of an episode
    nominal_start_prob: float = 0.5  # episodes started on z* (else z* + r |z*| xi)
    r_max: float = 0.15
    hidden: tuple = (64, 64)
    epochs: int = 150
    batch: int = 256
    lr: float = 3e-3
    aux_weight: float = 0.1  # weight of the factor head's mean squared error
    val_plants: int = 32  # validation hold: plants of seed 777, nominal z*
    val_strides: int = 100
    val_mismatch: str = "pm10"
    seed: int = 0


# --------------------------------------------------------------------------------------------
# The privileged teacher and the plants
# --------------------------------------------------------------------------------------------


def privileged_teacher(expert: MPCController, params) -> MPCController:
    """The expert planning on the robot's true plant ``params`` (its planning map built with
    them): privileged, a teacher and a reference, never a deployable controller."""
    t = copy.copy(expert)
    t.decision_seconds, t.decision_kinds = [], []
    t.model = StrideMap(
        expert.gait, plant_values(params), expert.dt, expert.max_torque, expert.rtol,
        segments=expert.segments,
    )  # fmt: skip
    t.params = params
    return t


def forced_cycle(expert: MPCController, plant: StrideMap, iters: int = 15, tol: float = 1e-9):
    """The plant's cycle nearest the nominal one: (z_c, u_c) with z_c = P(z_c, W u_c) on
    ``plant``, by Gauss-Newton from (z*, 0) on the unknowns ((z_c - z*) / s, u_c) with
    minimum-norm steps (so the least change of state and torque: the passive cycle where the
    plant has one near z*, else a forced one), central differences, halved steps; None when
    it does not converge to ``tol`` (normalized) with |u_c| <= 1."""
    K, S, z_ref = expert.basis.K, expert.scales, expert.z_ref

    def res(x):
        z = z_ref + x[:6] * S
        fz = plant.map(z, expert.profile_actions(x[6:])[0])
        return None if fz is None else (fz - z) / S

    x = np.zeros(6 + K)
    r = res(x)
    if r is None:
        return None
    h = 1e-5
    for _ in range(iters):
        if np.max(np.abs(r)) < tol:
            break
        J = np.zeros((6, 6 + K))
        for j in range(6 + K):
            e = np.zeros(6 + K)
            e[j] = h
            a, b = res(x + e), res(x - e)
            if a is None or b is None:
                return None
            J[:, j] = (a - b) / (2 * h)
        step = np.linalg.lstsq(J, -r, rcond=1e-10)[0]
        lam = 1.0
        while lam > 1e-3:
            xn = x + lam * step
            rn = res(xn) if np.max(np.abs(xn[6:])) <= 1.0 else None
            if rn is not None and np.max(np.abs(rn)) < np.max(np.abs(r)):
                break
            lam /= 2
        else:
            break
        x, r = xn, rn
    if np.max(np.abs(r)) >= tol:
        return None
    return z_ref + x[:6] * S, x[6:].copy()


class CycleTeacher:
    """The privileged teacher: the expert's LQR gain about the true plant's cycle nearest the
    nominal one (`forced_cycle`), u = clip(u_c - G (z - z_c), -1, 1), reading the true
    state; where that cycle is not found, the expert's MPC planning on the true plant
    (`privileged_teacher`). Privileged: a teacher and a reference, never deployable."""

    def __init__(self, expert: MPCController, params):
        self.expert = expert
        self.cycle = forced_cycle(expert, true_map(expert, params))
        self.mpc = privileged_teacher(expert, params) if self.cycle is None else None

    def plan(self, z) -> np.ndarray:
        if self.cycle is None:
            return self.mpc.plan(z)
        z_c, u_c = self.cycle
        return np.clip(u_c - self.expert.lqr.gain @ (np.asarray(z) - z_c), -1.0, 1.0)


def true_map(expert: MPCController, params) -> StrideMap:
    """The robot: the one stride map on ``params`` at the evaluation tolerance."""
    return StrideMap(expert.gait, plant_values(params), expert.dt, expert.max_torque, EVAL_RTOL)


def factor_range(spec) -> float:
    """The largest relative range of the eight parameters in ``spec`` (0.1 when none varies:
    the head's unit then stays that of the ±10 % plants)."""
    d = [dd for kk, dd in as_spec(spec).ranges if kk in FACTOR_KEYS]
    return max(d) if d and max(d) > 0 else 0.1


# --------------------------------------------------------------------------------------------
# Rollouts with labels
# --------------------------------------------------------------------------------------------


def episode(
    expert, student, params, factors, z0, strides, sigma, rng, out, fr, kind="cycle", beta=0.0
):
    """One episode on the plant ``params`` from z0: ``strides`` strides of the student (of the
    teacher while the student has no network, and at each stride with probability ``beta``).
    Appends (features, target correction or None, factor target) of every apex to ``out``;
    returns the strides completed."""
    if kind == "cycle":
        teacher = CycleTeacher(expert, params)
    else:
        teacher = privileged_teacher(expert, params)
    plant = true_map(expert, params)
    target = np.array([(factors.get(k, 1.0) - 1.0) / fr for k in FACTOR_KEYS])
    student.reset()
    z = np.asarray(z0, dtype=float)
    for t in range(strides):
        seen = z + sigma * rng.standard_normal(6)
        feats = student.features(seen)
        label = None
        u_lqr = expert.lqr.coefficients(seen)
        if not student.gated(seen):
            u_teacher = teacher.plan(z)  # privileged: the true plant and the true state
            label = u_teacher - u_lqr
            teach = not student.layers or (beta > 0 and rng.uniform() < beta)
            u = u_teacher if teach else student.decide(seen, feats)
        else:
            u = u_lqr
        out.append((feats, label, target))
        student.push(seen, u)
        z = plant.map(z, expert.profile_actions(u)[0])
        if z is None or not np.all(np.isfinite(z)):
            return t
    return strides


def draw_episodes(cfg: AdaptiveConfig, expert, n: int, rng):
    """n (params, factors, z0) of the training distribution (plants of ``cfg.mismatch``)."""
    from bound_env.envs.rescue_env import sample_starts

    spec = as_spec(cfg.mismatch)
    out = []
    for _ in range(n):
        factors = sample_factors(spec, rng)
        params = plant_params(expert.params, factors)
        if rng.uniform() < cfg.nominal_start_prob:
            z0 = expert.z_ref.copy()
        else:
            z0 = sample_starts(rng, 1, expert.z_ref, cfg.r_max, 0.25)[0]
        out.append((params, factors, z0))
    return out


def validation_plants(expert, spec, n: int) -> list:
    """The first n plants the margins draw for validation seed 777 (`mismatch_tasks`)."""
    from bound_env.analysis.margins.model_error.mismatch_tasks import mismatch_seeds
    from bound_env.model.mismatch import sample_plant_params

    seed = mismatch_seeds(VALIDATION_SEED)["plants"]
    return sample_plant_params(as_spec(spec), n, seed, expert.params)


def hold_on(ctrl, expert, plants, strides: int) -> list[int]:
    """Strides reached by ``ctrl`` (a fresh episode per plant) from the nominal z* on each
    plant, at most ``strides``, through the one stride map (the margins run the step env:
    the same strides to rounding)."""
    reached = []
    for p in plants:
        plant = true_map(expert, p)
        reset = getattr(ctrl, "reset", None)
        if callable(reset):
            reset()
        z, n = expert.z_ref.copy(), 0
        while n < strides:
            z = plant.map(z, expert.profile_actions(ctrl.plan(z))[0])
            if z is None:
                break
            n += 1
        reached.append(n)
    return reached


def validation_hold(ctrl, expert, cfg: AdaptiveConfig) -> dict:
    reached = hold_on(ctrl, expert, validation_plants(expert, cfg.val_mismatch, cfg.val_plants),
                      cfg.val_strides)  # fmt: skip
    held = sum(n == cfg.val_strides for n in reached)
    return {"held": int(held), "n": len(reached), "strides": reached}


# --------------------------------------------------------------------------------------------
# Training (torch only here)
# --------------------------------------------------------------------------------------------


def fit(F, T, W, Y, cfg: AdaptiveConfig, log=print):
    """The trunk and its two heads on inputs F, target corrections T (rows of weight W = 0
    carry none) and factor targets Y: weighted MSE of the correction + aux_weight * MSE of
    the factors."""
    import torch

    torch.manual_seed(cfg.seed)
    torch.set_num_threads(1)
    mu = F.mean(axis=0)
    sd = F.std(axis=0)
    sd = np.where(sd > 1e-6, sd, 1.0)
    x = torch.as_tensor((F - mu) / sd, dtype=torch.float32)
    t = torch.as_tensor(T, dtype=torch.float32)
    w = torch.as_tensor(W, dtype=torch.float32)
    y = torch.as_tensor(Y, dtype=torch.float32)
    K = T.shape[1]
    net, mods = tanh_mlp((F.shape[1], *cfg.hidden, K + Y.shape[1]))
    with torch.no_grad():  # start at the LQR: no correction
        mods[-1].weight.mul_(0.1)
        mods[-1].bias.zero_()
    n = len(x)

    def batch_loss(idx):
        out = net(x[idx])
        wi = w[idx]
        se = ((out[:, :K] - t[idx]) ** 2).mean(dim=1)
        loss = (se * wi).sum() / wi.sum().clamp(min=1.0)
        return loss + cfg.aux_weight * ((out[:, K:] - y[idx]) ** 2).mean()

    train_minibatches(net, n, cfg, batch_loss)
    with torch.no_grad():
        out = net(x)
        lab = w > 0
        rms = float(((out[:, :K] - t) ** 2)[lab].mean().sqrt()) if lab.any() else float("nan")
        spread = float((t[lab] ** 2).mean().sqrt()) if lab.any() else float("nan")
        err = float(((out[:, K:] - y) ** 2).mean().sqrt())
    log(
        f"[adaptive] fit: {n} states ({int(lab.sum())} labelled), correction rms {rms:.3f} "
        f"(targets' {spread:.3f}), factor rms {err:.3f} (units of the range; 0.577 = none)"
    )
    layers = linear_layers(net)
    return layers, mu, sd, {"correction_rms": rms, "target_rms": spread, "factor_rms": err}


def train_adaptive(cfg: AdaptiveConfig, out_dir, progress: bool = True) -> dict:
    """Run (or resume) DAgger into ``out_dir`` (module docstring); returns the summary (also
    ``summary.json``) and writes the policy to ``out_dir/policy``."""
    out_dir = Path(out_dir)
    log = progress_log(progress)
    expert = mpc_expert(cfg.expert, "expert")
    for key in ("rounds", "episodes_first", "episodes_round", "strides", "epochs", "batch"):
        if int(getattr(cfg, key)) < 1:
            raise ValueError(f"adaptive: {key} must be at least 1, got {getattr(cfg, key)!r}")
    if cfg.teacher not in ("cycle", "mpc"):
        raise ValueError(f"adaptive: teacher must be 'cycle' or 'mpc', got {cfg.teacher!r}")
    if cfg.k < 0:
        raise ValueError(f"adaptive: k must be >= 0, got {cfg.k!r}")
    as_spec(cfg.mismatch), as_spec(cfg.val_mismatch)  # a bad spec fails before the run
    claim_run(
        out_dir,
        "adaptive.json",
        cfg,
        "use another --name or --out, or the run's settings to resume it",
    )
    K = expert.basis.K
    sigma = as_spec(cfg.mismatch).obs_sigma(Z_NAMES)
    fr = factor_range(cfg.mismatch)
    D = n_features(cfg.k, K, cfg.summary)
    state = {
        "student": make_controller(
            expert, [], np.zeros(D), np.ones(D), cfg.k, "student", cfg.gate_surprise, cfg.summary
        )
    }
    t0 = time.perf_counter()
    history = []

    def collect(r: int) -> dict:
        rng = np.random.default_rng([cfg.seed, r, 3838])
        n = cfg.episodes_first if r == 0 else cfg.episodes_round
        data: list = []
        lengths = []
        for i, (params, factors, z0) in enumerate(draw_episodes(cfg, expert, n, rng)):
            lengths.append(
                episode(
                    expert,
                    state["student"],
                    params,
                    factors,
                    z0,
                    cfg.strides,
                    sigma,
                    rng,
                    data,
                    fr,
                    cfg.teacher,
                    cfg.beta**r if r > 0 else 0.0,
                )
            )
            if progress and (i + 1) % 20 == 0:
                log(
                    f"[adaptive] round {r}: {i + 1}/{n} episodes, {len(data)} states "
                    f"({time.perf_counter() - t0:.0f} s)"
                )
        return {
            "F": np.array([d[0] for d in data]).reshape(-1, D),
            "T": np.array([d[1] if d[1] is not None else np.zeros(K) for d in data]).reshape(-1, K),
            "W": np.array([float(d[1] is not None) for d in data]),
            "Y": np.array([d[2] for d in data]).reshape(-1, len(FACTOR_KEYS)),
            "lengths": np.array(lengths),
        }

    def refit(r: int, parts: list) -> None:
        part = parts[-1]
        cat = {key: np.concatenate([p[key] for p in parts]) for key in ("F", "T", "W", "Y")}
        layers, mu, sd, stats = fit(cat["F"], cat["T"], cat["W"], cat["Y"], cfg, log)
        student = make_controller(
            expert, layers, mu, sd, cfg.k, "student", cfg.gate_surprise, cfg.summary
        )
        student.factor_range = fr
        state["student"] = student
        val = validation_hold(student, expert, cfg)
        log(f"[adaptive] round {r}: validation hold {val['held']}/{val['n']} (seed 777)")
        history.append(
            {
                "round": r,
                "states": int(len(part["F"])),
                "labelled": int(part["W"].sum()),
                "total": int(len(cat["F"])),
                "episode_strides_mean": float(np.mean(part["lengths"])),
                "validation_hold": val["held"],
                "validation_n": val["n"],
                "seconds": time.perf_counter() - t0,
                **stats,
            }
        )
        atomic_write(out_dir / "curve.json", json.dumps(history, indent=2) + "\n")

    def saved(r: int, part: dict) -> str:
        return f"[adaptive] round {r}: {len(part['F'])} states (saved)"

    dagger_rounds(cfg.rounds, out_dir, collect, refit, saved, log)
    student = state["student"]
    save_policy(
        out_dir / "policy",
        expert,
        student,
        {"adaptive": asdict(cfg), "validation_curve": history},
    )
    summary = {"rounds": history, "seconds": time.perf_counter() - t0,
               "policy": str(out_dir / "policy")}  # fmt: skip
    atomic_write(out_dir / "summary.json", json.dumps(summary, indent=2) + "\n")
    return summary
