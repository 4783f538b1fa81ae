"""gbviewer: view trained 3D Gaussian Splatting scenes and compare Gaussian Blending with scalar blending."""

from __future__ import annotations

from pathlib import Path

from .core.cancel import CancelToken
from .core.errors import (
    BackendUnavailable,
    CallbackError,
    CameraError,
    Cancelled,
    GBViewerError,
    LoadCancelled,
    RenderCancelled,
    RenderError,
    SceneFormatError,
    VideoCancelled,
)
from .io import load, save
from .model.camera import Camera, load_cameras_json, orbit_camera
from .model.scene import Scene
from .render import (
    BackendChoice,
    Frame,
    FrameStats,
    Mode,
    PixelTrace,
    Renderer,
    RenderSettings,
    build_info,
    choose_backend,
    get_renderer,
    render,
    trace_pixel,
)

ASSETS = Path(__file__).parent / "assets"  # installed; a source checkout has it at the top level
if not ASSETS.is_dir():
    ASSETS = Path(__file__).resolve().parents[1] / "assets"
DEFAULT_SCENE = ASSETS / "fruit_drops_minimal.ply"

__all__ = [
    "ASSETS",
    "DEFAULT_SCENE",
    "BackendChoice",
    "BackendUnavailable",
    "CallbackError",
    "Camera",
    "CameraError",
    "CancelToken",
    "Cancelled",
    "Frame",
    "FrameStats",
    "GBViewerError",
    "LoadCancelled",
    "Mode",
    "PixelTrace",
    "RenderCancelled",
    "RenderError",
    "RenderSettings",
    "Renderer",
    "Scene",
    "SceneFormatError",
    "VideoCancelled",
    "build_info",
    "choose_backend",
    "get_renderer",
    "load",
    "load_cameras_json",
    "orbit_camera",
    "render",
    "save",
    "trace_pixel",
]
