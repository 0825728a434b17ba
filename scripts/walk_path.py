"""Walk ``path`` through `agents.runtime.policy.load_controller`: the modules ("rooms") it visits.

For each shipped kind of policy (a built-in name, a choice student, a stride policy, an adaptive
student, a residual and a plain SB3 step policy) this loads the policy once (imports, compiled
kernels), then again under `sys.setprofile`, and records in call order the module of every
project function (``agents`` or ``bound_env``) called with the path among its arguments: the
name or path given (that very object), the resolved path (equal to it; with ``--strict`` any
file path inside its folder too, ``folder/config.json``), or an object holding one of those in
an attribute
(`agents.runtime.kinds.PolicyFolder`, `agents.common.policy_files.PolicyFiles`). A "stay" is a
run of such calls in one module; the rooms are the distinct modules; a return is a stay in a
module already left (stays - rooms).

    PYTHONPATH=$PWD python scripts/walk_path.py [NAME ...] [--trace] [--strict]

prints one line per policy, the largest counts, and the counts of the walks one after another
(the whole loader); ``--trace`` prints each walk's stays. With
``PYTHONPATH`` at another checkout it walks that checkout's loader (the numbers before a change).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]  # reset to the checkout of the agents imported
# one policy per kind the loader knows (agents.runtime.names.shipped_policies, the archive by path)
KINDS = {
    "lqr": "built-in name",
    "default": "choice student (alias of finetuned/s0)",
    "agents/policies/archive/distilled/s0": "choice student (distilled)",
    "adaptive/s0": "adaptive student",
    "agents/policies/archive/stride-residual/s0": "stride policy",
    "step-ppo/s0": "residual step policy",
    "ppo-v1-final/s0": "plain SB3 step policy",
}


_MODULES: dict[str, str | None] = {}


def _module_name(filename: str) -> str | None:
    if filename in _MODULES:
        return _MODULES[filename]
    try:
        rel = Path(filename).resolve().relative_to(ROOT)
        ok = rel.parts[0] in ("agents", "bound_env")
    except ValueError:
        ok = False
    name = ".".join(rel.with_suffix("").parts).removesuffix(".__init__") if ok else None
    _MODULES[filename] = name
    return name


def _holds(value, marks: tuple, depth: int = 0) -> bool:
    given, folders, strict = marks
    if value is given:
        return True
    if isinstance(value, (str, Path)):
        text = str(value)
        return any(f in text if strict else f == text for f in folders)
    if depth == 0 and value is not None and not isinstance(value, (int, float, bool)):
        fields = getattr(value, "__dict__", None)
        if fields is None and hasattr(value, "_fields"):  # a namedtuple
            fields = value._asdict()
        if isinstance(fields, dict):
            return any(_holds(v, marks, 1) for v in list(fields.values())[:20])
    return False


def walk(name: str, strict: bool = False) -> list[str]:
    """The modules of the project calls that hold ``name`` (that object) or its resolved path
    (equal to it; with ``strict`` any path inside its folder too), in call order."""
    global ROOT
    import agents
    from agents.runtime.names import resolve_policy
    from agents.runtime.policy import load_controller

    name = "".join(list(name))  # a fresh object: not the interned "default" a gait also names
    resolved = resolve_policy(name)
    folders = () if isinstance(resolved, str) else (str(resolved), str(Path(resolved).resolve()))
    marks = (name, folders, strict)
    ROOT = Path(agents.__file__).resolve().parents[1]
    seen: list[str] = []
    load_controller(name)  # imports and compiled kernels first: the walk is of the load itself

    def profile(frame, event, arg):
        if event != "call":
            return
        module = _module_name(frame.f_code.co_filename)
        if module is None:
            return
        code = frame.f_code
        args = [frame.f_locals.get(v) for v in code.co_varnames[: code.co_argcount]]
        if any(_holds(a, marks) for a in args):
            seen.append(module)

    sys.setprofile(profile)
    try:
        load_controller(name)
    finally:
        sys.setprofile(None)
    return seen


def stays(modules: list[str]) -> list[str]:
    out: list[str] = []
    for m in modules:
        if not out or out[-1] != m:
            out.append(m)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("names", nargs="*", help="policies to walk (default: one per kind)")
    ap.add_argument("--trace", action="store_true", help="print each walk's stays")
    ap.add_argument(
        "--by-room",
        action="store_true",
        help="count rooms as tests/test_layers.py does (agents.runtime, bound_env.files, ...)",
    )
    ap.add_argument(
        "--strict", action="store_true", help="count calls with any path inside the folder too"
    )
    args = ap.parse_args(argv)
    names = args.names or list(KINDS)
    worst_rooms = worst_returns = 0
    all_rooms: set[str] = set()
    everything: list[str] = []
    for name in names:
        walked = walk(name, args.strict)
        if args.by_room:
            walked = [".".join(m.split(".")[:2]) for m in walked]
        everything += walked
        walked = stays(walked)
        rooms = set(walked)
        all_rooms |= rooms
        returns = len(walked) - len(rooms)
        worst_rooms, worst_returns = max(worst_rooms, len(rooms)), max(worst_returns, returns)
        print(
            f"{name:45s} {KINDS.get(name, ''):40s} stays {len(walked):3d}  rooms "
            f"{len(rooms):2d}  returns {returns:3d}"
        )
        if args.trace:
            print("    " + " -> ".join(walked))
    whole = stays(everything)
    print(
        f"largest: {worst_rooms} rooms, {worst_returns} returns; all kinds one after another: "
        f"{len(whole)} stays in {len(all_rooms)} rooms, {len(whole) - len(all_rooms)} returns"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
