"""Every writer round-trips through our reader: bit for bit where the format is lossless (.ply, .glb), within the
precision each encoder's module states where it quantises (.spz, .spz.glb, .splat, .compressed.ply, .sog);
renders of the shared scenes are equal after .glb; convert keeps the training mode where the target can say it,
says what the target drops, refuses to overwrite without --force and to write onto its input."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from encoders import random_params
from helpers import skip_or_fail
from test_convert import assert_same, raw_inria_ply

import gbviewer as gb
from gbviewer.cli import main
from gbviewer.io.write_packed import fractional_bits
from gbviewer.io.write_playcanvas import codebook, order
from gbviewer.model.scene import SH_C0

SCENES = Path(__file__).resolve().parents[2].parent / "shared" / "scenes"


def scene_of(n: int = 600, degree: int = 3, seed: int = 0, **meta) -> gb.Scene:
    """Random splats inside every quantised format's ranges (SH bands within SPZ's [-1, 1))."""
    s = random_params(n, sh_degree=degree, seed=seed)
    s["sh"][:, 1:] *= 1.5
    return gb.Scene.from_arrays(s["means"], s["scales"], s["quats"], s["opacities"], s["sh"], meta=meta)


def rebuilt(step: float) -> float:
    """Bound of a smallest-three quaternion's components given `step`, the others' error: the rebuilt largest one
    (at least 1/2) moves by at most sum |c_i| step / w <= 3 (1/sqrt2) step / (1/2)."""
    return 3 * math.sqrt(2) * step + 1e-6


def rotation_gap(a: np.ndarray, b: np.ndarray) -> float:
    """Largest per-component difference of unit quaternions, q and -q being the same rotation."""
    sign = np.where((a * b).sum(axis=1) < 0, -1.0, 1.0)[:, None]
    return float(np.abs(a - sign * b).max())


def test_ply_glb_ply_is_bit_exact(tmp_path):
    src = gb.load(raw_inria_ply(tmp_path / "in.ply", degree=3))
    src = gb.Scene.from_arrays(src.means, src.scales, src.quats, src.opacities, src.sh)  # .glb has no filter_3D
    glb = gb.save(src, tmp_path / "a.glb")
    back = gb.load(glb)
    assert_same(src, back)
    direct, via = gb.save(src, tmp_path / "direct.ply"), gb.save(back, tmp_path / "via.ply")
    assert direct.read_bytes() == via.read_bytes()


@pytest.mark.parametrize(
    "name", ["fruit_drops_minimal.ply", "biker.spz", "plant.splat", "guitar.compressed.ply", "st-peter.sog"]
)
def test_shared_scene_renders_equal_after_glb(tmp_path, name):
    if not (SCENES / name).exists():
        skip_or_fail(f"{SCENES / name} absent (shared/ is not beside the repo)")
    src = gb.load(SCENES / name)
    back = gb.load(gb.save(src, tmp_path / "s.glb"))
    assert_same(src, back)
    cam = gb.orbit_camera(src, width=96, height=64)
    before, after = (gb.render(s, cam, "gaussian_blending", backend="cpu").rgb for s in (src, back))
    np.testing.assert_array_equal(before, after)


def test_spz_within_its_precision(tmp_path):
    src = scene_of()
    for path in (tmp_path / "a.spz", tmp_path / "a.spz.glb"):
        back = gb.load(gb.save(src, path))
        assert back.sh_degree == 3 and back.meta["format"] == ("spz" if path.suffix == ".spz" else "glb")
        bits = fractional_bits(src.means)
        assert np.abs(back.means - src.means).max() <= 2.0 ** -(bits + 1) + 1e-6
        assert np.abs(np.log(back.scales) - np.log(src.scales)).max() <= 1 / 32 + 1e-5
        assert np.abs(back.opacities - src.opacities).max() <= 0.5 / 255 + 1e-6
        assert np.abs(back.sh[:, 0] - src.sh[:, 0]).max() <= 0.5 / (0.15 * 255) + 1e-6
        assert np.abs(back.sh[:, 1:] - src.sh[:, 1:]).max() <= 1 / 256 + 1e-6
        assert rotation_gap(back.quats, src.quats) <= rebuilt(math.sqrt(0.5) / 511 / 2)


def test_spz_positions_beyond_2048_keep_fitting(tmp_path):
    src = scene_of(50, 0)
    far = gb.Scene.from_arrays(src.means * 3000, src.scales, src.quats, src.opacities, src.sh)
    bits = fractional_bits(far.means)
    assert bits < 12
    back = gb.load(gb.save(far, tmp_path / "far.spz"))
    assert np.abs(back.means - far.means).max() <= 2.0 ** -(bits + 1) * 1.001


def test_splat_within_its_precision(tmp_path):
    src = scene_of(degree=0)
    back = gb.load(gb.save(src, tmp_path / "a.splat"))
    np.testing.assert_array_equal(back.means, src.means)
    np.testing.assert_allclose(back.scales, src.scales, rtol=1e-6)  # float32 as stored
    colour = np.clip(0.5 + SH_C0 * src.sh[:, 0], 0, 1)
    assert np.abs((0.5 + SH_C0 * back.sh[:, 0]) - colour).max() <= 0.5 / 255 + 1e-6
    assert np.abs(back.opacities - src.opacities).max() <= 0.5 / 255 + 1e-6
    assert rotation_gap(back.quats, src.quats) <= 4 / 256  # 1/256 per component, then normalised


def chunk_span(values: np.ndarray, perm: np.ndarray) -> np.ndarray:
    """Each splat's chunk range (max - min per axis) in the written order."""
    v = values[perm]
    n = len(v)
    pad = np.concatenate([v, np.repeat(v[-1:], -n % 256, axis=0)]).reshape(-1, 256, v.shape[1])
    return np.repeat(pad.max(axis=1) - pad.min(axis=1), 256, axis=0)[:n]


def test_compressed_ply_within_its_precision(tmp_path):
    src = scene_of(2000)
    back = gb.load(gb.save(src, tmp_path / "a.compressed.ply"))
    assert back.meta["format"] == "compressed-ply" and back.sh_degree == 3
    perm = order(src)
    steps = np.array([2047, 1023, 2047])
    assert (np.abs(back.means - src.means[perm]) <= chunk_span(src.means, perm) / steps / 2 + 1e-5).all()
    logs = np.log(src.scales.astype(np.float64))
    assert (np.abs(np.log(back.scales) - logs[perm]) <= chunk_span(logs, perm) / steps / 2 + 1e-5).all()
    rgb = 0.5 + SH_C0 * src.sh[:, 0].astype(np.float64)
    assert (np.abs(0.5 + SH_C0 * back.sh[:, 0] - rgb[perm]) <= chunk_span(rgb, perm) / 255 / 2 + 1e-5).all()
    assert np.abs(back.opacities - src.opacities[perm]).max() <= 0.5 / 255 + 1e-6
    assert np.abs(back.sh[:, 1:] - src.sh[perm, 1:]).max() <= 1 / 64 + 1e-6
    assert rotation_gap(back.quats, src.quats[perm]) <= rebuilt(math.sqrt(2) / 2046)


def half_gap(values: np.ndarray) -> float:
    book, _ = codebook(values)
    return float(np.diff(book.astype(np.float64)).max() / 2)


@pytest.mark.parametrize("n", [3000, 66000])
def test_sog_within_its_precision(tmp_path, n):
    src = scene_of(n, degree=1 if n > 65536 else 3)
    back = gb.load(gb.save(src, tmp_path / "a.sog"))
    perm = order(src)
    t = np.sign(src.means) * np.log1p(np.abs(src.means.astype(np.float64)))
    bound_t = (t.max(axis=0) - t.min(axis=0)) / 65535 / 2
    t_back = np.sign(back.means) * np.log1p(np.abs(back.means.astype(np.float64)))
    assert (np.abs(t_back - t[perm]) <= bound_t + 1e-6).all()
    logs = np.log(src.scales.astype(np.float64))
    assert np.abs(np.log(back.scales) - logs[perm]).max() <= half_gap(logs) + 1e-5
    assert np.abs(back.sh[:, 0] - src.sh[perm, 0]).max() <= half_gap(src.sh[:, 0]) + 1e-5
    assert np.abs(back.opacities - src.opacities[perm]).max() <= 0.5 / 255 + 1e-6
    assert rotation_gap(back.quats, src.quats[perm]) <= rebuilt((2 / 255) / math.sqrt(2) / 2)
    rest_error = np.abs(back.sh[:, 1:] - src.sh[perm, 1:])
    if n <= 65536:  # each splat its own palette entry: only the 256-entry codebook rounds
        assert rest_error.max() <= half_gap(src.sh[:, 1:]) + 1e-5
    else:  # a k-means palette: closer than the mean coefficient spread
        assert rest_error.mean() < np.abs(src.sh[:, 1:] - src.sh[:, 1:].mean(axis=0)).mean()


@pytest.mark.parametrize(
    "out,fmt,keeps",
    [
        ("a.glb", "glb", True),
        ("a.spz.glb", "glb-spz", True),
        ("a.spz", "spz", True),
        ("a.compressed.ply", "compressed-ply", True),
        ("a.sog", "sog", True),
        ("a.splat", "splat", False),
        ("a.ply", "ply", True),
    ],
)
def test_convert_keeps_training_mode_and_says_what_is_dropped(tmp_path, capsys, out, fmt, keeps):
    src = tmp_path / "in.ply"
    s = scene_of(300, seed=3)
    gb.save(gb.Scene.from_arrays(s.means, s.scales, s.quats, s.opacities, s.sh, filter_3d=np.full(300, 0.01)), src)
    assert main(["convert", str(src), str(tmp_path / out)]) == 0
    text = capsys.readouterr().out
    assert f": {fmt}, 300 splats" in text
    lost = [line for line in text.splitlines() if " drops " in line]
    if fmt == "ply":
        assert not lost
    else:
        assert len(lost) == 1 and "3D filter" in lost[0]
        assert ("SH bands 1-3" in lost[0]) == (fmt == "splat")
        assert ("training mode" in lost[0]) == (not keeps)
    back = gb.load(tmp_path / out)
    want = "mip-splatting (3D filter)" if fmt == "ply" else "antialiased"
    assert back.meta["trained_as"] == (want if keeps else "unknown")


def test_convert_refuses_overwrite_and_input(tmp_path, capsys):
    src = tmp_path / "in.glb"
    gb.save(scene_of(100, 0), src)
    first = src.read_bytes()
    for out in ("o.spz", "o.sog", "o.compressed.ply"):
        assert main(["convert", str(src), str(tmp_path / out)]) == 0
        before = (tmp_path / out).read_bytes()
        assert main(["convert", str(src), str(tmp_path / out)]) == 2
        assert "--force" in capsys.readouterr().err and (tmp_path / out).read_bytes() == before
        assert main(["convert", str(src), str(tmp_path / out), "--force"]) == 0
    assert main(["convert", str(src), str(src), "--force"]) == 2
    assert "is the input" in capsys.readouterr().err and src.read_bytes() == first
    assert main(["convert", str(src), str(tmp_path / "o.xyz")]) == 2
    assert "cannot tell the format" in capsys.readouterr().err
    assert main(["convert", str(src), str(tmp_path / "o.xyz"), "--format", "glb-spz"]) == 0
    assert gb.load(tmp_path / "o.xyz").meta["compression"] == "spz_2"
    assert not list(tmp_path.glob(".o*"))  # no temporary left behind
