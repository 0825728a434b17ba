"""The reproduction's published numbers have one source each: the gait files and CLAIMS."""

from __future__ import annotations

import numpy as np
import yaml

from bound_env.analysis.reproduce.claims import CLAIMS, REPRODUCING_FILE, published
from bound_env.model.params import load_gait, z_labels, z_to_paper


def test_published_gait_is_read_from_the_gait_file():
    pub = published()
    raw = yaml.safe_load(REPRODUCING_FILE.read_text())
    assert list(pub.z) == [float(v) for v in raw["z_published"]]  # exactly as written
    gait = load_gait("paper")
    np.testing.assert_allclose(z_to_paper(gait.z_published), pub.z, rtol=1e-14)
    gd = gait.params.to_gait_dict()
    assert (pub.kc, pub.alpha_deg, pub.kb) == (gd["kc"], gd["alpha_deg"], gd["kb"])
    assert f"{pub.alpha_deg:g}" == str(raw["alpha_deg"])  # prints as the paper prints it


def test_claims_are_consistent():
    lo, hi = CLAIMS.alpha_window
    assert lo < published().alpha_deg < hi  # the published slope lies in its window
    lo, hi = CLAIMS.kc_window
    assert lo <= published().kc <= hi
    assert round(published().alpha_deg, 2) == CLAIMS.alpha_text_deg  # the text rounds it
    assert len(CLAIMS.z_half_digit) == 6
    assert set(CLAIMS.param_half_digit) <= set(load_gait("paper").params.to_gait_dict())


def test_z_labels_from_one_declaration():
    assert z_labels("column")[3] == "xdot_g_mps" and z_labels("text")[1] == "θ1 [deg]"
    assert z_labels("tex")[0] == "$y_g^*$ [m]" and len(set(z_labels("inline"))) == 6
