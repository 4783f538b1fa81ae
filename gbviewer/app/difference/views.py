"""Difference and error views and live PSNR/SSIM per pane, computed off the UI thread.

`PaneAnalysis` (UI side, no imgui) looks after each UI frame at every visible pane part's newest full-resolution frame
and asks `thread.AnalysisThread` for what it needs: for the 'difference' view, the signed difference to pane A (pane A's
mode rendered at this pane's camera, or pane A's own frame where it is at the same camera); for the 'error' view and the
PSNR/SSIM labels, the difference to the chosen reference ('box' or 'dense' of `gbviewer.outputs.differences`, or
'photo': the snapped dataset view's photo at the rate, asked only for frames rendered at that view's camera) with PSNR
and SSIM; for the 'photo' view, that photo, shown instead of the render. Nothing is asked while the camera moves: the
labels keep their last values, marked stale, and a pane in one of these views shows its plain render, saying why, until
the analysis of its frame is in (`visualize`, which `panes.PaneRenders` calls for every upload). Snapping to a dataset
view turns the labels on against the photo."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ...io.datasets import View
from ...io.datasets.backdrop import format_rgb
from ...model.camera import camera_key, format_rate
from ...model.scene import Scene
from ...outputs.differences import REFERENCES, colour_difference
from ...outputs.flicker import DEFAULT_REFERENCE, VIEW_STEP, heat_colours, heat_scale
from ...render import Frame
from ...render.presets import differences
from ..frames.views import visualize as visualize_view
from ..pane_state import Shown
from ..settings import PANE_NAMES
from ..state import AppState
from ..threads.worker import RenderWorker
from .thread import PHOTO, Analysis, AnalysisThread, Request, Spec

ANALYSIS_VIEWS = ("difference", "error", PHOTO, "flicker")
REFERENCE_KINDS = {**REFERENCES, PHOTO: "the dataset view's photo"}
Slot = tuple[int, str]  # (pane index, part)


@dataclass
class AnalysisOptions:
    reference: str = "box"  # of the error view and the PSNR/SSIM labels: a key of REFERENCE_KINDS
    fidelity: bool = False  # PSNR/SSIM labels on every pane
    auto_scale: bool = True  # colour-map scale: each image's robust max |d| (else `scale` for all)
    scale: float = 0.05


def is_final(shown: Shown, scene: Scene | None) -> bool:
    """Whether a pane part shows the final full-resolution frame of `scene` (previews, quick stages and refining
    frames are not analysed)."""
    return shown.frame is not None and shown.job is not None and shown.job.scene is scene and shown.stage == "final"


def shows_photo(shown: Shown) -> bool:
    """Whether a pane part shows its photo (its legend, 'photo v00  x1/4  32x25', then is its label)."""
    return shown.view == PHOTO and shown.legend.startswith(f"{PHOTO} ")


class PaneAnalysis:
    """The difference and error views' state, requests and results; the actions of their keys."""

    def __init__(self, state: AppState, worker: RenderWorker | None = None) -> None:
        self.state, self.worker = state, worker
        self.options = AnalysisOptions()
        self.thread = AnalysisThread()
        self.latest: dict[Slot, Analysis] = {}
        self.shown_scale: dict[Slot, float] = {}  # the colour-map scale of what a pane part shows now
        self._asked: dict[Slot, tuple[Frame, Spec]] = {}
        self._told: dict[Slot, tuple[Frame, str]] = {}  # the frame whose pane says why it has no photo, and why
        self._scene: Scene | None = None
        self._snaps = 0  # the dataset snaps seen (each turns the labels on against the photo)

    # ---- actions (keys.py) -------------------------------------------------------------------------------------

    def toggle_difference(self) -> None:
        """The pane under the cursor shows its difference to pane A, or its colour again."""
        self._toggle_view("difference")

    def toggle_error(self) -> None:
        """The pane under the cursor shows its difference to the reference, or its colour again."""
        self._toggle_view("error")

    def toggle_fidelity(self) -> None:
        self.options.fidelity = not self.options.fidelity

    def next_reference(self) -> None:
        kinds = list(REFERENCE_KINDS)
        self.set_reference(kinds[(kinds.index(self.options.reference) + 1) % len(kinds)])

    def set_reference(self, kind: str) -> None:
        self.options.reference = kind
        self.state.message(f"reference: {REFERENCE_KINDS[kind]}")
        self.recolour()

    def set_scale(self, auto: bool, scale: float | None = None) -> None:
        self.options.auto_scale = auto
        if scale is not None:
            self.options.scale = float(min(1.0, max(1e-4, scale)))
        self.recolour()

    def _toggle_view(self, view: str) -> None:
        i = self.state.target
        self.state.set_pane(i, view="color" if self.state.settings.panes[i].view == view else view)

    # ---- requests and results ----------------------------------------------------------------------------------

    def spec(self, i: int, part: str) -> Spec:
        """What pane i's part needs computed."""
        view = self.state.settings.panes[i].view
        if view == PHOTO or (view == "difference" and self.a_shows_photo()):
            return Spec(PHOTO)  # (the difference to pane A showing the photo is the difference to the photo)
        reference = self.options.reference if view == "error" or self.options.fidelity else None
        to_pane = replace(self.state.settings_for(0, "a"), debug="none") if view == "difference" else None
        return Spec(reference, to_pane, view == "flicker")

    def a_shows_photo(self) -> bool:
        """Whether pane A's view is the photo (its difference views then compare with the photo)."""
        return self.state.settings.panes[0].view == PHOTO

    def update(self) -> None:
        """Once per UI frame, after the panes took their frames: finished analyses in (their panes re-coloured),
        new requests out (none while the camera moves)."""
        s = self.state
        if s.scene is not self._scene:
            self._scene = s.scene
            self.thread.forget()
            self.latest.clear()
            self._asked.clear()
            self._told.clear()
        if self.options.reference == PHOTO and s.dataset.dataset is None:  # the dataset was closed
            self.options.reference = "box"
            self.recolour()
        if s.dataset.snaps != self._snaps:
            self._snaps = s.dataset.snaps
            self.options.reference, self.options.fidelity = PHOTO, True
            self.recolour()
        for slot, result in self.thread.results():
            if slot not in self._asked or self._asked[slot][0] is not result.frame:
                continue  # overtaken by a newer request of its slot, or of the previous scene
            self.latest[slot] = result
            self.recolour(slot)
        if s.scene is None or s.moving:
            return
        pane_a = s.panes[0].parts["a"]
        for p in s.visible:
            for part in s.parts(p.index):
                slot, shown = (p.index, part), p.parts[part]
                spec = self.spec(*slot)
                if spec.empty or not is_final(shown, s.scene):
                    continue
                asked = self._asked.get(slot)
                if asked is not None and asked[0] is shown.frame and asked[1] == spec:
                    continue
                photo, note = self._photo(slot) if spec.reference == PHOTO else (None, "")
                if note:  # not at a dataset view's camera: nothing to ask; the label and the pane say why
                    told = self._told.get(slot)
                    if told is None or told[0] is not shown.frame or told[1] != note:
                        self._told[slot] = (shown.frame, note)
                        self.recolour(slot)
                    continue
                same_a = None
                if spec.to_pane is not None:
                    if (
                        is_final(pane_a, s.scene)
                        and replace(pane_a.job.settings, debug="none") == spec.to_pane
                        and camera_key(pane_a.job.camera) == camera_key(shown.job.camera)
                    ):
                        same_a = pane_a.frame
                    elif self.worker is not None and self.worker.busy((0, "a")):
                        continue  # pane A's frame is on its way: wait for it rather than render it twice
                for frame in (shown.frame, same_a):  # a frame drawn from GPU memory is read back here, in the UI
                    if frame is not None:  # thread (the analysis thread may not touch its texture)
                        _ = frame.rgb
                self._asked[slot] = (shown.frame, spec)
                self.thread.submit(
                    Request(
                        slot,
                        s.scene,
                        shown.frame,
                        shown.job.camera,
                        shown.job.info.get("rate", s.settings.rate),
                        shown.job.settings,
                        spec,
                        same_a,
                        photo,
                    )
                )
                self.recolour(slot)

    def recolour(self, slot: Slot | None = None) -> None:
        """Have the panes re-upload the images of pane parts in these views (all, or `slot`) next frame."""
        for p in self.state.visible:
            if self.state.settings.panes[p.index].view in ANALYSIS_VIEWS:
                for part, shown in p.parts.items():
                    if slot is None or slot == (p.index, part):
                        shown.view = ""

    def current(self) -> bool:
        """Whether every visible pane part that needs an analysis has the one of the frame it shows."""
        if self.thread.busy():
            return False
        for p in self.state.visible:
            for part in self.state.parts(p.index):
                spec, shown = self.spec(p.index, part), p.parts[part]
                if spec.empty or (spec.reference == PHOTO and self._photo((p.index, part))[1]):
                    continue
                a = self.latest.get((p.index, part))
                if a is None or a.frame is not shown.frame or a.spec != spec:
                    return False
        return True

    def stop(self) -> None:
        self.thread.stop()

    # ---- what the panes show -----------------------------------------------------------------------------------

    def visualize(self, slot: Slot, frame: Frame, view: str) -> tuple[np.ndarray, str]:
        """The image (H, W, 3 in [0, 1]) and legend pane part `slot` shows of `frame` in `view`: the colour-mapped
        difference, or the photo, once its analysis is in, until then the plain render and why (`views.visualize`
        for the other views)."""
        self.shown_scale.pop(slot, None)
        if view not in ANALYSIS_VIEWS:
            return visualize_view(frame, view)
        a, spec = self.latest.get(slot), self.spec(*slot)
        name = PANE_NAMES[slot[0]] + ("'" if slot[1] == "b" else "")
        fresh = a is not None and a.frame is frame
        if view == PHOTO:
            if not fresh or a.photo is None:
                return frame.rgb, f"{PHOTO}: {self._waiting(slot, a, frame, view)}"
            job = self.state.panes[slot[0]].parts[slot[1]].job
            rate = format_rate(job.info.get("rate", self.state.settings.rate) if job else self.state.settings.rate)
            return a.photo, f"{PHOTO} {a.photo_name}  {rate}  {a.photo.shape[1]}x{a.photo.shape[0]}"
        if view == "flicker":
            if not fresh or a.heat is None:
                return frame.rgb, f"flicker: {self._waiting(slot, a, frame, view)}"
            top = heat_scale([a.heat])
            return heat_colours(a.heat, top), (
                f"{name} flicker {a.flicker:.3f} levels ({VIEW_STEP:g} deg orbit "
                f"step vs {DEFAULT_REFERENCE}), red {top:.3g}"
            )
        if view == "difference" and spec.reference == PHOTO:
            plane, auto = (a.error, a.error_scale) if fresh and a.spec == spec else (None, 0.0)
            what = f"{name} - A (photo {a.photo_name})" if a is not None else ""
        elif view == "difference":
            plane, auto = (a.diff, a.diff_scale) if fresh and a.spec.to_pane == spec.to_pane else (None, 0.0)
            differ = differences(self.state.settings_for(*slot), spec.to_pane)
            what = f"{name} - A ({spec.to_pane.label})" + (f": {', '.join(differ)}" if differ else "")
        else:
            plane, auto = (a.error, a.error_scale) if fresh and a.spec.reference == spec.reference else (None, 0.0)
            what = f"{name} - {spec.reference} reference"
        if plane is None:
            return frame.rgb, f"{view}: {self._waiting(slot, a, frame, view)}"
        scale = auto if self.options.auto_scale else self.options.scale
        self.shown_scale[slot] = scale
        return colour_difference(plane, scale), what

    def _waiting(self, slot: Slot, a: Analysis | None, frame: Frame, view: str) -> str:
        if a is not None and a.frame is frame and a.note:
            return a.note
        if self.state.moving:
            return "when the camera stops"
        if self.spec(*slot).reference == PHOTO and self._photo(slot)[1]:
            return self._photo(slot)[1]
        if view in ("difference", "flicker"):
            return "computing..."
        return f"computing ({self.options.reference} reference)..."

    def fidelity_line(self, slot: Slot) -> tuple[str, bool] | None:
        """The PSNR/SSIM label of a pane part and whether it is stale (the camera moves, a newer frame or another
        reference is on the pane, the camera left the photo's view); None where there is nothing to show (the photo
        pane has no label of its own)."""
        spec = self.spec(*slot)
        if spec.reference is None or self.state.settings.panes[slot[0]].view == PHOTO:
            return None
        if spec.reference == PHOTO and not self.state.moving and self._photo(slot)[1]:
            return f"{PHOTO}: {self._photo(slot)[1]}", True
        a = self.latest.get(slot)
        shown = self.state.panes[slot[0]].parts[slot[1]]
        if a is None or a.spec.reference is None:
            return f"{spec.reference}: computing...", True
        if a.psnr is None:
            return a.note, a.frame is not shown.frame
        stale = self.state.moving or a.frame is not shown.frame or a.spec.reference != spec.reference
        against = a.spec.reference
        if against == PHOTO and shown.job is not None:  # the photo's backdrop and the render's background matter
            against += f" (bg {format_rgb(shown.job.settings.background)})"
        return f"PSNR {a.psnr:.2f} dB  SSIM {a.ssim:.4f} vs {against}" + ("  (stale)" if stale else ""), stale

    def _photo(self, slot: Slot) -> tuple[View | None, str]:
        """The dataset view whose photo is the 'photo' reference of the frame pane part `slot` shows (rendered at
        that photo's camera and rate), or None and why not."""
        job = self.state.panes[slot[0]].parts[slot[1]].job
        if job is None:
            return None, "no render yet"
        return self.state.dataset.photo_for(job.camera, job.info.get("rate", self.state.settings.rate))
