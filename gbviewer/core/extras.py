"""The optional extras: `pip install gbviewer` is the library and the command line's renders; a feature whose
third-party package comes with an extra imports it through `require`, which says in one line which extra to install.

No module outside `gbviewer.app` imports an extra's package at import time (tests/core/test_extras.py imports the
package with them blocked)."""

from __future__ import annotations

import importlib
import importlib.util
from types import ModuleType

from .errors import GBViewerError

# extra -> the import names of the packages it adds (pyproject.toml's [project.optional-dependencies])
EXTRAS: dict[str, tuple[str, ...]] = {
    "viewer": ("glfw", "imgui_bundle", "skimage"),
    "video": ("imageio_ffmpeg",),
    "eval": ("skimage", "matplotlib", "pycolmap"),
    "ray": ("ray",),
    "duplex": ("torch",),
}


class MissingExtra(GBViewerError):
    """A feature's package is not installed (or does not import); the message names the extra that installs it."""

    def __init__(self, extra: str, module: str, feature: str, why: str) -> None:
        self.extra, self.module = extra, module
        super().__init__(
            f"{feature} needs {module.split('.')[0]} ({' '.join(why.split())}): pip install 'gbviewer[{extra}]'"
        )


def require(extra: str, module: str, feature: str, load: bool = True) -> ModuleType | None:
    """Import `module` (e.g. "skimage.metrics") of `extra` for `feature` ("SSIM", "the viewer"); `load=False` only
    checks that it is installed (for a package a child process imports) and returns None. Raises `MissingExtra`."""
    if module.split(".")[0] not in EXTRAS[extra]:
        raise ValueError(f"{module} is not a package of the extra {extra!r}")
    try:
        if not load:
            if importlib.util.find_spec(module.split(".")[0]) is None:
                raise ImportError(f"No module named {module.split('.')[0]!r}")
            return None
        return importlib.import_module(module)
    except ImportError as exc:
        raise MissingExtra(extra, module, feature, str(exc) or type(exc).__name__) from None
