"""Side-by-side zoom videos: every frame of a camera path (`gbviewer.model.camera_paths`) rendered in several modes,
captioned and streamed frame by frame to imageio-ffmpeg's bundled ffmpeg (`record_video`) as H.264, H.265, VP9 or AV1 in
MP4 or WebM (`CODECS`, `CONTAINERS`)."""

from __future__ import annotations

import subprocess
import time
from dataclasses import dataclass
from fractions import Fraction
from functools import cache
from pathlib import Path
from typing import Callable, Iterable, Iterator, Sequence

import numpy as np
from PIL import Image

from ..core.errors import GBViewerError, RenderCancelled, VideoCancelled
from ..core.extras import require
from ..core.files import atomic_write, refuse_overwrite
from ..core.validate import integer, real
from ..model.camera import Camera, format_rate
from ..model.camera_paths import PathFrame
from ..model.scene import Scene
from ..render import RenderSettings, get_renderer
from ..render.tiles import render_tiled
from .figure import GAP, Cell, GridLayout, caption_font_size, compose_grid


@dataclass(frozen=True)
class Codec:
    """A video codec: the ffmpeg encoders that write it (the first one the ffmpeg at hand has is used), its
    constant-quality range and default (visually lossless for side-by-side comparisons), and the encoder options
    that select constant quality and a speed."""

    encoders: tuple[str, ...]
    min_crf: int
    max_crf: int
    default_crf: int
    options: dict[str, tuple[str, ...]]


# constant quality: libx264/libx265 take -crf 0..51, libvpx-vp9 and libaom-av1 -crf 0..63 with -b:v 0, libsvtav1
# -crf 1..63 (its 0 means "unset"); ffmpeg's encoder documentation (ffmpeg-codecs, "Video Encoders")
CODECS = {
    "h264": Codec(("libx264",), 0, 51, 18, {"libx264": ("-preset", "medium")}),
    "h265": Codec(
        ("libx265",), 0, 51, 20, {"libx265": ("-preset", "medium", "-tag:v", "hvc1", "-x265-params", "log-level=error")}
    ),
    "vp9": Codec(
        ("libvpx-vp9",), 0, 63, 24, {"libvpx-vp9": ("-b:v", "0", "-deadline", "good", "-cpu-used", "4", "-row-mt", "1")}
    ),
    "av1": Codec(
        ("libsvtav1", "libaom-av1"),
        1,
        63,
        24,
        {"libsvtav1": ("-preset", "8"), "libaom-av1": ("-b:v", "0", "-cpu-used", "6", "-row-mt", "1")},
    ),
}
CONTAINERS = {".mp4": ("h264", "h265", "vp9", "av1"), ".webm": ("vp9", "av1")}  # WebM holds VP8, VP9 and AV1 only
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


def compose_video_frame(
    cells: list[Cell], pf: PathFrame, inset: tuple[float, float, float, float] | None = None
) -> Image.Image:
    """The panes of one frame side by side, each captioned below with its mode and the sampling rate, the inset
    region (x1 pixels) following the content; even canvas size."""
    return compose_grid(
        [cells],
        pf.width,
        pf.height,
        GAP,
        captions="below",
        lines=_frame_lines(pf),
        inset=pf.map_box(inset) if inset is not None else None,
        even=True,
    )


def video_layout(pf: PathFrame, n_modes: int) -> GridLayout:
    """Where `compose_video_frame` puts the panes (GridLayout.origin(0, i) is pane i's top-left pixel)."""
    return GridLayout(
        1, n_modes, pf.width, pf.height, GAP, GridLayout.caption_height_for(2, caption_font_size(pf.height)), even=True
    )


def render_or_stop(renderer, camera: Camera, settings: RenderSettings, splats: int, cancel):
    """One cell's frame (in parts beyond the memory budget: `render_tiled`); a cancel set during it (the token
    reaches the native loop) stops the video at once."""
    try:
        return render_tiled(renderer, camera, settings, splats, cancel=cancel)
    except RenderCancelled:
        raise VideoCancelled("video cancelled; nothing written") from None


def record_video(
    scene: Scene,
    camera_path: Sequence[PathFrame | Camera],
    settings_list: Sequence[RenderSettings],
    out: str | Path,
    *,
    fps: float = 30.0,
    backend: str = "cpu",
    inset: tuple[float, float, float, float] | None = None,
    codec: str = "h264",
    crf: int | None = None,
    force: bool = False,
    progress: Callable[[int, int], None] | None = None,
    cancel=None,
) -> VideoInfo:
    """Render every frame of `camera_path` in every mode of `settings_list` side by side and write a video
    (`write_video`: `codec` in the container `out`'s extension names, quality `crf`, default the codec's).

    camera_path: PathFrames (`gbviewer.model.camera_paths`) or plain Cameras (rate 1, pane = the camera's size); every
    frame must have the same pane size. Frames are rendered, composed and piped to ffmpeg (imageio-ffmpeg's bundled
    one) one at a time, so memory does not grow with the length; the CPU backend uses every core for each frame.

    Safe to call from a background thread with a backend that needs no GL context (`Capabilities.gl_context`: a
    GL backend's context belongs to the thread that made it; the cpu renderer releases the GIL):
      progress(done, total) is called after each frame is encoded (from the calling thread);
      cancel: a gbviewer.CancelToken, threading.Event or anything with is_set(), checked before each render; when
      set, ffmpeg is stopped, the partial file removed and VideoCancelled (a gbviewer.Cancelled) raised.
    The video is written to a temporary file beside `out` and renamed onto it at the end: an exception, Ctrl-C
    or cancel leaves neither. Refuses to overwrite an existing `out` unless `force`.
    Returns a VideoInfo (path, frame count, frame size, fps, wall time).
    """
    require("video", "imageio_ffmpeg", "a video")
    out = Path(out)
    encoder, crf = video_encoder(out, codec, crf)
    refuse_overwrite(out, force)
    frames = [pf if isinstance(pf, PathFrame) else PathFrame.of(pf) for pf in camera_path]
    if not frames:
        raise GBViewerError("the camera path has no frames")
    if not settings_list:
        raise GBViewerError("no modes given")
    if any((pf.width, pf.height) != (frames[0].width, frames[0].height) for pf in frames):
        raise GBViewerError("every frame of the camera path must have the same pane size")
    fps = real(fps, "fps", lo=MIN_FPS, hi=MAX_FPS)
    renderer = get_renderer(scene, backend)
    t0 = time.perf_counter()

    def images() -> Iterator[np.ndarray]:
        for i, pf in enumerate(frames):
            cells = []
            for s in settings_list:
                if cancel is not None and cancel.is_set():
                    raise VideoCancelled("video cancelled; nothing written")
                cells.append(Cell.of(s, pf.rate, render_or_stop(renderer, pf.camera, s, scene.num_splats, cancel)))
            yield np.asarray(compose_video_frame(cells, pf, inset))
            if progress is not None:
                progress(i + 1, len(frames))

    width, height = write_video(out, images(), len(frames), fps=fps, codec=codec, crf=crf, force=force)
    return VideoInfo(out, len(frames), width, height, float(fps), time.perf_counter() - t0)


@cache
def available_encoders() -> frozenset[str]:
    """The video encoders imageio-ffmpeg's ffmpeg has (`ffmpeg -encoders`), read once."""
    imageio_ffmpeg = require("video", "imageio_ffmpeg", "a video")
    listing = subprocess.run(
        [imageio_ffmpeg.get_ffmpeg_exe(), "-hide_banner", "-encoders"], capture_output=True, text=True, check=False
    ).stdout
    return frozenset(
        line.split()[1] for line in listing.splitlines() if len(line.split()) > 1 and line.split()[0].startswith("V")
    )


def video_encoder(out: str | Path, codec: str, crf: int | None = None) -> tuple[str, int]:
    """The ffmpeg encoder that writes `codec` into `out` (its extension: .mp4 or .webm) and the checked quality
    (`crf`, default the codec's); a one-line `GBViewerError` for an unknown codec or container, a codec the
    container cannot hold, or one the ffmpeg at hand has no encoder for."""
    out = Path(out)
    if codec not in CODECS:
        raise GBViewerError(f"codec {codec!r:.40}: expected one of {', '.join(CODECS)}")
    ext = out.suffix.lower()
    if ext not in CONTAINERS:
        raise GBViewerError(f"{out}: output must end in {' or '.join(CONTAINERS)}")
    if codec not in CONTAINERS[ext]:
        raise GBViewerError(
            f"{out}: a {ext[1:].upper()} file cannot hold {codec}; use {', '.join(CONTAINERS[ext])} or write .mp4"
        )
    c = CODECS[codec]
    crf = integer(c.default_crf if crf is None else crf, f"crf of {codec}", lo=c.min_crf, hi=c.max_crf)
    have = available_encoders()
    encoder = next((e for e in c.encoders if e in have), None)
    if encoder is None:
        exe = require("video", "imageio_ffmpeg", "a video").get_ffmpeg_exe()
        raise GBViewerError(f"codec {codec}: the ffmpeg at hand ({exe}) has no {' or '.join(c.encoders)} encoder")
    return encoder, crf


def write_video(
    out: str | Path,
    images: Iterable[np.ndarray],
    count: int,
    *,
    fps: float = 30.0,
    codec: str = "h264",
    crf: int | None = None,
    force: bool = False,
) -> tuple[int, int]:
    """Stream `count` uint8 (H, W, 3) images of one size to imageio-ffmpeg's ffmpeg (`video_encoder`'s encoder,
    yuv420p, constant quality `crf`) into `out`, atomically: written beside it and renamed at the end, so an
    exception raised by `images` (a cancel) leaves no file. Returns (width, height)."""
    imageio_ffmpeg = require("video", "imageio_ffmpeg", "a video")
    encoder, crf = video_encoder(out, codec, crf)
    extra = ["-movflags", "+faststart"] if Path(out).suffix.lower() == ".mp4" else []
    size: list[int] = []

    def write(tmp: Path) -> None:
        writer = None
        try:
            for img in images:
                if writer is None:
                    size[:] = [img.shape[1], img.shape[0]]
                    writer = imageio_ffmpeg.write_frames(
                        str(tmp),
                        tuple(size),
                        fps=Fraction(fps).limit_denominator(1001),
                        codec=encoder,
                        pix_fmt_out="yuv420p",
                        quality=None,
                        macro_block_size=1,
                        output_params=["-crf", str(crf), *CODECS[codec].options[encoder], *extra],
                    )
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
