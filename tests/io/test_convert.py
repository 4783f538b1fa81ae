"""`gbviewer convert` writes a standard INRIA .ply; the round trip is exact for INRIA input; `info` names
the format and version."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import plyfile
import pytest
from encoders import encode_compressed_ply, encode_splat, encode_spz, random_params, sog_files, write_sog
from helpers import skip_or_fail

import gbviewer as gb
from gbviewer.cli import main

SCENES = Path(__file__).resolve().parents[2].parent / "shared" / "scenes"
FIELDS = ["means", "scales", "quats", "opacities", "sh", "filter_3d"]


def assert_same(a: gb.Scene, b: gb.Scene) -> None:
    for name in FIELDS:
        x, y = getattr(a, name), getattr(b, name)
        assert (x is None) == (y is None), name
        if x is not None:
            np.testing.assert_array_equal(x, y, err_msg=name)


def raw_inria_ply(path: Path, n: int = 3000, degree: int = 2, seed: int = 0) -> Path:
    """An extended INRIA layout: no normals, a Mip-Splatting filter_3D, extra properties of other types,
    raw values over wide ranges (saturating sigmoid and exp at the ends)."""
    rng = np.random.default_rng(seed)
    k = 3 * ((degree + 1) ** 2 - 1)
    names = (
        ["x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2"]
        + [f"f_rest_{i}" for i in range(k)]
        + ["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3", "filter_3D"]
    )
    dtype = [(name, "<f4") for name in names] + [("red", "u1"), ("confidence", "<f8")]
    v = np.zeros(n, dtype=dtype)
    for name in names:
        v[name] = rng.normal(0, 2, n)
    v["opacity"] = rng.uniform(-30, 30, n)
    v["opacity"][:6] = [-100, 100, 0, 1e-8, -17, 17]
    v["scale_0"] = rng.uniform(-15, 4, n)
    v["scale_0"][:2] = [-120, 0]
    v["filter_3D"] = np.abs(v["filter_3D"])
    plyfile.PlyData([plyfile.PlyElement.describe(v, "vertex")]).write(str(path))
    return path


def test_round_trip_exact_for_extended_inria(tmp_path):
    src = gb.load(raw_inria_ply(tmp_path / "in.ply"))
    assert src.filter_3d is not None and src.sh_degree == 2
    out = gb.io.write_inria_ply(src, tmp_path / "out.ply")
    assert_same(src, gb.load(out))


@pytest.mark.parametrize("name", ["fruit_drops_minimal.ply", "v3dg-donut.fused.ply"])
def test_round_trip_exact_for_shared_inria(tmp_path, name):
    if not (SCENES / name).exists():
        skip_or_fail(f"{SCENES / name} absent (shared/ is not beside the repo)")
    src = gb.load(SCENES / name)
    assert_same(src, gb.load(gb.io.write_inria_ply(src, tmp_path / "out.ply")))


def test_written_ply_is_standard(tmp_path):
    s = random_params(200, sh_degree=3, seed=1)
    scene = gb.Scene.from_arrays(s["means"], s["scales"], s["quats"], s["opacities"], s["sh"])
    ply = plyfile.PlyData.read(str(gb.io.write_inria_ply(scene, tmp_path / "o.ply")))
    names = [p.name for p in ply["vertex"].properties]
    assert names == (
        ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"]
        + [f"f_rest_{i}" for i in range(45)]
        + ["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]
    )
    assert all(p.val_dtype in ("f4", "float32") for p in ply["vertex"].properties)
    v = ply["vertex"].data
    np.testing.assert_allclose(1 / (1 + np.exp(-v["opacity"])), s["opacities"], atol=1e-6)
    # f_rest is channel-major: f_rest_0..14 are red coefficients 1..15
    np.testing.assert_allclose(v["f_rest_14"], s["sh"][:, 15, 0], atol=1e-7)
    np.testing.assert_allclose(v["f_rest_15"], s["sh"][:, 1, 1], atol=1e-7)


def test_convert_cli(tmp_path, capsys):
    s = random_params(300, sh_degree=1, seed=2)
    src = tmp_path / "scene.spz"
    src.write_bytes(encode_spz(s, 4))
    out = tmp_path / "out.ply"
    assert main(["convert", str(src), str(out)]) == 0
    assert "from spz (version 4)" in capsys.readouterr().out
    first = out.read_bytes()
    converted, loaded = gb.load(out), gb.load(src)
    for name in FIELDS[:5]:  # not always bit-exact: a/255 opacities need not be float32 sigmoids
        np.testing.assert_allclose(getattr(converted, name), getattr(loaded, name), rtol=1e-6, atol=1e-7)
    assert main(["convert", str(src), str(out)]) == 2  # refuses to overwrite
    assert "--force" in capsys.readouterr().err and out.read_bytes() == first
    assert main(["convert", str(src), str(out), "--force"]) == 0
    assert main(["convert", str(src), str(tmp_path / "out.png")]) == 2
    assert not (tmp_path / "out.png").exists()
    assert list(tmp_path.glob(".out-*")) == []  # no temporary left behind


def test_info_reports_format_and_version(tmp_path, capsys):
    s = random_params(300, seed=3)
    files = {
        "a.spz": encode_spz(s, 3),
        "b.ply": encode_compressed_ply(s, color_ranges=False),
        "c.splat": encode_splat(s),
    }
    for name, data in files.items():
        (tmp_path / name).write_bytes(data)
    write_sog(sog_files(s), tmp_path / "d.sog")
    expected = {
        "a.spz": ("spz", "3"),
        "b.ply": ("compressed-ply", "12-property chunks"),
        "c.splat": ("splat", "None"),
        "d.sog": ("sog", "2"),
    }
    for name, (fmt, version) in expected.items():
        assert main(["info", str(tmp_path / name)]) == 0
        lines = {
            line.split(":", 1)[0].strip(): line.split(":", 1)[1].strip()
            for line in capsys.readouterr().out.splitlines()
        }
        assert (lines["format"], lines["version"], lines["splats"]) == (fmt, version, "300")
