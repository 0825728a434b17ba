"""Side-view rendering of the two-body bounding model (Pillow drawing, no pygame).

The picture is the slope-aligned model frame rotated by the slope angle alpha, so the slope
descends to the right and the robot runs to the right. The camera follows the centre of mass
along the slope; the ground carries a tick mark every 0.25 m so that motion is visible.

Drawn, back to front: sky, ground with ticks, the legs as zigzag springs from hip to toe (a
fixed number of coils, so a compressed leg shows tighter coils; stance legs in a strong colour,
flight legs lighter and at their touchdown angle with rest length), feet as dots, the back and
front bodies as thick bars of different colours, the spine joint as a circle, and an optional
text overlay. Shapes are drawn at `SUPERSAMPLE` times the size and shrunk, which smooths edges.

Nothing is computed at import; matplotlib is imported only by a ``"human"`` `Renderer`.
"""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from ..model.dynamics import A_CB, A_CF, A_XB, A_XF, back_hip, front_hip, spine_joint
from ..model.params import P_ALPHA, P_GB, P_GF, P_LB, P_LF

SUPERSAMPLE = 3  # shapes are drawn this many times larger, then shrunk (anti-aliasing)
GROUND_ROW_FRAC = 0.78  # the ground under the camera sits at this fraction of the height
TICK_SPACING = 0.25  # [m] along the slope

# Colours (RGB).
SKY_TOP = (150, 195, 235)
SKY_BOTTOM = (222, 236, 248)
GROUND = (128, 106, 78)
GROUND_EDGE = (80, 130, 58)
TICK = (238, 228, 200)
BACK_BODY = (40, 90, 200)
FRONT_BODY = (225, 120, 30)
SPINE_FILL = (250, 250, 250)
OUTLINE = (25, 25, 30)
LEG_STANCE = (200, 25, 60)
LEG_FLIGHT = (235, 160, 175)
FOOT_STANCE = (20, 20, 20)
FOOT_FLIGHT = (150, 150, 160)

# Sizes in metres, so that they scale with the zoom.
BODY_WIDTH = 0.045
SPINE_RADIUS = 0.02
HIP_RADIUS = 0.01
SPRING_WIDTH = 0.008
SPRING_AMPLITUDE = 0.022
SPRING_LEAD = 0.035  # straight wire at each end of a spring
SPRING_COILS = 7
FOOT_RADIUS = 0.014
TICK_DEPTH = 0.035


def slope_to_pixel(x, y, alpha, camera_x, width=640, height=360, meters_visible=1.6):
    """Slope-frame point(s) (x along the slope, y normal to it) -> image (column, row).

    Columns and rows are continuous pixel indices (pixel (r, c) is centred on (c, r)); the
    ground point under ``camera_x`` lands at column ``width/2``, row ``GROUND_ROW_FRAC*height``.
    """
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    s = width / meters_visible
    ca, sa = np.cos(alpha), np.sin(alpha)
    dx = x - camera_x
    u = width / 2 + s * (dx * ca + y * sa)
    v = GROUND_ROW_FRAC * height + s * (dx * sa - y * ca)
    return u, v


def spring_points(p0, p1, coils=SPRING_COILS, amplitude=SPRING_AMPLITUDE, lead=SPRING_LEAD):
    """Polyline of a zigzag spring from p0 to p1: straight leads, then ``coils`` full zigzags.

    The number of coils is fixed, so a shorter spring has tighter coils. Units are those of
    the points (the amplitude and lead are in the same units).
    """
    p0, p1 = np.asarray(p0, dtype=float), np.asarray(p1, dtype=float)
    d = p1 - p0
    length = float(np.hypot(*d))
    if length < 1e-12:
        return np.array([p0, p1])
    e = d / length
    n = np.array([-e[1], e[0]])
    lead = min(lead, 0.2 * length)
    k = np.arange(2 * coils + 1)
    along = lead + (length - 2 * lead) * (k + 0.5) / (2 * coils + 1)
    side = amplitude * np.where(k % 2 == 0, 1.0, -1.0)
    zig = p0 + along[:, None] * e + side[:, None] * n
    return np.vstack([p0, p0 + lead * e, zig, p1 - lead * e, p1])


@functools.lru_cache(maxsize=4)
def _sky(width, height):
    """Sky background: a vertical gradient (cached per size; callers draw on a copy)."""
    t = np.linspace(0.0, 1.0, height)[:, None, None]
    column = (1 - t) * np.array(SKY_TOP) + t * np.array(SKY_BOTTOM)
    return Image.fromarray(np.round(column).astype(np.uint8)).resize((width, height))


def _leg_toe(hip, aux, stance, toe_index, gamma_index, rest_index):
    """Toe of a leg: its ground point in stance, else at touchdown angle and rest length."""
    if aux[stance] > 0.5:
        return aux[toe_index], 0.0
    g, lbar = aux[gamma_index], aux[rest_index]
    return hip[0] + lbar * np.sin(g), hip[1] - lbar * np.cos(g)


def render_frame(y, aux, width=640, height=360, meters_visible=1.6, camera_x=None, text=None):
    """One RGB frame, shape (height, width, 3), uint8, of state ``y`` with contacts ``aux``.

    ``camera_x`` is the slope coordinate shown at the image centre (default: x_g = y[0]).
    ``text``, if given, is written in the top-left corner.
    """
    y = np.asarray(y, dtype=float)
    aux = np.asarray(aux, dtype=float)
    alpha = float(aux[P_ALPHA])
    cam = float(y[0]) if camera_x is None else float(camera_x)
    k = SUPERSAMPLE
    W, H = width * k, height * k
    px = k * width / meters_visible  # supersampled pixels per metre

    def to_px(x, yy):
        u, v = slope_to_pixel(x, yy, alpha, cam, width, height, meters_visible)
        return k * u + (k - 1) / 2, k * v + (k - 1) / 2

    def pt(p):
        u, v = to_px(p[0], p[1])
        return float(u), float(v)

    def disc(c, r, fill, outline=None, w=0):
        draw.ellipse([c[0] - r, c[1] - r, c[0] + r, c[1] + r], fill=fill, outline=outline, width=w)

    def bar(a, b, w, fill):
        draw.line([a, b], fill=fill, width=w)
        disc(a, w / 2, fill)
        disc(b, w / 2, fill)

    img = _sky(W, H).copy()
    draw = ImageDraw.Draw(img)

    # Ground: a polygon under the slope line, with ticks every TICK_SPACING along the slope.
    half = 0.5 * meters_visible / max(np.cos(alpha), 0.1) + 0.5
    x_lo, x_hi = cam - half, cam + half
    a, b = pt((x_lo, 0.0)), pt((x_hi, 0.0))
    draw.polygon([a, b, (b[0], H + 10 * W), (a[0], H + 10 * W)], fill=GROUND)
    edge = max(1, round(0.006 * px))
    draw.line([a, b], fill=GROUND_EDGE, width=edge)
    for i in range(int(np.ceil(x_lo / TICK_SPACING)), int(np.floor(x_hi / TICK_SPACING)) + 1):
        xt = i * TICK_SPACING
        major = i % 4 == 0  # every metre
        depth = TICK_DEPTH * (2.0 if major else 1.0)
        draw.line(
            [pt((xt, -0.004)), pt((xt, -depth))],
            fill=TICK,
            width=max(1, round((0.006 if major else 0.004) * px)),
        )

    # Body points (slope frame).
    hb, sj, hf = back_hip(y, aux), spine_joint(y, aux), front_hip(y, aux)

    # Legs: springs from hip to toe, then feet.
    legs = (
        (hb, A_CB, _leg_toe(hb, aux, A_CB, A_XB, P_GB, P_LB)),
        (hf, A_CF, _leg_toe(hf, aux, A_CF, A_XF, P_GF, P_LF)),
    )
    for hip, stance, toe in legs:
        colour = LEG_STANCE if aux[stance] > 0.5 else LEG_FLIGHT
        pts = spring_points(
            pt(hip), pt(toe), amplitude=SPRING_AMPLITUDE * px, lead=SPRING_LEAD * px
        )
        draw.line(
            [tuple(p) for p in pts],
            fill=colour,
            width=max(1, round(SPRING_WIDTH * px)),
            joint="curve",
        )
    for _, stance, toe in legs:
        disc(pt(toe), FOOT_RADIUS * px, FOOT_STANCE if aux[stance] > 0.5 else FOOT_FLIGHT)

    # Bodies, hips and spine joint.
    bw = max(2, round(BODY_WIDTH * px))
    bar(pt(hb), pt(sj), bw, BACK_BODY)
    bar(pt(sj), pt(hf), bw, FRONT_BODY)
    for hip in (hb, hf):
        disc(pt(hip), HIP_RADIUS * px, OUTLINE)
    disc(pt(sj), SPINE_RADIUS * px, SPINE_FILL, OUTLINE, max(1, round(0.005 * px)))

    img = img.resize((width, height), Image.Resampling.BOX)
    if text:
        _overlay_text(img, text)
    return np.asarray(img, dtype=np.uint8)


def _overlay_text(img, text):
    """Write ``text`` in the top-left corner on a translucent white box (in place)."""
    draw = ImageDraw.Draw(img, "RGBA")
    font = ImageFont.load_default()
    x0, y0, x1, y1 = draw.multiline_textbbox((6, 5), text, font=font)
    draw.rectangle([x0 - 4, y0 - 3, x1 + 4, y1 + 3], fill=(255, 255, 255, 190))
    draw.multiline_text((6, 5), text, fill=(0, 0, 0, 255), font=font)


class Renderer:
    """Frames for an environment: ``"rgb_array"`` returns them, ``"human"`` shows them.

    Human mode opens one matplotlib window (imported lazily), reused for every frame; a
    window closed by the user is reopened on the next call.
    """

    MODES = ("human", "rgb_array")

    def __init__(self, render_mode, width=640, height=360, meters_visible=1.6):
        if render_mode not in self.MODES:
            raise ValueError(f"render_mode must be one of {self.MODES}, got {render_mode!r}")
        self.render_mode = render_mode
        self.width, self.height, self.meters_visible = int(width), int(height), meters_visible
        self._plt = self._fig = self._im = None

    def render(self, y, aux, text=None):
        """The frame of state ``y`` (camera on x_g); shown and None in human mode."""
        frame = render_frame(y, aux, self.width, self.height, self.meters_visible, text=text)
        if self.render_mode == "rgb_array":
            return frame
        self._show(frame)
        return None

    def _show(self, frame):
        if self._plt is None:
            import matplotlib.pyplot as plt

            self._plt = plt
        plt = self._plt
        if self._fig is None or not plt.fignum_exists(self._fig.number):
            plt.ion()
            dpi = 100
            self._fig = plt.figure(figsize=(self.width / dpi, self.height / dpi), dpi=dpi)
            ax = self._fig.add_axes((0, 0, 1, 1))
            ax.set_axis_off()
            self._im = ax.imshow(frame, interpolation="nearest")
        else:
            self._im.set_data(frame)
        self._fig.canvas.draw_idle()
        plt.pause(1e-3)

    def close(self):
        """Close the window, if one is open."""
        if self._fig is not None and self._plt is not None:
            self._plt.close(self._fig)
        self._fig = self._im = None


def save_gif(frames, path, fps=30):
    """Write ``frames`` (an iterable of H x W x 3 uint8 arrays) as an animated GIF that loops
    forever, streamed (`VideoWriter`: one frame in memory at a time).

    GIF stores delays in hundredths of a second, so the frame time is rounded to 10 ms.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "wb") as f:
        gif = _GifStream(f, fps)
        for frame in frames:
            gif.append(frame)
        if gif.n_frames == 0:
            raise ValueError("save_gif needs at least one frame")
        gif.close()
    return path


class _GifStream:
    """An animated GIF written frame by frame to an open binary file: each frame is quantized
    to its own 256-colour palette (a local colour table; fast octree, a mean error of about
    one level in 255 on the rendered frames) and encoded at once, so memory does
    not grow with the number of frames (Pillow's ``save_all`` keeps every frame until the end).
    """

    def __init__(self, f, fps):
        self.f, self.n_frames = f, 0
        self.duration = max(10, round(1000 / fps))  # ms, a multiple of 10 in the file

    def append(self, frame) -> None:
        from PIL import GifImagePlugin

        frame = np.asarray(frame)
        if frame.ndim != 3 or frame.shape[2] != 3:
            raise ValueError(f"a video frame must be H x W x 3, got shape {frame.shape}")
        im = Image.fromarray(np.ascontiguousarray(frame, dtype=np.uint8))
        q = im.quantize(256, method=Image.Quantize.FASTOCTREE)  # ~5x faster than median cut
        if self.n_frames == 0:
            self.size = im.size
            header, _ = GifImagePlugin.getheader(q.copy(), info={"loop": 0, "duration": 1})
            self.f.write(b"".join(header))
        elif im.size != self.size:
            raise ValueError(f"video frames must all be {self.size}, got {im.size}")
        data = GifImagePlugin.getdata(q, duration=self.duration, include_color_table=True)
        for chunk in data:
            self.f.write(chunk)
        # the list belongs to a class Pillow makes per call, which only the cyclic garbage
        # collector frees: empty it now, or the encoded frames pile up until it runs
        data.clear()
        self.n_frames += 1

    def close(self) -> None:
        self.f.write(b";")  # the GIF trailer


class VideoWriter:
    """Streams frames to an animation file: ``append(frame)`` encodes the frame and lets it
    go, so a video's memory does not depend on its length. A GIF (Pillow, at most 50 frames
    per second are honoured by players) or an MP4 (needs imageio with ffmpeg: ``pip install
    imageio-ffmpeg``). Written atomically (`bound_env.files.cache.atomic_path`): the file appears
    when the ``with`` block ends without error, and nothing is left behind otherwise. For
    example:

    ```python
    with VideoWriter("run.gif", fps=25) as video:
        for frame in frames:
            video.append(frame)
    ```
    """

    def __init__(self, path, fps):
        self.path = Path(path)
        suffix = self.path.suffix.lower()
        if suffix not in (".gif", ".mp4"):
            raise ValueError(f"{self.path}: an animation must end in .gif or .mp4")
        if not (isinstance(fps, (int, float)) and np.isfinite(fps) and fps > 0):
            raise ValueError(f"fps must be a positive number, got {fps!r}")
        self.fps, self.n_frames = fps, 0
        self._stack = self._sink = None

    def __enter__(self) -> VideoWriter:
        from contextlib import ExitStack

        from ..files.cache import atomic_path

        self.path.parent.mkdir(parents=True, exist_ok=True)
        with ExitStack() as stack:
            tmp = stack.enter_context(atomic_path(self.path, suffix=self.path.suffix))
            if self.path.suffix.lower() == ".gif":
                self._sink = _GifStream(stack.enter_context(open(tmp, "wb")), self.fps)
            else:
                self._sink = _mp4_writer(tmp, self.path, self.fps)
                stack.callback(self._sink.close)
            self._stack = stack.pop_all()
        return self

    def append(self, frame) -> None:
        """Encode one H x W x 3 uint8 frame."""
        try:
            if isinstance(self._sink, _GifStream):
                self._sink.append(frame)
            else:
                self._sink.append_data(np.ascontiguousarray(frame, dtype=np.uint8))
        except ValueError:
            raise
        except Exception as e:  # noqa: BLE001 - an ffmpeg pipe that broke
            raise ValueError(f"cannot write {self.path}: {e}") from None
        self.n_frames += 1

    def __exit__(self, exc_type, exc, tb):
        if exc_type is None and self.n_frames == 0:
            exc_type, exc = ValueError, ValueError(f"{self.path}: a video needs at least one frame")
            self._stack.__exit__(exc_type, exc, None)
            raise exc
        if exc_type is None and isinstance(self._sink, _GifStream):
            self._sink.close()
        return self._stack.__exit__(exc_type, exc, tb)


def _mp4_writer(tmp, path, fps):
    try:
        import imageio.v2 as imageio
    except ModuleNotFoundError:
        raise ValueError(
            f"{path}: an .mp4 needs imageio with ffmpeg (pip install imageio-ffmpeg); "
            "a .gif works without it"
        ) from None
    try:
        # macro_block_size=1: keep the frame size (640 x 360 is not a multiple of 16)
        return imageio.get_writer(tmp, format="FFMPEG", fps=fps, macro_block_size=1)
    except Exception as e:  # noqa: BLE001 - no ffmpeg backend
        raise ValueError(f"cannot write {path}: {e}; write a .gif instead") from None


def write_video(frames, path, fps) -> Path:
    """An animation file of ``frames`` (any iterable: a generator is never held in memory),
    streamed through `VideoWriter` and written atomically (`bound_env.files.cache.atomic_path`)."""
    path = Path(path)
    with VideoWriter(path, fps) as video:
        for frame in frames:
            video.append(frame)
    return path
