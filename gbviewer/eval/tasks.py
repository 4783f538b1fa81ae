"""One evaluation task: a scene's view rendered in every mode at every rate and measured against its ground truth.
The same function runs in this process, in a process pool and as a Ray task; each worker loads a scene once."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from functools import lru_cache
from pathlib import Path

from ..core.errors import GBViewerError
from ..io import load
from ..io.datasets import View
from ..model.scene import Scene
from ..outputs.metrics import psnr, ssim
from ..render import AUTO, RenderSettings, choose_backend, get_renderer
from .multiscale import camera_for_rate, ground_truths


@dataclass(frozen=True)
class ViewTask:
    """Everything a worker needs (picklable): which scene file, which view, the modes, rates, background, backend
    (auto: what `choose_backend` picks in the worker), CPU threads per render (0: all) and the cache folder."""

    scene: str
    scene_index: int
    view_index: int
    view: View
    settings: tuple[RenderSettings, ...]
    rates: tuple[float, ...]
    background: tuple[float, float, float]
    backend: str = "auto"
    threads: int = 0
    cache: str | None = None


@dataclass
class ViewResult:
    """The measures of one view: per mode and rate, PSNR, SSIM and the render's time (ms)."""

    scene_index: int
    view_index: int
    name: str
    backend: str
    results: list[dict] = field(default_factory=list)


def _scene(path: str) -> Scene:
    """A worker's scenes, each loaded once (tasks come scene by scene) for as long as its file is the same: an
    in-process run, or a Ray worker that lives on, evaluated a replaced file's old scene in the next run."""
    return _loaded(path, file_identity(Path(path)))


@lru_cache(maxsize=2)
def _loaded(path: str, identity: tuple) -> Scene:
    return load(path)


def file_identity(path: Path) -> tuple:
    """What changes whenever the file (a SOG folder: any of its files) is written or replaced: its inode, size,
    modification and status-change times (the last cannot be set back, as cp -p or rsync -a set the first)."""
    paths = sorted(path.iterdir()) if path.is_dir() else [path]
    out = []
    for p in paths:
        try:
            st = p.stat()
        except OSError:  # gone meanwhile: loading says so
            continue
        out.append((p.name, st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns, st.st_ctime_ns))
    return tuple(out)


def pick_backend(name: str) -> str:
    """`name`, or for auto: the backend `choose_backend` picks in this process (the same rule as everywhere)."""
    return choose_backend().name if name == AUTO else name


def finite(x: float) -> float | None:
    """x, or None where it is NaN or infinite (JSON has no such numbers)."""
    return x if math.isfinite(x) else None


def evaluate_view(task: ViewTask) -> ViewResult:
    """Render the view of `task` in every mode at every rate (`camera_for_rate`) and measure PSNR and SSIM against
    the ground truth at that rate."""
    backend = pick_backend(task.backend)
    renderer = get_renderer(_scene(task.scene), backend)
    cache = Path(task.cache) if task.cache is not None else None
    truths = ground_truths(task.view, task.rates, task.background, cache)
    out = ViewResult(task.scene_index, task.view_index, task.view.name, backend)
    for s in task.settings:
        settings = replace(s, background=task.background, threads=task.threads)
        for rate, truth in zip(task.rates, truths):
            frame = renderer.render(camera_for_rate(task.view.camera, rate), settings)
            out.results.append(
                {
                    "mode": s.spec,
                    "rate": rate,
                    "psnr": finite(psnr(frame.rgb, truth)),
                    "ssim": finite(ssim(frame.rgb, truth)),
                    "render_ms": frame.stats.total_ms,
                }
            )
    return out


def run_task(task: ViewTask) -> ViewResult:
    """`evaluate_view` for another process: its error comes back as a plain, picklable GBViewerError."""
    try:
        return evaluate_view(task)
    except GBViewerError as exc:
        raise GBViewerError(str(exc)) from None
