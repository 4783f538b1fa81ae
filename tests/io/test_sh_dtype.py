"""`gb.load(path, sh_dtype="float16")`: SH stored as float16, the rest as before, on every format; within float16's
rounding of the float32 load; out-of-range coefficients refused; rendered exactly as the float32 scene whose SH is
rounded to float16 (the renderers convert at upload)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import gbviewer as gb
from gbviewer.io.write import ply_header
from gbviewer.model.camera import orbit_camera
from gbviewer.render import Mode, RenderSettings, get_renderer

SEEDS = Path(__file__).parent / "fuzz" / "seeds"
FILES = sorted(p for kind in ("inria", "compressed", "spz", "splat", "sog") for p in (SEEDS / kind).iterdir())
FIELDS = ("means", "scales", "quats", "opacities", "filter_3d")


@pytest.mark.parametrize("path", FILES, ids=lambda p: f"{p.parent.name}/{p.name}")
def test_float16_is_the_float32_load_rounded(path):
    full, half = gb.load(path), gb.load(path, sh_dtype="float16")
    assert half.sh.dtype == np.float16 and half.sh.flags.c_contiguous and full.sh.dtype == np.float32
    np.testing.assert_array_equal(half.sh, full.sh.astype(np.float16), strict=True)
    for name in FIELDS:
        a, b = getattr(full, name), getattr(half, name)
        assert (a is None) == (b is None) and (a is None or np.array_equal(a, b)), name
    # the stated error: half a float16 step (2^-11 relative), or 2^-25 absolute below the normal range
    err = np.abs(half.sh.astype(np.float32) - full.sh)
    assert (err <= np.maximum(np.abs(full.sh) * 2.0**-11, 2.0**-25)).all()


def _raw_ply(path: Path, dc: float) -> Path:
    names = [
        "x",
        "y",
        "z",
        "f_dc_0",
        "f_dc_1",
        "f_dc_2",
        "opacity",
        "scale_0",
        "scale_1",
        "scale_2",
        "rot_0",
        "rot_1",
        "rot_2",
        "rot_3",
    ]
    body = np.zeros((4, len(names)), "<f4")
    body[:, 3], body[:, 10] = dc, 1.0
    path.write_bytes(ply_header(4, names) + body.tobytes())
    return path


def test_coefficients_beyond_float16_are_refused(tmp_path):
    path = _raw_ply(tmp_path / "big.ply", 1e5)
    assert gb.load(path).sh.max() == np.float32(1e5)  # float32 keeps them
    with pytest.raises(gb.SceneFormatError, match="beyond float16's range"):
        gb.load(path, sh_dtype="float16")


def test_an_unknown_sh_dtype_is_one_line():
    with pytest.raises(gb.GBViewerError, match="sh_dtype 'float64'; expected one of float32, float16"):
        gb.load(FILES[0], sh_dtype="float64")


@pytest.mark.parametrize("mode", [Mode.SCALAR, Mode.GAUSSIAN_BLENDING])
def test_cpu_renders_float16_sh_as_its_float32_value(mode):
    half = gb.load(SEEDS / "inria" / "sh1.ply", sh_dtype="float16")
    rounded = gb.Scene.from_arrays(half.means, half.scales, half.quats, half.opacities, half.sh.astype(np.float32))
    cam = orbit_camera(half, width=48, height=32)
    got = get_renderer(half, "cpu").render(cam, RenderSettings(mode=mode))
    want = get_renderer(rounded, "cpu").render(cam, RenderSettings(mode=mode))
    assert got.rgb.max() > 0
    np.testing.assert_array_equal(got.rgb, want.rgb)
    np.testing.assert_array_equal(got.alpha, want.alpha)
