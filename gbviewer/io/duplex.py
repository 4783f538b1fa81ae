"""Trained Duplex-GS checkpoints (docs/formats.md#duplex-gs): an anchor ply plus TorchScript MLPs, decoded per view.

Layout (LiYukeee/Duplex-GS `save_ply`, `save_mlp_checkpoints`): `point_cloud.ply` with one vertex per anchor (cell):
`x y z level extra_level info f_offset_* f_anchor_feat_* anchor_size_0..2 anchor_rot_0..3 anchor_shd_0 anchor_shv_*`,
where `f_offset_*` is channel-major (all x offsets, then y, then z), `anchor_size` is a log scale and `info` carries
the globals in its first rows (voxel_size, standard_dist, sigma, raw w_bg, ET_grade). The MLPs lie beside the ply
(or in a `checkpoint.pth/` folder there): `opacity_mlp.pt` (Tanh, K outputs), `cov_mlp.pt` (7K), `color_mlp.pt`
(Sigmoid, 3K), optional `feature_bank_mlp.pt` and `embedding_appearance.pt`; or all of them as state dicts in one
`checkpoints.pth` ('unite' mode), rebuilt as the published Linear-ReLU-Linear(-activation) stacks.

Decoded per view by `DuplexModel` (gbviewer/io/duplex_model.py) with the MLPs of `gbviewer.io.duplex_mlp`, which
imports torch (`pip install 'gbviewer[duplex]'`).
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import plyfile

from ..core.errors import SceneFormatError
from ..model.scene import Scene
from .duplex_mlp import import_torch, load_mlps
from .duplex_model import DuplexModel


def is_duplex_ply(ply: plyfile.PlyData) -> bool:
    names = set(ply["vertex"].data.dtype.names or ()) if "vertex" in ply else set()
    return "f_anchor_feat_0" in names and "f_offset_0" in names


def _indexed(names: list[str], prefix: str) -> list[str]:
    idx = sorted(int(m.group(1)) for n in names if (m := re.fullmatch(re.escape(prefix) + r"(\d+)", n)))
    return [f"{prefix}{i}" for i in idx] if idx == list(range(len(idx))) else []


def load_duplex(path: Path, ply: plyfile.PlyData) -> Scene:
    """A Duplex-GS anchor ply and its MLPs. The returned Scene renders through `neural.decode`; its splat arrays
    only hold the view-independent child centres (for bounds and framing)."""
    from .ply_read import vertex_columns

    names = list(ply["vertex"].data.dtype.names or ())
    n = ply["vertex"].count
    groups = {p: _indexed(names, p) for p in ("f_offset_", "f_anchor_feat_", "anchor_size_", "anchor_shv_")}
    for field in ("x", "y", "z", "level", "extra_level", "info", "anchor_shd_0"):
        if field not in names:
            raise SceneFormatError(path, "missing Duplex-GS anchor property", field=field)
    if len(groups["f_offset_"]) == 0 or len(groups["f_offset_"]) % 3:
        raise SceneFormatError(
            path, f"{len(groups['f_offset_'])} f_offset_* properties; expected 3 K (f_offset_0..)", field="f_offset"
        )
    if len(groups["anchor_size_"]) != 3:
        raise SceneFormatError(path, "expected anchor_size_0..2", field="anchor_size")
    if len(groups["anchor_shv_"]) not in (0, 3, 8, 15):
        raise SceneFormatError(
            path, f"{len(groups['anchor_shv_'])} anchor_shv_* properties; expected 0, 3, 8 or 15", field="anchor_shv"
        )
    if n < 5:
        raise SceneFormatError(path, f"{n} anchors; the info column needs 5 rows", field="info")
    torch = import_torch(path)
    wanted = (
        ["x", "y", "z", "level", "extra_level", "info"]
        + groups["f_offset_"]
        + groups["f_anchor_feat_"]
        + groups["anchor_size_"]
        + ["anchor_shd_0"]
        + groups["anchor_shv_"]
    )
    data = vertex_columns(path, ply, wanted)
    if not np.isfinite(data).all():
        raise SceneFormatError(path, "non-finite anchor values")
    pos = {name: i for i, name in enumerate(wanted)}

    def take(names_):
        return data[:, [pos[x] for x in names_]]

    k = len(groups["f_offset_"]) // 3
    offsets = take(groups["f_offset_"]).reshape(n, 3, k).transpose(0, 2, 1)  # channel-major in the file
    info = data[:5, pos["info"]]
    mlps = load_mlps(path, torch)
    model = DuplexModel(
        path,
        take(["x", "y", "z"]),
        data[:, pos["level"]].astype(np.int64),
        data[:, pos["extra_level"]],
        offsets,
        take(groups["f_anchor_feat_"]),
        np.exp(take(groups["anchor_size_"])),
        take(["anchor_shd_0"] + groups["anchor_shv_"]),
        info,
        mlps,
        torch,
    )
    centres = (model.anchors[:, None, :] + model.offsets * model.anchor_scales[:, None, :]).reshape(-1, 3)
    m = len(centres)
    meta = {
        "format": "duplex-gs",
        "version": None,
        "properties": names,
        "anchors": n,
        "offsets_per_anchor": k,
        "features": model.feats.shape[1],
        "mlps": sorted(model.mlps),
        "et_grade": model.et_grade,
        "sigma": model.sigma,
        "weight_background": model.weight_background,
    }
    return Scene.from_arrays(
        centres,
        np.repeat(model.anchor_scales, k, 0) / 3.0,
        np.tile([1.0, 0, 0, 0], (m, 1)),
        np.full(m, 0.5),
        np.zeros((m, 1, 3)),
        source=str(path),
        meta=meta,
        neural=model,
        wsr_sigma=model.sigma if model.sigma > 0 else None,
        weight_background=model.weight_background,
        et_grade=model.et_grade,
    )
