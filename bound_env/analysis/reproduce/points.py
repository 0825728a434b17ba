"""A fixed point summarised for the report; distances between apex states."""

from __future__ import annotations

import math

import numpy as np

from ...model.params import Params, z_to_paper
from ..poincare import StrideFailure, apex_energy, stride
from ..stability import stability


def eig_list(lam) -> list | None:
    return None if lam is None else [[float(v.real), float(v.imag)] for v in lam]


def point_summary(params: Params, z, **extra) -> dict:
    """A fixed point's parameters, z (paper units), residual, eigenvalues, phases."""
    z = np.asarray(z, dtype=float)
    res = stride(z, params)
    resid = math.inf if res.z1 is None else float(np.max(np.abs(res.z1 - z)))
    try:
        st = stability(z, params)
        lam, emax = st.eigenvalues, st.emax
    except StrideFailure:
        lam, emax = None, math.nan
    gd = params.to_gait_dict()
    out = {k: gd[k] for k in ("kc", "alpha_deg", "gamma_b_deg", "gamma_f_deg", "kb", "kf")}
    out.update(
        z=z_to_paper(z),
        residual=resid,
        emax=emax,
        eigenvalues=eig_list(lam),
        phases=list(res.phases),
        durations=list(res.durations),
        energy=apex_energy(z, params),
        has_ds="ds" in res.phases,
        **extra,
    )
    return out


def rel_distance(z_paper, z_ref_paper) -> float:
    """RMS over the six components of (z - z_ref) / |z_ref| (unit-free)."""
    z, r = np.asarray(z_paper, float), np.asarray(z_ref_paper, float)
    return float(np.sqrt(np.mean(((z - r) / np.abs(r)) ** 2)))
