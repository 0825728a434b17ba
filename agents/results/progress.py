"""The page's progress line (`PageProgress`): after every column's policy, what is done, its
wall and CPU time and an estimate of the time left (`bound-env compare` prints it on stderr)."""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

from .formatting import slug as _slug


class PageProgress:
    """The page's progress line (stderr), after every column's policy: how many are done,
    that one's wall and CPU time, the page's time so far and an estimate of the time left.

    The estimate: where the last run's ``columns.json`` (``previous``) has a column's time
    (`previous_seconds`: its ``seconds`` per policy), the time left is those of the policies
    still to run, scaled by how this run compares with it so far (the sum of this run's
    seconds over the last run's, for the policies done that it has); otherwise the mean time
    of a policy so far times the policies left. A policy whose every task came from the cache
    (seconds, not minutes) counts in neither; the estimate supposes the ones left compute
    theirs."""

    def __init__(self, entries, previous: Path, enabled: bool = True, stream=None):
        self.todo = [(label, pol) for label, pols, _gait in entries for pol in pols]
        self.before = previous_seconds(previous)
        self.enabled, self.stream = enabled, stream
        self.t0, self.k = time.perf_counter(), 0
        self.spent: list = []  # (seconds, the last run's or None, computed?) per policy done
        self._t = self.t0

    def start(self) -> None:
        self._t = time.perf_counter()

    def estimate_left(self) -> float | None:
        """Seconds left (module docstring), None before the first policy is done."""
        spent = [(a, b) for a, b, computed in self.spent if computed]
        if not spent:
            return None
        left = self.todo[self.k :]
        known = [(a, b) for a, b in spent if b]
        scale = sum(a for a, _ in known) / sum(b for _, b in known) if known else None
        mean = sum(a for a, _ in spent) / len(spent)
        total = 0.0
        for label, pol in left:
            prev = self.before.get((label, _slug(Path(pol).name)))
            total += prev * scale if (prev and scale is not None) else mean
        return total

    def done(self, label: str, policy: str, result: dict) -> str:
        """Count a policy done; its line (printed when enabled)."""
        now = time.perf_counter()
        prev = self.before.get((label, _slug(Path(policy).name)))
        computed = int((result.get("tasks") or {}).get("computed", 1)) > 0
        self.spent.append((now - self._t, prev, computed))
        self.k += 1
        left = self.estimate_left()
        name = label if Path(policy).name in (label, policy) else f"{label} {Path(policy).name}"
        line = (
            f"[page {self.k}/{len(self.todo)}] {name}: {now - self._t:.0f} s wall, "
            f"{float(result.get('cpu_seconds') or 0.0):.0f} s CPU in its workers; "
            f"page {now - self.t0:.0f} s so far"
            + (f", about {left:.0f} s left" if self.k < len(self.todo) and left is not None else "")
        )
        if self.enabled:
            print(line, file=self.stream or sys.stderr, flush=True)
        self._t = time.perf_counter()  # the next column starts now, unless `start` says later
        return line


def previous_seconds(path: Path) -> dict:
    """{(label, policy folder name): seconds per policy} of the last run's ``columns.json``
    (its column's ``seconds`` shared equally by its policies; a model-error column's label
    ``model error <label>``); {} without a readable one (an
    estimate only: a broken file is not an error here)."""
    try:
        data = json.loads(Path(path).read_text())
        cols = list(data.get("columns") or [])
        # the model-error section's columns, as the progress line names them
        cols += [{**c, "label": f"model error {c['label']}"} for c in data.get("model_error") or []]
        out = {}
        for c in cols:
            pols = c.get("policies") or []
            secs = float(c.get("seconds") or 0.0) / max(1, len(pols))
            for p in pols:
                out[(c["label"], _slug(Path(p).name))] = secs
        return out
    except (OSError, ValueError, TypeError, KeyError, AttributeError):
        return {}
