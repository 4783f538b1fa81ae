"""Each decoder against files these tests encode themselves (encoders.py) from known values.

Tolerances are half a quantisation step of each field, from the format's bit widths.
"""

from __future__ import annotations

import gzip
import math
import struct

import numpy as np
import pytest
from encoders import SH_C0, encode_compressed_ply, encode_splat, encode_spz, random_params, sog_files, write_sog

import gbviewer as gb


def check(
    scene: gb.Scene, s: dict, pos: float, log_scale: float, opacity: float, dc: float, rest: float, quat: float | None
) -> None:
    """Loaded scene vs the encoded values, each within its tolerance (quat: max component error)."""
    assert scene.num_splats == len(s["means"])
    np.testing.assert_allclose(scene.means, s["means"], rtol=0, atol=pos)
    np.testing.assert_allclose(np.log(scene.scales), np.log(s["scales"]), rtol=0, atol=log_scale)
    np.testing.assert_allclose(scene.opacities, s["opacities"], rtol=0, atol=opacity)
    np.testing.assert_allclose(scene.sh[:, 0], s["sh"][:, 0], rtol=0, atol=dc)
    if s["sh"].shape[1] > 1:
        np.testing.assert_allclose(scene.sh[:, 1:], s["sh"][:, 1:], rtol=0, atol=rest)
    sign = np.sign(np.einsum("ij,ij->i", scene.quats, s["quats"]))[:, None]
    if quat is not None:
        np.testing.assert_allclose(scene.quats, sign * s["quats"], rtol=0, atol=quat)


HALF_BYTE = 0.5 / 255 + 1e-6


def test_splat(tmp_path):
    s = random_params(500, seed=1)
    path = tmp_path / "scene.bin"  # no telling extension: detected by content
    path.write_bytes(encode_splat(s))
    scene = gb.load(path)
    assert scene.meta["format"] == "splat"
    # float32 positions and scales; colour, alpha bytes; quaternion bytes q*128+128 (then renormalised)
    check(scene, s, 1e-6, 1e-6, HALF_BYTE, 0.5 / 255 / SH_C0 + 1e-6, 0, 2 * 0.5 / 128 + 1e-6)


@pytest.mark.parametrize("version", [1, 2, 3, 4])
@pytest.mark.parametrize("degree", [0, 1, 2, 3])
def test_spz(tmp_path, version, degree):
    s = random_params(700, sh_degree=degree, seed=version * 10 + degree)
    path = tmp_path / "scene.dat"
    path.write_bytes(encode_spz(s, version, antialiased=True))
    scene = gb.load(path)
    assert (scene.meta["format"], scene.meta["version"], scene.sh_degree) == ("spz", version, degree)
    assert scene.meta["antialiased"]
    # v1 float16 positions (|x| <= 3: half ulp 2^-10); else 12 fractional bits; log scale 1/16 steps;
    # colour 1/(0.15*255) steps; SH (v-128)/128; v2 quaternion xyz bytes /127.5 (w rebuilt), v3+ 9-bit
    # smallest three of magnitude <= 1/sqrt2, largest rebuilt.
    pos = 2.0**-10 if version == 1 else 2.0**-13
    quat = None if version <= 2 else 3 * math.sqrt(0.5) * (math.sqrt(0.5) / 511 / 2) / 0.5 + 1e-6
    check(scene, s, pos + 1e-6, 1 / 32 + 1e-6, HALF_BYTE, 0.5 / (0.15 * 255) + 1e-6, 0.5 / 128 + 1e-6, quat)
    if version <= 2:  # xyz bytes: half step 0.5/127.5 each; w = sqrt(1 - |xyz|^2) errs by |xyz| * d / w
        q = s["quats"] * np.sign(s["quats"][:, :1])
        ok = q[:, 0] > 0.3
        d = math.sqrt(3) * 0.5 / 127.5
        np.testing.assert_allclose(scene.quats[ok], q[ok], rtol=0, atol=d / 0.3 + 1e-3)


def test_spz_containers_and_extensions(tmp_path):
    s = random_params(300, sh_degree=1, seed=5)
    ext = struct.pack("<II", 0xADBE0002, 12) + struct.pack("<3f", 0.1, 0.2, 0.3)
    ref = None
    for name, data in {
        "raw_v3": encode_spz(s, 3, gzipped=False),
        "ext_v3": encode_spz(s, 3, extensions=ext),
        "ext_v4": encode_spz(s, 4, extensions=ext),
        "frac8": encode_spz(s, 4, frac_bits=8),
    }.items():
        (tmp_path / name).write_bytes(data)
        scene = gb.load(tmp_path / name)
        if ref is None:
            ref = scene
        tol = 2.0**-9 if name == "frac8" else 0
        np.testing.assert_allclose(scene.means, ref.means, atol=tol, err_msg=name)
        np.testing.assert_array_equal(scene.sh, ref.sh, err_msg=name)


def test_spz_coordinate_convention(tmp_path):
    """A hand-built v2 file in spz's right-up-back frame: y and z flip into the INRIA right-down-front frame."""
    n = 1
    header = struct.pack("<4sIIBBBB", b"NGSP", 2, n, 1, 12, 0, 0)
    pos = b"".join((v * 4096 & 0xFFFFFF).to_bytes(3, "little") for v in (1, 2, 3))  # (1, 2, 3) in RUB
    rot = bytes([round(0.6 * 127.5 + 127.5), 128, 128])  # x = 0.6 (about 0.6), y = z = ~0, w = 0.8
    sh = bytes([128 + 64, 128, 128, 128 + 64, 128, 128, 128 + 64, 128, 128])  # 0.5 in each deg-1 coeff, R only
    body = pos + bytes([255]) + bytes([128, 128, 128]) + bytes([160, 160, 160]) + rot + sh
    (tmp_path / "hand.spz").write_bytes(gzip.compress(header + body))
    scene = gb.load(tmp_path / "hand.spz")
    np.testing.assert_allclose(scene.means[0], [1, -2, -3], atol=1e-6)
    # the RUB -> RDF change is a 180 degree turn about x: x-axis rotations keep their quaternion
    w, x = scene.quats[0, 0], scene.quats[0, 1]
    assert x > 0.59 and w > 0.79 and np.abs(scene.quats[0, 2:]).max() < 0.01
    # degree-1 basis (y, z, x): y and z coefficients flip sign, x keeps it
    np.testing.assert_allclose(scene.sh[0, 1:, 0], [-0.5, -0.5, 0.5])


def test_spz_degree_4_is_truncated(tmp_path):
    s = random_params(50, sh_degree=3, seed=2)
    s4 = dict(s, sh=np.concatenate([s["sh"], np.zeros((50, 9, 3))], axis=1))
    (tmp_path / "d4.spz").write_bytes(encode_spz(s4, 4))
    with pytest.warns(UserWarning, match="degree 4"):
        scene = gb.load(tmp_path / "d4.spz")
    assert scene.sh_degree == 3 and scene.meta["sh_degree_stored"] == 4


@pytest.mark.parametrize("color_ranges", [True, False])
@pytest.mark.parametrize("degree", [0, 1, 3])
def test_compressed_ply(tmp_path, color_ranges, degree):
    s = random_params(1000, sh_degree=degree, seed=degree)
    path = tmp_path / "c.ply"
    path.write_bytes(encode_compressed_ply(s, color_ranges))
    scene = gb.load(path)
    assert scene.meta["version"] == f"{18 if color_ranges else 12}-property chunks"
    assert scene.sh_degree == degree
    # per chunk of 256: positions / log scales 11-10-11 bits of the chunk range (at most 6 and 7 here),
    # colour 8 bits of the chunk range (or of 0..1), SH bytes of 8/256, quaternion 10 bits over +-1/sqrt2.
    span_p, span_s = 6.0, 7.0
    dc = (1.0 if not color_ranges else np.ptp(0.5 + SH_C0 * s["sh"][:, 0])) / (2 * 255) / SH_C0
    quat = 3 * math.sqrt(0.5) * (math.sqrt(2) / 1023 / 2) / 0.5
    check(
        scene,
        s,
        span_p / (2 * 1023) + 1e-5,
        span_s / (2 * 1023) + 1e-5,
        HALF_BYTE,
        dc + 1e-5,
        4 / 256 + 1e-6,
        quat + 1e-6,
    )


@pytest.mark.parametrize("form", ["bundled", "folder", "meta.json"])
def test_sog(tmp_path, form):
    n, degree, palette_size = 900, 2, 40
    s = random_params(n, sh_degree=degree, seed=7)
    rng = np.random.default_rng(8)
    palette = rng.uniform(-0.5, 0.5, (palette_size, (degree + 1) ** 2 - 1, 3))
    labels = rng.integers(0, palette_size, n)
    s["sh"][:, 1:] = palette[labels]
    files = sog_files(s, palette, labels)
    target = write_sog(files, tmp_path / ("s.sog" if form == "bundled" else "s"), bundled=form == "bundled")
    scene = gb.load(target / "meta.json" if form == "meta.json" else target)
    assert (scene.meta["format"], scene.meta["version"], scene.meta["bundled"]) == ("sog", 2, form == "bundled")
    assert scene.sh_degree == degree
    # means: 16 bits of the log-transformed range (|x| <= 3, d|x|/dt <= 4); codebooks: 256 linear steps of
    # each field's range; quaternion bytes over [-1/sqrt2, 1/sqrt2] -> sqrt2/255/2 per component.
    t_span = 2 * math.log1p(3)
    half = lambda a: np.ptp(a) / 255 / 2 + 1e-5  # noqa: E731
    quat = 3 * math.sqrt(0.5) * (math.sqrt(2) / 255 / 2) / 0.5
    check(
        scene,
        s,
        4 * t_span / 65535 / 2 + 1e-5,
        half(np.log(s["scales"])),
        HALF_BYTE,
        half(s["sh"][:, 0]),
        half(palette),
        quat + 1e-6,
    )
