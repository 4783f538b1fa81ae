"""The glsl backend's per-camera stage: the camera as the per-camera kernels' uniforms (`camera_uniforms`), and the
`stage` buffer stage.comp fills (`stage_splat` of every splat: view-space position and depth, 3D filter, 2D covariance
before the mode's filter, screen position, SH colour, near and on-screen cull) with the key of what it holds
(`Stage`), so that a mode, supersample or rate switch of one camera reuses it, as on the CPU."""

from __future__ import annotations

import time

import numpy as np

from ...model.camera import Camera
from ..presets import FILTERED_MODES
from ..types import Mode, RenderSettings
from ..view_filter import DILATION_3DGS
from . import interface as gi
from .gpu import WG, Gpu

VEC4 = gi.VEC4_BYTES


def camera_uniforms(camera: Camera, supersample: int) -> dict:
    """The camera as stage.comp, preprocess.comp and the binning kernels take it, at the frame's sampling grid (N x
    N samples per pixel): the tile grid, pose, intrinsics scaled by N (in float32), size, near plane and projection."""
    f32 = np.float32
    Nf = f32(supersample)
    RW, RH = camera.width * supersample, camera.height * supersample
    return dict(
        grid=(-(-RW // gi.TILE), -(-RH // gi.TILE)),
        cam_R=np.ascontiguousarray(camera.R, f32).reshape(9),
        cam_t=np.ascontiguousarray(camera.t, f32),
        cam_f=(
            float(f32(camera.fx) * Nf),
            float(f32(camera.fy) * Nf),
            float(f32(camera.cx) * Nf),
            float(f32(camera.cy) * Nf),
        ),
        cam_size=(RW, RH),
        cam_near=float(f32(camera.near)),
        cam_projection=camera.projection_code,
    )


class Stage:
    """The `stage` buffer on `gpu` and `key`, what it holds (None: nothing usable)."""

    def __init__(self, gpu: Gpu) -> None:
        self.gpu = gpu
        self.key: tuple | None = None

    def forget(self) -> None:
        """Nothing in the buffer is usable (a new scene, a release)."""
        self.key = None

    def build(
        self,
        settings: RenderSettings,
        n: int,
        sh_k: int,
        sh_deg: int,
        cam_uniforms: dict,
        rows,
        lod: dict,
        generations: tuple,
    ) -> tuple:
        """The `stage` buffer for this frame's camera (at its sampling grid), whether it was kept from an earlier
        frame and the ms spent building it: stage.comp runs (and the GL work finishes, for that time) only when the
        generations (`generations`: of the splats on the GPU, of the level-of-detail cut drawn in place or None),
        the camera, the SH degree or the on-screen cull's reach (the largest diagonal the frame's 2D filter adds, at
        least 3DGS's +0.3: stage_reach in preprocess_stage.h), the presets' stage rules (stage_rules) or the
        level-of-detail rows drawn in place (`rows`, `lod`: its uniform) changed."""
        gpu = self.gpu
        stage = gpu.ensure("stage", n * gi.STAGE_VEC4S * VEC4, "per-camera stage")
        vf = settings.view_filter.native() if settings.mode.label in FILTERED_MODES else np.zeros(2, np.float32)
        reach = float(max(np.float32(DILATION_3DGS), vf[0] + vf[1]))  # gbv::stage_reach, in float32
        rules = settings.view_filter.stage_rules if settings.mode.label in FILTERED_MODES else 0
        if settings.mode == Mode.EVAL3D:
            reach = 1e30  # eval3d: its footprint is the ray's: the stage keeps every splat in front of the plane
        camera_bytes = tuple(np.asarray(v).tobytes() for v in cam_uniforms.values())
        key = (*generations, camera_bytes, sh_deg, reach, rules)
        if key == self.key:
            return stage, True, 0.0
        self.key = None
        t0 = time.perf_counter()
        gpu.run(
            "stage.comp",
            -(-n // WG),
            (gpu.buffers["geom"], gpu.buffers["sh"], stage, rows),
            num_splats=n,
            sh_k=sh_k,
            sh_deg=sh_deg,
            reach=reach,
            rules=rules,
            **lod,
            **cam_uniforms,
        )
        self.gpu.ctx.finish()
        self.key = key
        return stage, False, (time.perf_counter() - t0) * 1e3
