"""The viewer's pure logic (no window, no OpenGL): camera controller, sampling-rate steps, pane layout, loupe,
resolution drop while moving, debug visualisations, settings persistence and recent files, shortcuts.

Everything here is unit-tested without a display (tests/test_app_logic.py); `gbviewer.app.window` draws it.
"""

from __future__ import annotations

import json
import math
import os
import struct
import time
import zlib
from collections import deque
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from ..camera import UP_AXES, Camera, focal_from_fov, format_rate, fov_of, frame_box, orbit_direction
from ..render import Mode

# ---- sampling rate -------------------------------------------------------------------------------------------------

RATE_STEPS = (8.0, 4.0, 2.0, 1.0, 0.5, 0.25, 0.125)
RATE_MIN, RATE_MAX = 0.125, 8.0


def clamp_rate(rate: float) -> float:
    if not (isinstance(rate, (int, float)) and math.isfinite(rate) and rate > 0):
        return 1.0
    return float(min(RATE_MAX, max(RATE_MIN, rate)))


def step_rate(rate: float, direction: int) -> float:
    """The next step of RATE_STEPS above (direction > 0, more pixels) or below (direction < 0) `rate`.

    From a continuous value between two steps this goes to the neighbouring step in that direction.
    """
    rate = clamp_rate(rate)
    eps = 1e-9
    if direction > 0:
        above = [s for s in RATE_STEPS if s > rate * (1 + eps)]
        return min(above) if above else RATE_MAX
    below = [s for s in RATE_STEPS if s < rate * (1 - eps)]
    return max(below) if below else RATE_MIN


def rate_to_slider(rate: float) -> float:
    """log2 of the rate: the slider runs linearly from -3 (x1/8) to 3 (x8)."""
    return math.log2(clamp_rate(rate))


def slider_to_rate(value: float, snap: float = 0.04) -> float:
    """Inverse of rate_to_slider; values within `snap` (log2 units) of a step snap onto it."""
    value = min(3.0, max(-3.0, float(value)))
    nearest = round(value)
    if abs(value - nearest) <= snap:
        value = nearest
    return clamp_rate(2.0 ** value)


def render_size(width: int, height: int, rate: float) -> tuple[int, int]:
    """The render resolution of a pane of width x height display pixels at `rate` (as Camera.at_sampling_rate)."""
    return max(1, round(width * rate)), max(1, round(height * rate))


# ---- resolution drop while the camera moves ------------------------------------------------------------------------

PREVIEW_FACTORS = (1.0, 0.5, 0.25, 0.125)


def preview_factor(pixels: int, ms_per_pixel: float | None, budget_ms: float, moving: bool) -> float:
    """Fraction of the render resolution (per axis) to use while the camera moves, so that one render takes about
    `budget_ms`; 1 when still, when nothing was measured yet, or when the full render fits the budget."""
    if not moving or not ms_per_pixel or ms_per_pixel <= 0 or pixels <= 0:
        return 1.0
    for f in PREVIEW_FACTORS:
        if pixels * f * f * ms_per_pixel <= budget_ms or f == PREVIEW_FACTORS[-1]:
            return f
    return PREVIEW_FACTORS[-1]


# ---- pane layout and loupe -----------------------------------------------------------------------------------------

LAYOUTS = ("row", "grid")


@dataclass(frozen=True)
class Rect:
    x: int
    y: int
    w: int
    h: int

    def contains(self, px: float, py: float) -> bool:
        return self.x <= px < self.x + self.w and self.y <= py < self.y + self.h


def grid_shape(n: int, layout: str) -> tuple[int, int]:
    """(rows, cols) for n panes: 'row' puts them side by side, 'grid' 2x2 (for 3 or 4 panes; 1 or 2 stay a row)."""
    if layout == "grid" and n >= 3:
        return 2, 2
    return 1, max(1, n)


def pane_rects(x: int, y: int, w: int, h: int, n: int, layout: str = "row", gap: int = 4) -> list[Rect]:
    """Integer rectangles of n panes filling (x, y, w, h), `gap` pixels apart, row-major."""
    rows, cols = grid_shape(n, layout)
    out = []
    for k in range(n):
        r, c = divmod(k, cols)
        x0 = x + (c * (w + gap)) // cols
        x1 = x + ((c + 1) * (w + gap)) // cols - gap
        y0 = y + (r * (h + gap)) // rows
        y1 = y + ((r + 1) * (h + gap)) // rows - gap
        out.append(Rect(x0, y0, max(1, x1 - x0), max(1, y1 - y0)))
    return out


def loupe_uv(u: float, v: float, pane_w: int, pane_h: int, radius_px: float, zoom: float
             ) -> tuple[float, float, float, float]:
    """Texture rectangle (u0, v0, u1, v1) that a loupe of `radius_px` (display pixels, half its side) magnifying
    `zoom` times shows around the normalised pane position (u, v); kept inside the pane."""
    half_u = radius_px / zoom / pane_w
    half_v = radius_px / zoom / pane_h
    cu = min(max(u, half_u), 1 - half_u) if half_u < 0.5 else 0.5
    cv = min(max(v, half_v), 1 - half_v) if half_v < 0.5 else 0.5
    return cu - half_u, cv - half_v, cu + half_u, cv + half_v


def split_parts(split_pos: float) -> tuple[tuple[float, float], tuple[float, float]]:
    """Horizontal texture ranges (u0, u1) of the left (first mode) and right (second mode) parts of a split pane."""
    s = min(1.0, max(0.0, split_pos))
    return (0.0, s), (s, 1.0)


# ---- camera controller ---------------------------------------------------------------------------------------------


def _rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    axis = np.asarray(axis, np.float64)
    axis = axis / np.linalg.norm(axis)
    x, y, z = axis
    c, s = math.cos(angle), math.sin(angle)
    K = np.array([[0, -z, y], [z, 0, -x], [-y, x, 0]])
    return c * np.eye(3) + s * K + (1 - c) * np.outer(axis, axis)


@dataclass
class CameraController:
    """One camera shared by every pane: a world-to-camera rotation R (OpenCV axes, rows x right, y down, z forward),
    an orbit target and the distance to it (the eye is target - distance * forward), a vertical field of view and
    the scene's up axis. Orbit and mouse look turn about the world up axis and the camera's x axis."""

    target: np.ndarray = field(default_factory=lambda: np.zeros(3))
    distance: float = 3.0
    R: np.ndarray = field(default_factory=lambda: np.eye(3))
    fov_y_deg: float = 50.0
    up: str = "-y"
    radius: float = 1.0  # scene size: sets pan, fly and dolly limits
    centre: np.ndarray = field(default_factory=lambda: np.zeros(3))
    orbit_speed: float = 0.3  # degrees per pixel

    MIN_FOV, MAX_FOV = 5.0, 120.0

    @property
    def up_vector(self) -> np.ndarray:
        return np.array(UP_AXES[self.up], np.float64)

    @property
    def forward(self) -> np.ndarray:
        return self.R[2].copy()

    @property
    def eye(self) -> np.ndarray:
        return self.target - self.distance * self.R[2]

    def camera(self, width: int, height: int) -> Camera:
        """A centred pinhole camera of width x height pixels with this pose and vertical field of view."""
        f = focal_from_fov(self.fov_y_deg, height)
        return Camera(width, height, f, f, width / 2, height / 2, self.R, -self.R @ self.eye)

    def frame_bounds(self, lo: np.ndarray, hi: np.ndarray, azimuth_deg: float = 30.0, elevation_deg: float = 20.0,
                     aspect: float = 4 / 3) -> None:
        """Default framing of the box lo..hi (as gbviewer.orbit_camera): orbit around its centre, far enough to see
        all of it."""
        lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
        self.centre, self.radius, self.distance = frame_box(lo, hi, self.fov_y_deg, aspect)
        self.target = self.centre.copy()
        self._look(self.target + self.distance * orbit_direction(self.up_vector, azimuth_deg, elevation_deg),
                   self.target)

    def _look(self, eye: np.ndarray, target: np.ndarray) -> None:
        cam = Camera.look_at(eye, target, self.up_vector, 64, 64, self.fov_y_deg)
        self.R = cam.R.copy()
        self.target = np.asarray(target, np.float64).copy()
        self.distance = float(np.linalg.norm(np.asarray(target) - np.asarray(eye)))

    def _turn(self, about_eye: bool, yaw: float, pitch: float) -> None:
        """Rotate the camera about the world up axis (yaw) and its own x axis (pitch), through the target (orbit)
        or the eye (look); pitch stops short of the poles and never turns the view upside down."""
        up = self.up_vector
        eye = self.eye
        rot = _rotation(up, yaw)
        R = self.R @ rot.T
        if pitch:
            rp = _rotation(R[0], pitch)
            R2 = R @ rp.T
            upright = float(self.R[1] @ -up) >= 0
            if abs(float(R2[2] @ up)) < 0.995 and (float(R2[1] @ -up) > 0) == upright:
                R = R2
        self.R = R
        if about_eye:
            self.target = eye + self.distance * R[2]

    def orbit(self, dx: float, dy: float) -> None:
        """Left drag: turn around the target by dx, dy pixels (drag right: the scene turns right)."""
        k = math.radians(self.orbit_speed)
        self._turn(False, -dx * k * self._up_sign(), -dy * k)

    def look(self, dx: float, dy: float) -> None:
        """Fly-mode mouse look: turn in place (drag right: look right)."""
        k = math.radians(self.orbit_speed) * 0.5
        self._turn(True, -dx * k * self._up_sign(), -dy * k)

    def _up_sign(self) -> float:
        # yaw about the world up axis turns the view right for positive angles when camera -y is along up
        return 1.0 if float(self.R[1] @ -self.up_vector) >= 0 else -1.0

    def pan(self, dx: float, dy: float, viewport_h: int) -> None:
        """Right/middle drag: the point under the cursor follows it (at the target's depth)."""
        scale = 2 * self.distance * math.tan(math.radians(self.fov_y_deg) / 2) / max(1, viewport_h)
        self.target = self.target - (dx * self.R[0] + dy * self.R[1]) * scale

    def dolly(self, steps: float) -> None:
        """Wheel: move towards (steps > 0) or away from the target, 10% of the distance per step."""
        self.distance = float(min(max(self.distance * 0.9 ** steps, 1e-3 * self.radius), 1e3 * self.radius))

    def fly(self, forward: float, right: float, upward: float, dt: float, speed: float = 1.0) -> None:
        """WASD/QE: move eye and target together, `speed` scene radii per second (upward is along the scene up)."""
        step = self.radius * speed * dt
        move = forward * self.R[2] + right * self.R[0] + upward * self.up_vector
        self.target = self.target + step * move

    def set_fov(self, fov_y_deg: float) -> None:
        self.fov_y_deg = float(min(self.MAX_FOV, max(self.MIN_FOV, fov_y_deg)))

    def set_up(self, up: str) -> None:
        """Change the scene's up axis and level the view to it (same eye and target)."""
        if up not in UP_AXES:
            raise ValueError(f"up axis {up!r}; expected one of {sorted(UP_AXES)}")
        eye, target = self.eye, self.target
        self.up = up
        self._look(eye, target)

    def snap_to(self, camera: Camera) -> None:
        """Take a (training) camera's pose and vertical field of view; the target stays `distance` ahead."""
        self.R = camera.R.copy()
        self.fov_y_deg = float(min(self.MAX_FOV, max(self.MIN_FOV, fov_of(camera))))
        dist = float(np.linalg.norm(self.centre - camera.position))
        self.distance = dist if dist > 1e-6 else self.distance
        self.target = camera.position + self.distance * self.R[2]

    def state(self) -> tuple:
        """A hashable summary (changes whenever the rendered view would)."""
        return (tuple(np.round(self.R.ravel(), 12)), tuple(np.round(self.target, 12)), round(self.distance, 12),
                round(self.fov_y_deg, 9))


# ---- debug views ---------------------------------------------------------------------------------------------------

VIEWS = ("color", "alpha", "transmittance", "window", "evals")
VIEW_HELP = {
    "color": "the image",
    "alpha": "accumulated alpha (1 - final transmittance), black 0 to white 1",
    "transmittance": "final transmittance T, black 0 to white 1",
    "window": "Gaussian Blending's final window size per pixel (sqrt(w*h), output pixels), viridis 0..max",
    "evals": "splats evaluated per pixel, viridis 0..max",
}

_VIRIDIS = np.array([[0.267, 0.005, 0.329], [0.283, 0.141, 0.458], [0.254, 0.265, 0.530], [0.207, 0.372, 0.553],
                     [0.164, 0.471, 0.558], [0.128, 0.567, 0.551], [0.135, 0.659, 0.518], [0.267, 0.749, 0.441],
                     [0.478, 0.821, 0.318], [0.741, 0.873, 0.150], [0.993, 0.906, 0.144]], np.float32)


def viridis(x: np.ndarray) -> np.ndarray:
    """Values in [0, 1] to RGB (an 11-point approximation of matplotlib's viridis)."""
    x = np.clip(np.nan_to_num(np.asarray(x, np.float32)), 0, 1) * (len(_VIRIDIS) - 1)
    i = np.minimum(x.astype(np.int32), len(_VIRIDIS) - 2)
    t = (x - i)[..., None]
    return _VIRIDIS[i] * (1 - t) + _VIRIDIS[i + 1] * t


def visualize(frame, view: str) -> tuple[np.ndarray, str]:
    """The RGB image (H, W, 3 float in [0, 1]) a pane shows for `view`, and a legend ('' for colour).

    'window' falls back to colour (saying so) when the frame has no window plane (modes other than
    gaussian_blending)."""
    if view == "alpha":
        a = np.clip(frame.alpha, 0, 1)
        return np.repeat(a[..., None], 3, axis=2), "alpha 0..1"
    if view == "transmittance":
        t = np.clip(1 - frame.alpha, 0, 1)
        return np.repeat(t[..., None], 3, axis=2), "transmittance 0..1"
    if view == "evals":
        ev = np.asarray(frame.debug.get("evals", np.zeros(frame.alpha.shape)), np.float32)
        top = max(1.0, float(ev.max()))
        return viridis(ev / top), f"evaluations/pixel 0..{top:.0f}"
    if view == "window":
        win = frame.debug.get("window")
        if win is None:
            return frame.rgb, "window: gaussian_blending only"
        size = np.sqrt(np.maximum(win[..., 0], 0) * np.maximum(win[..., 1], 0))
        top = max(1e-6, float(size.max()))
        return viridis(size / top), f"window size 0..{top:.2f} px"
    return frame.rgb, ""


# ---- frame rate ----------------------------------------------------------------------------------------------------


class RateMeter:
    """Events per second over the last `span` seconds."""

    def __init__(self, span: float = 2.0) -> None:
        self.span = span
        self.times: deque[float] = deque()

    def tick(self, t: float | None = None) -> None:
        t = time.perf_counter() if t is None else t
        self.times.append(t)
        while self.times and self.times[0] < t - self.span:
            self.times.popleft()

    def rate(self, now: float | None = None) -> float:
        now = time.perf_counter() if now is None else now
        ts = [t for t in self.times if t >= now - self.span]
        if len(ts) < 2:
            return 0.0
        return (len(ts) - 1) / max(1e-9, ts[-1] - ts[0])


# ---- 16-bit PNG ----------------------------------------------------------------------------------------------------


def encode_png16(rgb: np.ndarray) -> bytes:
    """A 16-bit-per-channel RGB PNG of a float image in [0, 1] (clipped): a pane's render at full precision."""
    img = np.clip(np.nan_to_num(np.asarray(rgb, np.float64)), 0, 1)
    h, w = img.shape[:2]
    data = np.round(img[..., :3] * 65535).astype(">u2")
    raw = b"".join(b"\x00" + data[r].tobytes() for r in range(h))

    def chunk(tag: bytes, body: bytes) -> bytes:
        return struct.pack(">I", len(body)) + tag + body + struct.pack(">I", zlib.crc32(tag + body) & 0xFFFFFFFF)

    header = struct.pack(">IIBBBBB", w, h, 16, 2, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(raw, 6)) + chunk(b"IEND", b"")


def decode_png16(data: bytes) -> np.ndarray:
    """Inverse of encode_png16 (unfiltered rows only): (H, W, 3) uint16."""
    pos, idat, w, h = 8, b"", 0, 0
    while pos < len(data):
        (n,) = struct.unpack(">I", data[pos:pos + 4])
        tag, body = data[pos + 4:pos + 8], data[pos + 8:pos + 8 + n]
        if tag == b"IHDR":
            w, h = struct.unpack(">II", body[:8])
        elif tag == b"IDAT":
            idat += body
        pos += 12 + n
    raw = zlib.decompress(idat)
    rows = np.frombuffer(raw, np.uint8).reshape(h, 1 + w * 6)
    return rows[:, 1:].copy().view(">u2").reshape(h, w, 3).astype(np.uint16)


# ---- settings and recent files -------------------------------------------------------------------------------------

MODE_NAMES = tuple(m.label for m in Mode)
MAX_PANES = 4
MAX_RECENT = 10
PANE_NAMES = "ABCD"


@dataclass
class PaneSettings:
    mode: str = "scalar"
    supersample: int = 1
    view: str = "color"
    split: bool = False
    split_mode: str = "gaussian_blending"
    split_pos: float = 0.5

    def normalised(self) -> "PaneSettings":
        mode = self.mode if self.mode in MODE_NAMES else "scalar"
        split_mode = self.split_mode if self.split_mode in MODE_NAMES else "gaussian_blending"
        ss = int(self.supersample) if isinstance(self.supersample, (int, float)) else 1
        pos = float(self.split_pos) if isinstance(self.split_pos, (int, float)) and math.isfinite(self.split_pos) \
            else 0.5
        return PaneSettings(mode, min(8, max(1, ss)), self.view if self.view in VIEWS else "color",
                            bool(self.split), split_mode, min(1.0, max(0.0, pos)))


DEFAULT_PANES = [PaneSettings("scalar"), PaneSettings("gaussian_blending"), PaneSettings("scalar", 3),
                 PaneSettings("mip")]


@dataclass
class AppSettings:
    """Everything that persists between runs (JSON in the user's config dir)."""

    panes: list[PaneSettings] = field(default_factory=lambda: [PaneSettings(p.mode, p.supersample)
                                                               for p in DEFAULT_PANES])
    pane_count: int = 2
    layout: str = "row"
    rate: float = 1.0
    window: tuple[int, int] = (1400, 860)
    backend: str = "cpu"
    fov_y_deg: float = 50.0
    up: str = "-y"
    loupe: bool = False
    loupe_zoom: float = 8.0
    show_info: bool = True
    fly_speed: float = 0.5
    background: tuple[float, float, float] = (0.0, 0.0, 0.0)
    recent: list[str] = field(default_factory=list)
    screenshot_dir: str = ""

    def normalised(self) -> "AppSettings":
        s = AppSettings()
        panes = [PaneSettings(**{k: v for k, v in p.items() if k in PaneSettings.__dataclass_fields__})
                 if isinstance(p, dict) else p for p in (self.panes or [])][:MAX_PANES]
        panes = [p.normalised() for p in panes if isinstance(p, PaneSettings)]
        s.panes = panes + [PaneSettings(d.mode, d.supersample) for d in DEFAULT_PANES[len(panes):]]
        s.pane_count = min(MAX_PANES, max(1, int(self.pane_count))) if isinstance(self.pane_count, int) else 2
        s.layout = self.layout if self.layout in LAYOUTS else "row"
        s.rate = clamp_rate(self.rate)
        try:
            w, h = (int(v) for v in self.window)
            s.window = (min(8192, max(640, w)), min(8192, max(480, h)))
        except (TypeError, ValueError):
            pass
        s.backend = self.backend if isinstance(self.backend, str) else "cpu"
        if isinstance(self.fov_y_deg, (int, float)) and math.isfinite(self.fov_y_deg):
            s.fov_y_deg = float(min(CameraController.MAX_FOV, max(CameraController.MIN_FOV, self.fov_y_deg)))
        s.up = self.up if self.up in UP_AXES else "-y"
        s.loupe = bool(self.loupe)
        if isinstance(self.loupe_zoom, (int, float)) and math.isfinite(self.loupe_zoom):
            s.loupe_zoom = float(min(32, max(2, self.loupe_zoom)))
        s.show_info = bool(self.show_info)
        if isinstance(self.fly_speed, (int, float)) and math.isfinite(self.fly_speed):
            s.fly_speed = float(min(10, max(0.01, self.fly_speed)))
        try:
            bg = tuple(float(v) for v in self.background)
            if len(bg) == 3 and all(math.isfinite(v) for v in bg):
                s.background = tuple(min(1.0, max(0.0, v)) for v in bg)
        except (TypeError, ValueError):
            pass
        s.recent = [str(p) for p in (self.recent or []) if isinstance(p, str)][:MAX_RECENT]
        s.screenshot_dir = self.screenshot_dir if isinstance(self.screenshot_dir, str) else ""
        return s

    def to_json(self) -> str:
        d = asdict(self)
        d["version"] = 1
        return json.dumps(d, indent=2)

    @classmethod
    def from_json(cls, text: str) -> "AppSettings":
        d = json.loads(text)
        if not isinstance(d, dict):
            raise ValueError("settings file is not a JSON object")
        known = {k: v for k, v in d.items() if k in cls.__dataclass_fields__}
        return cls(**known).normalised()


def config_dir() -> Path:
    """The user's config folder for gbviewer ($XDG_CONFIG_HOME/gbviewer on Linux, via platformdirs)."""
    try:
        import platformdirs

        return Path(platformdirs.user_config_dir("gbviewer", appauthor=False))
    except ImportError:  # pragma: no cover - platformdirs is a dependency
        base = os.environ.get("XDG_CONFIG_HOME") or str(Path.home() / ".config")
        return Path(base) / "gbviewer"


def settings_path() -> Path:
    return config_dir() / "settings.json"


def load_settings(path: Path | None = None) -> tuple[AppSettings, str]:
    """Settings from `path` (default: the config dir), and a warning when the file was unreadable (then defaults)."""
    path = path or settings_path()
    if not path.exists():
        return AppSettings(), ""
    try:
        return AppSettings.from_json(path.read_text()), ""
    except (OSError, UnicodeDecodeError, ValueError, TypeError) as exc:
        return AppSettings(), f"{path}: unreadable settings ({exc}); using defaults"


def save_settings(settings: AppSettings, path: Path | None = None) -> Path:
    from ..io.files import atomic_write

    path = path or settings_path()
    text = settings.normalised().to_json()
    return atomic_write(path, lambda p: p.write_text(text), force=True)


def add_recent(recent: list[str], path: str | Path, limit: int = MAX_RECENT) -> list[str]:
    """`path` (absolute) first, without duplicates, at most `limit` entries."""
    p = str(Path(path).expanduser().resolve())
    return [p] + [r for r in recent if r != p][: limit - 1]


# ---- shortcuts -----------------------------------------------------------------------------------------------------

SHORTCUTS = (
    ("F1 or ?", "show / hide this help"),
    ("Ctrl+O", "open a scene (or a cameras.json)"),
    ("drop a file", "open it (scene or cameras.json)"),
    ("Left drag", "orbit around the target (fly mode: look around)"),
    ("Right / middle drag", "pan"),
    ("Wheel", "dolly towards / away from the target"),
    ("F", "fly mode on / off"),
    ("W A S D", "fly forward / left / back / right (fly mode)"),
    ("Q E", "fly down / up (fly mode)"),
    ("Shift", "fly 4x faster"),
    ("R", "reset the camera to the default framing"),
    ("[ ]", "previous / next training camera"),
    ("U", "next up axis (-y, +y, +z, -z)"),
    ("- =", "sampling rate one step down / up (x1/8 .. x8)"),
    ("0", "sampling rate x1"),
    ("1 2 3 4", "number of panes"),
    ("G", "panes side by side / 2x2 grid"),
    ("M / Shift+M", "next / previous mode of the pane under the cursor"),
    ("V", "split view in the pane under the cursor (drag the line)"),
    ("L", "magnifier loupe under the cursor"),
    ("I", "information overlay on the panes"),
    ("F12", "screenshot of the window (PNG)"),
    ("Shift+F12", "screenshot of the pane under the cursor (16-bit PNG at render resolution)"),
    ("Esc", "close help, leave fly mode"),
    ("Ctrl+Q", "quit"),
)


def has_display_env(env: dict | None = None) -> tuple[bool, str]:
    """Whether the environment names a display a window could open on: (yes, '') or (no, why)."""
    env = os.environ if env is None else env
    if not (env.get("DISPLAY") or env.get("WAYLAND_DISPLAY")):
        return False, "no display (neither DISPLAY nor WAYLAND_DISPLAY is set)"
    return True, ""


def is_cameras_file(path: str | Path) -> bool:
    """A file the viewer opens as training cameras rather than a scene."""
    return Path(path).suffix.lower() == ".json"
