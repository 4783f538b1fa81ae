"""Frames as the viewer wants them from the render thread: a progressive job's quick stage, then its frame with the
finished tiles posted as they come; the panes of one camera rendered together (`Renderer.render_many`: the stage
the modes share done once, their tiles interleaved, so a second pane's first tiles arrive with the first's)."""

from __future__ import annotations

import time
from typing import TYPE_CHECKING, Callable

import numpy as np

from ...core.cancel import CancelToken
from ...model.camera import camera_key
from ...render import Frame, Renderer

if TYPE_CHECKING:
    from ..threads.worker import RenderJob as Job

PARTIAL_INTERVAL_S = 0.1  # how often a refining frame is posted (the first finished tiles at once)


# post(job, stage, frame, partial, progress): hand an intermediate result to the UI ("quick": frame; "partial")
Post = Callable[["Job", str, "Frame | None", "np.ndarray | None", float], None]


def scaled_nearest(image: np.ndarray, width: int, height: int) -> np.ndarray:
    """`image` (H, W, 3) resized to (height, width, 3) float32 by nearest neighbour."""
    h, w = image.shape[:2]
    ys = np.arange(height) * h // height
    xs = np.arange(width) * w // width
    return np.ascontiguousarray(image[ys[:, None], xs[None, :], :3], np.float32)


def companions(first: "Job", waiting: list) -> list:
    """Of the `waiting` jobs, those rendered in one `render_many` with `first`: frames of its kind (previews with a
    preview of the same splats, which share its cut's stage; final frames with a final frame) on the copy display
    path, of the same scene, backend and camera."""
    if first.display == "gpu":
        return []
    key = camera_key(first.camera)
    return [
        j
        for j in waiting
        if j.scene is first.scene
        and j.backend == first.backend
        and j.preview == first.preview
        and j.stand_in == first.stand_in
        and j.display != "gpu"
        and camera_key(j.camera) == key
    ]


def _poster(job: "Job", partial: np.ndarray, post: Post) -> Callable[[int, int], None]:
    """A render's on_progress that posts `partial` at once for the first finished tiles, then at most every
    PARTIAL_INTERVAL_S."""
    posted = [0.0, 0]  # when, tiles done

    def on_progress(done: int, total: int) -> None:
        now = time.perf_counter()
        if done > posted[1] and done < total and (posted[1] == 0 or now - posted[0] >= PARTIAL_INTERVAL_S):
            posted[:] = [now, done]
            post(job, "partial", None, partial, done / total)

    return on_progress


def render_jobs(renderer: Renderer, jobs: list, cancel: CancelToken, post: Post) -> list[Frame]:
    """The frames of `jobs` (one camera): each progressive job's quick stage first (posted), then every frame in
    one render, the progressive ones' tiles posted as they finish (over the job's underlay or quick stage)."""
    partials: list[np.ndarray | None] = []
    hooks: list[Callable[[int, int], None] | None] = []
    for job in jobs:
        if not job.progressive:
            partials.append(None)
            hooks.append(None)
            continue
        base = job.underlay
        if job.quick is not None:
            quick = renderer.render(*job.quick, cancel=cancel)
            post(job, "quick", quick, None, 0.0)
            base = quick.rgb
        w, h = job.camera.width, job.camera.height
        partials.append(scaled_nearest(base, w, h) if base is not None else np.zeros((h, w, 3), np.float32))
        hooks.append(_poster(job, partials[-1], post))
    if len(jobs) == 1:
        return [
            renderer.render(jobs[0].camera, jobs[0].settings, cancel=cancel, on_progress=hooks[0], partial=partials[0])
        ]

    def on_progress(k: int, done: int, total: int) -> None:
        if hooks[k] is not None:
            hooks[k](done, total)

    return renderer.render_many(
        [(j.camera, j.settings) for j in jobs], cancel=cancel, on_progress=on_progress, partials=partials
    )
