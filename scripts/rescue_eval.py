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

Bad input is a one-line error and exit 2 before any episode runs: the options are typed and
range-checked as the ``bound-env`` options are (`bound_env.files.values.number`; ``--env-id`` a
rescue env id); a model trained on another env than the rescue task's (its config.yaml),
or one whose config names another rescue env than ``--env-id`` (v1 observes a scaled error,
v0 the apex state: the numbers would be of another policy), is refused.
"""

from __future__ import annotations

import argparse
import pickle
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np

import bound_env
from agents.common.seeds import VALIDATION_SEED
from bound_env import RESCUE_ENV_ID, RESCUE_ENV_ID_V1
from bound_env.analysis.margins import DEFAULT_SEED, random_directions
from bound_env.commands.cli_args import add_json_arg, strict_json
from bound_env.files.values import number

SIZES = (0.1, 0.15, 0.2, 0.25, 0.3, 0.35, 0.4, 0.45)
N_DIRS = 32
MAX_DIRS = 10_000  # directions per size (each an episode of up to 30 strides)
MAX_SIZE = 1.0  # a start of z* + r |z*| xi: beyond r = 1 a component may change sign
SEED_MAX = 2**32 - 1  # NumPy's seeds are unsigned 32-bit integers
RESCUE_ENV_IDS = (RESCUE_ENV_ID, RESCUE_ENV_ID_V1)


# env kwargs that change the starts, the reward or the horizon, not the policy's env: every
# policy is measured from the same starts with the same 30-stride horizon
EVAL_IGNORED_KWARGS = ("r_min", "r_max", "axis_prob", "shaping", "gamma", "horizon")


def model_env(path: Path, env_id: str | None = None) -> tuple[str, dict]:
    """The env id and kwargs a model was trained on: its run's ``config.yaml`` (rl-zoo3
    format with a ``run:`` entry), else ``env_id`` (default PassiveBoundRescue-v0). A
    ValueError (one line) for a config that is not readable, trained on an env that is not a
    rescue env, or on another rescue env than ``env_id``."""
    from bound_env.files.schema import read_yaml

    path = Path(path)
    cfg = (path if path.is_dir() else path.parent) / "config.yaml"
    if not cfg.is_file():
        return env_id or RESCUE_ENV_ID, {}
    data = read_yaml(cfg, "config")
    run = data.get("run") if isinstance(data, dict) else None
    trained = run.get("env_id") if isinstance(run, dict) else None
    section = data.get(trained) if trained is not None else None
    if not isinstance(trained, str) or not isinstance(section, dict):
        raise ValueError(f"{cfg}: no run.env_id with its section (not a bound-env train run)")
    if trained not in RESCUE_ENV_IDS:
        raise ValueError(
            f"{path} was trained on {trained} (its {cfg.name}), not on the rescue task "
            f"({', '.join(RESCUE_ENV_IDS)}); measure it with bound-env margins --policy {path}"
        )
    if env_id is not None and env_id != trained:
        raise ValueError(
            f"--env-id {env_id}: {path} was trained on {trained} (its {cfg.name}), whose "
            "observation and actions differ; drop --env-id (it is for models without a config)"
        )
    kwargs = section.get("env_kwargs") or {}
    if not isinstance(kwargs, dict):
        raise ValueError(f"{cfg}: {trained}.env_kwargs must be a mapping, got {kwargs!r}")
    kwargs = {k: v for k, v in kwargs.items() if k not in EVAL_IGNORED_KWARGS}
    return trained, kwargs


def model_actor(path: Path):
    """act(obs, env) of a PPO model file (deterministic), with its observation statistics."""
    from stable_baselines3 import PPO

    path = Path(path)
    if path.is_dir():
        path = path / "model.zip"
    try:
        model = PPO.load(str(path), device="cpu")
    except Exception as e:  # noqa: BLE001 - a corrupt or foreign zip is the user's error
        why = " ".join(str(e).split())[:160] or type(e).__name__
        raise ValueError(f"{path}: not a readable PPO model ({why})") from None
    stats = path.parent / "vecnormalize.pkl"
    norm = None
    if stats.is_file():
        with open(stats, "rb") as f:
            vn = pickle.load(f)
        norm = vn if getattr(vn, "norm_obs", False) else None

    def act(obs, env):
        x = norm.normalize_obs(obs[None])[0] if norm is not None else obs
        return model.predict(x, deterministic=True)[0]

    act.spaces = (model.observation_space, model.action_space)
    return act


def check_spaces(act, env, spec: str) -> None:
    """ValueError (one line) unless a model's spaces are the env's: a model of another
    observation or action would act on numbers that mean something else."""
    spaces = getattr(act, "spaces", None)
    if spaces is None:
        return
    for what, mine, theirs in zip(
        ("observation", "action"), spaces, (env.observation_space, env.action_space), strict=True
    ):
        if getattr(mine, "shape", None) != theirs.shape:
            raise ValueError(
                f"{spec}: the model's {what} space has shape {mine.shape}, "
                f"{env.spec.id if env.spec else 'the env'}'s {theirs.shape}"
            )


def controller_actor(name: str):
    """act(obs, env) of a stride controller: its plan at the env's apex state."""
    from agents.runtime.policy import load_controller

    ctrl = load_controller(name)
    plan = getattr(ctrl, "stride_action", None)
    if plan is None and getattr(ctrl, "stateful", False):
        raise ValueError(
            f"{name}: a stride controller with memory across strides (stateful: e.g. held "
            "offset-free), which this script cannot run: it asks a memoryless plan "
            "(stride_action) of each start; evaluate the controller it wraps"
        )
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


def policy_arg(text: str) -> str:
    """An argparse ``type``: a policy's name or path, not empty."""
    if not text.strip():
        raise argparse.ArgumentTypeError("a policy must be a name or a path, got ''")
    return text


def parser() -> argparse.ArgumentParser:
    """The script's options, typed and range-checked (a bad one: usage error, exit 2)."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument(
        "policies", nargs="+", type=policy_arg, help="model.zip / run folder, or a controller name"
    )
    p.add_argument(
        "--sizes",
        type=number(float, 0.0, MAX_SIZE, lo_open=True),
        nargs="+",
        default=list(SIZES),
        help=f"relative start sizes r in (0, {MAX_SIZE:g}] (default: %(default)s)",
    )
    p.add_argument(
        "--dirs",
        type=number(int, 1, MAX_DIRS),
        default=N_DIRS,
        help="validation directions per size (default: %(default)s)",
    )
    p.add_argument(
        "--seed",
        type=number(int, 0, SEED_MAX),
        default=VALIDATION_SEED,
        help=f"directions' seed (default: %(default)s; {DEFAULT_SEED} is the test set's: refused)",
    )
    p.add_argument(
        "--env-id",
        default=None,
        choices=RESCUE_ENV_IDS,
        help="env of the models without a config.yaml (default: PassiveBoundRescue-v0)",
    )
    add_json_arg(p, "the return rates")
    return p


def main(argv=None) -> int:
    p = parser()
    args = p.parse_args(argv)
    if args.seed == DEFAULT_SEED:
        p.error(f"--seed {DEFAULT_SEED} is the test set's; choose on validation starts")
    gym.register_envs(bound_env)
    out = {}
    for spec in args.policies:
        path = Path(spec)
        try:
            if path.suffix == ".zip" or (path / "model.zip").is_file():
                env_id, kwargs = model_env(path, args.env_id)  # refused before loading torch
                act = model_actor(path)
            else:
                act, env_id, kwargs = controller_actor(spec), RESCUE_ENV_ID, {}
            env = gym.make(env_id, **kwargs)
            check_spaces(act, env, spec)
        except (OSError, ValueError, KeyError, TypeError, gym.error.Error) as e:
            print(f"{spec}: {' '.join(str(e).split())}", file=sys.stderr)
            return 2
        out[spec] = evaluate(act, env, args.sizes, args.dirs, args.seed)
        env.close()
        if not args.json:
            res = out[spec]
            cells = "  ".join(f"r={x['r']:.2f}: {x['returned']}/{x['n']}" for x in res["sizes"])
            rate = "-" if res["rate"] is None else f"{res['rate']:.3f}"  # no start past safe
            print(f"{spec}: return rate {rate} ({res['returned']}/{res['n']})  {cells}")
    if args.json:
        print(strict_json(out, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
