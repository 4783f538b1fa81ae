"""The evaluation's loop: datasets read here, one task per scene view run in this process, a process pool or on
Ray, results gathered in view order (so any number of workers gives the same numbers) and averaged."""

from __future__ import annotations

import os
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from contextlib import AbstractContextManager, nullcontext
from dataclasses import dataclass, field
from multiprocessing import get_context
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from ..core.errors import GBViewerError
from ..core.files import check_writable
from ..io.datasets import View, load_dataset
from ..io.datasets.backdrop import Background, choose_background, estimate_backdrop
from ..render import RenderSettings
from .memory import check_view_memory
from .multiscale import rate_factor
from .tasks import ViewResult, ViewTask, evaluate_view, finite, run_task

# progress(description, total tasks) -> a context that yields advance(tasks done)
Progress = Callable[[str, int], AbstractContextManager[Callable[[int], None]]]


@dataclass
class SceneEval:
    """One scene against its dataset (the folder or cameras.json given): the views of the split and each one's
    measures, in dataset order, and the background they were measured on."""

    scene: Path
    dataset: Path
    format: str
    views: list[View]
    results: list[ViewResult]
    background: Background  # what the renders and RGBA photos were on (`choose_background`)

    def table(self) -> dict[tuple[str, float], dict[str, float | None]]:
        """(mode, rate) -> mean PSNR, SSIM and render time over the views."""
        rows: dict[tuple[str, float], list[dict]] = {}
        for view in self.results:
            for r in view.results:
                rows.setdefault((r["mode"], r["rate"]), []).append(r)
        return {key: {m: mean([r[m] for r in rs]) for m in ("psnr", "ssim", "render_ms")} for key, rs in rows.items()}


@dataclass(eq=False)
class EvalResult:
    """Every scene's measures and how they were run."""

    modes: list[str]
    rates: list[float]
    split: str
    background: tuple[float, float, float] | None  # the one given (None: each dataset's, `choose_background`)
    runner: str
    scenes: list[SceneEval] = field(default_factory=list)
    elapsed_s: float = 0.0


def mean(values: Sequence[float | None]) -> float | None:
    """Mean of the values; None where any is None (NaN SSIM of a tiny image, infinite PSNR) or there are none."""
    if not values or any(v is None for v in values):
        return None
    return finite(float(np.mean(values)))


def _in_process(tasks: list[ViewTask], advance: Callable[[int], None]) -> list[ViewResult]:
    """The tasks one after another in this process."""
    out = []
    for task in tasks:
        out.append(evaluate_view(task))
        advance(1)
    return out


def _pool(tasks: list[ViewTask], workers: int, advance: Callable[[int], None]) -> list[ViewResult]:
    """A pool of fresh interpreters (spawn: a forked OpenMP runtime can hang), each keeping its scenes loaded."""
    out = []
    with ProcessPoolExecutor(max_workers=workers, mp_context=get_context("spawn")) as pool:
        futures = [pool.submit(run_task, t) for t in tasks]
        try:
            for future in as_completed(futures):
                out.append(future.result())
                advance(1)
        except BaseException:
            for f in futures:
                f.cancel()
            raise
    return out


def _refuse_cache_in_datasets(cache: Path, datasets: Sequence[Path], images: str) -> None:
    """A one-line error when the cache folder is a dataset's folder (a cameras.json's: its photo folder `images`
    beside it) or inside one: downsampled photos are never written into a dataset."""
    where = cache.resolve()
    for data in datasets:
        root = data.resolve() if data.is_dir() else data.resolve().parent / images
        if where == root or root in where.parents:
            raise GBViewerError(
                f"--cache {cache}: is inside the dataset {root}; the downsampled photos never go "
                "into a dataset (give a folder outside it)"
            )


def run_eval(
    pairs: Sequence[tuple[Path, Path]],
    settings: Sequence[RenderSettings],
    rates: Sequence[float],
    *,
    split: str = "test",
    background: tuple[float, float, float] | None = None,
    images: str = "images",
    backend: str = "auto",
    workers: int = 1,
    ray: str | None = None,
    threads: int | None = None,
    cache: Path | None = None,
    progress: Progress | None = None,
) -> EvalResult:
    """Evaluate each (scene file, dataset) pair: every view of `split` in every mode of `settings` at every rate
    1/k against the photos box-downsampled by k. workers > 1: a local process pool; `ray`: a Ray cluster's
    address (local: a Ray instance started here) instead. threads: CPU threads per render (default: the cores
    shared among the workers; on Ray as `cluster.run_on_ray` chooses). cache: folder of box-downsampled photos.
    background: the renders' and RGBA photos' (None: each dataset's, as the viewer's: `choose_background`)."""
    for rate in rates:
        rate_factor(rate)
    if ray:
        from .cluster import check_address

        check_address(ray)  # before the datasets: a wrong address is one line, not minutes of Ray retries
    if cache is not None:
        _refuse_cache_in_datasets(Path(cache), [Path(data) for _, data in pairs], images)
        cache = check_writable(cache, folder=True).resolve()  # absolute: workers may run elsewhere
    runner = f"ray {ray}" if ray else f"{workers} worker{'s' * (workers > 1)}"
    result = EvalResult([s.spec for s in settings], list(rates), split, background, runner)
    tasks: list[ViewTask] = []
    if threads is None:
        threads = 0 if ray or workers == 1 else max(1, (os.cpu_count() or 1) // workers)
    for i, (scene, data) in enumerate(pairs):
        scene = Path(scene).resolve()
        if not scene.exists():
            raise GBViewerError(f"{scene}: no such scene file")
        data = Path(data).resolve()
        dataset = load_dataset(data, images)
        views = dataset.split(split)
        for view in views:
            check_view_memory(view, settings, rates, dataset.format, 1 if ray else min(workers, len(views)))
        chosen = choose_background(background, None if background is not None else estimate_backdrop(dataset.views))
        result.scenes.append(SceneEval(scene, data, dataset.format, views, [], chosen))
        tasks += [
            ViewTask(
                str(scene),
                i,
                j,
                v,
                tuple(settings),
                tuple(rates),
                chosen.colour,
                backend,
                threads,
                str(cache) if cache is not None else None,
            )
            for j, v in enumerate(views)
        ]
    t0 = time.perf_counter()
    with progress("eval", len(tasks)) if progress else nullcontext(lambda n: None) as advance:
        if ray:
            from .cluster import run_on_ray

            done = run_on_ray(tasks, ray, advance)
        elif workers > 1:
            done = _pool(tasks, workers, advance)
        else:
            done = _in_process(tasks, advance)
    result.elapsed_s = time.perf_counter() - t0
    for r in sorted(done, key=lambda r: (r.scene_index, r.view_index)):
        result.scenes[r.scene_index].results.append(r)
    return result
