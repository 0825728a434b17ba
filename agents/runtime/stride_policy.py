"""A trained stride-level policy (`agents.runtime.stride`) as a controller of the step env.

`StridePolicyController` runs a trained stride policy inside the step env (`PassiveBound-v0`)
with the protocol of `bound_env.analysis.margins.ClosedLoop`: at every apex (``on_apex``) it
picks the coefficients u, and each control interval outputs the interval average of the
profile's torque, as `bound_env.control.StrideFeedback` does. Inference is NumPy (no torch in
margins' workers); the base gain is read from the policy's own ``base.json`` (written at training
time, `write_base`), so a later change of ``configs/controllers/lqr.yaml`` does not change a
trained policy. `load_stride_policy` reads a policy folder
(``agents.runtime.policy.load_controller`` calls it for a run of ``PassiveBoundStride-v*``).
"""

from __future__ import annotations

import hashlib
import json
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

# policies trained before v1 (agents/policies/stride-residual) name v0: they load, and act on v1
from bound_env import STRIDE_ENV_ID, STRIDE_ENV_IDS

from ..common.mlp import checked_actor, mlp_forward
from ..common.policy_files import (
    check_policy_files,
    find_policy_files,
    load_vecnormalize,
    read_policy_section,
    refuse_privileged,
)
from ..common.schema import (
    check_base,
    check_env_kwargs,
    check_obs_stats,
    check_residual_scale,
)
from .controllers import check_gait
from .stride import BASE_FILE, BASIS_RTOL, BaseGain


@dataclass
class StridePolicyController:
    """A trained stride policy in the margins protocol (see the module docstring).

    u = clip(u_base(z) + residual_scale * clip(mlp(x), -1, 1), -1, 1), x = (z - z*) / |z*|,
    chosen at each apex; each control interval outputs the interval average of the profile
    tau(t) = max_torque * sum_i u_i phi_i(t) (normalized by max_torque).
    """

    name: str
    layers: list  # [(W, b)] hidden layers, then the action layer
    activation: str
    z_ref: np.ndarray
    edges: np.ndarray  # sub-window edges of the torque basis [s]
    phi: np.ndarray  # (n_sub, K)
    max_torque: float
    base: BaseGain | None = None
    residual_scale: float = 1.0
    anchored: bool = False  # residual = g(x) (net(x) - net(0)) (`AnchoredMlpPolicy`)
    gate_scale: float = 0.0  # g(x) = |x|^2 / (|x|^2 + gate_scale^2), 1 if 0
    obs_mean: np.ndarray | None = None  # VecNormalize statistics of x (None: none)
    obs_var: np.ndarray | None = None
    epsilon: float = 1e-8
    clip_obs: float = 10.0
    dt: float = 0.01
    gait: str = "default"
    seed: int | None = None
    _taus: np.ndarray | None = field(default=None, repr=False)

    @property
    def env_kwargs(self) -> dict:
        return {"gait": self.gait, "max_torque": self.max_torque, "dt": self.dt}

    @property
    def basis(self):
        from bound_env.sim.stride_task import TorqueBasis

        return TorqueBasis("policy", self.edges, self.phi)

    def _net(self, x) -> np.ndarray:
        return mlp_forward(self.layers, x, self.activation)

    def residual(self, z) -> np.ndarray:
        """du = clip(mean action, -1, 1) at apex state z."""
        x = (np.asarray(z, dtype=float) - self.z_ref) / np.abs(self.z_ref)
        x = np.clip(x, -1e3, 1e3).astype(np.float32).astype(float)  # the env's observation
        if self.obs_mean is not None:
            x = np.clip(
                (x - self.obs_mean) / np.sqrt(self.obs_var + self.epsilon),
                -self.clip_obs,
                self.clip_obs,
            )
        mean = self._net(x)
        if self.anchored:
            mean = mean - self._net(np.zeros_like(x))
            if self.gate_scale > 0:
                q = float(np.dot(x, x))
                mean = mean * (q / (q + self.gate_scale**2))
        return np.clip(mean, -1.0, 1.0)

    def coefficients(self, z) -> np.ndarray:
        u0 = self.base(z) if self.base is not None else 0.0
        return np.clip(u0 + self.residual_scale * self.residual(z), -1.0, 1.0)

    def stride_action(self, z) -> np.ndarray:
        """The action of PassiveBoundStride-v1 at apex state z."""
        return self.coefficients(z)

    def interval_actions(self, Z) -> np.ndarray:
        """The step env's actions of the strides from the apex states Z (the protocol of
        `bound_env.control.controllers`)."""
        from bound_env.sim.stride_protocol import interval_actions_of, observed_times

        U = [self.coefficients(z) for z in np.atleast_2d(np.asarray(Z, dtype=float))]
        return interval_actions_of(self.basis, self.max_torque, U, observed_times(self.dt), self.dt)

    def apex_torques(self, z) -> np.ndarray:
        """The profile planned at apex state z: torque on each sub-window [N m]."""
        return self.max_torque * (self.phi @ self.coefficients(z))

    snaps_time = False  # the profile is read at the observed (float32) time since the apex

    def on_apex(self, z, time_since_apex: float = 0.0) -> None:
        self._taus = self.apex_torques(z)

    def planned_profile(self):
        """(taus [N m], t0) of the last apex's profile, as ``__call__`` reads it (None before
        the first apex; `bound_env.sim.stride_protocol.profile_rows`)."""
        return None if self._taus is None else (self._taus, 0.0)

    def __call__(self, obs) -> float:
        from bound_env.sim.stride_protocol import OBS_TIME, OBS_Z

        t = float(obs[OBS_TIME])
        if self._taus is None:
            self.on_apex(np.asarray(obs, dtype=float)[list(OBS_Z)], t)
        tau = self.basis.average(self._taus, t, t + self.dt)
        return float(np.clip(tau / self.max_torque, -1.0, 1.0))

    def fingerprint(self) -> str:
        h = hashlib.sha256(b"stride-policy")
        for W, b in self.layers:
            h.update(np.ascontiguousarray(W).tobytes())
            h.update(np.ascontiguousarray(b).tobytes())
        arrays = [self.z_ref, self.edges, self.phi]
        if self.base is not None:
            arrays.append(self.base.gain)
        if self.obs_mean is not None:
            arrays += [self.obs_mean, self.obs_var]
        for a in arrays:
            h.update(np.ascontiguousarray(a, dtype=float).tobytes())
        h.update(
            repr(
                (
                    self.max_torque,
                    self.dt,
                    self.gait,
                    self.residual_scale,
                    self.activation,
                    self.anchored,
                    self.gate_scale,
                )
            ).encode()
        )
        return h.hexdigest()[:16]

    def __getstate__(self):
        state = dict(self.__dict__)
        state["_taus"] = None
        return state


def wrapper_kwargs(env_wrappers, name: str) -> dict | None:
    """The kwargs of the ``env_wrapper`` entry whose class is ``name`` (None if absent)."""
    from ..common.config import class_entries

    for path, kw in class_entries(env_wrappers):
        if path.rsplit(".", 1)[-1] == name:
            return dict(kw)
    return None


def load_stride_policy(path, gait=None, force: bool = False) -> StridePolicyController:
    """A trained stride policy (folder or model zip) -> `StridePolicyController` (reads the
    model once, with torch; the controller itself is NumPy). Checks as
    `agents.runtime.policy.load_controller` does: the fingerprint of model and statistics, and the
    gait (another ``gait`` than the policy's own is refused unless ``force``)."""
    from stable_baselines3 import PPO

    from bound_env.sim.stride_task import StrideTask

    files = find_policy_files(path)
    model_path, vecnorm_path = files.model, files.vecnormalize
    section, env_id, seed = read_policy_section(files)
    refuse_privileged(section, files.config)
    if env_id not in STRIDE_ENV_IDS:
        raise ValueError(f"policy {path} was trained on {env_id}, not {STRIDE_ENV_ID}")
    for w in check_policy_files(files, section, force):
        print(f"warning: {w}", file=sys.stderr)
    env_kwargs = check_env_kwargs(dict(section.get("env_kwargs") or {}), str(files.config))
    wrappers = section.get("env_wrapper") or []
    ctl = wrapper_kwargs(wrappers, "StrideControl")
    if ctl is None:
        raise ValueError(f"{files.config}: no agents.runtime.stride.StrideControl in env_wrapper")
    residual_scale = check_residual_scale(ctl.get("residual_scale", 1.0), str(files.config))
    try:
        model = PPO.load(str(model_path), device="cpu")
    except Exception as e:  # noqa: BLE001 - a corrupt or foreign zip is the user's error
        raise ValueError(f"cannot load {model_path} as an SB3 PPO model: {e}") from None
    trained_gait = str(env_kwargs.get("gait", "default"))
    task = StrideTask(
        gait=trained_gait,
        basis=env_kwargs.get("basis", "windows"),
        K=env_kwargs.get("K"),
        max_torque=env_kwargs.get("max_torque", 80.0),
        rtol=BASIS_RTOL,
    )
    if tuple(model.observation_space.shape) != (6,) or tuple(model.action_space.shape) != (task.K,):
        raise ValueError(
            f"policy {model_path} has spaces {model.observation_space.shape} -> "
            f"{model.action_space.shape}; its stride env needs (6,) -> ({task.K},)"
        )
    base = None
    if ctl.get("base") is not None:
        base_path = model_path.parent / BASE_FILE
        if not base_path.is_file():
            raise FileNotFoundError(f"residual policy {path}: missing {base_path}")
        base = BaseGain.from_json(check_base(base_path, task.K))
    layers, activation = checked_actor(model, model_path)
    ctrl = StridePolicyController(
        name=str(path),
        layers=layers,
        activation=activation,
        z_ref=task.z_ref.copy(),
        edges=task.basis.edges.copy(),
        phi=task.basis.phi.copy(),
        max_torque=task.max_torque,
        base=base,
        residual_scale=residual_scale,
        gait=trained_gait,
        seed=seed,
        anchored=type(model.policy).__name__ == "AnchoredMlpPolicy",
        gate_scale=float(getattr(model.policy, "gate_scale", 0.0)),
    )
    if vecnorm_path is not None:
        vn = load_vecnormalize(vecnorm_path)
        if getattr(vn, "norm_obs", False):
            if ctrl.anchored:
                raise ValueError(f"{vecnorm_path}: an AnchoredMlpPolicy needs norm_obs=False")
            stats = check_obs_stats(vn, str(vecnorm_path), (6,))
            ctrl.obs_mean, ctrl.obs_var, ctrl.epsilon, ctrl.clip_obs = stats
    check_gait(ctrl, gait, force)
    return ctrl


def write_base(run_dir: Path, venv) -> None:
    """Write the base controller of a residual run's envs to ``run_dir/base.json``."""
    # has_attr, not get_attr + AttributeError: in a SubprocVecEnv the failing getattr would kill
    # the worker process (the parent then sees EOFError).
    if not venv.has_attr("base"):
        return
    from bound_env.files.cache import atomic_write

    bases = venv.get_attr("base")
    if bases and bases[0] is not None:
        atomic_write(Path(run_dir) / BASE_FILE, json.dumps(bases[0].to_json(), indent=2) + "\n")
