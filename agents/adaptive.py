"""A learned adaptive stride controller: it infers its robot from its own recent strides.

**What it is.** A stride controller distilled from a privileged teacher. Its input is not
only the apex it stands on but also its last ``k`` strides: at apex t it reads
x_t = (z_t - z*) / s and, for j = 1..k, the apex x_{t-j} it saw, the coefficients u_{t-j} it
played from there, and the *surprise* of that stride, r_{t-j} = (z_{t-j+1} - z* - A dz_{t-j}
- B u_{t-j}) / s, the part of the next apex the nominal linear stride map (A, B: the LQR's
design) did not predict. A robot 10 % off its model shows in the surprise from the first
stride on. Slots with no stride yet (an episode's start) are zeros with a 0 ``valid`` flag.

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
on the true plant (`privileged_teacher`, issue 37's probe). Unclipped, its plan differs from
the nominal LQR's by a constant per plant, u_c + G (z_c - z*): what the student has to infer.
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
``mismatch``, a `bound_env.mismatch` spec; starts at z* or near it), runs ``strides`` strides
of the teacher (round 0) or of the current student, labels every state the gate does not
take with the teacher on that robot's plant, aggregates, and refits. Every round's data is
saved (``round_<k>.npz``, atomic), so a killed run resumes at the first missing round; after
each fit the validation hold (the plants of validation seed 777, nominal z*, the stride map)
is recorded: the validation curve of the model card.

**State.** The history belongs to an episode: ``reset()`` clears it, and the loops call it at
every start (`bound_env.stride_protocol.reset_controller`, ``stateful = True``). So this
controller offers no stateless ``interval_actions`` or ``apex_torques`` (the margins' batched
stride paths would share one history among many robots): loops run it through its own
``on_apex`` / ``__call__``, a copy per robot.
"""

from __future__ import annotations

import copy
import hashlib
import json
import sys
import time
from collections import deque
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from bound_env.cache import atomic_write
from bound_env.control.mpc import MPCController
from bound_env.mismatch import EIGHT, as_spec, plant_params, plant_values, sample_factors
from bound_env.params import Z_NAMES
from bound_env.stride_map import EVAL_RTOL, StrideMap

from .distill import _npz_bytes, expert_of
from .mlp import mlp_forward
from .policy_files import FINGERPRINT_FILE, file_sha256, source_name

POLICY_FILE = "adaptive.npz"  # the network and its input statistics
VALIDATION_SEED = 777
FACTOR_KEYS = EIGHT  # the factors the auxiliary head predicts
FEATURE_CLIP = 10.0  # |normalized| inputs clipped here (a fall-bound state stays finite)


@dataclass
class AdaptiveConfig:
    """Settings of one training run (all of them go into its config.json)."""

    expert: str = "mpc"  # the expert's controller spec (its LQR gain; the fallback teacher)
    teacher: str = "cycle"  # "cycle": `CycleTeacher`; "mpc": `privileged_teacher`
    gate_surprise: float = 0.02  # the gate: within safe and the last surprise at most this
    mismatch: str = "pm10+noise"  # the training plants and sensor noise (bound_env.mismatch)
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
# The controller (NumPy inference; no torch)
# --------------------------------------------------------------------------------------------


def n_features(k: int, K: int) -> int:
    return 6 + k * (1 + 6 + K + 6)


@dataclass
class AdaptiveController(MPCController):
    """The learned adaptive controller (module docstring): the LQR's plan plus a correction
    read from the apex and the last ``k`` strides, with a plant-factor head. The MPC's
    protocol (``on_apex`` plans the stride, ``__call__`` plays its interval averages), with
    memory (``stateful``, ``reset``)."""

    layers: list = field(default_factory=list, repr=False)  # [(W, b), ...]
    k: int = 3
    mu: np.ndarray | None = field(default=None, repr=False)  # input mean and scale
    sd: np.ndarray | None = field(default=None, repr=False)
    factor_range: float = 0.1  # the head predicts (f - 1) / factor_range
    gate_surprise: float = 0.02  # the gate also needs the last stride's surprise this small
    stateful = True
    interval_actions = None  # no stateless paths (module docstring: the history is per robot)
    apex_torques = None

    def __post_init__(self):
        super().__post_init__()
        d = self.lqr.design
        self._A = np.asarray(d["A"], dtype=float)
        self._B = np.asarray(d["B"], dtype=float)
        self.reset()

    # -- the history --------------------------------------------------------------------------
    def reset(self) -> None:
        """Forget the episode: no strides in the history, no plan."""
        self._hist: deque = deque(maxlen=max(self.k, 1))  # (x, u, r) per stride, newest last
        self._last = None  # (z, u) of the stride under way
        self._u = None
        self._feat = None

    def _slot(self, z):
        z0, u0 = self._last
        dz0 = z0 - self.z_ref
        r = (z - self.z_ref - self._A @ dz0 - self._B @ u0) / self.scales
        return dz0 / self.scales, u0, r

    def push(self, z, u) -> None:
        """Record the stride from the apex z with coefficients u; the previous stride's
        surprise is computed now that its next apex (z) is known."""
        z = np.asarray(z, dtype=float)
        if self._last is not None and self.k > 0:
            self._hist.append(self._slot(z))
        self._last = (z.copy(), np.asarray(u, dtype=float).copy())

    def features(self, z) -> np.ndarray:
        """The network's input at apex z (module docstring), from the recorded strides: the
        stride just finished (its next apex is z) counts as the newest."""
        z = np.asarray(z, dtype=float)
        K = self.basis.K
        f = np.zeros(n_features(self.k, K))
        f[:6] = (z - self.z_ref) / self.scales
        if self.k > 0:
            slots = list(self._hist)
            if self._last is not None:
                slots.append(self._slot(z))
            for j, (x, u, r) in enumerate(reversed(slots[-self.k :])):
                o = 6 + j * (13 + K)
                f[o] = 1.0
                f[o + 1 : o + 7] = x
                f[o + 7 : o + 7 + K] = u
                f[o + 7 + K : o + 13 + K] = r
        return np.clip(f, -FEATURE_CLIP, FEATURE_CLIP)

    def outputs(self, feats) -> np.ndarray:
        """The network's outputs: K coefficients of the correction, then the factor head."""
        x = (np.asarray(feats, dtype=float) - self.mu) / self.sd
        return mlp_forward(self.layers, x, "Tanh")

    def predicted_factors(self, feats=None) -> dict:
        """The factor head's estimate {key: factor} at the last decision (or at ``feats``)."""
        feats = self._feat if feats is None else feats
        if feats is None:
            return {}
        y = self.outputs(feats)[self.basis.K :]
        return {k: 1.0 + self.factor_range * float(v) for k, v in zip(FACTOR_KEYS, y, strict=True)}

    def gated(self, z) -> bool:
        """The LQR alone at apex z: within ``safe`` of z*, and the robot behaved as the
        nominal model predicts (the last stride's surprise at most ``gate_surprise``; none
        yet at an episode's start)."""
        if np.max(np.abs(z - self.z_ref) / self.scales) > self.safe:
            return False
        if self._last is None or self.k == 0:  # no history: the radius alone
            return True
        r = self._slot(np.asarray(z, dtype=float))[2]
        return float(np.max(np.abs(r))) <= self.gate_surprise

    def decide(self, z, feats) -> np.ndarray:
        """The coefficients at apex z given the input ``feats``: the LQR's where `gated`,
        else the LQR's plus the network's correction (clipped to [-1, 1])."""
        u_lqr = self.lqr.coefficients(z)
        if self.gated(z):
            self._kind = "gate"
            return u_lqr
        self._kind = "override"
        return np.clip(u_lqr + self.outputs(feats)[: self.basis.K], -1.0, 1.0)

    def plan(self, z) -> np.ndarray:
        """The decision at apex z (the next stride of this episode): features, decision, and
        the stride recorded in the history."""
        z = np.asarray(z, dtype=float)
        if z.ndim == 2:
            raise ValueError(
                "AdaptiveController decides one apex of one episode at a time (it has memory)"
            )
        self._feat = self.features(z)
        u = self.decide(z, self._feat)
        self.push(z, u)
        return u

    def fingerprint(self) -> str:
        h = hashlib.sha256(b"adaptive")
        h.update(super().fingerprint().encode())
        h.update(repr(self.k).encode())
        for W, b in self.layers:
            h.update(np.ascontiguousarray(W).tobytes())
            h.update(np.ascontiguousarray(b).tobytes())
        for a in (self.mu, self.sd):
            h.update(np.ascontiguousarray(a, dtype=float).tobytes())
        return h.hexdigest()[:16]

    def __getstate__(self):
        state = super().__getstate__()
        state["_hist"] = deque(maxlen=max(self.k, 1))
        state["_last"] = state["_feat"] = None
        return state


def make_controller(
    expert: MPCController, layers, mu, sd, k: int, name="adaptive", gate_surprise: float = 0.02
):
    return AdaptiveController(
        name=name,
        lqr=expert.lqr,
        params=expert.params,
        safe=expert.safe,
        horizon=expert.horizon,
        rtol=expert.rtol,
        layers=layers,
        k=int(k),
        mu=np.asarray(mu, dtype=float),
        sd=np.asarray(sd, dtype=float),
        gate_surprise=float(gate_surprise),
    )


# --------------------------------------------------------------------------------------------
# Saving and loading a policy folder
# --------------------------------------------------------------------------------------------

FINGERPRINTED = (POLICY_FILE, "config.json")


def save_policy(folder: Path, expert: MPCController, ctrl: AdaptiveController, config: dict):
    """``adaptive.npz`` (layers, k, input statistics), ``config.json`` (kind, the frozen
    expert: its LQR and settings, the factor keys, the run's settings) and
    ``fingerprint.json`` (their sha256), each written atomically."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    arrays = {"n_layers": np.array(len(ctrl.layers)), "k": np.array(ctrl.k)}
    arrays["mu"], arrays["sd"] = ctrl.mu, ctrl.sd
    for j, (W, b) in enumerate(ctrl.layers):
        arrays[f"W{j}"], arrays[f"b{j}"] = W, b
    atomic_write(folder / POLICY_FILE, _npz_bytes(**arrays))
    lqr = expert.lqr
    spec = {
        "kind": "adaptive",
        "expert": {
            "name": source_name(expert.name),
            "gait": lqr.gait,
            "basis": lqr.basis.name,
            "K": lqr.basis.K,
            "max_torque": lqr.max_torque,
            "dt": lqr.dt,
            "gain": lqr.gain.tolist(),
            "settings": expert.settings(),
        },
        "factor_keys": list(FACTOR_KEYS),
        "factor_range": ctrl.factor_range,
        "gate_surprise": ctrl.gate_surprise,
        **config,
    }
    atomic_write(folder / "config.json", json.dumps(spec, indent=2, default=str) + "\n")
    data = {name: file_sha256(folder / name) for name in FINGERPRINTED}
    atomic_write(folder / FINGERPRINT_FILE, json.dumps(data, indent=2) + "\n")


def is_adaptive_folder(folder) -> bool:
    """A policy folder of this module (it holds ``adaptive.npz``)."""
    return (Path(folder) / POLICY_FILE).is_file()


def load_adaptive_policy(folder, gait=None, force: bool = False) -> AdaptiveController:
    """A saved adaptive controller, checked against its ``fingerprint.json`` (``force``: a
    mismatch loads with a warning) and its arrays' shapes; ValueError naming the file."""
    folder = Path(folder)
    fp = folder / FINGERPRINT_FILE
    if fp.is_file():
        try:
            want = json.loads(fp.read_text())
        except ValueError:
            raise ValueError(f"{fp}: not valid JSON") from None
        for name in FINGERPRINTED:
            p = folder / name
            if name in want and (not p.is_file() or file_sha256(p) != want.get(name)):
                msg = f"{p} does not match {fp} (sha256): changed after the policy was saved"
                if not force:
                    raise ValueError(msg + "; pass --force to evaluate it as it is")
                print(f"warning: {msg}", file=sys.stderr)
    where = folder / POLICY_FILE
    try:
        cfg = json.loads((folder / "config.json").read_text())
        with np.load(where) as d:
            arrays = {key: d[key] for key in d.files}
    except (OSError, ValueError) as e:
        raise ValueError(f"{folder}: not a readable adaptive policy ({e})") from None
    try:
        n = int(arrays["n_layers"])
        layers = [(arrays[f"W{j}"].astype(float), arrays[f"b{j}"].astype(float)) for j in range(n)]
        k = int(arrays["k"])
        mu, sd = arrays["mu"].astype(float), arrays["sd"].astype(float)
        K = int(cfg["expert"]["K"])
        fr = float(cfg.get("factor_range", 0.1))
        gs = float(cfg.get("gate_surprise", 0.02))
    except (KeyError, TypeError, ValueError) as e:
        raise ValueError(f"{where}: missing or malformed entry {e}") from None
    D = n_features(k, K)
    shapes_ok = (
        n >= 1
        and mu.shape == (D,)
        and sd.shape == (D,)
        and np.all(sd > 0)
        and layers[0][0].shape[1] == D
        and layers[-1][0].shape[0] == K + len(FACTOR_KEYS)
        and all(np.all(np.isfinite(a)) for W, b in layers for a in (W, b, mu, sd))
        and np.isfinite(fr)
        and fr > 0
        and np.isfinite(gs)
        and gs >= 0
    )
    if not shapes_ok:
        raise ValueError(
            f"{where}: arrays do not fit k = {k}, K = {K} ({D} inputs; {K} coefficients and "
            f"{len(FACTOR_KEYS)} factors out), or hold non-finite values"
        )
    expert = expert_of(cfg["expert"], gait)
    ctrl = make_controller(expert, layers, mu, sd, k, name=str(folder), gate_surprise=gs)
    ctrl.factor_range = fr
    return ctrl


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


def episode(expert, student, params, factors, z0, strides, sigma, rng, out, fr, kind="cycle"):
    """One episode on the plant ``params`` from z0: ``strides`` strides of the student (of the
    teacher while the student has no network). Appends (features, target correction or None,
    factor target) of every apex to ``out``; returns the strides completed."""
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
            u = student.decide(seen, feats) if student.layers else u_teacher
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
    from bound_env.rescue_env import sample_starts

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
    from bound_env.analysis.margins.mismatch_tasks import mismatch_seeds
    from bound_env.mismatch import sample_plant_params

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
    sizes = (F.shape[1], *cfg.hidden, K + Y.shape[1])
    mods = []
    for j in range(len(sizes) - 1):
        mods.append(torch.nn.Linear(sizes[j], sizes[j + 1]))
        if j < len(sizes) - 2:
            mods.append(torch.nn.Tanh())
    net = torch.nn.Sequential(*mods)
    with torch.no_grad():  # start at the LQR: no correction
        mods[-1].weight.mul_(0.1)
        mods[-1].bias.zero_()
    opt = torch.optim.Adam(net.parameters(), lr=cfg.lr)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, cfg.epochs)
    gen = torch.Generator().manual_seed(cfg.seed)
    n = len(x)
    for _ in range(cfg.epochs):
        perm = torch.randperm(n, generator=gen)
        for i in range(0, n, cfg.batch):
            idx = perm[i : i + cfg.batch]
            out = net(x[idx])
            wi = w[idx]
            se = ((out[:, :K] - t[idx]) ** 2).mean(dim=1)
            loss = (se * wi).sum() / wi.sum().clamp(min=1.0)
            loss = loss + cfg.aux_weight * ((out[:, K:] - y[idx]) ** 2).mean()
            opt.zero_grad()
            loss.backward()
            opt.step()
        sched.step()
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
    lin = [m for m in net if isinstance(m, torch.nn.Linear)]
    layers = [(m.weight.detach().double().numpy(), m.bias.detach().double().numpy()) for m in lin]
    return layers, mu, sd, {"correction_rms": rms, "target_rms": spread, "factor_rms": err}


def train_adaptive(cfg: AdaptiveConfig, out_dir, progress: bool = True) -> dict:
    """Run (or resume) DAgger into ``out_dir`` (module docstring); returns the summary (also
    ``summary.json``) and writes the policy to ``out_dir/policy``."""
    from bound_env.control import load_controller as load_classical

    out_dir = Path(out_dir)

    def log(msg):
        if progress:
            print(msg, file=sys.stderr, flush=True)

    expert = load_classical(cfg.expert)
    if not isinstance(expert, MPCController):
        raise ValueError(f"expert {cfg.expert!r} is not an mpc controller spec")
    for key in ("rounds", "episodes_first", "episodes_round", "strides", "epochs", "batch"):
        if int(getattr(cfg, key)) < 1:
            raise ValueError(f"adaptive: {key} must be at least 1, got {getattr(cfg, key)!r}")
    if cfg.teacher not in ("cycle", "mpc"):
        raise ValueError(f"adaptive: teacher must be 'cycle' or 'mpc', got {cfg.teacher!r}")
    if cfg.k < 0:
        raise ValueError(f"adaptive: k must be >= 0, got {cfg.k!r}")
    as_spec(cfg.mismatch), as_spec(cfg.val_mismatch)  # a bad spec fails before the run
    settings = json.dumps(asdict(cfg), sort_keys=True, default=str)
    cfg_path = out_dir / "adaptive.json"
    if cfg_path.is_file() and json.loads(cfg_path.read_text()) != json.loads(settings):
        raise ValueError(f"{out_dir}: holds a run with other settings; use another --out")
    out_dir.mkdir(parents=True, exist_ok=True)
    atomic_write(cfg_path, settings + "\n")
    K = expert.basis.K
    sigma = as_spec(cfg.mismatch).obs_sigma(Z_NAMES)
    fr = factor_range(cfg.mismatch)
    D = n_features(cfg.k, K)
    student = make_controller(
        expert, [], np.zeros(D), np.ones(D), cfg.k, "student", cfg.gate_surprise
    )
    t0 = time.perf_counter()
    parts, history = [], []
    for r in range(cfg.rounds):
        path = out_dir / f"round_{r}.npz"
        if path.is_file():
            with np.load(path) as d:
                part = {key: d[key] for key in d.files}
            log(f"[adaptive] round {r}: {len(part['F'])} states (saved)")
        else:
            rng = np.random.default_rng([cfg.seed, r, 3838])
            n = cfg.episodes_first if r == 0 else cfg.episodes_round
            data: list = []
            lengths = []
            for i, (params, factors, z0) in enumerate(draw_episodes(cfg, expert, n, rng)):
                lengths.append(
                    episode(
                        expert,
                        student,
                        params,
                        factors,
                        z0,
                        cfg.strides,
                        sigma,
                        rng,
                        data,
                        fr,
                        cfg.teacher,
                    )
                )
                if progress and (i + 1) % 20 == 0:
                    log(
                        f"[adaptive] round {r}: {i + 1}/{n} episodes, {len(data)} states "
                        f"({time.perf_counter() - t0:.0f} s)"
                    )
            part = {
                "F": np.array([d[0] for d in data]).reshape(-1, D),
                "T": np.array([d[1] if d[1] is not None else np.zeros(K) for d in data]).reshape(
                    -1, K
                ),
                "W": np.array([float(d[1] is not None) for d in data]),
                "Y": np.array([d[2] for d in data]).reshape(-1, len(FACTOR_KEYS)),
                "lengths": np.array(lengths),
            }
            atomic_write(path, _npz_bytes(**part))
        parts.append(part)
        cat = {key: np.concatenate([p[key] for p in parts]) for key in ("F", "T", "W", "Y")}
        layers, mu, sd, stats = fit(cat["F"], cat["T"], cat["W"], cat["Y"], cfg, log)
        student = make_controller(expert, layers, mu, sd, cfg.k, "student", cfg.gate_surprise)
        student.factor_range = fr
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


# --------------------------------------------------------------------------------------------
# The recipe: ``bound-env train --config adaptive`` (a config section with ``algo:
# adaptive-dagger``)
# --------------------------------------------------------------------------------------------

ALGO = "adaptive-dagger"
_RANDOMIZED = ("bound_env.wrappers.RandomizedPlant", "bound_env.randomized.RandomizedPlant")
_SECTION_KEYS = ("algo", "env_wrapper", "env_kwargs", "adaptive")


def is_dagger_section(hp) -> bool:
    """A config section of this module (``algo: adaptive-dagger``), not a PPO one."""
    return isinstance(hp, dict) and hp.get("algo") == ALGO


def config_from_section(hp: dict, env_id: str, seed: int, where: str = "config") -> AdaptiveConfig:
    """The run's `AdaptiveConfig` from a config section (keys `_SECTION_KEYS`):

    - the env id must be a stride env (its step is the one stride map's stride, which the
      rollouts advance directly);
    - ``env_wrapper``: `RandomizedPlant` with its ``mismatch`` (the training plants and
      noise; none: the nominal plant);
    - ``env_kwargs``: the stride env's gait, basis, K and max_torque, which must be the
      expert's (its LQR's);
    - ``adaptive``: any field of `AdaptiveConfig` but ``mismatch`` and ``seed``.

    Every bad key is a one-line ValueError naming it."""
    from dataclasses import fields

    from bound_env import STRIDE_ENV_IDS
    from bound_env.control import load_controller as load_classical

    if env_id not in STRIDE_ENV_IDS:
        raise ValueError(
            f"{where}: algo {ALGO} trains on a stride env {STRIDE_ENV_IDS}, got {env_id}"
        )
    unknown = sorted(set(hp) - set(_SECTION_KEYS))
    if unknown:
        raise ValueError(
            f"{where}: unknown key {unknown[0]!r} for algo {ALGO}; known: {_SECTION_KEYS}"
        )
    mismatch = "none"
    for item in hp.get("env_wrapper") or []:
        name, kw = (item, {}) if isinstance(item, str) else next(iter(dict(item).items()))
        if name not in _RANDOMIZED:
            raise ValueError(
                f"{where}: env_wrapper {name!r}: algo {ALGO} takes RandomizedPlant only"
            )
        kw = kw or {}
        if set(kw) - {"mismatch"}:
            raise ValueError(f"{where}: RandomizedPlant takes mismatch only, got {sorted(kw)}")
        mismatch = str(kw.get("mismatch", "pm5"))
    as_spec(mismatch)
    extra = dict(hp.get("adaptive") or {})
    names = {f.name for f in fields(AdaptiveConfig)} - {"mismatch", "seed"}
    for key in extra:
        if key not in names:
            raise ValueError(f"{where}: adaptive.{key}: unknown; known: {sorted(names)}")
    if "hidden" in extra:
        extra["hidden"] = tuple(int(h) for h in extra["hidden"])
    cfg = AdaptiveConfig(mismatch=mismatch, seed=int(seed), **extra)
    expert = load_classical(cfg.expert)
    want = {
        "gait": expert.gait,
        "basis": expert.basis.name,
        "K": expert.basis.K,
        "max_torque": expert.max_torque,
    }
    env_kwargs = dict(hp.get("env_kwargs") or {})
    for key, value in env_kwargs.items():
        if key in want and value != want[key]:
            raise ValueError(
                f"{where}: env_kwargs.{key} = {value!r}, but the expert {cfg.expert!r} has "
                f"{want[key]!r}"
            )
    return cfg


def train_from_config(
    config, env_id: str, seed: int, name=None, runs_dir="runs", sets=None, progress=True
) -> Path:
    """``bound-env train`` of a section with ``algo: adaptive-dagger``: DAgger into
    ``runs_dir/name`` (default ``adaptive_s<seed>``; resumed when it holds the same settings),
    with the policy in ``policy/`` and its ``run.json``. Returns the run folder."""
    from .config import apply_sets, load_hyperparams, resolve_config_path
    from .distill import write_run_info

    hp = apply_sets(load_hyperparams(config, env_id), sets)
    cfg = config_from_section(hp, env_id, seed, str(resolve_config_path(config)))
    run = Path(runs_dir) / (name or f"adaptive_s{seed}")
    summary = train_adaptive(cfg, run, progress=progress)
    rounds = summary["rounds"]
    write_run_info(
        run / "policy",
        seed,
        "bound-env " + " ".join(sys.argv[1:]),
        summary["seconds"],
        f"{sum(r['states'] for r in rounds)} apex states in {len(rounds)} DAgger rounds "
        f"({sum(r['labelled'] for r in rounds)} labelled by the privileged teacher)",
    )
    return run
