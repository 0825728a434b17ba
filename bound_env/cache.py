"""Files for resumable jobs: settings hashes, atomic writes, append-only JSON-lines caches.

Every long job in the project (``bound-env margins``, ``reproduce``, ``continue``) keeps its
finished work here, so that a run killed at any instant (``kill -9``) resumes with nothing
lost and nothing corrupt:

- `settings_hash`: a short hash of every setting that changes a result (a cache key).
- `atomic_write`: a whole file, written to ``name.tmp`` and renamed over ``name``: the file is
  complete or it is the previous version, never half written.
- `append_line` / `read_lines`: append-only logs; each append is flushed and fsynced, and a
  last line cut short by a kill is skipped with a warning on reading.
- `TaskCache`: task results as JSON lines ``{"key": ..., "result": ...}`` on top of those.
"""

from __future__ import annotations

import hashlib
import json
import os
import warnings
from pathlib import Path


def settings_hash(settings, length: int = 16) -> str:
    """Hex digest (``length`` characters) of ``settings`` as canonical JSON (sorted keys)."""
    text = json.dumps(settings, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:length]


def atomic_write(path, data: str | bytes) -> Path:
    """Write ``data`` to ``path`` through ``path.tmp`` and `os.replace` (atomic on POSIX)."""
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    try:
        with open(tmp, "wb") as f:
            f.write(data.encode() if isinstance(data, str) else data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def append_line(path, line: str, end: str = "\n") -> None:
    """Append one line (``end`` is added) and flush it to disk before returning."""
    with open(path, "a", encoding="utf-8", newline="") as f:
        f.write(line + end)
        f.flush()
        os.fsync(f.fileno())


def read_lines(path) -> list[str]:
    """The complete lines of an append-only file (split at "\n"); [] if it is missing.

    A last line without its newline was cut short by a kill: it is skipped with a warning
    (and the file truncated to its complete lines, so that the next append starts clean).
    """
    path = Path(path)
    if not path.is_file():
        return []
    text = path.read_text(encoding="utf-8")
    lines = text.split("\n")
    tail = lines.pop()  # "" when the file ends with a newline
    if tail:
        warnings.warn(
            f"{path}: skipping a truncated last line ({len(tail)} characters; an "
            "interrupted write)",
            RuntimeWarning,
            stacklevel=2,
        )
        with open(path, "r+b") as f:
            f.truncate(len(text.encode("utf-8")) - len(tail.encode("utf-8")))
    return lines


class TaskCache:
    """Task results as JSON lines ``{"key": key, "result": result}``; None: memory only.

    Keys are strings the caller builds from a `settings_hash` of everything that changes a
    result plus the task's own arguments. A later record of a key wins. Unreadable lines are
    skipped with a warning.
    """

    def __init__(self, path: Path | None):
        self.path = None if path is None else Path(path)
        self.data: dict = {}
        if self.path is None:
            return
        for n, line in enumerate(read_lines(self.path), 1):
            try:
                rec = json.loads(line)
                self.data[rec["key"]] = rec["result"]
            except (json.JSONDecodeError, KeyError, TypeError):
                warnings.warn(
                    f"{self.path}:{n}: skipping an unreadable cache line",
                    RuntimeWarning,
                    stacklevel=2,
                )

    def __contains__(self, key) -> bool:
        return key in self.data

    def get(self, key, default=None):
        return self.data.get(key, default)

    def put(self, key: str, result) -> None:
        self.data[key] = result
        if self.path is not None:
            append_line(self.path, json.dumps({"key": key, "result": result}))
