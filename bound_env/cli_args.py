"""Command-line arguments shared by the ``bound-env`` sub-commands (``--gait``, ``--set``).

Every sub-command that reads a gait file takes the same two flags, added by `add_gait_args`
and read back by `gait_from_args`; only the default gait differs per command.
"""

from __future__ import annotations


def add_gait_args(parser, default="paper"):
    """Add ``--gait NAME|PATH`` (defaulting to ``default``) and repeatable ``--set KEY=VALUE``."""
    parser.add_argument("--gait", default=default,
                        help="gait file path or name under configs/gaits/ (default: %(default)s)")
    parser.add_argument("--set", action="append", metavar="KEY=VALUE",
                        help="override a gait key, e.g. --set kc=300 --set alpha_deg=2.0")


def gait_overrides(args) -> dict:
    """The ``--set`` overrides as a dict of gait-file keys (clear errors on bad input)."""
    from .params import parse_override

    return dict(parse_override(s) for s in (getattr(args, "set", None) or []))


def gait_from_args(args):
    """The `bound_env.params.Gait` that ``--gait`` and ``--set`` name."""
    from .params import load_gait

    return load_gait(args.gait, gait_overrides(args))
