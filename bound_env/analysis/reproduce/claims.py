"""The published numbers, from one place each.

- The paper's parameters and its apex state z* are read from the gait files
  (``configs/gaits/paper.yaml``, reproducing reading; ``paper-literal.yaml``, literal
  reading): `published` gives them, z* exactly as printed (``z_published``, paper units).
- Everything else the paper states (windows, e_max, strides, the short flight, the body
  vibration, the rounded slope of the text) is in the one table `CLAIMS`, with where it is
  stated. The report and the figures read only these two.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache

import numpy as np
import yaml

from ...model.params import GAITS_DIR, Gait, load_gait, z_to_paper

REPRODUCING_FILE = GAITS_DIR / "paper.yaml"  # Table II, reproducing reading
LITERAL_FILE = GAITS_DIR / "paper-literal.yaml"  # Table II, literal reading


@dataclass(frozen=True)
class Claims:
    """What the paper states besides its parameters and z*."""

    emax: float  # "around 0.9" at the published gait (Sec. IV.B.2, Fig. 4)
    strides: int  # "about 40" strides to converge after +-1 % (Fig. 6)
    alpha_window: tuple  # stable slope window [deg] (Fig. 7)
    kc_window: tuple  # stable spine stiffness window [N m/rad] (Fig. 8)
    gap_s: float  # bs->df and df->fs interval [s] (Fig. 5)
    amplitude_deg: float  # "about 5 deg" body vibration (Sec. IV.B)
    alpha_text_deg: float  # the slope as printed in the text (the Fig. 6 caption: 1.9343)
    alpha_text_half_digit: float  # half a unit of its last printed digit
    z_half_digit: tuple  # half a unit of the last printed digit of each component of z*
    param_half_digit: dict  # ... of each published parameter (1.9343, 295, 46.7, ...)


CLAIMS = Claims(
    emax=0.9,
    strides=40,
    alpha_window=(1.92, 2.05),
    kc_window=(294.0, 308.0),
    gap_s=0.002,
    amplitude_deg=5.0,
    alpha_text_deg=1.93,
    alpha_text_half_digit=0.005,
    z_half_digit=(0.00005, 0.00005, 0.0005, 0.0005, 0.05, 0.05),
    param_half_digit={
        "alpha_deg": 0.00005,
        "kc": 0.5,
        "gamma_b_deg": 0.05,
        "gamma_f_deg": 0.05,
        "kb": 5.0,
        "kf": 5.0,
    },
)


@dataclass(frozen=True)
class Published:
    """The published gait: parameters (gait-file units) and z* as printed (paper units)."""

    z: tuple  # [y_g m, theta1 deg, theta2 deg, xdot_g m/s, theta1dot deg/s, theta2dot deg/s]
    kc: float  # [N m/rad]
    alpha_deg: float
    zeta: float
    gamma_b_deg: float
    gamma_f_deg: float
    kb: float  # [N/m]
    kf: float


@cache
def published() -> Published:
    """The published gait from ``paper.yaml`` (z* exactly as written there)."""
    raw = yaml.safe_load(REPRODUCING_FILE.read_text())
    gd = reproducing_gait().params.to_gait_dict()
    return Published(
        z=tuple(float(v) for v in raw["z_published"]),
        **{k: gd[k] for k in ("kc", "alpha_deg", "zeta", "gamma_b_deg", "gamma_f_deg", "kb", "kf")},
    )


def reproducing_gait() -> Gait:
    return load_gait(REPRODUCING_FILE)


def literal_gait() -> Gait:
    return load_gait(LITERAL_FILE)


def gait_config(g) -> dict:
    """What of a gait goes into the run's configuration (and its cache hashes)."""
    return {
        "params": g.params.to_gait_dict(),
        "min_leg_frac": g.params.min_leg_frac,
        "z_published": z_to_paper(g.z_published),
    }


def published_z() -> np.ndarray:
    """z* as printed, paper units."""
    return np.array(published().z)
