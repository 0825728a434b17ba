"""Gait files regenerated from the reproduction (``--write-gaits``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...model.params import GAITS_DIR, save_gait
from .claims import literal_gait, reproducing_gait


def _kept_meta(gait) -> dict:
    """The source gait file's notes that a regenerated gait file carries over."""
    return {
        k: v for k, v in (gait.meta or {}).items() if k in ("h_b_unused", "h_f_unused", "reading")
    }


def write_gait_files(results: dict, gaits_dir: Path = GAITS_DIR) -> list[Path]:
    """default.yaml (the published gait's fixed point, reproducing reading) and
    literal-cycle.yaml (the literal reading's periodic gait at the published parameters)."""
    written = []
    gr = reproducing_gait()
    fp = results["reproducing"]["fixed_point"]
    written.append(
        save_gait(
            gaits_dir / "default.yaml",
            gr.params,
            z_star=np.asarray(fp["z_si"]),
            z_published=gr.z_published,
            found_by="bound-env reproduce: Newton-Raphson on P(z) = z (central-difference "
            "Jacobian, eq. 23) from z_published at the parameters of paper.yaml, rtol = atol = "
            "1e-12; eigenvalues of nabla P by eq. 23 (dz = 1e-6)",
            residual=float(fp["residual"]),
            eigenvalues=fp["eigenvalues"],
            emax=float(fp["emax"]),
            phases=fp["phases"],
            durations=[float(d) for d in fp["durations"]],
            strides_to_converge=fp["strides_to_converge"],
            **_kept_meta(gr),
        )
    )
    lit = results["literal"].get("fixed_point")
    if lit:
        gl = literal_gait()
        written.append(
            save_gait(
                gaits_dir / "literal-cycle.yaml",
                gl.params,
                z_star=np.asarray(lit["z_si"]),
                z_published=gl.z_published,
                found_by="bound-env reproduce: homotopy from the reproducing reading's fixed "
                "point to the literal geometry (alpha freed, forward speed pinned), alpha "
                f"continued back to {gl.params.to_gait_dict()['alpha_deg']:g} deg, Newton at the "
                "parameters of paper-literal.yaml; "
                "the same point as multi-start Newton around z_published. UNSTABLE: a real "
                "eigenvalue outside the unit circle",
                residual=float(lit["residual"]),
                eigenvalues=lit["eigenvalues"],
                emax=float(lit["emax"]),
                phases=lit["phases"],
                durations=[float(d) for d in lit["durations"]],
                **_kept_meta(gl),
            )
        )
    return written
