"""Named offsets into flat float64 arrays, each family declared once.

The compiled code reads parameters, contact state, per-robot task state and task constants from
flat arrays. A `Layout` turns one declaration, an ordered tuple of field names (with a width
where a field spans several entries), into

- a namespace of offsets, ``P.G``, ``S.T``, ... plus ``.SIZE``: a named tuple of ints, which
  Numba freezes into the compiled code like any module-level integer;
- the flat module constants ``P_G``, ``S_T``, ... and the size ``N_PARAMS``, ``N_S``, ...
  (`Layout.constants`) that the rest of the package imports.

So adding a field is one edit, and no offset is ever written by hand.
"""

from __future__ import annotations

from collections import namedtuple


class Layout:
    """Consecutive fields of a flat array. ``fields``: names, or (name, width) pairs."""

    def __init__(self, prefix: str, fields, size_name: str, start: int = 0):
        names, offsets, at = [], [], start
        for f in fields:
            name, width = (f, 1) if isinstance(f, str) else f
            if int(width) < 1:
                raise ValueError(f"field {name} of layout {prefix}* needs a positive width")
            names.append(name.upper())
            offsets.append(at)
            at += int(width)
        if len(set(names)) != len(names) or "SIZE" in names:
            raise ValueError(f"layout {prefix}*: field names must be unique and not SIZE")
        self.prefix, self.size_name = prefix, size_name
        self.names = tuple(names)
        self.start, self.size = start, at
        self.ns = namedtuple(f"{prefix.rstrip('_')}Offsets", (*names, "SIZE"))(*offsets, at)

    def constants(self) -> dict[str, int]:
        """``{prefix + NAME: offset}`` for every field, and ``{size_name: end}``."""
        out = {self.prefix + n: getattr(self.ns, n) for n in self.names}
        out[self.size_name] = self.size
        return out
