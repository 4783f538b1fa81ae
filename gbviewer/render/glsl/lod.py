"""A level-of-detail cut drawn in place on the GPU (shaders/lod_rows.glsl): the hierarchy's interior nodes go up
once, as rows N.. of the scene's geometry and SH buffers, and per frame only a changed cut's row list."""

from __future__ import annotations

import numpy as np

from ...lod import Hierarchy
from ...model.scene import Scene
from ..prepare import CutRows, Prepared
from . import interface as gi
from .gpu import Gpu


class GpuCut:
    """The hierarchy whose interior nodes are on the GPU (`tree`) and the cut in "lod_rows" (`cut`)."""

    def __init__(self) -> None:
        self.tree: Hierarchy | None = None
        self.cut = CutRows()

    def forget(self) -> None:
        """Nothing of a hierarchy on the GPU (the scene's buffers went up again, or were freed)."""
        self.tree = None
        self.cut.forget()

    def sync(self, gpu: Gpu, prep: Prepared, threads: int, flag: np.ndarray | None) -> None:
        """Upload `prep`'s hierarchy where it is not yet there, and its cut's rows where they changed."""
        if prep.tree is not self.tree:
            self.forget()
            upload_tree(gpu, prep.tree, prep.scene)
            self.tree = prep.tree
        if self.cut.update(prep.tree, prep.lod, threads, flag):
            try:
                upload_rows(gpu, self.cut)
            except BaseException:
                self.cut.forget()  # not on the GPU: the next frame uploads it again
                raise


def upload_tree(gpu: Gpu, tree: Hierarchy, scene: Scene) -> None:
    """The interior nodes after the uploaded `scene`'s rows of "geom" and "sh" (SH rounded to the scene's dtype, as
    the gathered cut's)."""
    m, n = tree.num_interior, scene.num_splats
    f3d = tree.filter_3d if tree.filter_3d is not None else np.zeros(m, np.float32)
    geom = gi.records(gi.GEOM_VEC4S, tree.means, tree.opacities, tree.scales, f3d, tree.quats)
    sh = np.ascontiguousarray(tree.sh.astype(scene.sh.dtype, copy=False), np.float32)
    gpu.upload_after("geom", n * gi.GEOM_VEC4S * gi.VEC4_BYTES, geom, "level-of-detail node geometry")
    gpu.upload_after("sh", n * scene.sh.shape[1] * 3 * gi.WORD_BYTES, sh, "level-of-detail node SH")


def upload_rows(gpu: Gpu, cut: CutRows) -> None:
    """The cut's rows and weights as lod_rows.glsl's uvec2 (row, weight bits) into "lod_rows"."""
    gpu.upload(
        "lod_rows", np.column_stack((cut.rows.view(np.uint32), cut.weights.view(np.uint32))), "level-of-detail rows"
    )
