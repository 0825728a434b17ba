"""The ``margins`` sub-command's work (`agents.cli` registers it and parses its arguments)."""

from __future__ import annotations

from pathlib import Path

from bound_env.commands.cli_args import check_writable, strict_json

from ..runtime.policy_args import policy_label


def run_margins(args) -> int:
    """`bound-env margins`: one controller's margins (and under model error, ``--mismatch``)."""
    from bound_env.analysis.margins import summary_text

    from ..runtime.policy import load_controller
    from .margins import compute_margins  # the front: the core, with the policy's sources

    name = policy_label(args.policy)
    if args.seed != 12345:  # a held-out set: not over the test set's outputs
        name += f"-seed{args.seed}"
    out = Path(args.out or Path("out") / "margins" / name)
    check_writable(out, "--out")  # made by the run
    # a bar on a terminal, else a line every 30 s or 10 % of the tasks (bound_env.sim.parallel)
    progress = not args.no_progress
    mismatch = None
    if args.mismatch is not None:
        from bound_env.model.mismatch import parse_specs

        mismatch = parse_specs(args.mismatch)  # a bad spec fails before a policy is loaded
    ctrl = load_controller(args.policy, gait=args.gait, force=args.force, env_id=args.env_id)
    gait = args.gait or getattr(ctrl, "env_kwargs", {}).get("gait") or "default"
    r = compute_margins(
        ctrl,
        budget=args.budget,
        gait=gait,
        workers=args.workers,
        out=out,
        progress=progress,
        use_cache=not args.no_cache,
        scheduler=args.scheduler,
        seed=args.seed,
        mismatch=mismatch,
    )
    if args.json:
        print(strict_json(r))
    else:
        print(summary_text(r))
        if "mismatch" in r:
            from bound_env.analysis.margins.model_error.mismatch_report import mismatch_text

            print(mismatch_text(r["mismatch"]))
        print(f"outputs in {out}")
    return 0
