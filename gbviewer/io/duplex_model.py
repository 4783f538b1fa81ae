"""The per-view decode of a trained Duplex-GS model (`DuplexModel`): its anchors' MLPs run for a camera.

Decoding for a camera (`DuplexModel.decode`), as `generate_neural_gaussians`:
- anchors kept: Octree-GS level of detail (level <= round(log2(standard_dist / distance) + extra_level), clamped to
  the levels present; dist2level 'round') and in front of the near plane (z > 0.2; the published prefilter also
  drops anchors whose tile rectangle is off screen, which the renderer's cell culling does for duplex);
- view direction and distance of an anchor: from the camera centre (`Camera.view_rays`; an orthographic camera
  sees every anchor along its forward axis, at its depth);
- MLP input per anchor: [feature (through the feature bank when present), view direction, (distance), (level)],
  (+ appearance embedding 0 for colour). Which of distance / level each MLP takes follows from its input size; when
  every MLP has exactly one extra input it is taken as the distance (Scaffold-GS's add_*_dist; Octree-GS's
  add_level is off by default);
- per child k: opacity o (Tanh), colour (RGB, no SH), scale = anchor_scale * min(sigmoid(raw), (2 - |offset|)/3),
  rotation = normalize(raw), centre = anchor + offset * anchor_scale (offsets clamped to [-1, 1]);
- v = sigmoid(eval_sh(anchor_sh, view direction)) per anchor; the decoded splat's opacity is o * v (the published
  rasterizer multiplies them first; non-positive ones are culled);
- cell = the anchor: centre, scale exp(anchor_size), rotation = normalized mean of its children's quaternions
  weighted by max(o * v, 0).

The result is a per-view `Scene` with those splats, their cells and the trained globals (sigma, w_bg = relu(raw) +
0.1, ET_grade), which every mode renders (wsr and duplex use the globals; the others alpha-blend the decoded
splats). The MLPs (loaded by `gbviewer.io.duplex_mlp`) run on CUDA when torch has it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..core.errors import SceneFormatError
from ..model.camera import NEAR_PLANE, Camera
from ..model.cells import Cells
from ..model.scene import SH_C0, Scene
from .duplex_mlp import MLP_FILES, OPTIONAL_FILES, linear_shapes
from .transform import sh_basis


class DuplexModel:
    """Anchors, MLPs and globals of a trained Duplex-GS model; `decode(camera)` gives the per-view splats and cells
    (a `gbviewer.model.scene.ViewDecoder`)."""

    def __init__(
        self, path: Path, anchors, levels, extra_levels, offsets, feats, anchor_scales, sh_vi, info, mlps, torch
    ):
        self.path, self.torch = path, torch
        self.anchors = anchors.astype(np.float64)
        self.levels, self.extra_levels = levels, extra_levels
        self.offsets = np.clip(offsets, -1.0, 1.0)  # get_offset
        self.feats, self.anchor_scales, self.sh_vi = feats, anchor_scales, sh_vi
        self.voxel_size, self.standard_dist = float(info[0]), float(info[1])
        self.sigma = float(info[2])
        self.weight_background = max(float(info[3]), 0.0) + 0.1  # get_wbg = relu(_wbg) + 0.1
        self.et_grade = float(info[4])
        self.num_levels = int(levels.max() - levels.min() + 1)
        self.k = offsets.shape[1]
        self.device = "cuda" if torch.cuda.is_available() else "cpu"
        self.mlps = {kind: m.to(self.device) for kind, m in mlps.items()}
        self._check_mlps()

    def _check_mlps(self) -> None:
        """Input and output sizes of every MLP against the anchors' features and K offsets."""
        F, k = self.feats.shape[1], self.k
        shapes = {kind: linear_shapes(m) for kind, m in self.mlps.items() if kind != "appearance"}
        self.app_dim = 0
        if "appearance" in self.mlps:
            w = [p for p in self.mlps["appearance"].parameters()]
            self.app_dim = int(w[0].shape[1]) if w else 0
        feat_in = F
        if "feature_bank" in shapes:
            fin, fout = shapes["feature_bank"][0][0], shapes["feature_bank"][-1][1]
            if fout != 3 or fin not in (3, 4) or F % 4:
                raise SceneFormatError(
                    self.path.parent / OPTIONAL_FILES["feature_bank"],
                    f"feature bank maps {fin} inputs to {fout}; expected 3 (+1 level) -> 3 weights "
                    f"over {F} features (a multiple of 4)",
                )
        outs = {"opacity": k, "cov": 7 * k, "color": 3 * k}
        self.extra = {}
        for kind, want_out in outs.items():
            fname = MLP_FILES[kind]
            if not shapes[kind]:
                raise SceneFormatError(self.path.parent / fname, "has no linear layers")
            n_in, n_out = shapes[kind][0][0], shapes[kind][-1][1]
            base = feat_in + 3 + (self.app_dim if kind == "color" else 0)
            if n_out != want_out:
                raise SceneFormatError(
                    self.path.parent / fname,
                    f"wrong output size {n_out}; the anchors have {k} offsets, so expected {want_out}",
                )
            if not base <= n_in <= base + 2:
                raise SceneFormatError(
                    self.path.parent / fname,
                    f"wrong feature size: takes {n_in} inputs; the "
                    f"anchors have {F} features + 3 view direction"
                    + (f" + {self.app_dim} appearance" if kind == "color" and self.app_dim else "")
                    + f" (+1 distance, +1 level): expected {base}..{base + 2}",
                )
            self.extra[kind] = n_in - base
        self.level_input = 2 in self.extra.values()
        if self.level_input and 0 in self.extra.values():
            raise SceneFormatError(
                self.path.parent / MLP_FILES["opacity"],
                f"inconsistent MLP input sizes {self.extra}: the level input is shared by all MLPs",
            )

    def anchor_mask(self, camera: Camera) -> np.ndarray:
        """Anchors of this view: Octree-GS level of detail ('round') and in front of the near plane."""
        dist = camera.view_rays(self.anchors)[1]
        with np.errstate(divide="ignore"):
            pred = np.log2(self.standard_dist / np.maximum(dist, 1e-30)) + self.extra_levels
        lod = np.clip(np.round(pred), 0, self.num_levels - 1)
        z = self.anchors @ camera.R[2] + camera.t[2]
        return (self.levels <= lod) & (z > NEAR_PLANE)

    def _empty_view(self, camera: Camera) -> Scene:
        """No anchor in this view: one transparent splat in one cell, which every mode and backend culls, so the
        frame is the background (a Scene cannot be empty)."""
        centre = (camera.position + 1.0 * camera.R[2]).astype(np.float32)[None]
        cells = Cells(
            centre,
            np.ones((1, 3), np.float32),
            np.array([[1.0, 0, 0, 0]], np.float32),
            np.array([0, 1], np.int32),
            np.array([0], np.int32),
            "duplex-gs anchors (none in view)",
            0.0,
        )
        return Scene.from_arrays(
            centre,
            np.full((1, 3), 1e-3),
            np.array([[1.0, 0, 0, 0]]),
            np.zeros(1),
            np.zeros((1, 1, 3)),
            source=f"{self.path} @ view (no anchors)",
            meta={"format": "duplex-gs decoded", "view_weights_in_opacity": True},
            wsr_sigma=self.sigma if self.sigma > 0 else None,
            weight_background=self.weight_background,
            et_grade=self.et_grade,
            cells=cells,
        )

    def decode(self, camera: Camera) -> Scene:
        """The splats and cells of this view (see the module docstring)."""
        torch = self.torch
        keep = self.anchor_mask(camera)
        idx = np.flatnonzero(keep)
        A, k = len(idx), self.k
        if A == 0:
            return self._empty_view(camera)
        dev = self.device
        f32 = torch.float32
        anchor = self.anchors[idx]
        view, dist = camera.view_rays(anchor)
        dist = dist[:, None]
        with torch.no_grad():
            feat = torch.as_tensor(self.feats[idx], dtype=f32, device=dev)
            tview = torch.as_tensor(view, dtype=f32, device=dev)
            tdist = torch.as_tensor(dist, dtype=f32, device=dev)
            tlevel = torch.as_tensor(self.levels[idx, None], dtype=f32, device=dev)
            if "feature_bank" in self.mlps:
                cat = torch.cat([tview, tlevel], 1) if self.level_input else tview
                w = self.mlps["feature_bank"](cat).unsqueeze(1)  # (A, 1, 3)
                f = feat.unsqueeze(-1)
                feat = (
                    f[:, ::4, :1].repeat([1, 4, 1]) * w[:, :, :1]
                    + f[:, ::2, :1].repeat([1, 2, 1]) * w[:, :, 1:2]
                    + f * w[:, :, 2:]
                ).squeeze(-1)

            def inputs(kind: str):
                parts = [feat, tview]
                if self.extra[kind] == 2 or (self.extra[kind] == 1 and not self.level_input):
                    parts.append(tdist)
                if self.level_input:
                    parts.append(tlevel)
                if kind == "color" and self.app_dim:
                    app = self.mlps["appearance"](torch.zeros(A, dtype=torch.long, device=dev))
                    parts.append(app)
                return torch.cat(parts, 1)

            opacity = self.mlps["opacity"](inputs("opacity")).reshape(-1).float()
            color = self.mlps["color"](inputs("color")).reshape(A * k, 3).float()
            scale_rot = self.mlps["cov"](inputs("cov")).reshape(A * k, 7).float()
            offsets = torch.as_tensor(self.offsets[idx].reshape(-1, 3), dtype=f32, device=dev)
            a_scale = torch.as_tensor(self.anchor_scales[idx], dtype=f32, device=dev).repeat_interleave(k, 0)
            a_pos = torch.as_tensor(anchor, dtype=f32, device=dev).repeat_interleave(k, 0)
            ratio_max = (2.0 - torch.sqrt((offsets**2).sum(1, keepdim=True))) / 3.0
            scaling = a_scale * torch.minimum(torch.sigmoid(scale_rot[:, :3]), ratio_max)
            rot = torch.nn.functional.normalize(scale_rot[:, 3:7])
            xyz = a_pos + offsets * a_scale
            vi = torch.sigmoid(torch.as_tensor(_eval_sh(self.sh_vi[idx], view), dtype=f32, device=dev))
            vi = vi.repeat_interleave(k, 0)
            weights = (opacity * vi).clamp(min=0.0).reshape(-1, k)
            cell_rot = torch.nn.functional.normalize((rot.reshape(-1, k, 4) * weights.unsqueeze(2)).mean(1))
            opac = opacity * vi
            out = {
                name: v.cpu().numpy()
                for name, v in (
                    ("xyz", xyz),
                    ("scaling", scaling),
                    ("rot", rot),
                    ("color", color),
                    ("opac", opac),
                    ("cell_rot", cell_rot),
                )
            }
        sh = ((out["color"] - 0.5) / SH_C0)[:, None, :]
        quats, cq = out["rot"], out["cell_rot"].astype(np.float32)
        for q in (quats, cq):
            q[np.linalg.norm(q, axis=1) < 1e-12] = (1.0, 0.0, 0.0, 0.0)
        cells = Cells(
            anchor.astype(np.float32),
            self.anchor_scales[idx].astype(np.float32),
            cq,
            np.arange(0, A * k + 1, k, dtype=np.int32),
            np.arange(A * k, dtype=np.int32),
            "duplex-gs anchors",
            0.0,
        )
        return Scene.from_arrays(
            out["xyz"],
            out["scaling"],
            quats,
            np.clip(out["opac"], 0.0, 1.0),
            sh,
            source=f"{self.path} @ view",
            meta={"format": "duplex-gs decoded", "view_weights_in_opacity": True},
            wsr_sigma=self.sigma if self.sigma > 0 else None,
            weight_background=self.weight_background,
            et_grade=self.et_grade,
            cells=cells,
        )


def _eval_sh(coeffs: np.ndarray, dirs: np.ndarray) -> np.ndarray:
    """eval_sh of 3DGS for a 1-channel SH (A,K) at unit directions (A,3): the raw sum (no +0.5)."""
    c = np.asarray(coeffs, np.float64)
    return (sh_basis(dirs, c.shape[1]) * c).sum(1)
