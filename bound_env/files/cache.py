"""Files for resumable jobs: settings hashes, atomic writes, append-only JSON-lines caches.

Every long job in the project (``bound-env margins``, ``reproduce``, ``continue``) keeps its
finished work here, so that a run killed at any instant (``kill -9``) resumes with nothing
lost and nothing corrupt:

- `settings_hash`: a short hash of every setting that changes a result (a cache key).
- `atomic_write`: a whole file, written to a temporary name beside it and renamed over it: the
  file is complete or it is the previous version, never half written. `atomic_path` is the
  same for a writer that wants a path (``model.save(tmp)``, an image writer).
- `append_line` / `read_lines`: append-only logs; each append is flushed and fsynced, and a
  last line cut short by a kill is skipped with a warning on reading.
- `TaskCache`: task results as JSON lines ``{"key": ..., "result": ...}`` on top of those.
- `record_section`: one section of a JSON file of measurements (``docs/timings.json``), written
  atomically beside the others, with when, where and on which commit it was measured.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import secrets
import warnings
from pathlib import Path


def settings_hash(settings, length: int = 16) -> str:
    """Hex digest (``length`` characters) of ``settings`` as canonical JSON (sorted keys)."""
    text = json.dumps(settings, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:length]


def _reserve_temp(path: Path, suffix: str) -> Path:
    """A new empty file beside ``path`` with a name no other writer holds (pid and a random
    part, created exclusively). Not `tempfile.mkstemp`: its files are private (mode 0600),
    and the renamed file would keep that mode instead of the usual one (umask)."""
    while True:
        tmp = path.with_name(f".{path.name}.{os.getpid()}-{secrets.token_hex(4)}.tmp{suffix}")
        try:
            os.close(os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666))
        except FileExistsError:
            continue
        return tmp


@contextlib.contextmanager
def atomic_path(path, suffix: str = ""):
    """A temporary path beside ``path`` to write the new file to; when the block ends without
    error the file is flushed to disk and renamed over ``path`` (`os.replace`, atomic on
    POSIX), else it is removed. ``suffix`` ends the temporary name (writers that choose their
    format by the extension: ``suffix=path.suffix``). Concurrent writers of one path each
    write their own temporary file; the last rename wins."""
    path = Path(path)
    tmp = _reserve_temp(path, suffix)
    try:
        yield tmp
        with open(tmp, "rb") as f:
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def atomic_write(path, data: str | bytes) -> Path:
    """Write ``data`` (a str is written as UTF-8) to ``path`` through `atomic_path`."""
    path = Path(path)
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        f.write(data.encode() if isinstance(data, str) else data)
    return path


def record_section(path, section: str, data: dict, command: str = "") -> dict:
    """Set ``section`` of the JSON object in ``path`` (created if absent) to ``data`` plus how
    it was measured (``measured``: UTC time, cores, the load average after, the git commit of
    the checkout, ``command``), leaving the other sections as they are; written atomically.
    Returns the section. A file that is not a JSON object is a ValueError naming it."""
    import datetime
    import platform
    import subprocess

    path = Path(path)
    body = {}
    if path.is_file():
        try:
            body = json.loads(path.read_text())
        except json.JSONDecodeError as e:
            raise ValueError(f"{path}: not JSON ({e})") from None
        if not isinstance(body, dict):
            raise ValueError(f"{path}: not a JSON object")
    try:
        commit = (
            subprocess.run(
                ["git", "rev-parse", "HEAD"], capture_output=True, text=True, timeout=10
            ).stdout.strip()
            or None
        )
    except (OSError, subprocess.SubprocessError):
        commit = None
    entry = dict(data)
    entry["measured"] = {
        "utc": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M"),
        "cores": os.cpu_count(),
        "machine": platform.machine(),
        "load_average_after": [round(v, 2) for v in os.getloadavg()],
        "commit": commit,
        "command": command,
    }
    body[section] = entry
    atomic_write(path, json.dumps(body, indent=2, sort_keys=True) + "\n")
    return entry


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
