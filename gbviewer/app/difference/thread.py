"""The analysis thread of the difference and error views (`app/difference/views.py` asks, this computes): for one pane
part's frame, the signed difference to pane A's mode at the same camera and the difference to a reference with PSNR
and SSIM: 'box' or 'dense' of `gbviewer.outputs.differences`, or 'photo', a dataset view's photo at the rate
(`eval.ground_truth`, box-downsampled files cached on disk too). The newest request per pane part wins (a waiting
older one is dropped, a running one is cancelled between tiles); references render on the thread's own CPU renderer
and the last few are cached (panes of one size share them). No OpenGL here."""

from __future__ import annotations

import time
import traceback
from dataclasses import dataclass
from typing import Callable, Hashable

import numpy as np

from ...core.cancel import CancelToken
from ...core.errors import GBViewerError, RenderCancelled
from ...eval import default_cache, ground_truth
from ...io.datasets import View
from ...model.camera import Camera, camera_key
from ...model.scene import Scene
from ...outputs.differences import (
    DENSE_SUPERSAMPLE,
    fidelity,
    reference_image,
    reference_note,
    reference_settings,
    robust_scale,
    signed_difference,
)
from ...outputs.flicker import view_flicker
from ...outputs.metrics import zoom_out_factor
from ...render import Frame, RenderSettings
from ..panes import MAX_SAMPLES
from ..threads.slots import SlotThread

CACHE_SIZE = 4  # reference renders (and photos) kept
PHOTO = "photo"  # the reference kind of a dataset view's photo


@dataclass(frozen=True)
class Spec:
    """What one analysis computes."""

    reference: str | None = None  # 'box', 'dense' or PHOTO: the difference to it, PSNR and SSIM
    to_pane: RenderSettings | None = None  # pane A's settings: the difference to pane A
    flicker: bool = (
        False  # the flicker heat map of an orbit step from this view (gbviewer.outputs.flicker.view_flicker)
    )

    @property
    def empty(self) -> bool:
        return self.reference is None and self.to_pane is None and not self.flicker


@dataclass(eq=False)
class Request:
    slot: Hashable
    scene: Scene
    frame: Frame
    camera: Camera
    rate: float
    settings: RenderSettings
    spec: Spec
    pane_a: Frame | None = None  # pane A's frame when it was rendered at `camera` with spec.to_pane
    photo: View | None = None  # for the PHOTO reference: the view whose photo at `rate` has `camera`'s pixels


@dataclass(eq=False)
class Analysis:
    frame: Frame  # the frame analysed
    spec: Spec
    error: np.ndarray | None = None  # signed difference to the reference (H, W)
    error_scale: float = 0.0  # its robust max |d|
    psnr: float | None = None
    ssim: float | None = None
    diff: np.ndarray | None = None  # signed difference to pane A
    diff_scale: float = 0.0
    note: str = ""  # why something is missing: no box reference at this rate, over the sample limit, an error
    photo: np.ndarray | None = None  # the PHOTO reference (H, W, 3): what the photo pane shows
    photo_name: str = ""  # its view's name
    seconds: float = 0.0
    heat: np.ndarray | None = None  # the flicker heat map (H, W), 8-bit levels
    flicker: float = 0.0  # its mean


class AnalysisThread(SlotThread):
    """One thread computing the newest request per slot, the longest-waiting slot first (a newer request of the
    running slot cancels it); results are (slot, Analysis)."""

    NAME = "gbviewer-analysis"

    def __init__(self) -> None:
        self._cache: dict[tuple, np.ndarray | None] = {}  # references of the uploaded scene
        super().__init__()

    def _release(self) -> None:
        super()._release()
        self._cache.clear()

    def _work(self, req: Request, cancel: CancelToken) -> tuple[Hashable, Analysis] | None:
        result = self._analyse(req, cancel)
        return None if result is None else (req.slot, result)

    def _cached(self, key: tuple, make: Callable[[], np.ndarray | None]) -> np.ndarray | None:
        if key not in self._cache:
            value = make()
            while len(self._cache) >= CACHE_SIZE:
                self._cache.pop(next(iter(self._cache)))
            self._cache[key] = value
        return self._cache[key]

    def _analyse(self, req: Request, cancel: CancelToken) -> Analysis | None:
        """The request's analysis; None when it was cancelled (a newer request of its slot is waiting)."""
        t0 = time.perf_counter()
        out, spec, rgb = Analysis(req.frame, req.spec), req.spec, req.frame.rgb
        try:
            self._renderer_for(req.scene)
            cam = camera_key(req.camera)
            if spec.reference == PHOTO:
                ref = out.photo = self._cached(
                    ("photo", req.photo.image, req.rate, req.settings.background),
                    lambda: photo_truth(req.photo, req.rate, req.settings.background),
                )
                out.photo_name = req.photo.name
                if ref.shape != rgb.shape:
                    raise GBViewerError(
                        f"the photo at this rate is {ref.shape[1]}x{ref.shape[0]}, the render "
                        f"{rgb.shape[1]}x{rgb.shape[0]}"
                    )
            elif spec.reference is not None:
                kind = spec.reference
                check_samples(req.camera, req.rate, kind)
                ref = self._cached(
                    ("ref", kind, cam, req.rate, reference_settings(kind, req.settings)),
                    lambda: reference_image(self._renderer, req.camera, req.rate, kind, req.settings, cancel),
                )
            if spec.reference is not None:
                if ref is None:
                    out.note = reference_note(spec.reference, req.rate)
                else:
                    out.error = signed_difference(rgb, ref)
                    out.error_scale = robust_scale(out.error)
                    out.psnr, out.ssim = fidelity(rgb, ref)
            if spec.to_pane is not None:
                a = (
                    req.pane_a.rgb
                    if req.pane_a is not None
                    else self._cached(
                        ("pane", cam, spec.to_pane),
                        lambda: self._renderer.render(req.camera, spec.to_pane, cancel=cancel).rgb,
                    )
                )
                out.diff = signed_difference(rgb, a)
                out.diff_scale = robust_scale(out.diff)
            if spec.flicker:
                check_samples(req.camera, req.rate, "dense")
                m = view_flicker(self._renderer, req.scene, req.camera, req.settings, cancel=cancel)
                out.heat, out.flicker = m.heat, m.flicker
        except RenderCancelled:
            return None
        except GBViewerError as exc:
            out.note = str(exc)
        except Exception as exc:  # noqa: BLE001 - shown on the pane, never kills the thread
            traceback.print_exc()
            out.note = f"{type(exc).__name__}: {exc}"
        out.seconds = time.perf_counter() - t0
        return out


def photo_truth(view: View, rate: float, background: tuple[float, float, float]) -> np.ndarray:
    """The view's photo at `rate` on `background` (`eval.ground_truth`), its box-downsampled levels read from and
    written to the user's cache folder; computed without it where that folder cannot be written."""
    try:
        return ground_truth(view, rate, background, default_cache())
    except OSError:
        return ground_truth(view, rate, background)


def check_samples(camera: Camera, rate: float, kind: str) -> None:
    """Refuse a reference over the panes' sample limit (x8 with a dense reference would be billions)."""
    k = DENSE_SUPERSAMPLE if kind == "dense" else (zoom_out_factor(rate) or 1)
    samples = camera.width * camera.height * k * k
    if samples > MAX_SAMPLES:
        raise GBViewerError(
            f"the {kind} reference would take {samples / 1e6:.0f}M samples, over the "
            f"{MAX_SAMPLES // 1_000_000}M limit: lower the rate"
        )
