"""The learned adaptive controller as a controller: its history, its network, its files.

`AdaptiveController` is trained by `agents.experts.adaptive` (the reference for what it reads,
how it is taught and why); this module is what ``margins``, ``rollout`` and ``compare`` load
(`load_adaptive_policy`: a folder with ``adaptive.npz``, ``config.json`` and
``fingerprint.json``). NumPy inference only: no torch.

The input at apex t: x_t = (z_t - z*) / s and, for each of the last ``k`` strides (newest
first), a ``valid`` flag, the apex it saw, the coefficients it played and the stride's
surprise r = (z_next - z* - A dz - B u) / s against the nominal linear stride map (A, B: the
LQR's design), clipped to +-`FEATURE_CLIP`. The outputs: a correction of the LQR's plan,
u = clip(u_lqr(z) + Delta, -1, 1), and the eight plant factors' estimate (auxiliary head).
The gate: the LQR alone within ``safe`` of z* while the last surprise is at most
``gate_surprise`` (the radius alone without history), so the nominal cycle keeps zero
torque. The history is per episode: ``reset()``, called by every loop through
`bound_env.sim.stride_protocol.reset_controller` (``stateful``); there is no stateless
``interval_actions`` / ``apex_torques``, so loops run a copy per robot.
"""

from __future__ import annotations

import hashlib
import json
import sys
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from bound_env.control.mpc import MPCController
from bound_env.files.cache import atomic_write
from bound_env.model.mismatch import EIGHT

from ..common.mlp import mlp_forward

# source_name: kept importable from here (and this import block unchanged: it is part of the
# adaptive columns' code closure, bound_env.analysis.margins.code_closure)
from ..common.policy_files import FINGERPRINT_FILE, file_sha256, source_name  # noqa: F401
from .choice_policy import expert_of, npz_bytes
from .controllers import same_gait

POLICY_FILE = "adaptive.npz"  # the network and its input statistics
FACTOR_KEYS = EIGHT  # the factors the auxiliary head predicts
FEATURE_CLIP = 10.0  # |normalized| inputs clipped here (a fall-bound state stays finite)


# --------------------------------------------------------------------------------------------
# The controller (NumPy inference; no torch)
# --------------------------------------------------------------------------------------------


SUMMARY_STRIDES = 20  # the summary's count input saturates here


def n_features(k: int, K: int, summary: bool = False) -> int:
    """Inputs: the apex (6), k slots of (valid, x, u, r), and with ``summary`` (and k > 0) the
    episode's means of (x, u, r) and its stride count (min(n, 20) / 20)."""
    slot = 1 + 6 + K + 6
    return 6 + k * slot + (slot if summary and k > 0 else 0)


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
    summary: bool = False  # the episode's means of the slots as inputs too (k > 0)
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
        self._sum = np.zeros(6 + self.basis.K + 6)  # sums of (x, u, r) over the episode
        self._n = 0
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
            slot = self._slot(z)
            self._hist.append(slot)
            self._sum += np.concatenate(slot)
            self._n += 1
        self._last = (z.copy(), np.asarray(u, dtype=float).copy())

    def features(self, z) -> np.ndarray:
        """The network's input at apex z (module docstring), from the recorded strides: the
        stride just finished (its next apex is z) counts as the newest."""
        z = np.asarray(z, dtype=float)
        K = self.basis.K
        f = np.zeros(n_features(self.k, K, self.summary))
        f[:6] = (z - self.z_ref) / self.scales
        if self.k > 0:
            slots = list(self._hist)
            total, n = self._sum, self._n
            if self._last is not None:
                slots.append(self._slot(z))
                total, n = total + np.concatenate(slots[-1]), n + 1
            for j, (x, u, r) in enumerate(reversed(slots[-self.k :])):
                o = 6 + j * (13 + K)
                f[o] = 1.0
                f[o + 1 : o + 7] = x
                f[o + 7 : o + 7 + K] = u
                f[o + 7 + K : o + 13 + K] = r
            if self.summary and n > 0:
                o = 6 + self.k * (13 + K)
                f[o] = min(n, SUMMARY_STRIDES) / SUMMARY_STRIDES
                f[o + 1 : o + 13 + K] = total / n
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
    expert: MPCController,
    layers,
    mu,
    sd,
    k: int,
    name="adaptive",
    gate_surprise: float = 0.02,
    summary: bool = False,
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
        summary=bool(summary),
    )


# --------------------------------------------------------------------------------------------
# Saving and loading a policy folder
# --------------------------------------------------------------------------------------------

FINGERPRINTED = (POLICY_FILE, "config.json")


def save_policy(folder: Path, expert: MPCController, ctrl: AdaptiveController, config: dict):
    """``adaptive.npz`` (layers, k, input statistics), ``config.json`` (kind, the frozen
    expert: its LQR and settings, the factor keys, the run's settings) and
    ``fingerprint.json`` (their sha256), each written atomically."""
    from .choice_policy import frozen_expert  # the record a choice student saves too

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    arrays = {"n_layers": np.array(len(ctrl.layers)), "k": np.array(ctrl.k)}
    arrays["summary"] = np.array(int(ctrl.summary))
    arrays["mu"], arrays["sd"] = ctrl.mu, ctrl.sd
    for j, (W, b) in enumerate(ctrl.layers):
        arrays[f"W{j}"], arrays[f"b{j}"] = W, b
    atomic_write(folder / POLICY_FILE, npz_bytes(**arrays))
    spec = {
        "kind": "adaptive",
        "expert": frozen_expert(expert),
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
    want = None
    if fp.is_file():
        try:
            want = json.loads(fp.read_text())
        except ValueError:
            raise ValueError(f"{fp}: not valid JSON") from None
    if not isinstance(want, dict) or not all(isinstance(want.get(n), str) for n in FINGERPRINTED):
        # missing, {} or without an entry per file: its files cannot be checked
        what = "missing" if want is None else "without the sha256 of " + ", ".join(FINGERPRINTED)
        msg = f"{fp}: {what}: the policy's files cannot be checked against what was trained"
        if not force:
            raise ValueError(msg + "; pass --force to evaluate it as it is")
        print(f"warning: {msg}", file=sys.stderr)
        want = {}
    if want:
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
        summary = bool(int(arrays["summary"])) if "summary" in arrays else False
        mu, sd = arrays["mu"].astype(float), arrays["sd"].astype(float)
        K = int(cfg["expert"]["K"])
        fr = float(cfg.get("factor_range", 0.1))
        gs = float(cfg.get("gate_surprise", 0.02))
    except (KeyError, TypeError, ValueError) as e:
        raise ValueError(f"{where}: missing or malformed entry {e}") from None
    D = n_features(k, K, summary)
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
    trained = cfg["expert"].get("gait") if isinstance(cfg.get("expert"), dict) else None
    if gait is not None and trained is not None and not same_gait(trained, gait):
        msg = f"policy {folder} was trained on gait {trained!r}, not {str(gait)!r}"
        if not force:  # its history and correction were learned on that gait's robot
            raise ValueError(msg + "; pass --force to evaluate it there on purpose")
        print(f"warning: {msg} (--force)", file=sys.stderr)
    expert = expert_of(cfg["expert"], gait)
    ctrl = make_controller(
        expert, layers, mu, sd, k, name=str(folder), gate_surprise=gs, summary=summary
    )
    ctrl.factor_range = fr
    return ctrl
