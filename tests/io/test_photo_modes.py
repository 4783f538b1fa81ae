"""Every photo mode Pillow decodes from a PNG or JPEG is read with its real values (divided by its mode's largest)
or refused in one line, and a photo's size is checked against its camera from the header, before decoding: the
camera's size or an integer downscale of it (images_2, images_4, ...)."""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import numpy as np
import pytest
from dataset_builders import H, W, save_rgb, shots, write_cameras_json, write_colmap
from PIL import Image

from gbviewer.core.errors import DatasetError
from gbviewer.io.datasets import load_dataset, photos, read_photo

RNG = np.random.default_rng(7)
GREY16 = RNG.integers(0, 65536, (5, 6), dtype=np.uint16)
RGB16 = RNG.integers(0, 65536, (5, 6, 3), dtype=np.uint16)
RGBA16 = RNG.integers(0, 65536, (5, 6, 4), dtype=np.uint16)


def png(path: Path, rows: np.ndarray, depth: int, colour_type: int, extra: bytes = b"") -> Path:
    """A PNG written chunk by chunk (Pillow writes no 16-bit colour): `rows` big-endian samples, filter 0."""

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    h, w = rows.shape[:2]
    if depth < 8:  # each sample's bits, most significant first, packed along the row
        data = np.packbits(((rows[..., None] >> np.arange(depth)[::-1]) & 1).reshape(h, -1), axis=1).tobytes()
    else:
        data = rows.astype(">u2" if depth == 16 else np.uint8).tobytes()
    stride = len(data) // h
    raw = b"".join(b"\0" + data[i * stride : (i + 1) * stride] for i in range(h))
    ihdr = struct.pack(">IIBBBBB", w, h, depth, colour_type, 0, 0, 0)
    path.write_bytes(
        b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + extra + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b"")
    )
    return path


def pillow(path: Path, array: np.ndarray, mode: str | None = None, **save) -> Path:
    Image.fromarray(array, mode).save(path, **save) if mode else Image.fromarray(array).save(path, **save)
    return path


def grey(values: np.ndarray) -> np.ndarray:
    return np.repeat(values[..., None], 3, axis=-1).astype(np.float32)


def test_16_bit_grey_reads_its_values(tmp_path):
    got = read_photo(pillow(tmp_path / "g.png", GREY16))
    np.testing.assert_allclose(got, grey(GREY16 / 65535), atol=1e-7)
    assert read_photo(png(tmp_path / "k.png", np.full((2, 3), 1000), 16, 0))[0, 0, 0] == pytest.approx(1000 / 65535)


def test_8_bit_and_fewer_bits(tmp_path):
    bits = RNG.integers(0, 2, (5, 6)).astype(bool)
    np.testing.assert_array_equal(read_photo(pillow(tmp_path / "b.png", bits)), grey(bits))
    for depth in (2, 4):
        levels = RNG.integers(0, 1 << depth, (3, 7))
        got = read_photo(png(tmp_path / f"g{depth}.png", levels, depth, 0))
        np.testing.assert_allclose(got, grey(levels / ((1 << depth) - 1)), atol=1e-7)
    l8 = RNG.integers(0, 256, (5, 6), dtype=np.uint8)
    np.testing.assert_allclose(read_photo(pillow(tmp_path / "l.png", l8)), grey(l8 / 255), atol=1e-7)
    la = RNG.integers(0, 256, (5, 6, 2), dtype=np.uint8)
    got = read_photo(pillow(tmp_path / "la.png", la, "LA"))
    np.testing.assert_allclose(got, np.dstack([grey(la[..., 0] / 255), la[..., 1:] / 255]), atol=1e-7)
    rgb = RNG.integers(0, 256, (5, 6, 3), dtype=np.uint8)
    np.testing.assert_allclose(read_photo(pillow(tmp_path / "rgb.png", rgb)), rgb / 255, atol=1e-7)
    rgba = RNG.integers(0, 256, (5, 6, 4), dtype=np.uint8)
    np.testing.assert_allclose(read_photo(pillow(tmp_path / "rgba.png", rgba)), rgba / 255, atol=1e-7)


def test_palette_and_transparent_colours(tmp_path):
    rgb = RNG.integers(0, 256, (5, 6, 3), dtype=np.uint8)
    pal = Image.fromarray(rgb).quantize(16)
    pal.save(tmp_path / "p.png")
    np.testing.assert_allclose(read_photo(tmp_path / "p.png"), np.asarray(pal.convert("RGB")) / 255, atol=1e-7)
    pal.save(tmp_path / "pt.png", transparency=0)
    got = read_photo(tmp_path / "pt.png")
    np.testing.assert_array_equal(got[..., 3] == 0, np.asarray(pal) == 0)
    l8 = RNG.integers(0, 256, (5, 6), dtype=np.uint8)
    got = read_photo(pillow(tmp_path / "lt.png", l8, transparency=int(l8[0, 0])))
    np.testing.assert_array_equal(got[..., 3], (l8 != l8[0, 0]).astype(np.float32))
    np.testing.assert_allclose(got[..., :3], grey(l8 / 255), atol=1e-7)


def test_16_bit_colour_within_an_8_bit_step(tmp_path):
    """Pillow holds 16-bit colour at 8 bits: each value within 1/255 of its own, never clipped to white."""
    got = read_photo(png(tmp_path / "rgb16.png", RGB16, 16, 2))
    np.testing.assert_allclose(got, RGB16 / 65535, atol=1 / 255)
    got = read_photo(png(tmp_path / "rgba16.png", RGBA16, 16, 6))
    np.testing.assert_allclose(got, RGBA16 / 65535, atol=1 / 255)


def test_jpeg_grey_and_colour(tmp_path):
    flat = np.full((16, 16), 100, np.uint8)
    np.testing.assert_allclose(
        read_photo(pillow(tmp_path / "g.jpg", flat, quality=100)), grey(flat / 255), atol=2 / 255
    )
    np.testing.assert_allclose(
        read_photo(pillow(tmp_path / "c.jpg", np.dstack([flat] * 3), quality=100)), grey(flat / 255), atol=2 / 255
    )


@pytest.mark.parametrize(
    "make, says",
    [
        (lambda p: Image.new("CMYK", (8, 8), (0, 255, 0, 0)).save(p, "JPEG"), "a CMYK photo"),
        (lambda p: Image.fromarray(np.ones((4, 4), np.float32)).save(p, "TIFF"), "not a PNG or JPEG"),
        (lambda p: Image.new("I", (4, 4), 70000).save(p, "TIFF"), "not a PNG or JPEG"),
    ],
)
def test_other_modes_are_refused_in_one_line(tmp_path, make, says):
    path = tmp_path / "x.img"
    make(path)
    with pytest.raises(DatasetError) as exc:
        read_photo(path)
    assert says in str(exc.value) and str(path) in str(exc.value) and "\n" not in str(exc.value)


@pytest.fixture(scope="module")
def views(bundled_scene):
    return shots(bundled_scene, n=3)


def header_only(path: Path, w: int, h: int) -> None:
    """A PNG header claiming w x h pixels, with undecodable data enough for the bytes-per-pixel bound: decoding it
    would fail, so a size error proves nothing was decoded."""
    png(path, np.zeros((1, 1), np.uint8), 8, 2)
    data = path.read_bytes()
    ihdr = b"IHDR" + struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0)
    idat = b"IDAT" + b"\x01" * (w * h // photos.PIXELS_PER_BYTE + 1)
    path.write_bytes(
        data[:8]
        + struct.pack(">I", 13)
        + ihdr
        + struct.pack(">I", zlib.crc32(ihdr))
        + struct.pack(">I", len(idat) - 4)
        + idat
        + struct.pack(">I", zlib.crc32(idat))
    )


def test_a_photo_larger_than_its_colmap_camera_is_refused_from_its_header(tmp_path, views, monkeypatch):
    write_colmap(tmp_path, views)
    monkeypatch.setattr(Image.Image, "load", lambda self: pytest.fail("decoded a photo"))
    for w, h in ((W * 100, H * 100), (12000, 12000), (W + 2, H)):
        header_only(tmp_path / "images" / "v01.png", w, h)
        with pytest.raises(DatasetError) as exc:
            load_dataset(tmp_path)
        text = str(exc.value)
        assert "\n" not in text and f"v01.png: photo is {w}x{h} but its camera 'v01.png' is {W}x{H}" in text, text
        assert "integer downscale of it" in text


def test_integer_downscales_are_the_photos_that_fit(tmp_path, views):
    """images_4 of a 130x100 capture: 32 or 33 by 25 (each side rounded either way); 31 is not a quarter."""
    write_colmap(tmp_path, views)
    for s in views:
        save_rgb(tmp_path / "images_4" / f"{s.name}.png", s.rgb[:25, :33])
    got = load_dataset(tmp_path, images="images_4")
    assert [(v.camera.width, v.camera.height) for v in got.views] == [(33, 25)] * len(views)
    save_rgb(tmp_path / "images_4" / "v01.png", views[1].rgb[:25, :31])
    with pytest.raises(DatasetError, match="photo is 31x25 but its camera 'v01.png' is 130x100"):
        load_dataset(tmp_path, images="images_4")


def test_a_cameras_json_may_be_an_integer_fraction_of_its_photos(tmp_path, views):
    """A cameras.json may hold a training size below its photos' (an integer upscale fits); 12000x12000 does not."""
    write_cameras_json(tmp_path, views)
    header_only(tmp_path / "images" / "v01.png", 12000, 12000)
    with pytest.raises(
        DatasetError,
        match="12000x12000 but its camera 'v01' is 130x100; expected that size or an integer down- or upscale",
    ):
        load_dataset(tmp_path / "cameras.json")
