"""Command-line arguments shared by the ``bound-env`` sub-commands (``--gait``, ``--set``,
``--no-progress``) and the output conventions they share (strict JSON, ``--out`` folders).

Every sub-command that reads a gait file takes the same two flags, added by `add_gait_args`
and read back by `gait_from_args`; only the default gait differs per command.
"""

from __future__ import annotations

import json

from ..files.values import (  # noqa: F401 - importable from here too
    NAME_MAX,
    check_name,
    name_key,
    name_type,
    number,
)

# ``--gait`` help of the commands that run a policy: the policy's own gait unless told.
POLICY_GAIT_HELP = "gait name or path (default: the policy's own, else 'default')"


def add_gait_args(parser, default="paper", overrides=True, help=None):
    """Add ``--gait NAME|PATH`` (defaulting to ``default``) and, if ``overrides``, repeatable
    ``--set KEY=VALUE``. Every sub-command's ``--gait`` comes from here."""
    parser.add_argument(
        "--gait",
        default=default,
        help=help or "gait file path or name under configs/gaits/ (default: %(default)s)",
    )
    if overrides:
        parser.add_argument(
            "--set",
            action="append",
            metavar="KEY=VALUE",
            help="override a gait key, e.g. --set kc=300 --set alpha_deg=2.0",
        )


def gait_overrides(args) -> dict:
    """The ``--set`` overrides as a dict of gait-file keys (clear errors on bad input)."""
    from ..model.params import parse_override

    return dict(parse_override(s) for s in (getattr(args, "set", None) or []))


def gait_from_args(args):
    """The `bound_env.model.params.Gait` that ``--gait`` and ``--set`` name."""
    from ..model.params import load_gait

    return load_gait(args.gait, gait_overrides(args))


def add_progress_args(parser):
    """``--no-progress`` (alias ``--quiet``): silence progress bars and progress lines."""
    parser.add_argument(
        "--no-progress",
        "--quiet",
        dest="no_progress",
        action="store_true",
        help="no progress output (alias: --quiet)",
    )


def add_json_arg(parser, what="a JSON summary"):
    """``--json``: print ``what`` on stdout as strict JSON (`strict_json`); the human-readable
    lines then go to stderr."""
    parser.add_argument("--json", action="store_true", help=f"print {what} (strict JSON)")


def say(args, *parts) -> None:
    """A human-readable line: stdout, or stderr under ``--json`` (stdout is then JSON only)."""
    import sys

    print(*parts, file=sys.stderr if getattr(args, "json", False) else sys.stdout)


def strict_json(obj, indent: int | None = None) -> str:
    """JSON text with no NaN/Infinity tokens: a non-finite number becomes null, and its path is
    listed under ``"nonfinite"`` (the reason: "nan", "inf" or "-inf")."""
    import math

    reasons: dict[str, str] = {}

    def clean(v, path):
        if isinstance(v, float) and not math.isfinite(v):
            reasons[path or "."] = "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf")
            return None
        if isinstance(v, dict):
            return {k: clean(x, f"{path}.{k}" if path else str(k)) for k, x in v.items()}
        if isinstance(v, (list, tuple)):
            return [clean(x, f"{path}[{i}]") for i, x in enumerate(v)]
        if hasattr(v, "tolist") and not isinstance(v, (str, bytes)):  # numpy scalars/arrays
            return clean(v.tolist(), path)
        return v

    out = clean(obj, "")
    if reasons and isinstance(out, dict):
        out["nonfinite"] = {**(out.get("nonfinite") or {}), **reasons}
    return json.dumps(out, allow_nan=False, default=str, indent=indent)  # paths as text


def out_dir(path, flag: str = "--out"):
    """``path`` as a folder, created with its parents; ValueError (one line) when a file is
    in the way."""
    from pathlib import Path

    p = Path(path)
    for q in (p, *p.parents):
        if q.exists() and not q.is_dir():
            raise ValueError(f"{flag} {path}: {q} exists and is not a folder")
    p.mkdir(parents=True, exist_ok=True)
    return p


def check_writable(path, flag: str, folder: bool = True) -> None:
    """ValueError (one line, naming ``flag``) unless ``path`` could be created or replaced:
    no file in the way of its folders (nor at ``path`` itself, a ``folder``), and a file can
    be made in the nearest existing one (a probe, removed at once: permission bits do not tell
    root about a read-only mount). A command checks its outputs so before its work starts."""
    import os
    import tempfile
    from pathlib import Path

    p = Path(path).absolute()
    for q in (p, *p.parents):
        if not q.exists():
            continue
        if not q.is_dir():
            if q == p and not folder:  # a file to replace: its folder must take a new one
                continue
            raise ValueError(f"{flag} {path}: {q} exists and is not a folder")
        try:
            fd, probe = tempfile.mkstemp(dir=q, prefix=".write-probe-")
        except OSError as e:
            raise ValueError(f"{flag} {path}: cannot write in {q} ({e.strerror})") from None
        os.close(fd)
        os.unlink(probe)
        return
