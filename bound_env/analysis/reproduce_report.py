"""Old home of the reproduction's figures and report: `bound_env.analysis.reproduce.figures`
and `bound_env.analysis.reproduce.document.report` (kept importable, with ``PAPER`` made from
`reproduce.claims`)."""

from .reproduce.claims import CLAIMS, published
from .reproduce.document.report import write_report
from .reproduce.figures import write_figures

PAPER = {
    "z": list(published().z),
    "z_half_digit": list(CLAIMS.z_half_digit),
    "emax": CLAIMS.emax,
    "strides": CLAIMS.strides,
    "alpha_window": CLAIMS.alpha_window,
    "kc_window": CLAIMS.kc_window,
    "gap_s": CLAIMS.gap_s,
    "amplitude_deg": CLAIMS.amplitude_deg,
}

__all__ = ["PAPER", "write_figures", "write_report"]
