"""Model error: which plant parameters differ from the model, sensor noise and actuation delay.

A `MismatchSpec` says how a robot may differ from the model its controller was designed on:

- ``ranges``: relative half-widths delta per parameter (gait-file names, `PLANT_KEYS`): each
  robot's value is the gait's nominal value times U(1 - delta, 1 + delta), drawn
  independently per robot and parameter from a seeded `numpy.random.Generator`
  (`sample_factors`, in the order of `PLANT_KEYS`; a parameter with delta = 0 draws nothing);
- ``noise``: sensor noise per observation component, a standard deviation in units of that
  component's scale (`NOISE_SCALES`, SI: the apex scales of the task for the components of
  z, the same unit for the other continuous components); contact flags, touch flags, the
  clock and the odometer x_g are not noised;
- ``delay``: whole control intervals between the controller's decision and the torque (the
  action decided on interval k acts on interval k + delay; zero torque before the first).

Presets (`PRESETS`; join several with ``+``, e.g. ``pm5+noise+delay1``):

| name | what |
| --- | --- |
| ``pm5``, ``pm10``, ``pm20`` | m1, m2, I1, I2, kb, kf, kc, zeta, +-5/10/20 % |
| ``pm2.5``, ``pm7.5``, ``pm15`` | the same eight, +-2.5/7.5/15 % (hold against delta) |
| ``all5``, ``all10``, ``all20`` | every key of `PLANT_KEYS` (legs' rest lengths, slope too) |
| ``noise`` | sensor noise of 1 % of the scale on every noised component |
| ``noise5`` | the same at 5 % |
| ``delay1``, ``delay2`` | one, two control intervals of actuation delay |
| ``none`` | no error (the nominal plant) |

A YAML file (``--mismatch path.yaml``) has the keys ``params`` (a mapping of `PLANT_KEYS` to
delta), ``noise`` (a mapping of `NOISE_SCALES` names to sigma, or one number for all of
them), ``delay`` (an integer) and optionally ``name`` (default: the file's stem); every key
is optional, none may appear twice. A name is 1 to 64 letters, digits, ``. _ + - ( )`` and
single spaces (`bound_env.files.values.check_name`): it heads a column of the results page.
Ranges lie in [0, 1), noise in [0, `MAX_NOISE`] (one scale: more buries the signal, and
the observation sits at its bounds), the delay in [0, `MAX_DELAY`].

Several specs (``--mismatch pm5,pm10``: `parse_specs`) are split at the commas that do not
belong to an existing file's name, and must have different names (`check_distinct` names
the two sources that share one).

Every bad spec is a one-line ValueError naming the key (and the file).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..files import schema
from ..files.values import check_name
from .params import Params

# Plant parameters that may vary (gait-file names) and the `Params` field each scales.
PLANT_KEYS = ("m1", "m2", "I1", "I2", "kb", "kf", "kc", "zeta", "lb_bar", "lf_bar", "alpha_deg")
_FIELD = {k: ("alpha" if k == "alpha_deg" else k) for k in PLANT_KEYS}
EIGHT = PLANT_KEYS[:8]  # masses, inertias, leg and spine stiffness, spine damping ratio

# Scale [SI] of each observation component that sensor noise may touch: the task's apex
# scales for the components of z (`bound_env.sim.task.APEX_SCALES`), the same unit for the rest
# (ydot_g as xdot_g, leg lengths as y_g, leg angles as theta1).
NOISE_SCALES = {
    "y_g": 0.02,
    "theta1": 0.1,
    "theta2": 0.2,
    "xdot_g": 0.1,
    "ydot_g": 0.1,
    "theta1dot": 1.0,
    "theta2dot": 1.0,
    "leg_length_back": 0.02,
    "leg_angle_back": 0.1,
    "leg_length_front": 0.02,
    "leg_angle_front": 0.1,
}
MAX_DELAY = 20  # control intervals (half a stride at dt = 0.01 s)
MAX_NOISE = 1.0  # sigma in units of the scale: one apex scale of error on every reading
MAX_PLANTS = 1_000_000  # plants one call of `sample_plants` may draw


@dataclass(frozen=True)
class MismatchSpec:
    """Relative parameter ranges, sensor noise and actuation delay (module docstring)."""

    ranges: tuple = ()  # ((key, delta), ...) in the order of PLANT_KEYS
    noise: tuple = ()  # ((component, sigma in units of its scale), ...)
    delay: int = 0  # control intervals
    name: str = "custom"
    # where the spec came from (a preset's name, a file's path): named in errors, not compared
    source: str = field(default="", compare=False, repr=False)

    def __post_init__(self):
        put = object.__setattr__
        put(self, "ranges", _check_ranges(_pairs(self.ranges, "ranges")))
        put(self, "noise", _check_noise(_pairs(self.noise, "noise")))
        put(self, "delay", _check_delay(self.delay))
        put(self, "name", _check_name(self.name))
        put(self, "source", str(self.source or self.name))

    @property
    def is_nominal(self) -> bool:
        """No parameter varies, no noise, no delay."""
        return not any(d > 0 for _, d in self.ranges) and not self.has_noise and self.delay == 0

    @property
    def has_noise(self) -> bool:
        return any(s > 0 for _, s in self.noise)

    def to_dict(self) -> dict:
        """JSON-able: {"name", "params": {key: delta}, "noise": {component: sigma}, "delay"}."""
        return {
            "name": self.name,
            "params": dict(self.ranges),
            "noise": dict(self.noise),
            "delay": self.delay,
        }

    def obs_sigma(self, names) -> np.ndarray:
        """Standard deviation [SI] of the noise on each observation component ``names``."""
        noise = dict(self.noise)
        return np.array([noise.get(n, 0.0) * NOISE_SCALES.get(n, 0.0) for n in names])


def _pairs(value, key: str) -> dict:
    """{name: value} from a mapping or from (name, value) pairs; a name given twice, or anything
    else, is a ValueError naming ``key``."""
    what = f"mismatch {key} must be a mapping {{name: number}} or (name, number) pairs"
    if isinstance(value, Mapping):
        items = list(value.items())
    elif isinstance(value, (str, bytes)) or not hasattr(value, "__iter__"):
        raise ValueError(f"{what}, got {_show(value)}")
    else:
        items = list(value)
        if not all(isinstance(x, (tuple, list)) and len(x) == 2 for x in items):
            raise ValueError(f"{what}, got {_show(value)}")
    out = {}
    for k, v in items:
        if not isinstance(k, str):
            raise ValueError(f"mismatch {key}: a name must be a string, got {_show(k)}")
        if k in out:
            raise ValueError(f"mismatch {key}: {k!r} is given twice")
        out[k] = v
    return out


def _show(value) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _check_name(name) -> str:
    if not isinstance(name, str):
        raise ValueError(f"mismatch name must be a string (quote it in YAML), got {_show(name)}")
    return check_name(name, "mismatch name", spaces=True)


def _real(key: str, value) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ValueError(f"mismatch {key} must be a number, got {_show(value)}")
    try:
        v = float(value)
    except OverflowError:  # an integer beyond float's range
        v = math.inf
    if not math.isfinite(v):
        raise ValueError(f"mismatch {key} must be finite, got {value!r}")
    return v


def _check_ranges(ranges: dict) -> tuple:
    for k in ranges:
        if k not in PLANT_KEYS:
            raise ValueError(f"mismatch params: unknown parameter {k!r}; known: {PLANT_KEYS}")
    out = []
    for k in PLANT_KEYS:
        if k not in ranges:
            continue
        d = _real(f"params.{k}", ranges[k])
        if d < 0:
            raise ValueError(f"mismatch params.{k}: a range must be >= 0, got {d}")
        if d >= 1:
            raise ValueError(
                f"mismatch params.{k}: a range of {d} makes {k} non-positive (need < 1)"
            )
        out.append((k, d))
    return tuple(out)


def _check_noise(noise: dict) -> tuple:
    for k in noise:
        if k not in NOISE_SCALES:
            raise ValueError(
                f"mismatch noise: unknown observation component {k!r}; known: {tuple(NOISE_SCALES)}"
            )
    out = []
    for k in NOISE_SCALES:
        if k not in noise:
            continue
        s = _real(f"noise.{k}", noise[k])
        if s < 0:
            raise ValueError(f"mismatch noise.{k}: a standard deviation must be >= 0, got {s}")
        if s > MAX_NOISE:
            raise ValueError(
                f"mismatch noise.{k}: sigma {s:g} is beyond {MAX_NOISE:g} (in units of the "
                f"component's scale {NOISE_SCALES[k]:g}): the reading would be noise only, "
                "clipped at the observation's bounds"
            )
        out.append((k, s))
    return tuple(out)


def _check_delay(delay) -> int:
    if isinstance(delay, bool) or not isinstance(delay, (int, np.integer)):
        raise ValueError(
            f"mismatch delay must be a whole number of control intervals, got {_show(delay)}"
        )
    if not 0 <= delay <= MAX_DELAY:
        raise ValueError(f"mismatch delay must lie in [0, {MAX_DELAY}] intervals, got {delay}")
    return int(delay)


def _all(keys, delta: float) -> dict:
    return {k: delta for k in keys}


_ALL_NOISE = tuple(NOISE_SCALES)
PRESETS = {
    "none": {},
    "pm5": {"params": _all(EIGHT, 0.05)},
    "pm10": {"params": _all(EIGHT, 0.10)},
    "pm20": {"params": _all(EIGHT, 0.20)},
    "pm2.5": {"params": _all(EIGHT, 0.025)},
    "pm7.5": {"params": _all(EIGHT, 0.075)},
    "pm15": {"params": _all(EIGHT, 0.15)},
    "all5": {"params": _all(PLANT_KEYS, 0.05)},
    "all10": {"params": _all(PLANT_KEYS, 0.10)},
    "all20": {"params": _all(PLANT_KEYS, 0.20)},
    "noise": {"noise": _all(_ALL_NOISE, 0.01)},
    "noise5": {"noise": _all(_ALL_NOISE, 0.05)},
    "delay1": {"delay": 1},
    "delay2": {"delay": 2},
}
_KEYS = ("params", "noise", "delay", "name")


def presets_markdown() -> str:
    """`PRESETS` as a Markdown table: each preset's varied parameters with their relative
    range, its sensor noise (in units of each component's `NOISE_SCALES`) and its delay, as
    the code defines them (docs/yardsticks.md and docs/model-error.md print it)."""
    rows = [
        "| preset | parameters × U(1 − δ, 1 + δ) | sensor noise σ | delay |",
        "| --- | --- | --- | --- |",
    ]
    for name, p in PRESETS.items():
        params = p.get("params", {})
        deltas = sorted(set(params.values()))
        if not params:
            ptext = "none"
        elif len(deltas) == 1:
            ptext = f"{', '.join(params)}: δ = {deltas[0]:g}"
        else:
            ptext = ", ".join(f"{k}: δ = {v:g}" for k, v in params.items())
        noise = p.get("noise", {})
        sig = sorted(set(noise.values()))
        ntext = (
            "none"
            if not noise
            else f"{sig[0]:g} of the scale on {len(noise)} components"
            if len(sig) == 1
            else ", ".join(f"{k}: {v:g}" for k, v in noise.items())
        )
        dtext = f"{p['delay']} interval(s)" if p.get("delay") else "none"
        rows.append(f"| `{name}` | {ptext} | {ntext} | {dtext} |")
    return "\n".join(rows)


def from_dict(data, where: str = "mismatch", source: str = "") -> MismatchSpec:
    """A spec from the YAML form (module docstring); ``where`` names the source in errors."""
    if not isinstance(data, dict):
        raise ValueError(
            f"{where}: expected a mapping with keys {_KEYS}, got {type(data).__name__}"
        )
    unknown = sorted(set(map(str, data)) - set(_KEYS))
    if unknown:
        raise ValueError(f"{where}: unknown key(s) {unknown}; known: {_KEYS}")
    try:
        params = data.get("params")
        params = {} if params is None else params  # ``params:`` with nothing after it
        if not isinstance(params, dict):
            raise ValueError(
                f"mismatch params must be a mapping of parameter to range, got {_show(params)}"
            )
        noise = data.get("noise")
        if noise is None:
            noise = {}
        elif not isinstance(noise, dict):
            if isinstance(noise, bool) or not isinstance(noise, (int, float)):
                raise ValueError(
                    "mismatch noise must be a mapping of observation component to sigma, or "
                    f"one number for all of them, got {_show(noise)}"
                )
            noise = _all(_ALL_NOISE, _real("noise", noise))
        return MismatchSpec(
            ranges=params,
            noise=noise,
            delay=data.get("delay", 0),
            name=data.get("name", "custom"),
            source=source or where,
        )
    except ValueError as e:
        if where == "mismatch":
            raise
        raise ValueError(f"{where}: {str(e).removeprefix('mismatch ')}") from None


def combine(specs, name: str) -> MismatchSpec:
    """Several specs as one: the ranges and noise of each, the delay of the one that has one.
    Two specs that set the same parameter, noise component or a delay are a one-line
    ValueError naming both (``pm10+pm5``: which range would be meant?)."""
    ranges, noise, delay = {}, {}, 0
    owner: dict = {}  # what set each key: its spec's source
    for s in specs:
        keys = [*dict(s.ranges), *(f"noise {k}" for k in dict(s.noise))]
        keys += ["delay"] if s.delay else []
        for k in keys:
            if k in owner:
                raise ValueError(
                    f"mismatch {name!r}: {owner[k]} and {s.source} both set {k} (one range "
                    "per key: give one of them)"
                )
            owner[k] = s.source
        ranges.update(dict(s.ranges))
        noise.update(dict(s.noise))
        delay = max(delay, s.delay)
    return MismatchSpec(tuple(ranges.items()), tuple(noise.items()), delay, name, name)


def as_spec(spec) -> MismatchSpec:
    """A `MismatchSpec` from itself, a dict (the YAML form), a preset name (or several joined
    by ``+``) or a YAML file's path. None: no error."""
    if spec is None:
        return MismatchSpec(name="none")
    if isinstance(spec, MismatchSpec):
        return spec
    if isinstance(spec, dict):
        return from_dict(spec)
    if not isinstance(spec, (str, Path)):
        raise ValueError(f"mismatch must be a preset name or a YAML file, got {_show(spec)}")
    text = str(spec)
    path = Path(text)
    if _is_path(text):
        return load_spec(path)
    parts = [p.strip() for p in text.split("+")]
    for i, p in enumerate(parts):
        if p not in PRESETS:
            raise ValueError(
                f"unknown mismatch preset {_show(p)}; known: {sorted(PRESETS)} (or a .yaml file)"
            )
        if p in parts[:i]:
            raise ValueError(f"mismatch {text!r}: the preset {p!r} is given twice")
    return combine([from_dict(PRESETS[p], f"preset {p}") for p in parts], "+".join(parts))


def _is_path(text: str) -> bool:
    """Whether a spec's text names a file rather than presets: a .yaml/.yml name, something
    that exists (a folder too: `load_spec` says it is one) or anything with a path separator."""
    p = Path(text)
    return p.suffix in (".yaml", ".yml") or _on_disk(p, "exists") or "/" in text or "\\" in text


def _on_disk(p: Path, test: str) -> bool:
    """``p.exists()`` / ``p.is_file()``, False for a name the OS refuses (too long, a NUL)."""
    try:
        return bool(getattr(p, test)())
    except (OSError, ValueError):
        return False


def split_specs(text: str, flag: str = "--mismatch") -> list[str]:
    """The specs of a comma-separated list: split at every comma, except that the pieces
    whose join names an existing file stay together (``x,y.yaml`` is one file); an empty
    piece is a one-line ValueError naming ``flag``."""
    if not isinstance(text, str):
        raise ValueError(f"{flag} must be text, got {_show(text)}")
    pieces = text.split(",")
    out, i = [], 0
    while i < len(pieces):
        longest = range(len(pieces), i + 1, -1)
        j = next((j for j in longest if _on_disk(Path(",".join(pieces[i:j])), "is_file")), i + 1)
        part = ",".join(pieces[i:j]).strip()
        if not part:
            raise ValueError(
                f"{flag} {text!r}: an empty spec (give presets or YAML files separated by "
                "commas, e.g. pm5,pm10)"
            )
        out.append(part)
        i = j
    return out


def parse_specs(text: str, flag: str = "--mismatch") -> list[MismatchSpec]:
    """The specs of ``--mismatch A,B,...`` (`split_specs`, `as_spec`), checked distinct
    (`check_distinct`); a one-line ValueError naming ``flag`` otherwise."""
    try:
        specs = [as_spec(t) for t in split_specs(text, flag)]
    except ValueError as e:
        msg = str(e)
        raise ValueError(msg if msg.startswith(flag) else f"{flag}: {msg}") from None
    return check_distinct(specs, flag)


def check_distinct(specs, flag: str = "--mismatch") -> list[MismatchSpec]:
    """``specs`` if their names differ (results are keyed by name); else a one-line
    ValueError naming the two sources that share a name."""
    seen: dict[str, MismatchSpec] = {}
    for s in specs:
        other = seen.get(s.name)
        if other is not None:
            if other.source == s.source:
                raise ValueError(f"{flag} names a spec twice: {s.source!r}")
            raise ValueError(
                f"{flag}: {other.source} and {s.source} are both named {s.name!r} (results "
                "are keyed by name): give one a name: key of its own"
            )
        seen[s.name] = s
    return list(specs)


def load_spec(path) -> MismatchSpec:
    """A spec from a YAML file; a one-line ValueError naming the file otherwise."""
    path = Path(path)
    data = schema.read_yaml(path, "mismatch file")
    where = f"mismatch file {path}"
    if data is None or data == {}:
        raise ValueError(
            f"{where}: empty (give params, noise or delay; the nominal plant is the preset none)"
        )
    if isinstance(data, dict) and "name" not in data:
        try:
            check_name(path.stem, "name", spaces=True)
        except ValueError:
            raise ValueError(
                f"{where}: the file's stem {path.stem!r} is not a spec name (1 to 64 letters, "
                "digits, . _ + - ( ) and single spaces); give the spec a name: key"
            ) from None
        data = {**data, "name": path.stem}
    return from_dict(data, where, source=str(path))


# ---------------------------------------------------------------------------------------------
# Sampling plants
# ---------------------------------------------------------------------------------------------


def sample_factors(spec: MismatchSpec, rng: np.random.Generator) -> dict:
    """One robot's factors {key: U(1 - delta, 1 + delta)} in the order of `PLANT_KEYS`; a
    parameter with delta = 0 draws nothing (so a spec without ranges leaves ``rng`` as it
    is)."""
    return {k: float(rng.uniform(1.0 - d, 1.0 + d)) for k, d in spec.ranges if d > 0}


def plant_params(nominal: Params, factors: dict) -> Params:
    """The nominal parameters with each key of ``factors`` scaled (``nominal`` itself when
    there is none, so an unchanged plant is bit for bit the nominal one)."""
    if not factors:
        return nominal
    return replace(
        nominal, **{_FIELD[k]: getattr(nominal, _FIELD[k]) * f for k, f in factors.items()}
    )


def plant_values(params: Params) -> dict:
    """The `PLANT_KEYS` of ``params`` in gait-file units (``alpha_deg`` in degrees)."""
    return {
        k: float(math.degrees(params.alpha) if k == "alpha_deg" else getattr(params, k))
        for k in PLANT_KEYS
    }


def _count_and_seed(n, seed) -> tuple[int, int]:
    return (
        schema.integer(n, "sample_plants: n", 0, MAX_PLANTS),
        schema.integer(seed, "sample_plants: seed", 0),
    )


def sample_plants(spec, n: int, seed: int, gait="default") -> list[dict]:
    """Gait overrides (gait-file keys, the varied ones) of ``n`` robots' plants, robot i the
    i-th draw of ``numpy.random.default_rng(seed)`` (`sample_factors`): usable as the
    ``gait_overrides`` of PassiveBound, the stride map and the stride env."""
    from .params import load_gait

    spec = as_spec(spec)
    n, seed = _count_and_seed(n, seed)
    nominal = load_gait(gait).params
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        values = plant_values(plant_params(nominal, sample_factors(spec, rng)))
        out.append({k: values[k] for k, d in spec.ranges if d > 0})
    return out


def sample_plant_params(spec, n: int, seed: int, nominal: Params) -> list[Params]:
    """The `Params` of the plants of `sample_plants` (the same draws), without a round trip
    through gait-file units."""
    spec = as_spec(spec)
    n, seed = _count_and_seed(n, seed)
    rng = np.random.default_rng(seed)
    return [plant_params(nominal, sample_factors(spec, rng)) for _ in range(n)]
