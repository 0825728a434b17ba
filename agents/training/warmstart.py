"""Warm start of step-level PPO by behaviour cloning a stride controller (`train --init-from`).

The teacher (any controller with the stride protocol: ``on_apex`` and ``__call__(obs)``, e.g.
the shipped `default`) drives the training env itself, i.e. PassiveBound-v0 behind the
config's wrappers (`agents.common.wrappers.PerturbedStarts` at start sizes spread over the
curriculum's range, `agents.common.wrappers.ObservationFilter`). Every control interval gives one
pair (the policy's observation, the teacher's normalized torque). The observation statistics
of `VecNormalize` are set from these observations, and the actor's mean (the policy net and
the action head) is fitted to the teacher's torques by least squares. PPO then trains from
there as usual; the critic starts fresh.

The torque a stride controller applies on an interval depends on the apex state it planned
from, which the step policy does not observe: the clone can only approximate it from the
current state and the time since the apex. The fit's residual is reported (`bc_rmse`).
"""

from __future__ import annotations

import sys
import time

import numpy as np

BC_STEPS = 60_000  # control intervals of teacher data
BC_EPOCHS = 30
BC_EPISODE_STEPS = 240  # steps per teacher episode (about 6 strides: recoveries, then the cycle)
BC_SCALES = (0.5, 1.0, 1.5, 2.0, 2.5)  # start sizes (the curriculum's range of configs/ppo.yaml)


def _full_obs(filtered, idx_time: int, full_time: int, size: int) -> np.ndarray:
    """An observation of the unwrapped env's layout holding what the stride protocol reads: the
    time since the apex (the plan itself comes from ``on_apex``)."""
    out = np.zeros(size)
    out[full_time] = filtered[idx_time]
    return out


def collect(env, teacher, seed: int, n_steps: int = BC_STEPS, progress: bool = True):
    """(observations, actions) of the teacher in ``env`` (the wrapped training env)."""
    from bound_env.sim.stride_protocol import OBS_TIME, notify_apex

    from ..common.wrappers import ObservationFilter

    full = list(env.unwrapped.task.obs_names)  # the unwrapped observation's layout
    if full[0] == "x_g" or full[OBS_TIME] != "time_since_apex":
        raise ValueError("--init-from needs the default observation (x_g excluded)")
    kept, inner = full, env
    while inner is not None:  # the names the policy sees, through its ObservationFilter
        if isinstance(inner, ObservationFilter):
            kept = list(inner.names)
            break
        inner = getattr(inner, "env", None)
    idx_time = kept.index("time_since_apex")
    X, A = [], []
    rng = np.random.default_rng(seed)
    t0 = time.perf_counter()
    k = 0
    while len(X) < n_steps:
        scale = BC_SCALES[k % len(BC_SCALES)]
        k += 1
        _set_noise(env, scale)
        obs, info = env.reset(seed=int(rng.integers(2**31)))
        notify_apex(teacher, _full_obs(obs, idx_time, OBS_TIME, len(full)), info)
        for _ in range(BC_EPISODE_STEPS):
            a = teacher(_full_obs(obs, idx_time, OBS_TIME, len(full)))
            X.append(np.asarray(obs, dtype=float))
            A.append(a)
            obs, _, terminated, truncated, info = env.step(np.array([a], dtype=np.float32))
            if terminated or truncated:
                break
            notify_apex(teacher, _full_obs(obs, idx_time, OBS_TIME, len(full)), info)
        if progress and k % 50 == 0:
            print(
                f"[warm start] {len(X)}/{n_steps} teacher steps ({time.perf_counter() - t0:.0f} s)",
                file=sys.stderr,
                flush=True,
            )
    return np.array(X[:n_steps]), np.array(A[:n_steps], dtype=float)


def _set_noise(env, scale: float) -> None:
    inner = env
    while inner is not None:
        if hasattr(inner, "set_noise_scale"):
            inner.set_noise_scale(scale)
            return
        inner = getattr(inner, "env", None)


def clone(model, venv, X, A, seed: int, epochs: int = BC_EPOCHS) -> dict:
    """Set ``venv``'s observation statistics from X and fit the actor's mean to A."""
    import torch as th

    if getattr(venv, "obs_rms", None) is not None:
        venv.obs_rms.mean = X.mean(axis=0)
        venv.obs_rms.var = X.var(axis=0)
        venv.obs_rms.count = float(len(X))
        Xn = np.clip(
            (X - venv.obs_rms.mean) / np.sqrt(venv.obs_rms.var + venv.epsilon),
            -venv.clip_obs,
            venv.clip_obs,
        )
    else:
        Xn = X
    pol = model.policy
    x = th.as_tensor(Xn, dtype=th.float32)
    y = th.as_tensor(A, dtype=th.float32).reshape(-1, 1)
    params = list(pol.mlp_extractor.policy_net.parameters()) + list(pol.action_net.parameters())
    if hasattr(pol, "features_extractor"):
        params += list(pol.features_extractor.parameters())
    opt = th.optim.Adam(params, lr=1e-3)
    gen = th.Generator().manual_seed(seed)

    def mean_action(xb):
        feats = pol.extract_features(xb, pol.pi_features_extractor)
        return pol.action_net(pol.mlp_extractor.forward_actor(feats))

    n = len(x)
    for _ in range(epochs):
        perm = th.randperm(n, generator=gen)
        for i in range(0, n, 256):
            idx = perm[i : i + 256]
            loss = th.mean((mean_action(x[idx]) - y[idx]) ** 2)
            opt.zero_grad()
            loss.backward()
            opt.step()
    with th.no_grad():
        pred = th.clamp(mean_action(x), -1.0, 1.0)
        rmse = float(th.sqrt(th.mean((pred - y) ** 2)))
    return {
        "bc_steps": int(n),
        "bc_epochs": epochs,
        "bc_rmse": rmse,
        "teacher_rms": float(np.sqrt(np.mean(A**2))),
    }
