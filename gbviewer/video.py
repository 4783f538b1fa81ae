"""Side-by-side zoom videos: every frame of a camera path (`gbviewer.camera_paths`) rendered in several modes,
captioned and streamed frame by frame as H.264 MP4 to imageio-ffmpeg's bundled ffmpeg (`record_video`)."""

from __future__ import annotations

import time
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path
from typing import Callable, Iterable, Iterator, Sequence

import numpy as np
from PIL import Image

from .camera import Camera, format_rate
from .camera_paths import PathFrame
from .errors import GBViewerError, RenderCancelled, VideoCancelled
from .extras import require
from .figure import GAP, Cell, GridLayout, caption_font_size, compose_grid
from .io.files import atomic_write, refuse_overwrite
from .render import RenderSettings, get_renderer
from .scene import Scene
from .validate import integer, real

DEFAULT_CRF = 18  # libx264 constant rate factor: 0 lossless, ~18 visually lossless, 23 ffmpeg's default
MIN_FPS, MAX_FPS = 0.1, 1000.0  # frame rates of a video (the encoder's time base is fps to 1/1001)


@dataclass(frozen=True)
class VideoInfo:
    """What `record_video` wrote."""

    path: Path
    frames: int
    width: int
    height: int
    fps: float
    elapsed_s: float  # rendering and encoding, wall clock


def _frame_lines(pf: PathFrame) -> Callable[[Cell], list[str]]:
    def lines(cell: Cell) -> list[str]:
        h, w = cell.rgb.shape[:2]
        size = f"  (rendered {w}x{h})" if (w, h) != (pf.width, pf.height) else ""
        return [cell.mode_label, f"sampling rate {format_rate(pf.rate)}{size}"]
    return lines


def compose_video_frame(cells: list[Cell], pf: PathFrame, inset: tuple[float, float, float, float] | None = None
                        ) -> Image.Image:
    """The panes of one frame side by side, each captioned below with its mode and the sampling rate, the inset
    region (x1 pixels) following the content; even canvas size."""
    return compose_grid([cells], pf.width, pf.height, GAP, captions="below", lines=_frame_lines(pf),
                        inset=pf.map_box(inset) if inset is not None else None, even=True)


def video_layout(pf: PathFrame, n_modes: int) -> GridLayout:
    """Where `compose_video_frame` puts the panes (GridLayout.origin(0, i) is pane i's top-left pixel)."""
    return GridLayout(1, n_modes, pf.width, pf.height, GAP, GridLayout.caption_height_for(2, caption_font_size(
        pf.height)), even=True)


def render_or_stop(renderer, camera: Camera, settings: RenderSettings, cancel):
    """One cell's frame; a cancel set during it (the token reaches the native loop) stops the video at once."""
    try:
        return renderer.render(camera, settings, cancel=cancel)
    except RenderCancelled:
        raise VideoCancelled("video cancelled; nothing written") from None


def record_video(scene: Scene, camera_path: Sequence[PathFrame | Camera], settings_list: Sequence[RenderSettings],
                 out: str | Path, *, fps: float = 30.0, backend: str = "cpu",
                 inset: tuple[float, float, float, float] | None = None, crf: int = DEFAULT_CRF,
                 preset: str = "medium", force: bool = False, progress: Callable[[int, int], None] | None = None,
                 cancel=None) -> VideoInfo:
    """Render every frame of `camera_path` in every mode of `settings_list` side by side and write an H.264 MP4.

    camera_path: PathFrames (`gbviewer.camera_paths`) or plain
    Cameras (rate 1, pane = the camera's size); every frame must have the same pane size. Frames are rendered,
    composed and piped to ffmpeg (imageio-ffmpeg's bundled one: libx264, yuv420p, constant quality `crf`) one at a
    time, so memory does not grow with the length; the CPU backend uses every core for each frame.

    Safe to call from a background thread with a backend that needs no GL context (`Capabilities.gl_context`: a
    GL backend's context belongs to the thread that made it; the cpu renderer releases the GIL):
      progress(done, total) is called after each frame is encoded (from the calling thread);
      cancel: a gbviewer.CancelToken, threading.Event or anything with is_set(), checked before each render; when
      set, ffmpeg is stopped, the partial file removed and VideoCancelled (a gbviewer.Cancelled) raised.
    The video is written to a temporary file beside `out` and renamed onto it at the end: an exception, Ctrl-C
    or cancel leaves neither. Refuses to overwrite an existing `out` unless `force`.
    Returns a VideoInfo (path, frame count, frame size, fps, wall time).
    """
    require("video", "imageio_ffmpeg", "an MP4 video")
    out = Path(out)
    if out.suffix.lower() != ".mp4":
        raise GBViewerError(f"{out}: output must end in .mp4")
    refuse_overwrite(out, force)
    frames = [pf if isinstance(pf, PathFrame) else PathFrame.of(pf) for pf in camera_path]
    if not frames:
        raise GBViewerError("the camera path has no frames")
    if not settings_list:
        raise GBViewerError("no modes given")
    if any((pf.width, pf.height) != (frames[0].width, frames[0].height) for pf in frames):
        raise GBViewerError("every frame of the camera path must have the same pane size")
    fps = real(fps, "fps", lo=MIN_FPS, hi=MAX_FPS)
    crf = integer(crf, "crf", lo=0, hi=51)
    renderer = get_renderer(scene, backend)
    t0 = time.perf_counter()

    def images() -> Iterator[np.ndarray]:
        for i, pf in enumerate(frames):
            cells = []
            for s in settings_list:
                if cancel is not None and cancel.is_set():
                    raise VideoCancelled("video cancelled; nothing written")
                cells.append(Cell.of(s, pf.rate, render_or_stop(renderer, pf.camera, s, cancel)))
            yield np.asarray(compose_video_frame(cells, pf, inset))
            if progress is not None:
                progress(i + 1, len(frames))

    width, height = write_mp4(out, images(), len(frames), fps=fps, crf=crf, preset=preset, force=force)
    return VideoInfo(out, len(frames), width, height, float(fps), time.perf_counter() - t0)


def write_mp4(out: str | Path, images: Iterable[np.ndarray], count: int, *, fps: float = 30.0, crf: int = DEFAULT_CRF,
              preset: str = "medium", force: bool = False) -> tuple[int, int]:
    """Stream `count` uint8 (H, W, 3) images of one size to imageio-ffmpeg's ffmpeg (libx264, yuv420p, constant
    quality `crf`) into `out`, atomically: written beside it and renamed at the end, so an exception raised by
    `images` (a cancel) leaves no file. Returns (width, height)."""
    imageio_ffmpeg = require("video", "imageio_ffmpeg", "an MP4 video")
    size: list[int] = []

    def write(tmp: Path) -> None:
        writer = None
        try:
            for img in images:
                if writer is None:
                    size[:] = [img.shape[1], img.shape[0]]
                    writer = imageio_ffmpeg.write_frames(
                        str(tmp), tuple(size), fps=Fraction(fps).limit_denominator(1001), codec="libx264",
                        pix_fmt_out="yuv420p", quality=None, macro_block_size=1,
                        output_params=["-crf", str(crf), "-preset", preset, "-movflags", "+faststart"])
                    writer.send(None)
                writer.send(np.ascontiguousarray(img))
        finally:
            if writer is not None:
                writer.close()  # ffmpeg finishes (or is stopped) before the file is renamed or removed
        written = imageio_ffmpeg.count_frames_and_secs(str(tmp))[0]  # imageio does not check ffmpeg's exit status
        if written != count:
            raise GBViewerError(f"ffmpeg wrote {written} of {count} frames; see its messages above")

    atomic_write(out, write, force)
    return size[0], size[1]
