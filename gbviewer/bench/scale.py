"""The scale benchmark (`bench/scale.py`): on a tiled real-size scene (`scale_scene`), load time next to a raw read
of the same file and peak RSS (each in a fresh child process), per-stage times per mode and sampling rate, the
two-pane time (two modes of one camera, one after the other) and cancel latency. All ratios come from one run."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np

from ..core.cancel import CancelToken
from ..core.errors import RenderCancelled
from ..io import load
from ..model.camera import Camera, orbit_camera
from ..model.scene import Scene
from ..render import RenderSettings, get_renderer


def scene_bytes(scene: Scene) -> int:
    """Bytes of the scene's splat arrays."""
    arrays = [scene.means, scene.scales, scene.quats, scene.opacities, scene.sh, scene.filter_3d]
    if scene.oit is not None and scene.oit.view_weight_sh is not None:
        arrays.append(scene.oit.view_weight_sh)
    return sum(a.nbytes for a in arrays if a is not None)


def rss_bytes() -> int:
    """Resident bytes of this process now."""
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


def peak_rss_bytes() -> int:
    """The most resident bytes this process has had: VmHWM, of this process image alone (ru_maxrss is not: Linux
    hands the parent's peak at fork on to the child, across exec)."""
    with open("/proc/self/status") as fh:
        return next(int(line.split()[1]) * 1024 for line in fh if line.startswith("VmHWM:"))


def child_measure(kind: str, path: str) -> dict:
    """In a fresh process: "raw" reads the file into one numpy array, "load" runs gb.load(path); the time, resident
    bytes before and after, and the peak (`peak_rss_bytes`: the process's whole life)."""
    before = rss_bytes()
    t = time.perf_counter()
    if kind == "raw":
        with open(path, "rb") as fh:
            buf = np.empty(os.fstat(fh.fileno()).st_size, np.uint8)
            fh.readinto(buf)
        arrays = buf.nbytes
    else:
        scene = load(path)
        arrays = scene_bytes(scene)
    seconds = time.perf_counter() - t
    return {
        "seconds": seconds,
        "rss_before": before,
        "rss_after": rss_bytes(),
        "peak_rss": peak_rss_bytes(),
        "arrays": arrays,
    }


def measure_in_child(kind: str, path: Path) -> dict:
    """`child_measure` in a new interpreter (so that its peak RSS is the measured step's alone)."""
    code = "import json,sys; from gbviewer.bench.scale import child_measure as m; print(json.dumps(m(*sys.argv[1:])))"
    out = subprocess.run(
        [sys.executable, "-P", "-c", code, kind, str(path)], check=True, capture_output=True, text=True
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def measure_load(path: Path, repeat: int) -> dict:
    """Best of `repeat` raw reads and loads (warm page cache: one raw read first), with the load's memory."""
    measure_in_child("raw", path)
    raw = min((measure_in_child("raw", path) for _ in range(repeat)), key=lambda r: r["seconds"])
    loads = [measure_in_child("load", path) for _ in range(repeat)]
    best = min(loads, key=lambda r: r["seconds"])
    above = max(r["peak_rss"] - r["rss_before"] for r in loads)
    return {
        "raw_s": raw["seconds"],
        "load_s": best["seconds"],
        "load_over_raw": best["seconds"] / raw["seconds"],
        "arrays_bytes": best["arrays"],
        "baseline_rss": best["rss_before"],
        "peak_rss_above_baseline": above,
        "peak_over_arrays": above / best["arrays"],
        "after_over_arrays": (best["rss_after"] - best["rss_before"]) / best["arrays"],
    }


def scale_camera(scene: Scene, width: int = 1280, height: int = 720) -> Camera:
    """The benchmark's view: the orbit camera framing the whole tiled scene."""
    return orbit_camera(scene, 30.0, 35.0, width=width, height=height)


def _stages(frame) -> dict:
    s = frame.stats
    return {
        "preprocess_ms": s.preprocess_ms,
        "sort_ms": s.sort_ms,
        "blend_ms": s.blend_ms,
        "total_ms": s.total_ms,
        "visible": s.visible,
        "sort_length": s.sort_length,
        "evals_per_pixel": s.evals_per_pixel,
    }


def measure_stages(scene: Scene, cam: Camera, modes: list[str], rates: list[float], repeat: int) -> list[dict]:
    """Per mode and rate: the stage times of the fastest of `repeat` frames (FrameStats)."""
    renderer = get_renderer(scene, "cpu")
    rows = []
    for mode in modes:
        for rate in rates:
            view = cam.at_sampling_rate(rate)
            frames = [renderer.render(view, RenderSettings.parse(mode)) for _ in range(repeat)]
            best = min(frames, key=lambda f: f.stats.total_ms)
            rows.append({"mode": mode, "rate": rate, "width": view.width, "height": view.height, **_stages(best)})
    return rows


def measure_two_pane(scene: Scene, cam: Camera, modes: tuple[str, str]) -> dict:
    """Two panes of one camera as the viewer renders them: one `render_many` (the per-camera stage and depth order
    once, tiles interleaved) from a renderer that has not seen the camera; each pane's stage times, the call's wall
    time and when each pane's first tiles were reported (ms from the call's start). Per pane, shared_ms is the
    mode-independent work it did (the stage's preprocess and the depth order: FrameStats stage_ms + order_ms, 0
    where reused) and own_ms its mode's own finish and binning; second_over_first compares the panes' shared work
    (the issue's "preprocess + order"), before_blend_ratio all of their work before the blend."""
    renderer = get_renderer(scene, "cpu")
    renderer.render(cam.at_sampling_rate(0.5), RenderSettings())  # a stage of another camera: nothing to reuse
    jobs = [(cam, RenderSettings.parse(m)) for m in modes]
    first_tiles: dict[int, float] = {}
    t0 = time.perf_counter()

    def on_progress(k: int, done: int, total: int) -> None:
        if done > 0 and k not in first_tiles:
            first_tiles[k] = (time.perf_counter() - t0) * 1e3

    frames = renderer.render_many(jobs, on_progress=on_progress)
    total = (time.perf_counter() - t0) * 1e3
    panes = []
    for k, (m, f) in enumerate(zip(modes, frames)):
        shared = (f.stats.stage_ms or 0.0) + (f.stats.order_ms or 0.0)
        own = f.stats.preprocess_ms + f.stats.sort_ms - shared
        panes.append(
            {
                "mode": m,
                "first_tiles_ms": first_tiles.get(k),
                "stage_reused": f.stats.stage_reused,
                "order_reused": f.stats.order_reused,
                "shared_ms": shared,
                "own_ms": own,
                **_stages(f),
            }
        )
    before_blend = [p["preprocess_ms"] + p["sort_ms"] for p in panes]
    return {
        "panes": panes,
        "total_ms": total,
        "second_over_first": panes[1]["shared_ms"] / max(panes[0]["shared_ms"], 1e-9),
        "before_blend_ratio": before_blend[1] / max(before_blend[0], 1e-9),
    }


def measure_cancel(scene: Scene, cam: Camera, mode: str, moments_ms: list[float], supersample: int = 1) -> list[dict]:
    """A render whose CancelToken (what the viewer passes) is set in the middle of each stage of an uncancelled
    frame (preprocess, depth order and binning, blend) and at each of `moments_ms`: the time from the set to
    RenderCancelled (None with finished=True where the frame completed first)."""
    renderer = get_renderer(scene, "cpu")
    settings = RenderSettings.parse(mode, supersample=supersample)
    s = renderer.render(cam, settings).stats
    stages = {
        "preprocess": s.preprocess_ms / 2,
        "order+bin": s.preprocess_ms + s.sort_ms / 2,
        "blend": s.preprocess_ms + s.sort_ms + s.blend_ms / 2,
    }
    rows = []
    for stage, at in [*stages.items(), *(("", m) for m in moments_ms)]:
        token = CancelToken()
        stamp: list[float] = []

        def fire(t: CancelToken = token, st: list = stamp) -> None:
            st.append(time.perf_counter())
            t.set()

        timer = threading.Timer(at / 1e3, fire)
        t0 = time.perf_counter()
        timer.start()
        try:
            renderer.render(cam, settings, cancel=token)
            latency, finished = None, True
        except RenderCancelled:
            latency, finished = (time.perf_counter() - stamp[0]) * 1e3, False
        timer.cancel()
        rows.append(
            {
                "mode": mode,
                "supersample": supersample,
                "stage": stage,
                "set_at_ms": at,
                "latency_ms": latency,
                "finished": finished,
                "render_ms": (time.perf_counter() - t0) * 1e3,
            }
        )
    return rows


def run_scale(
    path: Path,
    repeat: int,
    modes: list[str],
    rates: list[float],
    moments_ms: list[float],
    width: int = 1280,
    height: int = 720,
    log=print,
) -> dict:
    """Every measurement of the scale benchmark on the tiled scene at `path`."""
    log(f"{path.name}: load")
    result: dict = {"file": str(path), "file_bytes": path.stat().st_size, "load": measure_load(path, repeat)}
    scene = load(path)
    result["splats"] = scene.num_splats
    cam = scale_camera(scene, width, height)
    log(f"{path.name}: stages")
    result["stages"] = measure_stages(scene, cam, modes, rates, repeat)
    log(f"{path.name}: two panes, cancel")
    result["two_pane"] = measure_two_pane(scene, cam, (modes[0], modes[-1]))
    result["cancel"] = measure_cancel(scene, cam, modes[-1], moments_ms) + measure_cancel(
        scene, scale_camera(scene, width // 2, height // 2), modes[0], [], 4
    )
    return result


def print_scale(r: dict) -> None:
    """The tables of one `run_scale` result."""
    ld = r["load"]
    print(f"\n{Path(r['file']).name}: {r['splats']:,} splats, {r['file_bytes'] / 1e9:.2f} GB")
    print(f"  raw read {ld['raw_s']:.2f} s | load {ld['load_s']:.2f} s | load/raw {ld['load_over_raw']:.2f}")
    print(
        f"  splat arrays {ld['arrays_bytes'] / 2**30:.2f} GiB | peak RSS above baseline "
        f"{ld['peak_rss_above_baseline'] / 2**30:.2f} GiB ({ld['peak_over_arrays']:.2f}x arrays) | after load "
        f"{ld['after_over_arrays']:.2f}x | baseline {ld['baseline_rss'] / 2**20:.0f} MiB"
    )
    print(
        f"  {'mode':<18}{'rate':>6}{'size':>11}{'pre ms':>9}{'sort ms':>9}{'blend ms':>10}{'total ms':>10}"
        f"{'sorted':>12}{'evals/px':>10}"
    )
    for s in r["stages"]:
        print(
            f"  {s['mode']:<18}{s['rate']:>6g}{s['width']:>6}x{s['height']:<4}{s['preprocess_ms']:>9.0f}"
            f"{s['sort_ms']:>9.0f}{s['blend_ms']:>10.0f}{s['total_ms']:>10.0f}{s['sort_length']:>12,}"
            f"{s['evals_per_pixel']:>10.0f}"
        )
    tp = r["two_pane"]
    panes = ", ".join(
        f"{p['mode']} stage+order {p['shared_ms']:.0f} ms (stage "
        f"{'reused' if p['stage_reused'] else 'built'}, order {'reused' if p['order_reused'] else 'sorted'}) "
        f"+ own finish+bin {p['own_ms']:.0f} ms, "
        f"first tiles at {p['first_tiles_ms'] or 0:.0f} ms"
        for p in tp["panes"]
    )
    print(
        f"  two panes, one camera, one render_many: {panes}; both final at {tp['total_ms']:.0f} ms; second "
        f"pane's stage+order / first's {tp['second_over_first']:.2f}, all its work before the blend / first's "
        f"{tp['before_blend_ratio']:.2f}"
    )
    for c in r["cancel"]:
        got = "finished first" if c["finished"] else f"RenderCancelled {c['latency_ms']:.1f} ms after the set"
        where = f" (mid {c['stage']})" if c["stage"] else ""
        ss = f" supersample {c['supersample']}" if c["supersample"] > 1 else ""
        print(f"  cancel {c['mode']}{ss} at {c['set_at_ms']:.0f} ms{where}: {got}")
