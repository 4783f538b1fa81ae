"""Trained Duplex-GS checkpoints (gbviewer/io/duplex.py): written here in the published layout (anchor ply + MLPs
saved by torch.jit.script of small nn.Sequential stacks, or one 'unite' checkpoints.pth), loaded, decoded, rendered.

- The hand-computed image: one visible anchor with two children whose MLPs output constants; its splats are flat
  and 10^4 px wide (constant alpha over the image), so duplex and scalar pixels are the published formulas evaluated
  once with the decoded opacity o * v, E and w_bg from the ply's info column.
- Decoding against numpy: random MLP weights, inputs [feature, view, distance] for one MLP and [feature, view] for
  the others, a feature bank; every decoded splat parameter within 1e-5.
- Bad or partial checkpoints give SceneFormatErrors that name the file and what was expected.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from helpers import skip_or_fail

import gbviewer as gb
from gbviewer.core.errors import SceneFormatError
from gbviewer.model.scene import SH_C0

torch = pytest.importorskip("torch", reason="Duplex-GS checkpoints need torch (pip install 'gbviewer[duplex]')")
nn = torch.nn
pytestmark = pytest.mark.filterwarnings("ignore:`torch.jit:DeprecationWarning")  # the published format is TorchScript


def write_anchor_ply(
    path: Path, anchors, offsets, feats, log_sizes, sh_vi, info, levels=None, extra=None, rots=None
) -> None:
    """The published save_ply layout (f_offset channel-major, info in the first rows)."""
    from plyfile import PlyData, PlyElement

    n, k = offsets.shape[:2]
    levels = np.zeros(n) if levels is None else levels
    extra = np.zeros(n) if extra is None else extra
    rots = np.tile([1.0, 0, 0, 0], (n, 1)) if rots is None else rots
    infos = np.zeros(n)
    infos[: len(info)] = info
    cols = [
        ("x", anchors[:, 0]),
        ("y", anchors[:, 1]),
        ("z", anchors[:, 2]),
        ("level", levels),
        ("extra_level", extra),
        ("info", infos),
    ]
    off = offsets.transpose(0, 2, 1).reshape(n, 3 * k)
    cols += [(f"f_offset_{i}", off[:, i]) for i in range(3 * k)]
    cols += [(f"f_anchor_feat_{i}", feats[:, i]) for i in range(feats.shape[1])]
    cols += [(f"anchor_size_{i}", log_sizes[:, i]) for i in range(3)]
    cols += [(f"anchor_rot_{i}", rots[:, i]) for i in range(4)]
    cols += [("anchor_shd_0", sh_vi[:, 0])] + [(f"anchor_shv_{i}", sh_vi[:, i + 1]) for i in range(sh_vi.shape[1] - 1)]
    el = np.empty(n, dtype=[(name, "f4") for name, _ in cols])
    for name, v in cols:
        el[name] = v
    PlyData([PlyElement.describe(el, "vertex")]).write(str(path))


def mlp(n_in, hidden, n_out, act=None, weights=True, seed=0, const=None):
    layers = [nn.Linear(n_in, hidden), nn.ReLU(True), nn.Linear(hidden, n_out)] + ([act] if act else [])
    m = nn.Sequential(*layers)
    with torch.no_grad():
        if const is not None:  # constant output: zero weights, last bias = const
            for p in m.parameters():
                p.zero_()
            m[2].bias.copy_(torch.as_tensor(const, dtype=torch.float32))
        elif weights:
            g = torch.Generator().manual_seed(seed)
            for p in m.parameters():
                p.copy_(torch.randn(p.shape, generator=g) * 0.5)
    return m.eval()


def save_mlps(folder: Path, mlps: dict) -> None:
    names = {
        "opacity": "opacity_mlp.pt",
        "cov": "cov_mlp.pt",
        "color": "color_mlp.pt",
        "feature_bank": "feature_bank_mlp.pt",
    }
    for kind, m in mlps.items():
        torch.jit.script(m).save(str(folder / names[kind]))


def logit(p):
    return math.log(p / (1 - p))


def hand_checkpoint(folder: Path, E=2.0, wbg_raw=0.15):
    """Anchor 0 in front of the camera at z = 4 with two children at z = 3.5 and 4.5; anchors 1-4 behind it."""
    F, k = 4, 2
    anchors = np.array([[0.0, 0.0, 4.0], [0, 0, -5], [1, 0, -5], [0, 1, -5], [1, 1, -5]])
    n = len(anchors)
    offsets = np.zeros((n, k, 3))
    offsets[:, 0, 2], offsets[:, 1, 2] = -0.5, 0.5
    big = 1e4 * 4.0 / 20.0  # anchor scale in x, y: ~10^4 px at focal 20
    log_sizes = np.log(np.tile([big, big, 1.0], (n, 1)))
    sh_vi = np.zeros((n, 16))
    sh_vi[:, 0] = logit(0.8) / SH_C0  # v = sigmoid(SH_C0 * shd) = 0.8
    info = [0.01, 10.0, 6.0, wbg_raw, E]
    write_anchor_ply(folder / "point_cloud.ply", anchors, offsets, np.ones((n, F)), log_sizes, sh_vi, info)
    colours = [(0.9, 0.2, 0.1), (0.1, 0.3, 0.8)]
    save_mlps(
        folder,
        {
            "opacity": mlp(F + 3, F, k, nn.Tanh(), const=[math.atanh(0.6), math.atanh(0.5)]),
            "cov": mlp(F + 3, F, 7 * k, const=[20.0, 20.0, 20.0, 1.0, 0.0, 0.0, 0.0] * k),
            "color": mlp(F + 3, F, 3 * k, nn.Sigmoid(), const=[logit(c) for col in colours for c in col]),
        },
    )
    return folder / "point_cloud.ply", colours


@pytest.fixture()
def camera():
    return gb.Camera(16, 12, 20.0, 20.0, 8.0, 6.0, np.eye(3), np.zeros(3))


def test_load_and_render_hand_computed(tmp_path, camera):
    path, colours = hand_checkpoint(tmp_path)
    scene = gb.load(path)
    assert scene.meta["format"] == "duplex-gs" and scene.oit.neural is not None and scene.oit.et_grade == 2.0
    assert scene.oit.weight_background == pytest.approx(0.25)
    view = scene.oit.neural.decode(camera)
    assert view.num_splats == 2 and view.oit.cells.num_cells == 1  # the anchors behind the camera are not decoded
    np.testing.assert_allclose(view.opacities, [0.48, 0.40], atol=1e-6)
    np.testing.assert_allclose(view.means[:, 2], [3.5, 4.5], atol=1e-6)
    np.testing.assert_allclose(view.scales[0], [0.5 * 2000, 0.5 * 2000, 0.5], rtol=1e-5)  # ratio_max (2-0.5)/3
    a, c, bg = np.array([0.48, 0.40]), np.array(colours), np.array([0.2, 0.4, 0.6])
    E, wbg = 2.0, 0.25
    T = (1 - a[0] / E) * (1 - a[1] / E)
    expect = ((a[:, None] / E * c).sum(0) + bg * wbg) / (a.sum() / E + wbg * T)
    f = gb.render(scene, camera, "duplex", background=tuple(bg))
    assert np.abs(f.rgb - expect).max() < 1e-5
    assert f.stats.decode_ms is not None and f.stats.cells == 1 and "K=" not in f.stats.mode
    scalar = gb.render(scene, camera, "scalar", background=tuple(bg))
    expect_scalar = a[0] * c[0] + (1 - a[0]) * a[1] * c[1] + (1 - a[0]) * (1 - a[1]) * bg
    assert np.abs(scalar.rgb - expect_scalar).max() < 1e-5
    wsr = gb.render(scene, camera, "wsr", background=tuple(bg))
    expect_wsr = ((a[:, None] * c).sum(0) + bg * wbg) / (a.sum() + wbg)
    assert np.abs(wsr.rgb - expect_wsr).max() < 1e-5 and "approx" not in wsr.stats.mode


def test_view_without_anchors_is_background(tmp_path):
    """Looking away from every anchor (or LOD dropping them all) draws the background in every mode."""
    path, _ = hand_checkpoint(tmp_path)
    scene = gb.load(path)
    looking_along_minus_y = np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]])
    away = gb.Camera(16, 12, 20.0, 20.0, 8.0, 6.0, looking_along_minus_y, np.zeros(3))
    bg = (0.2, 0.4, 0.6)
    for mode in ("duplex", "wsr", "scalar", "gaussian_blending"):
        f = gb.render(scene, away, mode, background=bg)
        np.testing.assert_allclose(f.rgb, np.broadcast_to(bg, f.rgb.shape), atol=1e-6, err_msg=mode)
        assert f.stats.visible == 0


@pytest.mark.parametrize("projection", ["perspective", "orthographic"])
def test_decode_matches_numpy(tmp_path, projection):
    """Random MLPs with a distance input (opacity only) and a feature bank; decoded splats against numpy. An
    orthographic camera sees every anchor along its forward axis (+z here), at its depth."""
    rng = np.random.default_rng(5)
    F, k, n = 8, 3, 12
    anchors = rng.uniform(-1, 1, (n, 3)) + [0, 0, 5]
    offsets = rng.uniform(-1.2, 1.2, (n, k, 3))
    feats = rng.normal(size=(n, F))
    log_sizes = np.log(rng.uniform(0.05, 0.3, (n, 3)))
    sh_vi = rng.normal(0, 0.5, (n, 16))
    info = [0.01, 10.0, 6.0, -0.3, 4.0]
    write_anchor_ply(tmp_path / "point_cloud.ply", anchors, offsets, feats, log_sizes, sh_vi, info)
    mlps = {
        "opacity": mlp(F + 4, F, k, nn.Tanh(), seed=1),
        "cov": mlp(F + 3, F, 7 * k, seed=2),
        "color": mlp(F + 3, F, 3 * k, nn.Sigmoid(), seed=3),
        "feature_bank": mlp(3, F, 3, nn.Softmax(dim=1), seed=4),
    }
    save_mlps(tmp_path, mlps)
    scene = gb.load(tmp_path / "point_cloud.ply")
    assert scene.oit.weight_background == pytest.approx(0.1)  # relu(-0.3) + 0.1
    cam = gb.Camera(32, 24, 30.0, 30.0, 16.0, 12.0, np.eye(3), np.zeros(3), projection=projection)
    view = scene.oit.neural.decode(cam)

    def np_mlp(m, x):
        W0, b0, W2, b2 = (p.detach().numpy().astype(np.float64) for p in m.parameters())
        return np.maximum(x @ W0.T + b0, 0) @ W2.T + b2

    ob = anchors - cam.position if projection == "perspective" else np.c_[0 * anchors[:, :2], anchors[:, 2]]
    dist = np.linalg.norm(ob, axis=1, keepdims=True)
    view_dir = ob / dist
    w = np_mlp(mlps["feature_bank"], view_dir)
    w = np.exp(w - w.max(1, keepdims=True))
    w /= w.sum(1, keepdims=True)
    f = np.tile(feats[:, ::4], (1, 4)) * w[:, :1] + np.tile(feats[:, ::2], (1, 2)) * w[:, 1:2] + feats * w[:, 2:]
    x = np.concatenate([f, view_dir], 1)
    opac = np.tanh(np_mlp(mlps["opacity"], np.concatenate([x, dist], 1))).reshape(-1)
    colour = (1 / (1 + np.exp(-np_mlp(mlps["color"], x)))).reshape(-1, 3)
    sr = np_mlp(mlps["cov"], x).reshape(-1, 7)
    off = np.clip(offsets, -1, 1).reshape(-1, 3)
    a_scale = np.repeat(np.exp(log_sizes), k, 0)
    scale = a_scale * np.minimum(1 / (1 + np.exp(-sr[:, :3])), (2 - np.linalg.norm(off, axis=1, keepdims=True)) / 3)
    from gbviewer.io.duplex_model import _eval_sh

    vi = np.repeat(1 / (1 + np.exp(-_eval_sh(sh_vi, view_dir))), k)
    np.testing.assert_allclose(view.means, np.repeat(anchors, k, 0) + off * a_scale, atol=1e-5)
    np.testing.assert_allclose(view.scales, scale, rtol=1e-4, atol=1e-6)
    np.testing.assert_allclose(view.opacities, np.clip(opac * vi, 0, 1), atol=1e-5)
    np.testing.assert_allclose(view.sh[:, 0] * SH_C0 + 0.5, colour, atol=1e-5)
    q = sr[:, 3:] / np.linalg.norm(sr[:, 3:], axis=1, keepdims=True)
    assert np.allclose(np.abs((view.quats * q).sum(1)), 1, atol=1e-5)
    frame = gb.render(scene, cam, "duplex")
    assert np.isfinite(frame.rgb).all() and frame.stats.cells == n


def test_unite_checkpoint(tmp_path, camera):
    """The same model saved as one checkpoints.pth of state dicts renders the same image."""
    path, _ = hand_checkpoint(tmp_path)
    ref = gb.render(gb.load(path), camera, "duplex").rgb
    state = {
        f"{kind}_mlp": torch.jit.load(str(tmp_path / f"{kind}_mlp.pt")).state_dict()
        for kind in ("opacity", "cov", "color")
    }
    for kind in ("opacity", "cov", "color"):
        (tmp_path / f"{kind}_mlp.pt").unlink()
    torch.save(state, tmp_path / "checkpoints.pth")
    assert np.abs(gb.render(gb.load(path), camera, "duplex").rgb - ref).max() < 1e-6


def test_missing_mlp_file(tmp_path):
    path, _ = hand_checkpoint(tmp_path)
    (tmp_path / "cov_mlp.pt").unlink()
    with pytest.raises(SceneFormatError, match=r"cov_mlp\.pt.*missing.*opacity_mlp\.pt, cov_mlp\.pt"):
        gb.load(path)


def test_wrong_feature_size(tmp_path):
    path, _ = hand_checkpoint(tmp_path)
    save_mlps(tmp_path, {"color": mlp(4 + 3 + 5, 4, 6, nn.Sigmoid())})
    with pytest.raises(SceneFormatError, match=r"color_mlp\.pt: wrong feature size: takes 12 inputs.*4 features"):
        gb.load(path)
    save_mlps(tmp_path, {"color": mlp(4 + 3, 4, 6, nn.Sigmoid()), "opacity": mlp(4 + 3, 4, 3, nn.Tanh())})
    with pytest.raises(SceneFormatError, match=r"opacity_mlp\.pt: wrong output size 3.*2 offsets"):
        gb.load(path)


def test_bad_files(tmp_path, monkeypatch):
    path, _ = hand_checkpoint(tmp_path)
    (tmp_path / "opacity_mlp.pt").write_bytes(b"not a zip")
    with pytest.raises(SceneFormatError, match=r"opacity_mlp\.pt: not a TorchScript module"):
        gb.load(path)
    import sys

    monkeypatch.setitem(sys.modules, "torch", None)
    with pytest.raises(SceneFormatError, match=r"needs PyTorch.*gbviewer\[duplex\]"):
        gb.load(path)


def test_glsl_renders_checkpoint(tmp_path, camera):
    from gbviewer.render.glsl import GlslRenderer

    ok, why = GlslRenderer.available()
    if not ok:
        skip_or_fail(why)
    path, _ = hand_checkpoint(tmp_path)
    scene = gb.load(path)
    for mode in ("duplex", "wsr", "scalar"):
        a = gb.render(scene, camera, mode)
        b = gb.render(scene, camera, mode, backend="glsl")
        assert np.abs(a.rgb - b.rgb).max() < 1e-5, mode
