"""Everything only a GPU can check, in one run (bench/gpu_session.sh builds the modules, then runs this):

    python bench/gpu_session.py OUT_DIR [--scenes DIR] [--no-gpu] [--deadline EPOCH_SECONDS] [--build-log FILE]

Pieces: the CUDA test files; CUDA vs CPU images for every mode and supersample 1-3 on the shared scenes (the
tolerances of tests/render/test_cuda.py); the GLSL backend on the machine's EGL driver vs CPU (test_glsl.py's
tolerances); CUDA-GL interop and the GLSL display path under a headless EGL context; timings (ms per mode at
1920x1080 per shared scene and on a 6 M-splat synthetic scene) next to the paper's GB/3DGS time ratio. Each piece is
one line of OUT_DIR/report.txt (and an entry of report.json; gpu_session_report.py writes them): ok, failed, "no
GPU: why", "skipped: why" or "partial: why" (comparisons cut short by the time budget, none of those made failing);
a comparison the backend refuses in one line (RenderError: its stated limits, e.g. a driver's loop limit) is named
on the line with the refusal, not counted as failing.
Without a CUDA device the GLSL pieces still run (on whatever EGL driver there is, Mesa llvmpipe included). A piece
that runs past the deadline is cut short and says so. Exit status 1 when a piece failed or a file is missing."""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
if any((REPO / "gbviewer").glob("_native*")):  # the checkout's build (gpu_session.sh's), else the installed package
    sys.path.insert(0, str(REPO))

from gpu_session_report import Session  # noqa: E402

import gbviewer as gb  # noqa: E402
from gbviewer.render import CudaRenderer, RenderSettings  # noqa: E402

# The test files only a GPU runs in full (bench/cuda_check.py runs them too); tests/install/test_gpu_session.py checks
# that they exist.
CUDA_TEST_FILES = (
    "tests/render/test_cuda.py",
    "tests/render/test_cuda_gpu.py",
    "tests/render/test_cuda_native.py",
    "tests/render/test_cuda_host.py",
    "tests/render/test_cuda_wrapper.py",
    "tests/render/test_render_to_texture.py",
    "tests/render/test_duplex_order.py",
    "tests/render/test_gpu_lod.py",
)
GLSL_TEST_FILES = ("tests/render/test_glsl.py",)
PIECES = ("cuda tests", "cuda vs cpu", "glsl on the EGL driver", "glsl vs cpu", "display path + interop", "timings")
CUDA_PIECES = ("cuda tests", "cuda vs cpu", "timings")  # the others need an OpenGL 4.3 context (any EGL driver)
MODES = (*(m.label for m in gb.Mode), "stopthepop:0")  # every mode; stopthepop also with the exact per-pixel sort
CUDA_TOL = dict(mean=1e-4, frac=0.002, counts="exact")  # tests/render/test_cuda.py
GLSL_TOL = dict(mean=1e-3, frac=0.002, counts=1e-4)  # tests/render/test_glsl.py (counts: relative slack)
# Gaussian Blending paper, Table 5 (multi-scale Blender, x1): 3DGS 131.80 FPS, Gaussian Blending-30K 123.08 FPS
PAPER_GB_OVER_3DGS = 131.80 / 123.08
LARGE_SPLATS = 6_000_000
SIZE = (1920, 1080)


def default_scenes() -> Path:
    for d in (REPO / "shared" / "scenes", REPO.parent / "shared" / "scenes"):
        if d.is_dir():
            return d
    return REPO.parent / "shared" / "scenes"


def check_paths(s: Session, scenes_dir: Path) -> list[Path]:
    """The files this session runs exist (the rot bench/cuda_check.py once had); returns the scenes."""
    missing = [f for f in (*CUDA_TEST_FILES, *GLSL_TEST_FILES) if not (REPO / f).is_file()]
    found = lambda d: sorted(p for p in d.glob("*") if p.suffix in (".ply", ".splat", ".spz", ".sog"))  # noqa: E731
    scenes, where = found(scenes_dir), f"{scenes_dir}"
    if not scenes:
        scenes, where = found(gb.DEFAULT_SCENE.parent), f"the bundled scene only ({scenes_dir} has none)"
    s.add(
        "paths",
        "missing: " + ", ".join(missing) if missing else "ok",
        f"{len(CUDA_TEST_FILES) + len(GLSL_TEST_FILES)} test files, {len(scenes)} scenes: {where}",
    )
    return scenes


def pytest_piece(s: Session, name: str, files: tuple[str, ...], budget: float) -> None:
    """Run the test files; the piece lists per file passed/failed/skipped and the failing tests."""
    xml = s.out / f"{name.replace(' ', '_')}.xml"
    cmd = [sys.executable, "-m", "pytest", "-q", "-rfEs", "-p", "no:cacheprovider", f"--junitxml={xml}", *files]
    try:
        proc = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=max(budget, 10))
        (s.out / f"{name.replace(' ', '_')}.log").write_text(proc.stdout + proc.stderr)
    except subprocess.TimeoutExpired:
        s.add(name, "failed", f"pytest ran past its {budget:.0f} s budget")
        return
    if not xml.exists():
        s.add(name, "failed", f"pytest exit {proc.returncode}: {(proc.stdout + proc.stderr).strip()[-300:]}")
        return
    rows, failing = {}, []
    for case in ET.parse(xml).getroot().iter("testcase"):
        f = case.get("file") or case.get("classname", "?").replace(".", "/") + ".py"
        kind = (
            "failed"
            if case.find("failure") is not None or case.find("error") is not None
            else ("skipped" if case.find("skipped") is not None else "passed")
        )
        rows.setdefault(f, dict(file=f, passed=0, failed=0, skipped=0))[kind] += 1
        if kind == "failed":
            failing.append(f"{case.get('classname')}::{case.get('name')}")
    total = {k: sum(r[k] for r in rows.values()) for k in ("passed", "failed", "skipped")}
    s.add(
        name,
        "ok" if proc.returncode == 0 else "failed",
        f"{total['passed']} passed, {total['failed']} failed, {total['skipped']} skipped"
        + (f"; failing: {', '.join(failing[:8])}" if failing else ""),
        list(rows.values()),
    )


def diff(a: gb.Frame, b: gb.Frame) -> dict:
    """Image differences and the counts that must agree across backends: visible splats and tile-list entries
    (pairs; sort_length differs by design, the cpu sorts one key per splat, the gpus one per pair)."""
    d = np.abs(a.rgb - b.rgb).max(axis=2)
    return dict(
        mean=float(d.mean()),
        max=float(d.max()),
        frac=float((d > 1 / 255).mean()),
        visible=(a.stats.visible, b.stats.visible),
        pairs=(a.stats.pairs, b.stats.pairs),
    )


def within(m: dict, tol: dict) -> bool:
    counts = all(
        x == y if tol["counts"] == "exact" else abs(x - y) <= tol["counts"] * max(y, 1)
        for x, y in (m["visible"], m["pairs"])
    )
    return m["mean"] < tol["mean"] and m["frac"] < tol["frac"] and counts


def compare_piece(s: Session, name: str, scenes: list[Path], make, tol: dict, supersamples, budget_end: float):
    """Every mode x supersample on every scene, backend `make()` against the CPU."""
    rows, bad, cut, refused = [], 0, "", {}
    other = make()
    for path in scenes:
        if time.time() > budget_end:
            cut = f"time budget spent before {path.name} and the scenes after it"
            break
        scene = gb.load(path)
        other.upload(scene)
        cam = gb.orbit_camera(scene, 40, 15, width=320, height=240)
        for mode in MODES:
            for ss in supersamples:
                settings = RenderSettings.parse(mode, supersample=ss)
                error, ok = "", None
                try:
                    m = diff(other.render(cam, settings), gb.render(scene, cam, settings, backend="cpu"))
                    ok = within(m, tol)
                except gb.GBViewerError as exc:
                    m = dict(mean=float("nan"), max=float("nan"), frac=float("nan"), visible=(0, 1), pairs=(0, 1))
                    error = str(exc)
                    # a one-line refusal (RenderError: e.g. llvmpipe's loop limit on the per-pixel sorted modes) is
                    # the backend's stated limit, reported apart (ok None); any other error fails the piece
                    ok = None if type(exc) is gb.RenderError else False
                bad += ok is False
                if ok is None:
                    refused.setdefault(error, []).append(f"{path.name} {settings.spec}")
                rows.append(
                    dict(
                        scene=path.name,
                        mode=mode,
                        ss=ss,
                        mean=m["mean"],
                        max=m["max"],
                        frac=m["frac"],
                        visible=f"{m['visible'][0]}/{m['visible'][1]}",
                        pairs=f"{m['pairs'][0]}/{m['pairs'][1]}",
                        ok=ok,
                        error=error,
                    )
                )
    why = "".join(f"; refused ({', '.join(what)}): {error}" for error, what in refused.items())
    s.add(
        name,
        "failed" if bad else f"partial: {cut}" if cut else "ok",
        f"{len(rows)} comparisons, {bad} outside mean < {tol['mean']}, >1/255 < {tol['frac']}, counts "
        f"{tol['counts']}{why}",
        rows,
    )


def interop_piece(s: Session, scene_path: Path, cuda: bool) -> None:
    """The GLSL display path and (with `cuda`) CUDA-GL interop on the process's headless EGL context: a texture
    written by render_to_texture holds render()'s frame exactly."""
    from gbviewer.render.glsl import GlslRenderer, standalone_context

    try:
        ctx = standalone_context()
    except gb.BackendUnavailable as exc:
        s.add("display path + interop", "failed", f"no headless EGL context: {exc}")
        return
    gl = ctx.info.get("GL_RENDERER", "?")
    scene = gb.load(scene_path)
    cam = gb.orbit_camera(scene, 30, 10, width=97, height=61)
    rows = []
    ok_interop, why = CudaRenderer.gl_interop() if cuda else (False, "no GPU")
    backends = [("glsl", lambda: GlslRenderer(ctx=ctx))] + ([("cuda", CudaRenderer)] if ok_interop else [])
    for name, make in backends:
        r = make()
        r.upload(scene)
        for spec in ("scalar", "gaussian_blending:2", "duplex"):
            settings = RenderSettings.parse(spec)
            tex = ctx.texture((97, 61), 4, dtype="f4")
            try:
                r.render_to_texture(tex, cam, settings)
                img = np.frombuffer(tex.read(), np.float32).reshape(61, 97, 4)
                frame = r.render(cam, settings)
                same = bool(np.array_equal(img[:, :, :3], frame.rgb) and np.array_equal(img[:, :, 3], frame.alpha))
                rows.append(dict(backend=name, spec=spec, same=same, error=""))
            except gb.GBViewerError as exc:
                rows.append(dict(backend=name, spec=spec, same=False, error=str(exc)))
            finally:
                if hasattr(r, "release_texture"):
                    r.release_texture(tex.glo)
                tex.release()
    good = all(r["same"] for r in rows) and (ok_interop or not cuda)
    s.add(
        "display path + interop",
        "ok" if good else "failed",
        f"EGL on {gl}; cuda interop: {'yes' if ok_interop else why}; "
        f"{sum(r['same'] for r in rows)}/{len(rows)} textures equal render()",
        rows,
    )


def time_scene(r, scene: gb.Scene, label: str, repeat: int = 5, modes: tuple[str, ...] = MODES) -> list[dict]:
    r.upload(scene)
    cam = gb.orbit_camera(scene, 30, 10, width=SIZE[0], height=SIZE[1])
    rows = []
    for mode in modes:
        settings = RenderSettings.parse(mode)
        r.render(cam, settings)  # warm-up: buffers sized, cells built
        wall, gpu = [], []
        for _ in range(repeat):
            t0 = time.perf_counter()
            f = r.render(cam, settings)
            wall.append((time.perf_counter() - t0) * 1e3)
            gpu.append(f.stats.preprocess_ms + f.stats.sort_ms + f.stats.blend_ms)
        rows.append(
            dict(
                scene=label,
                splats=scene.num_splats,
                mode=mode,
                wall_ms=float(np.median(wall)),
                gpu_ms=float(np.median(gpu)),
            )
        )
    by = {row["mode"]: row["gpu_ms"] for row in rows}
    for row in rows:
        row["gb_over_3dgs"] = by["gaussian_blending"] / by["scalar"] if row["mode"] == "gaussian_blending" else ""
    return rows


def timing_piece(s: Session, scenes: list[Path], budget_end: float) -> None:
    r = CudaRenderer()
    rows, cut = [], ""
    for path in scenes:
        if time.time() > budget_end:
            cut = f"; time budget spent before {path.name}"
            break
        rows += time_scene(r, gb.load(path), path.name)
    large = ""
    if not cut and time.time() < budget_end - 60:
        sys.path.insert(0, str(REPO / "bench"))
        from synthetic import make_scene

        rows += time_scene(
            r,
            make_scene(LARGE_SPLATS),
            f"synthetic {LARGE_SPLATS // 10**6} M",
            repeat=3,
            modes=tuple(m for m in MODES if m != "duplex"),
        )
        large = "; duplex not timed on it (its cells would be built on the CPU first)"
    else:
        large = "; the 6 M-splat scene not timed (time budget)"
    ratios = [row["gb_over_3dgs"] for row in rows if row["gb_over_3dgs"] != ""]
    s.add(
        "timings",
        "ok" if rows and not cut else "failed",
        f"ms per mode at {SIZE[0]}x{SIZE[1]} (median; gpu_ms = device events); GB/3DGS time ratio "
        f"{min(ratios, default=float('nan')):.2f}..{max(ratios, default=float('nan')):.2f} here, "
        f"{PAPER_GB_OVER_3DGS:.2f} in the paper (Table 5: 131.80 vs 123.08 FPS); no tiled-scene builder exists in "
        f"the repository: bench/synthetic.py's scene of {LARGE_SPLATS:,} splats stands in{cut}{large}",
        rows,
    )


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("--scenes", type=Path, default=None)
    ap.add_argument("--no-gpu", action="store_true", help="run no CUDA piece (the GLSL pieces still run)")
    ap.add_argument("--pieces", default=",".join(PIECES), help="comma-separated pieces to run (default: all)")
    ap.add_argument("--deadline", type=float, default=time.time() + 420)
    ap.add_argument("--build-log", type=Path, default=None, help="the build's one-line summary (gpu_session.sh)")
    args = ap.parse_args(argv)
    chosen = [p.strip() for p in args.pieces.split(",") if p.strip()]
    if unknown := sorted(set(chosen) - set(PIECES)):
        ap.error(f"--pieces: unknown {', '.join(unknown)}; expected some of: {', '.join(PIECES)}")
    s = Session(args.out, args.deadline)
    if args.build_log is not None and args.build_log.exists():
        status, _, detail = args.build_log.read_text().strip().partition(": ")
        s.add("build", status, detail)
    scenes = check_paths(s, args.scenes or default_scenes())
    ok, why = CudaRenderer.available()
    cuda = ok and not args.no_gpu
    no_cuda = "no GPU: --no-gpu given" if args.no_gpu else f"no GPU: the cuda backend is unavailable: {why}"
    no_gl = ""
    try:
        from gbviewer.render.glsl import GlslRenderer, standalone_context

        standalone_context()
    except gb.BackendUnavailable as exc:
        no_gl = f"skipped: no OpenGL 4.3 context through EGL: {exc}"

    def runs(name: str) -> bool:
        why_not = (
            no_cuda
            if name in CUDA_PIECES and not cuda
            else no_gl
            if name not in CUDA_PIECES and no_gl
            else "skipped: not selected (--pieces)"
            if name not in chosen
            else ""
        )
        if why_not:
            s.add(name, why_not, "")
        return not why_not

    # each piece gets a share of the time left when it starts (what one does not use goes to the next)
    if runs("cuda tests"):
        pytest_piece(s, "cuda tests", CUDA_TEST_FILES, 0.3 * s.left())
    if runs("cuda vs cpu"):
        compare_piece(s, "cuda vs cpu", scenes, CudaRenderer, CUDA_TOL, (1, 2, 3), time.time() + 0.35 * s.left())
    if runs("glsl on the EGL driver"):
        pytest_piece(s, "glsl on the EGL driver", GLSL_TEST_FILES, 0.3 * s.left())
    if runs("glsl vs cpu"):
        compare_piece(s, "glsl vs cpu", scenes, GlslRenderer, GLSL_TOL, (1,), time.time() + 0.3 * s.left())
    if runs("display path + interop"):
        interop_piece(s, scenes[0] if scenes else gb.DEFAULT_SCENE, cuda)
    if runs("timings"):
        timing_piece(s, scenes, s.deadline - 15)
    return 1 if any(p["status"].startswith(("failed", "missing")) for p in s.pieces) else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
