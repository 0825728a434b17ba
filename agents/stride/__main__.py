"""``python -m agents.stride POLICY [POLICY ...]``: the validation curve of each controller
(`agents.stride.stride_curve`) as JSON lines.

The package's ``__main__`` rather than a function of `agents.stride`: it loads controllers by
name (`agents.policy.load_controller`), and `agents.policy` sits above `agents.stride` (it loads
stride policies with `agents.stride.load_stride_policy`).
"""

from __future__ import annotations

import argparse
import json
import sys

from ..policy import load_controller
from . import VALIDATION_SEED, stride_curve


def main(argv=None) -> int:
    """``python -m agents.stride POLICY [POLICY ...]``: the validation curve as JSON lines."""
    p = argparse.ArgumentParser(prog="python -m agents.stride", description=main.__doc__)
    p.add_argument("policies", nargs="+", help="passive, lqr, a spec .yaml or a policy dir")
    p.add_argument("--n-dirs", type=int, default=64)
    p.add_argument("--seed", type=int, default=VALIDATION_SEED)
    args = p.parse_args(argv)
    for path in args.policies:
        try:
            ctrl = load_controller(path)
        except (FileNotFoundError, ValueError) as e:
            print(f"error: {e}", file=sys.stderr)
            return 2
        r = stride_curve(ctrl, n_dirs=args.n_dirs, seed=args.seed)
        print(json.dumps({"policy": str(path), **r}), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
