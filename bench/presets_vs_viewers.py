"""Our viewer presets against the real viewers: the same cameras rendered by Spark (npm @sparkjsdev/spark + three)
and the PlayCanvas engine (npm playcanvas, what SuperSplat runs) in headless Chromium (WebGL2 through SwiftShader),
read back, and compared with our CPU renderer's presets and modes: PSNR per (scene, viewer, our spec), averaged over
the cameras. Each preset is shown twice: with its viewer rules (gbviewer/render/presets.py) and with them off (the
2D filter only), so the table says what the rules gain. The antimatter15 viewer is not on npm, so it is not run.

    python bench/presets_vs_viewers.py [SCENE ...] [--viewers spark,playcanvas] [--cameras 3] [--size 256x192]

Needs `chromium` (Debian's package) and `npm`; the viewers are installed with npm into --cache (never into the
repository). Where something is missing it says what in one line and exits 2. Not part of the test suite."""

from __future__ import annotations

import argparse
import json
import math
import shutil
import subprocess
import sys
import threading
from dataclasses import replace
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from io import BytesIO
from pathlib import Path

import numpy as np
from PIL import Image

import gbviewer as gb
from gbviewer.model.camera import orbit_camera
from gbviewer.render import RenderSettings
from gbviewer.render.presets import PRESETS

HERE = Path(__file__).resolve().parent
HARNESS = HERE / "viewers"
PACKAGES = {"spark": ["@sparkjsdev/spark@2.2.0", "three"], "playcanvas": ["playcanvas"]}
MODES = ("scalar", "mip")
RULES_OFF = dict(dc_clamp=False, support=0.0, sort_radial=False)


def missing_tools() -> list[str]:
    """The tools this bench cannot run without, where they are absent."""
    return [name for name in ("chromium", "npm") if shutil.which(name) is None]


def ensure_packages(cache: Path, viewers: list[str]) -> None:
    """npm install the viewers' packages into `cache` (a directory outside the repository) where absent."""
    wanted = [p for v in viewers for p in PACKAGES[v]]
    todo = [p for p in wanted if not (cache / "node_modules" / (p[: p.rfind("@")] if p.rfind("@") > 0 else p)).is_dir()]
    if todo:
        cache.mkdir(parents=True, exist_ok=True)
        subprocess.run(
            ["npm", "install", "--no-audit", "--no-fund", "--prefix", str(cache), *todo],
            check=True,
            stdout=subprocess.DEVNULL,
        )


def write_ply(scene: gb.Scene, path: Path) -> None:
    """The scene as a standard 3DGS binary PLY (log scales, logit opacities, f_dc, channel-major f_rest)."""
    n, k = len(scene.means), scene.sh.shape[1]
    o = np.clip(np.asarray(scene.opacities, np.float64), 1e-7, 1 - 1e-7)
    sh = np.asarray(scene.sh, np.float32)
    cols = [
        np.asarray(scene.means, np.float32),
        sh[:, 0],
        sh[:, 1:].transpose(0, 2, 1).reshape(n, -1),
        np.log(o / (1 - o)).astype(np.float32)[:, None],
        np.log(np.maximum(np.asarray(scene.scales, np.float64), 1e-12)).astype(np.float32),
        np.asarray(scene.quats, np.float32),
    ]
    names = (
        ["x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2"]
        + [f"f_rest_{i}" for i in range(3 * (k - 1))]
        + ["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]
    )
    header = "ply\nformat binary_little_endian 1.0\nelement vertex %d\n%send_header\n" % (
        n,
        "".join(f"property float {c}\n" for c in names),
    )
    path.write_bytes(header.encode() + np.ascontiguousarray(np.concatenate(cols, 1), "<f4").tobytes())


def cameras(scene: gb.Scene, count: int, width: int, height: int, fov_y: float = 50.0) -> list[gb.Camera]:
    return [
        orbit_camera(
            scene, azimuth_deg=30.0 + 360.0 * i / count, elevation_deg=15.0, width=width, height=height, fov_y_deg=fov_y
        )
        for i in range(count)
    ]


def camera_json(cam: gb.Camera, fov_y: float) -> dict:
    """harness.js's camera: eye and the right / up / back axes (three.js and PlayCanvas look down -z, y up)."""
    R = np.asarray(cam.R, np.float64)
    return dict(
        width=cam.width,
        height=cam.height,
        fov_y=fov_y,
        eye=cam.position.tolist(),
        right=R[0].tolist(),
        up=(-R[1]).tolist(),
        back=(-R[2]).tolist(),
    )


class Page(BaseHTTPRequestHandler):
    """Serves the harness, the npm cache, the scene and the job; receives the frames."""

    files: dict[str, Path | bytes] = {}
    npm: Path = Path()
    frames: dict[int, np.ndarray] = {}
    finished = threading.Event()
    error = ""

    def log_message(self, *args) -> None:
        pass

    def do_GET(self) -> None:
        path = self.path.split("?")[0]
        body = self.files.get(path)
        if body is None and path.startswith("/npm/") and ".." not in path:
            body = self.npm / "node_modules" / path[len("/npm/") :]
        data = body if isinstance(body, bytes) else body.read_bytes() if body and body.is_file() else None
        if data is None:
            self.send_error(404)
            return
        self.send_response(200)
        types = {
            ".js": "text/javascript",
            ".mjs": "text/javascript",
            ".html": "text/html",
            ".json": "application/json",
            ".wasm": "application/wasm",
        }
        self.send_header("Content-Type", types.get(Path(path).suffix, "application/octet-stream"))
        self.end_headers()
        self.wfile.write(data)

    def do_POST(self) -> None:
        data = self.rfile.read(int(self.headers.get("Content-Length", 0)))
        if self.path.startswith("/frame/"):
            Page.frames[int(self.path.rsplit("/", 1)[1])] = np.asarray(Image.open(BytesIO(data)).convert("RGB"))
        elif self.path == "/error":
            Page.error = data.decode(errors="replace")
            Page.finished.set()
        elif self.path == "/done":
            Page.finished.set()
        self.send_response(204)
        self.end_headers()


def run_viewer(viewer: str, ply: Path, cams: list[dict], cache: Path, timeout: float) -> list[np.ndarray]:
    """The viewer's frames of `cams` (uint8 (H, W, 3) each); RuntimeError naming what failed."""
    job = dict(cameras=cams, settle_frames=12, settle_ms=150)
    Page.files = {
        "/harness.html": HARNESS / "harness.html",
        "/harness.js": HARNESS / "harness.js",
        "/scene.ply": ply,
        "/job.json": json.dumps(job).encode(),
    }
    Page.npm, Page.frames, Page.error = cache, {}, ""
    Page.finished.clear()
    server = ThreadingHTTPServer(("127.0.0.1", 0), Page)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    url = f"http://127.0.0.1:{server.server_port}/harness.html?viewer={viewer}"
    flags = [
        "--headless=new",
        "--no-sandbox",
        "--use-angle=swiftshader",
        "--enable-unsafe-swiftshader",
        "--ignore-gpu-blocklist",
        "--disable-gpu-sandbox",
        f"--user-data-dir={cache / 'chromium-profile'}",
    ]
    browser = subprocess.Popen(["chromium", *flags, url], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        done = Page.finished.wait(timeout)
    finally:
        browser.kill()
        browser.wait()
        server.shutdown()
    if Page.error or not done or len(Page.frames) != len(cams):
        raise RuntimeError(
            Page.error.splitlines()[0] if Page.error else f"{len(Page.frames)} of {len(cams)} frames in {timeout:g} s"
        )
    return [Page.frames[i] for i in range(len(cams))]


def our_specs() -> dict[str, RenderSettings]:
    """Our modes, and each preset with its viewer rules and without them ('-2d': the 2D filter alone)."""
    out = {m: RenderSettings.parse(m) for m in MODES}
    for name, p in PRESETS.items():
        s = RenderSettings.parse(f"preset:{name}")
        out[f"preset:{name}"] = s
        if replace(p.view_filter, **RULES_OFF) != p.view_filter:
            out[f"preset:{name}-2d"] = replace(s, view_filter=replace(p.view_filter, **RULES_OFF), preset="")
    return out


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    mse = float(np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2)) / 255.0**2
    return math.inf if mse == 0 else -10.0 * math.log10(mse)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenes", nargs="*", help="scene files (default: the bundled scene)")
    ap.add_argument("--viewers", default="spark,playcanvas")
    ap.add_argument("--cameras", type=int, default=3)
    ap.add_argument("--size", default="256x192")
    ap.add_argument("--cache", type=Path, default=Path.home() / ".cache" / "gbviewer-viewers")
    ap.add_argument("--timeout", type=float, default=600.0, help="seconds per viewer and scene")
    args = ap.parse_args(argv)
    gone = missing_tools()
    if gone:
        print(f"presets_vs_viewers: not run: {', '.join(gone)} not found (Debian: apt-get install chromium npm)")
        return 2
    viewers = [v for v in args.viewers.split(",") if v]
    unknown = [v for v in viewers if v not in PACKAGES]
    if unknown:
        print(f"presets_vs_viewers: --viewers {','.join(unknown)}: expected some of {','.join(PACKAGES)}")
        return 2
    width, height = (int(v) for v in args.size.lower().split("x"))
    ensure_packages(args.cache, viewers)
    scenes = args.scenes or [str(HERE.parent / "assets" / "fruit_drops_minimal.ply")]
    specs = our_specs()
    print("scene | viewer | " + " | ".join(specs))
    for path in scenes:
        scene = gb.load(path)
        cams = cameras(scene, args.cameras, width, height)
        ply = args.cache / "scene.ply"
        write_ply(scene, ply)
        ours = {
            k: [np.clip(np.rint(gb.get_renderer(scene, "cpu").render(c, s).rgb * 255), 0, 255) for c in cams]
            for k, s in specs.items()
        }
        for viewer in viewers:
            try:
                theirs = run_viewer(viewer, ply, [camera_json(c, 50.0) for c in cams], args.cache, args.timeout)
            except RuntimeError as exc:
                print(f"{Path(path).name} | {viewer} | failed: {exc}")
                continue
            row = [np.mean([psnr(o, t) for o, t in zip(ours[k], theirs)]) for k in specs]
            print(f"{Path(path).name} | {viewer} | " + " | ".join(f"{v:.2f}" for v in row), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
