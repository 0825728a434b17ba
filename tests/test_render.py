"""Tests of the side-view renderer: frame format, geometry on screen, legs, GIF output."""

import math
import subprocess
import sys

import numpy as np
import pytest
from PIL import Image

from bound_env.envs.render import (
    BACK_BODY,
    FRONT_BODY,
    GROUND_ROW_FRAC,
    LEG_FLIGHT,
    LEG_STANCE,
    Renderer,
    render_frame,
    save_gif,
    slope_to_pixel,
    spring_points,
)
from bound_env.model.dynamics import A_XB, back_hip, front_hip, make_aux
from bound_env.model.params import Params

W, H, METERS = 640, 360, 1.6
SCALE = W / METERS  # pixels per metre
Y0 = np.array([0.0, 0.25, 0.01, -0.02, 2.8, 0.0, 0.0, 0.0])
P = Params().to_array()
ALPHA = Params().alpha


def aux_for(y, back_stance, front_stance, dx_b=-0.05, dx_f=-0.05):
    """Contact state with stance toes placed dx behind their hips (a compressed leg)."""
    a0 = make_aux(P)
    xb = back_hip(y, a0)[0] + dx_b
    xf = front_hip(y, a0)[0] + dx_f
    return make_aux(P, back_stance, front_stance, xb, xf)


def colour_mask(frame, colour, tol=12):
    """Pixels within ``tol`` (max channel difference) of ``colour``."""
    return np.abs(frame.astype(int) - np.array(colour)).max(axis=2) <= tol


def centroid(mask):
    rows, cols = np.nonzero(mask)
    return cols.mean(), rows.mean()


def body_mask(frame):
    return colour_mask(frame, BACK_BODY) | colour_mask(frame, FRONT_BODY)


@pytest.fixture(scope="module")
def frame():
    return render_frame(Y0, aux_for(Y0, True, True))


def test_shape_and_dtype(frame):
    assert frame.shape == (H, W, 3)
    assert frame.dtype == np.uint8
    small = render_frame(Y0, aux_for(Y0, False, False), width=200, height=120)
    assert small.shape == (120, 200, 3) and small.dtype == np.uint8


def test_slope_to_pixel_matches_hand_formula():
    # Camera point on the ground: centre column, ground row.
    u, v = slope_to_pixel(0.3, 0.0, ALPHA, 0.3, W, H, METERS)
    assert u == pytest.approx(W / 2) and v == pytest.approx(GROUND_ROW_FRAC * H)
    # One metre downhill: right by cos(alpha) m and down by sin(alpha) m (slope descends).
    u, v = slope_to_pixel(1.3, 0.0, ALPHA, 0.3, W, H, METERS)
    assert u == pytest.approx(W / 2 + SCALE * math.cos(ALPHA))
    assert v == pytest.approx(GROUND_ROW_FRAC * H + SCALE * math.sin(ALPHA))
    # Height above the slope: up (smaller row) and slightly right (the normal leans forward).
    u, v = slope_to_pixel(0.3, 0.2, ALPHA, 0.3, W, H, METERS)
    assert u == pytest.approx(W / 2 + SCALE * 0.2 * math.sin(ALPHA))
    assert v == pytest.approx(GROUND_ROW_FRAC * H - SCALE * 0.2 * math.cos(ALPHA))


def test_frame_not_blank_and_body_at_com(frame):
    colours = np.unique(frame.reshape(-1, 3), axis=0)
    assert len(colours) > 20
    back, front = colour_mask(frame, BACK_BODY), colour_mask(frame, FRONT_BODY)
    assert back.sum() > 300 and front.sum() > 300
    # Camera on x_g, so the COM is drawn at the centre column, y_g above the ground row.
    u_com = W / 2 + SCALE * Y0[1] * math.sin(ALPHA)
    v_com = GROUND_ROW_FRAC * H - SCALE * Y0[1] * math.cos(ALPHA)
    cu, cv = centroid(back | front)
    assert abs(cu - u_com) < 6 and abs(cv - v_com) < 6
    # The back body is drawn behind (left of) the COM, the front body ahead of it.
    assert centroid(back)[0] < u_com - 40 < u_com + 40 < centroid(front)[0]
    # Body colours above the ground row only; the ground below the camera is not sky.
    assert not body_mask(frame)[int(GROUND_ROW_FRAC * H) + 5 :].any()
    assert frame[H - 5, W // 2, 2] < frame[5, W // 2, 2] - 50  # brown ground vs blue sky


def test_moving_com_shifts_body_with_camera_fixed():
    aux = aux_for(Y0, False, False)
    y1 = Y0.copy()
    y1[0] += 0.25
    f0 = render_frame(Y0, aux, camera_x=0.0)
    f1 = render_frame(y1, aux, camera_x=0.0)
    (u0, v0), (u1, v1) = centroid(body_mask(f0)), centroid(body_mask(f1))
    assert u1 - u0 == pytest.approx(0.25 * SCALE * math.cos(ALPHA), abs=3)
    assert v1 - v0 == pytest.approx(0.25 * SCALE * math.sin(ALPHA), abs=3)


def test_camera_follows_com_by_default():
    aux = aux_for(Y0, False, False)
    y1 = Y0.copy()
    y1[0] += 0.25
    c0, c1 = centroid(body_mask(render_frame(Y0, aux))), centroid(body_mask(render_frame(y1, aux)))
    assert c1 == pytest.approx(c0, abs=1)
    # ...while the ground ticks move: the frames differ below the ground line.
    f0, f1 = render_frame(Y0, aux), render_frame(y1 + [0.1, 0, 0, 0, 0, 0, 0, 0], aux)
    assert (f0[int(GROUND_ROW_FRAC * H) + 3 :] != f1[int(GROUND_ROW_FRAC * H) + 3 :]).any()


def test_stance_and_flight_legs_differ():
    stance = render_frame(Y0, aux_for(Y0, True, False))
    flight = render_frame(Y0, aux_for(Y0, False, False))
    assert (stance != flight).any()
    # Stance colour only where a leg is in stance; a flight leg has its own lighter colour.
    assert colour_mask(stance, LEG_STANCE).sum() > 100
    assert colour_mask(flight, LEG_STANCE).sum() == 0
    assert colour_mask(flight, LEG_FLIGHT).sum() > 2 * colour_mask(stance, LEG_FLIGHT).sum() > 0
    # The stance leg reaches the ground at its toe; the flight leg ends above the ground.
    aux = aux_for(Y0, True, False)
    ut, vt = slope_to_pixel(aux[A_XB], 0.0, ALPHA, Y0[0], W, H, METERS)
    rows, cols = np.nonzero(colour_mask(stance, LEG_STANCE))
    assert abs(rows.max() - vt) < 10 and abs(cols[rows.argmax()] - ut) < 10
    rows_f, _ = np.nonzero(colour_mask(flight, LEG_FLIGHT))
    assert rows_f.max() < GROUND_ROW_FRAC * H - 5


def test_spring_has_fixed_coil_count():
    long = spring_points((0.0, 0.0), (0.0, -0.32))
    short = spring_points((0.0, 0.0), (0.0, -0.16))
    assert len(long) == len(short)
    for pts, end in ((long, -0.32), (short, -0.16)):
        assert np.allclose(pts[0], (0.0, 0.0)) and np.allclose(pts[-1], (0.0, end))
        assert np.all(np.diff(pts[:, 1]) <= 0)  # monotone from hip to toe
    assert np.ptp(short[:, 0]) == pytest.approx(np.ptp(long[:, 0]))  # same coil width


def test_text_overlay_top_left_only(frame):
    r = Renderer("rgb_array", W, H)
    plain = r.render(Y0, aux_for(Y0, True, True))
    texted = r.render(Y0, aux_for(Y0, True, True), text="t=0.12 s  phase=ds")
    assert np.array_equal(plain, frame)
    diff = np.nonzero((plain != texted).any(axis=2))
    assert len(diff[0]) > 20
    assert diff[0].max() < 40 and diff[1].max() < 200


def test_renderer_modes():
    with pytest.raises(ValueError):
        Renderer("ansi", W, H)
    pytest.importorskip("matplotlib")
    import matplotlib

    matplotlib.use("Agg")
    r = Renderer("human", 160, 90)
    assert r.render(Y0, aux_for(Y0, True, False), text="x") is None
    assert r.render(Y0, aux_for(Y0, False, True)) is None
    r.close()
    r.close()


def test_import_is_lazy():
    code = (
        "import sys, bound_env.envs.render; "
        "assert 'matplotlib' not in sys.modules, 'matplotlib imported'; "
        "assert 'pygame' not in sys.modules"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


def test_save_gif(tmp_path):
    frames = []
    for i in range(5):
        y = Y0.copy()
        y[0] += 0.05 * i
        frames.append(render_frame(y, aux_for(Y0, i % 2 == 0, False), 160, 90, camera_x=0.0))
    path = save_gif(frames, tmp_path / "sub" / "anim.gif", fps=20)
    with Image.open(path) as im:
        assert im.format == "GIF"
        assert im.n_frames == 5
        assert im.size == (160, 90)
        assert im.info.get("loop") == 0
        assert im.info.get("duration") == 50
    with pytest.raises(ValueError):
        save_gif([], tmp_path / "empty.gif")
