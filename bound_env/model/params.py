"""Model parameters, gait files and unit conversions (paper Tables I-II, eqs. 25-26).

Angles are radians inside the package and degrees only at its edges (gait files, CLI,
plots); the conversions live here and nowhere else.

A gait file is YAML with the paper's symbols as keys (``g, m1, m2, l1, l2, I1, I2, lb_bar,
lf_bar, kb, kf, kc, zeta, alpha_deg, gamma_b_deg, gamma_f_deg``), where ``l1, l2`` are the
bodies' *half*-lengths and ``I1, I2`` are about each body's own centre of mass, plus the
published apex state ``z_published`` and, once solved, the model's own fixed point ``z_star``,
both in the paper's units [m, deg, deg, m/s, deg/s, deg/s].
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields, replace
from pathlib import Path

import numpy as np
import yaml

from ..files.layout import Layout
from ..files.resources import gaits_dir, parse_yaml

GAIT_KEYS = (
    "g",
    "m1",
    "m2",
    "l1",
    "l2",
    "I1",
    "I2",
    "lb_bar",
    "lf_bar",
    "kb",
    "kf",
    "kc",
    "zeta",
    "alpha_deg",
    "gamma_b_deg",
    "gamma_f_deg",
)
GAITS_DIR = gaits_dir()  # the repository's configs/gaits, or the wheel's copy (package data)

# Layout of the flat float64 parameter vector the compiled dynamics read (`Params.to_array`):
# P.G == P_G == 0, ..., N_PARAMS entries. SI units, radians; tau: spine torque [N m] (a
# generalized force on theta2); minleg: shortest physical leg length as a fraction of the rest
# length; gx, gy: gravity along and normal to the slope, g sin(alpha), g cos(alpha) [m/s^2].
PARAM_FIELDS = (
    "g",
    "alpha",
    "m1",
    "m2",
    "l1",
    "l2",
    "I1",
    "I2",
    "lb",
    "lf",
    "kb",
    "kf",
    "kc",
    "cc",
    "gb",
    "gf",
    "tau",
    "minleg",
    "gx",
    "gy",
)
PARAM_LAYOUT = Layout("P_", PARAM_FIELDS, "N_PARAMS")
P = PARAM_LAYOUT.ns
globals().update(PARAM_LAYOUT.constants())  # P_G, P_ALPHA, ..., P_GY, N_PARAMS
# The simulator's ``aux`` vector: the parameter vector followed by the contact state.
# cb, cf: 1.0 while the back / front leg is in stance; xb, xf: x of the back / front toe on
# the ground [m] (x_b^toe, x_f^toe of eq. 13). A.CB == A_CB == N_PARAMS, ..., N_AUX entries.
AUX_LAYOUT = Layout("A_", ("cb", "cf", "xb", "xf"), "N_AUX", start=PARAM_LAYOUT.size)
A = AUX_LAYOUT.ns
globals().update(AUX_LAYOUT.constants())  # A_CB, A_CF, A_XB, A_XF, N_AUX

# z on S_apex (eq. 17): [y_g, theta1, theta2, xdot_g, theta1dot, theta2dot].
Z_NAMES = ("y_g", "theta1", "theta2", "xdot_g", "theta1dot", "theta2dot")
Z_PAPER_UNITS = ("m", "deg", "deg", "m/s", "deg/s", "deg/s")
Z_SI_UNITS = ("m", "rad", "rad", "m/s", "rad/s", "rad/s")
Z_SYMBOLS = ("y_g", "θ1", "θ2", "ẋ_g", "θ̇1", "θ̇2")  # plain text
Z_TEX = ("y_g", r"\theta_1", r"\theta_2", r"\dot x_g", r"\dot\theta_1", r"\dot\theta_2")  # LaTeX
Z_IN_Y = (1, 2, 3, 4, 6, 7)  # z = y[Z_IN_Y] for the full state y = [q, qdot] at an apex


def z_labels(style: str = "text") -> tuple[str, ...]:
    """Labels of the six components of z, all made from the declarations above.

    ``"text"``: ``θ1 [deg]``; ``"tex"``: ``$\\theta_1^*$ [deg]`` (a fixed point's, for
    plots); ``"column"``: ``theta1_deg`` (CSV headers); ``"si_column"``: ``theta1_rad`` (CSV
    headers of SI values); ``"inline"``: ``θ1 deg``.
    """
    units = Z_PAPER_UNITS
    if style == "text":
        return tuple(f"{s} [{u}]" for s, u in zip(Z_SYMBOLS, units, strict=True))
    if style == "tex":
        return tuple(f"${t}^*$ [{u}]" for t, u in zip(Z_TEX, units, strict=True))
    if style == "column":
        return tuple(f"{n}_{u.replace('/s', 'ps')}" for n, u in zip(Z_NAMES, units, strict=True))
    if style == "si_column":
        return tuple(
            f"{n}_{u.replace('/s', 'ps')}" for n, u in zip(Z_NAMES, Z_SI_UNITS, strict=True)
        )
    if style == "inline":
        return tuple(f"{s} {u}" for s, u in zip(Z_SYMBOLS, units, strict=True))
    raise ValueError(f"z label style must be text, tex, column, si_column or inline, got {style!r}")


_Z_ANGULAR = np.array([False, True, True, False, True, True])


def deg(x):
    """Radians to degrees (arrays or scalars)."""
    return np.degrees(x)


def rad(x):
    """Degrees to radians (arrays or scalars)."""
    return np.radians(x)


def z_to_si(z_paper) -> np.ndarray:
    """Apex state from the paper's units [m, deg, deg, m/s, deg/s, deg/s] to SI."""
    z = np.array(z_paper, dtype=float).reshape(6)
    return np.where(_Z_ANGULAR, np.radians(z), z)


def z_to_paper(z_si) -> np.ndarray:
    """Apex state from SI to the paper's units [m, deg, deg, m/s, deg/s, deg/s]."""
    z = np.array(z_si, dtype=float).reshape(6)
    return np.where(_Z_ANGULAR, np.degrees(z), z)


@dataclass(frozen=True)
class Params:
    """Physical parameters of the two-body bounding model (Tables I-II), SI units, radians.

    ``l1, l2`` are half-lengths of the back and front bodies; ``I1, I2`` their pitch
    inertias about their own centres of mass. The spine damping ``c_c`` is not a parameter:
    it follows from ``zeta`` by eqs. (25)-(26), see `c_c`.
    """

    g: float = 9.8
    m1: float = 10.4
    m2: float = 10.4
    l1: float = 0.1375
    l2: float = 0.1375
    I1: float = 0.443375
    I2: float = 0.443375
    lb_bar: float = 0.32
    lf_bar: float = 0.32
    kb: float = 2420.0
    kf: float = 2420.0
    kc: float = 295.0
    zeta: float = 0.2
    alpha: float = math.radians(1.9343)
    gamma_b: float = math.radians(46.7)
    gamma_f: float = math.radians(44.6)
    min_leg_frac: float = 0.25  # a stance leg shorter than this x rest length is a failure

    def __post_init__(self):
        for f in fields(self):
            v = getattr(self, f.name)
            if not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ValueError(f"parameter {f.name} must be a finite number, got {v!r}")
        for name in ("g", "m1", "m2", "l1", "l2", "I1", "I2", "lb_bar", "lf_bar", "kb", "kf"):
            if getattr(self, name) <= 0:
                raise ValueError(f"parameter {name} must be positive, got {getattr(self, name)}")
        if self.kc < 0:
            raise ValueError(f"parameter kc must be non-negative, got {self.kc}")
        if self.zeta < 0:
            raise ValueError(f"parameter zeta must be non-negative, got {self.zeta}")
        for name in ("gamma_b", "gamma_f"):
            if not 0.0 < getattr(self, name) < math.pi / 2:
                raise ValueError(
                    f"touchdown angle {name}_deg must lie in (0, 90) deg, "
                    f"got {math.degrees(getattr(self, name))}"
                )
        if not -math.pi / 2 < self.alpha < math.pi / 2:
            raise ValueError(f"slope alpha_deg must lie in (-90, 90) deg, got {deg(self.alpha)}")
        if not 0.0 < self.min_leg_frac < 1.0:
            raise ValueError(f"min_leg_frac must lie in (0, 1), got {self.min_leg_frac}")

    @property
    def I1_joint(self) -> float:
        """Back body inertia about the spine joint, I1' (eq. 26)."""
        return self.m1 * self.l1**2 + self.I1

    @property
    def I2_joint(self) -> float:
        """Front body inertia about the spine joint, I2' (eq. 26)."""
        return self.m2 * self.l2**2 + self.I2

    @property
    def c_c(self) -> float:
        """Spine damping [N m s/rad] from the damping ratio zeta (eq. 25 solved for c_c)."""
        i1, i2 = self.I1_joint, self.I2_joint
        return 2.0 * self.zeta * math.sqrt(i1 * i2 * self.kc / (i1 + i2))

    @property
    def omega_n(self) -> float:
        """Natural frequency of the spine oscillation [rad/s] (eq. 25)."""
        i1, i2 = self.I1_joint, self.I2_joint
        return math.sqrt(self.kc * (i1 + i2) / (i1 * i2))

    def to_array(self, tau: float = 0.0) -> np.ndarray:
        """Flat float64 vector for the compiled dynamics (layout: the ``P_*`` constants)."""
        p = np.empty(P.SIZE)
        p[[P.G, P.ALPHA, P.M1, P.M2, P.L1, P.L2, P.I1, P.I2]] = (
            self.g,
            self.alpha,
            self.m1,
            self.m2,
            self.l1,
            self.l2,
            self.I1,
            self.I2,
        )
        p[[P.LB, P.LF, P.KB, P.KF, P.KC, P.CC, P.GB, P.GF]] = (
            self.lb_bar,
            self.lf_bar,
            self.kb,
            self.kf,
            self.kc,
            self.c_c,
            self.gamma_b,
            self.gamma_f,
        )
        p[P.TAU] = tau
        p[P.MINLEG] = self.min_leg_frac
        p[P.GX], p[P.GY] = self.g * math.sin(self.alpha), self.g * math.cos(self.alpha)  # eq. (2)
        return p

    def to_gait_dict(self) -> dict:
        """The gait-file keys (degrees for angles)."""
        d = {k: float(v) for k, v in asdict(self).items() if k in GAIT_KEYS}
        for k in ("alpha", "gamma_b", "gamma_f"):  # 13 digits undo the rad -> deg round trip
            d[f"{k}_deg"] = float(f"{deg(getattr(self, k)):.13g}")
        return {k: d[k] for k in GAIT_KEYS}

    @classmethod
    def from_gait_dict(cls, d: dict) -> Params:
        """Build from gait-file keys; unknown keys are an error, missing keys take defaults."""
        unknown = set(d) - set(GAIT_KEYS) - {"min_leg_frac"}
        if unknown:
            raise ValueError(f"unknown gait parameter(s): {sorted(unknown)}; known: {GAIT_KEYS}")
        kw = {}
        for k, v in d.items():
            try:
                v = float(v)
            except (TypeError, ValueError):
                raise ValueError(f"parameter {k} must be a number, got {v!r}") from None
            if k.endswith("_deg"):
                kw[k[: -len("_deg")]] = math.radians(v) if math.isfinite(v) else v
            else:
                kw[k] = v
        return cls(**kw)

    def with_values(self, **gait_keys) -> Params:
        """A copy with some gait-file keys changed, e.g. ``with_values(alpha_deg=2.0)``."""
        return Params.from_gait_dict(
            {**self.to_gait_dict(), "min_leg_frac": self.min_leg_frac, **gait_keys}
        )


@dataclass(frozen=True)
class Gait:
    """A gait file: parameters, the published and the solved apex state, and metadata."""

    params: Params
    z_published: np.ndarray | None = None  # SI
    z_star: np.ndarray | None = None  # SI
    meta: dict | None = None
    path: Path | None = None

    @property
    def z0(self) -> np.ndarray:
        """The default start: z_star where solved, else z_published (SI)."""
        z = self.z_star if self.z_star is not None else self.z_published
        if z is None:
            raise ValueError(f"gait {self.path} has neither z_star nor z_published")
        return z.copy()

    def with_params(self, params: Params) -> Gait:
        return replace(self, params=params)


def resolve_gait_path(gait: str | Path) -> Path:
    """A path, or a name under ``configs/gaits/`` such as ``"paper"`` or ``"paper-literal"``;
    TypeError for anything else (None, a number), ValueError for an empty one or a folder."""
    if not isinstance(gait, (str, Path)):
        raise TypeError(
            f"gait must be a gait name or a gait file's path, got {gait!r} ({type(gait).__name__})"
        )
    if not str(gait).strip():
        raise ValueError("gait must be a gait name or a gait file's path, got ''")
    p = Path(gait)
    try:
        if p.is_file():
            return p
        folder = p.is_dir()
    except (OSError, ValueError):  # a name the OS refuses (too long, a NUL byte)
        folder = False
    if folder:
        raise ValueError(f"gait {str(gait)!r} is a folder, not a gait file")
    for cand in (GAITS_DIR / f"{gait}.yaml", GAITS_DIR / str(gait)):
        if cand.is_file():
            return cand
    names = sorted(q.stem for q in GAITS_DIR.glob("*.yaml"))
    raise FileNotFoundError(f"no gait file {gait!r}; give a path or one of {names}")


def parse_override(text: str) -> tuple[str, float]:
    """``"KEY=VALUE"`` -> (key, float value) with a clear error."""
    if "=" not in text:
        raise ValueError(f"override {text!r} must look like KEY=VALUE")
    k, v = text.split("=", 1)
    k = k.strip()
    if k not in GAIT_KEYS and k != "min_leg_frac":
        raise ValueError(f"unknown gait parameter {k!r}; known: {GAIT_KEYS}")
    try:
        return k, float(v)
    except ValueError:
        raise ValueError(f"value of {k} must be a number, got {v!r}") from None


def parse_z(text: str | None, flag: str = "--z") -> np.ndarray | None:
    """``"v1,...,v6"`` in the paper's units -> apex state in SI (None for None), clear errors."""
    if text is None:
        return None
    parts = [p for p in text.replace(" ", "").split(",") if p]
    if len(parts) != 6:
        raise ValueError(f"{flag} needs 6 comma-separated numbers, got {len(parts)}: {text!r}")
    try:
        values = [float(p) for p in parts]
    except ValueError:
        raise ValueError(f"{flag} must be numbers, got {text!r}") from None
    if not all(math.isfinite(v) for v in values):
        raise ValueError(f"{flag} must be finite numbers, got {text!r}")
    return z_to_si(values)


def read_gait_file(path: Path) -> dict:
    """A gait file's YAML mapping; ValueError naming the file for anything else (binary, not
    YAML, a YAML tag, truncated to nothing useful, or not a mapping)."""
    try:
        text = Path(path).read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise ValueError(f"gait file {path}: not a text (UTF-8) file") from None
    except IsADirectoryError:
        raise ValueError(f"gait file {path} is a folder, not a file") from None
    try:
        data = parse_yaml(text)
    except yaml.YAMLError as e:
        where = getattr(e, "problem_mark", None)
        at = f" at line {where.line + 1}" if where is not None else ""
        problem = getattr(e, "problem", None) or type(e).__name__
        raise ValueError(f"gait file {path}: not valid YAML{at} ({problem})") from None
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ValueError(
            f"gait file {path}: expected a mapping of gait keys, got {type(data).__name__}"
        )
    return data


def _gait_z(data: dict, key: str, path: Path) -> np.ndarray | None:
    """``z_star``/``z_published`` of a gait file in SI, or None; clear errors for bad values."""
    value = data.get(key)
    if value is None:
        return None
    ok = isinstance(value, (list, tuple)) and len(value) == 6
    if ok:
        try:
            z = np.array([float(v) for v in value])
            ok = bool(np.all(np.isfinite(z))) and not any(isinstance(v, (str, bool)) for v in value)
        except (TypeError, ValueError):
            ok = False
    if not ok:
        raise ValueError(
            f"gait file {path}: {key} must be 6 finite numbers {Z_NAMES} in the "
            f"paper's units {Z_PAPER_UNITS}, got {value!r}"
        )
    return z_to_si(z)


def load_gait(gait: str | Path, overrides: dict | None = None) -> Gait:
    """Read a gait file (path or name), apply ``overrides`` (gait-file keys), validate."""
    path = resolve_gait_path(gait)
    data = read_gait_file(path)
    pdict = {k: data[k] for k in GAIT_KEYS if k in data}
    if "min_leg_frac" in data:
        pdict["min_leg_frac"] = data["min_leg_frac"]
    try:
        Params.from_gait_dict(pdict)  # the file's own values, named with the file
    except ValueError as e:
        raise ValueError(f"gait file {path}: {e}") from None
    pdict.update(overrides or {})
    params = Params.from_gait_dict(pdict)
    zp, zs = (_gait_z(data, key, path) for key in ("z_published", "z_star"))
    meta = {k: v for k, v in data.items() if k not in GAIT_KEYS}
    return Gait(params=params, z_published=zp, z_star=zs, meta=meta, path=path)


def save_gait(path: str | Path, params: Params, z_star=None, z_published=None, **meta) -> Path:
    """Write a gait file (z in paper units), atomically; extra keyword arguments are stored as
    metadata."""
    path = Path(path)
    data = params.to_gait_dict()
    if params.min_leg_frac != Params.min_leg_frac:
        data["min_leg_frac"] = params.min_leg_frac
    if z_published is not None:
        data["z_published"] = [float(v) for v in z_to_paper(z_published)]
    if z_star is not None:
        data["z_star"] = [float(v) for v in z_to_paper(z_star)]
    data.update(meta)
    from ..files.cache import atomic_write

    path.parent.mkdir(parents=True, exist_ok=True)
    return atomic_write(path, yaml.safe_dump(data, sort_keys=False, default_flow_style=None))
