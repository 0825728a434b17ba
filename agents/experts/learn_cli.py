"""``bound-env distill`` and ``bound-env finetune``: their arguments, registered without
importing NumPy, numba or torch; each command imports its module when it runs."""

from __future__ import annotations

from ..common.learn_config import DistillConfig, FinetuneConfig


def _run(module: str, name: str):
    """The sub-command ``agents.experts.<module>.<name>``, imported when it runs."""

    def run(args) -> int:
        from importlib import import_module

        return getattr(import_module(f"agents.experts.{module}"), name)(args)

    return run


def register_distill(sub) -> None:
    from bound_env.commands.cli_args import add_json_arg, add_progress_args
    from bound_env.files.values import number

    p = sub.add_parser(
        "distill",
        help="distill the MPC expert into a stride controller (DAgger; runs/distill_s<seed>/)",
    )
    p.add_argument("--seed", type=number(int, 0, 2**32 - 1), default=0, help="(default: 0)")
    p.add_argument("--out", help="run folder, resumable (default: runs/distill_s<seed>)")
    p.add_argument(
        "--expert", default="mpc", help="mpc controller spec: name or .yaml (default: mpc)"
    )
    d = DistillConfig()
    p.add_argument(
        "--rounds", type=number(int, 1, 100), default=d.rounds, help="(default: %(default)s)"
    )
    p.add_argument(
        "--starts",
        type=number(int, 10, 10**6),
        default=d.starts_first,
        help="starts of round 0; later rounds take half (default: %(default)s)",
    )
    p.add_argument(
        "--epochs", type=number(int, 1, 10**4), default=d.epochs, help="(default: %(default)s)"
    )
    p.add_argument(
        "--export",
        metavar="DIR",
        help="copy the final policy there (e.g. agents/policies/distilled/s0); an existing "
        "folder is refused without --force",
    )
    p.add_argument("--force", action="store_true", help="let --export replace a folder")
    add_progress_args(p)
    add_json_arg(p)
    p.set_defaults(func=_run("distill", "cmd_distill"))


def register_finetune(sub) -> None:
    from bound_env.commands.cli_args import add_json_arg, add_progress_args
    from bound_env.files.values import number

    p = sub.add_parser(
        "finetune", help="PPO fine-tuning of a distilled stride controller (runs/finetune_s<seed>/)"
    )
    p.add_argument("--student", required=True, help="a distilled policy folder or shipped name")
    p.add_argument("--seed", type=number(int, 0, 2**32 - 1), default=0, help="(default: 0)")
    p.add_argument("--out", help="run folder, resumable (default: runs/finetune_s<seed>)")
    p.add_argument(
        "--timesteps",
        type=number(int, 1000, 10**9),
        default=FinetuneConfig.timesteps,
        help="strides of PPO, in whole rollouts of 2048; the first 10 rollouts (or all, if "
        "fewer) train the critic alone (default: %(default)s)",
    )
    p.add_argument(
        "--export",
        metavar="DIR",
        help="copy the final policy there (refused if it exists, without --force)",
    )
    p.add_argument("--force", action="store_true")
    add_progress_args(p)
    add_json_arg(p)
    p.set_defaults(func=_run("finetune", "cmd_finetune"))
