"""A distilled student as a controller: the choice policy a ``--policy`` name or folder loads.

The student (`agents.experts.distill`, which fits it) picks, at an apex past the expert's safe
radius, one row of a fixed library of stride profiles: an MLP of the normalized apex error,
one logit per row, the argmax played; within the safe radius it is the LQR. A folder holds
``choice.npz`` (the network and the library), ``config.json`` (the frozen expert) and
``fingerprint.json``. NumPy inference only: margins and rollout never import torch for it.
"""

from __future__ import annotations

import hashlib
import json
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from bound_env.control import load_controller as load_classical
from bound_env.control.mpc import MPCController
from bound_env.files.cache import atomic_write

from ..common.mlp import mlp_forward
from ..common.policy_files import FINGERPRINT_FILE, file_sha256, source_name
from ..common.schema import check_choice_config, check_choice_npz, policy_kind

POLICY_FILE = "choice.npz"  # the student's weights and library, in a policy folder


# --------------------------------------------------------------------------------------------
# The controller (NumPy inference: margins and rollout never import torch for it)
# --------------------------------------------------------------------------------------------


@dataclass
class ChoicePolicyController(MPCController):
    """The distilled student (module docstring): the MPC's protocol, its plan a library row."""

    layers: list = field(default_factory=list, repr=False)  # [(W, b), ...]
    rows: np.ndarray | None = field(default=None, repr=False)  # the library (row 0: the LQR's)

    def logits(self, z) -> np.ndarray:
        x = (np.atleast_2d(z) - self.z_ref) / self.scales
        return mlp_forward(self.layers, x, "Tanh")  # tanh hidden layers, linear output

    def plan(self, z) -> np.ndarray:
        """The coefficients at apex z: the LQR's within the safe radius, else the library row
        the network picks (row 0: the LQR's own plan). For n apex states Z (n, 6) at once,
        (n, K): one forward pass for all (equal to row by row to rounding)."""
        z = np.asarray(z, dtype=float)
        if z.ndim == 2:
            U = np.array([self.lqr.coefficients(zi) for zi in z]).reshape(len(z), -1)
            past = np.max(np.abs(z - self.z_ref) / self.scales, axis=1) > self.safe
            if past.any():
                c = np.argmax(self.logits(z[past]), axis=1)
                rows = np.flatnonzero(past)
                U[rows[c > 0]] = self.rows[c[c > 0]]
            return U
        u_lqr = self.lqr.coefficients(z)
        if np.max(np.abs(z - self.z_ref) / self.scales) <= self.safe:
            self._kind = "gate"
            return u_lqr
        c = int(np.argmax(self.logits(z)[0]))
        self._kind = "lqr" if c == 0 else "override"
        return u_lqr if c == 0 else self.rows[c].copy()

    def fingerprint(self) -> str:
        h = hashlib.sha256(b"choice")
        h.update(super().fingerprint().encode())
        for W, b in self.layers:
            h.update(np.ascontiguousarray(W).tobytes())
            h.update(np.ascontiguousarray(b).tobytes())
        h.update(np.ascontiguousarray(self.rows).tobytes())
        return h.hexdigest()[:16]


def npz_bytes(**arrays) -> bytes:
    import io

    buf = io.BytesIO()
    np.savez(buf, **arrays)
    return buf.getvalue()


def frozen_lqr(lqr) -> dict:
    """An expert's LQR as saved with a student and handed to the rescue env: gait, basis, K,
    max_torque, dt and its gain, explicit (`expert_of` rebuilds it without a re-design)."""
    return {
        "gait": lqr.gait,
        "basis": lqr.basis.name,
        "K": lqr.basis.K,
        "max_torque": lqr.max_torque,
        "dt": lqr.dt,
        "gain": lqr.gain.tolist(),
    }


def frozen_expert(expert: MPCController) -> dict:
    """The ``expert`` record of a student's ``config.json`` (choice and adaptive): its name (a
    shipped one by its name, not a path), its LQR (`frozen_lqr`) and settings, frozen: later
    spec edits change nothing. `expert_of` reads it back."""
    return {
        "name": source_name(expert.name),
        **frozen_lqr(expert.lqr),
        "settings": expert.settings(),
    }


def save_policy(folder: Path, expert: MPCController, layers, rows, config: dict) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    arrays = {"rows": rows, "n_layers": np.array(len(layers))}
    for k, (W, b) in enumerate(layers):
        arrays[f"W{k}"], arrays[f"b{k}"] = W, b
    atomic_write(folder / POLICY_FILE, npz_bytes(**arrays))
    spec = {"kind": "choice", "expert": frozen_expert(expert), **config}
    atomic_write(folder / "config.json", json.dumps(spec, indent=2, default=str) + "\n")
    write_choice_fingerprint(folder)


# what a choice policy's fingerprint.json binds together (the network and library, and the
# frozen expert: its LQR gain, basis, max_torque, dt and settings)
FINGERPRINTED = (POLICY_FILE, "config.json")


def write_choice_fingerprint(folder) -> Path:
    """``fingerprint.json`` of a choice policy folder: the sha256 of ``choice.npz`` and
    ``config.json`` (written atomically), checked by `check_choice_fingerprint`, as
    `agents.common.policy_files.write_fingerprint` binds a PPO policy's files."""
    folder = Path(folder)
    data = {name: file_sha256(folder / name) for name in FINGERPRINTED}
    return atomic_write(folder / FINGERPRINT_FILE, json.dumps(data, indent=2) + "\n")


def check_choice_fingerprint(folder, force: bool = False) -> list[str]:
    """ValueError when ``choice.npz`` or ``config.json`` does not match the folder's
    ``fingerprint.json`` (changed or cut short since the policy was saved, or files of two
    policies mixed); ``force`` evaluates it as it is, and the mismatch comes back as a
    warning. A folder without a fingerprint (saved before they were written) passes."""
    from ..common.schema import read_fingerprint

    folder = Path(folder)
    fp = folder / FINGERPRINT_FILE
    want = read_fingerprint(folder)  # a folder or a broken file there is an error
    if want is None:
        return []
    warnings = []
    for name in FINGERPRINTED:
        path = folder / name
        if name in want and (not path.is_file() or file_sha256(path) != want[name]):
            msg = (
                f"{path} does not match {fp} (sha256): it was changed or cut short after the "
                "policy was saved"
            )
            if not force:
                raise ValueError(
                    msg + "; pass --force (margins, rollout, basin-map) to evaluate the policy "
                    "with it as it is"
                )
            warnings.append(msg)
    return warnings


def load_choice_policy(folder, gait=None, force: bool = False) -> ChoicePolicyController:
    """A saved student (a folder with ``choice.npz`` and ``config.json``), checked against its
    ``fingerprint.json`` (`check_choice_fingerprint`; ``force`` loads a mismatch with a
    warning) and against the schema of its files (`agents.common.schema`: types, shapes, finite
    values, ranges); ValueError naming the file and the field."""
    folder = Path(folder)
    for w in check_choice_fingerprint(folder, force):
        print(f"warning: {w}", file=sys.stderr)
    try:
        policy_kind(folder)  # a PPO folder with a choice.npz dropped in: ambiguous
        cfg = check_choice_config(folder / "config.json")
        layers, rows = check_choice_npz(folder / POLICY_FILE)
    except ValueError as e:
        raise ValueError(f"{e} (not a readable distilled policy)") from None
    if rows.shape[1] != cfg["expert"]["K"]:
        raise ValueError(
            f"{folder / POLICY_FILE}: rows has {rows.shape[1]} columns, but "
            f"{folder / 'config.json'}: expert.K is {cfg['expert']['K']} (not a readable "
            "distilled policy)"
        )
    expert = expert_of(cfg["expert"], gait)
    s = expert.settings()
    return ChoicePolicyController(
        name=str(folder),
        lqr=expert.lqr,
        params=expert.params,
        safe=s["safe"],
        horizon=s["horizon"],
        rtol=s["rtol"],
        layers=layers,
        rows=rows,
    )


def expert_of(frozen: dict, gait=None) -> MPCController:
    """The expert saved with a policy (its LQR gain explicit, not re-designed)."""
    from bound_env.control.spec import MPC_DEFAULTS, ControllerSpec

    s = dict(frozen["settings"])
    s["plan_rtol"] = s.pop("rtol")
    spec = ControllerSpec(
        controller="mpc",
        gait=frozen["gait"],
        max_torque=float(frozen["max_torque"]),
        dt=float(frozen["dt"]),
        basis=frozen["basis"],
        K=int(frozen["K"]),
        gain=frozen["gain"],
        extra={**MPC_DEFAULTS, **s},
    )
    spec.path = None
    return load_classical(spec, gait)
