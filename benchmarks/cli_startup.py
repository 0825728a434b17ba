"""Start-up time of the ``bound-env`` command line: ``--help`` and an argument error.

Run by hand: ``.venv/bin/python benchmarks/cli_startup.py [--rounds 5]``.

Each case runs ``python -c "from bound_env.commands.cli import main; main()" ARGS`` in a fresh
process (the console script does the same), so the time includes Python's start and every
import made before the arguments are parsed. The median wall time and the CPU time (user +
sys, which machine load affects less) of each case are printed, and the modules that parsing
imported: numba, torch, stable_baselines3 and scipy must not be among them.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time

CASES = {
    "--help": ["--help"],
    "argument error": ["margins", "--budget", "nope"],
    "sub-command --help": ["compare", "--help"],
}
HEAVY = ("numba", "torch", "stable_baselines3", "scipy", "matplotlib")
PROBE = (
    "import sys\nfrom bound_env.commands.cli import build_parser\nbuild_parser()\n"
    "print(' '.join(m for m in {heavy!r} if m in sys.modules))"
)


def run(args: list[str]) -> tuple[float, float]:
    """(wall, cpu) seconds of one CLI call in a fresh process."""
    code = "from bound_env.commands.cli import main; import sys; sys.exit(main())"
    t0 = time.perf_counter()
    before = os.times()
    subprocess.run([sys.executable, "-c", code, *args], capture_output=True, check=False)
    after = os.times()
    cpu = (after.children_user - before.children_user) + (
        after.children_system - before.children_system
    )
    return time.perf_counter() - t0, cpu


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--rounds", type=int, default=5)
    args = p.parse_args(argv)
    for name, cli_args in CASES.items():
        times = [run(cli_args) for _ in range(args.rounds)]
        wall = statistics.median(t[0] for t in times)
        cpu = statistics.median(t[1] for t in times)
        print(f"{name:20s} wall {wall:.3f} s   cpu {cpu:.3f} s   (median of {args.rounds})")
    out = subprocess.run(
        [sys.executable, "-c", PROBE.format(heavy=HEAVY)], capture_output=True, text=True
    )
    print("heavy modules imported while parsing:", out.stdout.strip() or "none")
    return 0


if __name__ == "__main__":
    sys.exit(main())
