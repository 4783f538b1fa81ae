"""The viewer's settings that persist between runs (JSON in the user's config folder) and the recent files."""

from __future__ import annotations

import json
import os
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Container

from ..core.errors import InvalidValue
from ..core.validate import array, integer, read_json, real
from ..model.camera import PROJECTIONS, UP_AXES
from ..render import AUTO, BACKEND_NAMES, Mode
from ..render.presets import PRESETS
from .camera.control import CameraController
from .frames.rates import clamp_rate
from .frames.views import VIEWS
from .ui.layout import LAYOUTS

# Panes render Gaussian Blending at the fast precision (AppState.settings_for); "+exact" is the reference kernel, to
# put beside it (the difference view shows what the precision changes).
MODE_NAMES = tuple(m.label for m in Mode) + ("gaussian_blending+exact",) + tuple(f"preset:{name}" for name in PRESETS)
MAX_PANES = 4
MAX_RECENT = 10
VERSION = 2  # of the settings file; 2: backend "auto"
PANE_NAMES = "ABCD"


def _number(value: Any, default: Any, lo: float | None = None, hi: float | None = None, integral: bool = False) -> Any:
    """A setting's number clamped to [lo, hi], or `default` when it is not a finite number (of the right kind):
    a hand-edited or corrupt settings file never stops the viewer."""
    try:
        x = integer(value, "setting") if integral else real(value, "setting")
    except InvalidValue:
        return default
    return x if lo is None or hi is None else min(hi, max(lo, x))


def _choice(value: Any, options: Container[str], default: str) -> str:
    return value if isinstance(value, str) and value in options else default


MAX_PANE_LOD = 64.0  # pixels: the panel's LOD slider's end


@dataclass
class PaneSettings:
    mode: str = "scalar"
    supersample: int = 1
    view: str = "color"
    split: bool = False
    split_mode: str = "gaussian_blending"
    split_pos: float = 0.5
    lod: float = 0.0  # the level-of-detail cut at this many pixels; 0: off (every splat)

    def normalised(self) -> "PaneSettings":
        return PaneSettings(
            _choice(self.mode, MODE_NAMES, "scalar"),
            _number(self.supersample, 1, 1, 8, integral=True),
            _choice(self.view, VIEWS, "color"),
            bool(self.split),
            _choice(self.split_mode, MODE_NAMES, "gaussian_blending"),
            _number(self.split_pos, 0.5, 0.0, 1.0),
            _number(self.lod, 0.0, 0.0, MAX_PANE_LOD),
        )


DEFAULT_PANES = [
    PaneSettings("scalar"),
    PaneSettings("gaussian_blending"),
    PaneSettings("scalar", 3),
    PaneSettings("mip"),
]


@dataclass
class AppSettings:
    """Everything that persists between runs (JSON in the user's config dir)."""

    panes: list[PaneSettings] = field(
        default_factory=lambda: [PaneSettings(p.mode, p.supersample) for p in DEFAULT_PANES]
    )
    pane_count: int = 2
    layout: str = "row"
    rate: float = 1.0
    window: tuple[int, int] = (1400, 860)
    backend: str = AUTO  # or cpu, glsl, cuda
    fov_y_deg: float = 50.0
    up: str = "-y"
    projection: str = "perspective"
    loupe: bool = False
    loupe_zoom: float = 8.0
    show_info: bool = False  # the info overlay (I)
    fly_speed: float = 0.5
    background: tuple[float, float, float] = (0.0, 0.0, 0.0)
    recent: list[str] = field(default_factory=list)
    screenshot_dir: str = ""

    def normalised(self) -> "AppSettings":
        s = AppSettings()
        panes = [
            PaneSettings(**{k: v for k, v in p.items() if k in PaneSettings.__dataclass_fields__})
            if isinstance(p, dict)
            else p
            for p in _listed(self.panes)
        ][:MAX_PANES]
        panes = [p.normalised() for p in panes if isinstance(p, PaneSettings)]
        s.panes = panes + [PaneSettings(d.mode, d.supersample) for d in DEFAULT_PANES[len(panes) :]]
        s.pane_count = _number(self.pane_count, 2, 1, MAX_PANES, integral=True)
        s.layout = _choice(self.layout, LAYOUTS, "row")
        s.rate = clamp_rate(_number(self.rate, 1.0))
        if isinstance(self.window, (list, tuple)) and len(self.window) == 2:
            s.window = (
                _number(self.window[0], s.window[0], 640, 8192, integral=True),
                _number(self.window[1], s.window[1], 480, 8192, integral=True),
            )
        s.backend = _choice(self.backend, BACKEND_NAMES, AUTO)
        s.fov_y_deg = float(_number(self.fov_y_deg, s.fov_y_deg, CameraController.MIN_FOV, CameraController.MAX_FOV))
        s.up = _choice(self.up, UP_AXES, "-y")
        s.projection = _choice(self.projection, PROJECTIONS, "perspective")
        s.loupe = bool(self.loupe)
        s.loupe_zoom = float(_number(self.loupe_zoom, s.loupe_zoom, 2, 32))
        s.show_info = bool(self.show_info)
        s.fly_speed = float(_number(self.fly_speed, s.fly_speed, 0.01, 10))
        try:
            s.background = tuple(min(1.0, max(0.0, v)) for v in array(self.background, "background", (3,)).tolist())
        except InvalidValue:
            pass
        s.recent = [p for p in _listed(self.recent) if isinstance(p, str)][:MAX_RECENT]
        s.screenshot_dir = self.screenshot_dir if isinstance(self.screenshot_dir, str) else ""
        return s

    def to_json(self) -> str:
        d = asdict(self)
        d["version"] = VERSION
        return json.dumps(d, indent=2)

    @classmethod
    def from_doc(cls, d: Any, what: str = "settings") -> "AppSettings":
        """Settings from a parsed JSON document: any value of a wrong type or range falls back to its default; only
        a document that is not an object raises (InvalidValue naming `what`)."""
        if not isinstance(d, dict):
            raise InvalidValue(f"{what}: not a JSON object")
        known = {k: v for k, v in d.items() if k in cls.__dataclass_fields__}
        if d.get("version") == 1 and known.get("backend") == "cpu":
            known["backend"] = AUTO  # version 1 saved its default, cpu, whatever the machine had: pick again
        return cls(**known).normalised()


def _listed(value: Any) -> list:
    return value if isinstance(value, list) else []


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
        return AppSettings.from_doc(read_json(path), str(path)), ""
    except InvalidValue as exc:
        return AppSettings(), f"{exc}; unreadable settings, using defaults"


def save_settings(settings: AppSettings, path: Path | None = None) -> Path:
    from ..core.files import atomic_write

    path = path or settings_path()
    text = settings.normalised().to_json()
    return atomic_write(path, lambda p: p.write_text(text), force=True)


def add_recent(recent: list[str], path: str | Path, limit: int = MAX_RECENT) -> list[str]:
    """`path` (absolute) first, without duplicates, at most `limit` entries."""
    p = str(Path(path).expanduser().resolve())
    return [p] + [r for r in recent if r != p][: limit - 1]
