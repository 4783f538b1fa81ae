"""The CPU module's binning in one global depth order (native/cpu/order.cpp, binning.cpp): every tile list equals,
entry for entry and in order, the list that sorting each tile's (depth bits, splat id) keys gives (computed here
in numpy from the frame's captured preprocess output), on the shared scenes and on adversarial depth ties; wsr's
lists are in splat order. And cancellation at random moments of a large supersampled frame, the depth sort
included, ends every render with RenderCancelled or the complete frame, and the next render is exact."""

from __future__ import annotations

import threading

import numpy as np
import pytest
from helpers import SHARED_SCENES, front_camera, shared_scene
from simd_helpers import PREPROCESS_RECORD

import gbviewer as gb
from gbviewer import _native
from gbviewer.render import Mode, RenderSettings
from gbviewer.render.cpu import CpuRenderer

SCENES = sorted(p.name for p in SHARED_SCENES.glob("*") if p.suffix != ".md") or ["biker.compressed.ply"]
TILE = 16


def captured(render) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Run render() with the capture on: (preprocess records, tile_start, keys) of its frame."""
    _native.testing.set_capture_preprocess(True)
    try:
        render()
        rec = np.frombuffer(_native.testing.captured_preprocess(), PREPROCESS_RECORD)
        starts, keys = _native.testing.captured_lists()
    finally:
        _native.testing.set_capture_preprocess(False)
    return rec, np.frombuffer(starts, np.int64), np.frombuffer(keys, np.uint64)


def reference_lists(rec: np.ndarray, width: int, height: int, sort: bool) -> tuple[np.ndarray, np.ndarray]:
    """Each tile's list as sequential binning in splat order, then a per-tile sort of the keys, would give it."""
    gx, gy = -(-width // TILE), -(-height // TILE)
    ids = np.flatnonzero(rec["valid"])
    r = rec["rect"][ids].astype(np.int64)  # x0, y0, x1, y1
    w, h = r[:, 2] - r[:, 0], r[:, 3] - r[:, 1]
    area = w * h
    owner = np.repeat(np.arange(len(ids)), area)
    within = np.arange(area.sum()) - np.repeat(np.cumsum(area) - area, area)
    tile = (r[owner, 1] + within // w[owner]) * gx + r[owner, 0] + within % w[owner]
    keys = (rec["splat"]["depth"][ids].astype(np.uint64) << np.uint64(32)) | ids.astype(np.uint64)
    keys = keys[owner]
    order = np.lexsort((keys, tile)) if sort else np.argsort(tile, kind="stable")
    starts = np.zeros(gx * gy + 1, np.int64)
    np.cumsum(np.bincount(tile, minlength=gx * gy), out=starts[1:])
    return starts, keys[order]


def check_lists(scene: gb.Scene, cam: gb.Camera, mode: str, supersample: int = 1, threads: int = 0) -> int:
    """The captured lists equal the reference; the number of list entries."""
    rec, starts, keys = captured(lambda: gb.render(scene, cam, mode, supersample, threads=threads))
    ref_starts, ref_keys = reference_lists(rec, cam.width * supersample, cam.height * supersample, mode != "wsr")
    np.testing.assert_array_equal(starts, ref_starts)
    np.testing.assert_array_equal(keys, ref_keys)
    return len(keys)


@pytest.mark.parametrize("name", SCENES)
def test_tile_lists_on_the_shared_scenes(name):
    scene = gb.load(shared_scene(name))
    cam = gb.orbit_camera(scene, 30, 20, width=320, height=240)
    assert check_lists(scene, cam, "scalar") > scene.num_splats // 10
    check_lists(scene, cam, "gaussian_blending", 2)
    check_lists(scene, cam, "analytic", threads=1)
    check_lists(scene, cam.at_sampling_rate(1 / 4), "mip", threads=3)
    check_lists(scene, cam, "wsr")


def tie_scene(z: np.ndarray, seed: int, xy: float = 0.6, scale: float = 0.02) -> gb.Scene:
    """Splats at depths z (exactly: the camera looks down +z from the origin) spread over the view."""
    rng = np.random.default_rng(seed)
    n = len(z)
    means = np.c_[rng.uniform(-xy, xy, n) * z, rng.uniform(-xy, xy, n) * z, z]
    return gb.Scene.from_arrays(
        means,
        np.full((n, 3), scale) * np.abs(z)[:, None],
        rng.normal(size=(n, 4)),
        rng.uniform(0.1, 0.9, n),
        rng.normal(0, 0.5, (n, 1, 3)),
    )


def tie_depths(kind: str, n: int, rng: np.random.Generator) -> np.ndarray:
    if kind == "all equal":
        return np.full(n, 3.0)
    if kind == "few values":  # runs of equal depth bits, ids interleaved
        return rng.choice([2.0, 2.5, np.nextafter(np.float32(2.5), np.float32(3.0)), 4.0], n)
    if kind == "one digit":  # depths that differ only in the lowest radix digit's bits
        return 2.0 + rng.integers(0, 2048, n) * np.finfo(np.float32).eps * 2.0
    return np.exp(rng.uniform(np.log(0.3), np.log(3e4), n))  # "many digits": every digit differs


@pytest.mark.parametrize("kind", ["all equal", "few values", "one digit", "many digits"])
def test_tile_lists_on_depth_ties(kind):
    rng = np.random.default_rng(len(kind))
    z = tie_depths(kind, 20_000, rng).astype(np.float32).astype(np.float64)
    scene = tie_scene(z, seed=len(kind))
    cam = front_camera(320, 240, 200.0)
    for threads in (1, 2, 5):
        check_lists(scene, cam, "scalar", threads=threads)
    rec, _, _ = captured(lambda: gb.render(scene, cam, "scalar"))
    depth = rec["splat"]["depth"][rec["valid"] == 1]
    assert len(depth) > 10_000 and (kind != "all equal" or len(np.unique(depth)) == 1)


@pytest.mark.parametrize("visible", [0, 1, 2, 3, 2**11, 2**15 + 1, 2**17])
def test_tile_lists_at_visible_counts(visible):
    """0, 1 and 2^k visible splats (the others behind the camera), with equal depths among them; the radix ranges
    and the cancel polls' blocks split at such counts."""
    n = max(visible, 1) + 500
    rng = np.random.default_rng(visible)
    z = rng.choice([1.5, 2.0, 7.0], n)
    z[visible:] = -2.0
    scene = tie_scene(z, seed=visible, xy=0.5, scale=0.01)
    cam = front_camera(160, 120, 100.0)
    for threads in (1, 2):
        check_lists(scene, cam, "scalar", threads=threads)
    assert gb.render(scene, cam, "scalar").stats.visible == visible


def test_one_huge_splat_over_every_tile():
    rng = np.random.default_rng(5)
    z = rng.uniform(2.0, 4.0, 3000)
    z[1500] = 3.0  # the huge one, amid the others' depths
    scene = tie_scene(z, seed=5)
    means, scales = scene.means.copy(), scene.scales.copy()
    means[1500], scales[1500] = (0.0, 0.0, 3.0), (1.5, 1.5, 1.5)
    scene = gb.Scene.from_arrays(means, scales, scene.quats, scene.opacities, scene.sh)
    cam = front_camera(320, 240, 200.0)
    rec, starts, keys = captured(lambda: gb.render(scene, cam, "scalar", 2))
    assert (np.diff(starts) > 0).all() and ((keys & np.uint64(0xFFFFFFFF)) == 1500).sum() == len(starts) - 1
    check_lists(scene, cam, "scalar", 2)


CANCEL_SETTINGS = RenderSettings(Mode.SCALAR, supersample=4)


@pytest.fixture(scope="module")
def big_frame():
    """A shared scene at 800x600 supersample 4 (3200x2400 samples), its frame and stage times; a small check view."""
    scene = gb.load(shared_scene("plant.splat"))
    r = CpuRenderer()
    r.upload(scene)
    cam = gb.orbit_camera(scene, 30, 20, width=800, height=600)
    frame = r.render(cam, CANCEL_SETTINGS)
    small = gb.orbit_camera(scene, 100, 10, width=96, height=72)
    yield r, cam, frame, small, r.render(small, RenderSettings(Mode.SCALAR))
    r.release()


def test_cancel_at_random_moments_ends_cancelled_or_exact(big_frame):
    """A CancelToken set from another thread in the middle of each stage (preprocess, depth order and binning,
    blend) and at random moments, half of those cleared again 1 ms later (a caller reusing its token: a frame
    that saw the flag must still raise, not return its incomplete image): every render raises RenderCancelled or
    returns the uncancelled frame, and the next render is exact."""
    r, cam, frame, small, small_frame = big_frame
    s = frame.stats
    moments = [
        s.preprocess_ms / 2,
        s.preprocess_ms + s.sort_ms / 4,
        s.preprocess_ms + s.sort_ms * 3 / 4,
        s.preprocess_ms + s.sort_ms + s.blend_ms / 2,
    ]
    rng = np.random.default_rng(23)
    moments += list(rng.uniform(0, s.total_ms * 1.1, 6))
    outcomes = []
    for k, at in enumerate(moments):
        token = gb.CancelToken()

        def fire(t: gb.CancelToken = token, clear: bool = k >= 4 and k % 2 == 0) -> None:
            t.set()
            if clear:
                threading.Event().wait(1e-3)
                t.clear()

        timer = threading.Timer(at / 1e3, fire)
        timer.start()
        try:
            out = r.render(cam, CANCEL_SETTINGS, cancel=token)
            np.testing.assert_array_equal(out.rgb, frame.rgb)
            np.testing.assert_array_equal(out.alpha, frame.alpha)
            outcomes.append("complete")
        except gb.RenderCancelled:
            outcomes.append("cancelled")
        timer.join()
        after = r.render(small, RenderSettings(Mode.SCALAR))
        np.testing.assert_array_equal(after.rgb, small_frame.rgb)
    assert outcomes[:3] == ["cancelled"] * 3, outcomes  # during preprocess and during the sort and binning
    np.testing.assert_array_equal(r.render(cam, CANCEL_SETTINGS).rgb, frame.rgb)


@pytest.mark.parametrize("mode", ["scalar", "mip", "analytic", "gaussian_blending", "wsr", "duplex"])
def test_every_pixel_is_written_without_a_zero_fill(mode):
    """The image planes are not zero-filled before the blend (image.h, Uninit): with each new image poisoned (NaN,
    evaluation counts -1), every mode and supersampling writes every pixel, bit-identically to an unpoisoned frame;
    views with empty tiles (x1/8 of a small scene, a view past the scene) included."""
    scene = gb.load(shared_scene("plant.splat"))
    cam = gb.orbit_camera(scene, 30, 20, width=120, height=90)
    away = gb.Camera(64, 48, 50.0, 50.0, 32.0, 24.0, np.eye(3), np.array([0.0, 0.0, -1e4]))
    views = [(cam, 1), (cam, 3), (cam.at_sampling_rate(1 / 8), 2), (away, 1), (away, 2)]
    window = "window" if mode == "gaussian_blending" else "none"
    plain = [gb.render(scene, c, mode, ss, debug=window) for c, ss in views]
    _native.testing.set_poison_images(True)
    try:
        poisoned = [gb.render(scene, c, mode, ss, debug=window) for c, ss in views]
    finally:
        _native.testing.set_poison_images(False)
    for a, b in zip(plain, poisoned):
        assert np.isfinite(b.rgb).all() and np.isfinite(b.alpha).all() and (b.debug["evals"] >= 0).all()
        np.testing.assert_array_equal(a.rgb, b.rgb)
        np.testing.assert_array_equal(a.alpha, b.alpha)
        np.testing.assert_array_equal(a.debug["evals"], b.debug["evals"])
        if window == "window":
            np.testing.assert_array_equal(a.debug["window"], b.debug["window"])
