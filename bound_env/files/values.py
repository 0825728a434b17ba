"""Checks of the values a user types on a command line: numbers in a range (an argparse
``type``), and names that become file or folder names. One-line errors naming the flag.

They sit below every room that reads a command-line value (the process pool's ``--workers``,
a model-error preset's name); `bound_env.commands.cli_args` re-exports them under their old
names.
"""

from __future__ import annotations


def number(kind=float, lo=None, hi=None, lo_open=False, allow_zero=True):
    """An argparse ``type``: a finite number of ``kind`` within [lo, hi] (``lo_open``: > lo),
    so that a bad value is a one-line usage error naming the flag (exit 2)."""
    import argparse
    import math

    def parse(text):
        try:
            v = kind(text)
        except (TypeError, ValueError):
            raise argparse.ArgumentTypeError(
                f"not {'an integer' if kind is int else 'a number'}: {text!r}"
            ) from None
        if isinstance(v, float) and not math.isfinite(v):
            raise argparse.ArgumentTypeError(f"must be finite, got {text!r}")
        if lo is not None and (v < lo or (lo_open and v == lo)):
            raise argparse.ArgumentTypeError(f"must be {'>' if lo_open else '>='} {lo}, got {v}")
        if hi is not None and v > hi:
            raise argparse.ArgumentTypeError(f"must be <= {hi}, got {v}")
        if not allow_zero and v == 0:
            raise argparse.ArgumentTypeError("must not be 0")
        return v

    parse.__name__ = kind.__name__  # argparse names the type in its messages
    return parse


NAME_MAX = 64  # characters of a name that becomes a file or folder name


def check_name(name, flag: str, spaces: bool = False) -> str:
    """A name that becomes a file or folder name (a run's ``--name``, a ``compare`` column's
    label), the one check of every such name: 1 to `NAME_MAX` letters, digits and ``. _ + -``
    (with ``spaces``, a label: also single spaces inside, which `name_key` turns into ``_``,
    and parentheses, e.g. ``tiny (2 seeds)``), starting with
    a letter or digit; so never a path (``/``, ``..``), a hidden file, or a character that
    breaks a Markdown table (``|``). ValueError (one line) naming ``flag``."""
    import re

    text = str(name)
    inner = r"(?:[A-Za-z0-9._+()-]| (?! ))*" if spaces else r"[A-Za-z0-9._+-]*"
    pattern = r"[A-Za-z0-9]" + inner
    if len(text) > NAME_MAX or not re.fullmatch(pattern, text) or text.endswith(" "):
        extra = " (and, inside, single spaces and parentheses)" if spaces else ""
        allowed = "letters, digits and . _ + -" + extra
        raise ValueError(
            f"{flag} {text!r}: a name must be 1 to {NAME_MAX} characters of {allowed}, "
            "starting with a letter or digit"
        )
    return text


def name_key(name) -> str:
    """The folder a checked name (`check_name`) is written to is ``name`` with spaces as
    ``_``; two names share it, on a case-insensitive file system too, when their keys agree."""
    return str(name).replace(" ", "_").lower()


def name_type(spaces: bool = False):
    """An argparse ``type`` running `check_name` (a bad name is a usage error, exit 2)."""
    import argparse

    def parse(text):
        try:
            return check_name(text, "name", spaces)
        except ValueError as e:
            raise argparse.ArgumentTypeError(str(e).split(": ", 1)[1]) from None

    parse.__name__ = "name"
    return parse
