"""Return rate on the rescue task (PassiveBoundRescue-v0/-v1) from validation starts.

    PYTHONPATH=. .venv/bin/python scripts/rescue_eval.py runs/rescue-ppo-s0/model.zip lqr mpc

Each argument is a PPO model trained on the rescue env's continuous actions (a ``model.zip``,
or a run folder holding one; its ``vecnormalize.pkl`` beside it is applied when it normalizes
observations; the env id and ``env_kwargs`` of the run's ``config.yaml`` beside it make the
env, so a PassiveBoundRescue-v1 model sees its own observation and action mode; without one,
``--env-id``), or a stride controller by name or path (``lqr``, ``mpc``, ``default``, a policy
folder: `agents.runtime.policy.load_controller`), which plays its plan at each apex state of
PassiveBoundRescue-v0 (the same plant, starts and returns as v1).

The starts are z* + r |z*| xi for ``--dirs`` validation directions xi (seed 777,
`agents.common.seeds.VALIDATION_SEED`; `bound_env.analysis.margins.random_directions`, never the
test set's 12345) at each size r of ``--sizes``; a start inside the safe radius is not counted.
An episode returns when the env says so (the apex state back inside the safe radius within
``horizon`` strides, without a fall). Prints one row per size and the mean over all starts;
``--json`` prints the numbers as JSON.
"""

from __future__ import annotations

import argparse
import json
import pickle
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np

import bound_env
from agents.common.seeds import VALIDATION_SEED
from bound_env import RESCUE_ENV_ID
from bound_env.analysis.margins import random_directions

SIZES = (0.1, 0.15, 0.2, 0.25, 0.3, 0.35, 0.4, 0.45)
N_DIRS = 32


# env kwargs that change the starts, the reward or the horizon, not the policy's env: every
# policy is measured from the same starts with the same 30-stride horizon
EVAL_IGNORED_KWARGS = ("r_min", "r_max", "axis_prob", "shaping", "gamma", "horizon")


def model_env(path: Path, env_id: str | None = None) -> tuple[str, dict]:
    """The env id and kwargs a model was trained on: its run's ``config.yaml`` (rl-zoo3
    format with a ``run:`` entry), else ``env_id`` (default PassiveBoundRescue-v0)."""
    import yaml

    path = Path(path)
    cfg = (path if path.is_dir() else path.parent) / "config.yaml"
    if env_id is None and cfg.is_file():
        data = yaml.safe_load(cfg.read_text())
        env_id = data["run"]["env_id"]
        kwargs = dict(data[env_id].get("env_kwargs") or {})
    else:
        kwargs = {}
    kwargs = {k: v for k, v in kwargs.items() if k not in EVAL_IGNORED_KWARGS}
    return env_id or RESCUE_ENV_ID, kwargs


def model_actor(path: Path):
    """act(obs, env) of a PPO model file (deterministic), with its observation statistics."""
    from stable_baselines3 import PPO

    path = Path(path)
    if path.is_dir():
        path = path / "model.zip"
    model = PPO.load(str(path), device="cpu")
    stats = path.parent / "vecnormalize.pkl"
    norm = None
    if stats.is_file():
        with open(stats, "rb") as f:
            vn = pickle.load(f)
        norm = vn if getattr(vn, "norm_obs", False) else None

    def act(obs, env):
        x = norm.normalize_obs(obs[None])[0] if norm is not None else obs
        return model.predict(x, deterministic=True)[0]

    return act


def controller_actor(name: str):
    """act(obs, env) of a stride controller: its plan at the env's apex state."""
    from agents.runtime.policy import load_controller

    ctrl = load_controller(name)
    plan = getattr(ctrl, "stride_action", None)
    if plan is None:
        raise ValueError(f"{name}: not a stride controller (no stride_action)")
    return lambda obs, env: np.asarray(plan(env.unwrapped.z), dtype=np.float32)


def evaluate(act, env, sizes=SIZES, n_dirs: int = N_DIRS, seed: int = VALIDATION_SEED) -> dict:
    """The return rate of ``act`` on ``env`` from the validation starts, per size."""
    base = env.unwrapped
    dirs = random_directions(n_dirs, seed)
    rows = []
    for r in sizes:
        k = n = 0
        for xi in dirs:
            z = base.z_ref + r * np.abs(base.z_ref) * xi
            if not base.past_safe(z):
                continue
            obs, _ = env.reset(options={"apex_state": z})
            done = False
            while not done:
                obs, _, term, trunc, info = env.step(act(obs, env))
                done = term or trunc
            n += 1
            k += bool(info["returned"])
        rows.append({"r": float(r), "returned": k, "n": n, "rate": k / n if n else None})
    k, n = sum(x["returned"] for x in rows), sum(x["n"] for x in rows)
    return {"sizes": rows, "returned": k, "n": n, "rate": k / n if n else None, "seed": seed}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("policies", nargs="+", help="model.zip / run folder, or a controller name")
    p.add_argument("--sizes", type=float, nargs="+", default=list(SIZES))
    p.add_argument("--dirs", type=int, default=N_DIRS, help="validation directions per size")
    p.add_argument("--seed", type=int, default=VALIDATION_SEED, help="directions' seed")
    p.add_argument(
        "--env-id",
        default=None,
        help="env of the models without a config.yaml (default: PassiveBoundRescue-v0)",
    )
    p.add_argument("--json", action="store_true")
    args = p.parse_args(argv)
    if args.seed == 12345:
        print("--seed 12345 is the test set's; choose on validation starts", file=sys.stderr)
        return 2
    gym.register_envs(bound_env)
    out = {}
    for spec in args.policies:
        path = Path(spec)
        is_model = path.suffix == ".zip" or (path / "model.zip").is_file()
        try:
            act = model_actor(path) if is_model else controller_actor(spec)
            env_id, kwargs = model_env(path, args.env_id) if is_model else (RESCUE_ENV_ID, {})
            env = gym.make(env_id, **kwargs)
        except (OSError, ValueError, KeyError, gym.error.Error) as e:
            print(f"{spec}: {e}", file=sys.stderr)
            return 2
        out[spec] = evaluate(act, env, args.sizes, args.dirs, args.seed)
        env.close()
        if not args.json:
            res = out[spec]
            cells = "  ".join(f"r={x['r']:.2f}: {x['returned']}/{x['n']}" for x in res["sizes"])
            print(f"{spec}: return rate {res['rate']:.3f} ({res['returned']}/{res['n']})  {cells}")
    if args.json:
        print(json.dumps(out, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
