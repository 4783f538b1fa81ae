"""The panes' renders: which requests go to the render thread this frame (one per pane part whose view changed, at a
preview resolution while the camera moves; at full resolution, refining progressively, once it stops; a large
scene's first picture in a pane is a preview, the full frame refines over it), previews drawing the hierarchy's cut
or, until it is there, the scene's sparse stand-in (never waiting for the hierarchy), frames
uploaded to textures as they come (quick stage, finished tiles, final) or, on the GPU display path, drawn from the
display texture they were rendered into (`display`), and their images queued for drawing."""

from __future__ import annotations

import os
import time
from dataclasses import replace
from typing import Callable

import moderngl
import numpy as np

from ..lod import hierarchy_state
from ..lod.sparse import stride
from ..model.camera import Camera
from ..outputs.figure import to_uint8
from ..render import Frame, RenderSettings
from .frames.accumulate import is_stochastic
from .frames.display import GpuFrame
from .frames.rates import first_preview, preview_factor, preview_lod
from .frames.views import visualize
from .pane_state import PaneError, PaneState, Shown
from .state import AppState
from .threads import loading
from .threads.worker import RenderJob, RenderResult, RenderWorker
from .ui.blit import Blitter
from .ui.layout import split_parts

MAX_SAMPLES = 96_000_000  # per render (pixels x supersampling^2): bounds memory and time at x8 with 8x8
PREVIEW_BUDGET_MS = 60.0  # per UI frame while the camera moves, shared by the panes
QUICK_MIN_MS = 150.0  # a still frame expected to take longer shows its x1 sample first (supersampled or zoomed in)


def pane_fps(p: PaneState, part: str) -> float:
    """Finished renders per second over the last 2 s while they keep coming, else 1000 / the last total."""
    rate = p.fps[part].rate()
    frame = p.parts[part].frame
    if rate > 0 or frame is None:
        return rate
    return 1000.0 / max(1e-3, frame.stats.total_ms)


class PaneRenders:
    """Requests renders for the visible panes and shows what comes back. Owns one texture per pane part, reused
    across frames and scenes (a new scene's panes start without an image, and no texture outlives its part)."""

    def __init__(
        self,
        state: AppState,
        worker: RenderWorker,
        ctx: moderngl.Context,
        colour: Callable[[tuple[int, str], Frame, str], tuple[np.ndarray, str]] | None = None,
    ) -> None:
        self.state, self.worker, self.ctx = state, worker, ctx
        self.colour = colour or (lambda slot, frame, view: visualize(frame, view))  # image and legend of a view
        self._textures: dict[tuple[int, str], moderngl.Texture] = {}

    def submit(self) -> None:
        """Send a request for every visible pane part whose view changed since its last request."""
        s = self.state
        if s.scene is None:
            return
        backend = self.worker.backend_for(s.settings.backend)
        view_key = s.controller.state()
        moving = s.moving
        slots = sum(len(s.parts(p.index)) for p in s.visible)
        jobs = []  # submitted together: the panes of one camera render as companions
        for p in s.visible:
            ps = s.settings.panes[p.index]
            for part in s.parts(p.index):
                w, h = p.render_size
                cost = p.ms_per_px.get((part, ps.mode if part == "a" else ps.split_mode, ps.supersample, backend))
                shown = p.parts[part]
                first = first_preview(s.scene.num_splats)  # a large scene's first picture: nothing of it shown yet
                first = first if first < 1.0 and shown.job is None and shown.error is None else None
                f = first or preview_factor(w * h, cost, PREVIEW_BUDGET_MS * 2 / max(2, slots), moving)
                cam = s.pane_camera(p.index, f)
                settings = s.settings_for(p.index, part)
                samples = cam.width * cam.height * settings.supersample**2
                if samples > MAX_SAMPLES:
                    p.parts[part].error = PaneError(
                        "too_large",
                        f"{cam.width}x{cam.height} with "
                        f"{settings.supersample}x{settings.supersample} samples is "
                        f"{samples / 1e6:.0f}M samples, over the "
                        f"{MAX_SAMPLES // 1_000_000}M limit: lower the rate or "
                        "supersampling",
                    )
                    p.submitted.pop(part, None)
                    continue
                if p.parts[part].error is not None and p.parts[part].error.kind == "too_large":
                    p.parts[part].error = None
                stochastic = is_stochastic(settings)  # its running mean needs each frame's pixels: the copy path
                gpu = ps.view == "color" and not stochastic and self.worker.display_path(backend)[0] == "gpu"
                display = "gpu" if gpu else "copy"
                key = base = (id(s.scene), view_key, (cam.width, cam.height), settings, backend, display)
                if stochastic:  # still: the next frame index of its running mean (accumulate)
                    settings = p.parts[part].accumulation.request(base, settings, moving or f < 1.0)
                    if settings is None:
                        continue
                    key = base + (settings.frame,)
                if moving and (os.cpu_count() or 1) > 1:  # leave a core to the UI thread while the camera moves
                    settings = replace(settings, threads=(os.cpu_count() or 2) - 1)
                stand_in = False
                if f < 1.0 and s.scene.oit is None:  # a preview draws a cut (rates), or the stand-in until it can
                    if hierarchy_state(s.scene) == "ready" or stride(s.scene.num_splats) == 1:
                        settings = replace(settings, lod=p.preview_lod) if settings.lod is None else settings
                    else:
                        settings, stand_in = replace(settings, lod=None), True
                if p.submitted.get(part) == key:
                    continue
                p.submitted[part] = key
                progressive = (
                    f == 1.0
                    and self.worker.capabilities(backend).progressive
                    and ps.view == "color"
                    and settings.frame == 0
                )  # a later frame of a running mean arrives whole
                est_ms = cost * w * h if cost else None
                jobs.append(
                    RenderJob(
                        (p.index, part),
                        s.scene,
                        cam,
                        settings,
                        backend,
                        {
                            "key": key,
                            "preview": f,
                            "rate": s.settings.rate,
                            "full_size": (w, h),
                            "accumulate": base if stochastic else None,
                            "first": first is not None,
                        },
                        priority=int(not moving and s.hover is not None and s.hover[0] == p.index),
                        preview=f < 1.0,
                        progressive=progressive,
                        underlay=shown.frame.rgb
                        if progressive and shown.frame is not None and shown.view == "color"
                        else None,
                        quick=self._quick(p.index, settings, est_ms) if progressive else None,
                        display=display,
                        stand_in=stand_in,
                    )
                )
                p.asked[part] = jobs[-1]
        if jobs:
            self.worker.submit_all(jobs)

    def _quick(self, i: int, settings: RenderSettings, est_ms: float | None) -> tuple[Camera, RenderSettings] | None:
        """The x1 sample of a still frame that supersamples or zooms in and is expected to be slow (or not measured
        yet): one sample per pane pixel, shown while the full frame refines."""
        rate = self.state.settings.rate
        if (settings.supersample == 1 and rate <= 1.0) or (est_ms is not None and est_ms < QUICK_MIN_MS):
            return None
        return self.state.pane_camera(i, min(1.0, 1.0 / rate)), replace(settings, supersample=1)

    def progress(self, i: int, part: str) -> str | None:
        """What pane i's part is waiting for while it has no image of the scene yet, or only its first preview: the
        render thread, a preview (of the stand-in), the full frame's first tiles; and the hierarchy's build or read
        in the background. None once its full frame's tiles come (its refining line), or with an earlier frame."""
        s = self.state
        p = s.panes[i]
        shown, asked = p.parts[part], p.asked.get(part)
        if asked is None or asked.scene is not s.scene or (shown.job is not None and not shown.job.info.get("first")):
            return None
        if shown.job is asked and not asked.preview:
            return None  # its quick stage, tiles or frame are on screen
        w, h = asked.camera.width, asked.camera.height
        if shown.job is asked:  # the preview came this frame: the full frame is asked for after drawing it
            doing = "rendering {}x{} next".format(*asked.info["full_size"])
        elif not asked.started:
            doing = "waiting for the render thread"
        elif asked.preview:
            k = stride(s.scene.num_splats)
            doing = f"rendering a preview {w}x{h}" + (f" (1 splat in {k})" if asked.stand_in else "")
        else:
            doing = f"rendering {w}x{h}"
        since = asked.started or asked.submitted
        line = ("preview shown; " if shown.job is not None else "") + doing
        line += "" if shown.job is asked else f" {time.perf_counter() - since:.1f} s"
        lod = hierarchy_state(s.scene)
        return line + (f" · {lod} level of detail" if lod in ("building", "reading") else "")

    def poll(self) -> None:
        """Take finished renders; re-colour frames whose pane view changed (a GPU frame's pane asks for a copy-path
        render instead: its texture holds colour only); hand the display textures of dropped frames back."""
        for res in self.worker.results():
            self._take(res)
        s = self.state
        if s.lod_due is not None and (
            time.perf_counter() >= s.lod_due
            or all(p.parts[part].job is not None for p in s.visible for part in s.parts(p.index))
        ):
            s.lod_due = None  # every pane shows the scene (or it waited long enough): its hierarchy's build begins
            loading.start_lod(s.scene)
        for p in self.state.visible:
            view = self.state.settings.panes[p.index].view
            for part, shown in p.parts.items():
                if shown.frame is not None and shown.view != view and not isinstance(shown.frame, GpuFrame):
                    self._upload((p.index, part), shown, shown.frame, view)
        self.worker.return_textures()

    def all_current(self) -> bool:
        """Whether every visible pane shows its latest request at full resolution."""
        for p in self.state.visible:
            for part in self.state.parts(p.index):
                key = p.submitted.get(part)
                job = p.parts[part].job
                if key is None or job is None or job.info.get("key") != key or job.info.get("preview", 1.0) != 1.0:
                    return False
        return not self.worker.busy()

    def queue_images(self, blitter: Blitter) -> None:
        """Each visible pane's image (both sides of a split) into `blitter`, nearest-upscaled to the pane."""
        if self.state.scene is None:
            return
        for p in self.state.visible:
            r = p.rect
            ps = self.state.settings.panes[p.index]
            ranges = split_parts(ps.split_pos) if ps.split else ((0.0, 1.0),)
            for part, (u0, u1) in zip(self.state.parts(p.index), ranges):
                shown = p.parts[part]
                if shown.texture is None or u1 <= u0:
                    continue
                blitter.add(shown.texture, r.x + u0 * r.w, r.y, r.x + u1 * r.w, r.y + r.h, (u0, 0.0, u1, 1.0))

    def release(self) -> None:
        for tex in self._textures.values():
            tex.release()
        self._textures.clear()

    def _take(self, res: RenderResult) -> None:
        i, part = res.job.slot
        s = self.state
        if res.job.scene is not s.scene:
            return
        p = s.panes[i]
        if res.cancelled:  # superseded: the newer request of its slot is queued
            if (
                res.job.preview
                and res.started
                and res.job.settings.lod == p.preview_lod
                and s.settings.panes[i].lod == 0
            ):
                # a preview stopped by the camera's stop after rendering longer than its budget: the next motion's
                # first preview draws a coarser cut (else a cut too fine for the scene is never measured, only
                # cancelled); its time in the queue does not count
                p.preview_lod = max(p.preview_lod, preview_lod(p.preview_lod, (res.finished - res.started) * 1e3))
            return
        shown = p.parts[part]
        if res.stage != "final":
            self._take_refining(res, shown)
            return
        if res.failed:  # the next request of this part goes to the backend auto picks now
            p.submitted.pop(part, None)
            s.message(
                f"{res.job.backend} {res.error}; rendering on {self.worker.backend_for(res.job.backend)}", "error"
            )
            return
        shown.job = res.job
        if res.frame is None:
            shown.error = PaneError("render", res.error)
            s.message(f"pane {p.name}: {res.error}", "error")
            return
        shown.error = None
        total_ms = res.frame.stats.total_ms
        cam = res.job.camera
        if res.job.info.get("preview", 1.0) == 1.0 and total_ms:
            key = (part, res.job.settings.name, res.job.settings.supersample, res.job.backend)
            p.ms_per_px[key] = total_ms / (cam.width * cam.height)
        p.fps[part].tick(res.finished)
        frame, base = res.frame, res.job.info.get("accumulate")
        if base is not None:
            frame = shown.accumulation.add(base, frame, res.job.settings.frame)
        self._upload(res.job.slot, shown, frame, s.settings.panes[i].view)
        preview = res.job.info.get("preview", 1.0) < 1.0
        if preview and res.job.settings.lod == p.preview_lod and s.settings.panes[i].lod == 0:
            p.preview_lod = preview_lod(p.preview_lod, total_ms)
        shown.stage, shown.progress = ("preview" if preview else "final"), None
        shown.pacing["preview" if preview else "final"] = (res.finished - res.job.submitted) * 1e3

    def _take_refining(self, res: RenderResult, shown: Shown) -> None:
        """The quick stage or the tiles so far of the pane part's latest request (older ones are dropped)."""
        i, part = res.job.slot
        if res.job.info.get("key") != self.state.panes[i].submitted.get(part):
            return
        shown.job = res.job
        if res.stage == "quick":
            self._upload(res.job.slot, shown, res.frame, "color")
            shown.stage, shown.progress = "quick", 0.0
            return
        self._write(res.job.slot, shown, np.ascontiguousarray(to_uint8(res.partial)))
        if shown.stage != "refining":
            shown.pacing.pop("final", None)
            shown.pacing["tiles"] = (res.finished - res.job.submitted) * 1e3
        shown.stage, shown.progress = "refining", res.progress

    def _upload(self, slot: tuple[int, str], shown: Shown, frame: Frame, view: str) -> None:
        if isinstance(frame, GpuFrame):  # drawn from the texture it was rendered into, in colour
            shown.texture, shown.image = frame.texture(self.ctx), None
            shown.frame, shown.view, shown.legend = frame, "color", ""
            return
        rgb, legend = self.colour(slot, frame, view)
        self._write(slot, shown, np.ascontiguousarray(to_uint8(rgb)))
        shown.frame, shown.view, shown.legend = frame, view, legend

    def _write(self, slot: tuple[int, str], shown: Shown, img: np.ndarray) -> None:
        """`img` (uint8 (H, W, 3)) into the part's texture (made or resized as needed)."""
        h, w = img.shape[:2]
        tex = self._textures.get(slot)
        if tex is None or tex.size != (w, h):
            if tex is not None:
                tex.release()
            tex = self.ctx.texture((w, h), 3, img.tobytes(), alignment=1)
            tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
            tex.repeat_x = tex.repeat_y = False
            self._textures[slot] = tex
        else:
            tex.write(img.tobytes(), alignment=1)
        shown.texture, shown.image = tex, img
