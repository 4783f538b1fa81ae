"""Viewer soak: open, switch and close scenes, good and bad, a few hundred times in the real window under
an Xvfb server of its own, with renders, backend switches and videos in flight; report memory over time and that
the app never died.

    python tools/soak_viewer.py --cycles 300 --out soak-report.json

Scenes: ../shared/scenes when present, the bundled scene, and bad files made here (truncated, garbage, missing,
empty, a directory, a header declaring 2^40 splats). Every `--sample` cycles (after the renders settle) the report
records RSS (VmRSS; again after glibc's malloc_trim, which tells memory in use from memory the allocator keeps),
tracemalloc's current Python allocation, the window context's live GL objects, the render worker's renderers and the
live threads; it gives first/last/max RSS and the linear-fit slope per cycle after the warm-up. Exit status 0 when
the app stayed alive, every bad file gave one error message and the GL objects came back to their level after the
warm-up.
"""

from __future__ import annotations

import argparse
import contextlib
import ctypes
import gc
import json
import os
import random
import select
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
import tracemalloc
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator

import numpy as np

REPO = Path(__file__).resolve().parents[1]
SHARED_SCENES = REPO.parent / "shared" / "scenes"
SCENE_SUFFIXES = (".ply", ".spz", ".sog", ".splat")
GL_NAME_SCAN = 4096  # GL object names probed per kind (Mesa reuses the lowest free names)


@contextlib.contextmanager
def xvfb_display(width: int = 1280, height: int = 800) -> Iterator[str]:
    """An Xvfb server on a free display number, DISPLAY pointing at it for the duration; RuntimeError when there is
    no Xvfb or it does not start."""
    exe = shutil.which("Xvfb")
    if exe is None:
        raise RuntimeError("Xvfb is not installed (apt-get install xvfb; scripts/setup.sh installs it)")
    # Xvfb picks the first free display itself (-displayfd): a number whose lock file is absent here can still be
    # taken by a server in another root or container sharing the abstract socket namespace
    read_fd, write_fd = os.pipe()
    proc = subprocess.Popen(
        [exe, "-displayfd", str(write_fd), "-screen", "0", f"{width}x{height}x24", "-nolisten", "tcp", "-noreset"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        pass_fds=(write_fd,),
    )
    os.close(write_fd)
    old = os.environ.get("DISPLAY")
    try:
        ready, _, _ = select.select([read_fd], [], [], 20)
        number = os.read(read_fd, 32).decode().strip() if ready else ""
        if not number.isdigit():
            raise RuntimeError(f"Xvfb did not start (exit {proc.poll()})")
        n = int(number)
        os.environ["DISPLAY"] = f":{n}"
        yield f":{n}"
    finally:
        os.close(read_fd)
        if old is None:
            os.environ.pop("DISPLAY", None)
        else:
            os.environ["DISPLAY"] = old
        proc.terminate()
        try:
            proc.wait(10)
        except subprocess.TimeoutExpired:
            proc.kill()


def gl_object_counts() -> dict[str, int]:
    """Live textures, buffers, vertex arrays and programs of the OpenGL context current in this thread (glIs* over
    the first GL_NAME_SCAN names): what leaks when a moderngl object is dropped without release()."""
    import glfw

    proto = ctypes.CFUNCTYPE(ctypes.c_ubyte, ctypes.c_uint)
    counts = {}
    for kind in ("Texture", "Buffer", "VertexArray", "Program"):
        is_kind = proto(glfw.get_proc_address(f"glIs{kind}"))
        counts[kind.lower()] = sum(1 for name in range(1, GL_NAME_SCAN) if is_kind(name))
    return counts


def rss_kib() -> int:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    return 0


def trim_malloc() -> bool:
    """Hand the C heap's free pages back to the system (glibc's malloc_trim), so that RSS shows what is in use rather
    than what the allocator keeps for later; False where there is no glibc."""
    try:
        return bool(ctypes.CDLL("libc.so.6").malloc_trim(0))
    except (OSError, AttributeError):
        return False


def make_bad_files(folder: Path, good: Path) -> list[Path]:
    """One file of each kind a user may open by mistake (the missing one is not created)."""
    folder.mkdir(parents=True, exist_ok=True)
    data = good.read_bytes()
    bad = {
        "truncated.ply": data[: len(data) // 2],
        "garbage.ply": random.Random(0).randbytes(4096),
        "garbage.spz": random.Random(1).randbytes(4096),
        "garbage.sog": random.Random(2).randbytes(4096),
        "empty.ply": b"",
        "huge-count.ply": b"ply\nformat binary_little_endian 1.0\nelement vertex 1099511627776\n"
        b"property float x\nproperty float y\nproperty float z\nend_header\n" + bytes(64),
    }
    for name, content in bad.items():
        (folder / name).write_bytes(content)
    (folder / "a-directory.ply").mkdir(exist_ok=True)
    return [folder / name for name in bad] + [folder / "a-directory.ply", folder / "missing.ply"]


def good_scenes() -> list[Path]:
    from gbviewer import DEFAULT_SCENE

    shared = sorted(SHARED_SCENES.glob("*")) if SHARED_SCENES.is_dir() else []
    bundled = Path(DEFAULT_SCENE)
    return [bundled] + [p for p in shared if p.suffix in SCENE_SUFFIXES and p.name != bundled.name]


@dataclass
class Soak:
    """Drives one ViewerApp through the cycles; `report()` says how it went."""

    app: object
    good: list[Path]
    bad: list[Path]
    out_dir: Path
    rng: random.Random
    samples: list[dict] = field(default_factory=list)
    bad_opened: int = 0
    bad_messages: int = 0
    problems: list[str] = field(default_factory=list)
    counts: dict[str, int] = field(default_factory=dict)

    def step_until(self, done, timeout: float = 120.0) -> bool:
        t0 = time.perf_counter()
        while not done():
            if time.perf_counter() - t0 > timeout:
                return False
            self.app.step()
            time.sleep(0.002)
        return True

    def tick(self, what: str) -> None:
        self.counts[what] = self.counts.get(what, 0) + 1

    def open_bad(self, path: Path) -> None:
        """Open a bad file, wait for the load to end: the scene stays, one error message naming the file."""
        s = self.app.state
        scene, before = s.scene, len([m for m in s.messages if m[2] == "error"])
        mark = time.perf_counter()
        s.open(path)
        if not self.step_until(lambda: s.loader is None):
            self.problems.append(f"{path.name}: the load did not end")
            return
        self.bad_opened += 1
        errors = [m for m in s.messages if m[2] == "error" and m[0] >= mark]
        if len(errors) == 1 and path.name in errors[0][1] and s.scene is scene and "\n" not in s.load_error:
            self.bad_messages += 1
        else:
            self.problems.append(
                f"{path.name}: {len(errors)} error messages, load_error {s.load_error!r}, "
                f"scene kept: {s.scene is scene} (messages before: {before})"
            )

    def cycle(self, i: int) -> None:
        from gbviewer.app.settings import MODE_NAMES

        app, s, rng = self.app, self.app.state, self.rng
        if i % 3 == 2:
            self.open_bad(self.bad[(i // 3) % len(self.bad)])
        s.open(self.good[i % len(self.good)])
        if rng.random() < 0.3:  # another scene (or a bad file) before this load or its renders finished
            app.run_frames(rng.randrange(0, 3))
            s.open(rng.choice(self.good + self.bad))
            self.tick("superseded_loads")
            app.run_frames(rng.randrange(0, 3))
            s.open(self.good[i % len(self.good)])
        if not self.step_until(lambda: s.loader is None):
            self.problems.append(f"cycle {i}: a scene load did not end")
        glsl = rng.random() < 0.1 and app.worker.backend_status("glsl")[0] is True
        if glsl:  # one small pane: llvmpipe takes seconds a frame, it is here for the switch and back
            s.set_pane_count(1)
            s.set_rate(1 / 8)
            s.set_pane(0, mode=rng.choice(("scalar", "gaussian_blending")), supersample=1, split=False)
        else:
            s.set_pane_count(rng.randint(1, 4))
            s.settings.layout = rng.choice(("row", "grid"))
            s.set_rate(rng.choice((1 / 8, 1 / 4, 1 / 2)))
            for k in range(s.settings.pane_count):
                s.set_pane(
                    k,
                    mode=rng.choice(MODE_NAMES),
                    split=rng.random() < 0.3,
                    split_mode=rng.choice(MODE_NAMES),
                    split_pos=rng.random(),
                )
        s.settings.backend = "glsl" if glsl else "cpu"
        self.tick(f"backend_{s.settings.backend}")
        for _ in range(rng.randint(2, 8)):  # camera moves: preview renders in flight
            s.controller.orbit(rng.uniform(-30, 30), rng.uniform(-10, 10))
            s.moved()
            app.step()
        if rng.random() < 0.15:
            self.video(i)
        if rng.random() < 0.5:  # let the renders finish (else the next scene opens over them)
            if not app.wait_rendered(120):
                self.problems.append(f"cycle {i}: the panes did not finish rendering")
        s.settings.backend = "cpu"

    def video(self, i: int) -> None:
        """Start a zoom video and cancel it after a few UI frames."""
        job = self.app.state.record_video(frames=60, out=self.out_dir / f"zoom-{i}.mp4")
        if job is None:
            return
        self.app.run_frames(self.rng.randint(1, 10))
        job.cancel()
        if not self.step_until(job.finished):
            self.problems.append(f"cycle {i}: a cancelled video did not stop")
        self.tick("videos_cancelled")

    def sample(self, i: int, started: float) -> None:
        self.app.wait_rendered(120)
        gc.collect()
        w = self.app.worker
        rss = rss_kib()
        trim_malloc()
        self.samples.append(
            {
                "cycle": i,
                "seconds": round(time.perf_counter() - started, 2),
                "rss_kib": rss,
                "rss_trimmed_kib": rss_kib(),
                "traced_kib": tracemalloc.get_traced_memory()[0] // 1024 if tracemalloc.is_tracing() else None,
                "gl": gl_object_counts(),
                "pane_textures": len(self.app.panes._textures),  # one per pane part shown: varies with the layout
                "renderers": len(w._renderers),
                "threads": threading.active_count(),
                "scene": self.app.state.scene_path.name if self.app.state.scene_path else None,
            }
        )


def summarise(samples: list[dict], warmup: int) -> dict:
    """First/last/max RSS, the slope per cycle after `warmup` cycles, GL objects and threads over the run."""
    after = [r for r in samples if r["cycle"] >= warmup] or samples
    cycles = np.array([r["cycle"] for r in after], float)
    rss = np.array([r["rss_kib"] for r in after], float)
    trimmed = np.array([r["rss_trimmed_kib"] for r in after], float)
    slope, trimmed_slope = (float(np.polyfit(cycles, y, 1)[0]) if len(after) > 2 else 0.0 for y in (rss, trimmed))
    out = {
        "rss_first_mib": samples[0]["rss_kib"] / 1024,
        "rss_last_mib": samples[-1]["rss_kib"] / 1024,
        "rss_max_mib": max(r["rss_kib"] for r in samples) / 1024,
        "rss_slope_kib_per_cycle": slope,
        "rss_trimmed_first_mib": samples[0]["rss_trimmed_kib"] / 1024,
        "rss_trimmed_last_mib": samples[-1]["rss_trimmed_kib"] / 1024,
        "rss_trimmed_slope_kib_per_cycle": trimmed_slope,
        "rss_after_warmup_min_mib": rss.min() / 1024,
        "rss_after_warmup_max_mib": rss.max() / 1024,
        "gl_after_warmup": after[0]["gl"],
        "gl_last": samples[-1]["gl"],
        "pane_textures_after_warmup": after[0]["pane_textures"],
        "pane_textures_last": samples[-1]["pane_textures"],
        "gl_max": {k: max(r["gl"][k] for r in samples) for k in samples[0]["gl"]},
        "threads_max": max(r["threads"] for r in samples),
    }
    if samples[0]["traced_kib"] is not None:
        traced = np.array([r["traced_kib"] for r in after], float)
        out["traced_first_mib"] = samples[0]["traced_kib"] / 1024
        out["traced_last_mib"] = samples[-1]["traced_kib"] / 1024
        out["traced_slope_kib_per_cycle"] = float(np.polyfit(cycles, traced, 1)[0]) if len(after) > 2 else 0.0
    return {k: round(v, 2) if isinstance(v, float) else v for k, v in out.items()}


def run_soak(
    cycles: int,
    sample_every: int = 0,
    warmup: int = 30,
    seed: int = 0,
    trace: bool = True,
    size: tuple[int, int] = (900, 600),
    progress: bool = False,
) -> dict:
    """The soak in the current DISPLAY; the report as a dict (`ok`: alive, one message per bad file, GL objects
    back to their level after the warm-up). Samples every `sample_every` cycles, by default once per round of the
    good scenes (so that every sample is taken with the same scene open)."""
    from gbviewer.app.window import ViewerApp

    if trace:
        tracemalloc.start()
    started = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="gbviewer-soak-") as tmp:
        tmp = Path(tmp)
        good = good_scenes()
        app = ViewerApp(good[0], settings_file=tmp / "settings.json", size=size, persist=False)
        soak = Soak(app, good, make_bad_files(tmp / "bad", good[0]), tmp, random.Random(seed))
        sample_every = sample_every or len(good)
        crash = ""
        try:
            soak.sample(0, started)
            for i in range(1, cycles + 1):
                soak.cycle(i)
                if i % sample_every == 0 or i == cycles:
                    soak.sample(i, started)
                    if progress:
                        print(json.dumps(soak.samples[-1]), file=sys.stderr, flush=True)
        except Exception as exc:  # noqa: BLE001 - the soak reports what killed the app
            import traceback

            crash = "".join(traceback.format_exception(exc))
        finally:
            alive = not app.closed and not crash
            app.close()
    if trace:
        tracemalloc.stop()
    summary = summarise(soak.samples, warmup)
    gl_back = all(summary["gl_last"][k] <= summary["gl_after_warmup"][k] for k in summary["gl_last"])
    return {
        "ok": alive and not soak.problems and soak.bad_messages == soak.bad_opened and gl_back,
        "cycles": cycles,
        "seconds": round(time.perf_counter() - started, 1),
        "alive": alive,
        "crash": crash,
        "bad_files_opened": soak.bad_opened,
        "bad_file_messages": soak.bad_messages,
        "problems": soak.problems,
        "events": soak.counts,
        "scenes": [p.name for p in soak.good],
        "renders": app.worker.rendered,
        "renders_dropped": app.worker.dropped,
        "summary": summary,
        "samples": soak.samples,
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cycles", type=int, default=300)
    ap.add_argument("--out", type=Path, default=Path("soak-report.json"))
    ap.add_argument(
        "--sample", type=int, default=0, help="record memory every N cycles (default: once per round of the scenes)"
    )
    ap.add_argument("--warmup", type=int, default=30, help="cycles before the slope is fitted")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--no-tracemalloc", action="store_true", help="RSS only (tracemalloc slows allocations)")
    args = ap.parse_args(argv)
    if args.cycles < 1 or args.sample < 0 or args.warmup < 0:
        ap.error("--cycles must be at least 1, --sample and --warmup not negative")
    if any((REPO / "gbviewer").glob("_native*")):  # this source tree when it is built, else the installed one
        sys.path.insert(0, str(REPO))
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))  # stop our Xvfb on the way out
    with xvfb_display():
        report = run_soak(args.cycles, args.sample, args.warmup, args.seed, not args.no_tracemalloc, progress=True)
    args.out.write_text(json.dumps(report, indent=1))
    print(json.dumps({k: v for k, v in report.items() if k != "samples"}, indent=1))
    return 0 if report["ok"] else 1


if __name__ == "__main__":
    sys.exit(main())
