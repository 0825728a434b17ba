"""Controller spec files: small YAML files under ``configs/controllers/``.

A spec names the controller and its design settings, e.g. ``configs/controllers/lqr.yaml``:

```yaml
controller: lqr      # lqr | deadbeat | damping
basis: windows       # torque basis of the stride (bound_env.sim.stride_task.BASES)
K: 6                 # number of basis functions
Q: 1.0               # weight(s) on the normalized apex error (z - z*)/s: a number or 6
R: 1.0               # weight(s) on the coefficients u: a number or K
max_torque: 80.0     # saturation [N m]
```

Every key (`SPEC_KEYS`) has a default; a key the controller does not use, or an unknown one,
is an error naming the file and the key.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from ..files import schema
from ..files.resources import controllers_dir, parse_yaml

# the repository's configs/controllers, or the wheel's copy (package data,
# bound_env.files.resources)
CONTROLLERS_DIR = controllers_dir()
KINDS = ("lqr", "deadbeat", "damping", "mpc")
COMMON_KEYS = ("controller", "gait", "max_torque", "dt")
# the search settings of an mpc spec and their defaults (bound_env.control.mpc.MPCController)
MPC_DEFAULTS = {
    "safe": 0.05,
    "horizon": 12,
    "n_random": 24,
    "n_noise": 24,
    "noise": 0.5,
    "cem_iters": 2,
    "cem_samples": 24,
    "cem_elites": 6,
    "plan_rtol": 1e-8,
    "seed": 0,
    "library_seed": -1,
    "early_exit": False,  # the search's shortcuts (bound_env.control.mpc): off, the full search
    "screen": 0,
    "hopeless": 0.75,
}
MPC_BOOLS = ("early_exit",)
MPC_INTS = ("horizon", "n_random", "n_noise", "cem_iters", "cem_samples", "cem_elites", "seed")
MPC_INTS += ("library_seed", "screen")
# the range of each search setting (bounded work per decision): (lo, hi), reals in (lo, hi]
MPC_LIMITS = {
    "safe": (0.0, 100.0),  # normalized apex error
    "horizon": (1, 1000),  # strides
    "n_random": (0, 10_000),
    "n_noise": (0, 10_000),
    "noise": (0.0, 100.0),
    "cem_iters": (0, 100),
    "cem_samples": (0, 10_000),
    "cem_elites": (1, 10_000),
    "plan_rtol": (0.0, 1e-2),
    "seed": (0, 2**32 - 1),
    "library_seed": (-1, 2**32 - 1),
    "screen": (0, 10_000),
    "hopeless": (0.0, 1.0),
}
MAX_TORQUE_LIMIT = 1e4  # [N m]: a saturation above this is certainly a mistake
# |gain| entries in units of the torque limit per apex scale (u = -G_n S dz; the shipped
# designs are ~1): beyond it an error of a millionth of a scale saturates the torque, and
# the closed loop's matrix A - B G overflows
MAX_GAIN = 1e6
SPEC_KEYS = {
    "lqr": COMMON_KEYS + ("basis", "K", "Q", "R", "jacobian", "gain", "offset_free"),
    "deadbeat": COMMON_KEYS + ("basis", "K", "jacobian", "gain", "offset_free"),
    "damping": COMMON_KEYS + ("c",),
    # the MPC's terminal controller is an LQR (its keys), plus the search (bound_env.control.mpc)
    "mpc": COMMON_KEYS
    + ("basis", "K", "Q", "R", "jacobian", "gain", "offset_free", "privileged", "adaptive")
    + tuple(MPC_DEFAULTS),
}
DEFAULT_MAX_TORQUE = 80.0  # [N m]: the saturation of the learned policies
DEFAULT_DT = 0.01  # control interval of the step env [s]


@dataclass
class ControllerSpec:
    """A parsed spec (see the module docstring)."""

    controller: str
    path: Path | None = None
    gait: str = "default"
    max_torque: float = DEFAULT_MAX_TORQUE
    dt: float = DEFAULT_DT
    basis: str = "windows"
    K: int | None = 4
    Q: object = 1.0
    R: object = 1.0
    jacobian: str = "fd"
    gain: object = None  # an explicit gain (K x 6, SI): a nested list or a file
    c: float = 0.0  # damping [N m s/rad]
    extra: dict = field(default_factory=dict)
    # None, or the settings of `bound_env.control.offset_free.OffsetFree` (checked): the
    # controller held on the plant's own cycle
    offset_free: object = None
    # an mpc re-designed on the robot's true plant (`bound_env.control.privileged`): an upper
    # reference, never a shipped or deployable policy
    privileged: bool = False
    # None, or the settings of `bound_env.control.adaptive.AdaptiveMPC` (checked): an mpc that
    # identifies its plant online and re-designs on the estimate
    adaptive: object = None

    @property
    def name(self) -> str:
        return self.path.stem if self.path is not None else self.controller


def resolve_spec_path(spec: str | Path) -> Path:
    """A path to a YAML file, or a name under ``configs/controllers/`` (``"lqr"``)."""
    if not isinstance(spec, (str, Path)) or not str(spec):
        raise TypeError(
            f"controller must be a name (lqr, deadbeat, mpc, damping) or a spec file's path, "
            f"got {spec!r} ({type(spec).__name__})"
        )
    p = Path(spec)
    if p.suffix in (".yaml", ".yml"):
        if not p.is_file():
            raise FileNotFoundError(f"controller spec {str(spec)!r} does not exist")
        return p
    cand = CONTROLLERS_DIR / f"{spec}.yaml"
    if not cand.is_file():
        known = sorted(q.stem for q in CONTROLLERS_DIR.glob("*.yaml"))
        raise FileNotFoundError(
            f"no controller spec {str(spec)!r}: give a .yaml file or one of {known}"
        )
    return cand


def _positive(path, key, value, hi: float | None = None) -> float:
    """A YAML number > 0 (and <= hi). PyYAML reads ``1e-8`` (no dot) as a string, so a
    string that spells a number is read as that number here (not in JSON files)."""
    if isinstance(value, str):
        try:
            value = float(value)
        except ValueError:
            raise ValueError(f"{path}: {key} must be a number, got {value!r}") from None
    return schema.real(value, f"{path}: {key}", 0.0, hi, lo_open=True)


def check_mpc_settings(values: dict, where, yaml_numbers: bool = True) -> dict:
    """The search settings of an mpc controller (`MPC_LIMITS`; ``rtol`` as ``plan_rtol``),
    checked: integers are integers, reals finite, each in its range. ``yaml_numbers``: a
    string that spells a real is read as it (see `_positive`; `schema.limited` checks each)."""
    out = dict(values)
    for key in MPC_BOOLS:
        if key in values:
            schema.boolean(values[key], f"{where}: {key}")
    for key, (lo, hi) in MPC_LIMITS.items():
        name = "rtol" if key == "plan_rtol" and "rtol" in values else key
        if name not in values:
            continue
        v = values[name]
        out[name] = schema.limited(v, f"{where}: {name}", lo, hi, lo_open=True, text=yaml_numbers)
    return out


def load_spec(spec: str | Path) -> ControllerSpec:
    """Read and check a spec file (name or path); ValueError naming the file and the key."""
    path = resolve_spec_path(spec)
    try:
        data = parse_yaml(path.read_text())
    except yaml.YAMLError as e:
        raise ValueError(f"{path}: not valid YAML ({str(e).splitlines()[0]})") from None
    except UnicodeDecodeError:
        raise ValueError(f"{path}: not a text file") from None
    if not isinstance(data, dict):
        raise ValueError(f"{path}: must be a mapping of keys to values")
    kind = data.get("controller")
    if kind not in KINDS:
        raise ValueError(f"{path}: controller must be one of {KINDS}, got {kind!r}")
    allowed = SPEC_KEYS[kind]
    for key in data:
        if key not in allowed:
            raise ValueError(
                f"{path}: unknown key {key!r} for a {kind} controller "
                f"(allowed: {', '.join(allowed)})"
            )
    for block in ("adaptive", "offset_free"):  # null would read as "absent": a plain mpc
        if block in data and data[block] is None:
            raise ValueError(f"{path}: {block} is null; give true, false or a mapping of settings")
    out = ControllerSpec(controller=kind, path=path)
    for key, value in data.items():
        setattr(out, key, value)
    out.max_torque = _positive(path, "max_torque", out.max_torque, MAX_TORQUE_LIMIT)
    out.dt = schema.dt_value(_positive(path, "dt", out.dt), f"{path}: dt")
    out.gait = str(out.gait)
    if kind == "damping":
        try:
            out.c = float(out.c)
        except (TypeError, ValueError):
            raise ValueError(f"{path}: c must be a number, got {out.c!r}") from None
        if not np.isfinite(out.c) or out.c < 0:
            raise ValueError(f"{path}: c must be finite and >= 0, got {out.c!r}")
    if (
        "K" in data
        and data["K"] is not None
        and (isinstance(data["K"], bool) or not isinstance(data["K"], int))
    ):
        raise ValueError(f"{path}: K must be an integer, got {data['K']!r}")
    if kind == "mpc":
        out.extra = check_mpc_settings({k: data.get(k, v) for k, v in MPC_DEFAULTS.items()}, path)
    if out.offset_free is not None:
        out.offset_free = check_offset_free(out.offset_free, path)
    schema.boolean(out.privileged, f"{path}: privileged", numpy=False)
    if out.adaptive is not None:
        from .adaptive_settings import check_adaptive

        out.adaptive = check_adaptive(out.adaptive, path)
    if sum([out.privileged, bool(out.adaptive), out.offset_free is not None]) > 1:
        raise ValueError(f"{path}: privileged, adaptive and offset_free exclude each other")
    if out.jacobian not in ("fd", "variational"):
        raise ValueError(f"{path}: jacobian must be 'fd' or 'variational', got {out.jacobian!r}")
    return out


def check_offset_free(value, path) -> dict:
    """The ``offset_free`` block: ``true`` (the defaults), ``false`` (none) or a mapping of some of
    ``estimator`` (torque | innovation), ``gain`` (0 < L <= 1), ``deadband`` and ``max_shift``
    (`bound_env.control.offset_free`)."""
    from .offset_free import OF_DEFAULTS

    return schema.settings_block(
        value, path, "offset_free", OF_DEFAULTS, lambda key, v, _: _offset_free_value(path, key, v)
    )


def _offset_free_value(path, key: str, v):
    from .offset_free import ESTIMATORS, OF_LIMITS

    where = f"{path}: offset_free.{key}"
    if key == "estimator":
        if v not in ESTIMATORS:
            raise ValueError(f"{where} must be one of {ESTIMATORS}, got {v!r}")
        return v
    lo, hi = OF_LIMITS[key]
    value_ = _positive(path, f"offset_free.{key}", v) if isinstance(v, str) else v
    return schema.real(value_, where, lo, hi, lo_open=key == "gain")


def weights(path, key: str, value, n: int) -> np.ndarray:
    """A diagonal weight matrix (n x n) from a number or n numbers, all >= 0 (R: > 0)."""
    try:
        w = np.array(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise ValueError(f"{path}: {key} must be a number or {n} numbers, got {value!r}") from None
    if w.size == 1:
        w = np.full(n, w[0])
    if w.size != n:
        raise ValueError(f"{path}: {key} must be a number or {n} numbers, got {w.size}")
    if not np.all(np.isfinite(w)) or np.any(w < 0) or (key == "R" and np.any(w <= 0)):
        raise ValueError(
            f"{path}: {key} must be finite and {'> 0' if key == 'R' else '>= 0'}, got {value!r}"
        )
    return np.diag(w)


def _gait_key(gains: dict, gait) -> str | None:
    """The key of ``gains`` that names the gait file ``gait`` (a name or a path), or None."""
    from ..model.params import load_gait

    if str(gait) in gains:
        return str(gait)
    try:
        path = load_gait(gait).path.resolve()
        return next((k for k in gains if load_gait(k).path.resolve() == path), None)
    except (OSError, ValueError):
        return None


def read_gain(spec: ControllerSpec, K: int, basis: str, gait: str | None = None):
    """The explicit gain of the spec (K x 6, SI) for ``gait`` (default: the spec's), or None
    (to be designed); ValueError if its shape does not match the basis. ``gain`` is one
    matrix (for every gait), a file, or a mapping of gait names to matrices (a gait it does
    not list is designed). Errors name where the gain came from: the spec's field
    (``gain`` or ``gain.<gait>``) or the gain file."""
    g, where = spec.gain, (f"{spec.path}: gain" if spec.path is not None else "gain")
    if isinstance(g, dict):
        key = _gait_key(g, gait if gait is not None else spec.gait)
        g, where = g.get(key), f"{where}.{key}"
    if g is None:
        return None
    if isinstance(g, str):
        p = Path(g)
        if not p.is_absolute() and spec.path is not None:
            p = spec.path.parent / p
        if not p.is_file():
            raise FileNotFoundError(f"{where}: gain file {str(p)!r} does not exist")
        try:
            if p.suffix == ".npy":
                g = np.load(p, allow_pickle=False)
            elif p.suffix == ".json":
                g = schema.read_json(p)
            else:
                g = np.loadtxt(p, delimiter=",", ndmin=2)
        except (OSError, EOFError, UnicodeDecodeError, ValueError) as e:
            raise ValueError(f"{where}: gain file {str(p)!r} is not readable ({e})") from None
        where = f"{p}: gain (from {spec.path})"
    try:
        G = np.array(g, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{where} must be a K x 6 matrix of numbers") from None
    if G.shape != (K, 6):
        raise ValueError(
            f"{where} has shape {G.shape}, but basis {basis!r} with "
            f"K={K} needs a ({K}, 6) gain (one row per basis function)"
        )
    G = schema.real_array(G, where, shape=(K, 6))  # finite: no NaN or inf
    from ..sim.task import APEX_SCALES

    big = float(np.max(np.abs(G * np.asarray(APEX_SCALES)[None, :])))
    if big > MAX_GAIN:
        raise ValueError(
            f"{where} has entries up to {big:.3g} times the torque limit per apex scale "
            f"(at most {MAX_GAIN:g}; the designed gains are ~1): a torque saturated by an "
            "error of a millionth of a scale"
        )
    return G
