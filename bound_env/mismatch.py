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
them), ``delay`` (an integer) and optionally ``name``; every key is optional.

Every bad spec is a one-line ValueError naming the key.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from .params import Params

# Plant parameters that may vary (gait-file names) and the `Params` field each scales.
PLANT_KEYS = ("m1", "m2", "I1", "I2", "kb", "kf", "kc", "zeta", "lb_bar", "lf_bar", "alpha_deg")
_FIELD = {k: ("alpha" if k == "alpha_deg" else k) for k in PLANT_KEYS}
EIGHT = PLANT_KEYS[:8]  # masses, inertias, leg and spine stiffness, spine damping ratio

# Scale [SI] of each observation component that sensor noise may touch: the task's apex
# scales for the components of z (`bound_env.task.APEX_SCALES`), the same unit for the rest
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


@dataclass(frozen=True)
class MismatchSpec:
    """Relative parameter ranges, sensor noise and actuation delay (module docstring)."""

    ranges: tuple = ()  # ((key, delta), ...) in the order of PLANT_KEYS
    noise: tuple = ()  # ((component, sigma in units of its scale), ...)
    delay: int = 0  # control intervals
    name: str = "custom"

    def __post_init__(self):
        put = object.__setattr__
        put(self, "ranges", _check_ranges(dict(self.ranges)))
        put(self, "noise", _check_noise(dict(self.noise)))
        put(self, "delay", _check_delay(self.delay))
        if not isinstance(self.name, str) or not self.name:
            raise ValueError(f"mismatch name must be a non-empty string, got {self.name!r}")

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


def _real(key: str, value) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ValueError(f"mismatch {key} must be a number, got {value!r}")
    v = float(value)
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
        out.append((k, s))
    return tuple(out)


def _check_delay(delay) -> int:
    if isinstance(delay, bool) or not isinstance(delay, (int, np.integer)):
        raise ValueError(
            f"mismatch delay must be a whole number of control intervals, got {delay!r}"
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


def from_dict(data, where: str = "mismatch") -> MismatchSpec:
    """A spec from the YAML form (module docstring); ``where`` names the source in errors."""
    if not isinstance(data, dict):
        raise ValueError(
            f"{where}: expected a mapping with keys {_KEYS}, got {type(data).__name__}"
        )
    unknown = sorted(set(map(str, data)) - set(_KEYS))
    if unknown:
        raise ValueError(f"{where}: unknown key(s) {unknown}; known: {_KEYS}")
    params = data.get("params") or {}
    if not isinstance(params, dict):
        raise ValueError(f"{where}: params must be a mapping of parameter to range, got {params!r}")
    noise = data.get("noise") or {}
    if not isinstance(noise, dict):
        noise = _all(_ALL_NOISE, _real("noise", noise))
    try:
        return MismatchSpec(
            ranges=tuple(params.items()),
            noise=tuple(noise.items()),
            delay=data.get("delay", 0),
            name=str(data.get("name", "custom")),
        )
    except ValueError as e:
        raise ValueError(f"{where}: {e}") from None


def combine(specs, name: str) -> MismatchSpec:
    """Several specs as one: the ranges and noise of each (a later one wins per key), the
    largest delay."""
    ranges, noise, delay = {}, {}, 0
    for s in specs:
        ranges.update(dict(s.ranges))
        noise.update(dict(s.noise))
        delay = max(delay, s.delay)
    return MismatchSpec(tuple(ranges.items()), tuple(noise.items()), delay, name)


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
        raise ValueError(f"mismatch must be a preset name or a YAML file, got {spec!r}")
    text = str(spec)
    path = Path(text)
    if path.suffix in (".yaml", ".yml") or path.is_file():
        return load_spec(path)
    parts = [p.strip() for p in text.split("+")]
    for p in parts:
        if p not in PRESETS:
            raise ValueError(
                f"unknown mismatch preset {p!r}; known: {sorted(PRESETS)} (or a .yaml file)"
            )
    return combine([from_dict(PRESETS[p], f"preset {p}") for p in parts], text)


def load_spec(path) -> MismatchSpec:
    """A spec from a YAML file; a one-line ValueError naming the file otherwise."""
    import yaml

    path = Path(path)
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ValueError(f"mismatch file {path} does not exist") from None
    except (OSError, UnicodeDecodeError) as e:
        raise ValueError(f"mismatch file {path}: cannot read it ({type(e).__name__})") from None
    except yaml.YAMLError:
        raise ValueError(f"mismatch file {path}: not valid YAML") from None
    data = {} if data is None else data
    if isinstance(data, dict) and "name" not in data:
        data = {**data, "name": path.stem}
    return from_dict(data, f"mismatch file {path}")


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


def sample_plants(spec, n: int, seed: int, gait="default") -> list[dict]:
    """Gait overrides (gait-file keys, the varied ones) of ``n`` robots' plants, robot i the
    i-th draw of ``numpy.random.default_rng(seed)`` (`sample_factors`): usable as the
    ``gait_overrides`` of PassiveBound, the stride map and the stride env."""
    from .params import load_gait

    spec = as_spec(spec)
    nominal = load_gait(gait).params
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(int(n)):
        values = plant_values(plant_params(nominal, sample_factors(spec, rng)))
        out.append({k: values[k] for k, d in spec.ranges if d > 0})
    return out


def sample_plant_params(spec, n: int, seed: int, nominal: Params) -> list[Params]:
    """The `Params` of the plants of `sample_plants` (the same draws), without a round trip
    through gait-file units."""
    spec = as_spec(spec)
    rng = np.random.default_rng(seed)
    return [plant_params(nominal, sample_factors(spec, rng)) for _ in range(int(n))]
