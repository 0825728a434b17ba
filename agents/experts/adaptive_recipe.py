"""The recipe of the learned adaptive controller: ``bound-env train --config
student-mpc-adaptive`` (its old name, ``--config adaptive``, reads the same sections).

A config section with ``algo: adaptive-dagger`` (``configs/student-mpc-adaptive.yaml``) is read
into an `agents.experts.adaptive.AdaptiveConfig` (`config_from_section`; the section's
``adaptive`` block holds only what differs from its defaults), trained by DAgger
(`agents.experts.adaptive.train_adaptive`) into ``runs/<name>/`` (`train_from_config`, what
``bound-env train`` runs for such a section: `train_recipe`), and every policy folder gets a
``MODEL_CARD.md`` (`model_card`).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from bound_env.files import schema as check
from bound_env.files.cache import atomic_write
from bound_env.model.mismatch import as_spec

from .adaptive import AdaptiveConfig, train_adaptive

# --------------------------------------------------------------------------------------------
# The recipe: ``bound-env train --config adaptive`` (a config section with ``algo:
# adaptive-dagger``)
# --------------------------------------------------------------------------------------------

ALGO = "adaptive-dagger"
_RANDOMIZED = (  # the old flat paths, which stored configs name, and the paths now
    "bound_env.wrappers.RandomizedPlant",
    "bound_env.randomized.RandomizedPlant",
    "bound_env.envs.wrappers.RandomizedPlant",
    "bound_env.envs.randomized.RandomizedPlant",
)
_SECTION_KEYS = ("algo", "env_wrapper", "env_kwargs", "adaptive")


def _hidden(v, where: str) -> tuple:
    if isinstance(v, (str, bytes)) or not isinstance(v, (list, tuple)) or not 1 <= len(v) <= 16:
        raise ValueError(f"{where} must be a list of 1 to 16 layer widths, got {v!r}")
    return tuple(check.integer(h, f"{where}[{i}]", 1, 4096) for i, h in enumerate(v))


def _flag(v, where: str) -> bool:
    return check.boolean(v, where, numpy=False)  # YAML's true or false


def _spec(v, where: str, plants_only: bool = False) -> str:
    try:
        spec = as_spec(check.text(v, where))
    except ValueError as e:
        msg = str(e)
        raise ValueError(msg if msg.startswith(where) else f"{where}: {msg}") from None
    if spec.delay:
        raise ValueError(
            f"{where} {v!r}: algo {ALGO} draws plants and sensor noise, never an actuation "
            "delay (its rollouts advance the stride map), so delay would be ignored"
        )
    if plants_only and spec.has_noise:
        raise ValueError(f"{where} {v!r}: the validation hold draws plants only (no noise)")
    return v


def _teacher_expert(v, where: str) -> str:
    return check.text(v, where)


def _int(lo, hi):
    return lambda v, where: check.integer(v, where, lo, hi)


def _real(lo, hi, lo_open=False):
    return lambda v, where: check.real(v, where, lo, hi, lo_open=lo_open)


# every key of the ``adaptive`` block (`AdaptiveConfig` but ``mismatch`` and ``seed``): its
# type and range, one line naming ``adaptive.KEY`` otherwise
RECIPE_KEYS = {
    "expert": _teacher_expert,  # an mpc spec: train_adaptive loads and checks it
    "teacher": lambda v, where: check.text(v, where, ("cycle", "mpc")),
    "gate_surprise": _real(0.0, 10.0, lo_open=True),
    "summary": _flag,
    "beta": _real(0.0, 1.0),
    "k": _int(0, 64),
    "rounds": _int(1, 100),
    "episodes_first": _int(1, 1_000_000),
    "episodes_round": _int(1, 1_000_000),
    "strides": _int(1, 100_000),
    "nominal_start_prob": _real(0.0, 1.0),
    "r_max": _real(0.0, 1.0),
    "hidden": _hidden,
    "epochs": _int(1, 1_000_000),
    "batch": _int(1, 10_000_000),
    "lr": _real(0.0, 1.0, lo_open=True),
    "aux_weight": _real(0.0, 1000.0),
    "val_plants": _int(1, 4096),
    "val_strides": _int(1, 100_000),
    "val_mismatch": lambda v, where: _spec(v, where, plants_only=True),
}
# the options of ``bound-env train`` for PPO that DAgger has no use for: given, each is refused
# (name, the attribute of the parsed arguments, its value when not given)
PPO_ONLY = (
    ("--n-timesteps", "n_timesteps", None),
    ("--eval-freq", "eval_freq", None),
    ("--n-eval-episodes", "n_eval_episodes", None),
    ("--save-freq", "save_freq", None),
    ("--export-from", "export_from", "final"),
    ("--vec-env", "vec_env", "auto"),
    ("--set", "set", None),
    ("--seeds", "seeds", None),
    ("--init-from", "init_from", None),
)


def check_recipe(block, where: str = "config") -> dict:
    """The ``adaptive`` block of a section, every key typed and range-checked (`RECIPE_KEYS`);
    a one-line ValueError naming ``adaptive.KEY`` and ``where`` otherwise."""
    if block is None:
        return {}
    if not isinstance(block, dict):
        raise ValueError(f"{where}: adaptive must be a mapping, got {block!r}")
    out = {}
    for key, v in block.items():
        if key not in RECIPE_KEYS:
            known = ", ".join(sorted(RECIPE_KEYS))
            raise ValueError(f"{where}: adaptive.{key}: unknown; known: {known}")
        out[key] = RECIPE_KEYS[key](v, f"{where}: adaptive.{key}")
    return out


def refuse_ppo_options(args) -> None:
    """A ValueError naming the first option of `PPO_ONLY` given to a DAgger run (it would be
    ignored)."""
    for flag, attr, unset in PPO_ONLY:
        value = getattr(args, attr, unset)
        if value != unset and not (attr == "set" and not value):
            shown = " ".join(value) if isinstance(value, list) else value
            raise ValueError(
                f"{flag} {shown}: not for algo {ALGO} (a PPO option; DAgger would ignore it: "
                f"its settings are the config's adaptive block, --hp adaptive.KEY=VALUE)"
            )


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
    wrappers = hp.get("env_wrapper") or []
    if not isinstance(wrappers, list):
        raise ValueError(f"{where}: env_wrapper must be a list, got {wrappers!r}")
    for item in wrappers:
        name, kw = (item, {}) if isinstance(item, str) else next(iter(dict(item).items()))
        if name not in _RANDOMIZED:
            raise ValueError(
                f"{where}: env_wrapper {name!r}: algo {ALGO} takes RandomizedPlant only"
            )
        kw = kw or {}
        if not isinstance(kw, dict) or set(kw) - {"mismatch"}:
            raise ValueError(f"{where}: RandomizedPlant takes mismatch only, got {kw!r}")
        mismatch = _spec(kw.get("mismatch", "pm5"), f"{where}: RandomizedPlant mismatch")
    as_spec(mismatch)
    extra = check_recipe(hp.get("adaptive", {}), where)
    cfg = AdaptiveConfig(mismatch=mismatch, seed=int(seed), **extra)
    expert = load_classical(cfg.expert)
    want = {
        "gait": expert.gait,
        "basis": expert.basis.name,
        "K": expert.basis.K,
        "max_torque": expert.max_torque,
    }
    env_kwargs = check.mapping(hp.get("env_kwargs") or {}, f"{where}: env_kwargs")
    for key, value in env_kwargs.items():
        if key not in want:  # e.g. gait_overrides (train --set kc=300): the rollouts ignore it
            raise ValueError(
                f"{where}: env_kwargs.{key}: algo {ALGO} reads {', '.join(want)} only (the "
                f"expert's), so {key} would be ignored"
            )
        if value != want[key]:
            raise ValueError(
                f"{where}: env_kwargs.{key} = {value!r}, but the expert {cfg.expert!r} has "
                f"{want[key]!r}"
            )
    return cfg


def train_from_config(
    config,
    env_id: str,
    seed: int | None,
    name=None,
    runs_dir="runs",
    sets=None,
    progress=True,
    resume: bool = False,
) -> Path:
    """``bound-env train`` of a section with ``algo: adaptive-dagger``: DAgger into
    ``runs_dir/name`` (default ``adaptive_s<seed>``; resumed when it holds the same settings,
    a ValueError naming each changed setting when it holds others; ``resume``: the run must
    be there; ``seed`` None: the resumed run's, else 0),
    with the policy in ``policy/`` and its ``run.json``. Returns the run folder."""
    from ..common.config import apply_sets, load_hyperparams, resolve_config_path
    from .distill import write_run_info

    hp = apply_sets(load_hyperparams(config, env_id), sets)
    run = Path(runs_dir) / (name or f"adaptive_s{0 if seed is None else seed}")
    recorded = run / "adaptive.json"
    if resume and not recorded.is_file():
        raise ValueError(f"--resume: {run} holds no run of algo {ALGO} to resume")
    if seed is None:  # --resume: the run's seed; else 0, as for PPO
        seed = 0
        if resume:
            seed = check.integer(json.loads(recorded.read_text()).get("seed"), f"{recorded}: seed")
    cfg = config_from_section(hp, env_id, seed, str(resolve_config_path(config)))
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
    write_model_card(run / "policy")
    return run


def model_card(folder) -> str:
    """The model card of a policy folder (markdown): the plants and their range, the noise,
    k, the teacher, the DAgger rounds and apex states, the training time and the validation
    curve, all read from its ``config.json`` (and ``run.json`` when there is one)."""
    folder = Path(folder)
    cfg = json.loads((folder / "config.json").read_text())
    a = cfg["adaptive"]
    spec = as_spec(a["mismatch"]).to_dict()
    ranges = ", ".join(f"{k} ±{d:.0%}" for k, d in spec["params"].items()) or "none (nominal)"
    noise = sorted(set(spec["noise"].values()))
    curve = cfg.get("validation_curve", [])
    run = json.loads((folder / "run.json").read_text()) if (folder / "run.json").is_file() else {}
    seconds = run.get("wall_time_s", curve[-1]["seconds"] if curve else float("nan"))
    lines = [
        f"# Model card: {folder.name}",
        "",
        "The learned adaptive controller (`agents.experts.adaptive`): deployable; its teacher "
        "was privileged.",
        "",
        f"- plants: {ranges} (uniform, one plant per episode)",
        f"- sensor noise: {noise[0]:.0%} of each component's scale" if noise else "- no noise",
        f"- history: k = {a['k']} strides"
        + (" plus the episode's means" if a.get("summary") and a["k"] > 0 else ""),
        f"- teacher: {a['teacher']} (privileged: the expert {a['expert']}'s LQR gain about the "
        "true plant's nearest cycle, else the MPC planning on the true plant)"
        if a["teacher"] == "cycle"
        else f"- teacher: the MPC {a['expert']} planning on the true plant (privileged)",
        f"- DAgger: {a['rounds']} rounds, {a['episodes_first']} + {a['episodes_round']} per "
        f"later round episodes of {a['strides']} strides, beta {a.get('beta', 0)}; "
        f"{sum(r['states'] for r in curve)} apex states "
        f"({sum(r['labelled'] for r in curve)} labelled)",
        f"- network: tanh {list(a['hidden'])}, {a['epochs']} epochs per round, seed {a['seed']}",
        f"- training time: {seconds:.0f} s on {run.get('machine', 'this machine')}",
        "- selection: the final model (no selection); validation only on seed 777's plants",
        "",
        f"Validation curve (hold of {a['val_plants']} {a['val_mismatch']} plants of seed 777 "
        f"for {a['val_strides']} strides from the nominal z*, the stride map):",
        "",
        "| round | states (total) | correction rms (targets') | factor rms | held |",
        "| --- | --- | --- | --- | --- |",
    ]
    for r in curve:
        lines.append(
            f"| {r['round']} | {r['states']} ({r['total']}) | {r['correction_rms']:.3f} "
            f"({r['target_rms']:.3f}) | {r['factor_rms']:.3f} | "
            f"{r['validation_hold']}/{r['validation_n']} |"
        )
    return "\n".join(lines) + "\n"


def write_model_card(folder) -> Path:
    """`model_card` written to ``folder/MODEL_CARD.md`` (atomically)."""
    return atomic_write(Path(folder) / "MODEL_CARD.md", model_card(folder))


def train_recipe(args, sets) -> tuple[Path, Path | None]:
    """``bound-env train`` of a section with ``algo: adaptive-dagger``: the export destination
    checked first (`agents.experts.distill.check_export`), the run (`train_from_config`), then
    its policy copied to ``--export-out``. Returns (run folder, export or None)."""
    from .distill import check_export, export_folder

    refuse_ppo_options(args)
    check_export(args.export, args.force)
    run = train_from_config(
        args.config,
        args.env_id,
        args.seed,
        name=args.name,
        runs_dir=args.runs_dir,
        sets=sets,
        progress=not args.no_progress,
        resume=bool(getattr(args, "resume", False)),
    )
    return run, (export_folder(run / "policy", args.export) if args.export else None)


def cmd_train_recipe(args, sets, say, strict_json, t0) -> int:
    """``bound-env train``'s command for an ``algo: adaptive-dagger`` section (`train_recipe`),
    reporting as ``train`` does (``say``, ``strict_json`` and the start time ``t0`` are the
    command line's)."""
    import time

    run, dest = train_recipe(args, sets)
    say(
        args,
        f"run {run}  ({time.perf_counter() - t0:.0f} s)"
        + (f", exported to {dest}" if dest else ""),
    )
    if args.json:
        print(strict_json({"run": str(run), "export": str(dest) if dest else None}))
    return 0
