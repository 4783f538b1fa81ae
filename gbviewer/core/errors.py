"""Typed errors: each names the file (or object), the field and what was expected."""

from __future__ import annotations


class GBViewerError(Exception):
    """Base class of every error gbviewer raises on bad input."""


class InvalidValue(GBViewerError):
    """A number or document from the command line or a file is out of range, non-finite or malformed."""


class SceneFormatError(GBViewerError):
    """A scene file cannot be read: wrong format, missing or malformed field, truncated data."""

    def __init__(self, path: object, message: str, field: str | None = None):
        self.path = str(path)
        self.field = field
        where = f"{self.path}: " + (f"field '{field}': " if field else "")
        super().__init__(where + message)


class CameraError(GBViewerError):
    """A camera (or cameras.json entry) is invalid."""


class DatasetError(GBViewerError):
    """A training dataset (COLMAP, Blender transforms, cameras.json with photos) cannot be used: missing photos,
    an unsupported camera model, an unreadable model file, an empty split."""


class RenderError(GBViewerError):
    """Invalid render settings or a backend that cannot run."""


class Cancelled(GBViewerError):
    """Work stopped because its caller set its `cancel` (a gbviewer.CancelToken or threading.Event); nothing is
    returned."""


class RenderCancelled(Cancelled):
    """A render stopped because its caller set the `cancel` event (the frame is not returned)."""


class LoadCancelled(Cancelled):
    """A scene load stopped because its caller set the `cancel` event (no scene is returned)."""


class VideoCancelled(Cancelled):
    """`record_video` stopped because its caller set its `cancel`; no output (and no temporary file) is left."""


class CallbackError(GBViewerError):
    """A caller's callback (a render's `on_progress`, a load's `progress`) raised: the work was cancelled, and the
    callback's exception is this one's `__cause__`."""


class BackendUnavailable(RenderError):
    """The requested backend cannot run on this machine; the message says why."""


class BackendFailed(RenderError):
    """A backend that was usable stopped working (a lost device, a failed kernel launch, a watchdog timeout): the
    renderer is marked unusable with this reason (`Renderer.usable()`), and callers move to another backend."""
