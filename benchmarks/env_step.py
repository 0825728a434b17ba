"""Steps per second of PassiveBound-v0 against Gymnasium's Pendulum-v1 (and HalfCheetah-v5).

Run by hand: ``.venv/bin/python benchmarks/env_step.py [--steps 20000] [--rounds 5]``.

Every environment is built with ``gym.make`` (so with Gymnasium's default wrappers) and fed
pre-drawn uniform random actions, resetting when an episode ends; the timing includes those
resets. The single environments are measured alternately, round by round, in the same process,
so that machine load affects them alike; the medians are printed. The vector environments
(sync, async, and the native ``vector_entry_point`` one with N = 8 and 64) are reported as
environment-steps per second (N per call). Ratios are against Pendulum-v1's single-env rate.
``--json PATH`` records the medians in the ``env_step`` section of PATH
(`bound_env.files.cache.record_section`); the docs quote ``docs/timings.json``'s.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time

import gymnasium as gym
import numpy as np

import bound_env

gym.register_envs(bound_env)


def single_rate(env, actions) -> float:
    """Steps per second of ``env`` over the given actions (resets included)."""
    env.reset(seed=0)
    t0 = time.perf_counter()
    for a in actions:
        _, _, terminated, truncated, _ = env.step(a)
        if terminated or truncated:
            env.reset()
    return len(actions) / (time.perf_counter() - t0)


def vector_rate(envs, actions) -> float:
    """Environment-steps per second of a vector env (autoreset: no resets by hand)."""
    envs.reset(seed=0)
    envs.step(actions[0])  # warm-up (compilation, worker start)
    t0 = time.perf_counter()
    for a in actions:
        envs.step(a)
    return len(actions) * envs.num_envs / (time.perf_counter() - t0)


def main():
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--steps", type=int, default=20000, help="steps per round (single envs)")
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--vector-steps", type=int, default=2000, help="calls per vector env")
    ap.add_argument("--json", help="record the rates in this file's env_step section")
    args = ap.parse_args()
    load0 = [round(v, 2) for v in os.getloadavg()]
    rng = np.random.default_rng(0)

    singles = {
        "PassiveBound-v0": gym.make("PassiveBound-v0"),
        "Pendulum-v1": gym.make("Pendulum-v1"),
    }
    try:
        import mujoco  # noqa: F401

        singles["HalfCheetah-v5"] = gym.make("HalfCheetah-v5")
    except ImportError:
        print("HalfCheetah-v5: skipped (mujoco is not installed)")
    actions = {}
    for name, env in singles.items():
        sp = env.action_space
        actions[name] = rng.uniform(sp.low, sp.high, (args.steps, *sp.shape)).astype(sp.dtype)
        single_rate(env, actions[name][:500])  # warm-up: compilation, caches
    rates = {name: [] for name in singles}
    for _ in range(args.rounds):
        for name, env in singles.items():
            rates[name].append(single_rate(env, actions[name]))
    med = {name: statistics.median(r) for name, r in rates.items()}
    ref = med["Pendulum-v1"]
    print(
        f"single environments, gym.make, random actions, median of {args.rounds} rounds "
        f"of {args.steps} steps:"
    )
    for name, r in med.items():
        print(f"  {name:<42s} {r:>11,.0f} steps/s   x{r / ref:6.2f} Pendulum-v1")

    vec = {}
    print(f"vector environments, {args.vector_steps} calls each (env-steps/s):")
    cases = [  # (label, key in --json, make_vec arguments)
        ("sync, N=8", "sync_8", dict(num_envs=8, vectorization_mode="sync")),
        ("async, N=8", "async_8", dict(num_envs=8, vectorization_mode="async")),
        ("native (vector_entry_point), N=8", "native_8", dict(num_envs=8)),
        ("native, N=64, serial", "native_64", dict(num_envs=64, parallel=False)),
        ("native, N=64, threads", "native_64_threads", dict(num_envs=64, parallel=True)),
    ]
    for label, key, kw in cases:
        envs = gym.make_vec("PassiveBound-v0", **kw)
        n = envs.num_envs
        acts = rng.uniform(-1, 1, (args.vector_steps, n, 1)).astype(np.float32)
        r = vector_rate(envs, acts)
        vec[key] = r
        envs.close()
        print(
            f"  PassiveBound-v0 {label:<26s} {r:>11,.0f} env-steps/s   x{r / ref:6.2f} Pendulum-v1"
        )
    for env in singles.values():
        env.close()
    if args.json:
        from bound_env.files.cache import record_section

        record_section(
            args.json,
            "env_step",
            {
                "steps_per_s": {**med, **vec},
                "rounds": args.rounds,
                "steps": args.steps,
                "load_average_before": load0,
                "what": "steps per second: gym.make(id), random actions, resets included, the "
                "median of the rounds; vector envs of PassiveBound-v0 in env-steps per second",
            },
            "python benchmarks/env_step.py " + " ".join(sys.argv[1:]),
        )
        print(f"recorded in {args.json}")


if __name__ == "__main__":
    main()
