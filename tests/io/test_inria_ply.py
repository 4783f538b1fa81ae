"""INRIA 3DGS .ply loading: activations, SH layout, tolerated variants and typed errors."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from plyfile import PlyData, PlyElement

import gbviewer as gb


def write_inria(path, n=5, degree=3, seed=0, extra=(), drop=(), filter_3d=None, values=None):
    """Write an INRIA-layout ply with known raw values; returns the raw columns as a dict."""
    rng = np.random.default_rng(seed)
    names = ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"]
    names += [f"f_rest_{i}" for i in range(3 * ((degree + 1) ** 2 - 1))]
    names += ["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3", *extra]
    if filter_3d is not None:
        names.append("filter_3D")
    names = [nm for nm in names if nm not in drop]
    raw = {nm: rng.normal(size=n).astype(np.float32) for nm in names}
    if filter_3d is not None:
        raw["filter_3D"] = np.full(n, filter_3d, np.float32)
    raw.update(values or {})
    arr = np.empty(n, dtype=[(nm, "f4") for nm in names])
    for nm in names:
        arr[nm] = raw[nm]
    PlyData([PlyElement.describe(arr, "vertex")]).write(str(path))
    return raw


@pytest.mark.parametrize("degree", [0, 1, 2, 3])
def test_activations_and_sh_layout(tmp_path, degree):
    path = tmp_path / "s.ply"
    raw = write_inria(path, degree=degree)
    scene = gb.load(path)
    k = (degree + 1) ** 2
    assert scene.sh_degree == degree and scene.sh.shape == (5, k, 3)
    np.testing.assert_allclose(scene.means[:, 1], raw["y"], rtol=1e-6)
    np.testing.assert_allclose(scene.scales[:, 2], np.exp(raw["scale_2"]), rtol=1e-6)
    np.testing.assert_allclose(scene.opacities, 1 / (1 + np.exp(-raw["opacity"])), rtol=1e-6)
    q = np.stack([raw[f"rot_{i}"] for i in range(4)], 1)
    np.testing.assert_allclose(scene.quats, q / np.linalg.norm(q, axis=1, keepdims=True), rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(scene.sh[:, 0, 1], raw["f_dc_1"], rtol=1e-6)
    for c in range(3):  # channel-major: f_rest_{c*(k-1) + j} is coefficient j+1 of channel c
        for j in range(k - 1):
            np.testing.assert_array_equal(scene.sh[:, j + 1, c], raw[f"f_rest_{c * (k - 1) + j}"])
    assert scene.meta["format"] == "inria-ply"


def test_variants_without_normals_or_rest_and_with_extras(tmp_path):
    path = tmp_path / "fused.ply"
    write_inria(path, degree=0, drop=("nx", "ny", "nz"), extra=("red", "transform"))
    scene = gb.load(path)
    assert scene.num_splats == 5 and scene.sh_degree == 0 and scene.filter_3d is None


def test_filter_3d_is_kept_and_applied(tmp_path):
    path = tmp_path / "mip.ply"
    write_inria(
        path,
        degree=0,
        filter_3d=0.05,
        values={"x": np.zeros(5, np.float32), "y": np.zeros(5, np.float32), "z": np.full(5, 3, np.float32)},
    )
    scene = gb.load(path)
    np.testing.assert_allclose(scene.filter_3d, 0.05)
    plain = gb.Scene.from_arrays(scene.means, scene.scales, scene.quats, scene.opacities, scene.sh)
    cam = gb.Camera(32, 32, 40, 40, 16, 16, np.eye(3), np.zeros(3))
    a = gb.render(scene, cam, "scalar").alpha
    b = gb.render(plain, cam, "scalar").alpha
    assert np.abs(a - b).max() > 1e-3  # the filter changes the image


def test_shared_inria_scene_loads():
    from helpers import shared_scene

    scene = gb.load(shared_scene("fruit_drops_minimal.ply"))
    assert (scene.num_splats, scene.sh_degree) == (4721, 3)
    scene = gb.load(shared_scene("v3dg-donut.fused.ply"))
    assert (scene.num_splats, scene.sh_degree) == (45624, 0)


def test_not_a_ply(tmp_path):
    path = tmp_path / "x.ply"
    path.write_bytes(b"hello world, not a ply at all\n")
    with pytest.raises(gb.SceneFormatError, match="x.ply"):
        gb.load(path)


def test_missing_file(tmp_path):
    with pytest.raises(gb.SceneFormatError, match="no such file"):
        gb.load(tmp_path / "nope.ply")


def test_no_vertex_element(tmp_path):
    path = tmp_path / "face.ply"
    PlyData([PlyElement.describe(np.zeros(3, dtype=[("a", "f4")]), "face")]).write(str(path))
    with pytest.raises(gb.SceneFormatError, match="vertex"):
        gb.load(path)


@pytest.mark.parametrize("field", ["opacity", "rot_2", "scale_0", "f_dc_2", "x"])
def test_missing_required_property(tmp_path, field):
    path = tmp_path / "m.ply"
    write_inria(path, drop=(field,))
    with pytest.raises(gb.SceneFormatError, match=f"'{field}'.*missing"):
        gb.load(path)


def test_inconsistent_rest_count(tmp_path):
    path = tmp_path / "r.ply"
    write_inria(path, degree=1, drop=("f_rest_4",))
    with pytest.raises(gb.SceneFormatError, match="f_rest"):
        gb.load(path)


def test_non_numeric_property(tmp_path):
    path = tmp_path / "list.ply"
    n = 3
    dt = [
        (nm, "f4")
        for nm in [
            "x",
            "y",
            "z",
            "f_dc_0",
            "f_dc_1",
            "f_dc_2",
            "scale_0",
            "scale_1",
            "scale_2",
            "rot_0",
            "rot_1",
            "rot_2",
            "rot_3",
        ]
    ] + [("opacity", "O")]
    arr = np.empty(n, dtype=dt)
    for nm, _ in dt[:-1]:
        arr[nm] = 0.5
    for i in range(n):
        arr["opacity"][i] = np.array([1.0, 2.0], np.float32)
    PlyData([PlyElement.describe(arr, "vertex")]).write(str(path))
    with pytest.raises(gb.SceneFormatError, match="'opacity'.*expected a scalar number"):
        gb.load(path)


def test_truncated(tmp_path):
    path = tmp_path / "t.ply"
    write_inria(path, n=50)
    data = path.read_bytes()
    path.write_bytes(data[: len(data) - 100])
    with pytest.raises(gb.SceneFormatError, match="truncated"):
        gb.load(path)


def test_zero_splats(tmp_path):
    path = tmp_path / "z.ply"
    write_inria(path, n=0)
    with pytest.raises(gb.SceneFormatError, match="zero splats"):
        gb.load(path)


def test_non_finite_splats_dropped_with_one_warning(tmp_path):
    path = tmp_path / "nan.ply"
    n = 20
    x = np.linspace(-1, 1, n).astype(np.float32)
    x[3] = np.nan
    sc = np.full(n, -3, np.float32)
    sc[11] = 1e5  # exp overflows to inf
    write_inria(path, n=n, degree=0, values={"x": x, "scale_0": sc})
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        scene = gb.load(path)
    msgs = [str(w.message) for w in caught if "non-finite" in str(w.message)]
    assert len(msgs) == 1 and "dropped 2 of 20" in msgs[0]
    assert scene.num_splats == 18


def test_degenerate_splats_render_without_nan(tmp_path):
    path = tmp_path / "deg.ply"
    n = 8
    z = np.full(n, 3.0, np.float32)
    sc = np.full(n, -3.0, np.float32)
    sc[:3] = -200.0  # exp underflows to 0
    rot0 = np.ones(n, np.float32)
    rot0[3:6] = 0.0
    zero = np.zeros(n, np.float32)
    values = {
        "x": np.linspace(-0.5, 0.5, n).astype(np.float32),
        "y": zero,
        "z": z,
        "scale_0": sc,
        "scale_1": sc,
        "scale_2": sc,
        "rot_0": rot0,
        "rot_1": zero,
        "rot_2": zero,
        "rot_3": zero,
        "opacity": np.full(n, 5.0, np.float32),
    }
    write_inria(path, n=n, degree=0, values=values)
    scene = gb.load(path)
    assert scene.num_splats == n
    np.testing.assert_allclose(scene.quats[3], [1, 0, 0, 0])
    cam = gb.Camera(48, 32, 40, 40, 24, 16, np.eye(3), np.zeros(3))
    for mode in ["scalar", "mip", "analytic", "gaussian_blending"]:
        for ss in (1, 2):
            f = gb.render(scene, cam, mode, supersample=ss)
            assert np.isfinite(f.rgb).all() and np.isfinite(f.alpha).all(), (mode, ss)
