"""``bound-env train | margins | compare`` (registered by `bound_env.commands.cli`)."""

from __future__ import annotations

import json
import shlex
import shutil
import sys
import time
from pathlib import Path

from bound_env.commands.cli_args import (
    POLICY_GAIT_HELP,
    add_gait_args,
    add_json_arg,
    out_dir,
    say,
    strict_json,
)

from .runtime.policy_args import POLICY_HELP, policy_label

SEED_MAX = 2**32 - 1  # NumPy's and Gymnasium's seeds are unsigned 32-bit integers
BUDGET_HELP = (
    "margins budget (bound_env.analysis.margins.BUDGETS): test (a smoke test), quick (32 random "
    "directions), standard or full (256 directions, the finest curves); the time of one "
    "policy's margins is not measured per budget (a whole compare page: see compare --help)"
)
# compare's budgets (the page's own run time is in docs/columns.json, quoted by the docs)
COMPARE_BUDGET_HELP = (
    "margins budget of every column (bound_env.analysis.margins.BUDGETS): test (a smoke test), "
    "quick (32 random directions), standard or full (256 directions, the finest curves: the "
    "results page's; the run that made it records its wall time in docs/columns.json, "
    "docs/yardsticks.md quotes it); with a warm cache only the page is rewritten"
)
# Files a shipped policy directory holds (copied from a run by ``train --export``).
POLICY_FILES = ("model.zip", "vecnormalize.pkl", "config.yaml", "run.json", "eval.csv", "eval.png")


def _add_sample_seed(p, number) -> None:
    """``--seed`` of margins and compare: the random samples (test set or a held-out one)."""
    p.add_argument(
        "--seed",
        type=number(int, 0, SEED_MAX),
        default=12345,  # bound_env.analysis.margins.DEFAULT_SEED
        help="picks the random directions, rough-terrain runs, push trials and MFPT robots "
        "(default: %(default)s, the test set of docs/MARGINS.md; any other seed is a "
        "held-out validation set)",
    )


def register(sub) -> None:
    from bound_env.commands.cli_args import add_progress_args, name_type, number
    from bound_env.sim.parallel import MAX_WORKERS, add_scheduler_args

    from .common.config import DEFAULT_CONFIG, DEFAULT_ENV_ID

    p = sub.add_parser("train", help="train a PPO spine controller (runs/<name>/)")
    p.add_argument(
        "--config",
        default=str(DEFAULT_CONFIG),
        help="rl-zoo3-style hyperparameter file, or a shipped one's name (ppo, ppo-stride, "
        "...: configs/*.yaml) (default: %(default)s)",
    )
    p.add_argument(
        "--env-id",
        default=None,
        help="section of the config and Gymnasium id (default: the config's only section, "
        f"else {DEFAULT_ENV_ID})",
    )
    p.add_argument(
        "--name",
        type=name_type(),
        help="run name: runs/<name>/ (default: <env-id>_s<seed>; letters, digits, . _ + -)",
    )
    p.add_argument(
        "--seed",
        type=number(int, 0, SEED_MAX),
        default=None,
        help="training seed (default: 0; on --resume the run's)",
    )
    p.add_argument("--n-timesteps", type=number(float, 1, 1e10), help="override n_timesteps")
    p.add_argument(
        "--hp",
        action="append",
        metavar="KEY=VALUE",
        help="override a hyperparameter (YAML value; dotted keys descend, e.g. n_steps=128, "
        "env_kwargs.max_torque=20)",
    )
    add_gait_args(
        p, default=None, overrides=False, help="gait name or path (default: the config's)"
    )
    p.add_argument(
        "--set",
        action="append",
        metavar="KEY=VALUE",
        help="override a gait key, as in every command (e.g. kc=300: the env's "
        "gait_overrides); a hyperparameter key is the old spelling of --hp (deprecated)",
    )
    p.add_argument(
        "--resume", action="store_true", help="continue runs/<name>/ from its last checkpoint"
    )
    p.add_argument(
        "--init-from",
        metavar="POLICY",
        help="warm start (PassiveBound-v0): clone a stride controller's torques (a name, e.g. "
        "default, or a policy folder) into the actor before PPO (agents/training/warmstart.py)",
    )
    p.add_argument(
        "--out",
        "--runs-dir",
        dest="runs_dir",
        default="runs",
        metavar="DIR",
        help="folder of the runs: the run is DIR/<name>/ (default: %(default)s; alias: --runs-dir)",
    )
    p.add_argument(
        "--vec-env",
        choices=("auto", "dummy", "subproc"),
        default="auto",
        help="auto: SubprocVecEnv when n_envs > 1 (default: %(default)s)",
    )
    p.add_argument(
        "--eval-freq",
        type=int,
        default=None,
        help="timesteps between evaluations (default: 100000; on --resume the run's)",
    )
    p.add_argument(
        "--n-eval-episodes",
        type=int,
        default=None,
        help="episodes per evaluation (default: 10; on --resume the run's)",
    )
    p.add_argument(
        "--save-freq",
        type=int,
        default=None,
        help="timesteps between checkpoints (default: 200000; on --resume the run's)",
    )
    p.add_argument(
        "--export-out",
        "--export",
        dest="export",
        metavar="DIR",
        help="afterwards copy the policy files to DIR (e.g. agents/policies/NAME): a new or "
        "empty folder unless --force (alias: --export)",
    )
    p.add_argument(
        "--force",
        action="store_true",
        help="with --export-out: replace the files of a folder that has some",
    )
    p.add_argument(
        "--export-from",
        choices=("final", "best"),
        default="final",
        help="export the final model (default: no selection), or the checkpoint "
        "with the best validation score (validation set disjoint from the "
        "margins' test set: see configs/ppo.yaml)",
    )
    add_progress_args(p)
    p.add_argument(
        "--seeds",
        metavar="S,S,...",
        help="one training per seed (runs <name>_s<seed>), each a task of the "
        "executor below, then compare over them (agents/multiseed.py)",
    )
    add_scheduler_args(p, workers_default=2)
    p.add_argument(
        "--runs-transfer",
        choices=("shared", "bytes"),
        default="shared",
        help="with --seeds: workers write --runs-dir themselves (shared storage), "
        "or send each run back as bytes (default: %(default)s)",
    )
    p.add_argument(
        "--compare-budget",
        choices=("test", "quick", "full", "none"),
        default="quick",
        help="with --seeds: margins budget of the final compare (default: %(default)s)",
    )
    add_json_arg(p, "the run summary (run.json)")
    p.set_defaults(func=cmd_train)

    p = sub.add_parser("margins", help="stability margins of the passive gait or a policy")
    p.add_argument("--policy", default="passive", help=POLICY_HELP)
    p.add_argument(
        "--budget",
        choices=("test", "quick", "standard", "full"),
        default="quick",
        help=BUDGET_HELP + " (default: %(default)s)",
    )
    _add_sample_seed(p, number)
    add_gait_args(p, default=None, overrides=False, help=POLICY_GAIT_HELP)
    p.add_argument(
        "--force",
        action="store_true",
        help="evaluate a policy on a gait or without files it was not trained for",
    )
    p.add_argument(
        "--env-id",
        metavar="ID",
        help="the env a plain SB3 model.zip without config.yaml was trained on (e.g. "
        "PassiveBound-v1: its registered kwargs, max_torque 80 N m); a policy with a config "
        "takes its own",
    )
    p.add_argument(
        "--workers",
        type=number(int, 1, MAX_WORKERS),
        default=2,
        help="worker processes (default: 2)",
    )
    add_scheduler_args(p, workers_default=None)
    p.add_argument(
        "--out",
        help="directory for margins.json, CSVs, PNGs and the task cache "
        "(default: out/margins/<policy name>)",
    )
    p.add_argument("--no-cache", action="store_true", help="ignore and do not write the cache")
    p.add_argument(
        "--mismatch",
        metavar="SPEC",
        help="also measure under model error (JSON key mismatch): a preset (pm5, pm10, pm20, "
        "pm2.5, pm7.5, pm15, all5, all10, all20, noise, noise5, delay1, delay2, none; join "
        "with +, e.g. pm5+delay1) or a YAML file (bound_env.mismatch); several separated by commas "
        "(pm5,pm10); quick/full: 32 plants",
    )
    p.add_argument("--json", action="store_true", help="print the JSON result")
    add_progress_args(p)
    p.set_defaults(func=cmd_margins)

    p = sub.add_parser("rollout", help="run a policy for N strides in its own environment")
    p.add_argument("--policy", default="default", help=POLICY_HELP + " (default: %(default)s)")
    add_gait_args(p, default=None, overrides=False, help=POLICY_GAIT_HELP)
    p.add_argument(
        "--strides", type=number(int, 1, 100_000), default=50, help="strides to run (default: 50)"
    )
    p.add_argument(
        "--seed",
        type=number(int, 0, SEED_MAX),
        default=0,
        help="seed of the start noise (default: 0)",
    )
    p.add_argument(
        "--noise",
        type=number(float, 0, 10),
        default=0.0,
        help="start noise, the env's reset_noise_scale (default: 0, on the cycle)",
    )
    p.add_argument("--video", metavar="F.gif|F.mp4", help="record the run")
    p.add_argument("--out", help="where summary.json goes (default: out/rollout/<policy>)")
    p.add_argument(
        "--force",
        action="store_true",
        help="run a policy on a gait or without files it was not trained for",
    )
    p.add_argument("--json", action="store_true", help="print the JSON summary")
    p.set_defaults(func=cmd_rollout)

    p = sub.add_parser("compare", help="passive vs learned margins -> docs/MARGINS.md")
    p.add_argument(
        "--entry",
        "--policy",
        action="append",
        dest="entry",
        metavar="LABEL=PATH[,PATH...][@GAIT]",
        help="a column besides passive: one controller, or several made the same "
        "way (seeds), e.g. learned=runs/s0,runs/s1,runs/s2 (mean and 95%% "
        "t interval over them), or a classical controller: lqr, deadbeat, "
        "damping or a spec .yaml (a bare name is its own label); repeatable "
        "(default: passive, lqr, deadbeat, mpc, the shipped policies and the literal "
        "cycle's columns)",
    )
    p.add_argument(
        "--keep-defaults",
        action="store_true",
        help="with --entry: keep every default column (passive, lqr, mpc, the shipped "
        "policies, ...) and add the entries (an entry named like a default column replaces "
        "it); without it, --entry keeps only passive",
    )
    p.add_argument(
        "--mismatch",
        metavar="SPEC",
        help="also measure every column under model error and add a Model error section "
        "(the specs of margins --mismatch, e.g. pm5,pm10) instead of the page's own one",
    )
    p.add_argument("--no-mismatch", action="store_true", help="leave out its Model error section")
    p.add_argument(
        "--budget",
        choices=("test", "quick", "standard", "full"),
        default="quick",  # what a first-time user should run; docs/MARGINS.md is --budget full
        help=COMPARE_BUDGET_HELP + " (default: %(default)s)",
    )
    _add_sample_seed(p, number)
    p.add_argument("--workers", type=number(int, 1, MAX_WORKERS), default=2)
    add_scheduler_args(p, workers_default=None)
    p.add_argument("--out", default="out/margins", help="per-entry results and caches")
    p.add_argument(
        "--docs",
        default=None,
        metavar="DIR",
        help="where MARGINS.md and its PNGs go (default: the --out folder; give "
        "--docs docs to update the repository's page)",
    )
    add_progress_args(p)
    add_json_arg(p)
    p.add_argument(
        "--note",
        default="",
        help="a paragraph for the top of the page (e.g. why the budget is not the full one)",
    )
    p.add_argument(
        "--render-only",
        action="store_true",
        help="compute nothing: rewrite the page, its plots, paired.json and headline.json "
        "from the margins.json files an earlier run of the same budget and seed left in --out",
    )
    p.set_defaults(func=cmd_compare)

    from .results.basin_cli import register as register_basin_map

    register_basin_map(sub)

    from .experts.learn_cli import register_distill, register_finetune

    register_distill(sub)
    register_finetune(sub)

    # the main job's passive-vs-learned comparison (bound-env demo; agents/results/demo.py)
    from bound_env.commands.render_cli import register_demo_part

    register_demo_part("comparison", demo_comparison)


def demo_comparison(**kwargs):
    """`agents.results.demo.demo_comparison`, imported when ``bound-env demo`` runs it."""
    from .results.demo import demo_comparison as run

    return run(**kwargs)


def cmd_rollout(args) -> int:
    from .runtime.rollout import rollout, summary_text

    r = rollout(
        args.policy,
        gait=args.gait,
        strides=args.strides,
        seed=args.seed,
        noise=args.noise,
        video=args.video,
        force=args.force,
    )
    out = Path(args.out) if args.out else Path("out") / "rollout" / policy_label(args.policy)
    path = _write_json(out / "summary.json", r)
    if args.json:
        print(strict_json(r))
    else:
        print(summary_text(r))
    say(args, f"wrote {path}" + (f" and the video {r['video']}" if r.get("video") else ""))
    return 0


def _write_json(path: Path, data) -> Path:
    """Write JSON atomically (`bound_env.files.cache.atomic_write`), creating the folder."""
    from bound_env.files.cache import atomic_write

    out_dir(path.parent)
    return atomic_write(path, json.dumps(data, indent=2) + "\n")


def cmd_train(args) -> int:
    from .training.train import train

    t0 = time.perf_counter()
    n = int(args.n_timesteps) if args.n_timesteps is not None else None
    if args.env_id is None:
        from .common.config import default_env_id

        args.env_id = default_env_id(args.config)
    from .common.config import load_hyperparams

    if load_hyperparams(args.config, args.env_id).get("algo") == "adaptive-dagger":  # DAgger
        from .experts.adaptive_recipe import cmd_train_recipe

        return cmd_train_recipe(args, train_sets(args), say, strict_json, t0)
    if args.seeds is not None:
        return _train_seeds(args, n, t0)
    if args.export:  # refused before training, not after it
        check_export_dest(args.export, args.force)
    run = train(
        config=args.config,
        env_id=args.env_id,
        name=args.name,
        seed=args.seed,
        n_timesteps=n,
        sets=train_sets(args),
        resume=args.resume,
        runs_dir=args.runs_dir,
        vec_env=args.vec_env,
        init_from=args.init_from,
        eval_freq=_default(args.eval_freq, 100_000, args.resume),
        n_eval_episodes=_default(args.n_eval_episodes, 10, args.resume),
        save_freq=_default(args.save_freq, 200_000, args.resume),
        progress_bar=not args.no_progress,
    )
    say(args, f"run {run}  ({time.perf_counter() - t0:.0f} s)")
    dest = None
    if args.export:
        dest = export_policy(run, args.export, source=args.export_from, force=args.force)
        say(args, f"exported to {dest}")
    if args.json:
        info = json.loads((Path(run) / "run.json").read_text())
        print(strict_json({"run": str(run), "export": str(dest) if dest else None, **info}))
    return 0


def train_sets(args) -> list[str]:
    """``train``'s overrides as hyperparameter settings: ``--hp`` as given, then each gait key
    of ``--set`` as ``env_kwargs.gait_overrides.KEY`` and ``--gait`` as ``env_kwargs.gait``. A
    ``--set`` of another key (``n_steps=``, ``env_kwargs.x=``) is the old spelling of ``--hp``:
    it still works, with a deprecation notice on stderr."""
    from bound_env.model.params import GAIT_KEYS, parse_override

    sets = list(getattr(args, "hp", None) or [])
    for text in args.set or []:
        key = text.partition("=")[0].strip()
        if key in GAIT_KEYS or key == "min_leg_frac":
            k, v = parse_override(text)
            sets.append(f"env_kwargs.gait_overrides.{k}={v!r}")
        else:
            print(
                f"bound-env train: deprecated: --set {text} sets a hyperparameter; use --hp "
                f"{text} (--set overrides a gait key, as in every command)",
                file=sys.stderr,
            )
            sets.append(text)
    if getattr(args, "gait", None) is not None:
        sets.append(f"env_kwargs.gait={json.dumps(str(args.gait))}")
    return sets


def check_export_dest(dest, force: bool = False) -> None:
    """ValueError unless ``dest`` is a new or empty folder (``force``: any folder): an export
    into a shipped policy's folder would overwrite its tracked files."""
    dest = Path(dest)
    if dest.exists() and not dest.is_dir():
        raise ValueError(f"--export-out {dest} exists and is not a folder")
    if not force and dest.is_dir() and any(dest.iterdir()):
        raise ValueError(
            f"--export-out {dest} already holds files (a shipped policy's?); give a new "
            "folder, or --force to replace them"
        )


def _default(value, default, resume: bool):
    """A schedule option: as given; else on --resume the run's own (None), else ``default``."""
    return value if value is not None or resume else default


def _train_seeds(args, n, t0) -> int:
    from .multiseed import parse_seeds, train_seeds

    seeds = parse_seeds(args.seeds)
    if args.export:
        raise ValueError("--export takes one run: export one of the seeds' runs afterwards")
    kwargs = dict(
        config=args.config,
        env_id=args.env_id,
        n_timesteps=n,
        sets=train_sets(args),
        resume=args.resume,
        vec_env="dummy" if args.vec_env == "auto" else args.vec_env,
        eval_freq=_default(args.eval_freq, 100_000, args.resume),
        n_eval_episodes=_default(args.n_eval_episodes, 10, args.resume),
        save_freq=_default(args.save_freq, 200_000, args.resume),
    )
    budget = None if args.compare_budget == "none" else args.compare_budget
    if args.name is None and args.env_id is None:
        from .common.config import default_env_id

        args.name = default_env_id(args.config)  # the seeds' runs: <env id>_s<seed>
    r = train_seeds(
        seeds,
        args.name or args.env_id,
        args.runs_dir,
        kwargs,
        scheduler=args.scheduler,
        workers=args.workers,
        transfer=args.runs_transfer,
        compare_budget=budget,
        progress=not args.no_progress,
    )
    for run in r["runs"]:
        print(f"run {run}")
    if r["compare"]:
        print(f"compare: {r['compare']}")
    print(f"({time.perf_counter() - t0:.0f} s)")
    return 0


def export_policy(run_dir, dest, source: str = "final", force: bool = False) -> Path:
    """Copy a run's policy files to ``dest``: the model and its VecNormalize statistics (with
    ``source="final"``, the default, the final ones: no selection; with ``"best"`` the
    best-validation ones from ``best/`` when the run kept them), and the config, run info,
    evaluation and validation curves. ``exported.json`` says which. ``dest`` must be a new or
    empty folder unless ``force`` (`check_export_dest`)."""
    run_dir, dest = Path(run_dir), Path(dest)
    check_export_dest(dest, force)
    if source not in ("final", "best"):
        raise ValueError(f"export source must be 'final' or 'best', got {source!r}")
    if not (run_dir / "model.zip").is_file():
        raise FileNotFoundError(f"no model.zip in {run_dir}")
    best = run_dir / "best"
    src = best if source == "best" and (best / "model.zip").is_file() else run_dir
    from .common.policy_files import check_policy_files, find_policy_files
    from .runtime.policy import write_policy_fingerprint

    files = find_policy_files(src)
    check_policy_files(files, {}, force=True)  # refuses statistics of another model
    dest.mkdir(parents=True, exist_ok=True)
    for name in ("model.zip", "vecnormalize.pkl"):
        if (src / name).is_file():
            shutil.copyfile(src / name, dest / name)
    for name in POLICY_FILES[2:] + ("basin_validation.csv", "base.json"):
        if (run_dir / name).is_file():
            shutil.copyfile(run_dir / name, dest / name)
    info = {
        "exported_from": str(src),
        "selection": "best validation" if src == best else "none (final model)",
    }
    if (src / "best.json").is_file():
        info.update(json.loads((src / "best.json").read_text()))
    (dest / "exported.json").write_text(json.dumps(info, indent=2) + "\n")
    if (dest / "eval.csv").is_file():  # the curve of what was exported: no best marker on a final
        from .common.run_files import plot_eval

        try:
            plot_eval(dest / "eval.csv", dest / "eval.png", kept="best" if src == best else "final")
        except Exception as e:  # noqa: BLE001 - a plot must never stop an export
            print(f"eval plot failed: {e}", file=sys.stderr)
    write_policy_fingerprint(dest)  # a residual's base pinned too
    return dest


def cmd_margins(args) -> int:
    from .results.margins_cli import run_margins  # loaded when the command runs, not when parsing

    return run_margins(args)


def _checked(path, flag: str) -> Path:
    """``path`` once `check_writable` passes (created later, by the command's own work)."""
    from bound_env.commands.cli_args import check_writable

    check_writable(path, flag)
    return Path(path)


def cmd_compare(args) -> int:
    from .results.compare import chosen_entries, compare, parse_entry

    parsed = [parse_entry(t) for t in args.entry or ()]
    mismatch = None
    if args.mismatch is not None:
        from bound_env.model.mismatch import parse_specs

        mismatch = parse_specs(args.mismatch)  # a bad spec: before any work
    entries = chosen_entries(parsed, keep_defaults=args.keep_defaults)
    path = compare(
        entries,
        budget=args.budget,
        workers=args.workers,
        out=args.out,
        docs=_checked(args.docs or args.out, "--docs"),  # made once the entries are checked
        progress=not args.no_progress,  # a bar on a terminal, else a line now and then
        note=args.note,
        scheduler=args.scheduler,
        seed=args.seed,
        render_only=args.render_only,
        mismatch=mismatch,
        command=shlex.join(["bound-env", *getattr(args, "argv", ["compare"])]),
        model_error=not args.no_mismatch and (not parsed or args.keep_defaults),  # its own
    )
    say(args, f"wrote {path}")
    if args.json:
        print(
            strict_json(
                {
                    "page": str(path),
                    "out": args.out,
                    "budget": args.budget,
                    "entries": [e[0] for e in entries],
                    "seed": args.seed,
                    "paired": str(path.with_name("paired.json")),
                }
            )
        )
    return 0
