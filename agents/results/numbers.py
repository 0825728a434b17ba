"""Every number the docs quote of a measurement, bound to the one value of the JSON it names.

A number in ``docs/*.md`` or ``README.md`` that quotes the results page (an r50, a Δr50, an
interval, a decision time, a speed ratio, a hold count, a torque) or another committed
measurement (the page's run time, a basin map's time, an env step's time) is written between
an HTML comment naming it and its end:

```markdown
`mpc` reaches r50 <!-- n:r50ci(mpc) -->0.289 [0.254, 0.334]<!-- /n --> ...
```

The key is a quantity and its arguments, a column label first (`QUANTITIES`: e.g.
``r50(mpc)``, ``dr50ci(fine-tuned,lqr)``, ``p50ms(mpc)``, ``hold(lqr,pm5)``,
``basinmap(mpc)``). The text between the comments is what `value` makes of the JSON (the
comments do not render), so it is regenerated, never edited. A whole table or paragraph is a
block ``<!-- table:NAME -->...<!-- /table:NAME -->`` (`TABLES`: the page's model-error tables
from ``model_error.json``, the model-error presets printed from `bound_env.model.mismatch`,
compare's default columns). ``python -m agents.results.prose`` rewrites every block with the
generated sentences, ``--check`` says whether they are up to date. A number quoted for the
wrong controller, or changed in its last digit, is a stale block; tests/test_docs_numbers.py
checks every block and finds measured numbers quoted outside them.

The sources (`Sources`, each in ``docs/``): ``headline.json`` (the headline's rows),
``columns.json`` (every column of the page: its r50 and MFPT σ with their intervals, its
fingerprint; the page's run), ``paired.json`` (the paired differences and the fair decision
times), ``model_error.json`` (the page's model-error section) and ``timings.json`` (the
measured speed of the env's step and of the basin maps, `benchmarks/`).

Any other committed data file is bound by its name and a key path: ``<!-- n:data(FILE,PATH)
-->TEXT<!-- /n -->`` (or ``data(FILE,PATH,UNIT)``), FILE one of ``docs/*.json``,
``docs/*.jsonl``, ``docs/data/*.json``, ``docs/data/*.jsonl`` (relative to ``docs/``), PATH its
keys joined by dots, a list's item by its index or by ``[field=value;field=value]`` (the one
item, or JSON-lines row, whose fields have those values), e.g.
``data(data/hold_vs_delta.json,columns.mpc.rows[delta=0.1].effort_median)``. TEXT keeps the
form it is written in (`formatting.render_like`: decimals, exponent, sign; ``k/n``), UNIT
scales the value first (``ms``, ``us``, ``min``, ``pct``, ``k``).
"""

from __future__ import annotations

import json
import re
from pathlib import Path

from .formatting import ROOT, data_lookup, num3, render_like

INLINE = re.compile(r"<!-- n:(?P<key>[^>]*?) -->(?P<text>.*?)<!-- /n -->", re.S)
KEY = re.compile(r"^(?P<q>[a-z0-9_]+)\((?P<args>[^()]*)\)$")
DOCS = ROOT / "docs"
FILES = {
    "headline": "headline.json",
    "columns": "columns.json",
    "paired": "paired.json",
    "model_error": "model_error.json",
    "timings": "timings.json",
}
REGENERATE = {
    "headline": "bound-env compare --budget full --workers 2 --docs docs",
    "columns": "bound-env compare --budget full --workers 2 --docs docs",
    "paired": "bound-env compare --budget full --workers 2 --docs docs",
    "model_error": "bound-env compare --budget full --workers 2 --docs docs --mismatch pm5,pm10",
    "timings": "python benchmarks/env_step.py --json docs/timings.json; python "
    "benchmarks/basin_map.py --no-dask --also lqr,default,mpc --json docs/timings.json",
}


class Sources:
    """The committed JSON files, read once each; a missing file or key is a ValueError of one
    line naming the file, the key and the command that writes it."""

    def __init__(self, docs: Path = DOCS):
        self.docs = Path(docs)
        self._cache: dict = {}

    def _load(self, name: str) -> dict:
        if name not in self._cache:
            path = self.docs / FILES[name]
            if not path.is_file():
                raise ValueError(f"{path}: missing (written by `{REGENERATE[name]}`)")
            try:
                data = json.loads(path.read_text())
            except (OSError, json.JSONDecodeError) as e:
                raise ValueError(f"{path}: not JSON ({e})") from None
            if not isinstance(data, dict):
                raise ValueError(f"{path}: not a JSON object")
            self._cache[name] = data
        return self._cache[name]

    def _fail(self, name: str, key: str):
        raise ValueError(f"{self.docs / FILES[name]}: {key}: missing")

    def column(self, label: str) -> dict:
        """The page's column ``label`` (``columns.json``)."""
        for col in self._load("columns").get("columns") or []:
            if col.get("label") == label:
                return col
        self._fail("columns", f"columns[label={label!r}]")

    def measure(self, label: str, key: str) -> dict:
        """A column's measure (value, low, high): the headline's row's when the headline has
        it (``headline.json``, the README's table), else the page's column's
        (``columns.json``); both are written by one run of `agents.results.compare`."""
        for row in self._load("headline").get("rows") or []:
            if row.get("label") == label and isinstance(row.get(key), dict):
                m = row[key]
                break
        else:
            m = self.column(label).get(key)
        if not isinstance(m, dict) or m.get("value") is None:
            self._fail("columns", f"columns[label={label!r}].{key}")
        return m

    def pair(self, column: str, reference: str) -> dict:
        for e in self._load("paired").get("pairs") or []:
            if e.get("column") == column and e.get("reference") == reference and "skipped" not in e:
                return e["delta_r50"]
        self._fail("paired", f"pairs[{column} vs {reference}]")

    def times(self, label: str) -> dict:
        ctrls = (self._load("paired").get("decision_times") or {}).get("controllers") or {}
        if label not in ctrls:
            self._fail("paired", f"decision_times.controllers.{label}")
        return ctrls[label]

    def run(self) -> dict:
        r = self._load("columns").get("run")
        if not isinstance(r, dict):
            self._fail("columns", "run")
        return r

    def model_error(self, label: str, spec: str) -> dict:
        """A column's row of the model-error section under ``spec`` (``model_error.json``:
        hold, torque, r50 and, paired with the reference, delta_r50)."""
        for e in self._load("model_error").get("specs") or []:
            if e.get("name") == spec:
                for row in e.get("rows") or []:
                    if row.get("column") == label:
                        return row
        self._fail("model_error", f"specs[name={spec!r}].rows[column={label!r}]")

    def model_error_pair(self, label: str, spec: str) -> dict:
        d = self.model_error(label, spec).get("delta_r50")
        if not isinstance(d, dict):
            self._fail("model_error", f"specs[name={spec!r}].rows[column={label!r}].delta_r50")
        return d

    def data(self, name: str):
        """``docs/NAME`` (`DATA_FILE`): its JSON, or for JSON lines the list of its rows."""
        if not DATA_FILE.match(name):
            raise ValueError(f"{name}: not a data file of docs/ (docs/[data/]NAME.json[l])")
        key = f"data:{name}"
        if key not in self._cache:
            path = self.docs / name
            try:
                text = path.read_text()
                if name.endswith(".jsonl"):
                    data = [json.loads(line) for line in text.splitlines() if line.strip()]
                else:
                    data = json.loads(text)
            except FileNotFoundError:
                raise ValueError(f"{path}: missing") from None
            except (OSError, json.JSONDecodeError) as e:
                raise ValueError(f"{path}: not JSON ({e})") from None
            self._cache[key] = data
        return self._cache[key]

    def timing(self, section: str, *keys: str) -> float:
        t = self._load("timings").get(section)
        for k in keys:
            if isinstance(t, list) and k.isdigit() and int(k) < len(t):
                t = t[int(k)]
            else:
                t = t.get(k) if isinstance(t, dict) else None
        if not isinstance(t, (int, float)) or isinstance(t, bool):
            self._fail("timings", ".".join((section, *keys)))
        return float(t)


DATA_FILE = re.compile(r"^(?:data/)?[A-Za-z0-9_.-]+\.jsonl?$")


def _data(s: Sources, name: str, path: str, unit: str = "", text: str = "") -> str:
    try:
        return render_like(data_lookup(s.data(name), path), text, unit)
    except (KeyError, TypeError) as e:
        raise ValueError(f"docs/{name}: {e.args[0]}") from None


HOLD_EVAL_SEEDS = (2026, 2027, 2028)  # scripts/hold_eval.py's test seeds, pooled


def _hold_eval_rows(s: Sources, policy: str | None, delta: str, seed: str = "test") -> list:
    """The rows of ``policy`` (None: every policy) at ``delta`` on ``seed``, or on the test
    seeds (``test``: each seed's, pooled)."""
    seeds = HOLD_EVAL_SEEDS if seed == "test" else (int(seed),)
    rows = [
        r
        for r in s.data("hold_eval.jsonl")
        if policy in (None, r.get("policy")) and r.get("delta") == float(delta)
        and not r.get("set") and r.get("measure") == "mm_hold" and r.get("seed") in seeds
    ]  # fmt: skip
    if policy is not None and sorted(r["seed"] for r in rows) != sorted(seeds):
        raise KeyError(f"hold_eval.jsonl: [policy={policy};delta={delta}] on {seeds}")
    return rows


def _held(rows: list[dict]) -> tuple[int, int]:
    return sum(sum(map(bool, r["held"])) for r in rows), sum(len(r["held"]) for r in rows)


def _held_effort(s: Sources, policy: str, delta: str) -> list[float]:
    """The tail |τ| of each plant ``policy`` holds at ``delta``, the test seeds pooled."""
    rows = _hold_eval_rows(s, policy, delta)
    return [e for r in rows for e, h in zip(r["tail_effort"], r["held"], strict=True) if h]


def _hold_eval_torque(s: Sources, policy: str, delta: str) -> str:
    import numpy as np

    return f"{float(np.median(_held_effort(s, policy, delta))):.2g}"


def _hold_eval_best(s: Sources, policy: str, delta: str, seed: str) -> str:
    """``k/n`` of one row; a ValueError naming a row of a test seed that holds more."""
    k, n = _held(_hold_eval_rows(s, policy, delta, seed))
    for r in _hold_eval_rows(s, None, delta):
        if _held([r])[0] * n > k * len(r["held"]):
            raise ValueError(
                f"hold_eval.jsonl: not the best at {delta}: {r['policy']} on seed "
                f"{r['seed']} holds {'/'.join(map(str, _held([r])))}"
            )
    return f"{k}/{n}"


def _hold_eval_table(s: Sources) -> str:
    """``scripts/hold_eval.py --table 2026 2027 2028`` of ``docs/hold_eval.jsonl``."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("hold_eval", ROOT / "scripts/hold_eval.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return "\n\n" + mod.table(s.docs / "hold_eval.jsonl", list(HOLD_EVAL_SEEDS)) + "\n\n"


def _interval(m: dict, fmt=num3) -> str:
    return f"{fmt(m['value'])} [{fmt(m['low'])}, {fmt(m['high'])}]"


def _signed(v: float) -> str:
    return f"{v:+.2g}".replace("-", "−")


def _unsigned(v: float) -> str:
    return f"{v:.2g}"


def _ms(seconds: float) -> str:
    return f"{1e3 * seconds:.3g}"


def _us(seconds: float) -> str:
    return f"{1e6 * seconds:.2g}"


def _ratio(r: float) -> str:
    return f"{r:.0f}" if r >= 10 else f"{r:.2g}"


def _seconds(s: float) -> str:
    return f"{s:.2g}" if s < 10 else f"{s:.0f}"


def _hold(b: dict) -> str:
    h = b["hold"]
    return f"{h['k']}/{h['n']}"


def _hold_ci(b: dict) -> str:
    h = b["hold"]
    return f"{h['k']}/{h['n']} [{h['low']:.2f}, {h['high']:.2f}]"


def _torque(b: dict) -> str:
    t = b.get("torque") or {}
    if t.get("median") is None:
        raise KeyError("torque.median (no held plant)")
    return f"{t['median']:.3g}"


# quantity: (number of arguments, what it is, its text from `Sources` and the arguments)
QUANTITIES = {
    "r50": (1, "a column's r50", lambda s, c: num3(s.measure(c, "r50")["value"])),
    "r50ci": (1, "r50 [95 % interval]", lambda s, c: _interval(s.measure(c, "r50"))),
    "mfpt100": (
        1,
        "the σ (deg) where the MFPT falls to 100 strides",
        lambda s, c: num3(s.measure(c, "mfpt_sigma_100_deg")["value"]),
    ),
    "mfpt100ci": (
        1,
        "that σ [95 % interval]",
        lambda s, c: _interval(s.measure(c, "mfpt_sigma_100_deg")),
    ),
    "sigma50": (
        1,
        "the σ (deg) at which rough-terrain survival falls below one half",
        lambda s, c: num3(s.measure(c, "terrain_sigma50_deg")["value"]),
    ),
    "colmin": (
        1,
        "the wall time of a column in the page's run [min] (all its seeds)",
        lambda s, c: f"{s.column(c)['seconds'] / 60:.1f}",
    ),
    "dr50": (
        2,
        "Δr50 of a column against a reference",
        lambda s, c, r: _signed(s.pair(c, r)["delta"]),
    ),
    "dr50ci": (
        2,
        "Δr50 [95 % bootstrap interval]",
        lambda s, c, r: (
            f"{_signed(s.pair(c, r)['delta'])} "
            f"[{_signed(s.pair(c, r)['low'])}, {_signed(s.pair(c, r)['high'])}]"
        ),
    ),
    "dr50below": (
        2,
        "how far a column stays below a reference in r50 [95 % interval]",
        lambda s, c, r: (
            f"{_unsigned(-s.pair(c, r)['delta'])} "
            f"[{_unsigned(-s.pair(c, r)['high'])}, {_unsigned(-s.pair(c, r)['low'])}]"
        ),
    ),
    "p50ms": (1, "decision time at the median [ms]", lambda s, c: _ms(s.times(c)["p50"])),
    "p99ms": (1, "decision time at the 99th percentile [ms]", lambda s, c: _ms(s.times(c)["p99"])),
    "meanms": (1, "mean decision time [ms]", lambda s, c: _ms(s.times(c)["mean"])),
    "p50us": (1, "decision time at the median [µs]", lambda s, c: _us(s.times(c)["p50"])),
    "speedup": (
        2,
        "how many times faster a column decides than another, at the median",
        lambda s, c, r: _ratio(s.times(r)["p50"] / s.times(c)["p50"]),
    ),
    "speedupmean": (
        2,
        "the same, on average",
        lambda s, c, r: _ratio(s.times(r)["mean"] / s.times(c)["mean"]),
    ),
    "hold": (2, "plants held under a model-error spec", lambda s, c, m: _hold(s.model_error(c, m))),
    "holdci": (
        2,
        "plants held [95 % Wilson interval]",
        lambda s, c, m: _hold_ci(s.model_error(c, m)),
    ),
    "torque": (
        2,
        "median mean |τ| on the held plants [N m]",
        lambda s, c, m: _torque(s.model_error(c, m)),
    ),
    "r50mm": (
        2,
        "r50 under model error",
        lambda s, c, m: num3(s.model_error(c, m)["r50"]["value"] or 0.0),
    ),
    "dr50mm": (
        2,
        "Δr50 under model error against the section's reference [95 % interval]",
        lambda s, c, m: (
            f"{_signed(s.model_error_pair(c, m)['delta'])} "
            f"[{_signed(s.model_error_pair(c, m)['low'])}, "
            f"{_signed(s.model_error_pair(c, m)['high'])}]"
        ),
    ),
    "holdevaltorque": (
        2,
        "median mean |τ| of the held plants, scripts/hold_eval.py's test seeds pooled [N m]",
        _hold_eval_torque,
    ),
    "holdevalk": (
        3,
        "plants held by a row of docs/hold_eval.jsonl (POLICY,DELTA,SEED; `test`: pooled)",
        lambda s, p, d, seed: str(_held(_hold_eval_rows(s, p, d, seed))[0]),
    ),
    "holdevalbest": (
        3,
        "plants held k/n by one row (POLICY,DELTA,SEED), checked to be the most of a test seed",
        _hold_eval_best,
    ),
    "holdevalbelow": (
        3,
        "held plants whose tail |τ| is below LEVEL N m (POLICY,DELTA,LEVEL), test seeds pooled",
        lambda s, p, d, level: str(sum(e < float(level) for e in _held_effort(s, p, d))),
    ),
    "pagemin": (0, "the page's wall time [min]", lambda s: f"{s.run()['wall_seconds'] / 60:.1f}"),
    "pageworkers": (0, "the page run's workers", lambda s: str(s.run()["workers"])),
    "basinmap": (
        1,
        "a 64 × 64 basin map's wall time [s], pool of 2",
        lambda s, c: _seconds(s.timing("basin_map", "seconds", c)),
    ),
    "load": (
        1,
        "the machine's load average (1 min) when a timing of docs/timings.json began",
        lambda s, sec: f"{s.timing(sec, 'load_average_before', '0'):.1f}",
    ),
    "stepus": (
        0,
        "one step of PassiveBound-v0 [µs]",
        lambda s: f"{1e6 / s.timing('env_step', 'steps_per_s', 'PassiveBound-v0'):.2g}",
    ),
    "envkps": (
        1,
        "steps per second of an env (an id, or a vector env's key) [thousands]",
        lambda s, k: f"{s.timing('env_step', 'steps_per_s', k) / 1e3:.0f}",
    ),
    "envratio": (
        1,
        "the same, against Pendulum-v1's single env",
        lambda s, k: _ratio(
            s.timing("env_step", "steps_per_s", k)
            / s.timing("env_step", "steps_per_s", "Pendulum-v1")
        ),
    ),
}


TABLE = re.compile(
    r"<!-- table:(?P<name>[a-z0-9-]+) -->(?P<text>.*?)<!-- /table:(?P=name) -->", re.S
)


def _model_error_run(s: Sources) -> str:
    me = s._load("model_error")
    run = me.get("run") or {}
    cols = ", ".join(f"`{c['label']}`" for c in me.get("columns") or [])
    specs = ",".join(e["name"] for e in me.get("specs") or [])
    wall = run.get("wall_seconds")
    load = (run.get("load_average_before") or ["?"])[0]
    seed = me.get("seed")
    role = "the test set: nothing was chosen on it" if seed == 12345 else "a held-out seed"
    return (
        f"\n\n**How these numbers were made.** One run of `compare --mismatch {specs}` on the "
        f"**{me.get('budget')}** budget with the seed {seed} ({role}), columns {cols}, "
        f"paired against `{me.get('reference')}`"
        + (
            f"; {wall / 60:.1f} min of wall time with {run.get('workers')} worker(s), load "
            f"average {load} before, at commit {(run.get('commit') or '?')[:12]}"
            if isinstance(wall, (int, float))
            else ""
        )
        + f" (`docs/{FILES['model_error']}`; the command: `{run.get('command') or '?'}`).\n\n"
    )


def _model_error_tables(s: Sources) -> str:
    from bound_env.analysis.margins.model_error.mismatch_report import mismatch_tables

    me = s._load("model_error")
    try:
        return "\n\n" + mismatch_tables(me, level=3) + "\n"
    except (KeyError, TypeError, IndexError) as e:
        raise ValueError(f"{s.docs / FILES['model_error']}: malformed ({e!r})") from None


def _presets(_s: Sources) -> str:
    from bound_env.model.mismatch import presets_markdown

    return "\n\n" + presets_markdown() + "\n\n"


def _default_columns(_s: Sources) -> str:
    from .compare import default_entries

    return ", ".join(
        f"`{label}`" + (f" ({len(p)} seeds)" if len(p) > 1 else "")
        for label, p, _gait in default_entries()
    )


# generated tables and text between <!-- table:NAME --> and <!-- /table:NAME -->
TABLES = {
    "compare-default-columns": _default_columns,  # compare's default columns, from the code
    "mismatch-presets": _presets,  # bound_env.model.mismatch.PRESETS, from the code
    "model-error-run": _model_error_run,  # how model_error.json was made
    "model-error": _model_error_tables,  # the page's model-error section, from its JSON
    "hold-eval": _hold_eval_table,  # scripts/hold_eval.py's table of docs/hold_eval.jsonl
}


NOT_FINITE = re.compile(r"(?<![A-Za-z])(?:nan|inf|-inf|Infinity|NaN)(?![A-Za-z])")


def parse_key(key: str) -> tuple[str, list[str]]:
    """(quantity, arguments) of a block's key; a ValueError naming the key otherwise."""
    m = KEY.match(key.strip())
    if m and m.group("q") == "data":  # data(FILE,PATH[,UNIT]): bound to a named data file
        args = [a.strip() for a in m.group("args").split(",")]
        if len(args) not in (2, 3) or not DATA_FILE.match(args[0]) or not args[1]:
            raise ValueError(f"<!-- n:{key} -->: data takes (FILE,PATH[,UNIT]), FILE in docs/")
        return "data", args
    if not m or m.group("q") not in QUANTITIES:
        raise ValueError(
            f"<!-- n:{key} -->: not a quantity (data, {', '.join(sorted(QUANTITIES))})"
        )
    args = [a.strip() for a in m.group("args").split(",")] if m.group("args").strip() else []
    if len(args) != QUANTITIES[m.group("q")][0]:
        raise ValueError(
            f"<!-- n:{key} -->: {m.group('q')} takes {QUANTITIES[m.group('q')][0]} argument(s)"
        )
    return m.group("q"), args


def value(key: str, sources: Sources, text: str = "") -> str:
    """The text of the block ``key`` from ``sources`` (a ValueError naming what is missing);
    a ``data`` block's in the form of its ``text``."""
    q, args = parse_key(key)
    try:
        if q == "data":
            text = _data(sources, *args, text=text)
        else:
            text = QUANTITIES[q][2](sources, *args)
    except ValueError as e:
        raise ValueError(f"<!-- n:{key} -->: {e}") from None
    except (KeyError, TypeError, ZeroDivisionError, AttributeError, IndexError) as e:
        raise ValueError(f"<!-- n:{key} -->: a malformed value in the JSON ({e!r})") from None
    if "nan" in text or "inf" in text:
        raise ValueError(f"<!-- n:{key} -->: not a finite number ({text})")
    return text


def table(name: str, sources: Sources) -> str:
    """The text of the table block ``name`` (`TABLES`)."""
    if name not in TABLES:
        raise ValueError(f"<!-- table:{name} -->: no such table ({', '.join(TABLES)})")
    text = TABLES[name](sources)
    bad = NOT_FINITE.search(text)
    if bad:
        raise ValueError(f"<!-- table:{name} -->: not a finite number ({bad.group(0)!r})")
    return text


# The two kinds of block a page holds, each read the same way: kind -> (its pattern, its value
# from the sources, its markers around the value, what `stale_blocks` says where its text is
# not its value)
BLOCKS = {
    "inline": (
        INLINE,
        lambda m, sources: value(m.group("key"), sources, m.group("text")),
        lambda m: (f"<!-- n:{m.group('key')} -->", "<!-- /n -->"),
        lambda m, v: f"n:{m.group('key')}: {m.group('text')!r}, its source says {v!r}",
    ),
    "table": (
        TABLE,
        lambda m, sources: table(m.group("name"), sources),
        lambda m: (f"<!-- table:{m.group('name')} -->", f"<!-- /table:{m.group('name')} -->"),
        lambda m, v: f"table:{m.group('name')}: not the table its source gives",
    ),
}


def update_text(text: str, sources: Sources, where: str = "", errors: list | None = None) -> str:
    """``text`` with every inline block and every table block rewritten from ``sources``. A
    block without a value is a ValueError naming it, or, with ``errors`` (a list), is left as
    it is and its error appended there."""

    def fill(m: re.Match, kind: str) -> str:
        _, make, ends, _ = BLOCKS[kind]
        try:
            v = make(m, sources)
        except ValueError as e:
            if errors is None:
                raise ValueError(f"{where}: {e}") from None
            errors.append(f"{where}: {e}")
            return m.group(0)
        head, tail = ends(m)
        return f"{head}{v}{tail}"

    for kind in ("inline", "table"):
        text = BLOCKS[kind][0].sub(lambda m, k=kind: fill(m, k), text)
    return text


def stale_blocks(text: str, sources: Sources) -> list[str]:
    """Each block whose text is not its value: ``KEY: 'TEXT', the JSON says 'VALUE'`` (or
    why it has no value); the tables first."""
    out = []
    for kind in ("table", "inline"):
        pattern, make, _, differs = BLOCKS[kind]
        for m in pattern.finditer(text):
            try:
                v = make(m, sources)
            except ValueError as e:
                out.append(str(e))
                continue
            if v != m.group("text"):
                out.append(differs(m, v))
    return out
