"""glTF splats (KHR_gaussian_splatting) read from hand-written files: every component type the extension allows per
attribute (normalised integers by glTF's rule), strides, sparse accessors, .glb / embedded / external buffers, node
hierarchies (TRS and matrix, with SH rotation), the axes convention, several primitives, hostile files."""

from __future__ import annotations

import json

import numpy as np
import pytest
from encoders import random_params
from fuzz_loaders import check_load
from gltf_files import GltfFile, P, quantise

import gbviewer as gb
from gbviewer.cli import main
from gbviewer.io.transform import sh_basis
from gbviewer.model.cells import rotation_matrices

TO_OURS = np.diag([-1.0, -1.0, 1.0])  # glTF -> INRIA: 180 degrees about z


def simple(s: dict, tmp_path, how: str = "glb", **node) -> gb.Scene:
    f = GltfFile()
    f.node(mesh=f.mesh(f.splats(s)), **node)
    return gb.load(f.write(tmp_path / ("s.glb" if how == "glb" else "s.gltf"), how))


def covariances(quats: np.ndarray, scales: np.ndarray) -> np.ndarray:
    r = rotation_matrices(quats)
    return np.einsum("nij,nj,nkj->nik", r, np.asarray(scales, np.float64) ** 2, r)


def colours(sh: np.ndarray, dirs: np.ndarray) -> np.ndarray:
    """(N, A, 3) raw SH colour sums at directions (A, 3)."""
    return np.einsum("ak,nkc->nac", sh_basis(dirs, sh.shape[1]), np.asarray(sh, np.float64))


@pytest.mark.parametrize("how", ["glb", "embedded", "external"])
def test_float_splats_load_exactly_with_axes_turned(tmp_path, how):
    s = {k: v.astype(np.float32) for k, v in random_params(50, sh_degree=3, seed=1).items()}
    scene = simple(s, tmp_path, how)
    assert scene.meta["format"] == ("glb" if how == "glb" else "gltf") and scene.sh_degree == 3
    np.testing.assert_array_equal(scene.means, s["means"] * np.float32([-1, -1, 1]))
    np.testing.assert_array_equal(scene.scales, s["scales"])
    np.testing.assert_array_equal(scene.opacities, s["opacities"])
    np.testing.assert_allclose(
        covariances(scene.quats, scene.scales), TO_OURS @ covariances(s["quats"], s["scales"]) @ TO_OURS, atol=1e-6
    )
    dirs = np.random.default_rng(0).normal(size=(20, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    np.testing.assert_allclose(colours(scene.sh, dirs), colours(s["sh"], dirs @ TO_OURS), atol=1e-5)


def test_axes_on_an_asymmetric_scene(tmp_path):
    """glTF +Y up, +Z forward, +X left: a splat up (+Y) and one left (+X) land at -y (up in the INRIA frame, y down)
    and -x; a splat stretched along glTF's X stays stretched along x; an SH that is brighter looking along +X
    stays brighter looking along our -x."""
    s = {
        "means": np.array([[0, 1, 5], [1, 0, 5]], np.float32),
        "scales": np.array([[1, 0.1, 0.1]] * 2, np.float32),
        "quats": np.array([[1, 0, 0, 0]] * 2, np.float32),
        "opacities": np.ones(2, np.float32),
        "sh": np.zeros((2, 4, 3), np.float32),
    }
    s["sh"][:, 3] = -1.0  # coefficient of -c1 x: brighter towards +x
    scene = simple(s, tmp_path)
    np.testing.assert_array_equal(scene.means, [[0, -1, 5], [-1, 0, 5]])
    np.testing.assert_allclose(covariances(scene.quats, scene.scales)[0], np.diag([1, 0.01, 0.01]), atol=1e-7)
    brighter = colours(scene.sh, np.array([[-1.0, 0, 0], [1.0, 0, 0]]))[0, :, 0]
    assert brighter[0] > 0 > brighter[1]


COMPONENTS = {  # attribute: (width, [(componentType, normalized)]), the extension's attribute table
    "POSITION": (3, [(5126, False), (5122, True), (5120, False), (5123, False)]),
    P + "ROTATION": (4, [(5126, False), (5120, True), (5122, True)]),
    P + "SCALE": (3, [(5126, False), (5120, False), (5120, True), (5122, False), (5122, True)]),
    P + "OPACITY": (1, [(5126, False), (5121, True), (5123, True)]),
}


@pytest.mark.parametrize("attr,ctype,norm", [(a, c, n) for a, (_, kinds) in COMPONENTS.items() for c, n in kinds])
def test_every_allowed_component_type(tmp_path, attr, ctype, norm):
    s = {k: v.astype(np.float32) for k, v in random_params(40, seed=2).items()}
    s["means"] = np.abs(s["means"]) / 3 if ctype == 5123 else s["means"] / 3  # inside the integer ranges
    s["scales"] = s["scales"] * 0.5
    width = COMPONENTS[attr][0]
    values = {
        "POSITION": s["means"],
        P + "ROTATION": np.concatenate([s["quats"][:, 1:], s["quats"][:, :1]], 1),
        P + "SCALE": s["scales"] * (1 if norm or ctype == 5126 else 100),
        P + "OPACITY": s["opacities"],
    }[attr]
    stored, decoded = quantise(values.reshape(40, width), ctype, norm)
    f = GltfFile()
    prim = f.splats(s)
    prim["attributes"][attr] = f.accessor(stored, ctype, norm)
    f.node(mesh=f.mesh(prim))
    scene = gb.load(f.write(tmp_path / "a.glb"))
    if attr == "POSITION":
        np.testing.assert_array_equal(scene.means, decoded * np.float32([-1, -1, 1]))
    elif attr == P + "SCALE":
        np.testing.assert_array_equal(scene.scales, decoded)
    elif attr == P + "OPACITY":
        np.testing.assert_array_equal(scene.opacities, decoded[:, 0])
    else:
        q = np.concatenate([decoded[:, 3:], decoded[:, :3]], 1)
        np.testing.assert_allclose(
            covariances(scene.quats, scene.scales),
            TO_OURS @ covariances(q / np.linalg.norm(q, axis=1, keepdims=True), s["scales"]) @ TO_OURS,
            atol=1e-6,
        )


def test_disallowed_component_type_is_one_line(tmp_path, capsys):
    s = random_params(5, seed=3)
    f = GltfFile()
    prim = f.splats(s)
    prim["attributes"][P + "OPACITY"] = f.accessor(np.full(5, 200), 5121, normalized=False)
    f.node(mesh=f.mesh(prim))
    path = f.write(tmp_path / "bad.glb")
    assert main(["info", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert "componentType 5121 is not allowed" in err and "unsigned byte normalized" in err and "\n" not in err


def test_stride_and_sparse(tmp_path):
    s = {k: v.astype(np.float32) for k, v in random_params(30, seed=4).items()}
    f = GltfFile()
    prim = f.splats(s)
    prim["attributes"]["POSITION"] = f.accessor(s["means"], stride=16, sparse=([2, 7], [[9, 9, 9], [8, 8, 8]]))
    prim["attributes"][P + "OPACITY"] = f.accessor(np.zeros(30), no_view=True, sparse=([0, 29], [0.25, 0.75]))
    f.node(mesh=f.mesh(prim))
    scene = gb.load(f.write(tmp_path / "a.glb"))
    want = s["means"].copy()
    want[2], want[7] = 9, 8
    np.testing.assert_array_equal(scene.means, want * np.float32([-1, -1, 1]))
    assert scene.opacities[0] == 0.25 and scene.opacities[29] == 0.75 and not scene.opacities[1:29].any()


def trs_matrix(t, q_xyzw, s) -> np.ndarray:
    x, y, z, w = q_xyzw
    m = np.eye(4)
    m[:3, :3] = rotation_matrices(np.array([[w, x, y, z]]))[0] * np.asarray(s, float)
    m[:3, 3] = t
    return m


@pytest.mark.parametrize("child_scale", [[1.5, 1.5, 1.5], [2.0, 0.5, 1.0]])
def test_node_hierarchy_trs_and_matrix(tmp_path, child_scale):
    """A TRS parent (a reflection-free similarity) over a child given as a column-major matrix (similarity or
    not): centres move by the world matrix, covariances by A S A^T, the SH colour turns with A's rotation."""
    s = {k: v.astype(np.float32) for k, v in random_params(25, sh_degree=2, seed=5).items()}
    q = np.array([0.2, -0.4, 0.1, 0.9])
    q /= np.linalg.norm(q)
    parent = trs_matrix([1, 2, 3], q, [2, 2, 2])
    child = trs_matrix([-0.5, 0, 0.25], [0, np.sin(0.3), 0, np.cos(0.3)], child_scale)
    f = GltfFile()
    mesh = f.mesh(f.splats(s))
    kid = f.node(mesh=mesh, matrix=child.T.ravel().tolist())
    f.node(children=[kid], translation=[1, 2, 3], rotation=q.tolist(), scale=[2, 2, 2])
    scene = gb.load(f.write(tmp_path / "h.glb"))
    world = parent @ child
    a = world[:3, :3]
    np.testing.assert_allclose(scene.means, (s["means"] @ a.T + world[:3, 3]) @ TO_OURS, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(
        covariances(scene.quats, scene.scales),
        TO_OURS @ a @ covariances(s["quats"], s["scales"]) @ a.T @ TO_OURS,
        rtol=1e-4,
        atol=1e-7,
    )
    u, _, vt = np.linalg.svd(a)
    rot = u @ vt
    dirs = np.random.default_rng(1).normal(size=(30, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    np.testing.assert_allclose(colours(scene.sh, dirs), colours(s["sh"], dirs @ TO_OURS @ rot), atol=1e-5)


def test_several_primitives_one_scene_or_one_by_index(tmp_path, capsys):
    a, b = (random_params(n, sh_degree=d, seed=n) for n, d in ((10, 1), (7, 0)))
    f = GltfFile()
    f.node(mesh=f.mesh(f.splats(a), f.splats(b)))
    path = f.write(tmp_path / "two.glb")
    with pytest.warns(UserWarning, match="2 splat primitives loaded as one scene"):
        both = gb.load(path)
    assert both.num_splats == 17 and both.sh_degree == 1 and both.meta["primitives"] == 2
    assert not both.sh[10:, 1:].any()  # the degree-0 primitive padded with zero bands
    second = gb.load(path, primitive=1)
    np.testing.assert_allclose(second.opacities, b["opacities"], rtol=1e-6)
    assert main(["info", str(path), "--primitive", "2"]) == 2
    assert "has 2 splat primitives (0..1)" in capsys.readouterr().err
    ply = tmp_path / "x.ply"
    gb.save(second, ply)
    assert main(["info", str(ply), "--primitive", "0"]) == 2
    assert "not a glTF file" in capsys.readouterr().err


def test_extension_properties_reported_and_unsupported_said(tmp_path, capsys):
    s = random_params(5, seed=6)
    f = GltfFile()
    prim = f.splats(s)
    prim["extensions"]["KHR_gaussian_splatting"] = {"kernel": "customShape", "colorSpace": "lin_rec709_display"}
    f.node(mesh=f.mesh(prim))
    path = f.write(tmp_path / "k.glb")
    with pytest.warns(UserWarning) as record:
        scene = gb.load(path)
    lines = [str(w.message) for w in record]
    assert any("kernel customShape is not supported" in m for m in lines)
    assert any("colorSpace lin_rec709_display is not supported" in m for m in lines)
    assert (scene.meta["kernel"], scene.meta["projection"], scene.meta["sortingMethod"]) == (
        "customShape",
        "perspective",
        "cameraDistance",
    )
    with pytest.warns(UserWarning):
        assert main(["info", str(path)]) == 0
    out = capsys.readouterr().out
    assert "kernel: customShape" in out and "colorSpace: lin_rec709_display" in out


def hostile(tmp_path, edit) -> str:
    s = random_params(8, seed=7)
    f = GltfFile()
    f.node(mesh=f.mesh(f.splats(s)))
    edit(f)
    return check_load(f.write(tmp_path / "h.glb"))


@pytest.mark.parametrize(
    "name,edit",
    [
        ("count beyond bytes", lambda f: f.doc["accessors"][0].update(count=1 << 27)),
        (
            "zeros beyond bytes",
            lambda f: (f.doc["accessors"][0].pop("bufferView"), f.doc["accessors"][0].update(count=1 << 40)),
        ),
        ("offset beyond view", lambda f: f.doc["accessors"][1].update(byteOffset=4000)),
        ("view beyond buffer", lambda f: f.doc["bufferViews"][0].update(byteLength=1 << 30)),
        ("bad index", lambda f: f.doc["accessors"][2].update(bufferView=99)),
        ("node cycle", lambda f: f.doc["nodes"].append({"children": [1]}) or f.doc["nodes"][0].update(children=[1])),
        (
            "sparse out of range",
            lambda f: f.doc["accessors"][0].update(
                sparse={"count": 1, "indices": {"bufferView": 0, "componentType": 5123}, "values": {"bufferView": 0}}
            ),
        ),
        (
            "partial SH",
            lambda f: f.doc["meshes"][0]["primitives"][0]["attributes"].update({P + "SH_DEGREE_1_COEF_0": 0}),
        ),
        ("no splat primitive", lambda f: f.doc["meshes"][0]["primitives"][0].pop("extensions")),
        ("lines mode", lambda f: f.doc["meshes"][0]["primitives"][0].update(mode=1)),
        ("deep json", lambda f: f.doc.update(extras=json.loads("[" * 40 + "]" * 40))),
    ],
)
def test_hostile_files_are_one_line(tmp_path, name, edit):
    assert hostile(tmp_path, edit) == "error"


def test_external_buffer_outside_the_folder_refused(tmp_path):
    f = GltfFile()
    f.node(mesh=f.mesh(f.splats(random_params(4, seed=8))))
    path = f.write(tmp_path / "e.gltf", "external")
    text = path.read_text().replace('"uri": "e.bin"', '"uri": "../e.bin"')
    path.write_text(text)
    with pytest.raises(gb.SceneFormatError, match="must be a relative path inside"):
        gb.load(path)


def test_truncated_glb_is_one_line(tmp_path):
    f = GltfFile()
    f.node(mesh=f.mesh(f.splats(random_params(20, seed=9))))
    path = f.write(tmp_path / "t.glb")
    data = path.read_bytes()
    for cut in (10, 30, len(data) // 2, len(data) - 4):
        path.write_bytes(data[:cut])
        assert check_load(path) == "error"
