"""The viewer's settings that persist between runs (JSON in the user's config folder) and the recent files."""

from __future__ import annotations

import json
import math
import os
from dataclasses import asdict, dataclass, field
from pathlib import Path

from ..camera import UP_AXES
from ..render import Mode
from .camera_control import CameraController
from .layout import LAYOUTS
from .rates import clamp_rate
from .views import VIEWS

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
