"""Peak memory of ``bound-env rollout --video``: does it grow with the run's length?

Run by hand, through the slot lock (it keeps a core busy for several minutes):
``/work/heavy .venv/bin/python benchmarks/video_memory.py [--baseline /work/main]``.

Each case is one ``agents.runtime.rollout.rollout(POLICY, strides=N, video=F.gif)`` in a fresh
process, which reports its own peak resident set size (``resource.getrusage``'s
``ru_maxrss``), its wall time, the frames written and the file's size. The cases:

- ``--strides`` (500 and 5000 by default) with the shipped frame cap
  (`agents.runtime.rollout.MAX_VIDEO_FRAMES`): the acceptance ratio, peak RSS at the longest run
  over the shortest (within 1.5x);
- the shortest run with a 10x smaller frame cap: the frames' share of the memory (streamed
  frames add nothing, so the two peaks should be close);
- with ``--baseline DIR``, the shortest run with ``DIR``'s code (e.g. main's, read-only), to
  compare the absolute peak with the code before streaming.

The machine's load (``uptime``) is printed beside the figures: wall times depend on it,
peak RSS does not.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

CHILD = r"""
import json, os, resource, sys, time
from agents.runtime import rollout as ro
policy, strides, cap, path = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
if cap > 0:
    ro.MAX_VIDEO_FRAMES = cap
t0 = time.perf_counter()
r = ro.rollout(policy, strides=strides, video=path)
wall = time.perf_counter() - t0
frames = r["steps"] // (r.get("video_every") or 1) + 1
print(json.dumps({
    "strides": r["strides"], "fell": r["fell"], "frames": frames,
    "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
    "wall_s": wall, "file_kb": os.path.getsize(path) / 1024,
}))
"""


def uptime() -> str:
    try:
        return subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()
    except OSError:
        return "uptime unavailable"


def run_case(code_root: Path, policy: str, strides: int, cap: int) -> dict:
    """One rollout with a video in a fresh process running ``code_root``'s packages."""
    with tempfile.TemporaryDirectory() as tmp:
        env = {**os.environ, "PYTHONPATH": str(code_root)}
        out = subprocess.run(
            [sys.executable, "-c", CHILD, policy, str(strides), str(cap), f"{tmp}/v.gif"],
            capture_output=True,
            text=True,
            env=env,
            cwd=tmp,
        )
    if out.returncode != 0:
        tail = (out.stderr.strip().splitlines() or ["(no output)"])[-1]
        raise SystemExit(f"video_memory: the case {strides} strides failed: {tail}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def show(label: str, r: dict) -> None:
    print(
        f"{label:<34} peak RSS {r['peak_rss_mb']:7.1f} MB  frames {r['frames']:5d}  "
        f"strides {r['strides']:5d}{' (fell)' if r['fell'] else ''}  "
        f"file {r['file_kb']:8.0f} kB  wall {r['wall_s']:6.1f} s   [{uptime()}]",
        flush=True,
    )


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--policy", default="passive", help="a policy name (default: %(default)s)")
    p.add_argument("--strides", type=int, nargs=2, default=[500, 5000], metavar=("SHORT", "LONG"))
    p.add_argument("--baseline", type=Path, help="another checkout to compare (e.g. /work/main)")
    args = p.parse_args(argv)
    from agents.runtime.rollout import MAX_VIDEO_FRAMES

    short, long = args.strides
    print(f"rollout --video, policy {args.policy}, frame cap {MAX_VIDEO_FRAMES}")
    a = run_case(ROOT, args.policy, short, 0)
    show(f"{short} strides", a)
    b = run_case(ROOT, args.policy, long, 0)
    show(f"{long} strides", b)
    c = run_case(ROOT, args.policy, short, max(1, MAX_VIDEO_FRAMES // 10))
    show(f"{short} strides, cap {max(1, MAX_VIDEO_FRAMES // 10)} frames", c)
    ratio = b["peak_rss_mb"] / a["peak_rss_mb"]
    print(f"peak RSS ratio {long}/{short} strides: {ratio:.3f} (acceptance: <= 1.5)")
    print(
        f"peak RSS ratio {a['frames']}/{c['frames']} frames: "
        f"{a['peak_rss_mb'] / c['peak_rss_mb']:.3f} (streamed: close to 1)"
    )
    if args.baseline:
        d = run_case(args.baseline.resolve(), args.policy, short, 0)
        show(f"{short} strides, {args.baseline}", d)
        print(
            f"peak RSS, this tree / baseline at {short} strides: "
            f"{a['peak_rss_mb'] / d['peak_rss_mb']:.3f}"
        )
    return 0 if ratio <= 1.5 else 1


if __name__ == "__main__":
    sys.exit(main())
